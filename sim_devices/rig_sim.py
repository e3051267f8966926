"""The `[sim]` table of a rig file -> a `SimBench`. Command-line values (design, layers, effects, seed) override the
file; everything else about the simulated rig (where the sensor touches, sensor range, camera, amplifier gain) is
in the file."""

from __future__ import annotations

from typing import Any

from hamr_bench.config import Section, section
from hamr_bench.errors import ConfigError
from sim_devices.bench import BenchSettings, SimBench, parse_fault
from sim_devices.bench_effects import check_effects, check_shapes


def make_bench(
    doc: dict[str, Any], source: str, *, design: int | None, layers: int | None, effects: dict[str, float] | None,
    seed: int | None, fixture: str, faults: list[str] | None = None,
    model_overrides: dict[str, dict[str, Any]] | None = None,
) -> SimBench:
    sim = section(doc, source, "sim")
    amp = section(doc, source, "amplifier")
    camera = section(doc, source, "camera", required=False) or Section(source, "camera", {})
    defaults = BenchSettings()
    file_effects = check_effects(sim.table_of_floats("effects"), sim.where("effects"))
    check_effects(dict(effects or {}), "--effects")
    file_design = sim.int("design", defaults.design, lo=1, hi=5)
    file_layers = sim.int("layers", defaults.layers, lo=1, hi=3)
    file_seed = sim.int("seed", defaults.seed)
    shapes = _table_of_tables(sim, "effect_shapes")
    specimen_seed = sim.int("specimen_seed", -1, lo=-1)
    model = _table_of_tables(sim, "model")
    settings = BenchSettings(
        fixture=fixture,
        design=design if design is not None else file_design,
        layers=layers if layers is not None else file_layers,
        params_set=sim.str("params", defaults.params_set, choices=("reported", "effective")),
        effects={**file_effects, **(effects or {})},
        effect_shapes=check_shapes(shapes, sim.where("effect_shapes")),
        seed=seed if seed is not None else file_seed,
        specimen_seed=None if specimen_seed < 0 else specimen_seed,
        dynamics=sim.bool("dynamics", defaults.dynamics),
        touch_stage_m=sim.float("touch_stage_m", defaults.touch_stage_m),
        stage_limits_m=sim.float_pair("stage_travel_m", defaults.stage_limits_m),
        stage_velocity_m_per_s=sim.float("stage_velocity_m_per_s", defaults.stage_velocity_m_per_s, positive=True),
        loadstar_capacity_kg=sim.float("loadstar_capacity_kg", defaults.loadstar_capacity_kg, positive=True),
        loadstar_resolution_kg=sim.float("loadstar_resolution_kg", defaults.loadstar_resolution_kg, positive=True),
        # The simulated hardware has the gain, monitor scale and optics the rig file says the real one has.
        amp_gain_V_per_V=amp.float("gain_V_per_V", defaults.amp_gain_V_per_V, positive=True),
        amp_monitor_scale_V_per_V=amp.float("monitor_scale_V_per_V", defaults.amp_monitor_scale_V_per_V,
                                            positive=True),
        amp_bandwidth_Hz=sim.float("amplifier_bandwidth_Hz", defaults.amp_bandwidth_Hz, positive=True),
        camera_frame_rate_Hz=camera.float("frame_rate_Hz", defaults.camera_frame_rate_Hz, positive=True),
        metres_per_pixel=camera.float("metres_per_pixel", defaults.metres_per_pixel, positive=True),
        noise=sim.bool("noise", defaults.noise),
        faults=tuple(parse_fault(f) for f in (faults or [])),
        model_overrides={**model, **(model_overrides or {})},
    )
    sim.check_no_unknown_keys()
    return SimBench(settings)


def _table_of_tables(sim: Section, key: str) -> dict[str, dict]:
    """A `[sim]` key holding a table of tables (`effect_shapes`, `model`), each inner table checked by its user."""
    value = sim.data.get(key, {})
    sim.mark_used(key)
    if not isinstance(value, dict) or not all(isinstance(v, dict) for v in value.values()):
        raise ConfigError(f"{sim.where(key)}: expected a table of tables, e.g. {{ hysteresis = {{ r0 = 0.4 }} }}")
    return {k: dict(v) for k, v in value.items()}
