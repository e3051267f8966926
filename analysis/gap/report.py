"""The gap report: residual map (before / after the best candidate), before/after overlays of data and model per
protocol, and the ranking, as PNGs with a Markdown summary (`hamr-bench gap ... --report DIR`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np



def _fitted(problem, strengths: dict) -> np.ndarray:
    z, _ = problem.residual(strengths)
    return problem.y - z * problem.sigma, z


def _best_strengths(result: dict) -> dict:
    top = next((e for e in result["ranking"] if e.get("reduction") is not None), None)
    if top is None:
        return {}
    if "+" in top["effect"]:
        return dict(zip(top["effect"].split("+"), top["strength"]))
    return {top["effect"]: top["strength"]}


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

    panels = []
    for run in problem.data.runs:
        for mode in sorted({r.mode for r in run.rows}):
            panels.append((run, mode))
    n = len(panels)
    cols = min(n, 3)
    rows_n = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows_n, cols, figsize=(5 * cols, 3.6 * rows_n), squeeze=False)
    for ax, (run, mode) in zip(axes.flat, panels):
        idx = [i for i, r in enumerate(problem.rows) if r.run == run.index and r.mode == mode
               and r.phase in ("high_late", "hold")]
        if not idx:
            ax.axis("off")
            continue
        rows = [problem.rows[i] for i in idx]
        use_sag = run.protocol in ("sag-sweep", "static")
        x = np.array([r.sag_m * 1e3 if use_sag else r.voltage_V for r in rows])
        scale = 1e3 if rows[0].quantity == "force_N" else 1e6
        unit = "mN" if rows[0].quantity == "force_N" else "um"
        order = np.argsort(x, kind="stable")
        ax.errorbar(x, problem.y[idx] * scale, yerr=2 * problem.sigma[idx] * scale, fmt="o", ms=3, color="k",
                    label="measured (+-2 se)")
        for fit, style, name in ((fit0, "--", "nominal"), (fit1, "-", label)):
            ax.plot(x[order], fit[idx][order] * scale, style, label=name)
        ax.set_xlabel("sag (mm)" if use_sag else "bias voltage (V)")
        ax.set_ylabel(f"{rows[0].quantity.split('_')[0]} ({unit})")
        who = f"design {run.design}" if run.fixture == "leg" else f"{run.layers}-layer actuator"
        ax.set_title(f"{run.protocol} {mode} ({who})".replace("  ", " "), fontsize=9)
        ax.legend(fontsize=7)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def ranking_png(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    entries = [e for e in result["ranking"] if e.get("reduction") is not None]
    fig, ax = plt.subplots(figsize=(8, 0.5 * max(len(entries), 1) + 1.5))
    if entries:
        names = [f"{e['effect']} ({e['verdict']})" for e in entries]
        red = np.array([e["reduction"] for e in entries]) * 100
        lo = red - np.array([e["reduction_ci95"][0] for e in entries]) * 100
        hi = np.array([e["reduction_ci95"][1] for e in entries]) * 100 - red
        ax.barh(range(len(entries)), red, xerr=[lo, hi], color=["tab:green" if e["verdict"] == "attributed" else
                                                                 "tab:gray" for e in entries])
        ax.set_yticks(range(len(entries)), names)
        ax.invert_yaxis()
    else:
        ax.text(0.5, 0.5, "no candidate passed screening", ha="center", transform=ax.transAxes)
    ax.set_xlabel("held-out gap reduction (%) with 95 % bootstrap interval over conditions")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(result: dict, out_dir: Path) -> Path:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    problem = result["_problem"]
    strengths = _best_strengths(result)
    label = " + ".join(f"{k} {v:.3g}" for k, v in strengths.items()) or "no candidate"
    fit0, z0 = _fitted(problem, {})
    # under the winner the run offsets are re-estimated (they depend on effects that act on the undriven rows)
    fit1, z1 = _fitted(problem.relinearised(strengths), strengths) if strengths else (fit0, z0)
    residual_map_png(problem, z0, z1, label, out_dir / "residual_map.png")
    overlays_png(problem, fit0, fit1, label, out_dir / "overlays.png")
    ranking_png(result, out_dir / "ranking.png")
    nominal = result["nominal_lack_of_fit"]
    lines = ["# Sim-to-real gap diagnosis", "",
             f"Recordings: {', '.join(Path(r.path).name for r in problem.data.runs)}.",
             f"Residuals are against the nominal model ({result.get('nominal_source', 'presets')}); units of the "
             f"held-out figures: {result['heldout_units']}.", "",
             "## Where", "",
             f"Gap above the noise floor: **{'yes' if result['gap_above_noise'] else 'no'}** (lack-of-fit F test "
             f"p = {nominal['p_value']:.3g}; RMS residual {nominal['z_rms']:.2f} x the pure-error standard error).",
             "", "![residual map](residual_map.png)", "",
             "| protocol | condition | RMS gap | noise floor | p (lack of fit) |", "|---|---|---|---|---|"]
    for g in result["where"][:15]:
        lines.append(f"| {g['protocol']} | {g['condition']} | {g['rms_gap']:.3g} | {g['noise_floor']:.3g} | "
                     f"{g['p_value']:.2g} |")
    lines += ["", "## Which", "", "![ranking](ranking.png)", "",
              "| effect | verdict | strength [95 % CI] | held-out RMS before -> after | reduction [95 % CI] | "
              "closed fraction | confusable with |", "|---|---|---|---|---|---|---|"]
    for e in result["ranking"]:
        if e.get("reduction") is None:
            continue
        ci = e.get("strength_ci95")
        st = (", ".join(f"{v:.3g}" for v in e["strength"]) if isinstance(e["strength"], list)
              else f"{e['strength']:.3g}") + (f" [{ci[0]:.3g}, {ci[1]:.3g}]" if ci else "")
        lines.append(f"| {e['effect']} | {e['verdict']} | {st} {e['unit'] if isinstance(e['unit'], str) else ''} | "
                     f"{e['heldout_rms_before']:.2f} -> {e['heldout_rms_after']:.2f} | {e['reduction']:.0%} "
                     f"[{e['reduction_ci95'][0]:.0%}, {e['reduction_ci95'][1]:.0%}] | {e['closed_fraction']:.2f} | "
                     f"{', '.join(e['confusable_with']) or '-'} |")
    lines += ["", f"**Best: {result['best'] or 'none'}**", "", "## How far", "",
              "![overlays](overlays.png)", ""]
    top = next((e for e in result["ranking"] if e.get("closes") is not None), None)
    if top:
        lines += [f"Regions {top['effect']} closes (no longer significant): "
                  f"{'; '.join(top['closes']) or 'none'}.", "",
                  f"Regions it leaves: {'; '.join(top['leaves']) or 'none'}.", ""]
    path = out_dir / "gap.md"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
