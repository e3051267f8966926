"""The simulated bench's mechanics against estimates made here by other routes: the Euler-Bernoulli first mode of
a uniform cantilever, the leg's stiffness from the model's static solver, the Nano17's published resonance, an
exact quadrature of the sensed force, a root finder on the clamp's force balance, a direct quadrature of the
lengthened tapered beam, the crank's torque balance with Coulomb friction, and a powertrain built afresh at the
relaxed bias."""

import math

from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import brentq

from hamr_bench.model import actuator as act
from hamr_bench.model import actuator_preset, powertrain
from hamr_bench.model import transmission as tr
from hamr_bench.model.powertrain import Powertrain
from sim_devices.bench import BenchSettings, SimBench
from sim_devices.bench_effects import ClampLineMoved
from sim_devices.bench_physics import (LEG_MASS_AT_FOOT_KG, NANO17_RESONANCE_HZ, actuator_tip_mass_kg,
                                       tip_compliance_m_per_N)
from sim_devices.contact_statics import ActuatorStatics, make_clamp

GAIN = 35.0


def _bench(**kw) -> SimBench:
    return SimBench(BenchSettings(noise=False, **kw))


def _set(bench: SimBench, bias_V: float, drive_V: float) -> None:
    bench.daq.write_ao_scalar("ao0", bias_V / GAIN)
    bench.daq.write_ao_scalar("ao1", drive_V / GAIN)


def _ringing(t: np.ndarray, x: np.ndarray) -> tuple[float, float]:
    """(damped frequency, damping ratio) of a decaying oscillation about its final value: zero crossings and the
    logarithmic decrement of successive peaks."""
    y = x - x[-1]
    crossings = t[:-1][np.sign(y[:-1]) != np.sign(y[1:])]
    period = 2.0 * float(np.median(np.diff(crossings[:12])))
    peaks = []
    for a, b in zip(crossings[:-1], crossings[1:], strict=True):
        sel = (t > a) & (t < b)
        peaks.append(float(np.max(np.abs(y[sel]))))
    delta = float(np.median(np.log(np.array(peaks[:8:2]) / np.array(peaks[2:10:2]))))   # one period apart
    zeta = delta / math.sqrt(4 * math.pi ** 2 + delta ** 2)
    return 1.0 / period, zeta


def test_bare_actuator_rings_at_the_euler_bernoulli_first_mode():
    """A uniform-width actuator without extension (width ratio 1, length ratio 0), free: the bench's tip rings at
    sqrt(k/m_eff) with Rayleigh's m_eff; the exact first mode of a uniform cantilever is
    (1.8751^2 / 2 pi) sqrt(EI / (rho A l^4)), which Rayleigh's quotient exceeds by ~1.5 %."""
    overrides = {"actuator": {"width_ratio": 1.0, "length_ratio": 0.0}}
    bench = _bench(fixture="actuator", model_overrides=overrides)
    try:
        a = bench.actuator
        _set(bench, 100.0, 50.0)
        bench.clock.sleep(0.2)
        t0 = bench.clock.now_s()
        bench.daq.write_ao_scalar("ao1", 60.0 / GAIN)
        t = t0 + 2e-3 + np.arange(0, 6e-3, 2e-6)   # after the amplifier's lag has passed
        f_d, zeta = _ringing(t, bench.plant.positions_m(t))
    finally:
        bench.close()
    f_n = f_d / math.sqrt(1 - zeta ** 2)
    ei = act.bending_rigidity_per_width(a) * a.width_nom_m
    mu = (2 * a.pzt_thickness_m * act.RHO_PZT_KG_PER_M3 + a.cf_thickness_m * act.RHO_CF_KG_PER_M3) * a.width_nom_m
    euler_bernoulli = 1.875104 ** 2 / (2 * math.pi) * math.sqrt(ei / (mu * a.length_m ** 4))
    assert 1.0 <= f_n / euler_bernoulli < 1.02
    # the tip damping of the public HAMR-VI model (0.02 N s/m) on this mass and stiffness
    m = actuator_tip_mass_kg(a)
    assert zeta == pytest.approx(0.02 / (2 * math.sqrt(act.stiffness_N_per_m(a) * m)), rel=0.05)


def test_uniform_cantilever_effective_mass_is_33_140():
    a = act.with_changes(actuator_preset(2, "effective"), width_ratio=1.0, length_ratio=0.0)
    mass = (2 * a.pzt_thickness_m * act.RHO_PZT_KG_PER_M3 + a.cf_thickness_m * act.RHO_CF_KG_PER_M3) \
        * a.length_m * a.width_nom_m
    assert actuator_tip_mass_kg(a) == pytest.approx(33 / 140 * mass, rel=1e-5)


def test_tip_compliance_quadrature_is_the_models_closed_form():
    for layers in (1, 2, 3):
        a = actuator_preset(layers, "effective")
        assert tip_compliance_m_per_N(a) == pytest.approx(1.0 / act.stiffness_N_per_m(a), rel=2e-4)


def test_loaded_leg_rings_at_the_static_solvers_stiffness():
    """Design 4, free, a small drive step about the undriven neutral: the foot rings at sqrt(k / m), k the leg's
    stiffness from the model's static solver (sag under a small load), m the leg's own mass at the foot plus the
    actuator's tip mass seen through the transmission ratio."""
    bench = _bench(fixture="leg", design=4)
    try:
        _set(bench, 100.0, 50.0)
        bench.clock.sleep(0.3)
        t0 = bench.clock.now_s()
        bench.daq.write_ao_scalar("ao1", 50.5 / GAIN)
        t = t0 + 3e-3 + np.arange(0, 40e-3, 1e-5)
        f_d, zeta = _ringing(t, bench.plant.positions_m(t))
    finally:
        bench.close()
    p = powertrain(4)
    load = 2e-5
    k = load / float(p.static_displacement_m(load))
    m = LEG_MASS_AT_FOOT_KG + actuator_tip_mass_kg(p.actuator) / float(p.transmission_ratio(0.0)) ** 2
    expected = math.sqrt(k / m) / (2 * math.pi)
    assert f_d / math.sqrt(1 - zeta ** 2) == pytest.approx(expected, rel=0.01)
    assert zeta == pytest.approx(0.1, rel=0.05)


def test_tip_on_the_nano17_rings_at_the_sensors_resonance():
    """In contact the tip moves with the sensor's element: the pair rings near the Nano17's published resonance
    (its element is 5 g against the tip's 12 mg and 1.1e7 N/m against the tip's 2e3 N/m)."""
    bench = _bench(fixture="actuator")
    try:
        bench.stage.home(bench.clock.now_s())
        bench.clock.sleep(2.0)
        bench.stage.move_absolute(bench.clock.now_s(), bench.settings.touch_stage_m)
        bench.clock.sleep(1.0)
        _set(bench, 100.0, 50.0)
        bench.clock.sleep(0.3)
        t0 = bench.clock.now_s()
        bench.daq.write_ao_scalar("ao1", 90.0 / GAIN)
        t = t0 + 1e-3 + np.arange(0, 4e-3, 2e-7)
        force = bench.contact_forces_N(t)
    finally:
        bench.close()
    assert np.all(force > 0)
    f_d, _ = _ringing(t, force)
    assert f_d == pytest.approx(NANO17_RESONANCE_HZ, rel=0.01)


def test_load_cell_reads_the_exact_average_over_its_conversion_period():
    bench = _bench(fixture="leg", design=4)
    try:
        bench.stage.home(bench.clock.now_s())
        bench.clock.sleep(2.0)
        bench.stage.move_absolute(bench.clock.now_s(), bench.settings.touch_stage_m + 0.5e-3)
        bench.clock.sleep(1.0)
        bench.daq.write_ao_scalar("ao0", 200.0 / GAIN)
        t0 = bench.clock.now_s()
        bench.daq.write_ao_waveform("ao1", np.linspace(0, 200.0, 50) / GAIN, 1000.0)   # a 50 ms ramp
        window = bench.conversion_s
        for end in t0 + np.array([0.012, 0.031, 0.052, 0.07]):
            fine = np.linspace(end - window, end, 40001)
            average = np.trapezoid(bench.contact_forces_N(fine), fine) / window
            assert bench.contact_force_N(end) == pytest.approx(average, rel=1e-6, abs=1e-10)
    finally:
        bench.close()


@pytest.mark.parametrize("shape", [{"form": 0.0, "hardening": 2.5, "pull_ratio": 1.0},
                                   {"form": 1.0, "pull_ratio": 0.4}])
def test_clamp_force_balance_against_a_root_finder(shape):
    a = actuator_preset(2, "effective")
    clamp = make_clamp(0.2, a, shape)
    k, ks = act.stiffness_N_per_m(a), 2e4
    statics = ActuatorStatics(k, ks, clamp)

    def give(f):   # the clamp's deflection by an independent cubic root (numpy's companion matrix)
        k0, k3 = (clamp.k0, clamp.k3) if f >= 0 else (clamp.k0 * clamp.pull_ratio, clamp.k3 * clamp.pull_ratio)
        roots = np.roots([k3, 0.0, k0, -f]) if k3 else np.array([f / k0])
        return float(np.real(roots[np.argmin(np.abs(np.imag(roots)))]))

    for u, q in ((1e-4, 0.0), (4e-5, 1e-5), (-3e-5, 0.0)):
        expected = brentq(lambda f, u=u, q=q: f * (1 + k / ks) + k * give(f) - k * (u - q), -1.0, 1.0, xtol=1e-15)
        assert statics.contact_force_N(np.array([u]), np.array([q]))[0] == pytest.approx(expected, rel=1e-9)
    # the strength: the blocked force at 250 V lost by the fraction asked (rigid sensor)
    u250 = float(act.free_displacement_m(a, 250.0))
    rigid = ActuatorStatics(k, 1e15, clamp).contact_force_N(np.array([u250]), np.array([0.0]))[0]
    assert rigid == pytest.approx(0.8 * k * u250, rel=1e-9)


def test_grounding_lengthening_is_the_tapered_beam_clamped_further_back():
    """The clamp line moved back by s l: integrate the curvature of the same laminate over the longer beam (its
    taper continued to the new clamp, the extension unchanged) and compare with the model's closed-form stiffness
    of the changed parameters."""
    a = actuator_preset(2, "effective")
    s = 0.09
    b = ClampLineMoved(strength=s).actuator_params(a)
    w_base, w_tip = a.width_ratio * a.width_nom_m, (2 - a.width_ratio) * a.width_nom_m
    length = a.length_m * (1 + s)
    ext = a.length_ratio * a.length_m
    x = np.linspace(0.0, length, 200001)              # from the new clamp to the end of the PZT
    width = w_tip + (w_base - w_tip) / a.length_m * (length - x)
    curvature = (length + ext - x) / (act.bending_rigidity_per_width(a) * width)
    slope = np.concatenate([[0.0], np.cumsum(0.5 * (curvature[1:] + curvature[:-1]) * np.diff(x))])
    deflection = np.concatenate([[0.0], np.cumsum(0.5 * (slope[1:] + slope[:-1]) * np.diff(x))])
    compliance = deflection[-1] + slope[-1] * ext
    assert 1.0 / act.stiffness_N_per_m(b) == pytest.approx(compliance, rel=1e-4)
    assert b.length_ratio * b.length_m == pytest.approx(ext, rel=1e-12)


def _frictionless_and_tan_alpha(p, sag_m):
    h = np.array([sag_m])
    th = p.theta_at_height(h)
    g = p.geometry
    return float(p.foot_force_N(0.0, 0.0, h)[0]), math.tan(g.leg_angle0_rad + float(th[0]) - g.theta_fab_rad)


def test_foot_friction_while_the_stage_slides_the_foot_is_the_crank_torque_balance():
    """Undriven design 4 pushed up by the stage (the foot slides along the sensor): the crank's balance
    U' = N h' + T x' with T = -mu N sign(x-velocity) gives N = N0 / (1 - mu tan(alpha)) while loading and
    N0 / (1 + mu tan(alpha)) while unloading (N0 the frictionless force from the model, alpha the leg's angle)."""
    mu = 0.25
    bench = _bench(fixture="leg", design=4, effects={"foot_friction": mu})
    try:
        touch = bench.settings.touch_stage_m
        bench.stage.home(bench.clock.now_s())
        bench.clock.sleep(2.0)
        bench.stage.move_absolute(bench.clock.now_s(), touch + 0.2e-3)
        bench.clock.sleep(1.0)
        t0 = bench.clock.now_s()
        bench.stage.move_absolute(t0, touch + 1.2e-3)            # loading: 1 mm at 5 mm/s
        t_load = t0 + 0.1
        sag_load = float(bench.stage.position_m(t_load)) - touch
        n_load = float(bench.contact_forces_N(np.array([t_load]))[0])
        bench.clock.sleep(1.0)
        t1 = bench.clock.now_s()
        bench.stage.move_absolute(t1, touch + 0.2e-3)            # unloading
        t_unload = t1 + 0.1
        sag_unload = float(bench.stage.position_m(t_unload)) - touch
        n_unload = float(bench.contact_forces_N(np.array([t_unload]))[0])
        # held still after unloading: the tangential force stays what the slide left (within the cone)
        bench.clock.sleep(1.0)
        n_held = float(bench.contact_forces_N(np.array([bench.clock.now_s()]))[0])
    finally:
        bench.close()
    p = powertrain(4)
    n0, r = _frictionless_and_tan_alpha(p, sag_load)
    assert n_load == pytest.approx(n0 / (1 - mu * r), rel=1e-3)
    n0, r = _frictionless_and_tan_alpha(p, sag_unload)
    assert n_unload == pytest.approx(n0 / (1 + mu * r), rel=1e-3)
    n0_end, r_end = _frictionless_and_tan_alpha(p, 0.2e-3)
    assert n_held == pytest.approx(n0_end / (1 + mu * r_end), rel=1e-3)
    assert n0 / (1 - mu * r) > 1.5 * n0 / (1 + mu * r)   # the loop is wide: friction matters at the foot


def test_bias_relaxation_follows_a_powertrain_built_at_that_bias():
    """At a fixed sag the undriven foot's force follows the relaxing bias: compared with the model built afresh
    at b(t) (no tables), its heights referred to the neutral the bench started from."""
    from sim_devices.bench_physics import BIAS_SHAPE, BiasRelaxation

    strength = -30e-6
    shape = {"run_fraction": 0.5, "tau1_s": 2.0, "tau2_s": 20.0, "weight1": 0.5}
    bench = _bench(fixture="leg", design=4, effects={"bias_error": strength},
                   effect_shapes={"bias_error": shape})
    try:
        touch = bench.settings.touch_stage_m
        bench.stage.home(bench.clock.now_s())
        bench.clock.sleep(2.0)
        sag = 0.6e-3
        bench.stage.move_absolute(bench.clock.now_s(), touch + sag)
        bench.clock.sleep(1.0)
        times = np.array([4.0, 10.0, 40.0])
        measured = []
        for t in times:   # asked as they come (the bench keeps the last 20 s)
            bench.clock.sleep(max(0.0, t - bench.clock.now_s()) + 0.01)
            measured.append(float(bench.contact_forces_N(np.array([t]))[0]))
    finally:
        bench.close()
    relax = BiasRelaxation(strength, **{**BIAS_SHAPE, **shape})
    base = powertrain(4)

    def at_bias(b):
        return Powertrain(base.actuator, replace(base.design, bias_m=b))

    p0 = at_bias(base.design.bias_m + float(relax.offset_m(0.0)))
    h0 = float(tr.foot_height_fab_m(p0.geometry, p0.theta_neutral_rad))
    for t, got in zip(times, measured, strict=True):
        p = at_bias(base.design.bias_m + float(relax.offset_m(t)))
        shift = float(tr.foot_height_fab_m(p.geometry, p.theta_neutral_rad)) - h0
        expected = float(p.foot_force_N(0.0, 0.0, sag - shift))
        assert got == pytest.approx(expected, rel=2e-3)
    assert abs(measured[-1] - measured[0]) > 0.05 * measured[0]   # the relaxation shows within the run
