"""A node whose launcher exits without passing a signal on vents and exits.

``kill -TERM`` (or ``-KILL``) of the ``ros2 launch`` process alone ends it
without signalling its nodes (seen: exit 143, the nodes commanding on).
Each node watches its parent
(:func:`bellow_ancf_ros.nodes.ros_util.watch_parent`) and then stops as on
SIGTERM: the vent (0 Pa gauge on every actuator) as its last command, then
the exit.

``launch`` and ``launch_ros`` are not installable from PyPI, so the launcher
here is a plain Python process (:data:`LAUNCHER`) that starts the inverse
node as its child with its output piped to it, as launch_ros's ``Node``
action with ``output='screen'`` does.  On a ROS install the launcher would be
``ros2 launch bellow_ancf_ros bellow_ancf.launch.py with_trajectory:=false``
(or a ``launch.LaunchService`` running a ``launch_ros.actions.Node`` of
``inverse_kinetostatic_node``), killed the same way.  This test process is
the orphan's subreaper (``PR_SET_CHILD_SUBREAPER``), so that it can wait
for the node and read its exit status.
"""

import ctypes
import os
import signal
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip('rclpy')

from geometry_msgs.msg import PoseStamped  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from bellow_ancf_ros.nodes import ros_util  # noqa: E402
from bellow_ancf_ros.nodes.ros_util import command_qos  # noqa: E402
from ros_processes import node_process_env, REPO, SpunClient, wait_for  # noqa: E402

pytestmark = pytest.mark.skipif(not sys.platform.startswith('linux'),
                                reason='PR_SET_CHILD_SUBREAPER (to wait for an orphan) is Linux')

STARTUP_TIMEOUT = 60.0
TIMEOUT = 15.0
PR_SET_CHILD_SUBREAPER = 36

#: The launcher: starts the inverse node as its child (from its main thread, or from a thread
#: that ends once the file argv[2] exists: ``thread``), prints the node's pid, relays the
#: node's output as launch does.
LAUNCHER = """
import os, subprocess, sys, threading, time
cmd = [sys.executable, '-m', 'bellow_ancf_ros.nodes.inverse_kinetostatic_node', '--ros-args']
started = []

def start():
    started.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                    stdin=subprocess.DEVNULL))
    print('NODE', started[0].pid, flush=True)
    while sys.argv[1] == 'thread' and not os.path.exists(sys.argv[2]):
        time.sleep(0.05)

if sys.argv[1] == 'thread':
    t = threading.Thread(target=start)
    t.start()
    t.join()
    print('THREAD ENDED', flush=True)
else:
    start()
for line in started[0].stdout:
    sys.stdout.buffer.write(line)
    sys.stdout.flush()
"""


@pytest.fixture
def env():
    return node_process_env()


class Client(SpunClient):
    """rclpy in this process on the node's domain: sends targets, records commands."""

    def __init__(self, domain):
        self.cmds, self.times = [], []
        super().__init__(domain, 'parent_exit_test_client')

    def setup(self, node):
        node.create_subscription(Float64MultiArray, 'pressure_command', self._add, command_qos())
        self.targets = node.create_publisher(PoseStamped, 'target_pose', command_qos())

    def _add(self, m):
        with self.lock:
            self.cmds.append(list(m.data))
            self.times.append(time.monotonic())

    def commands(self):
        with self.lock:
            return list(self.cmds)


@pytest.fixture
def client(env):
    c = Client(int(env['ROS_DOMAIN_ID']))
    yield c
    c.close()


@pytest.fixture
def subreaper():
    """This process adopts orphaned descendants while the test runs (to wait for them)."""
    libc = ctypes.CDLL(None, use_errno=True)
    assert libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0, os.strerror(ctypes.get_errno())
    try:
        yield
    finally:
        libc.prctl(PR_SET_CHILD_SUBREAPER, 0, 0, 0, 0)


def target(x=0.004, z=0.1):
    m = PoseStamped()
    m.header.frame_id = 'base'
    m.pose.position.x, m.pose.position.z = x, z
    m.pose.orientation.w = 1.0
    return m


def _wait_exit(pid, timeout):
    """The exit status of ``pid`` (our adopted orphan), or None if it is still running."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done == pid:
            return os.waitstatus_to_exitcode(status)
        time.sleep(0.02)
    return None


@pytest.mark.parametrize('started_from, sig', [('main', signal.SIGKILL),
                                               ('thread', signal.SIGTERM)])
def test_a_node_whose_launcher_exits_vents_and_exits(env, client, subreaper, tmp_path,
                                                     started_from, sig):
    """The launcher is killed alone: the node's last command is the vent, then it exits 0.

    ``thread``: the thread of the launcher that started the node ends while
    the node runs (``PR_SET_PDEATHSIG`` would fire then, see
    :func:`~bellow_ancf_ros.nodes.ros_util.watch_parent`): the node serves
    on while the launcher lives.
    """
    log_path, thread_may_end = tmp_path / 'launcher.log', tmp_path / 'thread_may_end'
    with open(log_path, 'w') as log:
        launcher = subprocess.Popen(
            [sys.executable, '-c', LAUNCHER, started_from, str(thread_may_end)], env=env,
            cwd=REPO, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            start_new_session=True)
    node_pid = None
    try:
        wait_for(lambda: 'NODE' in log_path.read_text(), STARTUP_TIMEOUT, 'the node started')
        node_pid = int(log_path.read_text().split('NODE', 1)[1].split()[0])
        wait_for(lambda: client.targets.get_subscription_count() >= 1, STARTUP_TIMEOUT,
                 'the inverse node subscribed')
        for x in (0.004, 0.006):
            before = client.commands()[-1] if client.commands() else None
            deadline = time.monotonic() + TIMEOUT
            # (the vent of the node's activation may come after the first target: not an answer)
            while (client.commands()[-1:] in ([], [before], [[0.0, 0.0, 0.0]])
                   and time.monotonic() < deadline):
                client.targets.publish(target(x=x))
                time.sleep(0.2)
            assert client.commands()[-1:] not in ([], [before]), log_path.read_text()
            assert any(v != 0.0 for v in client.commands()[-1])     # commanding, not vented
            if started_from == 'thread' and x == 0.004:   # the starting thread ends; it serves on
                thread_may_end.touch()
                wait_for(lambda: 'THREAD ENDED' in log_path.read_text(), what='the thread ended')
        n = len(client.commands())

        killed = time.monotonic()
        os.kill(launcher.pid, sig)                               # the launcher alone
        assert launcher.wait(TIMEOUT) == -sig
        code = _wait_exit(node_pid, ros_util.STOP_DEADLINE_S + 5.0)
        print(f'node exit {time.monotonic() - killed:.2f} s after the launcher\'s {sig.name}')
        assert code is not None, 'the node kept running after its launcher exited'
        node_pid = None
        assert code == 0, log_path.read_text()
        # it waited for our acknowledgement of the vent before it exited: the vent is here
        wait_for(lambda: client.commands()[-1] == [0.0, 0.0, 0.0], 5.0, 'the vent')
        assert len(client.commands()) > n
        with client.lock:
            vent_t = client.times[client.cmds.index([0.0, 0.0, 0.0], n)]
        print(f'vent {vent_t - killed:.2f} s after it')
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait(5.0)
        if node_pid is not None:
            try:
                os.kill(node_pid, signal.SIGKILL)
                os.waitpid(node_pid, 0)
            except (ProcessLookupError, ChildProcessError):
                pass
