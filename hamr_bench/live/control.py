"""Control from the live connection: one Foxglove service, `/hamr_bench/abort`, that asks the run in progress to
stop through the runner's own abort path (`Runner.request_abort`, the one Ctrl-C takes: the run ends `aborted`
with the reason, the rig made safe, the recording closed).

A request is JSON, `{"token": "...", "reason": "..."}`. It is refused unless its token is the one printed when
the server started (compared in constant time); reading the streams needs no token. The token is per server
start, random (128 bits), never written to a recording or a log.
"""

from __future__ import annotations

import hmac
import json
import secrets
import threading
from collections.abc import Callable
from typing import Any

from hamr_bench.errors import HamrBenchError

ABORT_SERVICE = "/hamr_bench/abort"
REQUEST_SCHEMA = {
    "type": "object",
    "properties": {"token": {"type": "string"}, "reason": {"type": "string"}},
    "required": ["token"],
}
RESPONSE_SCHEMA = {"type": "object", "properties": {"accepted": {"type": "boolean"}, "message": {"type": "string"}}}


class ControlRefused(HamrBenchError):
    """A control request without the right token, or with nothing to act on (its text goes to the client)."""


def new_token() -> str:
    return secrets.token_urlsafe(16)


class AbortControl:
    """Checks abort requests and passes the accepted ones to the run in progress."""

    def __init__(self, token: str) -> None:
        self._token = token.encode()
        self._lock = threading.Lock()
        self._target: Callable[[str], None] | None = None
        self.requested: str | None = None  # the reason of the first accepted request (a campaign stops on it)
        self.refused = 0

    def set_target(self, abort: Callable[[str], None] | None) -> None:
        """The run to stop (its runner's `request_abort`), or None between runs."""
        with self._lock:
            self._target = abort

    def handle(self, payload: bytes, client: str) -> dict[str, Any]:
        """One request; returns the response, raises ControlRefused (the client sees the message)."""
        try:
            body = json.loads(payload.decode("utf-8"))
        except (UnicodeDecodeError, ValueError):
            body = None
        if not isinstance(body, dict):
            self.refused += 1
            raise ControlRefused('abort refused: the request must be a JSON object {"token": ..., "reason": ...}')
        token = body.get("token")
        if not isinstance(token, str) or not hmac.compare_digest(token.encode(), self._token):
            self.refused += 1
            raise ControlRefused("abort refused: control token missing or wrong (it is printed when the live "
                                 "server starts)")
        reason = str(body.get("reason") or "no reason given")[:200].replace("\n", " ")
        with self._lock:
            target = self._target
            if self.requested is None:
                self.requested = reason
        if target is None:
            return {"accepted": True, "message": "no run in progress; the command stops before its next run"}
        target(f"live client {client}: {reason}")
        return {"accepted": True, "message": "abort requested: the run ends aborted, rig made safe"}
