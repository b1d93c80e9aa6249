"""The inverse node's closed loop: ``measured_pose`` -> core integral feedback -> shifted target.

:class:`FeedbackLink` is all the inverse node needs for parameter
``feedback`` (``none``, the default and the paper's feedforward, or
``integral``): it declares the feedback parameters, and when feedback is on
it subscribes ``measured_pose`` (geometry_msgs/PoseStamped in ``base_frame``),
feeds :class:`~bellow_ancf_ros.core.control.IntegralFeedback` (the control
law, plain Python in the core) and re-submits the newest target at
``feedback_rate_hz`` so that a held target keeps being corrected.  Measured
poses may come in ``base_frame``, in the robot file's mocap frame
(``mocap_frame``, written by ``bellow-ancf calibrate``) or, on a ROS install,
any frame tf2 knows (:class:`~bellow_ancf_ros.nodes.frames.PoseFrames`);
poses in another frame, with NaN/inf or (two or more segments) an
orientation that cannot be normalised are refused (throttled warning,
diagnostics WARN) and never reach the integrator; so are outliers (far from
the median of the last five).  A measured pose's stamp says when it was
taken: its age decides whether the integrator holds its correction (a
dropout), and it is compared with the target wanted at that time (a zero
stamp, or one in the future, counts as taken on arrival; a target's stamp is
the time it is wanted at).

The loop's margins with the robot's own first mode at the held equilibrium
(:class:`~bellow_ancf_ros.core.control.ModeCheck`: the controller's model,
its payload and tip force) are computed off the control path, in a thread
of their own, when the payload or the force changes and every two seconds
while the robot moves.  On ``feedback_gain_per_s: auto`` (the default) the
gain is the safe one (gain margin 3, phase margin 45 deg): computed at
configure for the vented robot with the configured payload, then again
whenever the mode moves by more than 5 % or the margins would get thinner;
each change is logged and shown on ``/diagnostics``.  A fixed gain that
leaves less than the documented margins is logged once per change as a
warning with the safe gain, and reported on ``/diagnostics`` (WARN) while it
lasts.
The first mode found there is watched for an oscillation
(:class:`~bellow_ancf_ros.core.control.OscillationWatchdog`): a sustained or
growing swing of the measured error near it halves the gain and holds the
correction for a window, with one ERROR line naming the frequency seen, and
an ERROR on ``/diagnostics`` for ten seconds.
"""

from __future__ import annotations

import math
import threading
from typing import Any, Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import ParameterType
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..core.control import (AUTO_GAIN, FEEDBACK_MODES, LOOP_DELAY_S, LOOP_LAG_S, RESTORE_S,
                            FeedbackSettings, IntegralFeedback, MismatchTransfer, ModeCheck,
                            gain_setting)
from ..core import geometry
from . import lockstep
from .diagnostics import Refusals
from .frames import PoseFrames
from .ros_util import (QOS_DEPTH, Param, StartupParameterError, control_clock, declare_all,
                       descriptor)

__all__ = ['FEEDBACK_PARAMETERS', 'FEEDBACK_PARAMETER_TABLE', 'FeedbackLink', 'measured_pose_qos']

_D, _S = ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_STRING
_DEF = FeedbackSettings()
#: The parameters FeedbackLink declares (what the inverse node's ``--help`` prints); all are
#: read on configure.
FEEDBACK_PARAMETER_TABLE = (
    Param('feedback', 'none', descriptor(
        "Closed loop from measured_pose: 'none' (feedforward only, the paper's controller) "
        "or 'integral' (integral action on the task-space error). Read on configure.", _S,
        constraints="one of: 'none', 'integral'")),
    Param('feedback_gain_per_s', AUTO_GAIN, descriptor(
        "Integral gain [1/s]: an error decays with time constant 1/gain. 'auto': the largest "
        'gain that keeps a gain margin of 3 and a phase margin of 45 deg with the robot\'s '
        'first mode at the held equilibrium, the regulators\' lag and the loop\'s delay '
        '(feedback_loop_lag_s, feedback_loop_delay_s), recomputed when the payload, the tip '
        'force or the pose moves that mode by more than 5 %. A fixed gain is warned about '
        'when its margins are thinner. Read on configure.', _S, dynamic=True,
        constraints="'auto' or a number from 0.01 to 50")),
) + tuple(Param(name, float(default), descriptor(text + ' Read on configure.', _D, lo=lo, hi=hi))
          for name, default, text, lo, hi in (
    ('feedback_max_correction_mm', _DEF.max_correction_m * 1e3,
     'Clamp on the position correction [mm].', 0.01, 100.0),
    ('feedback_max_correction_deg', math.degrees(_DEF.max_correction_rad),
     'Clamp on the z-axis correction (two or more segments) [deg].', 0.01, 45.0),
    ('measured_pose_timeout_s', _DEF.measured_pose_timeout_s,
     'Older measurements (a dropout): the integrator is frozen, its correction '
     'stays applied [s].', 0.01, 10.0),
    ('measured_pose_outlier_mm', _DEF.outlier_gate_m * 1e3,
     'A measured pose this far from the median of the last five is an outlier, '
     'never integrated [mm].', 0.1, 1000.0),
    ('feedback_rate_hz', 20.0,
     'Rate at which the newest target is re-solved with a fresh correction [Hz].',
     0.1, 1000.0),
    ('feedback_loop_lag_s', LOOP_LAG_S,
     "The regulators' time constant, for the loop's margins [s].", 0.0, 10.0),
    ('feedback_loop_delay_s', LOOP_DELAY_S,
     "The loop's delay for its margins: regulator dead time, mocap latency, half a "
     'control and half a measurement period [s].', 0.0, 10.0))) + (
    Param('feedback_correction_frame', _DEF.correction_frame, descriptor(
        "Frame the correction is integrated in: 'azimuthal' (turns with the target about "
        "the base z-axis: a symmetric robot's mismatch is constant in it), 'base' (an "
        "error fixed in the base frame, e.g. one stiffer actuator) or 'model' (azimuthal, "
        "and at every target jump read as a mismatch of the robot file's parameters and "
        "carried to the new target through the model; for a robot whose play and creep "
        "are compensated or negligible). Read on configure.", _S,
        constraints="one of: 'azimuthal', 'base', 'model'")),
)
#: Their names.
FEEDBACK_PARAMETERS = tuple(p.name for p in FEEDBACK_PARAMETER_TABLE)
#: A dropout of the measured poses (a marker occluded: about 0.5 s, every 15 s on the
#: realistic simulated robot) is logged at INFO and counted on /diagnostics; one that lasts
#: longer than this [s] is a WARN: the motion capture needs a look.
DROPOUT_WARN_S = 2.0
#: How long /diagnostics reports an oscillation watchdog's trip as an ERROR [s].
TRIP_REPORT_S = 10.0


def measured_pose_qos() -> QoSProfile:
    """Best effort, keep-last :data:`QOS_DEPTH`: matches reliable and best-effort publishers.

    Motion-capture drivers usually publish best effort (sensor data); a reliable
    subscription would not match them.  A lost sample is replaced by the next one.
    """
    return QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT,
                      history=HistoryPolicy.KEEP_LAST, depth=QOS_DEPTH)


class FeedbackLink:
    """Feedback parameters, ``measured_pose`` subscription and control law of one node."""

    def __init__(self, node, publish_diag: Callable) -> None:
        """Declare the feedback parameters on ``node`` (refuses a bad ``feedback`` value)."""
        declare_all(node, FEEDBACK_PARAMETER_TABLE)
        mode = node.get_parameter('feedback').value
        if mode not in FEEDBACK_MODES:
            raise StartupParameterError('feedback', mode, "one of: 'none', 'integral'")
        self.node = node
        self._clock = control_clock(node)   # every time here: control time (use_sim_time)
        self._gain_setting = self._read_gain()
        self._lock = threading.Lock()
        self._refusals = Refusals(node, 'measured poses', publish_diag)
        self._law: IntegralFeedback | None = None
        self._sub = self._timer = self._frames = None
        self._frame = ''
        self._use_orientation = False
        self._last_item = None
        self._was_fallback = True   # the loop starts waiting for measured poses
        self._blind_since: float | None = None   # start of the current dropout
        self._warned = False
        self.dropouts = 0
        self.longest_dropout_s = 0.0
        self.refused = 0
        self.received = 0
        self._trips_logged = 0
        self._restores_logged = 0
        self._trip_t = -math.inf
        self._mode_result = None

    # ------------------------------------------------------------ lifecycle
    def _read_gain(self) -> float | str:
        """``feedback_gain_per_s``: ``'auto'`` or a fixed gain (a bad value: one line)."""
        value = self.node.get_parameter('feedback_gain_per_s').value
        try:
            return gain_setting(value)
        except ValueError:
            raise StartupParameterError('feedback_gain_per_s', value,
                                        "'auto' or a number from 0.01 to 50 [1/s]") from None

    @property
    def wanted(self) -> bool:
        """True when ``feedback`` asks for the closed loop (it needs the first mode)."""
        return self.node.get_parameter('feedback').value != 'none'

    def mode_check(self) -> ModeCheck:
        """The margin check of this loop's gain setting, lag and delay (``'auto'``: no loop)."""
        g = self.node.get_parameter
        gain = self._read_gain() if self.wanted else AUTO_GAIN
        return ModeCheck(gain, g('feedback_loop_lag_s').value, g('feedback_loop_delay_s').value)

    def configure(self, model, resubmit: Callable[[Any], None], modes=None) -> None:
        """Read the parameters; with feedback on, subscribe and start the re-solve timer.

        ``model``: the controller's model (a jump's move carries the correction
        to its goal through it, :class:`~bellow_ancf_ros.core.control.MismatchTransfer`).

        ``modes``: the node's :class:`~.mode_watch.ModeWatch` (its check is
        :meth:`mode_check`); on ``feedback_gain_per_s: auto`` the gain is its
        answer's, the first one computed at start for the vented robot with
        the configured payload, before any command.
        """
        g = self.node.get_parameter
        self.release()
        if g('feedback').value == 'none':
            return
        cfg = model.cfg
        self._gain_setting = gain = self._read_gain()
        s = FeedbackSettings(
            gain_per_s=_DEF.gain_per_s if gain == AUTO_GAIN else gain,
            max_correction_m=1e-3 * g('feedback_max_correction_mm').value,
            max_correction_rad=math.radians(g('feedback_max_correction_deg').value),
            measured_pose_timeout_s=g('measured_pose_timeout_s').value,
            outlier_gate_m=1e-3 * g('measured_pose_outlier_mm').value,
            correction_frame=g('feedback_correction_frame').value)
        self._use_orientation = cfg.n_segments >= 2
        self._frame = g('base_frame').value
        self._frames = PoseFrames(self.node, self._frame, cfg.mocap_frame)
        with self._lock:
            self._law = IntegralFeedback(s, self._use_orientation, (
                MismatchTransfer(model) if s.correction_frame == 'model' else None))
            self._trips_logged = self._restores_logged = 0   # (a new law counts from 0)
        self._sub = self.node.create_subscription(PoseStamped, 'measured_pose',
                                                  self._on_measured, measured_pose_qos())

        period = 1.0 / g('feedback_rate_hz').value

        def tick():
            # a held target keeps being corrected; a target stream is solved anyway, and a
            # re-solve would only take the next target's slot of the rate limit
            item = self._last_item
            if item is not None and self._clock.now() - item[3] >= period:
                resubmit(item)
        self._timer = lockstep.create_timer(self.node, period, tick)
        if modes is not None:
            modes.listen(self._on_mode)
            if modes.result is not None:
                self._take(modes.result)
        law = self._law
        how = (f'automatic gain {law.gain_per_s:.3g} /s' if gain == AUTO_GAIN
               else f'gain {law.gain_per_s:g} /s')
        res = self._mode_result
        at = '' if res is None else (f' (first mode {res.frequency_hz:.3g} Hz, damping ratio '
                                     f'{res.damping_ratio:.3f}, payload {res.payload_kg:g} kg)')
        self.node.get_logger().info(
            f'feedback: integral on measured_pose ({how}{at}, clamp '
            f'{s.max_correction_m * 1e3:g} mm, timeout {s.measured_pose_timeout_s:g} s)')

    def release(self) -> None:
        """Drop the subscription, the timer and the integrator."""
        self._mode_result = None
        if self._timer is not None:
            self.node.destroy_timer(self._timer)
        if self._sub is not None:
            self.node.destroy_subscription(self._sub)
        self._sub = self._timer = self._last_item = self._frames = None
        with self._lock:
            self._law = None

    def reset(self) -> None:
        """Clear the correction and forget the last target (on activate: wait for a new one)."""
        self._last_item = None
        with self._lock:
            if self._law is not None:
                self._law.reset()

    @property
    def enabled(self) -> bool:
        """True when feedback is on (after configure)."""
        return self._law is not None

    # ------------------------------------------------------------ data flow
    def remember(self, item: Any) -> None:
        """The newest accepted target item (re-submitted at ``feedback_rate_hz`` while held).

        ``item[3]``: its arrival time (control time, :class:`~.ros_util.ControlClock`);
        no re-solve within one feedback period of it.
        """
        self._last_item = item

    def _on_measured(self, msg: PoseStamped) -> None:
        frames = self._frames
        if frames is None:   # released meanwhile
            return
        self.received += 1
        try:
            pos, quat = frames.pose_in_base(msg, self._use_orientation)
            z = None if quat is None else geometry.z_axis_from_quaternion(quat)
        except ValueError as exc:  # contract.InputError, or a bad quaternion (core.geometry)
            self.refused += 1
            self._refusals.report(str(exc), self.refused)
            return
        with self._lock:
            if self._law is not None:
                self._law.measurement(self._taken_at(msg.header.stamp), pos, z)

    def _control_time(self, stamp, future: bool) -> float:
        """A stamp as control time (:meth:`~.ros_util.ControlClock.time_of`)."""
        return self._clock.time_of(stamp, future)

    def _taken_at(self, stamp) -> float:
        """Control time the pose was taken: from its stamp (zero or future stamp: now)."""
        return self._control_time(stamp, future=False)

    def correct(self, position: np.ndarray, z_axis: np.ndarray | None, stamp=None,
                command: tuple | None = None, hold_until: float | None = None,
                move: tuple | None = None):
        """The target to hand to the inverse (``command``, or the target, when feedback is off).

        ``stamp``: the target's stamp, the time it is wanted at (zero: now; in
        the future: a target that previews the robot's lag).  ``command``:
        the target to correct when it is not the pose wanted (a dynamic
        feedforward's shift).  ``hold_until``: the correction is held for
        measurements captured before it (control time [s]; a jump's move,
        ``move``, whose goal the correction is carried to).  A
        change between integrating and holding the
        correction through a dropout is logged, not only reported on
        ``/diagnostics``.
        """
        with self._lock:
            if self._law is None:
                return (position, z_axis) if command is None else command
            out = self._law.corrected_target(self._clock.now(), position, z_axis,
                                             wanted_at=self._control_time(stamp, future=True),
                                             command=command, hold_until=hold_until,
                                             move=move)
            degraded, state = self._law.blind, self._law.state
            wd, law = self._law.watchdog, self._law
            trip = restored = gain = None
            if wd is not None and wd.trips > self._trips_logged:
                self._trips_logged, trip = wd.trips, wd.last_trip
                self._trip_t = self._clock.now()
            if law.restores > self._restores_logged:
                self._restores_logged = restored = law.restores
            if trip is not None or restored is not None:   # (the gain only when it is logged)
                gain = law.gain_per_s
        self._log_dropout(degraded, state)
        if trip is not None:
            self.node.get_logger().error(
                f'feedback: {trip.message}; gain cut to {gain:.3g} /s, correction held for '
                f'{2 / wd.frequency_hz:.2f} s (trip {wd.trips}; '
                + (f'doubled back after {RESTORE_S:g} s without one)' if law.restorable else
                   f'within {RESTORE_S:g} s of a restore: the loop rings itself, the cut stays)'))
        if restored is not None:
            self.node.get_logger().info(
                f'feedback: no oscillation for {RESTORE_S:g} s: gain doubled back to '
                f'{gain:.3g} /s (restore {restored})')
        return out

    def _log_dropout(self, degraded: bool, state: str) -> None:
        """A dropout: INFO at its start and end (counted); a WARN once if it lasts too long."""
        now, log = self._clock.now(), self.node.get_logger()
        if degraded != self._was_fallback:
            self._was_fallback = degraded
            if degraded:
                self._blind_since, self._warned = now, False
                self.dropouts += 1
                log.info(f'feedback: {state}; integrator frozen, correction held '
                         f'(dropout {self.dropouts})')
                return
            took = '' if self._blind_since is None else f' after {now - self._blind_since:.2f} s'
            if self._blind_since is not None:
                self.longest_dropout_s = max(self.longest_dropout_s, now - self._blind_since)
            self._blind_since = None
            log.info(f'feedback: measured poses back{took}, integrating again ({state})')
        elif (degraded and self._blind_since is not None and not self._warned
              and now - self._blind_since > DROPOUT_WARN_S):
            self._warned = True
            log.warning(f'feedback: no fresh measured pose for {now - self._blind_since:.1f} s '
                        f'(longer than the {DROPOUT_WARN_S:g} s a marker occlusion may take): '
                        'integrator frozen, correction held; check the motion capture')

    def after_solve(self, inv) -> None:
        """Anti-windup input: the inverse's outcome for the corrected target."""
        fw = inv.forward
        with self._lock:
            if self._law is not None and fw is not None:
                self._law.report(bool(inv.reachable), bool(np.any(inv.active_limits)),
                                 fw.position, fw.z_axis, inverse=inv)

    # ------------------------------------------------------------ margins
    def _on_mode(self, before, res) -> None:
        """A new first mode (ModeWatch's thread): take it; log a new gain or margin verdict."""
        if self._law is None:
            return
        log = self.node.get_logger()
        old_gain = None if before is None else before.gain_per_s
        self._take(res)
        if res.auto and res.gain_per_s != old_gain:
            log.info(f'feedback: automatic gain {res.gain_per_s:.3g} /s (was '
                     f'{"-" if old_gain is None else f"{old_gain:.3g}"}): {res.message}')
        elif before is None or before.ok != res.ok or (res.moved and not res.ok):
            if res.ok:   # (two calls: rclpy allows one severity per call site)
                log.info(f'loop margins: {res.message}')
            else:
                log.warning(f'loop margins: {res.message}')

    def _take(self, res) -> None:
        """A margin answer: the watchdog's band, and on ``auto`` the gain integrated with."""
        if res is None:
            return
        self._mode_result = res
        with self._lock:   # the watchdog watches the first mode where the robot is held
            if self._law is not None:
                self._law.watch(res.frequency_hz)
                if res.auto:
                    self._law.set_gain(res.gain_per_s)

    def trips(self) -> int:
        """How often the oscillation watchdog tripped since configure."""
        with self._lock:
            wd = None if self._law is None else self._law.watchdog
            return 0 if wd is None else wd.trips

    @property
    def oscillation_error(self) -> str | None:
        """What the oscillation watchdog saw, for :data:`TRIP_REPORT_S` after its last trip."""
        law = self._law
        wd = None if law is None else law.watchdog
        if (wd is None or wd.last_trip is None
                or self._clock.now() - self._trip_t > TRIP_REPORT_S):
            return None
        return f'{wd.last_trip.message}; feedback gain cut to {law.gain_per_s:.3g} /s'

    @property
    def margin_warning(self) -> str | None:
        """The margin line while the gain leaves less than the documented margins, else None."""
        res = self._mode_result
        return None if res is None or res.ok else res.message

    def no_command(self) -> None:
        """No command went out for the corrected target: the integrator freezes until one does."""
        with self._lock:
            if self._law is not None:
                self._law.no_command()

    @property
    def fallback(self) -> bool:
        """True while feedback is on but not integrating: no measurement yet, or a dropout."""
        with self._lock:
            return self._law is not None and self._law.blind

    def heartbeat(self, active: bool, extra: dict):
        """The loop's part of the node's heartbeat: its values and ``extra``.

        While ``active``: ERROR for :data:`TRIP_REPORT_S` after a watchdog
        trip, WARN while the gain leaves less than the margins or no fresh
        measured pose arrives: ``(level, message, values)``; else the values.
        """
        values = dict(self.status(), **extra)
        ringing, margin = self.oscillation_error, self.margin_warning
        if ringing is not None and active:
            return DiagnosticStatus.ERROR, f'feedback: {ringing}', values
        if margin is not None and active:
            return DiagnosticStatus.WARN, f'loop margins: {margin}', values
        if self.fallback and active:
            return (DiagnosticStatus.WARN,
                    f'feedback without measured poses: {values.get("feedback_state", "")}',
                    values)
        return values

    @staticmethod
    def refusal(param) -> str:
        """Why a new value of ``feedback_gain_per_s`` is not allowed, or ''."""
        if param.name != 'feedback_gain_per_s':   # dynamic typing: rclpy checks no type
            return ''
        try:
            gain_setting(param.value)
        except ValueError as exc:
            return f'feedback_gain_per_s: {exc}'
        return ''

    def status(self) -> dict:
        """Diagnostics values of the loop (``feedback: none`` when off)."""
        with self._lock:
            if self._law is None:
                return {'feedback': 'none'}
            values = self._law.status(self._clock.now())
            res = self._mode_result
            if res is not None:
                values.update(res.values())
            # one count of the measured poses that did not reach the integrator: bad input
            # (frame, NaN, quaternion) and outliers; the latter also on their own
            return dict(values, feedback='integral', feedback_gain_setting=(
                AUTO_GAIN if self._gain_setting == AUTO_GAIN else 'fixed'),
                measured_poses_refused=(
                self.refused + values['measured_poses_outliers']),
                feedback_dropouts=self.dropouts,
                feedback_longest_dropout_s=round(self.longest_dropout_s, 3))
