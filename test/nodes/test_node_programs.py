"""A node process stopped while it still loads: status 0, one line, no traceback."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bellow_ancf_ros import nodes

REPO = Path(__file__).resolve().parents[2]


def test_the_node_programs_are_setups_node_console_scripts():
    scripts = re.findall(r"'(\w+) = bellow_ancf_ros\.nodes\.(\w+):main'",
                         (REPO / 'setup.py').read_text())
    assert sorted(nodes.NODE_PROGRAMS) == sorted(name for name, _ in scripts)
    assert all(name == module for name, module in scripts)


@pytest.mark.parametrize('orig_argv, argv, program', [
    (['python', '-m', 'bellow_ancf_ros.nodes.mocap_relay', '--ros-args'], ['-m', '--ros-args'],
     'mocap_relay'),
    (['python', '-m', 'bellow_ancf_ros.nodes.contract'], ['-m'], ''),
    (['python', '-m', 'bellow_ancf_ros.cli', 'warm-up'], ['-m', 'warm-up'], ''),
    (['python', '/ws/install/lib/bellow_ancf_ros/regulator_driver', '--ros-args'],
     ['/ws/install/lib/bellow_ancf_ros/regulator_driver', '--ros-args'], 'regulator_driver'),
    (['python', '/ws/.venv/bin/pytest', '-k', 'x'], ['/ws/.venv/bin/pytest', '-k', 'x'], ''),
])
def test_a_node_program_is_told_from_its_command_line(orig_argv, argv, program):
    assert nodes._node_program(orig_argv, argv) == program


@pytest.mark.skipif(not Path('/proc/self/maps').exists(), reason='reads /proc/<pid>/maps')
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_a_signal_while_the_node_loads_ends_it_with_one_line(sig):
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get('PYTHONPATH', ''))
    proc = subprocess.Popen(
        [sys.executable, '-m', 'bellow_ancf_ros.nodes.inverse_kinetostatic_node', '--ros-args',
         '-p', 'robot_config:=one_segment'], cwd=REPO, env=env, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    # loading: numpy mapped, which the node's module imports first (after this package put its
    # handlers in place), long before rclpy is initialised (a fixed 1 s came after it on a fast
    # machine: the node then stopped without a word)
    maps = Path(f'/proc/{proc.pid}/maps')
    deadline = time.monotonic() + 30.0
    while '_multiarray_umath' not in maps.read_text() and time.monotonic() < deadline:
        time.sleep(0.005)
    proc.send_signal(sig)
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, out
    assert out == (f'[inverse_kinetostatic_node] stopped by {sig.name} while loading, '
                   'before anything was commanded\n')
