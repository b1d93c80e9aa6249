"""wrench_estimator_node (issue 20, item 3): poses and pressures in, the tip force out.

The poses come from the core's simulated robot under a known tip force
(its own robot file is the node's model), published by this test at 100 Hz
with the pressures; the node's ``estimated_wrench`` must come back to the
force, ``~/tare`` must zero it, and bad samples must be refused (counted,
WARN on ``/diagnostics``) while the node keeps estimating.
"""

import math
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from bellow_ancf_ros.core import geometry  # noqa: E402
from bellow_ancf_ros.core.control import SimulatedRobot  # noqa: E402
from bellow_ancf_ros.nodes.measured_feedback import measured_pose_qos  # noqa: E402
from bellow_ancf_ros.nodes.ros_util import command_qos  # noqa: E402
from bellow_ancf_ros.nodes.wrench_estimator_node import WrenchEstimatorNode  # noqa: E402
import test_ros_nodes as _rn  # noqa: E402
from test_ros_nodes import diag_statuses, pressure_msg, target_msg, wait_for  # noqa: E402

h = _rn.h   # the harness fixture (the isolated ROS context comes from conftest)
TRUTH = np.array([0.05, -0.02, 0.0])


def _stream(h, sim, pub_pose, pub_p, n, rate=100.0):
    for _ in range(n):
        sim.step(1.0 / rate)
        pos, R = sim.measure()
        pub_p.publish(pressure_msg(sim.pressures_pa))
        pub_pose.publish(target_msg(pos, geometry.quaternion_from_rotation(R)))
        time.sleep(1.0 / rate)


def test_estimated_wrench_tare_and_bad_samples(h):
    h.record(WrenchStamped, 'estimated_wrench')
    h.record(DiagnosticArray, '/diagnostics', command_qos())
    node = h.add(WrenchEstimatorNode, robot_config='one_segment_mismatched', rate_hz=50.0,
                 force_rate=0.0)
    pub_p = h.publisher(Float64MultiArray, 'measured_pressure')
    pub_pose = h.client.create_publisher(PoseStamped, 'measured_pose', measured_pose_qos())
    wait_for(lambda: pub_pose.get_subscription_count() >= 1, what='measured_pose matched')
    sim = SimulatedRobot('one_segment_mismatched', seed=7)
    sim.command([30e3, 10e3, 50e3])
    for _ in range(150):
        sim.step(0.01)
    sim.set_tip_force(TRUTH)
    _stream(h, sim, pub_pose, pub_p, 300)
    wait_for(lambda: node.estimator.samples >= 250, what='250 samples folded in')
    e = node.estimator.estimate()
    np.testing.assert_allclose(e.force_n[:2], TRUTH[:2], atol=0.02)
    assert abs(e.force_n[2] - TRUTH[2]) < 0.1
    wait_for(lambda: h.count('estimated_wrench') > 0, what='estimated_wrench')
    w = h.last('estimated_wrench')
    assert w.header.frame_id == 'base'
    assert w.wrench.torque.x == w.wrench.torque.y == w.wrench.torque.z == 0.0
    assert math.isclose(w.wrench.force.x, e.force_n[0], abs_tol=0.02)
    # tare: the reading goes to zero at the current estimate
    res = h.call(h.service(Trigger, f'{h.ns}/wrench_estimator_node/tare'), Trigger.Request())
    assert res.success
    n0 = h.count('estimated_wrench')
    wait_for(lambda: h.count('estimated_wrench') > n0 + 1, what='a reading after the tare')
    w = h.last('estimated_wrench')
    assert abs(w.wrench.force.x) < 1e-3 and abs(w.wrench.force.y) < 1e-3
    # bad samples: refused, counted, WARN; the node goes on
    refused = node.stats['refused']
    pub_pose.publish(target_msg([math.nan, 0.0, 0.1]))
    pub_p.publish(pressure_msg([1e9, 0.0, 0.0]))
    wait_for(lambda: node.stats['refused'] >= refused + 2, what='two refusals')
    wait_for(lambda: any(s.level == DiagnosticStatus.WARN
                         for s in diag_statuses(h, 'wrench_estimator_node: samples')),
             what='WARN diagnostics')
    samples = node.estimator.samples
    _stream(h, sim, pub_pose, pub_p, 20)
    wait_for(lambda: node.estimator.samples > samples, what='samples after the bad ones')
