"""The closed loop's goals, case by case, on any simulated robot (no ROS).

Each case runs a fresh :class:`~._loop_simulation.LoopSimulation` of the
inverse node's closed loop at its defaults (``feedback: integral``,
``feedback_gain_per_s: auto`` with the node's loop lag and delay, a jump of
the targets moved through smoothly: ``target_shaping: smooth``, a moving
target shifted for the mode and the regulators' lag: ``dynamic_feedforward``)
around a robot, with targets stamped when
they are wanted (nobody previewed them: ``preview_s`` 0), and measures what
the goals name, on the robot's true pose:

* :func:`held_case`: a held target, the RMSE (and the largest error) over
  its last half;
* :func:`circle_case`: the paper's circle (two segments: the bending circle
  of 10 deg) at a speed factor (1x: 20 s period), entered with a 1 s
  spin-up, the RMSE over its second period at full speed;
* :func:`step_case`: a 10 mm step target in ``y`` after a held one: the
  overshoot along the step, the largest error from 1.5 s after the step on,
  and how far the commands went beyond their settled change.

Every case also reports the watchdog's trips and the commands refused by
the safety gate (out of the limits or not finite; never sent).
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ..experiments import spin_up, trajectory_target
from ..model import RobotModel
from ..solve import solve_forward
from ..control import (AUTO_GAIN, LOOP_DELAY_S, LOOP_LAG_S, FeedbackSettings, JumpTransition,
                       ModeCheck, StreamFeedforward)
from ..sim import SimulatedRobot
from ._loop_simulation import LoopSimulation

__all__ = ['STEP_M', 'circle_case', 'default_loop', 'held_case',
           'paper_circle', 'step_case']

#: The step target's size [m].
STEP_M = 0.010
#: A settled command: its mean over the last second of the step case.
_SETTLED_S = 1.0
#: Smallest command change a step's excess is measured against [Pa] (a step that barely moves).
_MIN_CHANGE_PA = 1.0e3

Loop = Callable[[RobotModel, SimulatedRobot, float], LoopSimulation]


def default_loop(model: RobotModel, robot: SimulatedRobot, payload_kg: float = 0.0,
                 dynamic_feedforward: bool = True, smooth_jumps: bool = True,
                 creep_compensation: tuple[float, float] | None = None,
                 play_compensation_pa: float = 0.0,
                 correction_frame: str = FeedbackSettings.correction_frame) -> LoopSimulation:
    """The inverse node's closed loop at its defaults around ``robot`` (targets not previewed).

    ``dynamic_feedforward``: as the node's ``dynamic_feedforward`` (default
    true; False: off);
    ``smooth_jumps``: as its ``target_shaping: smooth`` (the default; False:
    ``none``); ``creep_compensation``: ``(fraction, time_constant_s)``, as its
    ``creep_fraction`` and ``creep_time_constant_s`` (None: off, the default);
    ``play_compensation_pa``: the regulators' play, as its ``regulator_play_kpa``
    (0: off, the default); ``correction_frame``: as its
    ``feedback_correction_frame``.
    """
    ff = (StreamFeedforward(1.0, 0.0, lag_s=LOOP_LAG_S) if dynamic_feedforward else None)
    return LoopSimulation(model, robot, FeedbackSettings(correction_frame=correction_frame),
                          preview_s=0.0,
                          physics_rate_hz=robot.auto_physics_rate_hz, payload_kg=payload_kg,
                          mode_check=ModeCheck(AUTO_GAIN, LOOP_LAG_S, LOOP_DELAY_S),
                          feedforward=ff,
                          jumps=(JumpTransition(mode_error=model.cfg.first_mode_error)
                                 if smooth_jumps else None),
                          creep_compensation=creep_compensation,
                          play_compensation_pa=play_compensation_pa)


def paper_circle(cfg, period: float):
    """The paper's circle for this robot as ``target(t)``.

    Planar for one segment; for two or more, the bending circle at 10 deg.
    """
    if cfg.n_segments == 1:
        return trajectory_target('planar_circle', cfg, period=period)
    return trajectory_target('bending_circle', cfg, period=period, bending_angle_deg=10.0)


def _rest_pose(model: RobotModel, payload_kg: float):
    """The held pose of the cases: actuator 1 at 30 kPa, the others vented."""
    p = np.zeros(model.A)
    p[0] = 30e3
    fw = solve_forward(model, p, payload_kg=payload_kg)
    if not fw.success:
        raise RuntimeError(f'no equilibrium for the held pose: {fw.message}')
    return fw.position, fw.z_axis


def _health(sim: LoopSimulation, rec) -> dict:
    wd = sim.feedback.watchdog if sim.feedback is not None else None
    return {'trips': 0 if wd is None else int(wd.trips), 'refused': int(rec.out_of_limits),
            'gain_per_s': None if sim.feedback is None else float(sim.feedback.gain_per_s)}


def _step_figures(rec, ts: float, start, goal, before_pa) -> dict:
    """A step from ``start`` to ``goal`` at ``ts``, the commands ``before_pa`` before it.

    ``overshoot_mm`` (and ``overshoot_frac`` of the step): the largest
    excursion past ``goal`` along the step; ``late_mm``: the largest distance
    from it from 1.5 s after the step on (NaN if the run ends before);
    ``command_excess``: how far any command went beyond its settled change
    (its mean over the last second), as a fraction of the step's command
    change (the largest settled change of an actuator, at least 1 kPa), and
    ``command_beyond_kpa`` the same in kPa.  Measured against the step's
    change, not each actuator's own: an actuator that barely moves (a step
    along one actuator's plane leaves it within a few kPa) would read any
    ripple of the loop as hundreds of percent (as overshoot is a fraction of
    the step, not of each axis's share of it).
    """
    a = rec.arrays()
    t = a['t']
    after = t >= ts
    size = float(np.linalg.norm(goal - start))
    u = (goal - start) / size
    over = max(float(np.max((a['true_p'][after] - goal) @ u)), 0.0)
    tail = a['true_p'][t >= ts + 1.5]   # (none in a run shorter than that: NaN)
    late = float(np.linalg.norm(tail - goal, axis=1).max()) if len(tail) else math.nan
    cmd = a['command_pa']
    change = cmd[t > t[-1] - _SETTLED_S].mean(axis=0) - before_pa
    past = cmd[after] - before_pa - change   # past the settled command: along its change
    beyond = max(float(np.max(np.where(change != 0.0, past * np.sign(change), np.abs(past)))),
                 0.0)
    scale = max(float(np.max(np.abs(change))), _MIN_CHANGE_PA)
    return {'overshoot_mm': over * 1e3, 'overshoot_frac': over / size, 'late_mm': late * 1e3,
            'command_excess': beyond / scale, 'command_beyond_kpa': beyond * 1e-3}


def held_case(model: RobotModel, robot: SimulatedRobot, payload_kg: float = 0.0,
              duration_s: float = 8.0, loop: Loop = default_loop) -> dict:
    """A held target, the first after start: RMSE and largest error over the last half.

    The robot starts where its regulators are (vented); ``first_*``: the
    figures of :func:`step_case` for the move from there to the target
    (``first_overshoot_frac``, ``first_command_excess``, ...).
    """
    sim = loop(model, robot, payload_kg)
    p, z = _rest_pose(model, payload_kg)
    t0 = robot.time_s
    before = robot.regulators.command_pa.copy()
    start, _ = robot.true_pose()
    rec = sim.run(duration_s, lambda t: (p, z))
    first = _step_figures(rec, t0, start, p, before)
    return {**rec.summary(t0 + duration_s / 2), **{f'first_{k}': v for k, v in first.items()},
            **_health(sim, rec)}


def circle_case(model: RobotModel, robot: SimulatedRobot, speed: float,
                payload_kg: float = 0.0, loop: Loop = default_loop, settle_s: float = 3.0,
                spin_up_s: float = 1.0) -> dict:
    """The paper's circle at ``speed`` times its speed: RMSE over the second full period."""
    sim = loop(model, robot, payload_kg)
    period = 20.0 / speed
    path = paper_circle(model.cfg, period)
    sim.run(settle_s, lambda t: path(0.0))
    t0 = robot.time_s
    rec = sim.run(spin_up_s + 2 * period, lambda t: path(spin_up(t - t0, spin_up_s)))
    start = t0 + spin_up_s + period
    return {**rec.summary(start, start + period), **_health(sim, rec)}


def step_case(model: RobotModel, robot: SimulatedRobot, payload_kg: float = 0.0,
              loop: Loop = default_loop, hold_s: float = 5.0, after_s: float = 4.0) -> dict:
    """A 10 mm step target in ``y`` after ``hold_s`` of the held one (:func:`_step_figures`)."""
    sim = loop(model, robot, payload_kg)
    p, z = _rest_pose(model, payload_kg)
    goal = p + STEP_M * np.array([0.0, 1.0, 0.0])
    rec = sim.run(hold_s, lambda t: (p, z))
    ts = robot.time_s
    rec = sim.run(after_s, lambda t: (p if t < ts else goal, z), record=rec)
    a = rec.arrays()
    before = a['command_pa'][a['t'] < ts][-1]
    return {**_step_figures(rec, ts, p, goal, before), **_health(sim, rec)}
