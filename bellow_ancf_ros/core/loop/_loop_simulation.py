"""The controller closed around the simulated robot, in simulated time (no ROS).

:class:`LoopSimulation` runs what the ROS pipeline runs, as events on one
simulated clock:

* physics every ``1/physics_rate_hz``: :meth:`SimulatedRobot.step`
  (regulators, creep, the robot's motion or equilibrium);
* motion capture every ``1/mocap_rate_hz`` (the robot's effects): a sample
  captured one latency ago reaches :meth:`IntegralFeedback.measurement` with
  its capture time (nothing during a dropout);
* control every ``1/control_rate_hz``: the target wanted ``preview_s`` from
  now (the trajectory previewed by the regulators' lag, as
  ``trajectory_publisher``'s ``preview_s`` does), corrected by the feedback,
  solved by the inverse (eqs. 28-30, warm-started), commanded to the
  regulators when the solve gave a usable answer (else the last command
  stands and the integrator is told).

It records, per control step, the reference (the target wanted *now*), the
true pose, the command and what the feedback did: :class:`LoopRecord` gives
the tracking errors the ROS demo measures, free of the motion capture's
noise.  Used by the tests and ``bench/effects_bench.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..geometry import angle_between
from ..model import RobotModel
from ..solve import solve_forward, solve_inverse
from ..control import (CommandOutput, FeedbackSettings, IntegralFeedback, MismatchTransfer,
                       TargetFilter)
from ..sim import SimulatedRobot

__all__ = ['LoopRecord', 'LoopSimulation']

#: ``target(t) -> (position (3,), z_axis (3,) or None)``: the pose wanted at time ``t``;
#: ``None``: no target then (the stream has stopped: the last one stands, re-solved).
Target = Callable[[float], tuple | None]


@dataclass
class LoopRecord:
    """What happened at every control step of :meth:`LoopSimulation.run`."""

    t: list = field(default_factory=list)              #: control times [s]
    reference_p: list = field(default_factory=list)    #: target wanted at t [m]
    reference_z: list = field(default_factory=list)    #: its z-axis (None: one segment)
    true_p: list = field(default_factory=list)         #: the robot's true position at t
    true_z: list = field(default_factory=list)         #: its true z-axis
    command_pa: list = field(default_factory=list)     #: the command in effect after t
    sent: list = field(default_factory=list)           #: a new command went out at t
    outlier_before: list = field(default_factory=list)   #: an outlier arrived since t - 1 step
    state: list = field(default_factory=list)          #: feedback state ('' without feedback)
    correction_m: list = field(default_factory=list)   #: feedback position correction [m]
    out_of_limits: int = 0                             #: commands outside the limits or NaN

    def arrays(self) -> dict:
        """Every per-step list as a numpy array (z-axes only when recorded)."""
        out = {k: np.array(getattr(self, k)) for k in
               ('t', 'reference_p', 'true_p', 'command_pa', 'sent', 'outlier_before',
                'correction_m')}
        if self.reference_z and self.reference_z[0] is not None:
            out['reference_z'] = np.array(self.reference_z)
            out['true_z'] = np.array(self.true_z)
        return out

    def errors(self, start_s: float = 0.0, end_s: float = math.inf):
        """``(t, position error [m], angle error [rad] or None)`` of the steps in the window."""
        a = self.arrays()
        m = (a['t'] >= start_s) & (a['t'] <= end_s)
        pos = np.linalg.norm(a['true_p'][m] - a['reference_p'][m], axis=1)
        ang = (angle_between(a['true_z'][m], a['reference_z'][m]) if 'reference_z' in a
               else None)
        return a['t'][m], pos, ang

    def summary(self, start_s: float = 0.0, end_s: float = math.inf) -> dict:
        """RMSE and maximum of the errors in the window (mm, deg)."""
        _, pos, ang = self.errors(start_s, end_s)
        out = {'rmse_mm': float(np.sqrt(np.mean(pos ** 2)) * 1e3),
               'max_mm': float(pos.max() * 1e3)}
        if ang is not None:
            out['rmse_deg'] = float(math.degrees(np.sqrt(np.mean(ang ** 2))))
            out['max_deg'] = float(math.degrees(ang.max()))
        return out

    def command_steps(self) -> tuple[np.ndarray, np.ndarray]:
        """``(largest change of any actuator's command at each step [Pa], outlier flags)``."""
        a = self.arrays()
        d = np.max(np.abs(np.diff(a['command_pa'], axis=0)), axis=1)
        return d, a['outlier_before'][1:]


class LoopSimulation:
    """Controller (the model's inverse, optional integral feedback) around a simulated robot.

    Parameters
    ----------
    model : the controller's :class:`RobotModel` (not the robot's).
    robot : the :class:`SimulatedRobot` it controls (its effects, its seed).
    feedback : :class:`FeedbackSettings`, or None for feedforward only.
    control_rate_hz : control steps per second (the ROS pipeline: the target
        stream's rate, 50 Hz in the demo).
    physics_rate_hz : robot steps per second; commands take effect at the
        next step (at most one physics period late).  With the robot's
        dynamics it must resolve the first mode
        (:meth:`SimulatedRobot.check_physics_rate`; ValueError otherwise).
    preview_s : the controller solves for the target wanted this far ahead
        (compensation of the regulators' known lag); measurements are
        compared with the target wanted at their capture time.
    payload_kg : the payload the controller is told (default: the model's).
    mode_check : a :class:`~._mode_check.ModeCheck` run on the inverse's
        equilibria in simulated time (every ``period_s`` and on a new load):
        the feedback's watchdog watches the first mode it finds, and a
        ``ModeCheck('auto', ...)`` sets the feedback's gain (the gain of the
        feedback settings is then only the start value), as the inverse node
        does with ``feedback_gain_per_s: auto``.
    feedforward : a :class:`~._dynamic_feedforward.StreamFeedforward`: the
        (previewed) target is shifted for the robot's first mode before the
        inverse (dynamic feedforward); its mode follows ``mode_check``.
    play_compensation_pa : the regulators' play the commands are compensated
        for (:class:`~._play.PlayCompensation`, as the inverse node's
        ``regulator_play_kpa``); 0: none.
    creep_compensation : ``(fraction, time_constant_s)`` of the bellows' creep
        the commands are compensated for (:class:`~._command_output.CreepCompensation`,
        as the inverse node's ``creep_fraction`` and ``creep_time_constant_s``);
        None: none.
    jumps : a :class:`~._jumps.JumpTransition`: a jump of the (previewed)
        target becomes a minimum-jerk move at the first mode of
        ``mode_check``, and the feedback holds its correction through it (the
        inverse node's ``target_shaping: smooth``).
    """

    def __init__(self, model: RobotModel, robot: SimulatedRobot,
                 feedback: FeedbackSettings | None = None, control_rate_hz: float = 50.0,
                 physics_rate_hz: float = 200.0, preview_s: float = 0.0,
                 payload_kg: float | None = None, mode_check=None, feedforward=None,
                 play_compensation_pa: float = 0.0, jumps=None,
                 creep_compensation: tuple[float, float] | None = None) -> None:
        """Set up the loop at the robot's current time; nothing is commanded yet."""
        for name, v in (('control_rate_hz', control_rate_hz),
                        ('physics_rate_hz', physics_rate_hz)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f'{name} must be > 0, got {v}')
        if not (math.isfinite(preview_s) and preview_s >= 0):
            raise ValueError(f'preview_s must be >= 0, got {preview_s}')
        robot.check_physics_rate(physics_rate_hz)
        self.model, self.robot = model, robot
        self.use_orientation = model.cfg.n_segments >= 2
        self.feedback = (None if feedback is None
                         else IntegralFeedback(feedback, self.use_orientation, (
                             MismatchTransfer(model) if feedback.correction_frame == 'model'
                             else None)))
        self.control_dt = 1.0 / control_rate_hz
        self.physics_dt = 1.0 / physics_rate_hz
        self.preview_s = float(preview_s)
        self.payload_kg = model.cfg.payload if payload_kg is None else float(payload_kg)
        self.inverse = None                  # the last usable solve (warm start)
        self.command = None                  # the last usable solve's pressures
        self.sent = None                     # what the regulators were last sent
        self.corrupt: Callable | None = None  # corrupt(sample) -> sample, for tests
        self._outlier_since = False
        self._last = None                     # the newest target (position, z_axis)
        self.mode_check = mode_check
        self.feedforward = feedforward
        self.jumps = jumps
        # the node's composition of the two (its TargetLink): the move of a jump, shifted by
        # the feedforward of the target stream itself (a move is the controller's, not a path)
        self.targets = (None if jumps is None and feedforward is None
                        else TargetFilter.of(jumps, feedforward))
        self.gains: list = []                 # (time, gain) whenever the automatic gain changed
        cfg = model.cfg
        self.output = CommandOutput(model, play_compensation_pa, creep_compensation)
        t = robot.time_s
        self._next = {'physics': t + self.physics_dt, 'mocap': t, 'control': t}
        if jumps is not None or mode_check is not None:   # as the node at configure: the
            start = solve_forward(model, np.clip(robot.regulators.command_pa, cfg.p_min,
                                                 cfg.p_max), payload_kg=self.payload_kg)
            if start.success:   # first mode where the robot rests, the first target from there
                self._check_modes(t, start)
                if self.targets is not None:
                    self.targets.reset((start.position,
                                        start.z_axis if self.use_orientation else None))

    def _control(self, t: float, target: Target, rec: LoopRecord) -> None:
        new = target(t + self.preview_s)
        if new is None:   # the stream stopped: the node re-solves its last target
            if self._last is None:
                raise ValueError(f'no target at t = {t:g} s, and none before')
            (p, z), ref = self._last, self._last
        else:
            p = np.asarray(new[0], dtype=float)
            z = (None if (new[1] is None or not self.use_orientation)
                 else np.asarray(new[1], dtype=float))
            ref = target(t) or (p, z)
            self._last = (p, z)
        ref_p, ref_z = ref
        command, hold, move = None, None, None
        if self.targets is not None:   # a jump becomes a move, a stream is shifted: the
            if new is not None:            # loop compares the move (wanted)
                self.targets.push(t + self.preview_s, p, z)
            shifted, (p, z) = self.targets.targets(t)
            command = shifted if self.feedforward is not None else None
            hold, move = self.targets.hold_until, self.targets.move
        fb = self.feedback
        if fb is not None:
            p, z = fb.corrected_target(t, p, z, wanted_at=t + self.preview_s, command=command,
                                       hold_until=hold, move=move)
        elif command is not None:
            p, z = command
        inv = solve_inverse(self.model, p, z, payload_kg=self.payload_kg,
                            warm_start=self.inverse)
        fw = inv.forward
        usable = fw is not None and fw.success
        cfg = self.model.cfg
        if usable:
            cmd = np.asarray(inv.pressures_pa, dtype=float)
            if not (np.all(np.isfinite(cmd)) and np.all(cmd >= cfg.p_min)
                    and np.all(cmd <= cfg.p_max)):
                rec.out_of_limits += 1    # never sent (the nodes' safety gate)
                usable = False
        if usable:
            self.inverse, self.command = inv, cmd
            self.sent = self.output.command(cmd, t)
            self.robot.command(self.sent, t - self.robot.time_s)
            self._check_modes(t, fw)
            if fb is not None:
                fb.report(bool(inv.reachable), bool(np.any(inv.active_limits)),
                          fw.position, fw.z_axis, inverse=inv)
        else:
            if self.output.timed and self.output.wanted is not None:   # (as the node's
                self.sent = self.output.again(t)                        # republishing)
                self.robot.command(self.sent, t - self.robot.time_s)
            if fb is not None:
                fb.no_command()
        true_p, true_R = self.robot.true_pose()
        rec.t.append(t)
        rec.reference_p.append(np.asarray(ref_p, dtype=float))
        rec.reference_z.append(None if ref_z is None or not self.use_orientation
                               else np.asarray(ref_z, dtype=float))
        rec.true_p.append(true_p)
        rec.true_z.append(true_R[:, 2])
        rec.command_pa.append(self.robot.regulators.command_pa.copy()
                              if self.sent is None else self.sent.copy())
        rec.sent.append(usable)
        rec.outlier_before.append(self._outlier_since)
        rec.state.append('' if fb is None else fb.state)
        rec.correction_m.append(np.zeros(3) if fb is None else fb.correction_m.copy())
        self._outlier_since = False

    def _check_modes(self, t: float, fw) -> None:
        """The first mode at the newest equilibrium: the watchdog's band, the automatic gain."""
        chk, fb = self.mode_check, self.feedback
        if (chk is None or (fb is None and self.feedforward is None and self.jumps is None)
                or not chk.due(fw, t)):
            return
        res = chk.update(fw, t)
        if res is None:
            return
        if self.targets is not None:
            self.targets.set_mode(res.frequency_hz, res.damping_ratio)
        if fb is None:
            return
        fb.watch(res.frequency_hz)
        if res.auto and (not self.gains or res.gain_per_s != self.gains[-1][1]):
            fb.set_gain(res.gain_per_s)
            self.gains.append((t, res.gain_per_s))

    def _mocap(self, t: float) -> None:
        sample = self.robot.capture(t)
        if sample is None:
            return
        if self.corrupt is not None:
            sample, self.corrupt = self.corrupt(sample), None
        self._outlier_since |= sample.outlier
        if self.feedback is not None:
            self.feedback.measurement(sample.captured_s, sample.position,
                                      sample.rotation[:, 2])

    def run(self, duration_s: float, target: Target, record: LoopRecord | None = None,
            solve_at=()) -> LoopRecord:
        """Run ``duration_s`` more seconds towards ``target``; the record (appended to).

        ``solve_at``: extra control steps at these times (the inverse node
        re-solves a shaped target at each of its shaper's impulse times); a
        command between two physics steps takes effect when it was sent.
        """
        rec = LoopRecord() if record is None else record
        end = self.robot.time_s + float(duration_s)
        mocap_dt = self.robot.mocap.period_s
        nxt = self._next
        extra = sorted(float(t) for t in solve_at if float(t) >= self.robot.time_s)
        nxt['extra'] = extra.pop(0) if extra else math.inf
        while True:
            kind = min(nxt, key=nxt.get)
            t = nxt[kind]
            if t > end + 1e-12:
                break
            if kind == 'physics':
                self.robot.step(t - self.robot.time_s)
                nxt[kind] = t + self.physics_dt
            elif kind == 'mocap':
                self._mocap(t)
                nxt[kind] = t + mocap_dt
            else:
                self._control(t, target, rec)
                if kind == 'extra':
                    nxt[kind] = extra.pop(0) if extra else math.inf
                else:
                    nxt[kind] = t + self.control_dt
        nxt.pop('extra', None)
        return rec
