"""The emulators on a real pseudo-terminal, as a person with a terminal program would use them: plain os.read
/ os.write of SMC100 commands, and `hamr-bench sim serve` as a subprocess (path on the first line, stops on
SIGTERM)."""

import os
import select
import signal
import subprocess
import sys
import time
import tty

import numpy as np
import pytest

from hamr_bench.clock import RealClock
from sim_devices.loadstar_emulator import LoadstarEmulator
from sim_devices.pty_server import PtyServer
from sim_devices.smc100_emulator import Smc100Emulator, Smc100Params
from sim_devices.smc100_protocol import Smc100Protocol


def open_terminal(path: str) -> int:
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    return fd


def type_line(fd: int, text: str, expect_reply: bool = True, timeout_s: float = 2.0) -> str:
    """Write one command (CR LF) and read one reply line, the way a terminal user sees it."""
    os.write(fd, text.encode() + b"\r\n")
    if not expect_reply:
        return ""
    data = b""
    deadline = time.monotonic() + timeout_s
    while not data.endswith(b"\r\n"):
        remaining = deadline - time.monotonic()
        assert remaining > 0, f"no reply to {text!r}; got {data!r}"
        readable, _, _ = select.select([fd], [], [], remaining)
        if readable:
            data += os.read(fd, 256)
    return data.decode().strip()


def wait_state(fd: int, codes: tuple[str, ...], timeout_s: float = 5.0) -> str:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        reply = type_line(fd, "1TS")
        if reply[-2:] in codes:
            return reply
        time.sleep(0.02)
    raise AssertionError(f"state never reached {codes}")


def test_home_and_move_by_typing_raw_commands():
    params = Smc100Params(velocity_m_per_s=8e-3, acceleration_m_per_s2=80e-3, home_settle_s=0.05, step_m=1e-7)
    emulator = Smc100Emulator(RealClock(), params)
    with PtyServer(Smc100Protocol(emulator)) as server:
        fd = open_terminal(server.path)
        try:
            assert type_line(fd, "1TS") == "1TS00000A"
            type_line(fd, "1OR", expect_reply=False)
            assert type_line(fd, "1TE") == "1TE@"
            assert wait_state(fd, ("32",)) == "1TS000032"
            type_line(fd, "1PA2", expect_reply=False)
            assert type_line(fd, "1TS") == "1TS000028"
            assert wait_state(fd, ("33",)) == "1TS000033"
            assert type_line(fd, "1TP") == "1TP2"
            type_line(fd, "1pr-0.5", expect_reply=False)  # lower case works too
            wait_state(fd, ("33",))
            assert type_line(fd, "1TP?") == "1TP1.5"
            type_line(fd, "1PA99", expect_reply=False)
            assert type_line(fd, "1TE") == "1TEG"
        finally:
            os.close(fd)


def test_server_survives_a_client_closing_and_reopening():
    emulator = LoadstarEmulator(RealClock(), lambda t: 0.0, np.random.default_rng(0))
    with PtyServer(emulator) as server:
        for _ in range(2):
            fd = open_terminal(server.path)
            os.write(fd, b"\r")
            readable, _, _ = select.select([fd], [], [], 2.0)
            assert readable and os.read(fd, 64) == b"A\r\n"
            os.close(fd)


@pytest.mark.parametrize(
    "device,command,reply", [("smc100", b"1TS\r\n", b"1TS00000A\r\n"), ("loadstar", b"\r", b"A\r\n")]
)
def test_sim_serve_prints_the_path_first_and_stops_on_sigterm(device, command, reply):
    proc = subprocess.Popen(
        [sys.executable, "-m", "hamr_bench", "sim", "serve", device],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        path = proc.stdout.readline().strip()
        assert path.startswith("/dev/")
        fd = open_terminal(path)
        try:
            os.write(fd, command)
            data = b""
            deadline = time.monotonic() + 5.0
            while not data.endswith(b"\n") and time.monotonic() < deadline:
                readable, _, _ = select.select([fd], [], [], 0.5)
                if readable:
                    data += os.read(fd, 64)
            assert data == reply
        finally:
            os.close(fd)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=5) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_sim_serve_rejects_unknown_effects_and_faults_in_one_line():
    for extra in (["--effects", "stage_backlash=abc"], ["--fault", "overload"]):
        out = subprocess.run(
            [sys.executable, "-m", "hamr_bench", "sim", "serve", "smc100", *extra],
            capture_output=True,
            text=True,
            timeout=20,
        )
        assert out.returncode == 2
        assert out.stderr.startswith("hamr-bench: error: ") and out.stderr.count("\n") == 1
        assert out.stdout == ""
