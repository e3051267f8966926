"""Overlay plots for `hamr-bench compare --plots DIR`: one PNG per channel with A and B against run time, the step
boundaries marked, and A - B underneath (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

UNITS = {"force_N": ("force", "mN", 1e3), "stage_position_m": ("stage position", "mm", 1e3),
         "bias_monitor_V": ("bias monitor", "V", 1.0), "drive_monitor_V": ("drive monitor", "V", 1.0),
         "displacement_m": ("displacement", "um", 1e6)}


def write_overlays(path_a: Path | str, path_b: Path | str, out_dir: Path | str,
                   result: dict[str, Any] | None = None) -> list[Path]:
    """Write `<channel>.png` per channel both recordings have; returns the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from analysis.compare import load_side

    a, b = load_side(path_a), load_side(path_b)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    beyond = set()
    if result is not None:
        beyond = {(st["index"], ch) for st in result["steps"] for ch, v in st["channels"].items()
                  if v["exceeds_noise"]}
    written = []
    for channel in [c for c in UNITS if c in a.channels and c in b.channels]:
        what, unit, scale = UNITS[channel]
        ta, xa = a.channels[channel]
        tb, xb = b.channels[channel]
        fig, (top, bottom) = plt.subplots(2, 1, figsize=(11, 6), sharex=True,
                                          gridspec_kw={"height_ratios": [3, 1]})
        top.plot(ta, xa * scale, lw=0.8, label=f"A: {a.path.name}")
        top.plot(tb, xb * scale, lw=0.8, ls="--", label=f"B: {b.path.name}")
        inside = (ta >= tb[0]) & (ta <= tb[-1]) if tb.size > 1 else np.zeros(ta.size, bool)
        if inside.any():
            bottom.plot(ta[inside], (xa[inside] - np.interp(ta[inside], tb, xb)) * scale, lw=0.6, color="k")
        for index, (start, end, _label, _cond) in a.steps.items():
            if index < 0:
                continue
            for ax in (top, bottom):
                ax.axvline(start, color="0.8", lw=0.5, zorder=0)
            if (index, channel) in beyond:
                top.axvspan(start, end, color="tab:red", alpha=0.12, lw=0)
        top.set_ylabel(f"{what} ({unit})")
        bottom.set_ylabel(f"A - B ({unit})")
        bottom.set_xlabel("time since run start (s)")
        title = f"{what}: A vs B (grey lines: step starts"
        top.set_title(title + ("; red: step beyond noise)" if beyond else ")"))
        top.legend(loc="upper left", fontsize=8)
        fig.tight_layout()
        path = out_dir / f"{channel}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written
