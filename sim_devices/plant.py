"""The bench's physics in time: everything between the amplifier outputs / the stage's motor and what the
sensors and the camera see, integrated on a fixed time grid (step h, 0.25 ms) in blocks.

Per block of grid points, vectorised (no Python loop per sample):

1. the amplifier outputs -> the drive chain (sim_devices.drive_chain) -> the actuator's free deflection u;
2. the stage's motor -> the carriage (sim_devices.stage_carriage) -> where the sensor surface is (x_s);
3. the quasi-static targets (sim_devices.contact_statics): the free position, and in contact the position
   x_s + N / k_s at which the sensor's spring holds the plant (clamp, sensor spring and foot friction included);
4. one mode of the plant, x'' + 2 zeta omega x' + omega^2 (x - target) = 0, exactly discretised for a target
   linear between grid points (sim_devices.linear_dynamics): the free mode (the bare actuator's tip, or the loaded
   leg) while x <= x_s, the contact mode (plant and the sensor's moving mass on plant + sensor stiffness) while
   x > x_s. At touchdown plant and sensor mass share momentum (a plastic impact); at lift-off the sensor stays
   behind. The switch is found on the grid (within one step);
5. the sensed force k_s (x - x_s) in contact (0 off it), its integral over each step in closed form (a load cell
   that averages over its conversion period reads the exact average), and the sensor's drift.

Row k of the stored grid holds the point's values (x_s, x, u, the free and contact targets, the cumulative force
integral, the drift) and the step that leaves it (`mode`, and `xi`, the modal state at k in that mode).

Inputs change when the runner acts (an analog-output write, a stage command): the emulators call `invalidate`,
which forgets every point at or after that moment (restoring the component states saved at the start of the block
that holds it); the next question recomputes. Between changes the plant computes ahead of the latest question by
an adaptive horizon (doubling while nothing changes, 20 ms -> 0.5 s), so blocks are long in dwells and short
while the runner steps the stage. Results depend on the inputs alone, not on how the questions were split (up to
rounding: block-wise sums round differently); the same run always splits the same way, so its recordings are
bit-identical run to run.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from sim_devices.linear_dynamics import SecondOrderMode

_CHUNK_STEPS = 256          # the dynamics are checked for a contact change every this many steps
_MIN_HORIZON_S = 0.02
_MAX_HORIZON_S = 0.5
_MAX_SWITCHES_PER_BLOCK = 2000
_NEAR_CONTACT_M = 50e-6     # the contact statics are solved where the free plant is within this of the surface


@dataclass(frozen=True)
class ModeSpec:
    """The plant's two modes: free (mass m, stiffness k) and in contact (m + m_sensor, k + k_sensor)."""

    mass_kg: float
    stiffness_N_per_m: float
    damping_ratio: float
    sensor_mass_kg: float
    sensor_stiffness_N_per_m: float
    contact_damping_ratio: float

    @property
    def free_frequency_Hz(self) -> float:
        return math.sqrt(self.stiffness_N_per_m / self.mass_kg) / (2 * math.pi)

    @property
    def contact_frequency_Hz(self) -> float:
        return math.sqrt((self.stiffness_N_per_m + self.sensor_stiffness_N_per_m)
                         / (self.mass_kg + self.sensor_mass_kg)) / (2 * math.pi)


# "contact" holds the contact mode's target as the sensor's compression N / k_s; "xi" is the modal state of the
# row's mode: the absolute position in the free mode, the compression x - x_s in the contact mode.
_COLUMNS = {"x_s": float, "x": float, "u": float, "free": float, "contact": float, "mode": np.int8,
            "xi": complex, "cum_force": float, "drift": float}


class BenchPlant:
    """See the module docstring.

    `statics`: `free_position_m(u, first, stop)`, `contact_force_N(u, x_s, dx_s, first, stop, near)`,
    `needs_history` (True when the contact force depends on earlier samples, e.g. friction), `snapshot()`,
    `restore(state)`; `first`/`stop` are the grid indices of the samples (for time-dependent parts).
    `amplifier_outputs(times) -> (v_bias, v_drive)`, `surface_at(times) -> x_s` (carriage and mount included, with
    `snapshot()`/`restore()` on the object `surface_state`), `drift`: a `sensor_drift.DriftProcess` or None."""

    def __init__(self, *, h_s: float, t0_s: float, modes: ModeSpec, drive: Any, statics: Any,
                 amplifier_outputs: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                 surface: Any, drift: Any = None, keep_s: float = 20.0, dynamics: bool = True) -> None:
        self.h = h_s
        self.t0 = t0_s
        self.spec = modes
        self.drive = drive
        self.statics = statics
        self.amplifier_outputs = amplifier_outputs
        self.surface = surface
        self.drift = drift
        self.dynamics = dynamics
        self.keep = max(int(keep_s / h_s), 4 * _CHUNK_STEPS)
        self.k_sensor = modes.sensor_stiffness_N_per_m
        self.free_mode = SecondOrderMode(2 * math.pi * modes.free_frequency_Hz, modes.damping_ratio, h_s)
        self.contact_mode = SecondOrderMode(2 * math.pi * modes.contact_frequency_Hz, modes.contact_damping_ratio,
                                            h_s)
        self.impact_ratio = modes.mass_kg / (modes.mass_kg + modes.sensor_mass_kg)
        self._store: dict[str, np.ndarray] = {n: np.empty(4096, dtype=d) for n, d in _COLUMNS.items()}
        self._rows = 0            # rows in use
        self.first = 0            # grid index of the first stored row
        self.snapshots: list[tuple[int, dict[str, Any]]] = []
        self.horizon_s = _MIN_HORIZON_S
        self.changed = False
        self.blocks = 0           # statistics for the benchmark: blocks computed, points computed
        self.points = 0
        self._start()

    # ------------------------------------------------------------------ grid bookkeeping
    @property
    def cols(self) -> dict[str, np.ndarray]:
        """The stored rows (views into the column store)."""
        return {name: arr[:self._rows] for name, arr in self._store.items()}

    @property
    def last(self) -> int:
        """Grid index of the last computed point."""
        return self.first + self._rows - 1

    def _time(self, k: np.ndarray) -> np.ndarray:
        return self.t0 + self.h * np.asarray(k, dtype=float)

    def _states(self) -> dict[str, Any]:
        return {"drive": self.drive.snapshot(), "surface": self.surface.snapshot(),
                "statics": self.statics.snapshot(), "drift": self.drift.snapshot() if self.drift else None}

    def _restore(self, states: dict[str, Any]) -> None:
        self.drive.restore(states["drive"])
        self.surface.restore(states["surface"])
        self.statics.restore(states["statics"])
        if self.drift:
            self.drift.restore(states["drift"])

    def _mode(self, mode: int) -> SecondOrderMode:
        return self.contact_mode if mode else self.free_mode

    def _start(self) -> None:
        t = np.array([self.t0])
        vb, vd = self.amplifier_outputs(t)
        u = self.drive.run(vb, vd)
        x_s = self.surface.run(t)
        free = self.statics.free_position_m(u, 0, 1)
        force = self.statics.contact_force_N(u, x_s, np.zeros(1), 0, 1, np.ones(1, bool))
        compression = force / self.k_sensor
        mode = 1 if free[0] > x_s[0] else 0
        x0 = float(x_s[0] + compression[0] if mode else free[0])
        state0 = float(compression[0]) if mode else x0
        drift = self.drift.run(0, 1, np.zeros(1)) if self.drift else np.zeros(1)
        self._append(x_s=x_s, x=np.array([x0]), u=u, free=free, contact=compression,
                     mode=np.array([mode], np.int8), xi=np.array([self._mode(mode).to_modal(state0, 0.0)]),
                     cum_force=np.zeros(1), drift=drift)
        # the starting point stands for the rig before any command: a change at the start time restarts after it
        self.snapshots.append((0, self._states()))

    def _append(self, **cols: np.ndarray) -> None:
        count = len(next(iter(cols.values())))
        need = self._rows + count
        capacity = len(self._store["x"])
        if need > capacity:
            size = max(need, 2 * capacity)
            for name, arr in self._store.items():
                grown = np.empty(size, dtype=arr.dtype)
                grown[:self._rows] = arr[:self._rows]
                self._store[name] = grown
        for name, values in cols.items():
            self._store[name][self._rows:need] = values
        self._rows = need

    def invalidate(self, time_s: float) -> None:
        """An input changes from `time_s` on: forget every grid point at or after it."""
        self.changed = True
        keep_through = int(math.ceil((time_s - self.t0) / self.h - 1e-9)) - 1   # last point strictly before
        keep_through = max(keep_through, self.first)
        if keep_through >= self.last:
            return
        while self.snapshots and self.snapshots[-1][0] > keep_through:
            self.snapshots.pop()
        if not self.snapshots:
            raise RuntimeError(f"simulated bench: an input changed at t={time_s:g} s, before the kept history")
        start, states = self.snapshots[-1]
        if start > self.first or len(self.snapshots) > 1:
            self.snapshots.pop()
        self._restore(states)
        self._rows = start - self.first + 1

    # ------------------------------------------------------------------ extension
    def ensure(self, time_s: float) -> None:
        """Compute the grid at least one step beyond `time_s`."""
        need = int(math.floor((time_s - self.t0) / self.h)) + 1
        if need <= self.last:
            return
        if need - self.first < 0:
            raise ValueError(f"simulated bench: t={time_s:g} s is before the kept history")
        if self.changed:
            self.horizon_s = _MIN_HORIZON_S
            self.changed = False
        else:
            self.horizon_s = min(2.0 * self.horizon_s, _MAX_HORIZON_S)
        self._extend(need + int(round(self.horizon_s / self.h)))

    def _extend(self, stop: int) -> None:
        k0 = self.last
        self.snapshots.append((k0, self._states()))
        idx = np.arange(k0 + 1, stop + 1)
        t = self._time(idx)
        vb, vd = self.amplifier_outputs(t)
        u = self.drive.run(vb, vd)
        x_s = self.surface.run(t)
        dx_s = np.diff(np.concatenate([self.cols["x_s"][-1:], x_s]))
        free = self.statics.free_position_m(u, k0 + 1, stop + 1)
        near = free > x_s - _NEAR_CONTACT_M
        force = np.zeros_like(u)
        if np.any(near) or self.statics.needs_history:
            force = self.statics.contact_force_N(u, x_s, dx_s, k0 + 1, stop + 1, near)
        # the contact mode's target: the sensor's compression (far from the surface only a guide back out: the
        # linear spring estimate, negative)
        contact = np.where(near, force, -self.spec.stiffness_N_per_m * (x_s - free)) / self.k_sensor
        x, mode, xi = self._integrate(x_s, free, contact)
        cum = self._force_integral(x_s, free, contact, mode, xi)
        drift = self.drift.run(k0 + 1, idx.size, t - self.t0) if self.drift else np.zeros(idx.size)
        self._store["mode"][self._rows - 1] = mode[0]
        self._store["xi"][self._rows - 1] = xi[0]
        self._append(x_s=x_s, x=x, u=u, free=free, contact=contact, mode=mode[1:], xi=xi[1:], cum_force=cum,
                     drift=drift)
        self.blocks += 1
        self.points += idx.size
        self._trim()

    def _integrate(self, x_s: np.ndarray, free: np.ndarray, contact: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x at the new points, and (mode, xi) for the previous last point and every new point.

        The free mode works in the plant's position x; the contact mode in the sensor's compression y = x - x_s,
        in the frame of the sensor's base: a moving stage then enters only through its acceleration, a force of
        (plant + sensor mass) x (stage acceleration), ~20 uN at the stage's 20 mm/s^2, which is left out.
        Touchdown: the free plant reaches the surface (x > x_s) where the quasi-static solution presses (target
        compression > 0); the crossing is found on the grid, so the plant is put on the surface there and shares
        momentum with the sensor's moving mass (which moves with the stage). Lift-off: the quasi-static force falls
        to 0; the plant leaves with its own velocity. Contact therefore never bounces, which a light contact on a
        real sensor may."""
        n = x_s.size
        xs_all = np.concatenate([self.cols["x_s"][-1:], x_s])
        v_s = np.diff(xs_all) / self.h                      # the surface's velocity over each step
        targets = (np.concatenate([self.cols["free"][-1:], free]),
                   np.concatenate([self.cols["contact"][-1:], contact]))
        presses = targets[1] > 0.0                          # the quasi-static solution is in contact
        mode_out = np.empty(n + 1, np.int8)
        xi_out = np.empty(n + 1, complex)
        x_out = np.empty(n)
        if not self.dynamics:
            flags = presses[1:].astype(np.int8)
            x_out[:] = np.where(flags == 1, x_s + contact, free)
            mode_out[0] = flags[0]
            mode_out[1:] = flags
            xi_out[:] = 0.0
            return x_out, mode_out, xi_out
        mode = int(self.cols["mode"][-1])
        q_arr, dq_arr = self._mode(mode).from_modal(complex(self.cols["xi"][-1]))   # the mode's own coordinate
        q, dq = float(q_arr), float(dq_arr)
        i = 0
        switches = 0
        while i < n:
            j = min(n, i + _CHUNK_STEPS)
            m = self._mode(mode)
            xi0 = m.to_modal(q, dq)
            xi = m.run(q, dq, targets[mode][i:j + 1])        # states at points i+1 .. j
            pos, vel = m.from_modal(xi)
            if mode:
                wrong = np.flatnonzero(~presses[i + 1:j + 1])
                absolute = pos + xs_all[i + 1:j + 1]
            else:
                wrong = np.flatnonzero((pos > xs_all[i + 1:j + 1]) & presses[i + 1:j + 1])
                absolute = pos
            switch = wrong.size > 0 and switches < _MAX_SWITCHES_PER_BLOCK
            stop = i + 1 + int(wrong[0]) if switch else j
            count = stop - i
            mode_out[i:stop] = mode
            xi_out[i] = xi0
            xi_out[i + 1:stop] = xi[:count - 1]
            x_out[i:stop] = absolute[:count]
            q, dq = float(pos[count - 1]), float(vel[count - 1])
            if switch:
                switches += 1
                surface_v = float(v_s[stop - 1])
                if mode:      # lift-off: the plant's own coordinate and velocity
                    q, dq = float(absolute[count - 1]), dq + surface_v
                else:         # touchdown: on the surface, momentum shared with the sensor's moving mass
                    q, dq = 0.0, self.impact_ratio * (dq - surface_v)
                    x_out[stop - 1] = xs_all[stop]
                mode = 1 - mode
            i = stop
        mode_out[n] = mode
        xi_out[n] = self._mode(mode).to_modal(q, dq)
        return x_out, mode_out, xi_out

    def _force_integral(self, x_s: np.ndarray, free: np.ndarray, contact: np.ndarray, mode: np.ndarray,
                        xi: np.ndarray) -> np.ndarray:
        """Cumulative integral of the sensed force at the new points (steps from the previous last point on)."""
        steps = np.zeros(x_s.size)
        in_contact = mode[:-1] == 1
        if np.any(in_contact):
            sel = np.flatnonzero(in_contact)
            tgt = np.concatenate([self.cols["contact"][-1:], contact])
            if self.dynamics:
                integral = self.contact_mode.step_integral(xi[sel], tgt[sel], tgt[sel + 1])
            else:
                integral = 0.5 * self.h * (tgt[sel] + tgt[sel + 1])
            steps[sel] = self.k_sensor * integral
        return float(self.cols["cum_force"][-1]) + np.cumsum(steps)

    def _trim(self) -> None:
        if self._rows > 2 * self.keep:
            drop = self._rows - self.keep
            for arr in self._store.values():
                arr[:self.keep] = arr[drop:self._rows]
            self._rows = self.keep
            self.first += drop
            self.snapshots = [s for s in self.snapshots if s[0] >= self.first]

    # ------------------------------------------------------------------ questions
    def _locate(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(row, time into the step) of each time; computes the grid far enough first."""
        t = np.asarray(times_s, dtype=float)
        if t.size:
            t_max = float(t.max()) if t.size > 1 else float(t.flat[0])
            self.ensure(t_max)
        f = (t - self.t0) * (1.0 / self.h)
        k = np.floor(f)
        row = k.astype(int) - self.first
        if row.size and int(row.min()) < 0:
            raise ValueError(f"simulated bench: t={float(t.min()):g} s is older than the kept history")
        return row, (f - k) * self.h

    def _positions(self, row: np.ndarray, tau: np.ndarray) -> np.ndarray:
        st = self._store
        if not self.dynamics:
            x = st["x"]
            return x[row] + (x[row + 1] - x[row]) * tau / self.h
        mode = st["mode"][row]
        first_mode = int(mode.flat[0]) if mode.size else 0
        if mode.size and not np.any(mode != first_mode):
            return self._within(first_mode, row, tau)
        out = np.empty(row.shape)
        for m_id in (0, 1):
            sel = mode == m_id
            if np.any(sel):
                out[sel] = self._within(m_id, row[sel], tau[sel])
        return out

    def _within(self, mode: int, row: np.ndarray, tau: np.ndarray, compression: bool = False) -> np.ndarray:
        """The position (or, in contact with `compression`, the sensor's compression) at tau into each row."""
        st = self._store
        if mode:
            y = self.contact_mode.within_step(st["xi"][row], st["contact"][row], st["contact"][row + 1], tau)
            if compression:
                return y
            x_s = st["x_s"][row] + (st["x_s"][row + 1] - st["x_s"][row]) * tau / self.h
            return x_s + y
        return self.free_mode.within_step(st["xi"][row], st["free"][row], st["free"][row + 1], tau)

    def positions_m(self, times_s: np.ndarray) -> np.ndarray:
        """The plant's position x at each time (exact between grid points)."""
        row, tau = self._locate(times_s)
        return self._positions(row, tau)

    def forces_N(self, times_s: np.ndarray) -> np.ndarray:
        """The force the sensor's element carries at each time (instantaneous, drift included)."""
        row, tau = self._locate(times_s)
        st = self._store
        contact = st["mode"][row] == 1
        force = np.zeros(row.shape)
        if np.any(contact):
            r, t = row[contact], tau[contact]
            if self.dynamics:
                y = self._within(1, r, t, compression=True)
            else:
                y = (st["x"][r] - st["x_s"][r]) + ((st["x"][r + 1] - st["x_s"][r + 1])
                                                   - (st["x"][r] - st["x_s"][r])) * t / self.h
            # not clipped at 0: in contact the plant and the sensor's element move as one (the contact holds until
            # the quasi-static force lets go), so ringing after a touchdown carries the element through zero as a
            # real load cell's does, and the averaged reading (`mean_force_N`) integrates the same signed force
            force[contact] = self.k_sensor * y
        if self.drift is not None:
            d = st["drift"]
            force += d[row] + (d[row + 1] - d[row]) * (tau / self.h)
        return force

    def mean_force_N(self, end_s: float, window_s: float) -> float:
        """The average sensed force over [end - window, end] (drift included): what a load cell that integrates
        over its conversion period reports, from the closed-form integral of each step."""
        row, tau = self._locate(np.array([end_s - window_s, end_s]))
        st = self._store
        cum = st["cum_force"][row].copy()
        contact = st["mode"][row] == 1
        if np.any(contact):
            r, t = row[contact], tau[contact]
            if self.dynamics:
                integral = self.contact_mode.partial_integral(st["xi"][r], st["contact"][r], st["contact"][r + 1], t)
            else:
                y0, y1 = st["contact"][r], st["contact"][r + 1]
                integral = t * y0 + (y1 - y0) * t * t / (2.0 * self.h)
            cum[contact] += self.k_sensor * integral
        mean = float((cum[1] - cum[0]) / window_s)
        if self.drift is not None:   # linear between grid points: the trapezoid of its samples in the window
            d = st["drift"]
            w = tau / self.h
            ends = d[row] + (d[row + 1] - d[row]) * w
            inner = d[row[0] + 1:row[1] + 1]
            times = np.concatenate([[0.0], self.h * (np.arange(1, inner.size + 1) - w[0]), [window_s]])
            values = np.concatenate([[ends[0]], inner, [ends[1]]])
            mean += float(np.trapezoid(values, times) / window_s)
        return mean

    def drive_state(self, times_s: np.ndarray) -> np.ndarray:
        """The free deflection u at each time (linear between grid points): for diagnostics and tests."""
        row, tau = self._locate(times_s)
        u = self.cols["u"]
        return u[row] + (u[row + 1] - u[row]) * tau / self.h
