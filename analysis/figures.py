"""The paper's Figs. 7-10 from data and the fitted model, as PNG (matplotlib, Agg backend).

Points are per-condition means over repetitions with error bars of one standard deviation over repetitions; lines
are the fitted model's prediction of the SAME observation (analysis/observations.py), so a measured peak-to-peak
stroke is compared with a predicted peak-to-peak stroke. Where a design or actuator was not fitted, the line is the
model with the parameters the recording names, drawn dashed and labelled so.

- fig7_actuator.png: blocked force, free displacement (one-sided = stroke / 2), energy F_b delta and energy density
  vs bias voltage, per layer count; with the protocol's stiffness sweep in the data, a fifth panel: undriven tip
  force vs push past contact, loading and unloading (a gap between them is the stage's reversal error x k_act);
- fig8_blocked_force.png: leg force at zero sag vs voltage (a) and at 250 V vs sag (b), per design, with the 5.3 mN
  line the paper uses;
- fig9_free_displacement.png: leg stroke vs voltage per design;
- fig10_static.png: undriven leg force vs sag per design (static recordings are not used by the fit: this is a
  held-out check: only the run's own zero-sag offset is fitted, the transmission is the fitted one), with the
  quarter body weight 2.65 mN.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from analysis.dataset import Dataset, Observation
from analysis.fit import FitReport
from analysis.observations import LegObservations

TARGET_FORCE_N = 5.3e-3        # the paper's zero-sag target (half the 10.6 mN body weight)
QUARTER_WEIGHT_N = 2.65e-3
COLORS = {1: "tab:blue", 2: "tab:orange", 3: "tab:green", 4: "tab:red", 5: "tab:purple"}
MARKERS = {1: "o", 2: "s", 3: "^", 4: "D", 5: "v"}     # designs 4 and 5 nearly coincide: the marker tells them apart


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _points(obs: list[Observation], x: str, minus: dict[int, float] | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per condition, the mean x and the mean and SD of the values (over repetitions and specimens). A condition
    is a cluster of x values: voltages within 1 % of the cluster's first (a measured V_bias of 199.98 V and one of
    200.01 V are one condition), sags within 1 nm. `minus`: a value to subtract per run (its session's offset)."""
    tol_rel, tol_abs = (0.01, 1e-9) if x == "voltage_V" else (0.0, 1e-9)
    points = sorted((float(getattr(o, x)), o.value - (minus or {}).get(o.run, 0.0)) for o in obs)
    groups: list[list[tuple[float, float]]] = []
    for p in points:
        if groups and p[0] - groups[-1][0][0] <= tol_rel * abs(groups[-1][0][0]) + tol_abs:
            groups[-1].append(p)
        else:
            groups.append([p])
    xs = np.array([np.mean([p[0] for p in g]) for g in groups])
    mean = np.array([np.mean([p[1] for p in g]) for g in groups])
    sd = np.array([np.std([p[1] for p in g], ddof=1) if len(g) > 1 else 0.0 for g in groups])
    return xs, mean, sd


def _leg_model(dataset: Dataset, fit: FitReport, design: int, obs: list[Observation]):
    """(actuator, design params, fitted?) for drawing design `design`."""
    from analysis.fit import leg_actuator
    from hamr_bench.model import design_preset

    g = fit.designs.get(design) if fit else None
    if g is not None and g.model is not None:
        return g.model[0], g.model[1], True
    return leg_actuator(dataset, obs, obs[0].layers, None), design_preset(design), False


def _predict_leg(a, d, protocol: str, volts: np.ndarray, sags: np.ndarray, offset_m: float) -> np.ndarray:
    from hamr_bench.model import Powertrain

    return LegObservations([protocol] * volts.size, volts, sags).predict(Powertrain(a, d), offset_m)


def run_offsets(dataset: Dataset, fit: FitReport, group: str, key: int, obs: list[Observation]) -> dict[int, float]:
    """Per run of these observations, its session's fitted zero offset (0 where none was fitted)."""
    groups = fit.designs if group == "design" else fit.actuators
    g = groups.get(key) if fit else None
    out = {}
    offsets = g.derived.get("zero_offsets", {}) if g is not None else {}
    sessions, runs = offsets.get("sessions", {}), offsets.get("runs", {})
    for r in {o.run for o in obs}:
        info = dataset.runs[r].info
        key_s = info.session or f"run {r}"
        out[r] = float(sessions[key_s]) if key_s in sessions else float(runs.get(info.path, 0.0))
    return out


def run_offset(dataset: Dataset, fit: FitReport, group: str, key: int, obs: list[Observation]) -> float:
    """The fitted zero offset of the session(s) these observations come from (0 if not fitted; mean over them)."""
    values = list(run_offsets(dataset, fit, group, key, obs).values())
    return float(np.mean(values)) if values else 0.0


def static_offset(dataset: Dataset, a, d, obs: list[Observation]) -> float:
    """Static runs are held out of the fit: their own zero offset, fitted with the transmission fixed."""
    from analysis.observations import fit_zero_sag_offset_m
    from hamr_bench.model import Powertrain

    legs = LegObservations(["static"] * len(obs), [0.0] * len(obs), [o.sag_m for o in obs])
    return fit_zero_sag_offset_m(Powertrain(a, d), legs, np.array([o.value for o in obs]))


def fig7_actuator(dataset: Dataset, fit: FitReport, path: Path) -> Path | None:
    from analysis.fit import _actuator_base
    from hamr_bench.model import actuator as act

    obs = [o for o in dataset.observations if o.fixture == "actuator"]
    if not obs:
        return None
    plt = _plt()
    sweep = any(o.mode == "stiffness" for o in obs)
    if sweep:   # a fifth panel for the undriven stiffness sweep
        fig, grid = plt.subplots(2, 3, figsize=(15, 7.5))
        ax_f, ax_d, ax_k, ax_e, ax_ed, spare = grid.ravel()
        spare.set_visible(False)
        axes = np.array([ax_f, ax_d, ax_k, ax_e, ax_ed])
    else:
        fig, axes = plt.subplots(2, 2, figsize=(10, 7.5))
        ax_f, ax_d, ax_e, ax_ed = axes.ravel()
    for layers in sorted({o.layers for o in obs}):
        mine = [o for o in obs if o.layers == layers]
        color = COLORS[layers]
        g = fit.actuators.get(layers) if fit else None
        a = g.model if g is not None and g.model is not None else _actuator_base(dataset, mine, layers)
        style = "-" if g is not None else "--"
        vmax = max(o.voltage_V for o in mine)
        vv = np.linspace(0, vmax, 50)
        blocked = [o for o in mine if o.mode == "blocked"]
        free = [o for o in mine if o.mode == "free"]
        label = f"{layers}x CF"
        pre = run_offsets(dataset, fit, "actuator", layers, blocked + [o for o in mine if o.mode == "stiffness"])
        if blocked:
            x, m, sd = _points(blocked, "voltage_V", pre)
            ax_f.errorbar(x, m * 1e3, sd * 1e3, fmt="o", color=color, capsize=3, label=f"{label} data")
        ax_f.plot(vv, act.blocked_force_N(a, vv) * 1e3, style, color=color, label=f"{label} model")
        if free:
            x, m, sd = _points(free, "voltage_V")
            ax_d.errorbar(x, m / 2 * 1e6, sd / 2 * 1e6, fmt="o", color=color, capsize=3, label=f"{label} data")
        ax_d.plot(vv, act.free_displacement_m(a, vv) * 1e6, style, color=color, label=f"{label} model")
        if blocked and free:
            xb, mb, _ = _points(blocked, "voltage_V", pre)
            xf, mf, _ = _points(free, "voltage_V")
            pairs = [(i, int(np.argmin(np.abs(xf - v)))) for i, v in enumerate(xb)
                     if np.min(np.abs(xf - v)) <= 0.01 * abs(v)]
            common = np.array([xb[i] for i, _ in pairs])
            fb = np.array([mb[i] for i, _ in pairs])
            df = np.array([mf[j] for _, j in pairs]) / 2
            ax_e.plot(common, fb * df * 1e6, "o", color=color, label=f"{label} data")
            ax_ed.plot(common, fb * df / act.mass_kg(a), "o", color=color, label=f"{label} data")
        stiff = [o for o in mine if o.mode == "stiffness"]
        if stiff:
            # the same per-run tip-zero offset as the blocked rows (the sweep pushes from the same contact)
            for direction, face in (("up", color), ("down", "none")):
                rows = [o for o in stiff if o.direction == direction]
                if rows:
                    x, m, _ = _points(rows, "sag_m", pre)
                    ax_k.plot(x * 1e6, m * 1e3, "o", color=color, markerfacecolor=face,
                              label=f"{label} {'loading' if direction == 'up' else 'unloading'}")
            pp = np.linspace(0, max(o.sag_m for o in stiff), 20)
            ax_k.plot(pp * 1e6, act.stiffness_N_per_m(a) * pp * 1e3, style, color=color,
                      label=f"{label} model k = {act.stiffness_N_per_m(a):.0f} N/m")
        ax_e.plot(vv, act.energy_J(a, vv) * 1e6, style, color=color, label=f"{label} model")
        ax_ed.plot(vv, act.energy_density_J_per_kg(a, vv), style, color=color, label=f"{label} model")
    ax_f.set(xlabel="bias voltage (V)", ylabel="blocked force (mN)", title="(a) blocked force")
    ax_d.set(xlabel="bias voltage (V)", ylabel="free displacement, one-sided (um)", title="(b) free displacement")
    if sweep:
        ax_k.set(xlabel="push past contact (um)", ylabel="tip force, undriven (mN)",
                 title="(e) stiffness sweep (filled: loading, open: unloading)")
    ax_e.set(xlabel="bias voltage (V)", ylabel="energy F_b x delta (uJ)", title="(c) energy")
    ax_ed.set(xlabel="bias voltage (V)", ylabel="energy density (J/kg)", title="(d) energy density (model mass)")
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("Fig. 7: actuator characterisation (points: data, mean +- sd over repetitions and specimens; lines: "
                 "fitted model)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _designs(dataset: Dataset, protocol: str) -> list[int]:
    return sorted({o.design for o in dataset.observations if o.protocol == protocol and o.design is not None})


def fig8_blocked_force(dataset: Dataset, fit: FitReport, path: Path) -> Path | None:
    have_bf, have_ss = _designs(dataset, "blocked-force"), _designs(dataset, "sag-sweep")
    if not have_bf and not have_ss:
        return None
    plt = _plt()
    fig, (ax_a, ax_b) = plt.subplots(1, 2, figsize=(11, 4.5))
    for design in have_bf:
        obs = dataset.select(protocol="blocked-force", design=design)
        a, d, fitted = _leg_model(dataset, fit, design, obs)
        x, m, sd = _points(obs, "voltage_V")
        c = COLORS.get(design, "k")
        ax_a.errorbar(x, m * 1e3, sd * 1e3, fmt=MARKERS.get(design, "o"), mfc="none", color=c, capsize=3,
                      label=f"design {design}")
        vv = np.linspace(min(x.min(), 50.0), x.max(), 40)
        pre = run_offset(dataset, fit, "design", design, obs)
        ax_a.plot(vv, _predict_leg(a, d, "blocked-force", vv, np.zeros_like(vv), pre) * 1e3,
                  "-" if fitted else "--", color=c)
    for design in have_ss:
        obs = dataset.select(protocol="sag-sweep", design=design)
        a, d, fitted = _leg_model(dataset, fit, design, obs)
        x, m, sd = _points(obs, "sag_m")
        c = COLORS.get(design, "k")
        ax_b.errorbar(x * 1e3, m * 1e3, sd * 1e3, fmt=MARKERS.get(design, "o"), mfc="none", color=c, capsize=3,
                      label=f"design {design}")
        ss = np.linspace(0, x.max(), 40)
        v = obs[0].voltage_V
        pre = run_offset(dataset, fit, "design", design, obs)
        ax_b.plot(ss * 1e3, _predict_leg(a, d, "sag-sweep", np.full_like(ss, v), ss, pre) * 1e3,
                  "-" if fitted else "--", color=c)
    for ax in (ax_a, ax_b):
        ax.axhline(TARGET_FORCE_N * 1e3, color="grey", ls=":", label="5.3 mN")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    ax_a.set(xlabel="bias voltage (V)", ylabel="leg force (mN)", title="(a) zero sag")
    ax_b.set(xlabel="sag (mm)", ylabel="leg force (mN)", title="(b) vs sag at the sweep voltage")
    fig.suptitle("Fig. 8: blocked leg force (points: data +- sd; solid: fitted model; dashed: recording's model)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def fig9_free_displacement(dataset: Dataset, fit: FitReport, path: Path) -> Path | None:
    designs = _designs(dataset, "free-displacement")
    if not designs:
        return None
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for design in designs:
        obs = dataset.select(protocol="free-displacement", design=design)
        a, d, fitted = _leg_model(dataset, fit, design, obs)
        x, m, sd = _points(obs, "voltage_V")
        c = COLORS.get(design, "k")
        ax.errorbar(x, m * 1e3, sd * 1e3, fmt=MARKERS.get(design, "o"), mfc="none", color=c, capsize=3,
                    label=f"design {design}")
        vv = np.linspace(min(x.min(), 50.0), x.max(), 30)
        ax.plot(vv, _predict_leg(a, d, "free-displacement", vv, np.zeros_like(vv), 0.0) * 1e3,
                "-" if fitted else "--", color=c)
    ax.set(xlabel="bias voltage (V)", ylabel="leg stroke, peak-to-peak (mm)",
           title="Fig. 9: free leg displacement (points: data +- sd; lines: model)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def fig10_static(dataset: Dataset, fit: FitReport, path: Path) -> Path | None:
    designs = _designs(dataset, "static")
    if not designs:
        return None
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for design in designs:
        obs = dataset.select(protocol="static", design=design)
        a, d, fitted = _leg_model(dataset, fit, design, obs)
        c = COLORS.get(design, "k")
        marker = MARKERS.get(design, "o")
        for direction in ("up", "down"):
            mine = [o for o in obs if o.direction == direction]
            if mine:
                ax.plot([o.sag_m * 1e3 for o in mine], [o.value * 1e3 for o in mine], marker, color=c, ms=5,
                        mfc="none" if direction == "down" else c, alpha=0.8,
                        label=f"design {design}" if direction == "up" else None)
        ss = np.linspace(0, max(o.sag_m for o in obs), 40)
        pre = static_offset(dataset, a, d, obs)
        ax.plot(ss * 1e3, _predict_leg(a, d, "static", np.zeros_like(ss), ss, pre) * 1e3,
                "-" if fitted else "--", color=c)
    ax.axhline(QUARTER_WEIGHT_N * 1e3, color="grey", ls=":", label="quarter weight 2.65 mN")
    ax.set(xlabel="leg displacement (sag, mm)", ylabel="force (mN)",
           title="Fig. 10: static leg stiffness (filled: loading, open: unloading;\nlines: fitted model, held out)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def all_figures(dataset: Dataset, fit: FitReport, out_dir: Path) -> dict[str, Path]:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    made: dict[str, Any] = {}
    for name, fn in (("fig7_actuator", fig7_actuator), ("fig8_blocked_force", fig8_blocked_force),
                     ("fig9_free_displacement", fig9_free_displacement), ("fig10_static", fig10_static)):
        p = fn(dataset, fit, out_dir / f"{name}.png")
        if p is not None:
            made[name] = p
    return made
