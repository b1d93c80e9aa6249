"""The main job (`make demo`, demos.closed_loop), shortened: it runs, reports, plots."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip('rclpy')

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_main_demo_short_run_one_segment(tmp_path):
    plot = tmp_path / 'demo.png'
    env = dict(os.environ)
    env['PYTHONPATH'] = str(REPO) + os.pathsep + env.get('PYTHONPATH', '')
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    res = subprocess.run([sys.executable, '-m', 'bellow_ancf_ros.demos.closed_loop',
                          '--cases', 'one_segment', '--speeds', '4',
                          '--period-scale', '0.5', '--lead-in', '1', '--hold', '1.5',
                          '--no-goals', '--no-step', '--side-by-side', '--plot', str(plot)],
                         env=env, cwd=tmp_path, capture_output=True, text=True, timeout=200,
                         stdin=subprocess.DEVNULL)
    out = res.stdout + res.stderr
    assert res.returncode == 0, out
    assert 'PASS' in out
    for mode in ('feedforward', 'dynamic FF', 'closed loop'):
        line = next(ln for ln in out.splitlines() if ln.strip().startswith(mode + ' ')
                    and 'RMSE' in ln)
        assert 'held target' in line, line
    assert out.count('all finite and within the limits: yes') == 3
    assert out.count('last (vent): [0.000, 0.000, 0.000]') == 3
    assert 'closed-loop / feedforward position RMSE' in out
    assert 'dynamic / quasi-static feedforward position RMSE' in out
    assert 'realistic plant' in out and 'outliers (largest command step after one' in out
    for png in (plot, tmp_path / 'demo_1seg.png'):   # the summary and the detail page
        assert png.is_file() and png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    # the results file: in the working directory by default, every printed figure, the goals
    data = json.loads((tmp_path / 'demo_results.json').read_text())
    assert data['machine']['cpus'] >= 1 and len(data['machine']['load_start']) == 3
    assert data['options']['speeds'] == [4.0] and not data['options']['goals_checked']
    assert data['options']['simulation_time']   # every node on the simulated robot's clock
    (col,) = data['cases']
    assert col['key'] == 'one_segment@4x' and set(col['runs']) == {'none', 'dynamic', 'integral'}
    assert [(g['goal'], g['unit'], g['limit']) for g in col['goals']][:2] == [
        ('RMSE', 'mm', 1.0), ('held', 'mm', 0.3)]
    assert col['missed'] == [g for g in col['missed'] if ' > ' in g]
    cl = col['runs']['integral']
    line = next(ln for ln in out.splitlines() if ln.strip().startswith('closed loop ')
                and 'RMSE' in ln)
    assert f'RMSE {cl["rmse_mm"]:6.3f} mm' in line and f'{cl["held_mm"]:.3f} mm' in line
    assert len(cl['series']['t_s']) <= 200 and cl['safe'] and cl['vent'] == [0.0] * 3
    goals = next(ln for ln in out.splitlines() if ln.strip().startswith('goals: RMSE <= 1 mm'))
    assert goals.endswith(': met') or 'NOT met; MISSED: ' in goals, goals


@pytest.mark.slow
def test_loads_phase(tmp_path):
    """The loads phase of make demo (20 s circle, simulation time): the estimator reads the loads.

    On a 12 s circle the compensated run's push reading missed the 0.03 N
    tolerance on a loaded CI machine (0.128 N, -0.035 N sideways): the
    estimate lags the faster path; on the wall clock a loaded CI machine read
    the payload as -0.177 N in the compensated run.  The phase now runs on the
    simulated robot's clock in lockstep, and its results file says so.
    """
    env = dict(os.environ)
    env['PYTHONPATH'] = str(REPO) + os.pathsep + env.get('PYTHONPATH', '')
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    res = subprocess.run([sys.executable, '-m', 'bellow_ancf_ros.demos.forces', '--period', '20'],
                         env=env, cwd=tmp_path, capture_output=True, text=True, timeout=150,
                         stdin=subprocess.DEVNULL)
    out = res.stdout + res.stderr
    assert res.returncode == 0 and 'PASS' in out, out
    assert out.count('(within 0.03 N sideways, 0.1 N vertically)') == 4
    assert out.count('all finite and within the limits: yes; ends with the vent: yes') == 2
    assert json.loads((tmp_path / 'loads_results.json').read_text())['simulation_time']
    for name in ('integral feedback alone', 'integral feedback + force compensation'):
        assert f'  {name}:' in out
    data = json.loads((tmp_path / 'loads_results.json').read_text())   # what it printed
    assert data['passed'] and [r['compensate'] for r in data['runs']] == [False, True]
    assert all(p['within'] for r in data['runs'] for p in r['phases'].values())
