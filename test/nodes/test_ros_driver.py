"""Drivers that must vent: the republished command, the driver template, the simulated robot.

A SIGKILLed controller sends nothing: the template driver and the simulated
robot vent within ``command_timeout_s``; a driver vents on its own shutdown;
a held target keeps being republished at ``command_rate_hz`` so that a live
controller is told from a dead one.
"""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from geometry_msgs.msg import PoseStamped  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from bellow_ancf_ros.core import solve_forward  # noqa: E402
from bellow_ancf_ros.nodes.inverse_kinetostatic_node import InverseKinetostaticNode  # noqa: E402
from bellow_ancf_ros.nodes.regulator_driver import RegulatorDriver  # noqa: E402
from bellow_ancf_ros.nodes.simulated_robot_node import SimulatedRobotNode  # noqa: E402
import test_ros_nodes as _rn  # noqa: E402
from test_ros_nodes import pressure_msg, target_msg, wait_for  # noqa: E402
from ros_processes import interrupt  # noqa: E402

h = _rn.h


class Written:
    """A stand-in regulator: what the driver wrote, with times."""

    def __init__(self):
        self.calls = []

    def __call__(self, p):
        self.calls.append((time.monotonic(), np.array(p, dtype=float)))

    @property
    def last(self):
        return self.calls[-1][1] if self.calls else None


def test_a_held_target_is_republished_at_command_rate_hz(h, one):
    h.record(Float64MultiArray, 'pressure_command')
    node = h.add(InverseKinetostaticNode, command_rate_hz=20.0, target_shaping='none')
    pub = h.publisher(PoseStamped, 'target_pose')
    pub.publish(target_msg(solve_forward(one, [70e3, 10e3, -30e3]).position))
    wait_for(lambda: node.stats['published'] >= 1, what='the first command')
    n0, t0 = h.count('pressure_command'), time.monotonic()
    time.sleep(1.0)
    rate = (h.count('pressure_command') - n0) / (time.monotonic() - t0)
    assert 14.0 <= rate <= 22.0, rate            # 20 Hz, none solved meanwhile
    assert node.stats['published'] == 1
    with h.lock:
        last = [np.array(m.data) for _, m in h.msgs['pressure_command'][-5:]]
    for c in last:
        np.testing.assert_array_equal(c, node.last_command_pa)
    node.trigger_deactivate()                     # inactive: the vent, then silence
    wait_for(lambda: np.all(np.array(h.last('pressure_command').data) == 0), what='vent')
    n1 = h.count('pressure_command')
    time.sleep(0.3)
    assert h.count('pressure_command') == n1


def test_driver_writes_refuses_bad_commands_and_vents_on_shutdown(h, one):
    wrote = Written()
    drv = h.add(lambda **kw: RegulatorDriver(wrote, **kw), command_timeout_s=5.0)
    pub = h.publisher(Float64MultiArray, 'pressure_command')
    pub.publish(pressure_msg([70e3, 10e3, -30e3]))
    wait_for(lambda: wrote.last is not None, what='a write')
    np.testing.assert_allclose(wrote.last, [70e3, 10e3, -30e3])
    pub.publish(pressure_msg([70.0, 10.0, -30.0], label='actuator_pressure_gauge_kpa'))
    wait_for(lambda: len(wrote.calls) >= 2, what='a kPa command')
    np.testing.assert_allclose(wrote.last, [70e3, 10e3, -30e3])
    for bad in ([np.nan, 0.0, 0.0], [0.0, 0.0], [500e3, 0.0, 0.0]):
        pub.publish(pressure_msg(bad))
    wait_for(lambda: drv.stats['refused'] >= 3, what='3 refusals')
    np.testing.assert_allclose(wrote.last, [70e3, 10e3, -30e3])   # set-points unchanged
    h.executor.remove_node(drv)
    h.nodes.remove(drv)
    drv.destroy_node()                            # the driver's own shutdown
    np.testing.assert_array_equal(wrote.last, np.zeros(3))
    assert drv.state.startswith('vented: driver shutdown')


def _controller_process(ns, rate_hz=20.0):
    """The inverse node as a process in the harness's namespace and domain."""
    cmd = [sys.executable, '-m', 'bellow_ancf_ros.nodes.inverse_kinetostatic_node',
           '--ros-args', '-r', f'__ns:={ns}', '-p', f'command_rate_hz:={rate_hz}']
    return subprocess.Popen(cmd, env=dict(os.environ), start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def test_sigkilled_controller_driver_and_simulated_robot_vent_within_the_timeout(h, one):
    h.record(Float64MultiArray, 'measured_pressure')
    wrote = Written()
    drv = h.add(lambda **kw: RegulatorDriver(wrote, **kw), command_timeout_s=0.5)
    sim = h.add(SimulatedRobotNode, command_timeout_s=0.5, seed=3)
    proc = _controller_process(h.ns)
    try:
        pub = h.client.create_publisher(PoseStamped, 'target_pose', _rn.command_qos())
        wait_for(lambda: pub.get_subscription_count() >= 1, timeout=60.0,
                 what='the controller process')
        target = solve_forward(one, [70e3, 10e3, -30e3]).position
        pub.publish(target_msg(target))
        wait_for(lambda: wrote.last is not None and np.any(wrote.last), timeout=30.0,
                 what='commands at the driver')
        time.sleep(1.0)                        # a held target: fed by the republished command
        assert drv.stats['timeouts'] == 0 and sim.stats['timeouts'] == 0
        assert np.any(wrote.last)
        killed = time.monotonic()
        os.killpg(proc.pid, signal.SIGKILL)
        wait_for(lambda: drv.stats['timeouts'] >= 1, what='the driver vents')
        vent_t = next(t for t, p in wrote.calls if t > killed and not np.any(p))
        assert vent_t - killed < 0.5 + 0.15, vent_t - killed   # timeout + watchdog period
        wait_for(lambda: sim.stats['timeouts'] >= 1, what='the simulated robot vents')
        # at the vent within the regulators' play (half the hysteresis band)
        play = 0.5 * sim.robot.effects.regulator_hysteresis_pa + 1.0
        wait_for(lambda: np.allclose(h.last('measured_pressure').data, 0.0, atol=play),
                 what='measured_pressure at 0')
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(10)


# ------------------------------------------------------------------ one owner of the topic
def test_two_publishers_on_pressure_command_never_alternate(h, one):
    """The controller holds a target; an excitation publisher is started by mistake.

    Once they have discovered each other both yield (ownership.py): the
    controller vents once and deactivates itself, the excitation aborts; the
    commands never flip back; both say why, naming the other node.  With the
    other gone, the controller stays silent until it is activated again.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState
    from bellow_ancf_ros.nodes.excitation_publisher import ExcitationPublisher
    from bellow_ancf_ros.nodes.ros_util import command_qos
    h.record(Float64MultiArray, 'pressure_command')
    h.record(DiagnosticArray, '/diagnostics', command_qos())
    inv = h.add(InverseKinetostaticNode, command_rate_hz=20.0, target_shaping='none')
    pub = h.publisher(PoseStamped, 'target_pose')
    pub.publish(target_msg(solve_forward(one, [70e3, 10e3, -30e3]).position))
    wait_for(lambda: inv.stats['published'] >= 1, what='the controller commands')
    held = inv.last_command_pa.copy()
    n0 = h.count('pressure_command')
    exc = h.add(ExcitationPublisher, dwell_s=0.5, rate_hz=20.0, exit_when_done=False)
    wait_for(lambda: exc.aborted and not inv.is_active, what='both yield')
    time.sleep(1.0)
    with h.lock:
        seq = [np.array(m.data) for _, m in h.msgs['pressure_command'][n0:]]
    kinds = ['vent' if not np.any(c) else 'controller' if np.allclose(c, held) else 'other'
             for c in seq]
    flips = sum(1 for a, b in zip(kinds, kinds[1:]) if {a, b} == {'controller', 'other'})
    assert flips <= 1, kinds          # at most the one switch before discovery, never back
    assert kinds[-1] == 'vent', kinds
    wait_for(lambda: any(exc.get_fully_qualified_name() in s.message
                         for s in _rn.diag_statuses(h, 'inverse')), what='inverse ERROR')
    wait_for(lambda: any(inv.get_fully_qualified_name() in s.message
                         for s in _rn.diag_statuses(h, 'excitation')), what='excitation ERROR')
    # the intruder goes: the controller does not come back by itself
    h.executor.remove_node(exc)
    h.nodes.remove(exc)
    exc.destroy_node()
    n2 = h.count('pressure_command')
    time.sleep(2.0)
    assert h.count('pressure_command') == n2 and not inv.is_active
    # activate (the explicit action): the vent is held until a new target
    change = h.service(ChangeState, f'{h.ns}/inverse_kinetostatic_node/change_state')
    req = ChangeState.Request()
    req.transition.id = Transition.TRANSITION_ACTIVATE
    assert h.call(change, req).success
    wait_for(lambda: h.count('pressure_command') > n2 + 3, what='commands again')
    assert not np.any(h.last('pressure_command').data)
    pub.publish(target_msg(solve_forward(one, [70e3, 10e3, -30e3]).position))
    wait_for(lambda: np.any(h.last('pressure_command').data), what='the target commanded')
    np.testing.assert_allclose(h.last('pressure_command').data, held, atol=1.0)


def test_excitation_publisher_process_exits_when_its_sequence_and_the_vent_are_done():
    cmd = [sys.executable, '-m', 'bellow_ancf_ros.nodes.excitation_publisher', '--ros-args',
           '-p', 'dwell_s:=0.05', '-p', 'points_per_scheme:=2', '-p', 'n_random:=1']
    t0 = time.monotonic()
    proc = subprocess.run(cmd, env=dict(os.environ), capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert 'excitation finished: vent command' in proc.stderr
    assert 'sequence and vent done: exiting' in proc.stderr
    assert time.monotonic() - t0 < 60


def test_driver_process_vents_on_ctrl_c(h):
    """The template as a process (as a launch file starts it): Ctrl-C -> it writes the vent."""
    cmd = [sys.executable, '-m', 'bellow_ancf_ros.nodes.regulator_driver', '--ros-args',
           '-r', f'__ns:={h.ns}', '-p', 'command_timeout_s:=30.0']
    proc = subprocess.Popen(cmd, env=dict(os.environ), start_new_session=True, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        pub = h.client.create_publisher(Float64MultiArray, 'pressure_command',
                                        _rn.command_qos())
        wait_for(lambda: pub.get_subscription_count() >= 1, timeout=60.0, what='the driver')
        for _ in range(10):   # a controller republishes; one message may precede matching
            pub.publish(pressure_msg([70e3, 10e3, -30e3]))
            time.sleep(0.1)
    finally:
        out = interrupt(proc, 20.0)
    assert proc.returncode == 0, out[-2000:]
    assert 'regulators <- 70.00 10.00 -30.00 kPa gauge' in out
    assert 'regulators <- 0.00 0.00 0.00 kPa gauge' in out and 'vented: driver shutdown' in out
    # its normal shutdown vent is news, not a warning (the timeout vent is the WARN)
    vent_line = next(line for line in out.splitlines() if 'vented: driver shutdown' in line)
    assert vent_line.startswith('[INFO]'), vent_line
    assert '[WARN]' not in out and '[ERROR]' not in out, out[-2000:]
