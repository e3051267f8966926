"""A readable Markdown report of recordings: what was read, the fitted parameters with 95 % intervals and
identifiability, the paper's values alongside (Table I effective, Table III), the held-out static check, and the
figures (analysis/figures.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Any
from collections.abc import Iterable

import numpy as np

from analysis.dataset import Dataset, load_dataset
from analysis.figures import all_figures
from analysis.fit import ACTUATOR_FIELDS, FitReport, fit_dataset
from analysis.observations import LegObservations

SCALE = {"Pa": (1e-9, "GPa"), "m/V": (1e12, "pm/V"), "m": (1e6, "um"), "N/m": (1.0, "N/m"),
         "N m/rad": (1e3, "N mm/rad")}


def _fmt(value: float | None, unit: str) -> str:
    if value is None or not np.isfinite(value):
        return "-"
    k, u = SCALE.get(unit, (1.0, unit))
    return f"{value * k:.4g}"


def paper_values(kind: str, key: int) -> dict[str, float]:
    """Table I effective (actuators) / Table III (designs 1-4) in SI, for the comparison column."""
    from hamr_bench.model import actuator_preset, design_preset

    if kind == "actuator":
        a = actuator_preset(key, "effective")
        return {name: getattr(a, f) for name, f in ACTUATOR_FIELDS.items()}
    if key not in (1, 2, 3, 4):
        return {}
    d = design_preset(key)
    k1, k2, k3 = d.kappa_N_m_per_rad
    return {"k_ser": d.k_ser_N_per_m, "kappa_1": k1, "kappa_2": k2, "kappa_3": k3, "bias": d.bias_m}


def recordings_table(dataset: Dataset) -> list[str]:
    """What was read: per run (a file, or one specimen of a file), its specimen, session and where its drive and
    stage timelines came from (commanded, inferred from the measured drive, measured), then the sessions."""
    md = ["## Recordings", "", "| file | specimen | protocol | design | layers | source | timelines (bias / drive "
          "/ stage) | session | exit | observations |", "|---|---|---|---|---|---|---|---|---|---|"]
    sessions: dict[str, list[str]] = {}
    for k, r in enumerate(dataset.runs):
        i = r.info
        tl = " / ".join(i.timelines.get(c, "-") for c in ("bias", "drive", "stage")) if i.timelines else "-"
        session = i.session or f"run {k}"
        name = Path(i.path).name
        sessions.setdefault(session, []).append(name + (f" ({i.specimen})" if i.specimen else ""))
        md.append(f"| {name} | {i.specimen or '-'} | {i.protocol} | {i.design or '-'} | {i.layers} | {i.source} | "
                  f"{tl} | {_session_label(session)} | {i.exit_status or 'unfinished'} | {len(r.observations)} |")
    md += ["", "Sessions (one specimen mounted once; their nuisances, the zero offsets, are shared by their "
           "recordings; rule: docs/log-format.md, Sessions):", ""]
    for key, names in sessions.items():
        md.append(f"- {_session_label(key)}: {', '.join(names)}")
    return md + [""]


def _session_label(key: str) -> str:
    if key.startswith("recording="):
        return "own (contact search)"
    return key.replace("|", " ").replace("default ", "default: ")


def specimens_table(g: Any) -> list[str]:
    """Per-specimen values of a group fitted per specimen, with the population row (mean, between-specimen SD)."""
    if not g.specimens:
        return []
    names = [n for n, d in g.derived.items() if isinstance(d, dict) and "between_specimen_sd" in d]
    if not names:
        return []
    md = ["", f"Specimens ({len(g.specimens)}; fitted one by one, scatter between them modelled, not lack of fit):",
          "", "| specimen | " + " | ".join(f"{n} ({g.derived[n]['unit']})" for n in names) + " |",
          "|---|" + "---|" * len(names)]
    for label, sg in g.specimens.items():
        md.append(f"| {label} | " + " | ".join(f"{sg.derived[n]['value']:.4g}" if n in sg.derived else "-"
                                               for n in names) + " |")
    md.append("| mean +- SD | " + " | ".join(f"{g.derived[n]['value']:.4g} +- {g.derived[n]['between_specimen_sd']:.2g}"
                                            for n in names) + " |")
    return md


def static_check(dataset: Dataset, fit: FitReport) -> list[str]:
    """RMS of the fitted model against the static recordings, which the fit did not use (only each static run's
    own zero-sag offset is fitted, with the transmission held at the fit)."""
    from analysis.figures import static_offset
    from hamr_bench.model import Powertrain

    lines = []
    for design, g in sorted(fit.designs.items()):
        obs = dataset.select(protocol="static", design=design)
        if not obs or g.model is None:
            continue
        h0 = static_offset(dataset, g.model[0], g.model[1], obs)
        legs = LegObservations(["static"] * len(obs), [0.0] * len(obs), [o.sag_m for o in obs])
        pred = legs.predict(Powertrain(*g.model), h0)
        y = np.array([o.value for o in obs])
        rms = float(np.sqrt(np.nanmean((pred - y) ** 2)))
        lines.append(f"| {design} | {len(obs)} | {h0 * 1e6:.3g} | {rms * 1e3:.3g} | {float(np.max(y)) * 1e3:.3g} |")
    if lines:
        lines = ["| design | points | zero-sag offset (um) | RMS (mN) | largest force (mN) |",
                 "|---|---|---|---|---|"] + lines
    return lines


def write_report(recordings: Iterable[Path], out_dir: Path, method: str = "least-squares") -> Path:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    dataset = load_dataset(list(recordings))
    fit = fit_dataset(dataset, method)
    figures = all_figures(dataset, fit, out_dir)
    md = ["# hamr-bench report", ""]
    md += recordings_table(dataset)
    md += ["", f"Fit method: **{method}**; intervals: 95 % profile likelihood (noise scale from the fit). "
           "Status 'not identifiable' means the profile stays under the 95 % threshold across the whole search "
           "range: the value is then the reference it started from, not a measurement.", ""]
    for title, groups, kind in (("Actuators (paper Table I)", fit.actuators, "actuator"),
                                ("Transmissions (paper Table III)", fit.designs, "design")):
        if not groups:
            continue
        md += [f"## {title}", ""]
        for key, g in sorted(groups.items()):
            paper = paper_values(kind, key)
            head = f"{key} carbon-fibre layer(s)" if kind == "actuator" else f"design {key}"
            rms = []
            if g.rms_N is not None:
                rms.append(f"force RMS {g.rms_N * 1e3:.3g} mN")
            if g.rms_m is not None:
                rms.append(f"displacement RMS {g.rms_m * 1e6:.3g} um")
            chi2 = f"; reduced chi2 {g.chi2 / g.dof:.3g}" if g.dof > 0 else ""
            md += [f"### {head}", "", f"{g.n_observations} observations; {'; '.join(rms)}{chi2}", "",
                   "| parameter | unit | fitted | 95 % interval | status | paper |", "|---|---|---|---|---|---|"]
            for p in g.params.values():
                u = SCALE.get(p.unit, (1.0, p.unit))[1]
                ci = "-" if p.ci95 is None else f"{_fmt(p.ci95[0], p.unit)} .. {_fmt(p.ci95[1], p.unit)}"
                md.append(f"| {p.name} | {u} | {_fmt(p.value, p.unit)} | {ci} | {p.status} | "
                          f"{_fmt(paper.get(p.name), p.unit)} |")
            derived = {k: v for k, v in g.derived.items() if isinstance(v, dict) and "ci95" in v}
            if derived:
                md += ["", "What these data identify:", "", "| quantity | value | 95 % interval | unit |",
                       "|---|---|---|---|"]
                for name, d in derived.items():
                    md.append(f"| {name} | {d['value']:.4g} | {d['ci95'][0]:.4g} .. {d['ci95'][1]:.4g} | {d['unit']} |")
            md += specimens_table(g)
            if g.warnings:
                md += [""] + [f"- warning: {w}" for w in g.warnings]
            md.append("")
    check = static_check(dataset, fit)
    if check:
        md += ["## Held-out check: static stiffness (Fig. 10)", "",
               "The fit does not use the static recordings; the fitted model's prediction against them:", ""]
        md += check + [""]
    if figures:
        md += ["## Figures", ""]
        for name, figure in figures.items():
            md += [f"![{name}]({figure.name})", ""]
    if fit.warnings:
        md += ["## Warnings", ""] + [f"- {w}" for w in fit.warnings]
    path = out_dir / "report.md"
    path.write_text("\n".join(md) + "\n", encoding="utf-8")
    (out_dir / "fit.json").write_text(fit.to_json() + "\n", encoding="utf-8")
    return path
