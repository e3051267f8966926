"""The paper's characterisation tests as plans (one module each), the trapezoid drive, and the runner that carries
a plan out on a rig. `PROTOCOLS` maps each command-line name to its module."""

from __future__ import annotations

from hamr_bench.errors import ConfigError
from hamr_bench.protocols import actuator, blocked_force, free_displacement, sag_sweep, static
from hamr_bench.protocols.plan import ProtocolModule

PROTOCOLS: dict[str, ProtocolModule] = {
    m.NAME: m for m in (actuator, blocked_force, sag_sweep, free_displacement, static)
}


def get_protocol(name: str) -> ProtocolModule:
    try:
        return PROTOCOLS[name]
    except KeyError:
        raise ConfigError(f"unknown protocol {name!r} (known: {', '.join(PROTOCOLS)})") from None
