"""Channel-by-channel comparison of two recordings (a run and its twin, two runs, sim and real), step by step.

Alignment: steps are matched by their index (the `step` events; what comes before the first step, the setup and
contact search, is step -1). Within a step, time is measured from the step's start on each side, and B is
interpolated linearly onto A's sample times where both sides have data (so a twin with the source's sample times
is compared sample by sample).

Per channel and step:
- the difference d = A - B: mean, RMS and largest magnitude;
- the noise of each side, sigma = the largest of
  * white noise: the sample-to-sample scatter, MAD(successive differences) / (0.6745 sqrt 2) (robust to the
    signal's own edges, which move only a few samples);
  * replicate noise: where the side has other steps with the same condition (every condition key except
    `repetition`), the RMS difference between this step and each of those, aligned on step time, over sqrt 2
    (repetition-to-repetition and cycle-to-cycle variability: drift, creep, hysteresis);
  * the channel's resolution: the smallest non-zero change the side ever recorded on it, over sqrt 12;
- timing noise: a sample's time stamp is known only to about its sample spacing (a serial sensor's samples are
  stamped when the driver reads them, spaced back from there), so where the signal moves (the drive's ramps) a
  stamp error becomes a value error: per sample, |dx/dt| x (median spacing / sqrt 12), for each side;
- the difference exceeds noise when sqrt(mean(d_i^2 / v_i)) > EXCEED_FACTOR, with v_i = sigma_A^2 + sigma_B^2 +
  both sides' timing noise at sample i. Two records of the same signal with independent noise give a ratio ~ 1,
  so above 3 means a systematic difference of roughly 2.8 sigma or more;
- or the step carries a steady offset: the mean difference's z-score (mean / (sigma_d / sqrt n), sigma_d =
  sqrt(sigma_A^2 + sigma_B^2)) exceeds OFFSET_Z AND the mean difference is at least sigma_d and at least
  OFFSET_FRACTION of the channel's span over both recordings. The RMS test alone misses a shift of about one
  sigma held over hundreds of samples (hysteresis moves every high dwell by ~5 % of a noisy force signal); the
  z-score alone flags offsets too small to matter, because a step's samples are not independent (slow sensor noise
  moves a whole step's mean by a fraction of sigma from run to run) and because 0.1 V on a 250 V drive monitor is
  statistically clear but irrelevant. So an offset must also be as large as one sample's noise and of practical
  size, 1 % of span being about what bench instruments are specified to (load cells 0.1-1 % of full scale).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hamr_bench.errors import RecordingError
from hamr_bench.recording.contract import Topic
from hamr_bench.recording.steps import parse_run

CHANNELS = {  # measured streams (commands are inputs: a replay copies them)
    "force_N": (Topic.FORCE, "force_N"),
    "stage_position_m": (Topic.STAGE_POSITION, "position_m"),
    "bias_monitor_V": (Topic.BIAS_MONITOR, "voltage_V"),
    "drive_monitor_V": (Topic.DRIVE_MONITOR, "voltage_V"),
    "displacement_m": (Topic.CAMERA_DISPLACEMENT, "displacement_m"),
}
EXCEED_FACTOR = 3.0
OFFSET_Z = 5.0
OFFSET_FRACTION = 0.01
MIN_SAMPLES = 3
END_MARGIN_S = 1e-9


@dataclass
class Side:
    """One recording cut into steps: per channel (time_s, value) arrays, and each step's span and condition."""

    path: Path
    channels: dict[str, tuple[np.ndarray, np.ndarray]]
    steps: dict[int, tuple[float, float, str, dict[str, Any]]]  # index -> (start_s, end_s, label, condition)
    resolution: dict[str, float] = field(default_factory=dict)

    def segment(self, channel: str, index: int) -> tuple[np.ndarray, np.ndarray]:
        """(time since the step start, value) of `channel` during step `index`."""
        t, x = self.channels[channel]
        start, end, _label, _cond = self.steps[index]
        sel = (t >= start) & (t < end)
        return t[sel] - start, x[sel]


def load_side(path: Path | str) -> Side:
    from hamr_bench.recording import RecordingReader

    path = Path(path)
    reader = RecordingReader(path)
    topics = reader.topics()
    channels = {}
    resolution = {}
    for name, (topic, field_name) in CHANNELS.items():
        if topic not in topics or topics[topic].message_count == 0:
            continue
        data = reader.scalars(topic)
        if field_name not in data:
            raise RecordingError(f"{path}: topic {topic} has no field {field_name}")
        t, x = data["time_s"], data[field_name]
        ok = np.isfinite(t) & np.isfinite(x)
        order = np.argsort(t[ok], kind="stable")
        t, x = t[ok][order], x[ok][order]
        channels[name] = (t, x)
        steps_nonzero = np.abs(np.diff(x))
        steps_nonzero = steps_nonzero[steps_nonzero > 0]
        resolution[name] = float(steps_nonzero.min()) / math.sqrt(12) if steps_nonzero.size else 0.0
    # the steps as the recording contract's one step parser reads them; spans are half-open, so the last one is
    # stretched by 1 ns to keep the data's last sample
    parsed = parse_run(reader)
    bounds = [st.start_s for st in parsed.steps] + [parsed.end_s + END_MARGIN_S]
    steps: dict[int, tuple[float, float, str, dict[str, Any]]] = {
        -1: (parsed.start_s, bounds[0], "before the first step", {})}
    for st, end_s in zip(parsed.steps, bounds[1:], strict=True):
        steps[st.index] = (st.start_s, end_s, st.message, dict(st.condition))
    return Side(path, channels, steps, resolution)


def white_noise(x: np.ndarray) -> float:
    if x.size < MIN_SAMPLES:
        return 0.0
    d = np.diff(x)
    return float(np.median(np.abs(d - np.median(d))) / (0.6745 * math.sqrt(2)))


def _condition_key(condition: dict[str, Any]) -> str:
    return json.dumps({k: v for k, v in condition.items() if k != "repetition"}, sort_keys=True)


def _aligned_diff(ta: np.ndarray, xa: np.ndarray, tb: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """A - B on A's times inside B's span (B interpolated)."""
    return _aligned(ta, xa, tb, xb)[1]


def _aligned(ta: np.ndarray, xa: np.ndarray, tb: np.ndarray, xb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mask of A's samples inside B's span, A - B there)."""
    if ta.size == 0 or tb.size < 2:
        return np.zeros(ta.size, dtype=bool), np.zeros(0)
    inside = (ta >= tb[0]) & (ta <= tb[-1])
    return inside, xa[inside] - np.interp(ta[inside], tb, xb)


def timing_noise(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Per sample: |dx/dt| x (median sample spacing / sqrt 12), the value error a stamp error makes."""
    if t.size < MIN_SAMPLES:
        return np.zeros(t.size)
    dt = np.diff(t)
    spacing = float(np.median(dt[dt > 0])) if np.any(dt > 0) else 0.0
    _, keep = np.unique(t, return_index=True)
    if keep.size < 2:
        return np.zeros(t.size)
    slope = np.gradient(x[keep], t[keep])
    return np.abs(np.interp(t, t[keep], slope)) * spacing / math.sqrt(12)


def replicate_noise(side: Side, channel: str, index: int) -> float:
    if index < 0:
        return 0.0
    key = _condition_key(side.steps[index][3])
    ta, xa = side.segment(channel, index)
    rms = []
    for other, (_s, _e, _l, cond) in side.steps.items():
        if other == index or other < 0 or _condition_key(cond) != key:
            continue
        tb, xb = side.segment(channel, other)
        d = _aligned_diff(ta, xa, tb, xb)
        if d.size >= MIN_SAMPLES:
            rms.append(float(np.sqrt(np.mean(d ** 2))) / math.sqrt(2))
    return float(np.mean(rms)) if rms else 0.0


def side_noise(side: Side, channel: str, index: int, x: np.ndarray) -> float:
    return max(white_noise(x), replicate_noise(side, channel, index), side.resolution.get(channel, 0.0))


def _span(xa: np.ndarray, xb: np.ndarray) -> float:
    """Range of a channel over both recordings (finite values only): the scale an offset is judged against."""
    x = np.concatenate([xa, xb])
    x = x[np.isfinite(x)]
    return float(x.max() - x.min()) if x.size else 0.0


def compare_recordings(path_a: Path | str, path_b: Path | str) -> dict[str, Any]:
    """The comparison as a JSON-ready dict (see the module docstring for the definitions)."""
    a, b = load_side(path_a), load_side(path_b)
    common_steps = sorted(set(a.steps) & set(b.steps))
    common_channels = [c for c in CHANNELS if c in a.channels and c in b.channels]
    span = {c: _span(a.channels[c][1], b.channels[c][1]) for c in common_channels}
    steps_out = []
    summary: dict[str, dict[str, Any]] = {c: {"steps_compared": 0, "steps_exceeding": 0, "max_rms_over_noise": 0.0,
                                             "max_abs_diff": 0.0} for c in common_channels}
    for index in common_steps:
        label, cond = a.steps[index][2], a.steps[index][3]
        entry: dict[str, Any] = {"index": index, "label": label, "condition": cond,
                                 "condition_b": b.steps[index][3], "channels": {}}
        for channel in common_channels:
            ta, xa = a.segment(channel, index)
            tb, xb = b.segment(channel, index)
            inside, d = _aligned(ta, xa, tb, xb)
            if d.size < MIN_SAMPLES:
                continue
            noise_a = side_noise(a, channel, index, xa)
            noise_b = side_noise(b, channel, index, xb)
            noise_d = math.hypot(noise_a, noise_b)
            timing = np.hypot(timing_noise(ta, xa)[inside],
                              np.interp(ta[inside], tb, timing_noise(tb, xb)))
            variance = noise_d ** 2 + timing ** 2
            rms = float(np.sqrt(np.mean(d ** 2)))
            mean = float(np.mean(d))
            with np.errstate(divide="ignore", invalid="ignore"):
                terms = np.where(variance > 0, d ** 2 / variance, np.where(d == 0, 0.0, np.inf))
            ratio = float(np.sqrt(np.mean(terms)))
            mean_z = mean / (noise_d / math.sqrt(d.size)) if noise_d > 0 else (0.0 if mean == 0 else math.inf)
            floor = max(noise_d, OFFSET_FRACTION * span[channel])
            offset = bool(abs(mean_z) > OFFSET_Z and abs(mean) > floor)
            exceeds = bool(ratio > EXCEED_FACTOR) or offset
            entry["channels"][channel] = {
                "n": int(d.size), "mean_diff": mean, "rms_diff": rms, "max_abs_diff": float(np.max(np.abs(d))),
                "noise_a": noise_a, "noise_b": noise_b, "noise_diff": noise_d,
                "timing_noise_rms": float(np.sqrt(np.mean(timing ** 2))), "rms_over_noise": ratio,
                "mean_z": mean_z, "offset_floor": floor, "steady_offset": offset,
                "exceeds_noise": exceeds}
            s = summary[channel]
            s["steps_compared"] += 1
            s["steps_exceeding"] += int(exceeds)
            s["max_rms_over_noise"] = max(s["max_rms_over_noise"], ratio)
            s["max_abs_diff"] = max(s["max_abs_diff"], float(np.max(np.abs(d))))
        steps_out.append(entry)
    for s in summary.values():
        s["exceeds_noise"] = s["steps_exceeding"] > 0
    return {
        "a": str(a.path), "b": str(b.path), "exceed_factor": EXCEED_FACTOR,
        "offset_z": OFFSET_Z, "offset_fraction": OFFSET_FRACTION,
        "channels": summary, "steps": steps_out,
        "steps_only_in_a": sorted(set(a.steps) - set(b.steps)),
        "steps_only_in_b": sorted(set(b.steps) - set(a.steps)),
        "channels_only_in_a": sorted(set(a.channels) - set(b.channels)),
        "channels_only_in_b": sorted(set(b.channels) - set(a.channels)),
    }


def format_comparison(result: dict[str, Any]) -> str:
    lines = [f"A: {result['a']}", f"B: {result['b']}",
             f"{'channel':<18} {'steps':>5} {'beyond':>6} {'max |A-B|':>12} {'max RMS/noise':>14}"]
    for name, s in result["channels"].items():
        lines.append(f"{name:<18} {s['steps_compared']:>5} {s['steps_exceeding']:>6} {s['max_abs_diff']:>12.4g} "
                     f"{s['max_rms_over_noise']:>14.3g}")
    beyond = [(st["index"], st["label"], ch, v) for st in result["steps"] for ch, v in st["channels"].items()
              if v["exceeds_noise"]]
    if beyond:
        lines.append(f"beyond noise (RMS of (A-B)/noise > {result['exceed_factor']:g}, or a steady offset: "
                     f"|mean z| > {result['offset_z']:g} and |mean| > noise and > "
                     f"{result['offset_fraction']:.0%} of span):")
        for index, label, ch, v in beyond:
            why = "steady offset" if v["steady_offset"] else "RMS"
            lines.append(f"  step {index} ({label}) {ch}: mean {v['mean_diff']:.4g} (z {v['mean_z']:.3g}), "
                         f"RMS {v['rms_diff']:.4g}, noise {v['noise_diff']:.4g} [{why}]")
    else:
        lines.append("no channel differs beyond noise in any step")
    lines.append("(max |A-B|: the largest single difference, B interpolated onto A's times, ramps included, so it can "
                 "be large where the two sample a ramp ms apart; the verdicts weigh each step against its noise)")
    for key in ("steps_only_in_a", "steps_only_in_b", "channels_only_in_a", "channels_only_in_b"):
        if result[key]:
            lines.append(f"{key.replace('_', ' ')}: {result[key]}")
    return "\n".join(lines)
