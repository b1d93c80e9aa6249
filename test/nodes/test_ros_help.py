"""``--help`` of every node executable: it answers before ROS starts and publishes nothing.

Every console script of ``setup.py`` except the CLI is started with ``-h``
or ``--help`` (every other one; as ``ros2 run bellow_ancf_ros <exe> --help``
would start it), on a random ROS_DOMAIN_ID with LOCALHOST discovery, while
a real rclpy listener in this process subscribes every topic the nodes
publish.  The
listener is shown to hear a node that does start (the trajectory publisher
without ``--help``), so that "received nothing" means something.  The help
text comes from the node's own parameter table: it prints each parameter's
default and, where the descriptor declares one, its range (read back from
the text and compared with the table), and an in-process node of each class
declares exactly the parameters, defaults and descriptors its help prints.
"""

import ast
import importlib
import os
import random
import re
import signal
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip('rclpy')

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

from bellow_ancf_ros.nodes.ros_util import command_qos  # noqa: E402
from ros_processes import node_process_env, REPO, SpunClient  # noqa: E402

HELP_TIMEOUT_S = 60.0   # eight interpreters at once on two shared cores (9-13 s measured)
#: every topic a node of the package publishes, with its type
TOPICS = {
    'pressure_command': Float64MultiArray, 'measured_pressure': Float64MultiArray,
    'target_pose': PoseStamped, 'commanded_pose': PoseStamped, 'measured_pose': PoseStamped,
    'true_pose': PoseStamped, 'predicted_pose': PoseStamped, 'predicted_shape': MarkerArray,
    'estimated_wrench': WrenchStamped, 'estimated_wrench_marker': Marker,
    '/diagnostics': DiagnosticArray,
}


def node_entry_points():
    """(executable, module) of every node console script in setup.py (not the CLI)."""
    tree = ast.parse((REPO / 'setup.py').read_text())
    scripts = next(ast.literal_eval(kw.value)['console_scripts'] for node in ast.walk(tree)
                   if isinstance(node, ast.Call) for kw in node.keywords
                   if kw.arg == 'entry_points')
    out = []
    for line in scripts:
        exe, target = (part.strip() for part in line.split('='))
        module, func = target.split(':')
        assert func == 'main', line
        if module.startswith('bellow_ancf_ros.nodes.'):
            out.append((exe, module))
    return out


NODES = node_entry_points()


def node_class(module):
    mod = importlib.import_module(module)
    main = mod.main
    classes = [v for v in vars(mod).values()
               if isinstance(v, type) and v.__module__ == module and hasattr(v, 'PARAMETERS')]
    assert len(classes) == 1, (module, classes)
    assert main is not None
    return classes[0]


@pytest.fixture(scope='module')
def env():
    return node_process_env()


class Listener(SpunClient):
    """A real rclpy subscriber of every topic in :data:`TOPICS`, spun in a thread."""

    def __init__(self, domain):
        self.got = []
        super().__init__(domain, 'help_test_listener')

    def setup(self, node):
        for topic, mtype in TOPICS.items():
            node.create_subscription(mtype, topic, lambda m, t=topic: self._add(t),
                                     command_qos())

    def _add(self, topic):
        with self.lock:
            self.got.append(topic)

    def received(self):
        with self.lock:
            return list(self.got)

    def other_nodes(self):
        return [n for n in self.node.get_node_names() if n != 'help_test_listener']


def _help_default(text):
    """The default as the help prints it (Python literals, true/false) -> a Python value."""
    return ast.literal_eval(re.sub(r'\btrue\b', 'True', re.sub(r'\bfalse\b', 'False', text)))


def _table_default(value):
    return value.tolist() if hasattr(value, 'tolist') else (
        list(value) if isinstance(value, (list, tuple)) else value)


def check_parameter_lines(out, cls):
    """Each parameter's help line shows its default and the descriptor's range, if any.

    The line is ``  name: default; allowed[; read-only (start-up only)]``
    (ros_util.node_help); the default and the range are read back from the
    text and compared with the node's table.
    """
    lines = {line.split(':')[0].strip(): line for line in out.splitlines()
             if re.match(r'  [a-z_0-9]+: ', line)}
    for p in cls.PARAMETERS:
        assert p.name in lines, (p.name, out)
        line = lines[p.name]
        default_text, allowed = line[len(f'  {p.name}: '):].split('; ', 1)
        default, want = _help_default(default_text), _table_default(p.default)
        assert default == want and type(default) is type(want), (line, p.default)
        if isinstance(want, list):
            assert [type(v) for v in default] == [type(v) for v in want], (line, p.default)
        d = p.descriptor
        ranges = re.findall(r'from (\S+?) to ([^\s,;]+)', allowed)
        if d.floating_point_range:
            r = d.floating_point_range[0]
            assert len(ranges) == 1, line
            assert [float(v) for v in ranges[0]] == pytest.approx(
                [r.from_value, r.to_value], rel=1e-5), line   # printed with 6 digits (:g)
        elif d.integer_range:
            r = d.integer_range[0]
            assert len(ranges) == 1, line
            assert [int(v) for v in ranges[0]] == [r.from_value, r.to_value], line
        elif not d.additional_constraints:
            assert not ranges, line   # no range printed that the descriptor does not declare
        assert line.endswith('; read-only (start-up only)') == d.read_only, line


def _start(module, args, env, log_path):
    log = open(log_path, 'w')
    proc = subprocess.Popen([sys.executable, '-m', module, *args], env=env, stdout=log,
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    return proc, log


def test_every_node_executable_is_listed_and_goes_through_main_for():
    """main_for gives every executable --help, the one-line start-up errors, the exit deadline."""
    assert {exe for exe, _ in NODES} == {
        'inverse_kinetostatic_node', 'forward_kinetostatic_node', 'trajectory_publisher',
        'excitation_publisher', 'simulated_robot_node', 'mocap_relay', 'regulator_driver',
        'wrench_estimator_node'}
    for _, module in NODES:
        main = importlib.import_module(module).main
        assert main.__qualname__ == 'main_for.<locals>.main', module


def test_help_answers_before_ros_and_publishes_nothing(env, tmp_path):
    listener = Listener(int(env['ROS_DOMAIN_ID']))
    procs = {}
    try:
        # strangers already there (a participant killed elsewhere stays in discovery until
        # its lease ends) are not the help's
        time.sleep(1.0)
        before = set(listener.other_nodes())
        t0 = time.monotonic()
        flags = {exe: ('-h', '--help')[i % 2] for i, (exe, _) in enumerate(NODES)}
        assert set(flags.values()) == {'-h', '--help'}
        for exe, module in NODES:
            procs[exe] = _start(module, [flags[exe]], env, tmp_path / f'{exe}.log')
        nodes_seen, ended = set(), {}
        while len(ended) < len(procs) and time.monotonic() - t0 < HELP_TIMEOUT_S:
            nodes_seen.update(listener.other_nodes())
            for exe, (proc, _) in procs.items():
                if exe not in ended and proc.poll() is not None:
                    ended[exe] = time.monotonic() - t0
            time.sleep(0.02)
        time.sleep(1.0)   # a late message would still arrive
        assert not listener.received(), listener.received()
        assert not nodes_seen - before, (nodes_seen, before)
        for exe, module in NODES:
            proc, log = procs[exe]
            log.close()
            out = (tmp_path / f'{exe}.log').read_text()
            assert exe in ended, f'{exe} {flags[exe]} did not end in {HELP_TIMEOUT_S} s:\n{out}'
            assert proc.returncode == 0, out
            assert 'Traceback' not in out, out
            assert f'ros2 run bellow_ancf_ros {exe}' in out, out
            cls = node_class(module)
            first = sys.modules[module].__doc__.strip().splitlines()[0].replace('``', '')
            assert first[:40] in ' '.join(out.split()), (first, out)
            check_parameter_lines(out, cls)   # every parameter: default, range
            for t in cls.TOPICS:
                assert t.name in out, (t.name, out)
        print('help answered in ' + ', '.join(f'{k} {v:.1f} s' for k, v in ended.items()))

        # the listener hears a node that does start: its silence above is a real one (no
        # lead-in: it would wait for a controller first)
        proc, log = _start('bellow_ancf_ros.nodes.trajectory_publisher',
                           ['--ros-args', '-p', 'ramp_in_s:=0.0'], env, tmp_path / 'control.log')
        procs['control'] = (proc, log)
        deadline = time.monotonic() + HELP_TIMEOUT_S
        while 'target_pose' not in listener.received() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert 'target_pose' in listener.received(), (tmp_path / 'control.log').read_text()
    finally:
        for proc, log in procs.values():
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(5.0)
            log.close()
        listener.close()


@pytest.mark.parametrize('exe,module', NODES)
def test_help_is_what_the_node_declares(ros_context, exe, module):
    """One source of truth: the node declares exactly its table, defaults and descriptors."""
    cls = node_class(module)
    overrides = {'inverse_kinetostatic_node': [Parameter('autostart', value=False)]}
    kwargs = {'context': ros_context, 'namespace': f'/help{random.randint(0, 99999)}',
              'parameter_overrides': overrides.get(exe, [])}
    node = cls(**kwargs)
    try:
        assert cls.NODE_NAME == exe == node.get_name()
        declared = set(node._parameters) - {'use_sim_time', 'start_type_description_service'}
        assert declared == {p.name for p in cls.PARAMETERS}
        given = {o.name for o in kwargs['parameter_overrides']}
        for p in cls.PARAMETERS:
            value = node.get_parameter(p.name).value
            if p.name in given:
                continue
            assert (list(value) if isinstance(value, (list, tuple)) or hasattr(value, 'tolist')
                    else value) == p.default, p.name
            d = node.describe_parameter(p.name)
            assert d.description == p.descriptor.description, p.name
            assert d.read_only == p.descriptor.read_only, p.name
            assert list(d.floating_point_range) == list(p.descriptor.floating_point_range)
            assert list(d.integer_range) == list(p.descriptor.integer_range)
    finally:
        if hasattr(node, 'vent_and_wait'):   # the excitation publisher must not run on
            node.finished = True
        node.destroy_node()
