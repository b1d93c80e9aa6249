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
constant ``1/k`` once the regulators have followed.  ``t_m`` is the time the
measurement was *taken* (its stamp): it is compared with the target wanted
then (interpolated between the targets around it), not with the newest one,
so that the measurement's latency does not turn the target's motion into a
spurious error (a moving target would otherwise be led by ``speed * delay``).

**Azimuthal frame** (``correction_frame = 'azimuthal'``, the default): the
correction is integrated in a frame that turns with the target's azimuth
about the base z-axis (``e_p`` measured at the target's azimuth then is
turned to the current target's azimuth before it is added).  The robot is
symmetric about its base z-axis (identical actuators at equal angles), so the
error a mismatch of its shared parameters (pitch radius, ``D_a``, stiffness,
masses) causes turns with the azimuth: constant in this frame, it is learned
once, and a circle about the axis is tracked without the lag a base-frame
integrator has while its correction turns (``bench/effects_bench.py``, the
realistic robot, two-segment bending circle at four times the paper's speed:
0.155 mm RMSE against 5.187 mm in the base frame).  An error fixed in the
base frame (a mocap offset, one actuator stiffer than the others) turns in
this frame instead:
``correction_frame = 'base'`` integrates in the base frame.  Within
:data:`AZIMUTH_MIN_RADIUS_M` of the axis the azimuth is undefined and the
last one is kept.

**Model** (``correction_frame = 'model'``): azimuthal, and at every jump
of the targets (a move of :class:`~._jumps.JumpTransition`) the correction
held is read as a mismatch of the robot file's parameters and carried to
the move's goal through the model (:class:`~._mismatch.MismatchTransfer`,
given by the caller), along the move; the loop then refines it there.  The
correction a stiffness, geometry or mass mismatch asks for changes with the
pose, which neither frame follows (the shipped two-segment mismatched robot,
creep and play compensated: 0.58 mm off 1.5 s after a 10 mm step in the
azimuthal frame, 0.24-0.35 mm carried once, 0.05-0.11 mm carried and asked
again at the goal's pressures, :data:`CARRY_AGAIN`; one segment: 1.68 mm of
overshoot, 0.12 mm).  It assumes the correction held is the static mismatch:
with the regulators' play or the bellows' creep not compensated, the correction
holds their offsets too, which the transfer then carries the wrong way
(for a lab that compensates both, ``regulator_play_kpa`` and
``creep_fraction``).

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
* **A move of the controller's own**: a jump of the target stream made a
  smooth move (:class:`~._jumps.JumpTransition`) is not a mismatch: the
  caller passes ``hold_until`` and measurements captured before it are not
  integrated (state ``MOVING``); the correction stays applied.  A jump does
  not clear the correction either: in the azimuthal frame it is the robot's
  mismatch, which holds across the workspace.
* **Outliers** (a swapped or ghost marker): a measurement farther than
  ``outlier_gate_m`` (or ``outlier_gate_rad``) from the median of the last
  :data:`OUTLIER_WINDOW` received measurements is not integrated; the
  correction stays as it is and keeps being applied, so a single wrong sample
  moves no command.  A real, lasting change of the measurements moves the
  median and is accepted a few samples later.
* **Dropouts**: when the newest accepted measurement is older than
  ``measured_pose_timeout_s`` the integrator is frozen and the correction it
  holds stays applied (state ``STALE``); when measurements return,
  integration resumes over the time since their return (no catch-up step),
  so the commands do not jump.  Only before the first measurement (state
  ``WAITING``) is the pure feedforward target handed on.
* **Capture time**: a measurement is compared with the target *wanted* at
  the time it was taken: targets carry the time they are wanted at (a
  target stamped in the future, from a trajectory source that previews the
  regulators' lag, is wanted then), measurements the time they were
  captured (the mocap's latency is thereby taken out).
* Each accepted measurement is integrated once: at a control step, every
  one accepted since the previous integration is compared with the target
  wanted at its capture time, and their mean is integrated over the time
  since the previous integration, capped at ``max_dt_s`` (a late control
  step does not make a large jump; control faster than the measurements
  does not integrate an old error twice; a motion capture faster than the
  control steps averages its noise instead of dropping all but the newest
  sample).

Times are plain floats in seconds from one monotonic clock, supplied by the
caller (the ROS node uses ``time.monotonic()``; tests use simulated time).

Stability with the loop's lag and delay (:func:`~._loop_margins.loop_margins`): seen from the
correction, the robot answers like the regulators, a first-order lag ``tau``
after a delay ``T`` (regulator dead time, mocap latency, half a control
period, half a physics step), so the open loop is
``L(s) = k exp(-s T) / (s (tau s + 1))``.  The default gain 2.5 /s with
``tau`` = 0.06 s and ``T`` = 0.05 s has a phase margin of about 74 deg and a
gain margin of about 10 (the gain could be ten times higher before the loop
oscillates); a model-robot mismatch of 10 % in the robot's static gain
changes ``k`` by as much, far inside that margin.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..geometry import rotation_between, rotation_from_vector, rotation_z
from ..history import bracket
from ..solve import solve_inverse
from ..status import InverseStatus
from ._median_gate import WINDOW, MedianGate
from ._mismatch import ROTATION_LENGTH_M, MismatchTransfer
from ._mocap_noise import NOISE_GATE_S, MocapNoise
from ._watchdog import OscillationWatchdog

__all__ = ['FEEDBACK_MODES', 'FeedbackSettings', 'IntegralFeedback']

#: Targets older than this are forgotten [s] (measurements are compared with the target then).
HISTORY_S = 2.0
#: Received measurements whose median an accepted one must lie near (outlier gate).
OUTLIER_WINDOW = WINDOW
#: Accepted measurements kept for the next integration (a 1 kHz motion capture, 50 ms).
MAX_PENDING = 50

#: Values of the inverse node's ``feedback`` parameter.
FEEDBACK_MODES = ('none', 'integral')
#: Frames the correction is integrated in (``FeedbackSettings.correction_frame``).
CORRECTION_FRAMES = ('azimuthal', 'base', 'model')
#: Targets nearer the base z-axis than this [m] keep the last azimuth (it is undefined on it).
AZIMUTH_MIN_RADIUS_M = 0.002

# states (``IntegralFeedback.state``)
WAITING = 'waiting for measured_pose'
NO_TARGET = 'measured poses arriving, waiting for a target'
TRACKING = 'integrating'
SATURATED = 'holding (pressure limit or unreachable target)'
STALE = 'holding the correction: measured_pose too old (dropout)'
OUTLIER = 'holding the correction: newest measured_pose is an outlier'
HELD = 'frozen: no command went out for the corrected target'
OSCILLATING = 'holding the correction: oscillation seen, gain cut'
MOVING = 'holding the correction: a move of its own (a target jump, a stopped stream braking)'

#: A gain the watchdog cut is doubled back (up to the full gain) after this long without a
#: trip [s]: a swing from outside the loop (a knock, a target stream that rang the robot) is not
#: the loop's own, and a gain cut for the rest of a run left a lab-style trial's robot 2-3 mm
#: off a held target.  A trip within this long after such a restore keeps the cut for good:
#: the loop itself rang (a gain too high for the robot rings again within a few periods).
RESTORE_S = 20.0
#: Time budget of the inverse solve that carries the correction to a jump's goal [s].
CARRY_BUDGET_S = 0.02
#: Times the carried correction is solved for at the goal and asked again
#: (:meth:`~._mismatch.MismatchTransfer.again`).
CARRY_AGAIN = 2
#: A carried correction differs from the azimuthally turned one by at most this share of the
#: move's length: the family's static mismatch (25 one- and 49 two-segment robots and the
#: shipped mismatched ones, a 10 mm step across the bend) asks for at most 1.45 mm; a fit of
#: one held pose that extrapolates badly (a robot 1.9 times as heavy as its file) for 4 mm.
CARRY_SHARE = 0.15


@dataclass(frozen=True)
class FeedbackSettings:
    """Gains, limits and timeouts of :class:`IntegralFeedback` (SI units)."""

    gain_per_s: float = 2.5
    max_correction_m: float = 0.020
    max_correction_rad: float = math.radians(10.0)
    measured_pose_timeout_s: float = 0.25
    outlier_gate_m: float = 0.005
    outlier_gate_rad: float = math.radians(5.0)
    max_dt_s: float = 0.1
    correction_frame: str = 'azimuthal'

    def __post_init__(self) -> None:
        """Refuse a non-positive or non-finite setting, naming it."""
        if self.correction_frame not in CORRECTION_FRAMES:
            raise ValueError(f'feedback setting correction_frame: {self.correction_frame!r} is '
                             f'not one of {list(CORRECTION_FRAMES)}')
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == 'correction_frame':
                continue
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f'feedback setting {f.name} must be a positive finite number, '
                                 f'got {v!r}')


def _turn_from_median(z: np.ndarray, median: np.ndarray) -> float:
    """Angle [rad] from the (renormalised) median z-axis to ``z``; 0 for a zero median."""
    n = float(np.linalg.norm(median))
    return float(np.linalg.norm(rotation_between(median / n, z))) if n > 0 else 0.0


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
                 use_orientation: bool = False,
                 transfer: MismatchTransfer | None = None) -> None:
        """Start with no correction; ``use_orientation`` for two or more segments.

        ``transfer``: carries the correction to the goal of every jump's
        move (:class:`~._mismatch.MismatchTransfer`; None: the correction
        stays as it was learned).
        """
        self.settings = settings or FeedbackSettings()
        self.use_orientation = bool(use_orientation)
        self.transfer = transfer
        self.reset()
        self._meas_t: float | None = None
        self._meas_p = self._meas_z = None
        self._pending: list = []    # accepted (t, position, z-axis) not yet integrated
        s = self.settings
        self._gate_p = MedianGate(s.outlier_gate_m)
        self._gate_z = MedianGate(s.outlier_gate_rad, distance=_turn_from_median)
        self._outlier = False       # the newest received sample was an outlier
        self.rejected = 0
        self.watchdog: OscillationWatchdog | None = None
        self.base_gain_per_s = float(self.settings.gain_per_s)   # set_gain: the automatic one
        self._automatic = False     # set_gain was called: the motion capture's noise caps it
        self.noise = MocapNoise()   # of the accepted positions (the automatic gain's cap)
        self.gain_scale = 1.0       # cut by the watchdog on every trip, restored (RESTORE_S)
        self.restores = 0           # cuts undone after RESTORE_S without a trip
        self.restorable = True      # False: a trip came within RESTORE_S of a restore
        self._trip_t = -math.inf    # the newest trip (or restore): RESTORE_S counts from it
        self._restore_t = -math.inf
        self._hold_until = -math.inf
        self._move_until = -math.inf   # a jump's move (and its settling) ends then

    # ------------------------------------------------------------ state
    def reset(self) -> None:
        """Clear the correction (the integrator state)."""
        self._phi = 0.0                   # azimuth of the current target (azimuthal frame)
        self._c = np.zeros(3)             # correction in the frame turned by _phi
        self._r = np.zeros(3)
        self._last_t: float | None = None
        self._used_meas_t: float | None = None
        self._pending = []
        self._history: deque = deque()    # (wanted-at time, target position, target z-axis)
        self._command_p = self._command_z = None
        self._saturated = False
        self._held = False
        self._mean_error: np.ndarray | None = None   # over NOISE_GATE_S (the noise cap's gate)
        self._held_inverse = None   # the inverse's answer for the last command that went out
        self._move_seen = None      # the start time of the newest move carried to its goal
        self._carry = None          # (from, to, start, goal, until): the correction carried
        self.carries = [0, 0]       # corrections carried to a jump's goal: tried, cut short
        self.state = WAITING

    @property
    def correction_m(self) -> np.ndarray:
        """The position correction [m, base frame] at the current target."""
        return rotation_z(self._phi) @ self._c

    @correction_m.setter
    def correction_m(self, value: np.ndarray) -> None:
        self._c = rotation_z(-self._phi) @ np.asarray(value, dtype=float)

    @property
    def correction_rad(self) -> np.ndarray:
        """The z-axis correction (rotation vector [rad], base frame) at the current target."""
        return rotation_z(self._phi) @ self._r

    @correction_rad.setter
    def correction_rad(self, value: np.ndarray) -> None:
        self._r = rotation_z(-self._phi) @ np.asarray(value, dtype=float)

    def _azimuth(self, p: np.ndarray) -> float:
        """Azimuth of a target about the base z-axis (the last one near the axis; base: 0)."""
        if self.settings.correction_frame == 'base':   # ('model': azimuthal between jumps)
            return 0.0
        if math.hypot(p[0], p[1]) < AZIMUTH_MIN_RADIUS_M:
            return self._phi
        return math.atan2(p[1], p[0])

    @property
    def fallback(self) -> bool:
        """True while the pure feedforward target is used (no measurement yet)."""
        return self.state == WAITING

    @property
    def blind(self) -> bool:
        """True while no fresh measurement arrives: none yet, or a dropout (state ``STALE``)."""
        return self.state in (WAITING, STALE)

    @property
    def frozen(self) -> bool:
        """True while the integrator holds its correction (dropout, outlier, no command, move)."""
        return self.state in (STALE, OUTLIER, HELD, MOVING)

    # ------------------------------------------------------------ inputs
    def watch(self, frequency_hz: float) -> None:
        """Watch the measured error for an oscillation near this mode (the robot's first).

        On a trip (:class:`~._watchdog.OscillationWatchdog`) the gain is
        halved (:attr:`gain_scale`) and the correction is held for one
        window (state ``OSCILLATING``); :attr:`watchdog` ``.last_trip`` says
        what was seen.  After :data:`RESTORE_S` of integrating without a
        trip the cut is doubled back (:attr:`restores`), unless a trip came
        within that time of a restore (:attr:`restorable` False).  A new
        frequency (a payload moved the mode) keeps the cut gain.  Samples
        captured while a move of the controller's own holds the correction
        (``hold_until`` of :meth:`corrected_target`) are not watched: the
        loop is open then, and its windows start again after the move.
        """
        if self.watchdog is None:
            self.watchdog = OscillationWatchdog(frequency_hz)
        elif abs(self.watchdog.frequency_hz - frequency_hz) > 1e-9:
            self.watchdog.set_mode(frequency_hz)

    def set_gain(self, gain_per_s: float) -> None:
        """Integrate with this gain from now on (an automatic gain that follows the mode).

        The motion capture's noise holds it down (:attr:`gain_per_s`); the
        watchdog's cuts still apply on top of it.
        """
        k = float(gain_per_s)
        if not (math.isfinite(k) and k > 0):
            raise ValueError(f'gain_per_s must be > 0, got {gain_per_s!r}')
        self.base_gain_per_s = k
        self._automatic = True

    @property
    def gain_per_s(self) -> float:
        """The integral gain in use: the set gain times the watchdog's cuts.

        An automatic gain (:meth:`set_gain`) is held at the gain at which the
        motion capture's noise, estimated from the accepted samples, moves
        the robot by 0.05 mm RMS while the mean error is within its noise,
        and is given in full when it is not
        (:meth:`~._mocap_noise.MocapNoise.allowed_gain`); the settings'
        fixed gain is used as it is.
        """
        k = self.base_gain_per_s
        if self._automatic:
            e = None if self._mean_error is None else float(np.linalg.norm(self._mean_error))
            k = self.noise.allowed_gain(k, e)
        return k * self.gain_scale

    def measurement(self, t: float, position: Any, z_axis: Any = None) -> bool:
        """Record a pose captured at time ``t``; False if refused as an outlier.

        An outlier (farther than the gate from the median of the last
        :data:`OUTLIER_WINDOW` received samples, this one excluded) is
        counted in :attr:`rejected` and never integrated.
        """
        p = np.asarray(position, dtype=float).reshape(3)
        z = None if z_axis is None else np.asarray(z_axis, dtype=float).reshape(3)
        if not np.all(np.isfinite(p)) or (z is not None and not np.all(np.isfinite(z))):
            raise ValueError('measured pose must be finite')
        if z is not None:
            z = z / np.linalg.norm(z)
        # both gates see every sample (each remembers it), then either may refuse it
        far_p = self._gate_p.refuses(p)
        far_z = self.use_orientation and z is not None and self._gate_z.refuses(z)
        self._outlier = far_p or far_z
        if self._outlier:
            self.rejected += 1
            return False
        self._meas_t, self._meas_p, self._meas_z = float(t), p, z
        self._pending.append((float(t), p, z))
        if self.state == WAITING:   # (a control step says more once a target is there)
            self.state = NO_TARGET
        self.noise.add(float(t), p)
        if len(self._pending) > MAX_PENDING:   # (no control step for a while: the newest)
            del self._pending[0]
        if self.watchdog is not None and self._history:
            if float(t) < self._move_until:
                # a move of the controller's own holds the correction: the loop is open,
                # nothing of it can ring, and the move's own transient (the robot lagging the
                # move, its residual swing) grew from window to window as the move went on
                # (the shipped one-segment robot's 10 mm step on the wall clock: 0.40 mm at
                # 10 Hz "growing 3 times in a row" 0.39 s after the step, in two runs of
                # three): its windows start again after it
                self.watchdog.reset()
                return True
            # every accepted sample, at the measurements' rate: a control step is too slow
            # to see a swing near a stiff robot's mode
            then = self._target_at(float(t))
            trip = None if then is None else self.watchdog.feed(float(t), then[0] - p)
            if trip is not None:
                self.gain_scale *= 0.5
                self._hold_until = float(t) + self.watchdog.window_s
                if float(t) - self._restore_t < RESTORE_S:
                    self.restorable = False   # rang again after a restore: the loop's own
                self._trip_t = float(t)
        return True

    def measurement_age(self, t: float) -> float | None:
        """Age [s] of the newest accepted measurement at time ``t`` (None: none yet)."""
        return None if self._meas_t is None else float(t) - self._meas_t

    # ------------------------------------------------------------ control step
    def corrected_target(self, t: float, position: Any, z_axis: Any = None,
                         wanted_at: float | None = None, command: tuple | None = None,
                         hold_until: float | None = None, move: tuple | None = None):
        """The target to hand to the inverse at time ``t``: ``(position, z_axis or None)``.

        ``wanted_at``: the time the target is wanted at (default ``t``; later
        for a target that previews the robot's lag).  ``command``: the
        ``(position, z_axis)`` to correct and hand on, when it is not the pose
        wanted (a dynamic feedforward shifts the command by the motion's
        loads; the measured pose is still compared with the pose wanted).
        ``hold_until``: measurements captured before this time are not
        integrated (a jump's move is running, :class:`~._jumps.JumpTransition`).
        ``move``: that move, ``(start time, start position, goal position,
        goal z-axis)`` (:attr:`~._jumps.JumpTransition.move`): a new one
        carries the correction to its goal (:meth:`_carry_to`), along the
        move.  Integrates the newest accepted measurement first (unless a
        safeguard says otherwise); see the module docstring.
        """
        if hold_until is not None:   # (the caller's: a brake cut short ends earlier)
            self._move_until = float(hold_until)
        if move is not None and move[0] != self._move_seen:
            self._move_seen = move[0]
            self._carry_to(move)
        s = self.settings
        p_t = np.asarray(position, dtype=float).reshape(3)
        z_t = None
        if self.use_orientation:
            z_t = np.asarray(z_axis, dtype=float).reshape(3)
            z_t = z_t / np.linalg.norm(z_t)
        p_c, z_c = p_t, z_t
        if command is not None:
            p_c = np.asarray(command[0], dtype=float).reshape(3)
            if self.use_orientation:
                z_c = np.asarray(command[1], dtype=float).reshape(3)
                z_c = z_c / np.linalg.norm(z_c)
        self._phi = self._azimuth(p_t)
        if self._carry is not None:
            self._carry_along(float(t), p_t)
        self._command_p, self._command_z = p_c, z_c
        self._history.append((float(t if wanted_at is None else wanted_at), p_t, z_t))
        while len(self._history) > 2 and self._history[1][0] < float(t) - HISTORY_S:
            self._history.popleft()
        age = self.measurement_age(t)
        if age is None:
            self.state = WAITING
        elif age > s.measured_pose_timeout_s:
            self.state = STALE
            self._last_t = None   # integration restarts with dt = 0 when measurements return
        elif self._held:
            self.state = HELD
            self._last_t, self._used_meas_t = float(t), self._meas_t   # nothing to catch up
            self._pending.clear()
        elif self._meas_t != self._used_meas_t and self._meas_t < self._hold_until:
            self.state = OSCILLATING   # the watchdog tripped: hold, then integrate slower
            self._last_t, self._used_meas_t = float(t), self._meas_t
            self._pending.clear()
        elif self._meas_t != self._used_meas_t and self._meas_t < self._move_until:
            self.state = MOVING
            self._last_t, self._used_meas_t = float(t), self._meas_t
            self._pending.clear()
        elif self._meas_t != self._used_meas_t:
            # each measurement is integrated once, over the time since the last integration
            dt = 0.0 if self._last_t is None else min(max(float(t) - self._last_t, 0.0),
                                                      s.max_dt_s)
            self._last_t, self._used_meas_t = float(t), self._meas_t
            self._integrate(dt, p_t, z_t)
        elif self._outlier:
            self.state = OUTLIER
        if self.fallback:
            return p_c.copy(), None if z_c is None else z_c.copy()
        return self._apply(p_c, z_c)

    def _carry_to(self, move: tuple) -> None:
        """Plan the correction at a new move's goal (:class:`~._mismatch.MismatchTransfer`).

        The model's answer for the goal with the correction as it is, and the
        correction held there (the last command's answer), give the
        correction at the goal; :meth:`_carry_along` moves it there as the
        target moves.  Nothing changes without a transfer, a correction, an
        answer for the last command, or when a solve fails.
        """
        held, tr = self._held_inverse, self.transfer
        self._carry = None
        if tr is None or held is None or held.forward is None or self.fallback:
            return
        c_old, r_old = self.correction_m, self.correction_rad
        if not (np.any(c_old) or np.any(r_old)):
            return
        _, start, goal, goal_z = move
        start, goal = np.asarray(start, float), np.asarray(goal, float)
        z_goal = (goal_z / np.linalg.norm(goal_z)
                  if self.use_orientation and goal_z is not None else None)
        load = held.forward.load

        def solve_goal(c, r, warm):   # the model's answer for the goal corrected by (c, r)
            z = None if z_goal is None else rotation_from_vector(r) @ z_goal
            res = solve_inverse(tr.model, goal + c, z, payload_kg=load.payload_kg,
                                tip_force_n=load.force_n, warm_start=warm,
                                time_budget_s=CARRY_BUDGET_S)
            if res.status == InverseStatus.TIME_BUDGET:
                cut[0] = True
            return res if res.forward is not None and res.forward.success else None

        cut = [False]   # a solve ran out of its budget: the answer so far stands
        self.carries[0] += 1
        new = solve_goal(c_old, r_old, held)
        if new is None:
            self.carries[1] += 1
            return
        got = tr.transfer(held.forward, c_old, r_old, new.forward)
        for _ in range(CARRY_AGAIN):   # the goal's pressures with the carried correction
            if got is None:
                return
            new = solve_goal(got[0], got[1], new)
            if new is None:
                break   # (the answer so far stands)
            got = tr.again(new.forward)
        if cut[0] or new is None:
            self.carries[1] += 1
        if got is None:
            return
        s = self.settings
        # at most CARRY_SHARE of the way from where the azimuthal frame turns the correction
        turned = rotation_z(self._azimuth(goal) - self._phi)
        c_az, r_az = turned @ c_old, turned @ r_old
        room = CARRY_SHARE * float(np.linalg.norm(goal - start))
        c_new = _clamp(c_az + _clamp(got[0] - c_az, room), s.max_correction_m)
        r_new = r_az
        if got[1] is not None:
            r_new = _clamp(r_az + _clamp(got[1] - r_az, room / ROTATION_LENGTH_M),
                           s.max_correction_rad)
        self._carry = ((c_old, r_old), (c_new, r_new), start, goal, self._move_until)

    def _carry_along(self, t: float, p_t: np.ndarray) -> None:
        """The carried correction at the target ``p_t``: in proportion to the way to the goal.

        Done (the goal's correction, the integrator's again) at the goal or
        when the move's hold ends.
        """
        (c0, r0), (c1, r1), a, b, until = self._carry
        way = b - a
        n2 = float(way @ way)
        f = 1.0 if n2 <= 0.0 or t >= until else min(max(float((p_t - a) @ way) / n2, 0.0), 1.0)
        self.correction_m = c0 + f * (c1 - c0)
        self.correction_rad = r0 + f * (r1 - r0)
        if f >= 1.0:
            self._carry = None

    def _target_at(self, t: float):
        """The target wanted at time ``t``: interpolated between the targets around it.

        Linear in position (the z-axis renormalised) between the last target
        wanted at or before ``t`` and the next one; the newest one after the
        last; None before the first one since a reset.
        """
        before, after = bracket(self._history, t)
        if before is None:
            return None
        if after is None or after[0] <= before[0]:
            return before[1:]
        a = (t - before[0]) / (after[0] - before[0])
        p = before[1] + a * (after[1] - before[1])
        if before[2] is None:
            return p, None
        z = before[2] + a * (after[2] - before[2])
        return p, z / np.linalg.norm(z)

    def _sample_errors(self):
        """Mean error of the pending samples, turned to the current target's azimuth.

        ``(position error, z-axis error or None)``, or None when no pending
        sample can be compared (captured before the current targets began, or
        while the correction was held).  Every accepted sample counts once: a
        motion capture faster than the control steps averages its noise.
        """
        hold = max(self._hold_until, self._move_until)
        e_p, e_r = [], []
        for t_m, p_m, z_m in self._pending:
            then = None if t_m < hold else self._target_at(t_m)
            if then is None:
                continue
            p_t, z_t = then
            # the error measured at the target then, turned to the current target's azimuth
            turn = rotation_z(self._phi - self._azimuth(p_t))
            e_p.append(turn @ (p_t - p_m))
            if self.use_orientation and z_m is not None:
                e_r.append(turn @ rotation_between(z_m, z_t))
        self._pending.clear()
        if not e_p:
            return None
        return np.mean(e_p, axis=0), (np.mean(e_r, axis=0) if e_r else None)

    def _integrate(self, dt: float, p_now: np.ndarray, z_now: np.ndarray | None) -> None:
        s = self.settings
        if self._meas_t < self._hold_until:   # the watchdog tripped on this sample
            self._pending.clear()
            self.state = OSCILLATING
            return
        errors = self._sample_errors()
        if errors is None:        # measured before the current targets began: nothing to compare
            self.state = TRACKING
            return
        if (self.gain_scale < 1.0 and self.restorable
                and self._meas_t - self._trip_t >= RESTORE_S):
            self.gain_scale = min(1.0, 2.0 * self.gain_scale)
            self.restores += 1
            self._trip_t = self._restore_t = self._meas_t
        e_p, e_r = errors
        if self._mean_error is None:
            self._mean_error = e_p
        else:
            self._mean_error = self._mean_error + (1.0 - math.exp(-dt / NOISE_GATE_S)) * (
                e_p - self._mean_error)
        k = self.gain_per_s * dt
        c_new = _clamp(self.correction_m + k * e_p, s.max_correction_m)
        r_new = self.correction_rad
        if e_r is not None:
            r = self.correction_rad + k * e_r
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
               achieved_z_axis: Any = None, inverse=None) -> None:
        """The inverse's outcome for the last corrected target (anti-windup input).

        ``achieved_*``: the model's pose for the pressures it returned; with
        an unreachable target the correction is cut back to what it realised.
        ``inverse``: its answer (an ``InverseResult`` whose command went out),
        where a jump's transfer starts from (:meth:`_carry_to`).
        """
        self._saturated = bool((not reachable) or at_limit)
        self._held = False
        if inverse is not None and reachable and not at_limit:
            self._held_inverse = inverse
        if reachable or self.fallback or achieved_position is None or self._command_p is None:
            return
        s = self.settings
        c_real = np.asarray(achieved_position, dtype=float).reshape(3) - self._command_p
        if np.linalg.norm(c_real) < np.linalg.norm(self.correction_m):
            self.correction_m = _clamp(c_real, s.max_correction_m)
        if self.use_orientation and achieved_z_axis is not None:
            r_real = rotation_between(self._command_z, achieved_z_axis)
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
            'measured_poses_outliers': self.rejected,
            'feedback_carries': self.carries[0],
            'feedback_carries_cut': self.carries[1],
            'feedback_gain_per_s': f'{self.gain_per_s:.4g}',
            **self.noise.status(),
            'oscillation_trips': 0 if self.watchdog is None else self.watchdog.trips,
            'oscillation_gain_restores': self.restores,
            'oscillation_seen': ('none' if self.watchdog is None or self.watchdog.last_trip is None
                                 else self.watchdog.last_trip.message),
        }
