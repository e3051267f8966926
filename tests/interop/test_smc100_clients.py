"""Published third-party SMC100 clients, installed from PyPI (the `test` extra), drive the SMC100 emulator
through a
pseudo-terminal as they would a real controller: `labdevices` (Krauth; PyVISA-py, synchronous; its SMC100
class is
the one PyMoDAQ's Newport plugin ships) and `yaqd-newport` (the yaq daemon, asyncio). Neither was written
against
this emulator, so they check it independently of this project's own driver.

Where a client is wrong against the reference the test asserts the client's documented behaviour and says so;
the
emulator is not changed to suit it. Real time (a pty cannot run on a virtual clock): the stage is fast and
the reboot
short so the tests stay in seconds."""

from __future__ import annotations

import asyncio
import time

import pytest

from hamr_bench.clock import RealClock
from sim_devices.pty_server import PtyServer
from sim_devices.smc100_emulator import Smc100Emulator, Smc100Params
from sim_devices.smc100_protocol import Smc100Protocol

pytestmark = pytest.mark.slow

FAST = Smc100Params(velocity_m_per_s=8e-3, acceleration_m_per_s2=80e-3, home_settle_s=0.05, reset_time_s=0.3,
                    initial_position_m=0.4e-3)


@pytest.fixture
def served():
    """(emulator, pty path) on a real clock."""
    emulator = Smc100Emulator(RealClock(), FAST)
    server = PtyServer(Smc100Protocol(emulator)).start()
    yield emulator, server.path
    server.close()


def wait_for(condition, timeout_s: float = 5.0, poll_s: float = 0.02) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out waiting for the client"
        time.sleep(poll_s)


# -- labdevices
# ---------------------------------------------------------------------------------------------------
@pytest.fixture
def labdevices_smc100(served):
    newport = pytest.importorskip("labdevices.newport")
    emulator, path = served
    client = newport.SMC100(path, 1)
    client.initialize()  # opens ASRL<path>::INSTR with PyVISA-py (CR LF both ways, XON/XOFF) and reads ID?
    yield client, emulator
    client.close()


def test_labdevices_identify_home_move_stop(labdevices_smc100):
    client, emulator = labdevices_smc100
    assert client.idn == "UTS100PP"
    assert client.error_and_controller_status() == ("0000", "0A")
    client.home()  # OR
    wait_for(lambda: client.error_and_controller_status()[1] == "32")
    client.move_abs(2.0)
    assert client.is_moving
    client.wait_move_finish(0.02)
    assert client.error_and_controller_status() == ("0000", "33")
    assert float(client.query("TP")) == pytest.approx(2.0, abs=0.001)
    client.move_abs(20.0)
    time.sleep(0.3)
    client.write("ST")  # the class has no stop(); its own write() sends the reference's command
    wait_for(lambda: client.error_and_controller_status()[1] == "33")
    assert 2.5 < float(client.query("TP")) < 10.0


def test_labdevices_position_reads_the_target_not_the_position(labdevices_smc100):
    # The client's `position` sends PA?, which the reference defines as the TARGET position; the current
    # position
    # is TP. A client bug against the reference: while moving, `position` already reports where the stage is
    # going.
    client, emulator = labdevices_smc100
    client.home()
    wait_for(lambda: client.error_and_controller_status()[1] == "32")
    client.move_abs(10.0)
    assert client.position == pytest.approx(10.0, abs=0.001)
    assert float(client.query("TP")) < 9.0  # still on its way
    client.write("ST")


def test_labdevices_error_letter_and_text(labdevices_smc100):
    client, emulator = labdevices_smc100
    client.move_abs(1.0)  # NOT REFERENCED: refused
    letter = client.get_last_command_error()
    assert letter == "H"
    assert client.get_last_command_error() == "@"  # reading cleared it
    # The client's own table words the letters as the command pages' error lists do ("Execution not allowed
    # ...");
    # TB answers with the TE page's list ("Command not allowed ..."). Both name the same condition.
    assert client.error_code[letter] == "Execution not allowed in NOT REFERENCED state"
    assert client.query("TB" + letter) == "H Command not allowed in NOT REFERENCED state"


def test_labdevices_fault_and_disable_enable(labdevices_smc100):
    client, emulator = labdevices_smc100
    client.home()
    wait_for(lambda: client.error_and_controller_status()[1] == "32")
    client.write("MM0")
    assert client.error_and_controller_status() == ("0000", "3C")
    client.write("MM1")
    assert client.error_and_controller_status() == ("0000", "34")
    client.move_abs(20.0)
    wait_for(lambda: client.is_moving)  # the write is on its way through the pty: wait until PA has arrived
    emulator.faults.inject("following_error")
    assert client.error_and_controller_status() == ("0020", "3D")  # bit 5, DISABLE from MOVING
    assert client.error_and_controller_status() == ("0000", "3D")  # TS read and cleared the bit
    assert not client.is_moving


# -- yaqd-newport
# -------------------------------------------------------------------------------------------------
def run_yaqd(path: str, tmp_path, scenario) -> None:
    """Build the yaq daemon in-process (no TCP server: its methods are what the RPC would call) on a fresh
    event
    loop and run `scenario(daemon, emulator)` as a coroutine."""
    motor = pytest.importorskip("yaqd_newport._newport_motor")
    smc100 = pytest.importorskip("yaqd_newport._newport_smc100")

    async def main():
        motor.NewportMotor.serial_dispatchers.clear()  # one dispatcher per port, kept at class level
        config = smc100.NewportSMC100._parse_config({"stage": {"serial_port": path, "port": 0}}, "stage")
        daemon = smc100.NewportSMC100("stage", config, tmp_path / "config.toml")
        try:
            await scenario(daemon)
        finally:
            for task in list(daemon.tasks) + list(daemon._tasks):
                task.cancel()
            daemon._serial.port.close()
            for task in daemon._serial.tasks:
                task.cancel()
            await asyncio.sleep(0.05)

    asyncio.run(main())


async def until(condition, timeout_s: float = 15.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out waiting for the daemon"
        await asyncio.sleep(0.05)


@pytest.fixture
def yaq_env(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))  # the daemon's state file
    return tmp_path


def test_yaqd_homes_reads_limits_moves_and_stops(served, yaq_env):
    emulator, path = served

    async def scenario(daemon):
        # the daemon resets (RS), waits 5 s, homes (OR) and reads SL?/SR? on its own
        await until(lambda: not daemon._homing)
        assert daemon._state["hw_limits"] == [-50.0, 50.0]
        assert daemon._state["status"] == "READY from HOMING"
        daemon.set_position(3.0)
        await until(lambda: daemon._state["status"] == "MOVING")
        await until(lambda: not daemon.busy() and daemon._state["status"].startswith("READY"))
        assert daemon.get_position() == pytest.approx(3.0, abs=0.001)
        daemon.set_position(30.0)
        await until(lambda: daemon._state["status"] == "MOVING")
        daemon.set_position(4.0)  # while MOVING the daemon sends ST, then PA once READY
        await until(lambda: not daemon.busy() and daemon._state["status"].startswith("READY"), 10.0)
        assert daemon.get_position() == pytest.approx(4.0, abs=0.001)
        assert daemon._state["error_code"] == "0000"

    run_yaqd(path, yaq_env, scenario)


def test_yaqd_error_letter_fault_and_disable_enable(served, yaq_env, caplog):
    emulator, path = served

    async def scenario(daemon):
        await until(lambda: not daemon._homing)
        daemon.direct_serial_write(b"XX")  # sends 1XX then 1TE
        await until(lambda: "Unknown message code" in caplog.text, 5.0)
        daemon.direct_serial_write(b"MM0")
        await until(lambda: daemon._state["status"] == "DISABLE from READY", 5.0)
        daemon.clear_disable()  # MM1
        await until(lambda: daemon._state["status"] == "READY from DISABLE", 5.0)
        daemon.set_position(30.0)
        await until(lambda: daemon._state["status"] == "MOVING")
        emulator.faults.inject("following_error")
        # The daemon logs bit 5 (it calls it a motion time-out) and leaves the stage in DISABLE: the position
        # is
        # outside its tolerance of 0, so it does not send MM1.
        await until(lambda: daemon._state["status"] == "DISABLE from MOVING", 5.0)
        await until(lambda: "ERROR CODE: 0020" in caplog.text, 5.0)

    caplog.set_level("INFO")
    run_yaqd(path, yaq_env, scenario)
