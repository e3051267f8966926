"""The paper's whole test matrix as a list of runs: the actuator test for 1, 2 and 3 carbon-fibre layers, and
every leg protocol for designs 1-5. Runs are independent, so they go to a process pool."""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from hamr_bench.errors import ConfigError
from hamr_bench.protocols.session import RunRequest, run_protocol

LEG_PROTOCOLS = ("blocked-force", "sag-sweep", "free-displacement", "static")
DESIGNS = (1, 2, 3, 4, 5)
LAYERS = (1, 2, 3)


@dataclass(frozen=True)
class CampaignRun:
    name: str
    request: RunRequest


def campaign_runs(
    out_dir: Path, effects: dict[str, float], seed: int, overwrite: bool, set_options: list[str] | None = None,
    designs: tuple[int, ...] = DESIGNS, layers: tuple[int, ...] = LAYERS,
    protocols: tuple[str, ...] = ("actuator",) + LEG_PROTOCOLS, camera_storage: Any = None,
) -> list[CampaignRun]:
    runs = []
    index = 0
    for protocol in protocols:
        if protocol == "actuator":
            for n in layers:
                name = f"actuator-{n}layer"
                runs.append(CampaignRun(name, RunRequest(
                    protocol="actuator", out=out_dir / f"{name}.mcap", layers=n, design=4, effects=effects,
                    seed=seed * 1000 + index, overwrite=overwrite, camera_storage=camera_storage,
                    set_options=options_for(protocol, list(set_options or [])))))
                index += 1
            continue
        for design in designs:
            name = f"design{design}-{protocol}"
            runs.append(CampaignRun(name, RunRequest(
                protocol=protocol, out=out_dir / f"{name}.mcap", design=design, layers=2, effects=effects,
                seed=seed * 1000 + index, overwrite=overwrite, camera_storage=camera_storage,
                set_options=options_for(protocol, list(set_options or [])))))
            index += 1
    if not overwrite:
        existing = [r.request.out for r in runs if r.request.out.exists()]
        if existing:
            raise ConfigError(f"{existing[0]} exists (and {len(existing) - 1} more): use --force to overwrite")
    return runs


def options_for(protocol: str, set_options: list[str]) -> list[str]:
    """The `--set` options that apply to `protocol` (a campaign-wide option such as drive.cycles=2 skips the
    protocols that have no drive)."""
    from hamr_bench.protocols import get_protocol
    from hamr_bench.protocols.params import field_names

    params = get_protocol(protocol).Params()
    kept = []
    for option in set_options:
        name = option.partition("=")[0]
        table, dot, key = name.partition(".")
        if table in field_names(type(params)) and (not dot or key in field_names(type(getattr(params, table)))):
            kept.append(option)
    return kept


def _run_one(run: CampaignRun) -> tuple[str, str, str]:
    result = run_protocol(run.request)
    return run.name, result.exit_status, result.reason


def run_campaign(runs: list[CampaignRun], jobs: int | None = None, progress: bool = True,
                 live: Any = None) -> list[tuple[str, str, str]]:
    """Run every request; returns (name, exit_status, reason) per run, in order. With a live view (`live`, a
    hamr_bench.live.session.LiveView) the runs go one at a time in this process, each served while it runs, and an
    abort accepted from the view ends the run in progress and starts no other."""
    if live is not None:
        runs = [CampaignRun(r.name, replace(r.request, live=live)) for r in runs]
        jobs = 1
    jobs = jobs or min(len(runs), os.cpu_count() or 1)
    bar = None
    if progress:
        from tqdm import tqdm

        # disable=None: no bar when stderr is not a terminal (a log gets the result lines, not redraws)
        bar = tqdm(total=len(runs), desc="campaign", unit="run", dynamic_ncols=True, disable=None)
    results: list[tuple[str, str, str]] = []
    if jobs <= 1:
        for run in runs:
            if live is not None and live.abort_requested is not None:
                results.append((run.name, "aborted", f"not started: abort requested ({live.abort_requested})"))
                continue
            results.append(_run_one(run))
            if bar:
                bar.update()
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            for result in pool.map(_run_one, runs):
                results.append(result)
                if bar:
                    bar.update()
                    bar.set_postfix_str(result[0])
    if bar:
        bar.close()
    return results
