"""`python -m tests.reliability.kill_child RUN-ARGS...`: the real `hamr-bench` command line, plus a witness of what the
process had handed to its recorder and when.

A daemon thread prints one line every `WITNESS_PERIOD_S` of wall time: `W <time.time_ns()> <JSON topic -> count>`,
the number of messages per topic given to `Recorder` so far (counted after the hand-over returned). The parent that
SIGKILLs this process reads those lines to know which samples existed by a given wall time; nothing else about the
run is changed (the counter wraps `Recorder._put`, which every write goes through).
"""

from __future__ import annotations

import json
import sys
import threading
import time
from collections import Counter

WITNESS_PERIOD_S = 0.01


def main(argv: list[str]) -> int:
    from hamr_bench.cli import main as cli_main
    from hamr_bench.recording.writer import Recorder

    counts: Counter[str] = Counter()
    real_put = Recorder._put

    def counted_put(self, channel, time_s, payload):  # type: ignore[no-untyped-def]
        real_put(self, channel, time_s, payload)
        counts[channel.topic] += 1

    Recorder._put = counted_put  # type: ignore[method-assign]
    out = sys.stdout
    never = threading.Event()

    def witness() -> None:
        while True:
            snapshot = dict(counts)  # a copy taken before the time stamp: never more than existed at that time
            out.write(f"W {time.time_ns()} {json.dumps(snapshot)}\n")
            out.flush()
            never.wait(WITNESS_PERIOD_S)  # wall-clock pacing of this test-only witness, not of the run

    threading.Thread(target=witness, daemon=True).start()
    code = cli_main(argv)
    out.write(f"W {time.time_ns()} {json.dumps(dict(counts))}\nDONE {code}\n")
    out.flush()
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
