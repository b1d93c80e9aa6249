"""The launch file's parameters, as launch_ros composes them, reach every node.

``launch`` and ``launch_ros`` are not installable from PyPI, so this test
runs ``launch/bellow_ancf.launch.py`` against small stand-ins of the launch
API that do what launch_ros documents (launch_ros 0.26, Jazzy):

* ``ros2 launch ... name:=value`` sets launch configurations; undeclared
  names keep the ``DeclareLaunchArgument`` default;
* ``Node(parameters=[params_file, {dict}, ...])`` becomes one
  ``--params-file`` per entry, in order; each dict is written to a
  temporary YAML file under the wildcard key ``/**:``; a substitution value
  is converted with ``ParameterValue``'s ``value_type`` (or read as YAML
  without one);
* ``name=`` becomes ``-r __node:=<name>``, ``remappings`` ``-r from:=to``.

The precedence of those parameter files is not modelled: the real node
classes are created by rclpy with exactly that command line, so rcl itself
decides which entry wins (node-specific over ``/**:``, later over earlier).
"""

import importlib.util
from ros_domains import fresh_domain  # noqa: E402
import re
import shlex
import sys
import types
from pathlib import Path

import pytest
import yaml

rclpy = pytest.importorskip('rclpy')

from rclpy.context import Context  # noqa: E402

from bellow_ancf_ros.nodes.forward_kinetostatic_node import ForwardKinetostaticNode  # noqa: E402
from bellow_ancf_ros.nodes.inverse_kinetostatic_node import InverseKinetostaticNode  # noqa: E402
from bellow_ancf_ros.nodes.simulated_robot_node import SimulatedRobotNode  # noqa: E402
from bellow_ancf_ros.nodes.trajectory_publisher import TrajectoryPublisher  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
LAUNCH_FILE = REPO / 'launch' / 'bellow_ancf.launch.py'
NODE_CLASSES = {
    'inverse_kinetostatic_node': InverseKinetostaticNode,
    'forward_kinetostatic_node': ForwardKinetostaticNode,
    'trajectory_publisher': TrajectoryPublisher,
    'simulated_robot_node': SimulatedRobotNode,
}
DEFAULT_NODES = {'inverse_kinetostatic_node', 'forward_kinetostatic_node', 'trajectory_publisher'}
ISSUE_EXAMPLE = ('robot_config:=two_segment trajectory:=bending_circle bending_angle_deg:=10.0 '
                 'period_s:=20.0 pressure_unit:=kPa')


# ------------------------------------------------ stand-ins of the launch API
class LaunchConfiguration:
    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return context[self.name]


class ParameterValue:
    def __init__(self, value, value_type=None):
        self.value, self.value_type = value, value_type


class DeclareLaunchArgument:
    def __init__(self, name, default_value=None, description=''):
        self.name, self.default_value, self.description = name, default_value, description


class IfCondition:
    def __init__(self, predicate):
        self.predicate = predicate

    def evaluate(self, context):
        value = _perform(self.predicate, context).strip().lower()
        assert value in ('true', 'false', '1', '0'), f'not a launch boolean: {value!r}'
        return value in ('true', '1')


class _Action:
    def __init__(self, condition=None, **kwargs):
        self.condition = condition
        self.kwargs = kwargs

    def enabled(self, context):
        return self.condition is None or self.condition.evaluate(context)


class Node(_Action):
    def __init__(self, *, package, executable, name=None, parameters=(), remappings=(),
                 arguments=(), output=None, condition=None, on_exit=None, sigterm_timeout=None):
        super().__init__(condition)
        self.package, self.executable, self.name = package, executable, name
        self.parameters, self.remappings, self.arguments = list(parameters), remappings, arguments
        self.on_exit, self.sigterm_timeout = on_exit, sigterm_timeout


class Shutdown:
    """launch.actions.Shutdown: ends the launch (as a node's ``on_exit``)."""

    def __init__(self, *, reason=''):
        self.reason = reason


class LogInfo(_Action):
    def __init__(self, *, msg, condition=None):
        super().__init__(condition)
        self.msg = msg


class LaunchDescription:
    def __init__(self, entities):
        self.entities = list(entities)


class PackageNotFoundError(KeyError):
    pass


def _perform(value, context):
    if isinstance(value, LaunchConfiguration):
        return value.perform(context)
    if isinstance(value, (list, tuple)):
        return ''.join(_perform(v, context) for v in value)
    return value


def _parameter_value(value, context):
    """launch_ros evaluate_parameters: a substitution with or without value_type."""
    if isinstance(value, ParameterValue):
        text = _perform(value.value, context)
        if value.value_type is str:
            return text
        if value.value_type is None:
            return yaml.safe_load(text)
        return value.value_type(yaml.safe_load(text))
    if isinstance(value, LaunchConfiguration):
        return yaml.safe_load(value.perform(context))
    return value


def load_launch_file(installed=('bellow_ancf_ros',)):
    """Import the launch file with the stand-ins; ``installed``: packages in the ament index."""
    def share(pkg):
        if pkg not in installed:
            raise PackageNotFoundError(pkg)
        return str(REPO) if pkg == 'bellow_ancf_ros' else f'/opt/ros/jazzy/share/{pkg}'

    stubs = {
        'launch': types.ModuleType('launch'),
        'launch.actions': types.ModuleType('launch.actions'),
        'launch.conditions': types.ModuleType('launch.conditions'),
        'launch.substitutions': types.ModuleType('launch.substitutions'),
        'launch_ros': types.ModuleType('launch_ros'),
        'launch_ros.actions': types.ModuleType('launch_ros.actions'),
        'launch_ros.parameter_descriptions': types.ModuleType('launch_ros.parameter_descriptions'),
        'ament_index_python': types.ModuleType('ament_index_python'),
        'ament_index_python.packages': types.ModuleType('ament_index_python.packages'),
    }
    stubs['launch'].LaunchDescription = LaunchDescription
    stubs['launch.actions'].DeclareLaunchArgument = DeclareLaunchArgument
    stubs['launch.actions'].LogInfo = LogInfo
    stubs['launch.actions'].Shutdown = Shutdown
    stubs['launch.conditions'].IfCondition = IfCondition
    stubs['launch.substitutions'].LaunchConfiguration = LaunchConfiguration
    stubs['launch_ros.actions'].Node = Node
    stubs['launch_ros.parameter_descriptions'].ParameterValue = ParameterValue
    stubs['ament_index_python.packages'].get_package_share_directory = share
    stubs['ament_index_python.packages'].PackageNotFoundError = PackageNotFoundError
    saved = {k: sys.modules.get(k) for k in stubs}
    sys.modules.update(stubs)
    try:
        spec = importlib.util.spec_from_file_location('bellow_ancf_launch', LAUNCH_FILE)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module.generate_launch_description()
    finally:
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v


def launch_context(description, cli_args):
    """Launch configurations: ``name:=value`` arguments, then the declared defaults.

    As launch does: each ``DeclareLaunchArgument``, in order, sets its
    default (a substitution: evaluated then) where no argument was given.
    """
    declared = [e for e in description.entities if isinstance(e, DeclareLaunchArgument)]
    context = {}
    for arg in shlex.split(cli_args) if isinstance(cli_args, str) else cli_args:
        name, value = arg.split(':=', 1)
        assert name in {e.name for e in declared}, \
            f'launch argument {name!r} is not declared by the launch file'
        context[name] = value
    for e in declared:
        if e.name not in context:
            context[e.name] = _perform(e.default_value, context)
    return context


def node_command_line(node, context, tmp_path):
    """The ``--ros-args`` launch_ros gives ``node`` (parameter dicts as ``/**:`` files)."""
    args = ['--ros-args']
    if node.name:
        args += ['-r', f'__node:={node.name}']
    for src, dst in node.remappings:
        args += ['-r', f'{_perform(src, context)}:={_perform(dst, context)}']
    for i, entry in enumerate(node.parameters):
        if isinstance(entry, dict):
            values = {k: _parameter_value(v, context) for k, v in entry.items()}
            path = tmp_path / f'{node.name}_{i}.yaml'
            path.write_text(yaml.safe_dump({'/**': {'ros__parameters': values}}))
        else:
            path = Path(_perform(entry, context))
        args += ['--params-file', str(path)]
    return args


def launch_argument_parameters(node, context):
    """Parameter name -> expected value for every parameter a launch argument sets."""
    out = {}
    for entry in node.parameters:
        if isinstance(entry, dict):
            for key, value in entry.items():
                out[key] = _parameter_value(value, context)
    return out


@pytest.fixture(scope='module')
def domain_id():
    return fresh_domain()


def start_node(cls, ros_args, domain):
    """Create ``cls`` in a process-like context: ``ros_args`` as the process arguments.

    launch_ros puts ``--ros-args ...`` on the executable's command line, which
    rclpy.init reads as global arguments, so that is what this does (one
    context per node).
    """
    ctx = Context()
    rclpy.init(args=['node'] + ros_args, context=ctx, domain_id=domain)
    try:
        return cls(context=ctx), ctx
    except BaseException:
        rclpy.try_shutdown(context=ctx)
        raise


def stop_node(n, ctx):
    if isinstance(n, InverseKinetostaticNode):
        n.vent_and_shutdown()
    n.destroy_node()
    rclpy.try_shutdown(context=ctx)


def effective_parameters(domain, node, context, tmp_path, names):
    """Create the real node class with launch_ros's command line; read ``names``."""
    cli = node_command_line(node, context, tmp_path)
    n, ctx = start_node(NODE_CLASSES[node.executable], cli, domain)
    try:
        assert n.get_name() == node.name
        return {k: n.get_parameter(k).value for k in names}
    finally:
        stop_node(n, ctx)


def run_launch(domain, tmp_path, cli_args):
    description = load_launch_file()
    context = launch_context(description, cli_args)
    results = {}
    for node in description.entities:
        if not isinstance(node, Node) or node.package != 'bellow_ancf_ros':
            continue
        if not node.enabled(context):
            continue
        expected = launch_argument_parameters(node, context)
        got = effective_parameters(domain, node, context, tmp_path, expected)
        results[node.executable] = (expected, got)
    return results


# ------------------------------------------------------------------ tests
def test_issue_example_launch_arguments_win_over_the_params_file(domain_id, tmp_path):
    results = run_launch(domain_id, tmp_path, ISSUE_EXAMPLE)
    assert set(results) == DEFAULT_NODES
    for exe, (expected, got) in results.items():
        assert got == expected, exe
    assert results['trajectory_publisher'][1] == {
        'robot_config': 'two_segment', 'base_frame': 'base', 'trajectory': 'bending_circle',
        'bending_angle_deg': 10.0, 'period_s': 20.0, 'payload_kg': 0.0, 'use_sim_time': False}
    for exe in ('inverse_kinetostatic_node', 'forward_kinetostatic_node'):
        got = dict(results[exe][1])
        assert got.pop('payload_kg') == 0.0 and got.pop('feedback', 'none') == 'none'
        assert got == {'robot_config': 'two_segment', 'base_frame': 'base',
                       'pressure_unit': 'kPa', 'use_sim_time': False}


def test_defaults_are_the_declared_defaults(domain_id, tmp_path):
    results = run_launch(domain_id, tmp_path, '')
    assert results['trajectory_publisher'][1]['trajectory'] == 'planar_circle'
    assert results['inverse_kinetostatic_node'][1]['robot_config'] == 'one_segment'
    for exe, (expected, got) in results.items():
        assert got == expected, exe


def test_every_readme_and_docstring_launch_example(domain_id, tmp_path):
    """Every ``ros2 launch bellow_ancf_ros bellow_ancf.launch.py ...`` line we document."""
    texts = [(REPO / 'README.md').read_text(), LAUNCH_FILE.read_text()]
    examples = []
    for text in texts:
        text = text.replace('\\\n', ' ')
        examples += re.findall(r'ros2 launch bellow_ancf_ros bellow_ancf\.launch\.py([^\n`]*)',
                               text)
    assert len(examples) >= 4, examples
    for args in examples:
        results = run_launch(domain_id, tmp_path, args.strip())
        for exe, (expected, got) in results.items():
            assert got == expected, (args, exe)


def test_node_specific_params_file_entry_would_win_so_nodes_yaml_has_none(domain_id, tmp_path):
    """Why the shipped nodes.yaml keeps launch-argument parameters under ``/**:`` only.

    A params file shaped like the old one (``/**:`` first, then a
    node-specific entry for a launch argument) makes the launch argument lose
    (rcl precedence, checked with a real node): the failure of the issue.  The
    shipped file has no such entry.
    """
    bad = tmp_path / 'node_specific.yaml'
    bad.write_text(yaml.safe_dump({
        '/**': {'ros__parameters': {'robot_config': 'one_segment'}},
        'trajectory_publisher': {'ros__parameters': {'trajectory': 'planar_rose'}}},
        sort_keys=False))
    description = load_launch_file()
    context = launch_context(description, [f'params_file:={bad}', 'trajectory:=space_spiral'])
    node = next(e for e in description.entities
                if isinstance(e, Node) and e.executable == 'trajectory_publisher')
    got = effective_parameters(domain_id, node, context, tmp_path, ['trajectory'])
    assert got['trajectory'] == 'planar_rose'      # node-specific entry beats the launch argument

    shipped = yaml.safe_load((REPO / 'config' / 'nodes.yaml').read_text())
    for node in description.entities:
        if isinstance(node, Node) and node.package == 'bellow_ancf_ros':
            specific = shipped.get(node.name, {}).get('ros__parameters', {})
            clash = set(specific) & set(launch_argument_parameters(node, context))
            assert not clash, f'{node.name}: node-specific {sorted(clash)} in nodes.yaml'


def test_plain_command_line_parameter_overrides_nodes_yaml(domain_id, tmp_path):
    """``--params-file config/nodes.yaml -p trajectory:=...`` (README's ros2 run line)."""
    cli = ['--ros-args', '--params-file', str(REPO / 'config' / 'nodes.yaml'),
           '-p', 'robot_config:=two_segment', '-p', 'trajectory:=bending_circle',
           '-p', 'trajectory_publisher:rate_hz:=20.0']
    n, ctx = start_node(TrajectoryPublisher, cli, domain_id)
    try:
        assert n.get_parameter('trajectory').value == 'bending_circle'
        assert n.cfg.name == 'two_segment'
        assert n.get_parameter('rate_hz').value == 20.0
    finally:
        stop_node(n, ctx)


def test_rviz_argument(tmp_path):
    with_rviz = load_launch_file(installed=('bellow_ancf_ros', 'rviz2'))
    rviz = [e for e in with_rviz.entities if isinstance(e, Node) and e.package == 'rviz2']
    assert len(rviz) == 1
    for value, started in (('true', True), ('false', False)):
        context = launch_context(with_rviz, [f'rviz:={value}'])
        assert rviz[0].enabled(context) is started
        args = [_perform(a, context) for a in rviz[0].arguments]
        assert args[0] == '-d' and Path(args[1]) == REPO / 'rviz' / 'bellow_ancf.rviz'
        assert Path(args[1]).is_file()
    assert not rviz[0].enabled(launch_context(with_rviz, ''))   # off by default
    # without rviz2: no rviz node, a log line instead when asked for
    without = load_launch_file(installed=('bellow_ancf_ros',))
    assert not [e for e in without.entities if isinstance(e, Node) and e.package == 'rviz2']
    logs = [e for e in without.entities if isinstance(e, LogInfo)]
    assert len(logs) == 1 and 'not installed' in logs[0].msg
    assert logs[0].enabled(launch_context(without, ['rviz:=true']))
    assert not logs[0].enabled(launch_context(without, ['rviz:=false']))


def test_rviz_config_shows_the_topics_in_the_base_frame():
    cfg = yaml.safe_load((REPO / 'rviz' / 'bellow_ancf.rviz').read_text())
    vm = cfg['Visualization Manager']
    assert vm['Global Options']['Fixed Frame'] == 'base'
    displays = {d['Topic']['Value']: d['Class'] for d in vm['Displays'] if 'Topic' in d}
    assert displays['/predicted_shape'] == 'rviz_default_plugins/MarkerArray'
    for topic in ('/target_pose', '/commanded_pose', '/predicted_pose', '/measured_pose'):
        assert displays[topic] == 'rviz_default_plugins/Pose', topic
    for d in vm['Displays']:
        if 'Topic' in d:
            assert d['Topic']['Reliability Policy'] == 'Reliable'   # the nodes publish reliable
            assert d['Enabled'] is True


def test_sim_feedback_and_payload_arguments(domain_id, tmp_path):
    """sim:=true feedback:=integral payload_kg:=0.02: a simulated robot that vents on its own."""
    results = run_launch(domain_id, tmp_path, 'sim:=true feedback:=integral payload_kg:=0.02')
    assert set(results) == DEFAULT_NODES | {'simulated_robot_node'}
    for exe, (expected, got) in results.items():
        assert got == expected, exe
    assert results['inverse_kinetostatic_node'][1]['feedback'] == 'integral'
    assert results['inverse_kinetostatic_node'][1]['payload_kg'] == 0.02
    assert results['forward_kinetostatic_node'][1]['payload_kg'] == 0.02
    assert results['trajectory_publisher'][1]['payload_kg'] == 0.02   # the robot at rest
    sim = results['simulated_robot_node'][1]
    assert sim['robot_config'] == 'one_segment_mismatched' and sim['command_timeout_s'] == 0.5
    # the simulated robot is the clock, in lockstep; every node runs on it
    assert sim['publish_clock'] and sim['lockstep'] and sim['real_time_factor'] == 1.0
    assert all(got['use_sim_time'] for _, got in results.values())


def test_the_simulated_robot_is_the_mismatched_one_of_robot_config(domain_id, tmp_path):
    """``robot_config:=two_segment sim:=true``: a two-segment simulated robot, not the default.

    A lab-style trial launched exactly that and got the one-segment robot,
    which refused every six-pressure command while the controller wound up.
    """
    results = run_launch(domain_id, tmp_path, 'robot_config:=two_segment sim:=true')
    for exe, (expected, got) in results.items():
        assert got == expected, exe
    assert results['simulated_robot_node'][1]['robot_config'] == 'two_segment_mismatched'
    given = run_launch(domain_id, tmp_path,
                       'robot_config:=two_segment sim:=true sim_robot_config:=two_segment')
    assert given['simulated_robot_node'][1]['robot_config'] == 'two_segment'


@pytest.mark.parametrize('args,sim_time', [('', False), ('sim:=true use_sim_time:=false', False),
                                           ('use_sim_time:=true', True),
                                           ('sim:=true sim_real_time_factor:=0.5', True)])
def test_use_sim_time_reaches_every_node_and_the_simulated_robot_is_the_clock(
        domain_id, tmp_path, args, sim_time):
    results = run_launch(domain_id, tmp_path, args)
    for exe, (expected, got) in results.items():
        assert got == expected, exe
        assert got['use_sim_time'] is sim_time, exe
    if 'simulated_robot_node' in results:
        sim = results['simulated_robot_node'][1]
        assert sim['publish_clock'] is sim_time
        assert sim['real_time_factor'] == (0.5 if '0.5' in args else 1.0)


def test_one_outcome_and_time_to_vent():
    """A node that ends ends the launch; the controller's SIGTERM wait covers its vent wait."""
    from bellow_ancf_ros.nodes.ros_util import VENT_ACK_TIMEOUT_S
    nodes = {e.executable: e for e in load_launch_file().entities
             if isinstance(e, Node) and e.package == 'bellow_ancf_ros'}
    for exe in ('inverse_kinetostatic_node', 'forward_kinetostatic_node', 'simulated_robot_node'):
        assert isinstance(nodes[exe].on_exit, Shutdown), exe
    assert float(nodes['inverse_kinetostatic_node'].sigterm_timeout) > VENT_ACK_TIMEOUT_S
