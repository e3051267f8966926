"""Driver for an ATI Nano17 six-axis force/torque sensor read through six DAQ analog inputs (the rig's
actuator tests). Implements `hamr_bench.interfaces.ForceSensor` on one force axis (Fz by default, sign
configurable).

Owns: reading the sensor's ATI calibration XML file (`.cal`: the `UserAxis` rows give the 6x6 matrix from
gauge volts to Fx, Fy, Fz, Tx, Ty, Tz in the file's units, converted here to N and N m; `max` gives each
axis's calibrated range), the bias (mean gauge voltages with the sensor unloaded, taken by `tare`), the
conversion `wrench = C (V - V_bias)`, and overload detection: any axis beyond its calibrated range, or any
gauge at the DAQ's input range, raises DeviceFault (a reading there is not a measurement).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError, DeviceFault
from hamr_bench.interfaces import DaqBackend, ForceSample
from hamr_bench.rig_file import NANO17_SAMPLE_RATE_HZ

AXES = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
_FORCE_TO_N = {"N": 1.0, "lbf": 4.4482216152605, "kgf": 9.80665}
_TORQUE_TO_N_M = {"N-m": 1.0, "N-mm": 1e-3, "lbf-in": 0.1129848290276167, "lbf-ft": 1.3558179483314004,
                  "kgf-cm": 0.0980665}


@dataclass(frozen=True, eq=False)
class AtiCalibration:
    """A sensor's calibration in SI: `matrix_SI` maps 6 gauge volts to (N, N, N, N m, N m, N m); `max_SI` is
    the calibrated range of each axis in the same units."""

    path: str
    serial: str
    part_number: str
    matrix_SI: np.ndarray
    max_SI: np.ndarray
    force_units: str
    torque_units: str


def load_ati_calibration(path: Path | str) -> AtiCalibration:
    """Parse an ATI calibration XML (`.cal`) file. Errors name the file and the element at fault."""
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        raise ConfigError(f"{path}: calibration file not found") from None
    except ET.ParseError as exc:
        raise ConfigError(f"{path}: not an ATI calibration XML file ({exc})") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror})") from None
    cal = root.find("Calibration")
    if root.tag != "FTSensor" or cal is None:
        raise ConfigError(f"{path}: expected <FTSensor><Calibration>, found <{root.tag}>")
    force_units = cal.get("ForceUnits", "")
    torque_units = cal.get("TorqueUnits", "")
    if force_units not in _FORCE_TO_N:
        raise ConfigError(f"{path}: ForceUnits={force_units!r} not one of {', '.join(_FORCE_TO_N)}")
    if torque_units not in _TORQUE_TO_N_M:
        raise ConfigError(f"{path}: TorqueUnits={torque_units!r} not one of {', '.join(_TORQUE_TO_N_M)}")
    rows: dict[str, tuple[list[float], float]] = {}
    for elem in cal.findall("UserAxis"):
        name = elem.get("Name", "")
        try:
            values = [float(v) for v in elem.get("values", "").split()]
            max_value = float(elem.get("max", "nan"))
        except ValueError:
            raise ConfigError(f"{path}: UserAxis {name!r} has a non-numeric value") from None
        if len(values) != 6 or not all(map(math.isfinite, values)):
            raise ConfigError(f"{path}: UserAxis {name!r} needs 6 finite values, has {len(values)}")
        rows[name] = (values, max_value)
    missing = [a for a in AXES if a not in rows]
    if missing:
        raise ConfigError(f"{path}: UserAxis rows missing for {', '.join(missing)}")
    scale = np.array([_FORCE_TO_N[force_units]] * 3 + [_TORQUE_TO_N_M[torque_units]] * 3)
    matrix = np.array([rows[a][0] for a in AXES]) * scale[:, None]
    max_si = np.array([rows[a][1] for a in AXES]) * scale
    if not np.all(np.isfinite(max_si) & (max_si > 0)):
        raise ConfigError(f"{path}: every UserAxis needs a positive 'max' (calibrated range)")
    if abs(np.linalg.det(matrix)) < 1e-300 or np.linalg.cond(matrix) > 1e12:
        raise ConfigError(f"{path}: the UserAxis matrix is singular")
    return AtiCalibration(str(path), root.get("Serial", "?"), cal.get("PartNumber", "?"), matrix, max_si,
                          force_units, torque_units)


def gauges_to_wrench(matrix_SI: np.ndarray, gauge_V: np.ndarray, bias_V: np.ndarray) -> np.ndarray:
    """`C (V - V_bias)` for gauge voltages shaped (6, n): returns (6, n) in N and N m."""
    return matrix_SI @ (np.asarray(gauge_V, dtype=float) - np.asarray(bias_V, dtype=float).reshape(6, 1))


class AtiNano17:
    """An ATI Nano17 on six DAQ analog inputs, exposing one force axis as a `ForceSensor`."""

    def __init__(
        self,
        daq: DaqBackend,
        clock: Clock,
        calibration: AtiCalibration | Path | str,
        *,
        gauge_channels: Sequence[str],
        axis: str = "Fz",
        sign: float = 1.0,
        sample_rate_Hz: float = NANO17_SAMPLE_RATE_HZ,
        samples_per_reading: int = 50,
        tare_samples: int = 500,
        gauge_range_V: float = 10.0,
        timeout_s: float = 2.0,
        name: str = "force_sensor",
    ) -> None:
        if not isinstance(calibration, AtiCalibration):
            calibration = load_ati_calibration(calibration)
        self._cal = calibration
        if len(gauge_channels) != 6:
            raise ConfigError(f"AtiNano17 {name}: gauge_channels needs 6 channels, got {len(gauge_channels)}")
        if axis not in AXES[:3]:
            raise ConfigError(f"AtiNano17 {name}: axis={axis!r} must be one of Fx, Fy, Fz")
        if sign not in (1, -1, 1.0, -1.0):
            raise ConfigError(f"AtiNano17 {name}: sign must be +1 or -1, got {sign!r}")
        for label, value in (("sample_rate_Hz", sample_rate_Hz), ("timeout_s", timeout_s),
                             ("gauge_range_V", gauge_range_V)):
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"AtiNano17 {name}: {label} must be positive, got {value!r}")
        if samples_per_reading < 1 or tare_samples < 1:
            raise ConfigError(f"AtiNano17 {name}: samples_per_reading and tare_samples must be >= 1")
        self._daq = daq
        self._clock = clock
        self._channels = tuple(gauge_channels)
        self._axis = AXES.index(axis)
        self._sign = float(sign)
        self._rate = float(sample_rate_Hz)
        self._n = int(samples_per_reading)
        self._n_tare = int(tare_samples)
        self._saturation_V = 0.999 * gauge_range_V
        self._timeout_s = float(timeout_s)
        self._name = name
        self._bias_V = np.zeros(6)
        self._streaming = False

    @property
    def calibration(self) -> AtiCalibration:
        return self._cal

    @property
    def bias_V(self) -> np.ndarray:
        return self._bias_V.copy()

    @property
    def capacity_N(self) -> float:
        return float(self._cal.max_SI[self._axis])

    def tare(self) -> None:
        """Take the bias from the mean of `tare_samples` gauge readings; the sensor must be unloaded."""
        block = self._read(self._n_tare)
        data = np.asarray(block.data_V, dtype=float)
        self._check_saturation(data)
        self._bias_V = data.mean(axis=1)

    def read_wrench(self) -> np.ndarray:
        """Mean of one reading's samples: (Fx, Fy, Fz, Tx, Ty, Tz) in N and N m."""
        data = np.asarray(self._read(self._n).data_V, dtype=float)
        return self._convert(data).mean(axis=1)

    def read_N(self) -> float:
        return self._sign * float(self.read_wrench()[self._axis])

    def start_stream(self) -> None:
        self._daq.start_ai_stream(self._channels, self._rate)
        self._streaming = True

    def read_stream(self) -> list[ForceSample]:
        if not self._streaming:
            return []
        block = self._daq.read_ai_stream()
        data = np.asarray(block.data_V, dtype=float)
        if data.size == 0:
            return []
        times = block.start_time_s + np.arange(data.shape[1]) / block.sample_rate_Hz
        try:
            force = self._sign * self._convert(data)[self._axis]
        except DeviceFault as exc:
            # Samples before the first overloaded one are good readings: they travel with the error
            # (`samples_before`) so the caller can keep them.
            good = self._good_prefix(data)
            force = self._sign * self._convert(data[:, :good])[self._axis] if good else np.empty(0)
            exc.samples_before = [ForceSample(t, f) for t, f in zip(times[:good].tolist(), force.tolist(), strict=True)]
            raise
        return [ForceSample(t, f) for t, f in zip(times.tolist(), force.tolist(), strict=True)]

    def _good_prefix(self, data: np.ndarray) -> int:
        """How many leading samples of a block convert without an overload."""
        lo, hi = 0, data.shape[1]  # the first bad sample lies in [lo, hi)
        while lo < hi:
            mid = (lo + hi) // 2
            try:
                self._convert(data[:, : mid + 1])
                lo = mid + 1
            except DeviceFault:
                hi = mid
        return lo

    def stop_stream(self) -> None:
        if self._streaming:
            self._streaming = False
            self._daq.stop_ai_stream()

    def close(self) -> None:
        self.stop_stream()

    # ---- internals -----------------------------------------------------------------------------------------
    def _read(self, n: int):
        if self._streaming:
            raise ConfigError(f"{self._name}: single readings while streaming; call stop_stream() first")
        return self._daq.read_ai(self._channels, n, self._rate, self._timeout_s)

    def _check_saturation(self, data: np.ndarray) -> None:
        peak = np.max(np.abs(data), axis=1)
        if np.any(peak >= self._saturation_V):
            g = int(np.argmax(peak))
            raise DeviceFault(
                f"{self._name}: overload: gauge {self._channels[g]} at {peak[g]:.2f} V, the DAQ input limit",
                device=self._name,
            )

    def _convert(self, data: np.ndarray) -> np.ndarray:
        self._check_saturation(data)
        wrench = gauges_to_wrench(self._cal.matrix_SI, data, self._bias_V)
        peak = np.max(np.abs(wrench), axis=1)
        over = peak > self._cal.max_SI
        if np.any(over):
            i = int(np.flatnonzero(over)[0])
            unit = "N" if i < 3 else "N m"
            raise DeviceFault(
                f"{self._name}: overload: {AXES[i]} reached {peak[i]:.4g} {unit}, "
                f"beyond the calibrated range "
                f"{self._cal.max_SI[i]:.4g} {unit} of {Path(self._cal.path).name}",
                device=self._name,
            )
        return wrench
