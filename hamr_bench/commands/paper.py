"""`hamr-bench paper [--json | --markdown]`: the seed paper's claims next to the model's values, computed now."""

from __future__ import annotations

import argparse
import json


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("paper",
                                   help="reproduction table of the seed paper's claims (computed by the model)")
    fmt = parser.add_mutually_exclusive_group()
    fmt.add_argument("--json", action="store_true", help="JSON: a list of claims")
    fmt.add_argument("--markdown", action="store_true", help="Markdown (docs/paper-reproduction.md)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hamr_bench.model.claims import as_markdown, summary, table

    claims = table()
    if args.json:
        print(json.dumps({"claims": [c.as_dict() for c in claims]}, indent=2))
    elif args.markdown:
        print(as_markdown(claims), end="")
    else:
        for c in claims:
            mark = "ok " if c.reproduced else "NOT"
            note = f"  ({c.note})" if c.note else ""
            print(f"[{mark}] {c.id:28s} margin {c.margin:+.3f}  paper: {c.paper}  model: {c.model}{note}")
            if not c.reproduced:
                print(f"      reason: {c.reason}")
        print(summary(claims))
    return 0
