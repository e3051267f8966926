"""One live server for the runs of one command (`run`, `campaign`, `replay`): started before the first run,
attached to each run's recorder and runner in turn, stopped at the end.

`open_live_view(options)` prints where to connect and the control token; `LiveView.follow(recorder, runner)` is
what `run_protocol` and `run_replay` call for each run.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TextIO

from hamr_bench.live.control import ABORT_SERVICE, AbortControl, new_token
from hamr_bench.live.options import LiveOptions
from hamr_bench.live.server import LiveServer
from hamr_bench.live.tap import LiveTap


class LiveView:
    """The server of one command and the run it follows."""

    def __init__(self, options: LiveOptions, token: str | None = None, **server_options: Any) -> None:
        self.options = options
        self.token = token or new_token()
        self.control = AbortControl(self.token)
        self.server = LiveServer(options, self.control, **server_options)
        self._tap: LiveTap | None = None
        self._recorder: Any = None

    def start(self) -> None:
        self.server.start()

    def stop(self) -> None:
        self.unfollow()
        self.server.stop()

    @property
    def url(self) -> str:
        return LiveOptions(self.options.host, self.server.port).url

    @property
    def abort_requested(self) -> str | None:
        """The reason of an accepted abort request (a campaign starts no further run after one)."""
        return self.control.requested

    def follow(self, recorder: Any, request_abort: Callable[[str], None]) -> None:
        """Serve `recorder`'s streams from now on; accepted abort requests go to `request_abort` (the runner's)."""
        self.unfollow()
        tap = LiveTap(frame_interval_s=1.0 / self.server.frame_rate_Hz)
        camera = getattr(recorder, "camera", None)
        self.server.attach(tap, recorder.start_time_ns, frames_only_live=getattr(camera, "mode", "") == "none")
        recorder.add_tap(tap)
        self.control.set_target(request_abort)
        if self.control.requested is not None:  # asked before this run started: it stops at its first check
            request_abort(f"live client: {self.control.requested}")
        self._tap, self._recorder = tap, recorder

    def unfollow(self) -> None:
        self.control.set_target(None)
        if self._tap is not None:
            self._recorder.remove_tap(self._tap)
            self.server.detach()
        self._tap = self._recorder = None


@contextmanager
def open_live_view(options: LiveOptions | None, out: TextIO | None = None) -> Iterator[LiveView | None]:
    """A started LiveView for `options` (None: no live view), stopped on the way out."""
    if options is None:
        yield None
        return
    out = out or sys.stderr
    view = LiveView(options)
    view.start()
    print(f"live view: {view.url} (Foxglove: Open connection > Foxglove WebSocket; layout docs/foxglove/"
          f"hamr-bench.json)", file=out)
    print(f"live control token: {view.token} (abort through the {ABORT_SERVICE} service; reading needs none)",
          file=out)
    if not options.is_local:
        print(f"live view: listening on {options.host}, not only this machine: anyone who can reach it can watch "
              "(the token guards control only)", file=out)
    try:
        yield view
    finally:
        view.stop()
