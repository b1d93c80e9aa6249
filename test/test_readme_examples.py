"""Every command the README and the pages of ``docs/`` document works.

Commands are collected from the code blocks of ``README.md`` and of every
``docs/*.md`` page.

* ``bellow-ancf ...`` lines: concrete ones (no placeholder left once the
  optional ``[...]`` parts are dropped) run and exit 0, except the long
  studies listed in ``SLOW`` (tested with smaller inputs in
  ``test/cli/test_cli_tools.py``); for every line each documented option is in
  the subcommand's ``--help``.
* ``.venv/bin/python -m bellow_ancf_ros.nodes...`` lines start as processes,
  come up and stop cleanly on Ctrl-C.
* ``ros2 run`` lines (a ROS install is needed for the ``ros2`` command):
  the same node class starts with the same ``--ros-args`` and the
  parameters given there are in effect; ``ros2 param set`` values are
  accepted; ``ros2 lifecycle set`` transitions succeed; the ``ros2 topic pub``
  target is reachable on the robot the block's inverse node (``ros2 run`` or
  ``ros2 launch`` line) runs.  ``ros2 launch`` lines:
  ``test/nodes/test_launch.py``, which reads the README's; a page's launch
  line must therefore also be in the README.
"""

import os
import random
import re
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

rclpy = pytest.importorskip('rclpy')

from rclpy.context import Context  # noqa: E402
from rclpy.lifecycle import TransitionCallbackReturn  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from bellow_ancf_ros.core import RobotModel, load_robot, solve_inverse  # noqa: E402
from bellow_ancf_ros.core import geometry  # noqa: E402
from bellow_ancf_ros.nodes.forward_kinetostatic_node import ForwardKinetostaticNode  # noqa: E402
from bellow_ancf_ros.nodes.inverse_kinetostatic_node import InverseKinetostaticNode  # noqa: E402
from bellow_ancf_ros.nodes.excitation_publisher import ExcitationPublisher  # noqa: E402
from bellow_ancf_ros.nodes.simulated_robot_node import SimulatedRobotNode  # noqa: E402
from bellow_ancf_ros.nodes.trajectory_publisher import TrajectoryPublisher  # noqa: E402
from bellow_ancf_ros.nodes.mocap_relay import MocapRelay  # noqa: E402
from bellow_ancf_ros.nodes.regulator_driver import RegulatorDriver  # noqa: E402
from bellow_ancf_ros.nodes.wrench_estimator_node import WrenchEstimatorNode  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
README = REPO / 'README.md'
#: the documents whose code blocks hold commands: the README, then every page of docs/
DOCUMENTS = [README, *sorted((REPO / 'docs').glob('*.md'))]
NODES = {'mocap_relay': MocapRelay, 'regulator_driver': RegulatorDriver,
         'inverse_kinetostatic_node': InverseKinetostaticNode,
         'forward_kinetostatic_node': ForwardKinetostaticNode,
         'trajectory_publisher': TrajectoryPublisher,
         'excitation_publisher': ExcitationPublisher,
         'simulated_robot_node': SimulatedRobotNode,
         'wrench_estimator_node': WrenchEstimatorNode}
#: studies that take 25-45 s on the 2-core machine; only their options are checked here
SLOW = ('workspace', 'compare-pcc')
#: commands that read the user's own recording; test/test_cli_calibrate.py runs them on
#: simulated recordings (CSV and both bag storages); only their options are checked here
NEEDS_RECORDING = ('calibrate',)
STARTED = {'inverse_kinetostatic_node': 'active: pressure commands enabled',
           'forward_kinetostatic_node': 'listening on',
           'trajectory_publisher': 'publishing',
           'simulated_robot_node': 'simulating robot'}


def code_lines(documents=None):
    """Commands in the documents' code blocks (continuation lines joined), in order.

    Each comes with its block, ``(document name, block number)``.
    """
    lines = []
    for doc in DOCUMENTS if documents is None else documents:
        text = doc.read_text()
        blocks = re.findall(r'```[a-z]*\n(.*?)```', text, re.S)
        for b, block in enumerate(blocks):
            for line in block.replace('\\\n', ' ').splitlines():
                line = line.split('  #')[0].strip()
                if line:
                    lines.append(((doc.relative_to(REPO).as_posix(), b),
                                  ' '.join(line.split())))
    return lines


def strip_optional(line):
    while re.search(r'\[[^\[\]]*\]', line):
        line = re.sub(r'\s*\[[^\[\]]*\]', '', line)
    return line


def is_concrete(args):
    return not any(re.fullmatch(r'[A-Z][A-Z0-9]*', a) or a == '...' for a in args)


#: the command line as a ROS user runs it after installation: the same command
ROS2_RUN_CLI = 'ros2 run bellow_ancf_ros bellow-ancf '


def cli_lines():
    return [line.replace(ROS2_RUN_CLI, 'bellow-ancf ', 1) for _, line in code_lines()
            if line.startswith(('bellow-ancf ', ROS2_RUN_CLI))]


def test_readme_has_the_examples_this_file_checks():
    lines = [line for _, line in code_lines()]
    assert len(cli_lines()) >= 10
    venv_nodes = [line for line in lines
                  if line.startswith('.venv/bin/python -m bellow_ancf_ros.nodes.')]
    assert len(venv_nodes) >= 3
    assert sum(line.startswith('ros2 run bellow_ancf_ros ') for line in lines) >= 4
    assert any(line.startswith('ros2 topic pub') for line in lines)
    assert any(line.startswith('ros2 param set') for line in lines)
    assert any(line.startswith('ros2 lifecycle set') for line in lines)
    assert {doc for (doc, _), _ in code_lines()} >= {'README.md', 'docs/ros.md', 'docs/cli.md'}


def test_every_documented_launch_line_is_one_test_launch_runs():
    """``test/nodes/test_launch.py`` runs the README's ``ros2 launch`` lines."""
    readme = {line for _, line in code_lines([README])
              if line.startswith('ros2 launch bellow_ancf_ros ')}
    assert readme
    for (doc, _), line in code_lines():
        if line.startswith('ros2 launch'):
            assert line in readme, (doc, line)


def test_every_documented_cli_option_exists(capsys):
    from bellow_ancf_ros.cli import build_parser
    helps = {}
    for line in cli_lines():
        tokens = shlex.split(line)[1:]
        sub = tuple(t for t in tokens[:2] if not t.startswith('-'))
        if sub not in helps:
            with pytest.raises(SystemExit) as done:
                build_parser().parse_args([*sub, '--help'])
            assert done.value.code == 0, sub
            helps[sub] = capsys.readouterr().out
        for opt in re.findall(r'(--[a-z][a-z0-9-]*)', line):
            assert opt in helps[sub], (line, opt)


def test_concrete_cli_examples_run(tmp_path):
    ran = []
    procs = []
    for line in cli_lines():
        args = shlex.split(strip_optional(line))[1:]
        if not is_concrete(args) or args[0] in SLOW + NEEDS_RECORDING:
            continue
        # relative data paths are the repository's; outputs go to a scratch directory
        args = [str(REPO / a) if a.startswith('data/') else a for a in args]
        procs.append((line, subprocess.Popen(
            [sys.executable, '-m', 'bellow_ancf_ros.cli', *args], cwd=tmp_path,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            stdin=subprocess.DEVNULL)))
        ran.append(args[0])
        if len(procs) >= 2:      # two cores
            _finish(procs.pop(0))
    for p in procs:
        _finish(p)
    assert {'identify', 'convergence', 'track'} <= set(ran), ran


def _finish(item):
    line, proc = item
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, (line, err[-2000:])
    assert out.strip(), line


# ------------------------------------------------------------------ nodes
def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_venv_node_commands_start_and_stop(tmp_path):
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(random.randint(0, 101))
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONPATH'] = str(REPO) + os.pathsep + env.get('PYTHONPATH', '')
    env['PYTHONUNBUFFERED'] = '1'
    procs = []
    for _, line in code_lines():
        if not line.startswith('.venv/bin/python -m bellow_ancf_ros.nodes.'):
            continue
        args = shlex.split(line)
        module = args[2].rsplit('.', 1)[1]
        robot = _given_parameters(args, module).get('robot_config', 'one_segment')
        log = tmp_path / f'{len(procs)}_{module}.log'
        with open(log, 'w') as out:
            procs.append((module, robot, log, subprocess.Popen(
                [sys.executable, *args[1:]], cwd=REPO, env=env, stdout=out,
                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True,
                preexec_fn=_default_sigint)))
    try:
        deadline = time.monotonic() + 60.0
        for module, robot, log, proc in procs:
            while STARTED[module] not in log.read_text():
                assert proc.poll() is None, log.read_text()
                if time.monotonic() >= deadline:
                    os.kill(proc.pid, signal.SIGUSR1)  # its stacks into its log (faulthandler)
                    time.sleep(1.0)
                    raise AssertionError(log.read_text())
                time.sleep(0.05)
            assert f"'{robot}'" in log.read_text(), (robot, log.read_text())
    finally:
        for *_, proc in procs:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGINT)
        codes = []
        for _, _, log, proc in procs:
            try:
                codes.append(proc.wait(20.0))
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                codes.append(proc.wait(5.0))
    assert codes == [0] * len(procs), [log.read_text() for _, _, log, _ in procs]


def _ros2_run_lines():
    """(block, executable, ros-args) of every ``ros2 run bellow_ancf_ros`` line."""
    out = []
    for block, line in code_lines():
        if line.startswith('ros2 run bellow_ancf_ros ') and not line.startswith(ROS2_RUN_CLI):
            args = shlex.split(line)
            out.append((block, args[3], args[4:]))
    return out


def _start(cls, ros_args):
    ctx = Context()
    rclpy.init(args=['node', *ros_args], context=ctx, domain_id=random.randint(0, 101))
    try:
        return cls(context=ctx), ctx
    except BaseException:
        rclpy.try_shutdown(context=ctx)
        raise


def _stop(node, ctx):
    if isinstance(node, InverseKinetostaticNode):
        node.vent_and_shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)


def _given_parameters(ros_args, node_name):
    """Parameters a ``--ros-args`` list sets for ``node_name`` with ``-p``."""
    out = {}
    for flag, value in zip(ros_args, ros_args[1:]):
        if flag != '-p':
            continue
        name, raw = value.split(':=', 1)
        if ':' in name:
            node, name = name.split(':', 1)
            if node != node_name:
                continue
        out[name] = yaml.safe_load(raw)
    return out


def test_ros2_run_lines_start_with_their_parameters():
    lines = _ros2_run_lines()
    for _, exe, ros_args in lines:
        ros_args = [str(REPO / a) if a.startswith('config/') else a for a in ros_args]
        node, ctx = _start(NODES[exe], ros_args)
        try:
            for name, value in _given_parameters(ros_args, exe).items():
                assert node.get_parameter(name).value == value, (exe, name)
            if isinstance(node, InverseKinetostaticNode):
                assert node.is_active
        finally:
            _stop(node, ctx)


def _block_robots():
    """The robot of each block's inverse node (its ``ros2 run`` or ``ros2 launch`` line)."""
    out = {}
    for block, line in code_lines():
        args = shlex.split(line)
        if line.startswith('ros2 run bellow_ancf_ros inverse_kinetostatic_node'):
            out[block] = _given_parameters(args[4:], args[3]).get('robot_config', 'one_segment')
        elif line.startswith('ros2 launch bellow_ancf_ros ') and block not in out:
            given = dict(a.split(':=', 1) for a in args[4:] if ':=' in a)
            out[block] = given.get('robot_config', 'one_segment')
    return out


def test_ros2_param_set_and_topic_pub_examples():
    block_robot = _block_robots()
    checked = 0
    for block, line in code_lines():
        args = shlex.split(line)
        if line.startswith('ros2 param set /inverse_kinetostatic_node'):
            name, raw = args[4], args[5]
            node, ctx = _start(InverseKinetostaticNode, ['--ros-args', '-p',
                                                         f'robot_config:={block_robot[block]}'])
            try:
                res = node.set_parameters([Parameter(name, value=yaml.safe_load(raw))])
                assert res[0].successful, (line, res[0].reason)
            finally:
                _stop(node, ctx)
            checked += 1
        elif line.startswith('ros2 topic pub') and '/target_pose' in args:
            msg = yaml.safe_load(args[-1])
            assert msg['header']['frame_id'] == 'base'
            p = msg['pose']['position']
            q = msg['pose']['orientation']
            quat = [q.get(k, 0.0) for k in ('x', 'y', 'z', 'w')]
            model = RobotModel(load_robot(block_robot[block]))
            z = geometry.z_axis_from_quaternion(quat) if model.cfg.n_segments >= 2 else None
            inv = solve_inverse(model, [p.get('x', 0.0), p.get('y', 0.0), p.get('z', 0.0)], z)
            assert inv.reachable and inv.success, (line, inv.message)
            checked += 1
    assert checked >= 2


def test_ros2_lifecycle_set_examples():
    """Each block's ``ros2 lifecycle set`` transitions, in order, on its inverse node."""
    block_robot = _block_robots()
    transitions = {}
    for block, line in code_lines():
        if line.startswith('ros2 lifecycle set'):
            args = shlex.split(line)
            assert args[3] == '/inverse_kinetostatic_node', line
            transitions.setdefault(block, []).append(args[4])
    assert transitions
    for block, names in transitions.items():
        node, ctx = _start(InverseKinetostaticNode, ['--ros-args', '-p',
                                                     f'robot_config:={block_robot[block]}'])
        try:
            assert node.is_active
            for name in names:
                done = getattr(node, f'trigger_{name}')()
                assert done == TransitionCallbackReturn.SUCCESS, (block, name, done)
                if name in ('activate', 'deactivate'):
                    assert node.is_active == (name == 'activate'), (block, name)
        finally:
            _stop(node, ctx)
