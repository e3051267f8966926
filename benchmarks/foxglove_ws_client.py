"""A small Foxglove WebSocket client (the `websockets` package), written from the protocol's description, for the
live-view benchmark and tests: connect, learn the channels and services, subscribe, receive message data with its
arrival time, call a service. It runs its own asyncio loop on a thread, so a test drives it with plain calls.

Not the Foxglove app: it checks the protocol as another implementation would use it (independent of the server's
code), and it can play a client that stops reading (`stall=True`) to show a stalled client changes nothing.
"""

from __future__ import annotations

import asyncio
import contextlib
import base64
import json
import struct
import threading
import time
from dataclasses import dataclass, field
from typing import Any

SUBPROTOCOL = "foxglove.sdk.v1"  # the subprotocol the foxglove-sdk server selects
_OP_MESSAGE_DATA, _OP_SERVICE_RESPONSE = 0x01, 0x03
_OP_SERVICE_REQUEST = 0x02


@dataclass
class Received:
    topic: str
    receive_ns: int  # wall clock (time.time_ns) when the client had it
    log_ns: int  # the timestamp the server sent with it (the recording's log time)
    payload: bytes


@dataclass
class ChannelInfo:
    id: int
    topic: str
    encoding: str
    schema_name: str
    schema: bytes  # decoded (protobuf: the FileDescriptorSet bytes)
    metadata: dict[str, str] = field(default_factory=dict)


class FoxgloveClient:
    """Connects to `url`; subscribes to every channel whose topic is in `topics` (None: all) as it is advertised."""

    def __init__(self, url: str, topics: set[str] | None = None, stall: bool = False,
                 keep_payloads: bool = True) -> None:
        self.url = url
        self.topics = topics
        self.stall = stall
        self.keep_payloads = keep_payloads
        self.channels: dict[int, ChannelInfo] = {}
        self.services: dict[str, int] = {}
        self.received: list[Received] = []
        self.counts: dict[str, int] = {}
        self.errors: list[str] = []
        self.statuses: list[str] = []  # the server's status messages ("level: message"), e.g. a refused subscription
        self._subscriptions: dict[int, int] = {}  # subscription id -> channel id
        self._replies: dict[int, tuple[str, Any]] = {}
        self._next_call = 1
        self._loop = asyncio.new_event_loop()
        self._ws: Any = None
        self._connected = threading.Event()
        self._closed = threading.Event()
        self._thread = threading.Thread(target=self._run, name="foxglove-client", daemon=True)

    # ------------------------------------------------------------------ plain calls
    def start(self, timeout_s: float = 10.0) -> FoxgloveClient:
        self._thread.start()
        if not self._connected.wait(timeout_s):
            raise TimeoutError(f"no connection to {self.url} within {timeout_s} s: {self.errors}")
        return self

    def wait_for(self, condition: Any, timeout_s: float = 30.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if condition(self):
                return True
            time.sleep(0.02)
        return bool(condition(self))

    def call_service(self, name: str, request: dict[str, Any], timeout_s: float = 10.0) -> tuple[str, Any]:
        """('ok', response dict) or ('failure', message)."""
        if not self.wait_for(lambda c: name in c.services, timeout_s):
            raise TimeoutError(f"service {name} not advertised")
        call_id = self._next_call
        self._next_call += 1
        encoding = b"json"
        frame = struct.pack("<BIII", _OP_SERVICE_REQUEST, self.services[name], call_id, len(encoding)) + encoding \
            + json.dumps(request).encode()
        asyncio.run_coroutine_threadsafe(self._ws.send(frame), self._loop).result(timeout_s)
        if not self.wait_for(lambda c: call_id in c._replies, timeout_s):
            raise TimeoutError(f"no reply to the call of {name}")
        return self._replies.pop(call_id)

    def subscribed_topics(self) -> list[str]:
        """The topics this client has asked for (a channel unadvertised since shows as its id)."""
        return sorted(self.channels[c].topic if c in self.channels else f"#{c}" for c in self._subscriptions.values())

    def close(self) -> None:
        if self._ws is not None and not self._closed.is_set():
            asyncio.run_coroutine_threadsafe(self._ws.close(), self._loop)
        self._thread.join(5.0)

    # ------------------------------------------------------------------ the loop
    def _run(self) -> None:
        try:
            self._loop.run_until_complete(self._main())
        except Exception as exc:  # noqa: BLE001 - reported to the caller through `errors`
            self.errors.append(f"{type(exc).__name__}: {exc}")
        finally:
            self._closed.set()
            self._connected.set()

    async def _main(self) -> None:
        import websockets

        # A stalled client reads nothing: one queued frame is enough to stop reading from the socket, so the
        # server's sends back up in TCP as they would for a client that hangs.
        queue = 1 if self.stall else 4096
        from websockets.typing import Subprotocol

        async with websockets.connect(self.url, subprotocols=[Subprotocol(SUBPROTOCOL)], max_size=None,
                                      max_queue=queue) as ws:
            self._ws = ws
            self._connected.set()
            if self.stall:
                await self._read_until_subscribed(ws)
                await ws.wait_closed()
                return
            async for message in ws:
                self._handle(ws, message)

    async def _send(self, ws: Any, text: str) -> None:
        import websockets

        with contextlib.suppress(websockets.ConnectionClosed):  # the server went away: nothing to subscribe to
            await ws.send(text)

    async def _read_until_subscribed(self, ws: Any) -> None:
        async for message in ws:
            self._handle(ws, message)
            if self._subscriptions:
                return

    def _handle(self, ws: Any, message: str | bytes) -> None:
        if isinstance(message, str):
            self._handle_json(ws, json.loads(message))
            return
        op = message[0]
        if op == _OP_MESSAGE_DATA:
            subscription, log_ns = struct.unpack_from("<IQ", message, 1)
            channel = self.channels.get(self._subscriptions.get(subscription, -1))
            topic = channel.topic if channel else f"?{subscription}"
            self.counts[topic] = self.counts.get(topic, 0) + 1
            self.received.append(Received(topic, time.time_ns(), log_ns,
                                          bytes(message[13:]) if self.keep_payloads else b""))
        elif op == _OP_SERVICE_RESPONSE:
            _, call_id, length = struct.unpack_from("<III", message, 1)
            body = bytes(message[13 + length:])
            self._replies[call_id] = ("ok", json.loads(body) if body else {})

    def _handle_json(self, ws: Any, body: dict[str, Any]) -> None:
        op = body.get("op")
        if op == "advertise":
            self._advertised(ws, body)
        elif op == "unadvertise":
            for cid in body.get("channelIds", []):
                self.channels.pop(cid, None)
        elif op == "advertiseServices":
            for s in body["services"]:
                self.services[s["name"]] = s["id"]
        elif op == "serviceCallFailure":
            self._replies[body["callId"]] = ("failure", body.get("message", ""))
        elif op == "status":
            self.statuses.append(f"{body.get('level')}: {body.get('message', '')}")

    def _advertised(self, ws: Any, body: dict[str, Any]) -> None:
        """New channels: learn them, subscribe to the wanted ones."""
        wanted = []
        for c in body["channels"]:
            schema = c.get("schema", "")
            data = base64.b64decode(schema) if c.get("encoding") == "protobuf" else schema.encode()
            info = ChannelInfo(c["id"], c["topic"], c["encoding"], c["schemaName"], data, c.get("metadata", {}))
            self.channels[info.id] = info
            if self.topics is None or info.topic in self.topics:
                wanted.append(info.id)
        if wanted:
            subs = [{"id": len(self._subscriptions) + i + 1, "channelId": cid} for i, cid in enumerate(wanted)]
            for s in subs:
                self._subscriptions[s["id"]] = s["channelId"]
            asyncio.ensure_future(self._send(ws, json.dumps({"op": "subscribe", "subscriptions": subs})))


def latency_summary(received: list[Received]) -> dict[str, dict[str, float]]:
    """Per topic: messages, and the delay from each message's own time (its log time) to its arrival, in ms."""
    by_topic: dict[str, list[float]] = {}
    for m in received:
        by_topic.setdefault(m.topic, []).append((m.receive_ns - m.log_ns) / 1e6)
    out = {}
    for topic, delays in sorted(by_topic.items()):
        ordered = sorted(delays)
        out[topic] = {"messages": len(ordered), "median_ms": ordered[len(ordered) // 2],
                      "p95_ms": ordered[min(len(ordered) - 1, int(0.95 * len(ordered)))], "max_ms": ordered[-1]}
    return out


def main(argv: list[str] | None = None) -> int:
    """`python -m benchmarks.foxglove_ws_client URL --seconds S`: watch every topic for S seconds (or until the
    server closes) and print the per-topic latency summary as JSON (the live benchmark's client process)."""
    import argparse
    import sys

    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("url")
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args(argv)
    client = FoxgloveClient(args.url, keep_payloads=False).start()
    client.wait_for(lambda c: c._closed.is_set(), args.seconds)
    received = list(client.received)
    client.close()
    json.dump({"topics": latency_summary(received), "errors": client.errors}, sys.stdout)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
