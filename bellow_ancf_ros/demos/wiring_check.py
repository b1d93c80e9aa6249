"""Wiring check of the ROS 2 pipeline: the model against itself.

``python -m bellow_ancf_ros.demos.wiring_check`` (a test runs it shortened;
``make demo`` runs the main job, :mod:`bellow_ancf_ros.demos.closed_loop`).

Starts the three nodes as separate processes, each in its own session, on an
isolated random ``ROS_DOMAIN_ID`` with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``,
on the default two-segment robot::

    trajectory_publisher --target_pose--> inverse_kinetostatic_node
        --pressure_command--> forward_kinetostatic_node --predicted_pose-->

runs a trajectory for about 20 s (default: the paper's circle at a 10 deg
bending angle, one period in 20 s, 10 targets per second), records
``target_pose``, ``pressure_command``, ``commanded_pose``, ``predicted_pose``
and ``/diagnostics`` with rclpy in this process, stops the nodes with SIGINT
to their process groups (SIGKILL after a timeout), prints a tracking summary
and writes a PNG plot (``--plot``, default ``wiring_check.png``).

Tracking error = target pose vs the pose the forward node predicts from the
pressures the inverse node commanded: the model's feedforward controller
closed through the model itself, across three processes.  Each prediction is
paired with its target through the inverse node's ``commanded_pose`` (which
carries the target's stamp): among the commands received from one second
before to half a second after the prediction, the one whose pose the
prediction reproduces.

Exit status 0 when the nodes came up, enough samples were paired, every
pressure was finite and within the limits, and the errors are below
``--max-position-error`` / ``--max-angle-error``; 1 otherwise.
"""

from __future__ import annotations

import argparse
import math
import random
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..core.geometry import angle_between
from .pipeline import NodeProcess, Recorder, child_env, tidy, wait_until, wait_up

ROBOT = 'two_segment'
TOPICS = ('target_pose', 'pressure_command', 'commanded_pose', 'predicted_pose', '/diagnostics')


def _recorder(domain: int) -> Recorder:
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped
    from std_msgs.msg import Float64MultiArray
    return Recorder(domain, {'target_pose': PoseStamped, 'pressure_command': Float64MultiArray,
                             'commanded_pose': PoseStamped, 'predicted_pose': PoseStamped,
                             '/diagnostics': DiagnosticArray})


NODES = ('inverse_kinetostatic_node', 'forward_kinetostatic_node', 'trajectory_publisher')


# ---------------------------------------------------------------- analysis
def _pose(msg):
    from ..core.geometry import z_axis_from_quaternion
    p, o = msg.pose.position, msg.pose.orientation
    return np.array([p.x, p.y, p.z]), z_axis_from_quaternion((o.x, o.y, o.z, o.w))


def _stamp(msg) -> tuple:
    return (msg.header.stamp.sec, msg.header.stamp.nanosec)


#: A prediction belongs to a command when it reproduces the command's pose to this [m]
#: (the forward model reproduces it to round-off, ~1e-13 m).
PAIR_TOL_M = 1e-6


def analyse(rec: dict, t_start: float, t_end: float) -> dict:
    """Pair predictions with targets (via commanded_pose stamps); errors and timings."""
    targets = {}
    for _, m in rec['target_pose']:
        targets[_stamp(m)] = m
    commanded = [(t, _stamp(m), _pose(m)[0]) for t, m in rec['commanded_pose']]
    rows = []   # (time, target pos, target z, predicted pos, predicted z)
    unmatched = 0
    for t_p, m in rec['predicted_pose']:
        if not (t_start <= t_p <= t_end):
            continue
        p_pos, p_z = _pose(m)
        # the command's pose may arrive after the prediction made from it (separate topics,
        # loaded machine): look 1 s back and 0.5 s ahead, the matching pose wins by distance
        cands = [(np.linalg.norm(c_pos - p_pos), stamp) for t_c, stamp, c_pos in commanded
                 if t_p - 1.0 <= t_c <= t_p + 0.5 and stamp in targets]
        if not cands:
            continue
        dist, stamp = min(cands, key=lambda c: c[0])
        if dist > PAIR_TOL_M:
            unmatched += 1  # a prediction from a command whose pose or target was not recorded
            continue
        t_pos, t_z = _pose(targets[stamp])
        rows.append((t_p, t_pos, t_z, p_pos, p_z))
    out = {'n_targets': sum(t_start <= t <= t_end for t, _ in rec['target_pose']),
           'n_commands': sum(t_start <= t <= t_end for t, _ in rec['pressure_command']),
           'n_predictions': sum(t_start <= t <= t_end for t, _ in rec['predicted_pose']),
           'n_paired': len(rows), 'n_unmatched': unmatched}
    if rows:
        t = np.array([r[0] for r in rows]) - t_start
        tp = np.array([r[1] for r in rows])
        tz = np.array([r[2] for r in rows])
        pp = np.array([r[3] for r in rows])
        pz = np.array([r[4] for r in rows])
        pos_err = np.linalg.norm(pp - tp, axis=1)
        ang_err = angle_between(tz, pz)
        out.update(t=t, target=tp, predicted=pp, pos_err=pos_err, ang_err=ang_err)
    solve = {'inverse': [], 'forward': []}
    levels = {'inverse': [0, 0, 0], 'forward': [0, 0, 0]}
    for t_d, arr in rec['/diagnostics']:
        if not (t_start <= t_d <= t_end):
            continue
        for st in arr.status:
            kind = ('inverse' if 'inverse' in st.name
                    else 'forward' if 'forward' in st.name else None)
            if kind is None:
                continue
            lvl = st.level[0] if isinstance(st.level, (bytes, bytearray)) else int(st.level)
            if lvl < 3:
                levels[kind][lvl] += 1
            for kv in st.values:
                if kv.key == 'solve_time_ms':
                    solve[kind].append(float(kv.value))
    out['solve_ms'] = {k: np.array(v) for k, v in solve.items()}
    out['levels'] = levels
    # pressure safety over the whole run
    out['pressures'] = [np.asarray(m.data, dtype=float) for _, m in rec['pressure_command']]
    return out


def _plot(res: dict, path: Path, title: str) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(12, 5.5))
    ax = fig.add_subplot(1, 2, 1, projection='3d')
    tp, pp = res['target'] * 1e3, res['predicted'] * 1e3
    ax.plot(tp[:, 0], tp[:, 1], tp[:, 2], 'o', ms=3, color='tab:blue', label='target')
    ax.plot(pp[:, 0], pp[:, 1], pp[:, 2], '-', lw=1.5, color='tab:orange', label='predicted')
    ax.set_xlabel('x [mm]')
    ax.set_ylabel('y [mm]')
    ax.set_zlabel('z [mm]')
    ax.set_title('end-effector path (base frame)')
    ax.legend(loc='upper left')
    floor = 1e-16   # exact zeros (and round-off below it) are drawn at the floor
    ax1 = fig.add_subplot(2, 2, 2)
    ax1.semilogy(res['t'], np.maximum(res['pos_err'] * 1e3, floor), '.-', color='tab:red', ms=3)
    ax1.set_ylabel('position error [mm]')
    ax1.set_title('target vs predicted (log scale)', fontsize=9)
    ax1.grid(True, which='both', alpha=0.3)
    ax2 = fig.add_subplot(2, 2, 4, sharex=ax1)
    ax2.semilogy(res['t'], np.maximum(np.degrees(res['ang_err']), floor), '.-',
                 color='tab:green', ms=3)
    ax2.set_ylabel('angle error [deg]')
    ax2.set_xlabel('time [s]')
    ax2.grid(True, which='both', alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------- main
def _parse(argv):
    ap = argparse.ArgumentParser(prog='python -m bellow_ancf_ros.demos.wiring_check',
                                 description=__doc__.split('\n\n')[0])
    ap.add_argument('--plot', default='wiring_check.png',
                    help='PNG output path (default: %(default)s)')
    ap.add_argument('--duration', type=float, default=20.0, help='trajectory run time [s]')
    ap.add_argument('--trajectory', default='bending_circle',
                    help='trajectory name (default: %(default)s)')
    ap.add_argument('--bending-angle', type=float, default=10.0,
                    help='bending angle [deg] of bending_circle')
    ap.add_argument('--period', type=float, default=20.0, help='trajectory period [s]')
    ap.add_argument('--rate', type=float, default=10.0, help='target rate [Hz]')
    ap.add_argument('--robot', default=ROBOT, help='robot config (default: %(default)s)')
    ap.add_argument('--max-position-error', type=float, default=1e-4, help='pass threshold [m]')
    ap.add_argument('--max-angle-error', type=float, default=1e-3, help='pass threshold [rad]')
    ap.add_argument('--startup-timeout', type=float, default=30.0, help='[s]')
    ap.add_argument('--domain-id', type=int, default=None,
                    help='ROS_DOMAIN_ID for the run, 0..101 (default: random)')
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = _parse(argv)
    from ..core import load_robot
    from ..core import limit_blas_threads
    limit_blas_threads()
    cfg = load_robot(args.robot)
    domain = random.randint(0, 101) if args.domain_id is None else args.domain_id
    if not 0 <= domain <= 101:
        print(f'--domain-id must be in 0..101, got {domain}')
        return 2
    env = child_env(domain)
    log_dir = Path(tempfile.mkdtemp(prefix='bellow_ancf_ros_wiring_'))
    print(f'bellow_ancf_ros ROS 2 pipeline demo: robot {cfg.name!r} ({cfg.n_segments} segment(s), '
          f'{cfg.n_actuators_total} actuators), ROS_DOMAIN_ID={domain}, node logs in {log_dir}')
    common_params = {'robot_config': args.robot}
    procs: dict[str, NodeProcess] = {}
    rec = None
    ok = True
    try:
        rec = _recorder(domain)
        t0 = time.monotonic()
        # the static pipeline checked against itself: the targets as they come (no smooth
        # start of the stream, no dynamic shift, which would be measured as errors here)
        procs['inverse'] = NodeProcess('inverse_kinetostatic_node',
                                       {**common_params, 'target_shaping': 'none',
                                        'dynamic_feedforward': False}, env, log_dir)
        procs['forward'] = NodeProcess('forward_kinetostatic_node', common_params, env, log_dir)
        up = wait_up(procs.values(), lambda: (rec.publishers('pressure_command') >= 1
                                              and rec.publishers('predicted_pose') >= 1
                                              and all(p.alive() for p in procs.values())),
                     args.startup_timeout)
        if not up:
            raise RuntimeError('inverse/forward nodes did not come up')
        print(f'  inverse and forward nodes up after {time.monotonic() - t0:.1f} s')
        traj_params = dict(common_params, trajectory=args.trajectory, rate_hz=float(args.rate),
                           period_s=float(args.period))
        if cfg.n_segments >= 2:
            traj_params['bending_angle_deg'] = float(args.bending_angle)
        n_pred = rec.count('predicted_pose')
        procs['trajectory'] = NodeProcess('trajectory_publisher', traj_params, env, log_dir)
        # the recorder must see the targets too (discovery of a new process takes up to ~3 s)
        if not wait_until(lambda: (rec.publishers('target_pose') >= 1
                                   and rec.count('predicted_pose') > n_pred),
                          args.startup_timeout):
            raise RuntimeError('no prediction arrived: the pipeline is not flowing')
        t_start = time.monotonic()
        print(f'  pipeline flowing; running {args.trajectory!r} for {args.duration:g} s ...')
        while time.monotonic() - t_start < args.duration:
            time.sleep(0.1)
            dead = [k for k, p in procs.items() if p.proc.poll() is not None]
            if dead:
                raise RuntimeError(f'node(s) died: {dead}')
        procs['trajectory'].stop()
        wait_until(lambda: False, 0.5)       # let the last commands and predictions arrive
        t_end = time.monotonic()
    except Exception as exc:  # noqa: BLE001 - report, clean up, fail
        print(f'FAILED: {exc}')
        for p in procs.values():
            print(f'--- {p.module} log (last lines):\n{p.tail()}')
        ok = False
        t_start = t_end = None
    finally:
        codes = {k: p.stop() for k, p in reversed(list(procs.items()))}
        snapshot = rec.snapshot() if rec is not None else None
        if rec is not None:
            rec.close()
    bad_exit = {k: c for k, c in codes.items() if c not in (0, None)}
    if bad_exit:
        print(f'  nodes exited with non-zero codes: {bad_exit}')
        ok = False
    if not ok or snapshot is None:
        return 1

    res = analyse(snapshot, t_start, t_end)
    vent = snapshot['pressure_command'][-1][1].data if snapshot['pressure_command'] else None
    pressures = (np.array(res['pressures']) if res['pressures']
                 else np.zeros((0, cfg.n_actuators_total)))
    safe = bool(pressures.size) and np.all(np.isfinite(pressures)) and np.all(
        (pressures >= cfg.p_min) & (pressures <= cfg.p_max))
    print()
    print(f'tracking summary ({args.trajectory}'
          + (f', bending angle {args.bending_angle:g} deg' if cfg.n_segments >= 2 else '')
          + f', period {args.period:g} s, {args.rate:g} Hz):')
    print(f'  messages: {res["n_targets"]} targets, {res["n_commands"]} pressure commands, '
          f'{res["n_predictions"]} predictions, {res["n_paired"]} paired with their targets'
          f' ({res["n_unmatched"]} not reproducing any recorded command)')
    if res['n_paired'] == 0:
        print('FAILED: no prediction could be paired with a target')
        return 1
    pe, ae = res['pos_err'], res['ang_err']
    print(f'  position error target vs predicted: RMS {math.sqrt(np.mean(pe**2)) * 1e3:.3g} mm, '
          f'max {pe.max() * 1e3:.3g} mm')
    ang_rms = np.degrees(math.sqrt(np.mean(ae**2)))
    print(f'  angle error target vs predicted z-axis: RMS {ang_rms:.3g} deg, '
          f'max {np.degrees(ae.max()):.3g} deg')
    for kind in ('inverse', 'forward'):
        s = res['solve_ms'][kind]
        if s.size:
            print(f'  {kind} solve time (from /diagnostics): median {np.median(s):.1f} ms, '
                  f'p99 {np.percentile(s, 99):.1f} ms, max {s.max():.1f} ms over {s.size} solves')
    lv = res['levels']['inverse']
    print(f'  inverse diagnostics: {lv[0]} OK, {lv[1]} WARN, {lv[2]} ERROR')
    print(f'  pressures: {len(pressures)} commands, all finite and within '
          f'[{cfg.p_min / 1e3:g}, {cfg.p_max / 1e3:g}] kPa: {"yes" if safe else "NO"}; '
          f'last command after shutdown (vent): {list(vent) if vent is not None else None}')
    path = Path(args.plot)
    _plot(res, path, f'bellow_ancf_ros pipeline: {cfg.name}, {args.trajectory}'
          + (f' at {args.bending_angle:g} deg' if cfg.n_segments >= 2 else '')
          + f' (RMS position error {math.sqrt(np.mean(pe**2)) * 1e3:.2g} mm)')
    print(f'  plot written to {path}')
    min_pairs = max(5, int(0.5 * args.duration * args.rate))
    passed = (safe and res['n_paired'] >= min_pairs and pe.max() <= args.max_position_error
              and ae.max() <= args.max_angle_error and lv[2] == 0)
    print('PASS' if passed else f'FAIL (need >= {min_pairs} paired samples, errors below '
                                f'{args.max_position_error:g} m / {args.max_angle_error:g} rad, '
                                'no ERROR, safe pressures)')
    tidy(log_dir, passed)
    return 0 if passed else 1


if __name__ == '__main__':
    sys.exit(main())
