"""What data a lab needs before the self-check's hidden shifts and springs can be told from fabrication scatter.

A change common to every specimen (a fabrication shift, a series spring) shows only as a move of the specimens'
mean gains (log stroke, log stiffness), and the tolerance prior lets a batch's mean sit anywhere within its
spread. For each drawn effect this module computes, from the trial's seed alone (no simulation, no diagnosis), how
far the effect moves that mean in units of the prior's spread, summed over the layer counts a lab would test, and
whether that reaches the level the 2-dof-per-layer-count population test needs at the gap level (1e-3). An effect
below it cannot be named by any method that allows the tolerances, whatever the diagnosis does; so the share of
trials above it bounds the self-check's top-1 and multi-effect figures from above.

It is a property of the draw and the tolerance prior only (`selfcheck.gain_sigmas` is its one-layer-count,
drawn-design case); it shares nothing with the diagnosis's fits. Drive effects, creep and drift are counted as
detectable (an upper bound: a drift can still sit below the noise)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import stats

from hamr_bench.model import ActuatorParams

if TYPE_CHECKING:
    from sim_devices.scenarios import EffectTruth

GAP_ALPHA = 1e-3
SPRINGS = ("sensor_compliance", "base_compliance")


@dataclass(frozen=True)
class Design:
    """A lab's data design: the layer counts it tests and the specimens it builds of each."""

    layer_counts: tuple[int, ...]
    specimens: int

    @property
    def label(self) -> str:
        layers = "+".join(str(n) for n in self.layer_counts)
        return f"{self.specimens} specimens x layers {layers}"

    @property
    def threshold_sigmas(self) -> float:
        """The population test's level: sqrt of the chi^2 quantile for 2 dof per layer count."""
        return math.sqrt(float(stats.chi2.ppf(1.0 - GAP_ALPHA, 2 * len(self.layer_counts))))


@dataclass(frozen=True)
class DesignShare:
    """Of one design's draws: single-effect trials and multi-effect trials' effects, how many are effects on the
    common gains, and how many of those reach the detection level."""

    design: Design
    single: int
    single_gain: int
    single_gain_detectable: int
    multi_effects: int
    multi_gain: int
    multi_gain_detectable: int

    @property
    def single_ceiling(self) -> float:
        """The largest top-1 any honest method can reach on these single-effect trials."""
        missed = self.single_gain - self.single_gain_detectable
        return (self.single - missed) / self.single if self.single else float("nan")

    @property
    def multi_ceiling(self) -> float:
        missed = self.multi_gain - self.multi_gain_detectable
        return (self.multi_effects - missed) / self.multi_effects if self.multi_effects else float("nan")


def effect_sigmas(name: str, strength: float, shape: dict[str, float], design: Design) -> float | None:
    """How far a common effect moves the specimens' mean gains, in the tolerance prior's units, over every layer
    count of the design (the root of the summed noncentralities); None for an effect that is not a change of the
    common gains. The same effect on every layer count as the bench builds it: a fabrication parameter's
    fractional change, the same sensor's compliance (a larger share of a stiffer actuator's force), a clamp
    sized to lose the drawn share of each actuator's blocked force (`sim_devices.bench_physics`)."""
    from analysis.gap import tolerances as tol
    from analysis.gap.families import FABRICATION
    from hamr_bench.model import actuator_preset

    if name not in FABRICATION and name not in SPRINGS:
        return None
    total = 0.0
    for layers in design.layer_counts:
        a = actuator_preset(layers, "effective")
        w = tol.whitening(a)
        if name in FABRICATION:
            sig = tol.common_shift_sigmas(a, w, design.specimens, name, strength)
        else:
            loss = spring_loss(name, strength, shape, a)
            sig = math.sqrt(design.specimens) * float(np.linalg.norm(w @ np.array([0.0, math.log1p(-loss)])))
        total += sig * sig
    return math.sqrt(total)


def spring_loss(name: str, strength: float, shape: dict[str, float], a: ActuatorParams) -> float:
    """The blocked-force loss at 250 V a series spring causes on actuator `a` (its share of the tip's travel)."""
    from hamr_bench.model import actuator as act

    k = act.stiffness_N_per_m(a)
    if name == "sensor_compliance":
        ck = strength * k
        return ck / (1.0 + ck)
    from sim_devices.contact_statics import ActuatorStatics, make_clamp

    clamp = make_clamp(strength, a, shape)
    u = float(act.free_displacement_m(a, 250.0))
    f = float(ActuatorStatics(k, 1e12, clamp).contact_force_N(np.array([u]), np.array([0.0]))[0])
    return 1.0 - f / (k * u)


def gain_strength(e: EffectTruth) -> float | None:
    """The strength `effect_sigmas` reads: the generator's own for a clamp (its form is rebuilt per actuator),
    the candidate's unit otherwise (None where the units differ: not a change of the gains)."""
    return e.strength if e.name == "base_compliance" else e.library_strength


def design_shares(seeds: Sequence[int], designs: Sequence[Design], null_fraction: float = 0.15,
                  decoy_fraction: float = 0.1) -> list[DesignShare]:
    """Each design's `DesignShare` over the self-check's draws at these trial seeds (the effects and strengths
    as `selfcheck.draw_trial` draws them; the specimens a design builds do not change the draw)."""
    from analysis.gap.selfcheck import draw_trial

    counts = {d: [0, 0, 0, 0, 0, 0] for d in designs}
    for seed in seeds:
        sc = draw_trial(seed, null_fraction, decoy_fraction)
        if sc.kind not in ("single", "multi"):
            continue
        hidden = [e for e in sc.effects if not e.decoy and e.library_name]
        for d in designs:
            c = counts[d]
            offset = 0 if sc.kind == "single" else 3
            for e in hidden[:1] if sc.kind == "single" else hidden:
                strength = gain_strength(e)
                sig = None if strength is None else effect_sigmas(str(e.library_name), strength, e.shape, d)
                c[offset] += 1
                c[offset + 1] += sig is not None
                c[offset + 2] += sig is not None and sig >= d.threshold_sigmas
    return [DesignShare(d, *counts[d]) for d in designs]
