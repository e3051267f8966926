"""The gap report (`hamr-bench gap ... --report DIR`): the residual map before / after the named effects, overlays
of data, nominal and final model per experiment, and the waterfall (held-out gap after each named effect, with
its interval), as PNGs with a Markdown summary."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from analysis.gap.results import best_text, closed_share_text, floor_text


def specimen_label(group: str) -> str:
    """A specimen group's key (`layers=2|specimen=B`) as a table cell: `2 layers, specimen B`, or `2 layers` for a
    recording that names no specimen ('|' escaped: it would split the cell)."""
    parts: dict[str, str] = {}
    for item in group.split("|"):
        key, _, value = item.partition("=")
        parts[key] = value
    layers, specimen = parts.get("layers", ""), parts.get("specimen", "")
    if not layers or set(parts) - {"layers", "specimen"}:
        label = group
    else:
        label = f"{layers} layer{'' if layers == '1' else 's'}" + (f", specimen {specimen}" if specimen else "")
    return label.replace("|", "\\|")


def _group_label(problem, i: int) -> str:
    r = problem.rows[i]
    run = problem.data.runs[r.run]
    who = f"design {run.design}" if run.fixture == "leg" else f"{run.layers}-layer"
    return f"{r.protocol} {r.mode} ({who})".replace("  ", " ")


def residual_map_png(problem, z_before, z_after, label_after: str, path: Path) -> None:
    """RMS residual over noise by run x (phase / sweep direction), nominal vs with the winner, log colour scale
    from the noise floor (1) up; the per-condition detail is in the Markdown table."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    groups, cols = [], []
    for i, r in enumerate(problem.rows):
        g, c = _group_label(problem, i), f"{r.phase}/{r.direction}"
        if g not in groups:
            groups.append(g)
        if c not in cols:
            cols.append(c)
    fig, axes = plt.subplots(1, 2, figsize=(13, 0.32 * len(groups) + 2.5), sharey=True)
    grids = []
    for z in (z_before, z_after):
        acc = np.zeros((len(groups), len(cols)))
        n = np.zeros_like(acc)
        for i, r in enumerate(problem.rows):
            a, b = groups.index(_group_label(problem, i)), cols.index(f"{r.phase}/{r.direction}")
            acc[a, b] += z[i] ** 2
            n[a, b] += 1
        with np.errstate(invalid="ignore"):
            grids.append(np.sqrt(acc / n))
    vmax = max(10.0, float(np.nanmax(grids[0])))
    for ax, grid, title in ((axes[0], grids[0], "nominal model"), (axes[1], grids[1], label_after)):
        im = ax.imshow(np.clip(grid, 0.3, None), aspect="auto", cmap="magma_r", norm=LogNorm(vmin=0.3, vmax=vmax))
        ax.set_xticks(range(len(cols)), cols, rotation=40, ha="right", fontsize=8)
        ax.set_title(f"RMS residual / noise: {title}", fontsize=10)
    axes[0].set_yticks(range(len(groups)), groups, fontsize=8)
    fig.colorbar(im, ax=axes, shrink=0.8, label="RMS (measured - model) / standard error (1 = noise floor)")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def overlays_png(problem, fit0: np.ndarray, fit1: np.ndarray, label: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = _overlay_panels(problem)
    n = len(panels)
    if n == 0:
        fig, ax = plt.subplots(figsize=(5, 2))
        ax.text(0.5, 0.5, "no settled rows (high dwell, hold) to overlay", ha="center", va="center")
        ax.axis("off")
        fig.savefig(path, dpi=110)
        plt.close(fig)
        return
    cols = min(n, 3)
    rows_n = int(np.ceil(n / cols))
    # under each overlay its residuals: a gap of a few noise widths is invisible on the full scale of the data
    fig, axes = plt.subplots(2 * rows_n, cols, figsize=(5 * cols, 5.4 * rows_n), squeeze=False,
                             gridspec_kw={"height_ratios": [3, 1.6] * rows_n})
    for j, ((k, mode), idx) in enumerate(panels.items()):
        ax, res = axes[2 * (j // cols), j % cols], axes[2 * (j // cols) + 1, j % cols]
        run = problem.data.runs[k]
        rows = [problem.rows[i] for i in idx]
        # against sag where the rows sweep it (sag sweeps, static loads, an actuator's stiffness steps at 0 V)
        use_sag = run.protocol in ("sag-sweep", "static") or len({round(r.voltage_V) for r in rows}) == 1
        x = np.array([r.sag_m * 1e3 if use_sag else r.voltage_V for r in rows])
        scale = 1e3 if rows[0].quantity == "force_N" else 1e6
        unit = "mN" if rows[0].quantity == "force_N" else "um"
        order = np.argsort(x, kind="stable")
        y, err = problem.y[idx] * scale, 2 * problem.sigma[idx] * scale
        ax.errorbar(x, y, yerr=err, fmt="o", ms=3, color="k", label="measured (+-2 se)")
        res.axhline(0.0, color="k", lw=0.8)
        nudge = 0.01 * (np.ptp(x) or 1.0)     # the two models' residuals side by side, not on top of each other
        for side, (fit, style, name) in zip((-1, 1), ((fit0, "x--", "nominal"), (fit1, "+-", label)), strict=True):
            ax.plot(x[order], fit[idx][order] * scale, style, ms=6, label=name)
            res.errorbar(x + side * nudge, y - fit[idx] * scale, yerr=err, fmt=style[0], ms=5, capsize=2)
        res.set_xlabel("sag (mm)" if use_sag else "bias voltage (V)")
        ax.set_ylabel(f"{rows[0].quantity.split('_')[0]} ({unit})")
        res.set_ylabel(f"measured - model ({unit})", fontsize=8)
        who = f"design {run.design}" if run.fixture == "leg" else f"{run.layers}-layer actuator"
        who += f", specimen {run.specimen}" if run.specimen else ""
        ax.set_title(f"{run.protocol} {mode} ({who})".replace("  ", " "), fontsize=9)
        ax.legend(fontsize=7)
    for j in range(n, rows_n * cols):
        axes[2 * (j // cols), j % cols].axis("off")
        axes[2 * (j // cols) + 1, j % cols].axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _bar_label(step: dict[str, Any]) -> str:
    """A waterfall bar's effect, with its ambiguous set and the effect it entered with (neither passed alone)."""
    label = f"+ {step['added']}"
    if step["ambiguous_with"]:
        label += f"\n(or {', '.join(step['ambiguous_with'])})"
    if step.get("joint_with"):
        label += f"\n(entered with {', '.join(step['joint_with'])})"
    return label


def waterfall_png(result: dict[str, Any], path: Path) -> None:
    """Held-out RMS gap (noise units) of the nominal model and after each named effect, with 95 % bootstrap
    intervals; the noise floor (1) as a line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker as mticker

    steps = result["waterfall"]
    labels = ["nominal"] + [_bar_label(w) for w in steps[1:]]
    y = np.array([w["heldout_rms"] for w in steps])
    lo = y - np.array([w["heldout_rms_ci95"][0] for w in steps])
    hi = np.array([w["heldout_rms_ci95"][1] for w in steps]) - y
    verdict = {e["effect"]: e["verdict"] for e in result["named"]}
    colours = ["tab:gray"] + ["tab:green" if verdict.get(w["added"]) == "attributed" else "tab:orange"
                              for w in steps[1:]]
    fig, ax = plt.subplots(figsize=(1.8 * len(steps) + 3, 4))
    ax.bar(range(len(steps)), y, yerr=[np.maximum(lo, 0), np.maximum(hi, 0)], color=colours, capsize=4)
    ax.axhline(1.0, color="k", ls="--", lw=1, label="noise floor")
    ax.set_xticks(range(len(steps)), labels, fontsize=8)
    ax.set_yscale("log")
    # plain figures on the log axis (1.2, not 1.2 x 10^0); the minor ticks labelled only within one decade,
    # where matplotlib would otherwise label them in powers of ten (most gaps read are between 1 and 2)
    ax.yaxis.set_major_formatter(mticker.FormatStrFormatter("%.3g"))
    low, high = ax.get_ylim()
    if high / low < 10:
        ax.yaxis.set_minor_formatter(mticker.FormatStrFormatter("%.3g"))
    ax.set_ylabel("held-out RMS gap (residual / standard error)")
    ax.set_title("held-out gap after each named effect\n(green: attributed, orange: ambiguous or partial)",
                 fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _overlay_panels(problem) -> dict[tuple[int, str], list[int]]:
    """(first run's index, mode) -> the indices of the rows one overlay panel shows: each run's settled rows (the high
    dwell's late part, an undriven hold). An actuator specimen's runs share a panel (an imported trace holds one
    bias voltage per file, so alone each would be one point); a leg run sweeps sag within itself and keeps its own."""
    panels: dict[tuple[int, str], list[int]] = {}
    first: dict[tuple, int] = {}
    for i, r in enumerate(problem.rows):
        if r.phase not in ("high_late", "hold"):
            continue
        run = problem.data.runs[r.run]
        own = run.fixture == "leg" or run.protocol in ("sag-sweep", "static")
        key = (run.index,) if own else (run.protocol, run.fixture, run.layers, run.specimen, run.session)
        panels.setdefault((first.setdefault(key, run.index), r.mode), []).append(i)
    return panels


def write_report(diagnosis: Any, result: dict[str, Any], out_dir: Path) -> Path:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    problem = diagnosis.fits.problem
    nominal, final = diagnosis.fits.nominal, diagnosis.fits.final
    fit0 = problem.model(nominal.layout, nominal.x)
    fit1 = problem.model(final.layout, final.x)
    label = " + ".join(e["effect"] for e in result["named"]) or "no effect named"
    residual_map_png(problem, nominal.z, final.z, label, out_dir / "residual_map.png")
    overlays_png(problem, fit0, fit1, label, out_dir / "overlays.png")
    waterfall_png(result, out_dir / "waterfall.png")
    nominal_lof = result["nominal_lack_of_fit"]
    lines = ["# Sim-to-real gap diagnosis", "",
             f"Recordings: {', '.join(sorted({Path(r.path).name for r in problem.data.runs}))}.",
             f"Residuals are against the nominal model ({result.get('nominal_source', 'presets')}) with each "
             f"specimen fitted within its fabrication tolerances; held-out figures in {result['heldout_units']}.",
             "", "## Where", "",
             f"Gap above the noise floor: **{'yes' if result['gap_above_noise'] else 'no'}** (lack-of-fit F test "
             f"p = {nominal_lof['p_value']:.3g}; RMS residual {nominal_lof['z_rms']:.2f} x the pure-error standard "
             "error).", "", "![residual map](residual_map.png)", "",
             "| protocol | condition | RMS gap | noise floor | p (lack of fit) |", "|---|---|---|---|---|"]
    for g in result["where"][:15]:
        lines.append(f"| {g['protocol']} | {g['condition']} | {g['rms_gap']:.3g} | {g['noise_floor']:.3g} | "
                     f"{g['p_value']:.2g} |")
    lines += ["", "## Which, and how much of the gap", "", "![waterfall](waterfall.png)", "",
              "| effect | verdict | strength [95 % CI] | held-out RMS before -> after | closes | confusable with "
              "| notes |",
              "|---|---|---|---|---|---|---|"]
    for e in result["named"]:
        ci = e["strength_ci95"]
        lines.append(f"| {e['effect']} | {e['verdict']} | {e['strength']:.3g} [{ci[0]:.3g}, {ci[1]:.3g}] "
                     f"{e['unit']} | {e['heldout_rms_before']:.2f} -> {e['heldout_rms_after']:.2f} | "
                     f"{closed_share_text(e['closed_fraction'])} | {', '.join(e['confusable_with']) or '-'} | "
                     f"{'; '.join(e.get('notes', [])) or '-'} |")
    if not result["named"]:
        lines.append("| none | | | | | | |")
    for c in result["cannot_separate"]:
        lines += ["", f"The data cannot separate {', '.join(c['effects'])}. Measurements that would: "
                  + "; ".join(f"{k}: {v}" for k, v in c["separated_by"].items() if v) + "."]
    if result.get("turned_down"):
        lines += ["", "Tried next, none passing:", ""]
        lines += [f"- {c['effect']}: {c['why']}" for c in result["turned_down"]]
    rest = result["unexplained"]
    lines += ["", f"Left unexplained: held-out RMS {rest['heldout_rms']:.2f} x noise "
              f"[{rest['heldout_rms_ci95'][0]:.2f}, {rest['heldout_rms_ci95'][1]:.2f}]"
              + floor_text(rest) + ".",
              "", f"**Best: {best_text(result)}**", "", "## Specimens", ""]
    plates = any("plate_thickness_change" in v for v in result["specimens"].values())
    lines += ["| specimen | free stroke vs preset | stiffness vs preset | tolerance sigmas |"
              + (" plate thickness (fitted with d31(E)) |" if plates else ""), "|---|---|---|---|" + "---|" * plates]
    for g, v in result["specimens"].items():
        label = specimen_label(g)
        lines.append(f"| {label} | {v['stroke_change']:+.1%} | {v['stiffness_change']:+.1%} | "
                     f"{v['tolerance_sigmas']:.2f} |" + (f" {v['plate_thickness_change']:+.1%} |" if plates else ""))
    lines += ["", "A fabrication shift common to a layer count's specimens shows from these sizes on (smaller ones "
              "look like specimen scatter; the limits fall roughly as 1 / sqrt(specimens)):", ""]
    for layer_count, v in result.get("detection_limits", {}).items():
        sizes = ", ".join(f"{n} {x:.0%}" for n, x in v["smallest_common_shift"].items() if x is not None)
        lines.append(f"- {layer_count}, {v['specimens']} specimen(s): {sizes}")
    lines += ["", "## How far", "", "![overlays](overlays.png)", ""]
    path = out_dir / "gap.md"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
