"""The simulated bench as a backend (`simulated-bench`): the `[sim]` table of a rig file -> a `SimBench`.

Command-line values (design, layers, effects, seed) override the file; everything else about the simulated rig
(where the sensor touches, sensor range, amplifier bandwidth) is in the `[sim]` table, and the simulated hardware
has the amplifier gain and monitor scale of `[amplifier]` and the camera optics of `[camera]` (checked already by
`hamr_bench.rig_file`). `SimTable`'s defaults are `BenchSettings`' own.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from hamr_bench.backends import BenchOptions
from hamr_bench.config import load_table, setting
from hamr_bench.rig_file import RigFile
from sim_devices.bench import BenchSettings, SimBench, parse_fault
from sim_devices.bench_effects import check_effects, check_shapes

_DEFAULTS = BenchSettings()


@dataclass(frozen=True)
class SimTable:
    """`[sim]` (simulated rigs only); docs/rig-file.md lists each key."""

    design: int = setting(_DEFAULTS.design, lo=1, hi=5)
    layers: int = setting(_DEFAULTS.layers, lo=1, hi=3)
    seed: int = _DEFAULTS.seed
    params: str = setting(_DEFAULTS.params_set, choices=("reported", "effective"))
    effects: dict[str, float] = field(default_factory=dict)
    effect_shapes: dict[str, dict[str, float]] = field(default_factory=dict)
    specimen_seed: int = setting(-1, lo=-1)  # -1: the specimen is the nominal one
    dynamics: bool = _DEFAULTS.dynamics
    model: dict[str, dict[str, Any]] = field(default_factory=dict)
    touch_stage_m: float = _DEFAULTS.touch_stage_m
    stage_travel_m: tuple[float, float] = _DEFAULTS.stage_limits_m
    stage_velocity_m_per_s: float = setting(_DEFAULTS.stage_velocity_m_per_s, positive=True)
    loadstar_capacity_kg: float = setting(_DEFAULTS.loadstar_capacity_kg, positive=True)
    loadstar_resolution_kg: float = setting(_DEFAULTS.loadstar_resolution_kg, positive=True)
    amplifier_bandwidth_Hz: float = setting(_DEFAULTS.amp_bandwidth_Hz, positive=True)
    noise: bool = _DEFAULTS.noise


def make_bench(rig_file: RigFile, options: BenchOptions) -> SimBench:
    place = rig_file.place("sim")
    sim = load_table(SimTable, rig_file.sim, place)
    file_effects = check_effects(sim.effects, place.key("effects"))
    check_effects(dict(options.effects), "--effects")
    camera = rig_file.camera
    settings = BenchSettings(
        fixture=options.fixture,
        design=options.design if options.design is not None else sim.design,
        layers=options.layers if options.layers is not None else sim.layers,
        params_set=sim.params,
        effects={**file_effects, **options.effects},
        effect_shapes=check_shapes(sim.effect_shapes, place.key("effect_shapes")),
        specimen_seed=None if sim.specimen_seed < 0 else sim.specimen_seed,
        dynamics=sim.dynamics,
        seed=options.seed if options.seed is not None else sim.seed,
        touch_stage_m=sim.touch_stage_m,
        stage_limits_m=sim.stage_travel_m,
        stage_velocity_m_per_s=sim.stage_velocity_m_per_s,
        loadstar_capacity_kg=sim.loadstar_capacity_kg,
        loadstar_resolution_kg=sim.loadstar_resolution_kg,
        amp_gain_V_per_V=rig_file.amplifier.gain_V_per_V,
        amp_monitor_scale_V_per_V=rig_file.amplifier.monitor_scale_V_per_V,
        amp_bandwidth_Hz=sim.amplifier_bandwidth_Hz,
        camera_frame_rate_Hz=camera.frame_rate_Hz if camera else _DEFAULTS.camera_frame_rate_Hz,
        metres_per_pixel=camera.metres_per_pixel if camera else _DEFAULTS.metres_per_pixel,
        noise=sim.noise,
        faults=tuple(parse_fault(f) for f in options.faults),
        model_overrides={**sim.model, **{k: dict(v) for k, v in options.model_overrides.items()}},
    )
    return SimBench(settings)
