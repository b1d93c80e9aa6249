"""The main job's step phase: a 10 mm step target, feedforward and closed loop (``make demo``).

The two-segment pipeline of :mod:`.closed_loop` (the mismatched realistic
robot, the default model, the commands compensated for the regulators'
documented 1 kPa play and the bellows' creep:
:func:`~.pipeline.hardware_parameters`) holds a target, then the target
jumps 10 mm sideways, published once (nobody previewed it).  The inverse
node runs with feedforward alone, ``target_shaping: none`` and ``zvd`` (the
shaper at the model's first mode at the held equilibrium), and closed on
the measured poses (``feedback: integral``, ``target_shaping: smooth``, the
correction carried to the step's goal: ``feedback_correction_frame:
model``).  Measured on the robot's true pose: the
overshoot along the step, the largest error from 1.5 s after it, and the residual swing from
1 s to 2 s after the step was published, the largest distance from a
quadratic fitted over that second (the bellows' creep moves the robot slowly
on; a quadratic takes that drift out and leaves the swing at the 2.4 Hz
mode), and the time the shaper adds (its delay, from the node's log).
Goals: shaped, a swing of at most :data:`STEP_GOAL_M`; closed loop, an
overshoot of at most :data:`OVERSHOOT_GOAL_M` and an error of at most
:data:`LATE_GOAL_M` from 1.5 s after the step.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..cli.output import number
from .pipeline import (NodeProcess, Recorder, TargetSender, child_env, clock_parameters,
                       hardware_parameters, message_time, start_clock, stop_all, wait_up,
                       wait_until)

__all__ = ['LATE_GOAL_M', 'OVERSHOOT_GOAL_M', 'RUNS', 'STEP_GOAL_M', 'STEP_M',
           'residual_swing', 'step_phase']

STEP_M = 0.010     # the step target's size
STEP_GOAL_M = 1e-4  # shaped: the residual swing 1-2 s after the step at most this
OVERSHOOT_GOAL_M = 5e-4   # closed loop: the overshoot along the step at most this (5 %)
LATE_GOAL_M = 2e-4        # closed loop: the error from 1.5 s after the step at most this
#: run -> (feedback, target_shaping)
RUNS = {'none': ('none', 'none'), 'zvd': ('none', 'zvd'), 'closed': ('integral', 'smooth')}

FIRST_S = 0.5      # [simulated s] the first target (on simulation time)
SETTLE_S = 8.0     # the first target is held until then (or this long) before the step
AFTER_S = 3.0      # the step target is held this long
ROBOT = 'two_segment'


def residual_swing(t: np.ndarray, positions: np.ndarray, start_s: float,
                   end_s: float) -> float:
    """Largest distance [m] of the positions in ``[start_s, end_s]`` from a quadratic fit.

    The fit (per coordinate, in time) takes out a slow drift (creep); what
    is left is the swing.
    """
    m = (t >= start_s) & (t <= end_s)
    if m.sum() < 5:
        raise ValueError(f'{int(m.sum())} samples in the residual window')
    tt = t[m] - t[m].mean()
    resid = np.column_stack([positions[m, k] - np.polyval(np.polyfit(tt, positions[m, k], 2), tt)
                             for k in range(3)])
    return float(np.linalg.norm(resid, axis=1).max())


def _targets():
    """The held pose and the step's pose: 10 mm sideways (a reachable pair of the bench)."""
    from ..core import RobotModel, load_robot, solve_forward
    fw = solve_forward(RobotModel(load_robot(ROBOT)), [30e3, 0, 0, 0, 0, 0])
    return (fw.position, fw.z_axis), (fw.position + np.array([0.0, STEP_M, 0.0]), fw.z_axis)


def _run(kind: str, args, domain: int, log_dir: Path, poses) -> dict:
    from geometry_msgs.msg import PoseStamped

    from ..core.geometry import quaternion_from_z_axis
    from ..nodes.ros_util import pose_message
    from builtin_interfaces.msg import Time
    env = child_env(domain)
    feedback, shaping = RUNS[kind]
    tag = f'step_{kind}_'
    rec = Recorder(domain, {'true_pose': PoseStamped}, name=f'ros_demo_step_{kind}',
                   sim_time=args.sim_time)
    procs = {
        'robot': NodeProcess('simulated_robot_node', {
            'robot_config': ROBOT + '_mismatched', 'seed': args.seed, 'plant': args.plant,
            'physics_rate_hz': args.physics_rate,
            **clock_parameters(args.sim_time, robot=True,
                               real_time_factor=args.real_time_factor)}, env, log_dir, tag=tag),
        'inverse': NodeProcess('inverse_kinetostatic_node', {
            'robot_config': ROBOT, 'feedback': feedback, 'target_shaping': shaping,
            **hardware_parameters(args.plant), **clock_parameters(args.sim_time)}, env,
            log_dir, tag=tag)}
    out = {'ok': False}
    targets = TargetSender(rec.node)
    try:
        pub = targets.pub
        if args.sim_time:   # robot, inverse node and this recorder on the clock, then it runs
            targets.hold(FIRST_S)   # the first target at the same simulated time in every run
            start_clock(rec, procs.values(), lambda: pub.get_subscription_count() >= 1, 3,
                        args.startup_timeout)
        if not wait_up(procs.values(), lambda: rec.count('true_pose') > 0
                       and pub.get_subscription_count() >= 1, args.startup_timeout):
            raise RuntimeError('nodes did not come up')
        msgs = [pose_message(p, quaternion_from_z_axis(z), 'base', Time(sec=0, nanosec=0))
                for p, z in poses]
        timer = None
        if args.sim_time:   # once, counted: the simulation waits for the inverse node to take it
            if not wait_until(targets.inverse_matched, args.startup_timeout):
                raise RuntimeError('the inverse node did not match the targets')
            rec.wait_for(FIRST_S)
            targets.send(msgs[0])
            targets.hold(SETTLE_S)   # the step at the same simulated time in every run
        else:
            timer = rec.node.create_timer(0.1, lambda: targets.send(msgs[0]))
        rec.wait_for(SETTLE_S if args.sim_time else rec.now() + SETTLE_S)
        if timer is not None:
            timer.cancel()   # the step target once (the node holds it): no re-solve of the same
        targets.send(msgs[1])   # target between the shaper's levels
        t_step = SETTLE_S if args.sim_time else rec.now()
        targets.hold(None)
        rec.wait_for(t_step + AFTER_S)
        snap = rec.snapshot()['true_pose']
        t = np.array([message_time(a, m, args.sim_time) for a, m in snap]) - t_step
        pos = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                        for _, m in snap])
        goal = poses[1][0]
        u = (goal - poses[0][0]) / STEP_M
        out.update(ok=True, swing_m=residual_swing(t, pos, 1.0, 2.0),
                   before_m=residual_swing(t, pos, -2.0, -0.5),
                   overshoot_m=max(float(np.max((pos[t >= 0] - goal) @ u)), 0.0),
                   late_m=float(np.linalg.norm(pos[t >= 1.5] - goal, axis=1).max()))
    except Exception as exc:  # noqa: BLE001 - report, clean up, fail
        print(f'FAILED (step, {kind}): {exc}')
        for p in procs.values():
            print(f'--- {p.module} log (last lines):\n{p.tail()}')
    targets.close()
    codes = stop_all(procs)   # the inverse node first: its vent reaches the others
    if any(c not in (0, None) for c in codes.values()):
        print(f'  step, {kind}: nodes exited with non-zero codes: {codes}')
        out['ok'] = False
    rec.close()
    out['log'] = procs['inverse'].log_path
    return out


def _shaper_line(log: Path) -> str:
    """The inverse node's line about its shaper (mode and delay), if it wrote one."""
    try:
        lines = [ln for ln in log.read_text().splitlines() if 'shaping' in ln.lower()]
    except OSError:
        return ''
    return lines[-1].split(']: ', 1)[-1] if lines else ''


def step_phase(args, domains: list, log_dir: Path) -> dict:
    """The three runs (:data:`RUNS`) and the printed comparison.

    Returns ``ran`` (every run ran), ``runs`` (per run, None if it failed:
    the residual swing 1-2 s after the step and before it, ``swing_mm``,
    ``before_mm``; the overshoot along the step, ``overshoot_mm``; the
    largest error from 1.5 s after it, ``late_mm``) and ``shaper`` (the
    shaped run's inverse node's line about its shaper).  The goals are the
    caller's to judge.
    """
    poses = _targets()
    print(f'\n10 mm step target, two segments (robot: {ROBOT}_mismatched, {args.plant} plant), '
          'published once: feedforward unshaped and ZVD-shaped, and the closed loop with the '
          'correction carried to the goal (true pose; residual swing 1-2 s after the step '
          'with a quadratic drift taken out)')
    todo = [(k, domains.pop()) for k in RUNS]
    # on simulation time side by side (each on its own clock, in lockstep: the cores'
    # sharing slows the runs, never changes them), else one after the other
    with ThreadPoolExecutor(1 if args.sequential else len(todo)) as pool:
        res = dict(zip(RUNS, pool.map(lambda kd: _run(kd[0], args, kd[1], log_dir, poses),
                                      todo)))
    runs = {}
    for k, r in res.items():
        runs[k] = None
        if r['ok']:
            runs[k] = {f'{f}_mm': r[f'{f}_m'] * 1e3
                       for f in ('swing', 'before', 'overshoot', 'late')}
            feedback, shaping = RUNS[k]
            print(f'  feedback {feedback:8s} target_shaping {shaping:6s}: overshoot '
                  f'{number(r["overshoot_m"] * 1e3)} mm, error from 1.5 s on '
                  f'{number(r["late_m"] * 1e3)} mm, residual swing '
                  f'{number(r["swing_m"] * 1e3)} mm (before the step: '
                  f'{number(r["before_m"] * 1e3)} mm)')
    line = _shaper_line(res['zvd']['log'])
    if line:
        print(f'    the shaped run\'s inverse node: {line}')
    return {'ran': all(r['ok'] for r in res.values()), 'runs': runs, 'shaper': line}
