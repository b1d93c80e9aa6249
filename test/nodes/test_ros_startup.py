"""Node executables as a user meets them: start-up errors, recovery, Ctrl-C.

Each node runs as ``python -m bellow_ancf_ros.nodes.<module> --ros-args ...``
in its own session with SIGINT at its default action (a process started from
a non-interactive shell inherits SIGINT ignored), on a random ROS_DOMAIN_ID
with LOCALHOST discovery.  The test talks to it with rclpy: lifecycle and
parameter services, topics.  Waits poll with deadlines.
"""

import os
import random
import signal
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip('rclpy')

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from lifecycle_msgs.msg import Transition  # noqa: E402
from lifecycle_msgs.srv import ChangeState  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from bellow_ancf_ros.core.model import shipped_robot_names  # noqa: E402
from bellow_ancf_ros.nodes import ros_util  # noqa: E402
from bellow_ancf_ros.nodes.ros_util import command_qos  # noqa: E402
from ros_processes import node_process_env, REPO, SpunClient, wait_for  # noqa: E402

STARTUP_TIMEOUT = 30.0
TIMEOUT = 15.0
INVERSE = '/inverse_kinetostatic_node'


#: Fast DDS's own log line when its shared-memory transport finds a port's lock file left by
#: a process killed earlier (it recreates it, or goes on over UDP): the middleware's line,
#: not the node's, printed before the node runs any of its code.
FASTDDS_SHM_RACE = '[RTPS_TRANSPORT_SHM Error] Failed init_port'


def node_lines(out: str) -> list:
    """The non-blank lines a node process wrote, without Fast DDS's shared-memory race line."""
    return [line for line in out.splitlines()
            if line.strip() and FASTDDS_SHM_RACE not in line]


def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGQUIT, signal.SIG_DFL)


class Proc:
    """A node executable in its own session, output captured in a file."""

    def __init__(self, module, args, env, log_path):
        self.log_path = log_path
        cmd = [sys.executable, '-m', f'bellow_ancf_ros.nodes.{module}', '--ros-args', *args]
        with open(log_path, 'w') as log:
            self.proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT,
                                         stdin=subprocess.DEVNULL, start_new_session=True,
                                         preexec_fn=_default_sigint)

    def log(self):
        return self.log_path.read_text()

    def signal(self, sig):
        os.killpg(self.proc.pid, sig)

    def wait(self, timeout=TIMEOUT):
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            raise AssertionError(f'process did not exit within {timeout} s:\n{self.log()}')

    def kill(self):
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGCONT)
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.wait(5.0)


@pytest.fixture(scope='module')
def env():
    return node_process_env()


class Client(SpunClient):
    """rclpy in this process on the nodes' domain: records commands and diagnostics."""

    def __init__(self, domain):
        self.cmds, self.diags = [], []
        super().__init__(domain, 'startup_test_client')

    def setup(self, node):
        node.create_subscription(Float64MultiArray, 'pressure_command',
                                 lambda m: self._add(self.cmds, m), command_qos())
        node.create_subscription(DiagnosticArray, '/diagnostics',
                                 lambda m: self._add(self.diags, m), command_qos())
        self.targets = node.create_publisher(PoseStamped, 'target_pose', command_qos())

    def _add(self, lst, m):
        with self.lock:
            lst.append(m)

    def statuses(self, name_part):
        with self.lock:
            return [s for arr in self.diags for s in arr.status if name_part in s.name]

    def n_cmds(self):
        with self.lock:
            return len(self.cmds)

    def last_cmd(self):
        with self.lock:
            return list(self.cmds[-1].data)

    def call(self, srv_type, name, req):
        cli = self.node.create_client(srv_type, name)
        assert cli.wait_for_service(timeout_sec=STARTUP_TIMEOUT), name
        res = cli.call(req, timeout_sec=TIMEOUT)
        assert res is not None, f'{name} timed out'
        return res

    def transition(self, tid):
        req = ChangeState.Request()
        req.transition.id = tid
        return self.call(ChangeState, INVERSE + '/change_state', req).success


@pytest.fixture
def client(env):
    c = Client(int(env['ROS_DOMAIN_ID']))
    yield c
    c.close()


def kv(status):
    return {v.key: v.value for v in status.values}


def target(z=0.1, x=0.004):
    m = PoseStamped()
    m.header.frame_id = 'base'
    m.pose.position.x, m.pose.position.z = x, z
    m.pose.orientation.w = 1.0
    return m


# ------------------------------------------------------------------ tests
BAD_STARTUP = [
    ('inverse_kinetostatic_node', 'payload_kg:=-1.0', 'payload_kg', '-1.0', 'from 0 to 1'),
    ('inverse_kinetostatic_node', 'max_rate_hz:=-5.0', 'max_rate_hz', '-5.0', 'from 0.1 to 1000'),
    ('inverse_kinetostatic_node', 'pressure_unit:=bar', 'pressure_unit', "'bar'", "'kPa'"),
    ('inverse_kinetostatic_node', 'payload_kg:=1', 'payload_kg', '1', 'floating-point'),
    ('forward_kinetostatic_node', 'robot_config:=nonexistent', 'robot_config', "'nonexistent'",
     'shipped robots: ' + ', '.join(shipped_robot_names())),
    ('forward_kinetostatic_node', 'backbone_points:=1', 'backbone_points', '1', 'from 2 to 200'),
    ('trajectory_publisher', 'trajectory:=figure_eight', 'trajectory', "'figure_eight'",
     'planar_circle'),
    ('wrench_estimator_node', 'mode:=torque', 'mode', "'torque'", "one of: 'force', 'mass'"),
    ('simulated_robot_node', 'plant:=perfect', 'plant', "'perfect'", "'realistic' or 'ideal'"),
    ('excitation_publisher', 'dwell_s:=0.0', 'dwell_s', '0.0', 'from 0.01 to 3600'),
    ('mocap_relay', 'robot_config:=7', 'robot_config', '7', 'a string'),
]


def test_bad_startup_parameter_one_line_and_exit_2(env, tmp_path):
    procs = [Proc(mod, ['-p', arg], env, tmp_path / f'{i}.log')
             for i, (mod, arg, *_rest) in enumerate(BAD_STARTUP)]
    for p, (mod, arg, name, value, allowed) in zip(procs, BAD_STARTUP):
        code = p.wait(STARTUP_TIMEOUT)
        out = p.log()
        lines = node_lines(out)
        assert code == 2, (arg, out)
        assert 'Traceback' not in out, out
        assert len(lines) == 1, (arg, out)
        line = lines[0]
        assert line.startswith(f'[{mod}] cannot start: '), line   # the node's name
        assert f'parameter {name} = {value}' in line, line
        assert 'allowed' in line and allowed in line, line


BAD_PARAMS_FILES = [   # node, file content (None: no file), what the line says
    ('inverse_kinetostatic_node', None, 'no such file'),
    ('trajectory_publisher', 'a: [1, 2\n', 'not valid YAML, line 2'),
    ('mocap_relay', '- 1\n- 2\n', 'not a ROS 2 parameters file'),
    ('forward_kinetostatic_node', '/**:\n  ros__parameters:\n    x: [1, "s"]\n',
     'refused by rcl'),
]


def test_bad_params_file_one_line_and_exit_2(env, tmp_path):
    """A --params-file that is missing, not YAML or refused by rcl: one line, exit 2."""
    procs = []
    for i, (mod, content, _) in enumerate(BAD_PARAMS_FILES):
        path = tmp_path / f'params{i}.yaml'
        if content is not None:
            path.write_text(content)
        procs.append((Proc(mod, ['--params-file', str(path)], env, tmp_path / f'{i}.log'),
                      path))
    for (p, path), (mod, _, says) in zip(procs, BAD_PARAMS_FILES):
        code = p.wait(STARTUP_TIMEOUT)
        out = p.log()
        lines = node_lines(out)
        assert code == ros_util.STARTUP_ERROR_EXIT, out
        assert 'Traceback' not in out and len(lines) == 1, out
        assert lines[0].startswith(f'[{mod}] cannot start: '), lines[0]
        assert str(path) in lines[0] and says in lines[0], lines[0]


def test_bad_executor_name_one_line_and_exit_2(env, tmp_path):
    p = Proc('inverse_kinetostatic_node', [], {**env, ros_util.EXECUTOR_ENV: 'fast'},
             tmp_path / 'bad.log')
    code = p.wait(STARTUP_TIMEOUT)
    lines = node_lines(p.log())
    assert code == 2, p.log()
    assert len(lines) == 1 and 'Traceback' not in p.log(), p.log()
    assert "environment variable BELLOW_ANCF_EXECUTOR = 'fast'" in lines[0], lines[0]
    assert 'allowed: events, single_threaded' in lines[0], lines[0]


def test_nonexistent_robot_stays_unconfigured_then_recovers_and_vents(env, tmp_path, client):
    node = Proc('inverse_kinetostatic_node', ['-p', 'robot_config:=nonexistent'], env,
                tmp_path / 'inverse.log')
    try:
        wait_for(lambda: 'stays unconfigured' in node.log(), STARTUP_TIMEOUT, 'hint in the log')
        log = node.log()
        assert "configure failed: robot_config 'nonexistent'" in log
        assert f'ros2 param set {INVERSE} robot_config' in log
        assert f'ros2 lifecycle set {INVERSE} configure' in log
        # the heartbeat says so too, every second, while it waits
        wait_for(lambda: any(kv(s).get('lifecycle_state') == 'unconfigured'
                             for s in client.statuses('inverse_kinetostatic_node: status')),
                 STARTUP_TIMEOUT, 'heartbeat while unconfigured')
        st = [s for s in client.statuses('inverse_kinetostatic_node: status')][-1]
        assert st.level == DiagnosticStatus.ERROR and 'ros2 param set' in st.message
        assert node.proc.poll() is None

        # recovery as the hint says: set the parameter, configure, activate
        res = client.call(SetParameters, INVERSE + '/set_parameters', SetParameters.Request(
            parameters=[Parameter('robot_config', value='one_segment').to_parameter_msg()]))
        assert res.results[0].successful, res.results[0].reason
        assert client.transition(Transition.TRANSITION_CONFIGURE)
        assert client.transition(Transition.TRANSITION_ACTIVATE)
        wait_for(lambda: client.targets.get_subscription_count() >= 1, STARTUP_TIMEOUT,
                 'target_pose subscribed')
        n0 = client.n_cmds()
        deadline = time.monotonic() + TIMEOUT
        while client.n_cmds() == n0 and time.monotonic() < deadline:
            client.targets.publish(target())
            time.sleep(0.2)
        assert client.n_cmds() > n0, node.log()
        assert client.last_cmd() != [0.0, 0.0, 0.0]

        # Ctrl-C: the vent arrives and the node says it was acknowledged
        n1 = client.n_cmds()
        node.signal(signal.SIGINT)
        assert node.wait() == 0, node.log()
        wait_for(lambda: client.n_cmds() > n1, 5.0, 'vent command')
        assert client.last_cmd() == [0.0, 0.0, 0.0]
        assert "vent command (0 Pa gauge) acknowledged by all" in node.log(), node.log()
    finally:
        node.kill()


def _active_inverse(env, path, client):
    node = Proc('inverse_kinetostatic_node', [], env, path)
    return _first_command(node, client)


def _first_command(node, client):
    wait_for(lambda: client.targets.get_subscription_count() >= 1, STARTUP_TIMEOUT,
             'inverse node subscribed')
    deadline = time.monotonic() + TIMEOUT
    while client.n_cmds() == 0 and time.monotonic() < deadline:
        client.targets.publish(target())
        time.sleep(0.2)
    assert client.n_cmds() > 0, node.log()
    return node


SIGINT_AT_EXECUTOR = """
import signal
from rclpy.node import Node
from bellow_ancf_ros.nodes import ros_util

make_executor = ros_util.make_executor

def executor():
    signal.raise_signal(signal.SIGINT)  # Ctrl-C after the constructor, before the spin
    return make_executor()

class Probe(Node):
    def __init__(self):
        super().__init__('startup_sigint_probe')

ros_util.make_executor = executor
ros_util.main_for(Probe, before_destroy=lambda node: print('VENT', flush=True))()
print('CLEAN EXIT', flush=True)
"""


def test_sigint_between_constructor_and_spin_exits_cleanly_and_vents(env):
    """Regression: a Ctrl-C while the executor was being built gave a traceback, no vent."""
    res = subprocess.run([sys.executable, '-c', SIGINT_AT_EXECUTOR], env=env, cwd=REPO,
                         capture_output=True, text=True, timeout=60,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    out = res.stdout + res.stderr
    assert res.returncode == 0, out
    assert 'VENT' in res.stdout and 'CLEAN EXIT' in res.stdout, out
    assert 'Traceback' not in out, out


HANGING_TEARDOWN = """
import ctypes, sys, time
from rclpy.node import Node
from bellow_ancf_ros.nodes import ros_util

class Probe(Node):
    def __init__(self):
        super().__init__('hanging_teardown_probe')
        # 'UP' once spinning: a SIGINT in the constructor rightly just returns (nothing to vent)
        self._up = self.create_timer(0.01, self._say_up)

    def _say_up(self):
        self._up.cancel()
        print('UP', flush=True)

    def destroy_node(self):
        if sys.argv[1] == 'teardown':
            time.sleep(60)  # a teardown that hangs (the interpreter free)
        if sys.argv[1] == 'gil':
            # a C call that hangs holding the GIL (as Fast DDS destroy_participant did in
            # rcl_node_fini): PyDLL keeps the GIL during the call, no Python thread can run
            ctypes.PyDLL(None).sleep(60)
        return super().destroy_node()

def vent(node):
    if sys.argv[1] == 'vent':
        time.sleep(60)  # a vent step that hangs

ros_util.main_for(Probe, before_destroy=vent)()
print('RETURNED', flush=True)
"""


@pytest.mark.slow
def test_a_hanging_shutdown_still_ends_the_process_by_the_deadline(env, tmp_path):
    """Whatever hangs after Ctrl-C, the process exits by STOP_DEADLINE_S, and says so.

    With the interpreter free (a Python sleep in the teardown or the vent) the
    Python guard ends it at CLEAN_EXIT_S with its line (status 0 after the
    vent, 1 before); with the main thread blocked in a C call that holds the
    GIL, faulthandler's C watchdog ends it at WATCHDOG_EXIT_S with every
    thread's stack (status 1).
    """
    procs = {}
    for where in ('teardown', 'vent', 'gil'):
        log = open(tmp_path / f'{where}.log', 'w')
        procs[where] = (subprocess.Popen(
            [sys.executable, '-c', HANGING_TEARDOWN, where], env=env, cwd=REPO, stdout=log,
            stderr=subprocess.STDOUT, start_new_session=True, preexec_fn=_default_sigint), log)
    for where, (proc, _) in procs.items():
        wait_for(lambda: 'UP' in (tmp_path / f'{where}.log').read_text(), STARTUP_TIMEOUT,
                 f'{where} probe up')
    t0 = {}
    for where, (proc, _) in procs.items():
        t0[where] = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
    ended = {}
    for where, (proc, log) in procs.items():
        try:
            code = proc.wait(ros_util.STOP_DEADLINE_S + 10.0)
            ended[where] = time.monotonic() - t0[where]
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
            log.close()
        out = (tmp_path / f'{where}.log').read_text()
        assert 'RETURNED' not in out
        if where == 'gil':
            assert code == 1, out
            assert ros_util.WATCHDOG_EXIT_S - 0.2 <= ended[where], (ended, out)
            assert 'Timeout (0:00:07.5' in out, out
            assert 'in destroy_node' in out, out   # the stack of the hanging call
        else:
            assert code == (0 if where == 'teardown' else 1), out
            assert f'shutdown did not finish within {ros_util.CLEAN_EXIT_S:g} s' in out, out
            assert ros_util.CLEAN_EXIT_S - 0.2 <= ended[where], (ended, out)
        # the documented deadline holds, measured up to the parent's wait() seeing the exit
        assert ended[where] <= ros_util.STOP_DEADLINE_S, (where, ended, out)
    print('exit after SIGINT: ' + ', '.join(f'{k} {v:.2f} s' for k, v in ended.items()))


@pytest.mark.parametrize('executor', ros_util.EXECUTORS)
def test_double_sigint_still_vents(env, tmp_path, client, executor):
    """Terminal and ``ros2 launch`` both send SIGINT: the second must not cut the vent.

    With either executor (``BELLOW_ANCF_EXECUTOR``): commands, then the vent.
    """
    node = _first_command(Proc('inverse_kinetostatic_node', [],
                               {**env, ros_util.EXECUTOR_ENV: executor},
                               tmp_path / 'inverse.log'), client)
    try:
        n = client.n_cmds()
        node.signal(signal.SIGINT)
        node.signal(signal.SIGINT)
        time.sleep(0.05)
        node.signal(signal.SIGINT)
        assert node.wait() == 0, node.log()
        wait_for(lambda: client.n_cmds() > n, 5.0, 'vent command')
        assert client.last_cmd() == [0.0, 0.0, 0.0]
        assert 'acknowledged by all' in node.log()
    finally:
        node.kill()


@pytest.mark.slow
def test_vent_not_acknowledged_by_a_stopped_subscriber_is_logged(env, tmp_path, client):
    node = _active_inverse(env, tmp_path / 'inverse.log', client)
    # a second subscriber of pressure_command (the forward node), then frozen (SIGSTOP)
    listener = Proc('forward_kinetostatic_node', [], env, tmp_path / 'forward.log')
    try:
        preds = []
        client.node.create_subscription(PoseStamped, 'predicted_pose', preds.append,
                                        command_qos())
        # matched with the inverse node once a command of it produced a prediction
        deadline = time.monotonic() + STARTUP_TIMEOUT
        while not preds and time.monotonic() < deadline:
            client.targets.publish(target(x=0.002 + 0.001 * random.random()))
            time.sleep(0.3)
        assert preds, listener.log()
        listener.signal(signal.SIGSTOP)
        n = client.n_cmds()
        t0 = time.monotonic()
        node.signal(signal.SIGINT)
        assert node.wait() == 0, node.log()
        elapsed = time.monotonic() - t0
        log = node.log()
        assert 'NOT acknowledged by all 2 matched subscriber(s) within 4 s' in log, log
        assert elapsed < 10.0          # the wait is bounded (4 s)
        # the running subscriber got the vent all the same
        wait_for(lambda: client.n_cmds() > n, 5.0, 'vent command')
        assert client.last_cmd() == [0.0, 0.0, 0.0]
    finally:
        listener.kill()
        node.kill()


#: how long the first start compiles, in the words of README.md and docs/cli.md (52-66 s)
COMPILE_TIME = 'about a minute on a 2-core machine'


def test_a_first_start_says_at_once_that_it_compiles(tmp_path):
    """An empty kernel cache (as after installation): the first line says what the wait is.

    The duration it gives is the one README.md and docs/cli.md give.
    """
    import signal as _signal
    for doc in ('README.md', 'docs/cli.md'):
        assert COMPILE_TIME in ' '.join((REPO / doc).read_text().split()), doc
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), PYTHONUNBUFFERED='1')
    proc = subprocess.Popen([sys.executable, '-m',
                             'bellow_ancf_ros.nodes.inverse_kinetostatic_node'],
                            env=env, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        first = proc.stderr.readline()
        assert first.startswith('[inverse_kinetostatic_node] compiling the numerical kernels '
                                f'once after installation ({COMPILE_TIME}; '), first
        assert '`ros2 run bellow_ancf_ros bellow-ancf warm-up` does it ahead of time' in first
    finally:
        os.killpg(proc.pid, _signal.SIGKILL)
        proc.wait(10)


def _errors(log):
    return [line for line in log.splitlines() if line.startswith('[ERROR]')]


def _lifecycle_state(client):
    from lifecycle_msgs.srv import GetState
    return client.call(GetState, INVERSE + '/get_state', GetState.Request()).current_state.label


def test_one_owner_yields_with_a_vent_and_resumes_only_on_activate(env, tmp_path, client):
    """The ownership rule (docs/ros.md): an excitation started beside the active controller.

    Both nodes see another publisher of pressure_command: the controller
    vents once and deactivates itself, the excitation aborts; each logs one
    ERROR naming the other node (not the graph's placeholder).  When the
    excitation has gone, the controller does not come back by itself; an
    explicit ``activate`` resumes it (the vent held until a new target).
    """
    node = _active_inverse(env, tmp_path / 'inverse.log', client)
    exc = None
    try:
        assert client.last_cmd() != [0.0, 0.0, 0.0]
        exc = Proc('excitation_publisher', ['-p', 'start_delay_s:=0.2', '-p', 'dwell_s:=0.5',
                                            '-p', 'exit_when_done:=false'],
                   env, tmp_path / 'excitation.log')
        wait_for(lambda: 'yielding pressure_command: vent command (0 Pa gauge) published'
                 in node.log(), STARTUP_TIMEOUT, 'the controller vents on its yield')
        wait_for(lambda: _errors(node.log()) and _errors(exc.log()), STARTUP_TIMEOUT,
                 'both ERRORs')
        wait_for(lambda: client.last_cmd() == [0.0, 0.0, 0.0], TIMEOUT, 'the vent last')
        assert _lifecycle_state(client) == 'inactive'
        time.sleep(2.5)   # reminders come every 10 s, not every 2 s
        for log, other in ((node.log(), '/excitation_publisher'),
                           (exc.log(), '/inverse_kinetostatic_node')):
            errors = _errors(log)
            assert len(errors) == 1, errors   # one ERROR, not three variants every 2 s
            assert other in errors[0] and 'UNKNOWN' not in errors[0], errors[0]
            assert 'no automatic resume' in errors[0], errors[0]
        assert f'ros2 lifecycle set {INVERSE} activate' in _errors(node.log())[0]
        assert 'excitation aborted' not in exc.log()   # exit_when_done false: it stays
        n_vented = client.n_cmds()

        # the excitation leaves: one INFO, no resume by itself
        exc.signal(signal.SIGINT)
        assert exc.wait() == 0, exc.log()
        wait_for(lambda: 'no longer publishes' in node.log(), TIMEOUT, 'the INFO line')
        time.sleep(2.0)   # the controller used to resume (and jump) about 1 s after
        assert client.n_cmds() == n_vented, 'a command after the yield, without an action'
        assert _lifecycle_state(client) == 'inactive'

        # the explicit action: activate; the vent holds until a new target
        assert client.transition(Transition.TRANSITION_ACTIVATE)
        wait_for(lambda: client.n_cmds() > n_vented, TIMEOUT, 'commands again')
        assert client.last_cmd() == [0.0, 0.0, 0.0]   # the vent, republished: no jump
        deadline = time.monotonic() + TIMEOUT
        while client.last_cmd() == [0.0, 0.0, 0.0] and time.monotonic() < deadline:
            client.targets.publish(target(x=0.003))
            time.sleep(0.2)
        assert client.last_cmd() != [0.0, 0.0, 0.0], node.log()

        # an excitation that finds the controller commanding aborts at once, status 1
        exc = Proc('excitation_publisher', ['-p', 'start_delay_s:=0.2'], env,
                   tmp_path / 'excitation2.log')
        assert exc.wait(STARTUP_TIMEOUT) == 1, exc.log()
        assert 'excitation aborted: exiting (status 1)' in exc.log()
        assert '/inverse_kinetostatic_node' in _errors(exc.log())[0]
    finally:
        if exc is not None:
            exc.kill()
        node.kill()


class Recorder:
    """Every ``pressure_command`` message delivered to this process, in order, and a rival.

    Its subscription (reliable, keep-all) is never spun: :meth:`drain` takes
    what the middleware holds.  A message acknowledged to its publisher
    (``wait_for_all_acked``) is in that history: once the publisher has said
    that its last message was acknowledged and its process has ended, one
    drain gives everything it sent, and "nothing after the vent" needs no
    waiting.
    """

    def __init__(self, domain, namespace):
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=domain)
        self.ns = namespace
        self.node = rclpy.create_node('command_recorder', namespace=namespace, context=self.ctx,
                                      start_parameter_services=False)
        qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_ALL)
        self.sub = self.node.create_subscription(Float64MultiArray, 'pressure_command',
                                                 lambda m: None, qos)
        self.got = []
        self.rival = None

    def drain(self):
        """Take every message held for the subscription; all taken so far."""
        while True:
            with self.sub.handle:
                taken = self.sub.handle.take_message(self.sub.msg_type, self.sub.raw)
            if taken is None:
                return self.got
            self.got.append(list(taken[0].data))

    def start_rival(self, name):
        """A second node with a publisher of pressure_command (it never publishes)."""
        self.rival = rclpy.create_node(name, namespace=self.ns, context=self.ctx,
                                       start_parameter_services=False)
        self.rival.create_publisher(Float64MultiArray, 'pressure_command', command_qos())

    def close(self):
        for n in (self.rival, self.node):
            if n is not None:
                n.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def _steps(vectors):
    """The vectors without their repetitions (a step is republished at rate_hz)."""
    return [v for i, v in enumerate(vectors) if i == 0 or v != vectors[i - 1]]


def test_an_excitation_that_has_commanded_yields_with_one_vent_as_its_last_message(env, tmp_path):
    """The ownership rule after commanding: the regulators end vented, then silence.

    The excitation publisher steps (0.4 s each) with a recorder matched from
    its first step; then a second node publishes pressure_command (a plain
    rclpy publisher, as docs/ros.md "One owner of pressure_command" counts
    any).  The excitation sends the vent once, as its last message, logs one
    ERROR naming that node, waits until the recorder has acknowledged the vent
    and ends with status 1 (``exit_when_done``).
    """
    from bellow_ancf_ros.core import load_robot
    from bellow_ancf_ros.core.fit import excitation_sequence

    ns = f'/yield{random.randint(0, 99999)}'   # apart from any other test on the domain
    rec = Recorder(int(env['ROS_DOMAIN_ID']), ns)
    exc = None
    try:
        exc = Proc('excitation_publisher', ['-r', f'__ns:={ns}',
                                            '-p', 'start_delay_s:=0.0', '-p', 'dwell_s:=0.4',
                                            '-p', 'rate_hz:=20.0',
                                            '-p', 'wait_for_subscribers:=1'],
                   env, tmp_path / 'excitation.log')
        try:
            wait_for(lambda: len(_steps(rec.drain())) >= 3, STARTUP_TIMEOUT, 'three steps')
        except AssertionError as err:
            raise AssertionError(f'{err}:\n{exc.log()}') from None
        assert exc.proc.poll() is None
        rec.start_rival('rival_commander')
        status = exc.wait(STARTUP_TIMEOUT)
        log = exc.log()
        assert status == 1, log
        assert 'vent acknowledged by all 1 matched subscriber(s)' in log, log
        got = rec.drain()   # all it sent (the class docstring)

        # the messages: steps of the sequence in order, then one vent, the last
        sequence = [list(p) for p in excitation_sequence(load_robot('one_segment'), 4, 40, 0)]
        assert all(any(p) for p in sequence)   # a zero vector can only be the vent
        assert got[-1] == [0.0, 0.0, 0.0], got[-5:]
        assert [p for p in got if not any(p)] == [[0.0, 0.0, 0.0]], 'one vent only'
        steps = _steps(got[:-1])
        assert steps == sequence[:len(steps)]
        assert len(steps) < len(sequence)

        # the log: the vent at the step it yielded at, one ERROR naming the rival, exit
        lines = log.splitlines()
        vents = [i for i, line in enumerate(lines) if 'vent command (0 Pa gauge)' in line]
        assert len(vents) == 1, log   # no second vent on the way out
        step_of = f'yielding pressure_command at step {len(steps)} of {len(sequence)}: '
        step_after = f'yielding pressure_command at step {len(steps) + 1} of {len(sequence)}: '
        assert step_of in lines[vents[0]] or step_after in lines[vents[0]], lines[vents[0]]
        errors = [i for i, line in enumerate(lines) if line.startswith('[ERROR]')]
        assert len(errors) == 1, log
        error = lines[errors[0]]
        assert f'{ns}/pressure_command: {ns}/rival_commander publishes it too: vented once ' \
               'and stopped commanding; no automatic resume' in error, error
        assert 'UNKNOWN' not in log, log
        (acked,) = [i for i, line in enumerate(lines) if 'vent acknowledged' in line]
        (done,) = [i for i, line in enumerate(lines)
                   if 'excitation aborted: exiting (status 1)' in line]
        assert vents[0] < errors[0] < acked < done, log
    finally:
        if exc is not None:
            exc.kill()
        rec.close()
