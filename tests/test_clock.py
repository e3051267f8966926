"""The virtual clock only moves forward and only when someone waits."""

from hamr_bench.clock import RealClock, VirtualClock


def test_virtual_sleep_advances_exactly():
    clock = VirtualClock()
    clock.sleep(1.5)
    clock.sleep(0.25)
    assert clock.now_s() == 1.75


def test_virtual_clock_never_runs_backwards():
    clock = VirtualClock(10.0)
    clock.advance_to(5.0)
    clock.sleep(-1.0)
    assert clock.now_s() == 10.0


def test_real_clock_is_monotonic():
    clock = RealClock()
    a = clock.now_s()
    clock.sleep(0.001)
    assert clock.now_s() > a
