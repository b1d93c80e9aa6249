"""Every command the README and the pages of ``docs/`` document works.

Commands are collected from the code blocks of ``README.md`` and of every
``docs/*.md`` page.

* ``ros2 run bellow_ancf_ros bellow-ancf ...`` lines (the command line is
  written that way everywhere: after a colcon install the console script is
  in ``lib/bellow_ancf_ros``, not on ``PATH``): concrete ones (no placeholder
  left once the optional ``[...]`` parts are dropped) run as written, in bash,
  after ``source install/setup.sh`` of a colcon build of this checkout (the
  session's ``colcon_install`` fixture), from a directory outside any source
  tree (a line that names a file an earlier line of its code block names runs
  after it, in its directory; the others two at a time), with a
  ``ros2`` command that does what ``ros2 run`` and ``ros2 pkg prefix`` do
  (``test/support/ros2_shim.py``), so that shipped files are found as
  ``$(ros2 pkg prefix --share bellow_ancf_ros)/...``; they must exit 0.  Lines
  on the user's own recordings (:data:`USER_RECORDINGS`) are not run
  (``test/cli/test_cli_calibrate.py`` runs ``calibrate`` on simulated ones).
  For every line each documented option is in the subcommand's ``--help``.
* ``.venv/bin/python -m bellow_ancf_ros.nodes...`` lines start as processes,
  come up and stop cleanly on Ctrl-C.
* ``ros2 run bellow_ancf_ros <node>`` lines: run as written on the colcon
  install (as above; each in its own ROS domain), the node comes up and ends
  with status 0 on Ctrl-C; and in-process, the same node class starts with the
  same ``--ros-args`` (shipped files from the install) and the parameters
  given there are in effect; ``ros2 param set`` values are
  accepted; ``ros2 lifecycle set`` transitions succeed; the ``ros2 topic pub``
  target is reachable on the robot the block's inverse node (``ros2 run`` or
  ``ros2 launch`` line) runs.  ``ros2 launch`` lines:
  ``test/nodes/test_launch.py``, which reads the README's; a page's launch
  line must therefore also be in the README.
"""

import os
from ros_domains import fresh_domain  # noqa: E402
import re
from concurrent.futures import ThreadPoolExecutor
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
from ros_processes import interrupt_all  # noqa: E402

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
#: the user's own recordings a documented line reads (docs/calibration.md); such lines are
#: only checked for their options (test/cli/test_cli_calibrate.py runs calibrate on simulated
#: recordings, CSV and both bag storages)
USER_RECORDINGS = ('my_robot_bag', 'samples.csv')
#: the shipped files' directory as the documentation writes it (a colcon install's share dir)
SHARE = '$(ros2 pkg prefix --share bellow_ancf_ros)'
STARTED = {'inverse_kinetostatic_node': 'active: pressure commands enabled',
           'forward_kinetostatic_node': 'listening on',
           'trajectory_publisher': 'publishing',
           'simulated_robot_node': 'simulating robot',
           'excitation_publisher': 'excitation of robot',
           'mocap_relay': 'relaying mocap_pose',
           'regulator_driver': 'regulator driver for',
           'wrench_estimator_node': 'estimating the tip'}


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


#: the command line as a ROS user runs it after installation
ROS2_RUN_CLI = 'ros2 run bellow_ancf_ros bellow-ancf '


def cli_lines(with_blocks=False):
    """The documented command lines, as ``bellow-ancf ...`` with ``SHARE`` for the share dir."""
    out = [(block, line.replace(ROS2_RUN_CLI, 'bellow-ancf ', 1).replace(SHARE, 'SHARE'))
           for block, line in code_lines() if line.startswith(ROS2_RUN_CLI)]
    return out if with_blocks else [line for _, line in out]


def test_the_command_line_is_written_as_ros2_run():
    """Bare ``bellow-ancf`` is not on PATH after a colcon install; no code block uses it."""
    bare = [(block, line) for block, line in code_lines()
            if line.startswith('bellow-ancf') or ' data/' in line or ' config/' in line]
    assert not bare, bare


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


def _files_of(line):
    """The files a command line names (``.yaml``, ``.csv``, ``.png``, a bag directory)."""
    return {a for a in shlex.split(line) if a.endswith(('.yaml', '.yml', '.csv', '.png', '_bag'))}


def _concrete_chains():
    """The documented CLI lines that run, as written, in chains.

    A line joins the chain of the last earlier line of its code block that
    names one of its files (it may read what that line wrote); other lines
    start their own chain.  Chains are ``(name, [lines])``, in document order.
    """
    chains = []
    for block, line in cli_lines(with_blocks=True):
        args = shlex.split(strip_optional(line))
        if not is_concrete(args[1:]) or any(r in args for r in USER_RECORDINGS):
            continue
        written = strip_optional(line).replace('bellow-ancf ', ROS2_RUN_CLI, 1)
        written = written.replace('SHARE', SHARE)
        mine = [c for c in chains if c[0] == block
                and any(_files_of(x) & _files_of(written) for x in c[2])]
        if mine:
            mine[-1][2].append(written)
        else:
            chains.append((block, len(chains), [written]))
    return [(f'{doc.replace("/", "_")}_{b}_{k}', lines) for (doc, b), k, lines in chains]


def _run_chain(install, name, lines):
    """Run the lines of one chain in order, in a fresh directory outside the checkout."""
    cwd = install.outside / name
    cwd.mkdir()
    done = []
    for line in lines:
        res = install.shell(line, cwd)
        assert res.returncode == 0, (name, line, res.stderr[-2000:])
        assert res.stdout.strip(), (name, line, res.stderr[-2000:])
        done.append((line, res))
    return done


def test_documented_cli_lines_run_on_a_colcon_install(colcon_install):
    """Each concrete ``ros2 run bellow_ancf_ros bellow-ancf`` line runs as written."""
    chains = _concrete_chains()
    ran = {shlex.split(line)[4] for _, lines in chains for line in lines}
    assert {'warm-up', 'identify', 'calibrate', 'convergence', 'workspace', 'compare-pcc',
            'track'} <= ran, ran
    readme = [c for c in chains if any('one_segment_bag' in x for x in c[1])]
    assert len(readme) == 1 and len(readme[0][1]) == 3, chains   # identify x2 -> calibrate
    # warm-up first, alone: it compiles the install's kernels, once
    first = [c for c in chains if any(' warm-up' in x for x in c[1])][0]
    chains.remove(first)
    results = _run_chain(colcon_install, *first)
    warm = results[0][1]
    # the installed package ran (its kernel cache is in the install), not the checkout's
    assert str(colcon_install.prefix) in warm.stdout, warm.stdout
    with ThreadPoolExecutor(2) as pool:       # two cores
        for done in pool.map(lambda chain: _run_chain(colcon_install, *chain), chains):
            results += done
    outputs = {line: res.stdout for line, res in results}
    # README's "Your own robot": identify writes my_robot.yaml, calibrate reads it and the bag
    assert 'position RMSE' in outputs[readme[0][1][-1]]
    written = colcon_install.outside / readme[0][0] / 'my_robot_calibrated.yaml'
    from bellow_ancf_ros.core import load_robot
    calibrated = load_robot(str(written))
    assert calibrated.name == 'my_robot_calibrated' and calibrated.mocap_frame is not None
    assert '# unpressurised actuator length [m]' in written.read_text()   # comments kept


# ------------------------------------------------------------------ nodes
def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_venv_node_commands_start_and_stop(tmp_path):
    """Every document's venv node lines start and stop; each block in its own ROS domain.

    A block is what a user runs together: two blocks' inverse nodes on one
    domain would share ``/pressure_command``, which the owner check refuses.
    """
    base = dict(os.environ)
    base['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    base['PYTHONPATH'] = str(REPO) + os.pathsep + base.get('PYTHONPATH', '')
    base['PYTHONUNBUFFERED'] = '1'
    procs, domains = [], {}
    for block, line in code_lines():
        if not line.startswith('.venv/bin/python -m bellow_ancf_ros.nodes.'):
            continue
        if block not in domains:   # (a domain drawn once per block)
            domains[block] = {**base, 'ROS_DOMAIN_ID': str(fresh_domain())}
        env = domains[block]
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
        interrupt_all([proc for *_, proc in procs], 20.0)
    codes = [proc.returncode for *_, proc in procs]
    assert codes == [0] * len(procs), [log.read_text() for _, _, log, _ in procs]


def _ros2_run_lines(share=None):
    """(block, executable, ros-args) of every ``ros2 run bellow_ancf_ros`` node line.

    ``$(ros2 pkg prefix --share bellow_ancf_ros)`` becomes ``share``.
    """
    out = []
    for block, line in code_lines():
        if line.startswith('ros2 run bellow_ancf_ros ') and not line.startswith(ROS2_RUN_CLI):
            if share is not None:
                line = line.replace(SHARE, str(share))
            args = shlex.split(line)
            out.append((block, args[3], args[4:]))
    return out


def _start(cls, ros_args):
    ctx = Context()
    rclpy.init(args=['node', *ros_args], context=ctx, domain_id=fresh_domain())
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


def test_ros2_run_lines_start_with_their_parameters(colcon_install):
    """The node starts with the line's arguments (shipped files: the install's share dir)."""
    lines = _ros2_run_lines(colcon_install.share)
    assert any(colcon_install.share.as_posix() in ' '.join(a) for _, _, a in lines)
    for _, exe, ros_args in lines:
        node, ctx = _start(NODES[exe], ros_args)
        try:
            for name, value in _given_parameters(ros_args, exe).items():
                assert node.get_parameter(name).value == value, (exe, name)
            if isinstance(node, InverseKinetostaticNode):
                assert node.is_active
        finally:
            _stop(node, ctx)


def _documented_base_frame_nodes():
    """``(nodes with, nodes without)`` the ``base_frame`` parameter, as docs/ros.md says."""
    text = (REPO / 'docs' / 'ros.md').read_text()
    bullet = re.search(r'^\* `base_frame` .*?;$', text, re.M | re.S).group(0)
    with_part, _, without_part = bullet.partition('(not')
    return (set(re.findall(r'`(\w+_\w+)`', with_part)) - {'base_frame'},
            set(re.findall(r'`(\w+_\w+)`', without_part)))


def test_documented_common_parameters_are_declared():
    """Every node declares ``robot_config``; ``base_frame`` exactly those docs/ros.md names."""
    with_frame, without_frame = _documented_base_frame_nodes()
    assert with_frame | without_frame == set(NODES) and not with_frame & without_frame
    for exe, cls in NODES.items():
        node, ctx = _start(cls, [])
        try:
            assert node.has_parameter('robot_config'), exe
            assert node.has_parameter('base_frame') == (exe in with_frame), exe
            if exe in with_frame:
                assert node.get_parameter('base_frame').value == 'base', exe
        finally:
            _stop(node, ctx)


def test_documented_ros2_run_node_lines_start_on_a_colcon_install(colcon_install):
    """Each ``ros2 run bellow_ancf_ros <node> ...`` line, as written, starts the installed node.

    In bash after ``source install/setup.sh``, from a directory outside the
    source tree, each line in its own ``ROS_DOMAIN_ID`` (as if run alone); the
    node must come up (its first log line) and end with status 0 on Ctrl-C.
    """
    lines = [line for _, line in code_lines()
             if line.startswith('ros2 run bellow_ancf_ros ') and not line.startswith(ROS2_RUN_CLI)]
    assert len(lines) >= 8 and any(SHARE in line for line in lines)
    domains = [fresh_domain() for _ in lines]
    procs = []
    for k, (line, domain) in enumerate(zip(lines, domains)):
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1',
                   ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                   PATH=str(colcon_install.bin) + os.pathsep + os.environ.get('PATH', ''))
        env.pop('AMENT_PREFIX_PATH', None)
        env.pop('PYTHONPATH', None)
        log = colcon_install.root / f'node_line_{k}.log'
        script = (f'. {colcon_install.install / "setup.sh"} && cd {colcon_install.outside} '
                  f'&& exec {line}')
        with open(log, 'w') as out:
            procs.append((line, log, subprocess.Popen(
                ['bash', '-c', script], env=env, stdout=out, stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL, start_new_session=True, preexec_fn=_default_sigint)))
    try:
        deadline = time.monotonic() + 120.0
        for line, log, proc in procs:
            marker = STARTED[shlex.split(line)[3]]
            while marker not in log.read_text():
                assert proc.poll() is None, (line, log.read_text())
                assert time.monotonic() < deadline, (line, log.read_text())
                time.sleep(0.1)
            # the installed node ran, not the checkout's module
            assert str(REPO) not in log.read_text(), log.read_text()
    finally:
        interrupt_all([proc for *_, proc in procs], 20.0)
    codes = [proc.returncode for *_, proc in procs]
    failed = [(line, log.read_text()[-1500:])
              for (line, log, _), code in zip(procs, codes) if code]
    assert codes == [0] * len(procs), failed


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
