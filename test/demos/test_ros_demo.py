"""The main job (`make demo`, demos.closed_loop), shortened: it runs, reports, plots."""

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
    assert plot.is_file() and plot.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_plot_has_plain_z_ticks_and_draws_only_the_evaluated_path():
    """Issue 10 item 11: no offset label on the 3-D axes, no line back to the start."""
    import matplotlib.pyplot as plt
    import numpy as np

    from bellow_ancf_ros.demos import closed_loop as ros_demo, closed_loop_plot as ros_demo_plot

    t = np.linspace(0.0, 20.0, 400, endpoint=False)
    circle = np.column_stack([0.02 * np.cos(t / 20 * 2 * np.pi),
                              0.02 * np.sin(t / 20 * 2 * np.pi), np.full_like(t, 0.20912)])
    res = {'t': t, 'target': circle, 'measured': circle + 1e-3, 'pos_err': np.full_like(t, 1e-3),
           'ang_err': np.full_like(t, 0.01)}
    cols = ros_demo.columns()
    fig = ros_demo_plot.figure({c.key: {'none': res, 'integral': res} for c in cols}, cols)
    fig.canvas.draw()
    axes3d = [a for a in fig.axes if a.name == '3d']
    assert len(axes3d) == len(cols) == 8   # 1x, 4x, 10x per robot; 50 g at 1x and 10x
    for ax in axes3d:
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            assert axis.get_major_formatter().get_offset() == ''
        labels = [tl.get_text() for tl in ax.zaxis.get_ticklabels() if tl.get_text()]
        assert labels and all(len(lab) <= 6 for lab in labels), labels   # e.g. '209', '211'
        for line in ax.get_lines():
            xs, ys, zs = line.get_data_3d()
            assert len(xs) == len(t)          # exactly the evaluated samples, nothing appended
            shift = 0.0 if line.get_label() == 'target' else 1.0   # measured = target + 1 mm
            np.testing.assert_allclose(xs[-1], circle[-1, 0] * 1e3 + shift)
    plt.close(fig)


@pytest.mark.slow
def test_loads_phase(tmp_path):
    """The loads phase of make demo (its 20 s circle): the estimator reads the loads.

    On a 12 s circle the compensated run's push reading missed the 0.03 N
    tolerance on a loaded CI machine (0.128 N, -0.035 N sideways): the
    estimate lags the faster path.
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
    for name in ('integral feedback alone', 'integral feedback + force compensation'):
        assert f'  {name}:' in out
