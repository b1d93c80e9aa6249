"""The simulated robot's actuation: pressure regulators and the bellows' creep.

* :class:`PressureRegulators`: one proportional regulator per actuator: a
  set-point arrives after a dead time, passes a play (backlash) operator of
  width ``hysteresis_pa``, and the pressure follows it as a first-order lag
  ``tau dp/dt = w - p`` (exact between set-point changes), slew-limited and
  within the hardware limits ``[p_min, p_max]`` of the robot file.  The
  vent, a set-point of exactly 0 Pa gauge, opens the exhaust to atmosphere:
  it bypasses the play (the pressure goes to 0, not to the edge of the
  band, half the hysteresis away), with the same dead time and lag (the
  exhaust flow through the valve).
* :class:`BellowCreep`: the part ``fraction`` of each actuator's stage-1
  elongation (eq. 10) that follows a pressure change with time constant
  ``time_constant_s``; the equilibrium is solved at the *effective*
  pressure that gives the crept elongation.

Settings and sources: :mod:`bellow_ancf_ros.core.sim._plant_effects`.
Pressures are gauge pressures in Pa.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

__all__ = ['BellowCreep', 'PressureRegulators']


class PressureRegulators:
    """Regulators with dead time, play hysteresis, first-order lag, slew and hardware limits.

    ``set_command(p)`` hands new set-points (clipped into ``[p_min, p_max]``,
    as a regulator cannot exceed its supply) to the regulators at their
    current time; they take effect ``dead_time_s`` later.  ``step(dt)``
    advances the output pressures by ``dt`` seconds, piecewise exactly
    between the moments set-points take effect.  ``tau = 0`` follows the
    set-point at once (still slew-limited).
    """

    def __init__(self, n: int, p_min: float, p_max: float,
                 time_constant_s: float = 0.1, slew_rate_pa_per_s: float = 1.0e6,
                 initial_pa: Any = None, dead_time_s: float = 0.0,
                 hysteresis_pa: float = 0.0) -> None:
        """Regulators at ``initial_pa`` (default: vent, 0 Pa gauge) with that set-point."""
        if not (math.isfinite(p_min) and math.isfinite(p_max) and p_min < p_max):
            raise ValueError(f'pressure limits must be finite with p_min < p_max, got '
                             f'[{p_min}, {p_max}] Pa')
        for name, v in (('time_constant_s', time_constant_s), ('dead_time_s', dead_time_s),
                        ('hysteresis_pa', hysteresis_pa)):
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f'{name} must be >= 0, got {v}')
        if not (slew_rate_pa_per_s > 0):
            raise ValueError(f'slew_rate_pa_per_s must be > 0, got {slew_rate_pa_per_s}')
        self.n, self.p_min, self.p_max = int(n), float(p_min), float(p_max)
        self.time_constant_s = float(time_constant_s)
        self.slew_rate_pa_per_s = float(slew_rate_pa_per_s)
        self.dead_time_s = float(dead_time_s)
        self.hysteresis_pa = float(hysteresis_pa)
        start = np.clip(np.zeros(self.n), p_min, p_max) if initial_pa is None else initial_pa
        self.pressures_pa = self._checked(start)
        self.command_pa = self.pressures_pa.copy()     # the newest set-point received
        self.setpoint_pa = self.pressures_pa.copy()    # what the valves follow (after the play)
        self.time_s = 0.0
        self._pending: deque = deque()                 # (time it takes effect, set-point)

    def _checked(self, p: Any) -> np.ndarray:
        arr = np.array(p, dtype=float).ravel()
        if arr.size != self.n:
            raise ValueError(f'expected {self.n} pressures (one per actuator), got {arr.size}')
        if not np.isfinite(arr).all():
            raise ValueError('pressures must be finite numbers')
        return np.minimum(np.maximum(arr, self.p_min), self.p_max)   # (np.clip: slower)

    def set_command(self, p: Any, after_s: float = 0.0) -> None:
        """New set-points [Pa] (clipped into the hardware limits; NaN/inf raise ``ValueError``).

        ``after_s``: they arrived this long after the regulators' current time
        (a command between two physics steps takes effect when it arrived,
        plus the dead time, not at a step's edge).
        """
        c = self._checked(p)
        self.command_pa = c
        at = self.time_s + self.dead_time_s + max(float(after_s), 0.0)
        if self._pending and at < self._pending[-1][0]:
            at = self._pending[-1][0]   # in the order they arrived
        self._pending.append((at, c))

    def _advance(self, dt: float) -> None:
        """Follow the current set-point for ``dt`` (exact lag, slew-limited, clipped)."""
        if dt <= 0:
            return
        decay = math.exp(-dt / self.time_constant_s) if self.time_constant_s > 0 else 0.0
        gain = 1.0 - decay
        max_step = self.slew_rate_pa_per_s * dt
        lo, hi = self.p_min, self.p_max
        # (plain floats: at a robot's few actuators numpy's per-call cost was most of the step)
        out = []
        for p, w in zip(self.pressures_pa.tolist(), self.setpoint_pa.tolist()):
            move = min(max((w - p) * gain, -max_step), max_step)
            out.append(min(max(p + move, lo), hi))
        self.pressures_pa = np.array(out)
        self.time_s += dt

    def step(self, dt: float) -> np.ndarray:
        """Advance by ``dt`` >= 0 seconds; returns the output pressures [Pa]."""
        dt = float(dt)
        if not (math.isfinite(dt) and dt >= 0):
            raise ValueError(f'dt must be a finite non-negative time, got {dt}')
        end = self.time_s + dt
        half = 0.5 * self.hysteresis_pa
        while self._pending and self._pending[0][0] <= end:
            t_on, c = self._pending.popleft()
            self._advance(t_on - self.time_s)
            # play operator: the valve moves only when the set-point leaves the band; the
            # vent (0 Pa gauge) opens the exhaust to atmosphere instead: no play
            self.setpoint_pa = np.where(c == 0.0, 0.0, np.minimum(
                np.maximum(self.setpoint_pa, c - half), c + half))
        self._advance(end - self.time_s)
        self.time_s = end
        return self.pressures_pa.copy()


class BellowCreep:
    """Creep of the bellows: a part of the stage-1 elongation follows the pressure with a lag.

    With ``x(p) = lambda(p) - 1`` the stage-1 elongation (eq. 10) and ``s``
    its slow part (``T ds/dt = x(p) - s``, exact for the pressure held over a
    step), the bellows stand at the elongation
    ``x_eff = (1 - fraction) x(p) + fraction s``; :meth:`step` returns the
    pressure that gives ``x_eff`` in stage 1 (its explicit inverse), so that
    stage 2 sees the crept stretch and its stiffnesses.  At rest ``s = x``
    and the effective pressure is the applied one.
    """

    def __init__(self, stage1, fraction: float, time_constant_s: float,
                 initial_pa: Any) -> None:
        """Creep at rest at ``initial_pa`` (``stage1``: the robot's :class:`Stage1`)."""
        if not (0.0 <= fraction < 1.0):
            raise ValueError(f'creep fraction must be in [0, 1), got {fraction}')
        if not (math.isfinite(time_constant_s) and time_constant_s > 0):
            raise ValueError(f'creep time constant must be > 0, got {time_constant_s}')
        self.stage1 = stage1
        self.fraction, self.time_constant_s = float(fraction), float(time_constant_s)
        p = np.array(initial_pa, dtype=float)
        self.slow = np.asarray(stage1.stretch(p), dtype=float) - 1.0

    def step(self, pressures_pa: np.ndarray, dt: float) -> np.ndarray:
        """Advance by ``dt`` with ``pressures_pa`` applied; the effective pressures [Pa]."""
        p = np.asarray(pressures_pa, dtype=float)
        if self.fraction == 0.0:
            return p.copy()
        decay = math.exp(-float(dt) / self.time_constant_s)
        f = self.fraction
        # (plain floats: at a robot's few actuators numpy's per-call cost was most of the step)
        slow, lam_eff = [], []
        for lam, s in zip(np.asarray(self.stage1.stretch(p), dtype=float).ravel().tolist(),
                          self.slow.ravel().tolist()):
            x = lam - 1.0
            s = x + (s - x) * decay
            slow.append(s)
            lam_eff.append(1.0 + ((1.0 - f) * x + f * s))
        self.slow = np.array(slow)
        return np.asarray(self.stage1.pressure(np.array(lam_eff)), dtype=float)
