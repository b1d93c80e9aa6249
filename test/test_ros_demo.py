"""The main job (`make demo`, bellow_ancf_ros.ros_demo), shortened: it runs, reports, plots."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip('rclpy')

REPO = Path(__file__).resolve().parents[1]


def test_main_demo_short_run_one_segment(tmp_path):
    plot = tmp_path / 'demo.png'
    env = dict(os.environ)
    env['PYTHONPATH'] = str(REPO) + os.pathsep + env.get('PYTHONPATH', '')
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    res = subprocess.run([sys.executable, '-m', 'bellow_ancf_ros.ros_demo',
                          '--cases', 'one_segment',
                          '--period-scale', '0.25', '--lead-in', '1', '--hold', '1.5',
                          '--no-goals', '--plot', str(plot)],
                         env=env, cwd=tmp_path, capture_output=True, text=True, timeout=150,
                         stdin=subprocess.DEVNULL)
    out = res.stdout + res.stderr
    assert res.returncode == 0, out
    assert 'PASS' in out
    for mode in ('feedforward', 'closed loop'):
        line = next(ln for ln in out.splitlines() if ln.strip().startswith(mode + ' ')
                    and 'RMSE' in ln)
        assert 'held target' in line, line
    assert out.count('all finite and within the limits: yes') == 2
    assert out.count('last (vent): [0.0, 0.0, 0.0]') == 2
    assert 'closed-loop / feedforward position RMSE' in out
    assert plot.is_file() and plot.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
