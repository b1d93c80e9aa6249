"""The main job (``make demo``): a robot that is not the model, feedforward then closed loop.

For each of two cases, one segment on the paper's planar circle and two
segments on the paper's bending circle at 10 deg, it runs the pipeline as
separate processes on an isolated random ``ROS_DOMAIN_ID`` (localhost
discovery)::

    trajectory_publisher --target_pose--> inverse_kinetostatic_node (default model)
        --pressure_command--> simulated_robot_node (config/*_mismatched.yaml)
        --measured_pose--> (back to the inverse node when feedback is on)
        --measured_pressure--> forward_kinetostatic_node --predicted_pose-->

first with ``feedback: none`` (the paper's feedforward controller), then with
``feedback: integral`` (one segment: both at once, in two domains; two
segments: one after the other).  Each run: the nodes come up; this process
holds the path's first point (lead-in) until the trajectory publisher,
started with ``start_delay_s`` = ``--lead-in`` (default 2 s) once the lead-in
targets reach the inverse node, sends its first target; one full period
(20 s, 25 s) is evaluated; then the trajectory publisher stops and the last
target is held (``--hold``, default 4 s) for the steady-state error.

Measured = ``measured_pose`` of the simulated robot (motion capture with
0.15 mm noise), each sample against the newest target that had arrived
before it.  Printed: RMSE and maximum of the position error (mm) and, for two
segments, of the end-effector z-axis angle error (deg), for feedforward and
closed loop, next to the paper's figures for its real robot; the
steady-state error on the held target (error of the mean measured pose over
the last half of the hold); the model's own error (forward node's prediction
from the measured pressures vs the measured pose); the pressure safety
check.  Writes a PNG (``--plot``, default ``demo_tracking.png``): 3-D paths
(target, measured under feedforward, measured in closed loop) and the errors
over time.

Exit status 0 when every run flowed, every pressure command was finite and
within the limits, and the closed loop met the goals (RMSE at most 25 % of
the feedforward RMSE; steady-state error at most 0.3 mm for one segment and
0.5 mm / 0.5 deg for two); 1 otherwise.
"""

from __future__ import annotations

import argparse
import math
import random
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.geometry import angle_between
from .closed_loop_plot import MODE_NAMES, MODES, PAPER, plot
from .closed_loop_plot import rms as _rms
from .pipeline import NodeProcess, Recorder, child_env, tidy, wait_until, wait_up

RMSE_RATIO_GOAL = 0.25
STEADY_GOALS = {1: (0.3, None), 2: (0.5, 0.5)}   # segments -> (mm, deg)


@dataclass(frozen=True)
class Case:
    """One demo case: the controller's robot and the trajectory."""

    robot: str
    trajectory: str
    period_s: float
    bending_angle_deg: float | None
    label: str
    parallel: bool

    @property
    def plant(self) -> str:
        """The simulated robot's file: the shipped mismatched one."""
        return self.robot + '_mismatched'


CASES = (
    Case('one_segment', 'planar_circle', 20.0, None, 'one segment, planar circle', True),
    Case('two_segment', 'bending_circle', 25.0, 10.0, 'two segments, bending circle at 10 deg',
         False),
)


# ---------------------------------------------------------------- one run
def _recorder(domain: int) -> Recorder:
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped
    from std_msgs.msg import Float64MultiArray
    return Recorder(domain, {
        'target_pose': PoseStamped, 'pressure_command': Float64MultiArray,
        'measured_pose': PoseStamped, 'predicted_pose': PoseStamped,
        '/diagnostics': DiagnosticArray})


class Run:
    """One case in one mode: its node processes, recorder and phase times."""

    def __init__(self, case: Case, mode: str, args, domain: int, log_dir: Path) -> None:
        """Start the robot, inverse and forward node processes and the recorder."""
        self.case, self.mode, self.args, self.log_dir = case, mode, args, log_dir
        self.name = f'{case.label}, {MODE_NAMES[mode]}'
        self.env = child_env(domain)
        self.rec = _recorder(domain)
        self.procs: dict[str, NodeProcess] = {}
        self.tag = f'{case.robot}_{mode}_'
        self.ok = True
        self.times: dict[str, float] = {}
        self.stopped: set = set()
        self.t0 = time.monotonic()
        self.procs['robot'] = NodeProcess('simulated_robot_node', {
            'robot_config': case.plant, 'seed': args.seed,
            'physics_rate_hz': args.physics_rate}, self.env, log_dir, tag=self.tag)
        self.procs['inverse'] = NodeProcess('inverse_kinetostatic_node', {
            'robot_config': case.robot, 'feedback': mode}, self.env, log_dir, tag=self.tag)
        self.procs['forward'] = NodeProcess('forward_kinetostatic_node', {
            'robot_config': case.robot, 'max_rate_hz': 5.0}, self.env, log_dir,
            remaps={'pressure_command': 'measured_pressure'}, tag=self.tag)

    def _check(self) -> None:
        dead = [k for k, p in self.procs.items() if not p.alive() and k not in self.stopped]
        if dead:
            raise RuntimeError(f'node(s) died: {dead}')

    def wait_up(self) -> None:
        """Wait until the robot measures, the forward node predicts, the inverse commands."""
        rec = self.rec
        if not wait_up(self.procs.values(),
                       lambda: rec.count('measured_pose') > 0
                       and rec.count('predicted_pose') > 0
                       and rec.publishers('pressure_command') >= 1
                       and all(p.alive() for p in self.procs.values()),
                       self.args.startup_timeout):
            raise RuntimeError('nodes did not come up')

    def start_trajectory(self) -> None:
        """Hold the path's first point (lead-in), start the trajectory publisher after it.

        The lead-in targets come from this process (stamp zero) at 10 Hz until the
        trajectory publisher's first target (a real stamp) arrives (checked on
        every lead-in tick, so that no lead-in target follows it); it waits
        ``--lead-in`` seconds after its start-up (``start_delay_s``).
        """
        from geometry_msgs.msg import PoseStamped

        from ..core.experiments import trajectory
        from ..core.geometry import quaternion_from_z_axis
        from ..nodes.ros_util import command_qos, pose_message
        case = self.case
        kw = {'period': case.period_s}
        if case.bending_angle_deg is not None:
            kw['bending_angle_deg'] = case.bending_angle_deg
        pos, z = trajectory(case.trajectory, 0.0, case.robot, **kw)
        q = (0.0, 0.0, 0.0, 1.0) if z is None else quaternion_from_z_axis(z[0])
        first = pose_message(pos[0], q, 'base', self._zero_stamp())
        pub = self.rec.node.create_publisher(PoseStamped, 'target_pose', command_qos())
        self._target_pub = pub
        if not wait_until(lambda: pub.get_subscription_count() >= 1, self.args.startup_timeout):
            raise RuntimeError('the inverse node does not subscribe target_pose')

        def lead_in() -> None:
            # stop at once when the trajectory flows: a lead-in target after that would
            # pull the robot back to the path's first point (latest target wins)
            if self._first_trajectory_target() is not None:
                self._lead_in.cancel()
            else:
                pub.publish(first)
        self._lead_in = self.rec.node.create_timer(0.1, lead_in)
        traj = {'robot_config': case.robot, 'trajectory': case.trajectory, 'rate_hz': 10.0,
                'period_s': case.period_s, 'start_delay_s': self.args.lead_in}
        if case.bending_angle_deg is not None:
            traj['bending_angle_deg'] = case.bending_angle_deg
        self.procs['trajectory'] = NodeProcess('trajectory_publisher', traj, self.env,
                                               self.log_dir, tag=self.tag)

    @staticmethod
    def _zero_stamp():
        from builtin_interfaces.msg import Time
        return Time(sec=0, nanosec=0)

    def _first_trajectory_target(self) -> float | None:
        with self.rec.lock:
            for t, m in self.rec.msgs['target_pose']:
                if m.header.stamp.sec != 0 or m.header.stamp.nanosec != 0:
                    return t
        return None

    def wait_flowing(self) -> None:
        """Wait for the trajectory publisher's first target; set the evaluation window."""
        ok = wait_until(lambda: self._first_trajectory_target() is not None,
                        self.args.startup_timeout + self.args.lead_in)
        self._lead_in.cancel()
        if not ok:
            raise RuntimeError('no target from the trajectory publisher')
        self.times['eval'] = self._first_trajectory_target()
        self.times['stop'] = self.times['eval'] + self.case.period_s
        print(f'  {self.name}: trajectory started {time.monotonic() - self.t0:.1f} s after '
              f'the nodes; {self.case.period_s:g} s evaluated, then {self.args.hold:g} s hold',
              flush=True)

    def run_until_stop(self) -> None:
        """Wait for the end of the evaluated period (a dead node raises)."""
        while time.monotonic() < self.times['stop']:
            time.sleep(0.05)
            self._check()

    def stop_trajectory(self) -> None:
        """Stop the trajectory publisher: the last target is held from now on.

        The newest target this process recorded is republished at 10 Hz during
        the hold, so that the inverse node holds the same target as the one the
        measured poses are compared with (a publisher stopped by a signal may
        have sent a last sample that only one of the two received).
        """
        self.procs['trajectory'].stop()
        self.stopped.add('trajectory')
        with self.rec.lock:
            _, last = self.rec.msgs['target_pose'][-1]
        self._hold_timer = self.rec.node.create_timer(
            0.1, lambda: self._target_pub.publish(last))
        self.times['hold'] = time.monotonic()
        self.times['end'] = self.times['hold'] + self.args.hold

    def hold(self) -> None:
        """Wait until the end of the hold phase (a dead node raises)."""
        while time.monotonic() < self.times['end']:
            time.sleep(0.05)
            self._check()
        self._hold_timer.cancel()

    def fail(self, exc: Exception) -> None:
        """Report a failed run with the nodes' last log lines."""
        print(f'FAILED ({self.name}): {exc}')
        for p in self.procs.values():
            print(f'--- {p.module} log (last lines):\n{p.tail()}')
        self.ok = False

    def finish(self) -> dict:
        """Stop the nodes (SIGINT, the inverse vents), close the recorder; the recording."""
        for p in self.procs.values():
            p.interrupt()                   # all at once: they shut down in parallel
        codes = {k: p.stop() for k, p in reversed(list(self.procs.items()))}
        bad = {k: c for k, c in codes.items() if c not in (0, None)}
        if bad:
            print(f'  {self.name}: nodes exited with non-zero codes: {bad}')
            self.ok = False
        snap = self.rec.snapshot()
        self.rec.close()
        return dict(self.times, ok=self.ok and 'end' in self.times, rec=snap)


def run_case(case: Case, args, domains: list, log_dir: Path) -> dict:
    """Feedforward and closed loop of one case: both node sets start together.

    ``args.parallel``: both trajectories run at the same time (cheap one-segment
    case); otherwise feedforward first, closed loop once its trajectory stopped
    (the feedforward hold overlaps the closed loop's start).
    """
    runs = [Run(case, mode, args, domains.pop(), log_dir) for mode in MODES]
    out = {}
    try:
        for r in runs:
            r.wait_up()
        order = [runs] if case.parallel else [[r] for r in runs]
        previous = None
        for group in order:
            for r in group:
                r.start_trajectory()
            if previous is not None:
                for r in previous:
                    r.hold()
                    out[r.mode] = r.finish()   # free the CPU for the next group
            for r in group:
                r.wait_flowing()
            for r in group:
                r.run_until_stop()
            for r in group:
                r.stop_trajectory()
            previous = group
        for r in previous:
            r.hold()
    except Exception as exc:  # noqa: BLE001 - report, clean up, fail
        for r in runs:
            r.fail(exc)
    for r in runs:
        if r.mode not in out:
            out[r.mode] = r.finish()
    return out


# ---------------------------------------------------------------- analysis
def _pose(msg):
    from ..core.geometry import z_axis_from_quaternion
    p, o = msg.pose.position, msg.pose.orientation
    return np.array([p.x, p.y, p.z]), z_axis_from_quaternion((o.x, o.y, o.z, o.w))


def analyse(run: dict, cfg) -> dict:
    """Errors of the measured pose against the target, steady state, model error, safety."""
    rec = run['rec']
    tt = np.array([t for t, _ in rec['target_pose']])
    targets = [_pose(m) for _, m in rec['target_pose']]
    meas = [(t, *_pose(m)) for t, m in rec['measured_pose']]
    rows = []
    for t, p, z in meas:
        if not run['eval'] <= t <= run['stop']:
            continue
        i = int(np.searchsorted(tt, t, side='right')) - 1
        if i >= 0:
            rows.append((t - run['eval'], targets[i][0], targets[i][1], p, z))
    res = {'n_targets': len(targets), 'n_measured': len(rows)}
    if rows:
        res['t'] = np.array([r[0] for r in rows])
        res['target'] = np.array([r[1] for r in rows])
        res['measured'] = np.array([r[3] for r in rows])
        res['pos_err'] = np.linalg.norm(res['measured'] - res['target'], axis=1)
        res['ang_err'] = angle_between(np.array([r[2] for r in rows]),
                                       np.array([r[4] for r in rows]))
    # steady state: the last target, held; mean of the measured poses over the last half
    last = [i for i, t in enumerate(tt) if t <= run['hold']]
    held = [(p, z) for t, p, z in meas if 0.5 * (run['hold'] + run['end']) <= t <= run['end']]
    if last and held:
        tp, tz = targets[last[-1]]
        mp = np.mean([h[0] for h in held], axis=0)
        mz = np.mean([h[1] for h in held], axis=0)
        res['steady_mm'] = float(np.linalg.norm(mp - tp) * 1e3)
        res['steady_deg'] = float(np.degrees(angle_between(tz, mz / np.linalg.norm(mz))))
    # the model's own error: prediction from measured pressures vs the measured pose
    mt = np.array([m[0] for m in meas])
    model_err = []
    for t, m in rec['predicted_pose']:
        if run['eval'] <= t <= run['stop']:
            near = [meas[j][1] for j in np.flatnonzero(np.abs(mt - t) <= 0.05)]
            if near:
                model_err.append(np.linalg.norm(_pose(m)[0] - np.mean(near, axis=0)))
    res['model_rms_mm'] = (float(np.sqrt(np.mean(np.square(model_err))) * 1e3) if model_err
                           else None)
    # pressure safety over the whole run
    cmds = [np.asarray(m.data, dtype=float) for _, m in rec['pressure_command']]
    res['n_commands'] = len(cmds)
    res['safe'] = bool(cmds) and all(
        c.shape == (cfg.n_actuators_total,) and np.all(np.isfinite(c))
        and np.all((c >= cfg.p_min) & (c <= cfg.p_max)) for c in cmds)
    res['vent'] = [float(v) for v in cmds[-1]] if cmds else None
    levels = [0, 0, 0]
    for _, arr in rec['/diagnostics']:
        for st in arr.status:
            if 'inverse' in st.name:
                lvl = st.level[0] if isinstance(st.level, (bytes, bytearray)) else int(st.level)
                if lvl < 3:
                    levels[lvl] += 1
    res['levels'] = levels
    return res


# ---------------------------------------------------------------- main
def _parse(argv):
    ap = argparse.ArgumentParser(prog='python -m bellow_ancf_ros.demos.closed_loop',
                                 description=__doc__.split('\n\n')[0])
    ap.add_argument('--plot', default='demo_tracking.png',
                    help='PNG output (default: %(default)s)')
    ap.add_argument('--lead-in', type=float, default=2.0,
                    help='[s] the path\'s first point is held at least this long')
    ap.add_argument('--hold', type=float, default=4.0, help='[s] the last target is held')
    ap.add_argument('--period-scale', type=float, default=1.0,
                    help='scale the trajectory periods (20 s, 25 s) by this (tests: shorter runs)')
    ap.add_argument('--seed', type=int, default=1, help='motion-capture noise seed')
    ap.add_argument('--physics-rate', type=float, default=25.0,
                    help='simulated robot physics rate [Hz] (default: %(default)s)')
    ap.add_argument('--startup-timeout', type=float, default=40.0, help='[s]')
    ap.add_argument('--cases', default='one_segment,two_segment',
                    help='comma-separated robots to run (default: %(default)s)')
    ap.add_argument('--no-goals', action='store_true',
                    help='exit 0 without checking the closed-loop goals (short test runs)')
    return ap.parse_args(argv)


def _fmt(r: dict, two: bool) -> str:
    if 'pos_err' not in r:
        return 'no data'
    s = f'{_rms(r["pos_err"]) * 1e3:6.2f} mm (max {r["pos_err"].max() * 1e3:5.2f})'
    if two:
        s += (f', {math.degrees(_rms(r["ang_err"])):5.2f} deg '
              f'(max {math.degrees(r["ang_err"].max()):4.2f})')
    return s


def main(argv=None) -> int:
    """Run the cases, print the summary, write the plot; exit status 0 when the goals hold."""
    args = _parse(argv)
    from ..core import load_robot
    from ..core import limit_blas_threads
    limit_blas_threads()
    log_dir = Path(tempfile.mkdtemp(prefix='bellow_ancf_ros_demo_'))
    domains = random.sample(range(102), 2 * len(CASES))
    print('bellow_ancf_ros main job: the default model controls a simulated robot that is not '
          f'the model (config/*_mismatched.yaml); node logs in {log_dir} (kept if it fails)')
    t_all = time.monotonic()
    results, ok = {}, True
    cases = [c for c in CASES if c.robot in args.cases.split(',')]
    for case in cases:
        case_run = Case(case.robot, case.trajectory, case.period_s * args.period_scale,
                        case.bending_angle_deg, case.label, case.parallel)
        cfg = load_robot(case.robot)
        results[case.robot] = {}
        for mode, run in run_case(case_run, args, domains, log_dir).items():
            if not run['ok']:
                ok = False
                continue
            results[case.robot][mode] = analyse(run, cfg)
            results[case.robot][mode]['raw'] = run
    print(f'\nmeasured pose vs target over one trajectory period ({PAPER}):')
    passed = ok and bool(cases)
    for case in cases:
        two = case.bending_angle_deg is not None
        res = results.get(case.robot, {})
        print(f'  {case.label} (controller: default model, robot: {case.plant}):')
        for mode in MODES:
            r = res.get(mode)
            if r is None:
                print(f'    {MODE_NAMES[mode]:12s} FAILED')
                passed = False
                continue
            steady = ('n/a' if 'steady_mm' not in r else f'{r["steady_mm"]:.3f} mm'
                      + (f' / {r["steady_deg"]:.3f} deg' if two else ''))
            model = 'n/a' if r['model_rms_mm'] is None else f'{r["model_rms_mm"]:.2f} mm'
            print(f'    {MODE_NAMES[mode]:12s} RMSE {_fmt(r, two)}; held target: {steady}; '
                  f'{r["n_measured"]} samples; model vs robot {model}')
            print(f'    {"":12s} {r["n_commands"]} pressure commands, all finite and within '
                  f'the limits: {"yes" if r["safe"] else "NO"}; last (vent): '
                  f'{[round(v, 3) for v in r["vent"]] if r["vent"] else None}; inverse '
                  f'diagnostics {r["levels"][0]} OK / {r["levels"][1]} WARN / '
                  f'{r["levels"][2]} ERROR')
            passed &= r['safe']
        ff, cl = res.get('none'), res.get('integral')
        if ff and cl and 'pos_err' in ff and 'pos_err' in cl:
            ratio = _rms(cl['pos_err']) / _rms(ff['pos_err'])
            goal_mm, goal_deg = STEADY_GOALS[2 if two else 1]
            steady_ok = cl.get('steady_mm', math.inf) <= goal_mm and (
                goal_deg is None or cl.get('steady_deg', math.inf) <= goal_deg)
            line = f'    closed-loop / feedforward position RMSE: {ratio * 100:.1f} %'
            if two:
                line += (f', angle RMSE: '
                         f'{_rms(cl["ang_err"]) / _rms(ff["ang_err"]) * 100:.1f} %')
            print(line + f' (goal <= {RMSE_RATIO_GOAL * 100:.0f} %); held-target goal '
                  f'<= {goal_mm} mm' + (f' / {goal_deg} deg' if goal_deg else '')
                  + f': {"met" if steady_ok else "NOT met"}')
            if not args.no_goals:
                passed &= ratio <= RMSE_RATIO_GOAL and steady_ok
    path = Path(args.plot)
    plot(results, cases, path)
    print(f'  plot written to {path}; total {time.monotonic() - t_all:.0f} s')
    print('PASS' if passed else 'FAIL')
    tidy(log_dir, passed)
    return 0 if passed else 1


if __name__ == '__main__':
    sys.exit(main())
