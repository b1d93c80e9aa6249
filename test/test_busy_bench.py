"""bench/busy_bench.py without ROS processes: its targets, its figures, its goals."""

import dataclasses
import os
import sys

import numpy as np
import pytest

from bellow_ancf_ros.core import load_robot
from bellow_ancf_ros.core.loop import STEP_M

ROOT = os.path.join(os.path.dirname(__file__), "..")
sys.path.insert(0, os.path.join(ROOT, "bench"))
import busy_bench  # noqa: E402

pytest.importorskip('diagnostic_msgs')
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402

T0 = 1.7e9   # the stream's start [s, ROS time]


@pytest.fixture(scope='module')
def cfg():
    return load_robot('one_segment')


def test_targets_hold_circle_back_home_then_step(cfg):
    s = busy_bench.Schedule()
    tg = busy_bench.Targets(cfg, s)
    home = tg.home[0]
    assert s.end_s == pytest.approx(8.0 + 7.0 + 3.0 + 4.0)
    for t in (0.0, 7.99):
        np.testing.assert_array_equal(tg(t)[0], home)
    t = np.arange(0.0, s.end_s, 0.02)
    p = np.array([tg(x)[0] for x in t])
    circle = (t >= s.held_s) & (t < s.held_s + s.circle_s)
    assert np.ptp(p[circle, 0]) > 0.015   # the circle is run (10.4 mm radius)
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    k = int(np.argmax(step))
    assert t[k + 1] == pytest.approx(s.step_at) and step[k] == pytest.approx(STEP_M)
    # otherwise smooth: the circle starts and stops without a jump and ends where it began
    assert np.delete(step, k).max() < 0.002
    np.testing.assert_allclose(tg(s.held_s + s.circle_s - 1e-9)[0], home, atol=1e-6)
    np.testing.assert_allclose(tg(s.end_s)[0], home + [0.0, STEP_M, 0.0])
    # the evaluated period is at full speed: after the spin-up, before the spin-down
    a, b = s.circle_window
    assert a >= s.held_s + busy_bench.SPIN_S and b <= s.held_s + busy_bench.SPIN_S + s.full_s
    short = busy_bench.Schedule(held_s=4.0, circle_periods=2, settle_s=0.0, after_s=0.0)
    assert short.circle_window is None and short.step_at is None and short.end_s == 9.0


def _pose(t, p):
    m = PoseStamped()
    m.header.stamp.sec, m.header.stamp.nanosec = int(t), int(round(t % 1.0 * 1e9))
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in p)
    m.pose.orientation.w = 1.0
    return m


def _diag(t, name, values):
    arr = DiagnosticArray()
    arr.header.stamp.sec, arr.header.stamp.nanosec = int(t), int(round(t % 1.0 * 1e9))
    arr.status = [DiagnosticStatus(name=name, message='target reached',
                                   values=[KeyValue(key=k, value=str(v))
                                           for k, v in values.items()])]
    return arr


def test_figures_of_a_recording(cfg):
    """Periods, a gap, a bad command, ages outside a dropout, jump holds, errors, trips."""
    s = busy_bench.Schedule(held_s=4.0, circle_periods=1, settle_s=1.0, after_s=3.0)
    tg = busy_bench.Targets(cfg, s)
    rx = list(np.arange(T0, T0 + s.end_s, 0.02))
    rx = [t for t in rx if not T0 + 2.0 < t < T0 + 2.6]   # one 0.62 s gap
    good = (10e3, 20e3, 30e3)
    cmds = [(int(t * 1e9), int(t * 1e9), good, 'actuator_pressure_gauge_pa') for t in rx]
    cmds[-1] = (cmds[-1][0], cmds[-1][1], (10e3, 20e3, 900e3), 'actuator_pressure_gauge_pa')
    # true poses at 120 Hz: 0.1 mm off the target in x; the step reached at once, 0.2 mm past
    ts = np.arange(T0, T0 + s.end_s, 1 / 120)
    off = np.array([1e-4, 0.0, 0.0])
    true = [_pose(t, tg(t - T0)[0] + (off if t - T0 < s.step_at else [0.0, 2e-4, 0.0]))
            for t in ts]
    # the motion capture: nothing captured from 1.0 to 1.5 s (a dropout; true poses flow)
    measured = [t for t in ts if not T0 + 1.0 < t < T0 + 1.5]
    inv = busy_bench.INVERSE
    # on the circle (4-7 s), its first half holding the correction for a target jump
    diag = [_diag(T0 + t, f'{inv}: inverse kinetostatics',
                  {'measured_pose_age_s': 0.4 if 1.0 < t < 1.6 else 0.02,
                   'solve_time_ms': 1.5, 'oscillation_trips': 0,
                   'feedback_state': ('holding the correction: a move of its own (a target '
                                      'jump, a stopped stream braking)' if 4.0 <= t < 5.5
                                      else 'integrating')})
            for t in np.arange(0.05, s.end_s, 0.1)]
    diag.append(_diag(T0 - 0.5, f'{inv}: status', {'targets_published': 10,
                                                   'oscillation_trips': 0}))
    diag.append(_diag(T0 + 5.5, f'{inv}: status', {'targets_published': 310,
                                                   'oscillation_trips': 2}))
    diag.append(_diag(T0 + s.end_s, f'{inv}: status', {'targets_published': 410,
                                                       'oscillation_trips': 2}))
    data = {'commands': cmds, 'true': true, 'measured': measured, 'diag': diag,
            'sent': list(np.arange(T0, T0 + s.end_s, 0.02))}
    f = busy_bench.figures(data, cfg, tg, T0)
    assert f['period_ms']['p50'] == pytest.approx(20.0, abs=0.01)
    assert f['period_ms']['max'] == pytest.approx(620.0, abs=1.0)
    assert f['gaps_over_0_5_s'] == 1
    assert f['commands_bad'] == 1 and not f['commands_safe']
    assert f['dropouts'] == 1
    assert f['age_ms']['max'] == pytest.approx(20.0)   # the dropout's ages are left out
    assert f['trips'] == 2 and f['counts']['published'] == 400
    assert f['trip_at_s'] == [5.5, 5.5]   # two trips first reported together, on the circle
    assert busy_bench.phase(dataclasses.asdict(s), 5.5) == 'circle'
    assert f['held_rmse_mm'] == pytest.approx(0.1, rel=1e-3)
    assert f['step_overshoot_mm'] == pytest.approx(0.2, rel=1e-3)
    assert f['step_late_mm'] == pytest.approx(0.2, rel=1e-3)
    assert f['circle_jump_pct'] == pytest.approx(50.0, abs=4.0)
    assert f['circle_rmse_mm'] is None and f['held_rmse_deg'] is None   # no 2nd full period


def _run(period_p99, held, trips=0):
    return {'period_ms': {'p50': 20.0, 'p99': period_p99, 'max': 40.0},
            'age_ms': {'p50': 15.0, 'p99': 25.0}, 'held_rmse_mm': held, 'held_rmse_deg': None,
            'circle_rmse_mm': None, 'circle_rmse_deg': None, 'step_overshoot_mm': None,
            'step_late_mm': None, 'trips': trips, 'commands_safe': True}


def test_goals_ratio_nominal_and_trips():
    quiet, busy = _run(25.0, 0.10), _run(31.0, 0.14, 1)
    rows = {r['figure']: r for r in busy_bench.compare(quiet, busy, 0.05)}
    assert 'circle_mm' not in rows   # no figure in either run: no row
    assert rows['period_p99']['ratio'] == pytest.approx(1.24) and rows['period_p99']['met']
    assert not rows['held_mm']['met']   # 1.4x
    assert not rows['trips']['met'] and rows['commands_safe']['met']
    # within 1.3x but over twice the nominal period
    rows = {r['figure']: r for r in busy_bench.compare(_run(90.0, 0.1), _run(110.0, 0.1), 0.05)}
    assert not rows['period_p99']['met'] and rows['held_mm']['met']


def test_the_tracking_goals_hold_in_both_runs_beside_the_ratio():
    """A held error of 0.25 mm quiet and busy: within 1.3x, above two segments' 0.2 mm."""
    limits = busy_bench.tracking_goals(2)
    assert limits['held_mm'] == 0.2 and busy_bench.tracking_goals(1)['held_mm'] == 0.1
    rows = {r['figure']: r for r in busy_bench.compare(_run(25.0, 0.25), _run(25.0, 0.25),
                                                       0.05, limits)}
    assert rows['held_mm']['ratio'] == pytest.approx(1.0) and not rows['held_mm']['met']
    assert rows['held_mm']['goal'] == 'busy <= 1.3x quiet, both <= 0.2'
    rows = {r['figure']: r for r in busy_bench.compare(_run(25.0, 0.15), _run(25.0, 0.18),
                                                       0.05, limits)}
    assert rows['held_mm']['met']


def test_repeats_combine_into_medians_with_their_range_and_the_worst_checks():
    runs = [_run(25.0, 0.10), _run(31.0, 0.14, 1), _run(27.0, 0.30)]
    for r, t in zip(runs, ([], [3.5], [])):
        r.update(trip_at_s=t, oscillation_messages=[], commands_bad_examples=[])
    runs[2]['commands_safe'] = False
    got = busy_bench.combined(runs)
    assert got['period_ms']['p99'] == 27.0 and got['held_rmse_mm'] == pytest.approx(0.14)
    assert got['spread']['held_mm'] == (0.10, 0.30) and got['spread']['period_p99'] == (25.0, 31.0)
    assert got['trips'] == 1 and got['trip_at_s'] == [3.5] and not got['commands_safe']
    assert got['repeats'] == 3 and got['circle_rmse_mm'] is None
    assert runs[0]['held_rmse_mm'] == 0.10      # the runs themselves are left as they were
    one = busy_bench.combined(runs[:1])
    rows = {r['figure']: r for r in busy_bench.compare(got, one, 0.05)}
    assert rows['held_mm']['quiet_range'] == (0.10, 0.30)
    assert rows['held_mm']['busy_range'] == (0.10, 0.10)
