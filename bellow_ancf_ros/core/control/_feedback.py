"""Closed-loop correction from measured poses: integral action on the task-space error.

The feedforward controller (inverse kinetostatics, eqs. 28-30) computes the
pressures that put the *model* at the target.  The real robot differs from
its model, so it settles elsewhere.  :class:`IntegralFeedback` shifts the
target handed to the inverse by a correction that integrates the measured
task-space error::

    e_p = p_target(t_m) - p_measured(t_m)          (position error, m)
    c_p <- clamp(c_p + k dt e_p, max_correction_m)
    p_handed_to_inverse = p_target + c_p

and, for robots with two or more segments, the end-effector z-axis
(rotation vectors, rad)::

    e_r = angle(z_measured -> z_target) * unit(z_measured x z_target)   (both at t_m)
    c_r <- clamp(c_r + k dt e_r, max_correction_rad)   (component along z_target removed)
    z_handed_to_inverse = Rot(c_r) z_target

``k`` is ``gain_per_s`` (1/s): an error is integrated away with time
constant ``1/k`` once the regulators (0.1 s) have followed.  ``t_m`` is the
time the measurement was *taken* (its stamp): it is compared with the target
that was in effect then, not with the newest one, so that the transport
delay of the measurement does not turn the target's motion into a spurious
error (a moving target would otherwise be led by ``speed * delay``).

Safeguards
----------
* **Anti-windup**: while the last inverse solve was unreachable or had
  pressures at a limit, a step that would grow the correction is not taken
  (one that shrinks it is); when the corrected target was unreachable the
  correction is also cut back to the part the model could realise
  (back-calculation).  The correction can therefore never wind up beyond
  the clamp, and an unreachable target leaves it bounded.
* **No command, no integration**: when the inverse gives no usable answer
  for the corrected target (a failed or unstable solve, e.g. a payload
  beyond the buckling load: nothing is sent, the last command stands), the
  caller says so (:meth:`IntegralFeedback.no_command`) and the integrator is
  frozen (state ``HELD``) until a solve's answer goes out again
  (:meth:`IntegralFeedback.report`): the robot did not move because of the
  correction, so its error says nothing about the correction.
* **Reset**: a target jump larger than ``reset_jump_m`` (or
  ``reset_jump_rad``) clears the correction (the old one belongs elsewhere
  in the workspace).
* **Fallback to pure feedforward**: when the newest accepted measurement is
  older than ``measured_pose_timeout_s``, or the newest measurement jumped
  implausibly far from the one before (more than ``max_measurement_jump_m``
  / ``max_measurement_jump_rad``), the uncorrected target is handed to the
  inverse and the integrator is frozen (kept, not integrated).  When fresh,
  plausible measurements return, the held correction is applied again and
  integration resumes.
* Each measurement is integrated once, over the time since the previous
  integration, capped at ``max_dt_s`` (a late control step does not make a
  large jump; control faster than the measurements does not integrate an
  old error twice).

Times are plain floats in seconds from one monotonic clock, supplied by the
caller (the ROS node uses ``time.monotonic()``; tests use simulated time).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..geometry import rotation_between, rotation_from_vector

__all__ = ['FEEDBACK_MODES', 'FeedbackSettings', 'IntegralFeedback']

#: Targets older than this are forgotten [s] (measurements are compared with the target then).
HISTORY_S = 2.0

#: Values of the inverse node's ``feedback`` parameter.
FEEDBACK_MODES = ('none', 'integral')

# states (``IntegralFeedback.state``)
WAITING = 'waiting for measured_pose'
TRACKING = 'integrating'
SATURATED = 'holding (pressure limit or unreachable target)'
STALE = 'fallback to feedforward: measured_pose too old'
JUMP = 'fallback to feedforward: measured_pose jumped implausibly'
HELD = 'frozen: no command went out for the corrected target'


@dataclass(frozen=True)
class FeedbackSettings:
    """Gains, limits and timeouts of :class:`IntegralFeedback` (SI units)."""

    gain_per_s: float = 2.5
    max_correction_m: float = 0.010
    max_correction_rad: float = math.radians(10.0)
    measured_pose_timeout_s: float = 0.25
    max_measurement_jump_m: float = 0.010
    max_measurement_jump_rad: float = math.radians(10.0)
    reset_jump_m: float = 0.010
    reset_jump_rad: float = math.radians(10.0)
    max_dt_s: float = 0.1

    def __post_init__(self) -> None:
        """Refuse a non-positive or non-finite setting, naming it."""
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f'feedback setting {f.name} must be a positive finite number, '
                                 f'got {v!r}')


def _clamp(v: np.ndarray, limit: float) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v * (limit / n) if n > limit else v


class IntegralFeedback:
    """Integral task-space correction of the target (see the module docstring).

    Use: :meth:`measurement` for every measured pose, :meth:`corrected_target`
    once per control step (returns what to hand to the inverse), then
    :meth:`report` with the inverse's outcome.
    """

    def __init__(self, settings: FeedbackSettings | None = None,
                 use_orientation: bool = False) -> None:
        """Start with no correction; ``use_orientation`` for two or more segments."""
        self.settings = settings or FeedbackSettings()
        self.use_orientation = bool(use_orientation)
        self.reset()
        self._meas_t: float | None = None
        self._meas_p = self._meas_z = None
        self._prev_p = self._prev_z = None       # newest received sample (accepted or not)
        self._meas_ok = False
        self.rejected = 0
        self.resets = 0

    # ------------------------------------------------------------ state
    def reset(self) -> None:
        """Clear the correction (the integrator state)."""
        self.correction_m = np.zeros(3)
        self.correction_rad = np.zeros(3)
        self._last_t: float | None = None
        self._used_meas_t: float | None = None
        self._history: deque = deque()    # (time, target position, target z-axis)
        self._target_p = self._target_z = None
        self._saturated = False
        self._held = False
        self.state = WAITING

    @property
    def fallback(self) -> bool:
        """True while the pure feedforward target is used (stale or implausible measurements)."""
        return self.state in (STALE, JUMP, WAITING)

    # ------------------------------------------------------------ inputs
    def measurement(self, t: float, position: Any, z_axis: Any = None) -> bool:
        """Record a pose measured (taken) at time ``t``; False if refused as an implausible jump.

        A sample farther than the jump limits from the previous *received*
        sample is refused (the next one is compared with it, so a real,
        lasting change is accepted one sample later; an isolated spike costs
        two samples).
        """
        p = np.asarray(position, dtype=float).reshape(3)
        z = None if z_axis is None else np.asarray(z_axis, dtype=float).reshape(3)
        if not np.all(np.isfinite(p)) or (z is not None and not np.all(np.isfinite(z))):
            raise ValueError('measured pose must be finite')
        if z is not None:
            z = z / np.linalg.norm(z)
        s = self.settings
        plausible = True
        if self._prev_p is not None:
            if np.linalg.norm(p - self._prev_p) > s.max_measurement_jump_m:
                plausible = False
            if self.use_orientation and z is not None and self._prev_z is not None:
                turn = float(np.linalg.norm(rotation_between(self._prev_z, z)))
                plausible = plausible and turn <= s.max_measurement_jump_rad
        self._prev_p, self._prev_z = p, z
        self._meas_ok = plausible
        if not plausible:
            self.rejected += 1
            return False
        self._meas_t, self._meas_p, self._meas_z = float(t), p, z
        return True

    def measurement_age(self, t: float) -> float | None:
        """Age [s] of the newest accepted measurement at time ``t`` (None: none yet)."""
        return None if self._meas_t is None else float(t) - self._meas_t

    # ------------------------------------------------------------ control step
    def corrected_target(self, t: float, position: Any, z_axis: Any = None):
        """The target to hand to the inverse at time ``t``: ``(position, z_axis or None)``.

        Integrates the newest measured error first (unless a safeguard says
        otherwise); see the module docstring.
        """
        s = self.settings
        p_t = np.asarray(position, dtype=float).reshape(3)
        z_t = None
        if self.use_orientation:
            z_t = np.asarray(z_axis, dtype=float).reshape(3)
            z_t = z_t / np.linalg.norm(z_t)
        if self._target_p is not None and (
                np.linalg.norm(p_t - self._target_p) > s.reset_jump_m
                or (z_t is not None and np.linalg.norm(rotation_between(self._target_z, z_t))
                    > s.reset_jump_rad)):
            self.reset()
            self.resets += 1
        self._target_p, self._target_z = p_t, z_t
        self._history.append((float(t), p_t, z_t))
        while len(self._history) > 2 and self._history[1][0] < float(t) - HISTORY_S:
            self._history.popleft()
        age = self.measurement_age(t)
        if age is None:
            self.state = WAITING
        elif not self._meas_ok:
            self.state = JUMP
        elif age > s.measured_pose_timeout_s:
            self.state = STALE
        elif self._held:
            self.state = HELD
            self._last_t, self._used_meas_t = float(t), self._meas_t   # nothing to catch up
        elif self._meas_t != self._used_meas_t:
            # each measurement is integrated once, over the time since the last integration
            dt = 0.0 if self._last_t is None else min(max(float(t) - self._last_t, 0.0),
                                                      s.max_dt_s)
            self._last_t, self._used_meas_t = float(t), self._meas_t
            self._integrate(dt, p_t, z_t)
        if self.state in (STALE, JUMP):
            self._last_t = None   # integration restarts with dt = 0 on recovery
        if self.fallback:
            return p_t.copy(), None if z_t is None else z_t.copy()
        return self._apply(p_t, z_t)

    def _target_at(self, t: float):
        """The target in effect at time ``t`` (None before the first one since a reset)."""
        found = None
        for entry in self._history:
            if entry[0] > t:
                break
            found = entry
        return None if found is None else found[1:]

    def _integrate(self, dt: float, p_now: np.ndarray, z_now: np.ndarray | None) -> None:
        s = self.settings
        then = self._target_at(self._meas_t)
        if then is None:          # measured before the current targets began: nothing to compare
            self.state = TRACKING
            return
        p_t, z_t = then
        k = s.gain_per_s * dt
        c_new = _clamp(self.correction_m + k * (p_t - self._meas_p), s.max_correction_m)
        r_new = self.correction_rad
        if self.use_orientation and self._meas_z is not None:
            r = self.correction_rad + k * rotation_between(self._meas_z, z_t)
            r_new = _clamp(r - (r @ z_now) * z_now, s.max_correction_rad)
        if self._saturated:
            # anti-windup: only unwind while the inverse is at a limit
            if np.linalg.norm(c_new) > np.linalg.norm(self.correction_m):
                c_new = self.correction_m
            if np.linalg.norm(r_new) > np.linalg.norm(self.correction_rad):
                r_new = self.correction_rad
            self.state = SATURATED
        else:
            self.state = TRACKING
        self.correction_m, self.correction_rad = c_new, r_new

    def _apply(self, p_t: np.ndarray, z_t: np.ndarray | None):
        p = p_t + self.correction_m
        if z_t is None:
            return p, None
        return p, rotation_from_vector(self.correction_rad) @ z_t

    def report(self, reachable: bool, at_limit: bool, achieved_position: Any = None,
               achieved_z_axis: Any = None) -> None:
        """The inverse's outcome for the last corrected target (anti-windup input).

        ``achieved_*``: the model's pose for the pressures it returned; with
        an unreachable target the correction is cut back to what it realised.
        """
        self._saturated = bool((not reachable) or at_limit)
        self._held = False
        if reachable or self.fallback or achieved_position is None or self._target_p is None:
            return
        s = self.settings
        c_real = np.asarray(achieved_position, dtype=float).reshape(3) - self._target_p
        if np.linalg.norm(c_real) < np.linalg.norm(self.correction_m):
            self.correction_m = _clamp(c_real, s.max_correction_m)
        if self.use_orientation and achieved_z_axis is not None:
            r_real = rotation_between(self._target_z, achieved_z_axis)
            if np.linalg.norm(r_real) < np.linalg.norm(self.correction_rad):
                self.correction_rad = _clamp(r_real, s.max_correction_rad)

    def no_command(self) -> None:
        """No command went out for the last corrected target: freeze the integrator.

        Kept (and still applied to the target) but not integrated until the
        next :meth:`report` of an answer that went out.
        """
        self._held = True

    def status(self, t: float) -> dict:
        """Diagnostics values: state, correction, measurement age, counters."""
        age = self.measurement_age(t)
        return {
            'feedback_state': self.state,
            'feedback_correction_mm': f'{np.linalg.norm(self.correction_m) * 1e3:.3f}',
            'feedback_correction_deg': f'{math.degrees(np.linalg.norm(self.correction_rad)):.3f}',
            'measured_pose_age_s': 'none' if age is None else f'{age:.3f}',
            'measured_poses_implausible': self.rejected,
            'feedback_resets': self.resets,
        }
