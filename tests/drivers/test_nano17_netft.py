"""Net F/T (RDT over UDP) driver against a loopback UDP emulator written here from the protocol description in
docs/notes (request `!HHI`, 36-byte `!IIIiiiiii` records), on a real clock."""

from __future__ import annotations

import socket
import struct
import threading

import pytest

from drivers.ati_netft import AtiNetFt
from hamr_bench.clock import RealClock
from hamr_bench.errors import DeviceFault, DeviceProtocolError, DeviceTimeout
from hamr_bench.interfaces import ForceSensor

CPF, CPT = 1_000_000.0, 1_000_000.0


class NetFtEmulator:
    """Answers RDT requests with records of a set wrench (in counts); a bias command zeroes subsequent
    records. Modes: 'ok', 'silent' (no reply), 'garbage' (short datagrams), 'status' (non-zero status
    word)."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.02)
        self.port = self.sock.getsockname()[1]
        self.counts = [0, 0, int(2.5 * CPF), 0, 0, int(0.001 * CPT)]
        self.bias = [0] * 6
        self.mode = "ok"
        self.rdt = 100
        self.streaming_to = None
        self.requests: list[tuple[int, int, int]] = []
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def record(self) -> bytes:
        self.rdt += 1
        status = 0x80010000 if self.mode == "status" else 0
        values = [c - b for c, b in zip(self.counts, self.bias)]
        return struct.pack("!IIIiiiiii", self.rdt, self.rdt, status, *values)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, peer = self.sock.recvfrom(64)
            except TimeoutError:
                if self.streaming_to is not None:
                    for _ in range(5):
                        self.sock.sendto(self.record(), self.streaming_to)
                continue
            header, command, count = struct.unpack("!HHI", data)
            self.requests.append((header, command, count))
            if header != 0x1234 or self.mode == "silent":
                continue
            if command == 0x42:
                self.bias = list(self.counts)
            elif command == 0:
                self.streaming_to = None
            elif command == 2 and count == 0:
                self.streaming_to = peer
            elif command == 2:
                for _ in range(count):
                    payload = b"\x01\x02\x03" if self.mode == "garbage" else self.record()
                    self.sock.sendto(payload, peer)

    def close(self) -> None:
        self._stop.set()
        self.thread.join()
        self.sock.close()


@pytest.fixture
def box():
    emulator = NetFtEmulator()
    clock = RealClock()
    sensor = AtiNetFt(clock, "127.0.0.1", port=emulator.port, counts_per_force=CPF, counts_per_torque=CPT,
                      capacity_N=17.0, timeout_s=0.3)
    yield emulator, sensor, clock
    sensor.close()
    emulator.close()


def test_single_reading_bias_and_request_bytes(box) -> None:
    emulator, sensor, _ = box
    assert isinstance(sensor, ForceSensor)
    assert sensor.read_wrench() == pytest.approx((0, 0, 2.5, 0, 0, 0.001))
    assert emulator.requests[-1] == (0x1234, 2, 1)
    sensor.tare()
    assert sensor.read_N() == pytest.approx(0.0)  # the box applied the bias before the next request
    assert (0x1234, 0x42, 0) in emulator.requests


def test_stream_and_clean_stop(box) -> None:
    emulator, sensor, clock = box
    sensor.start_stream()
    samples = []
    t0 = clock.now_s()
    while len(samples) < 20 and clock.now_s() - t0 < 2.0:
        samples += sensor.read_stream()
        clock.sleep(0.01)
    sensor.stop_stream()
    assert len(samples) >= 20
    assert all(s.force_N == pytest.approx(2.5) for s in samples)
    # consecutive RDT sequence numbers at the box's 1 kHz: 1 ms apart
    assert samples[1].time_s - samples[0].time_s == pytest.approx(1e-3)
    assert emulator.requests[-1] == (0x1234, 0, 0)
    assert sensor.read_N() == pytest.approx(2.5)  # drained: the next single reading is a fresh record


def test_faults(box) -> None:
    emulator, sensor, clock = box
    emulator.mode = "silent"
    t0 = clock.now_s()
    with pytest.raises(DeviceTimeout):
        sensor.read_N()
    assert clock.now_s() - t0 < 0.3 + 0.2
    emulator.mode = "garbage"
    with pytest.raises(DeviceProtocolError):
        sensor.read_N()
    emulator.mode = "status"
    with pytest.raises(DeviceFault, match="status 0x80010000"):
        sensor.read_N()
    emulator.mode = "ok"
    emulator.counts[2] = int(20 * CPF)
    with pytest.raises(DeviceFault, match="overload"):
        sensor.read_N()
