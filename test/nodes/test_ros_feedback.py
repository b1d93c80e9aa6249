"""rclpy tests of the closed-loop wiring: simulated_robot_node and the inverse node's feedback.

Same idioms as test_ros_nodes.py (its Harness: isolated random domain,
namespaced nodes, one executor thread, polling with deadlines).
"""

import math
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward  # noqa: E402
from bellow_ancf_ros.nodes.inverse_kinetostatic_node import InverseKinetostaticNode  # noqa: E402
from bellow_ancf_ros.nodes.ros_util import command_qos  # noqa: E402
from bellow_ancf_ros.nodes.simulated_robot_node import SimulatedRobotNode  # noqa: E402
import test_ros_nodes as _rn  # noqa: E402
from test_ros_nodes import (  # noqa: E402
    assert_safe,
    diag_statuses,
    kv,
    pose_of,
    pressure_msg,
    target_msg,
    wait_for,
)

h = _rn.h   # the harness fixture (the isolated ROS context comes from conftest)


def positions(h, topic, n):
    with h.lock:
        return np.array([pose_of(m)[0] for _, m in h.msgs[topic][-n:]])


# ------------------------------------------------------------------ simulated robot node
def test_simulated_robot_node_regulates_measures_and_refuses_bad_input(h, one):
    h.record(PoseStamped, 'measured_pose')
    h.record(Float64MultiArray, 'measured_pressure')
    h.record(DiagnosticArray, '/diagnostics', command_qos())
    node = h.add(SimulatedRobotNode, seed=5, plant='ideal')   # exact equilibria, noise only
    pub = h.publisher(Float64MultiArray, 'pressure_command')
    p = [70e3, 10e3, -30e3]
    pub.publish(pressure_msg(p))
    wait_for(lambda: h.count('measured_pressure') > 0
             and np.allclose(h.last('measured_pressure').data, p, atol=1.0), what='regulated')
    assert h.last('measured_pressure').layout.dim[0].label == 'actuator_pressure_gauge_pa'
    n0 = h.count('measured_pose')
    wait_for(lambda: h.count('measured_pose') >= n0 + 50, what='50 measured poses')
    assert h.last('measured_pose').header.frame_id == 'base'
    own = solve_forward(node.robot.model, p)
    meas = positions(h, 'measured_pose', 40)
    np.testing.assert_allclose(meas.mean(axis=0), own.position, atol=0.15e-3)   # 0.15 mm noise
    assert 0.05e-3 < meas.std(axis=0).mean() < 0.3e-3
    model = solve_forward(one, p)
    assert np.linalg.norm(own.position - model.position) > 1e-3   # not the model

    # bad input: refused, the last set-points stay
    for bad in (pressure_msg([70.0, 10.0, -30.0], label='actuator_pressure_gauge_kpa'),
                pressure_msg([np.nan, 0.0, 0.0]), pressure_msg([0.0, 0.0]),
                pressure_msg([500e3, 0.0, 0.0])):
        pub.publish(bad)
    wait_for(lambda: node.stats['refused'] >= 4, what='4 refusals')
    wait_for(lambda: any(s.level == DiagnosticStatus.WARN and 'refused' in s.message
                         for s in diag_statuses(h, 'simulated robot')), what='WARN diagnostics')
    # its status names the publishers of its commands it has matched: this test's one
    wait_for(lambda: any({kv.key: kv.value for kv in s.values}.get('command_publishers') == '1'
                         for s in diag_statuses(h, 'simulated robot')),
             what='command_publishers 1 in the status')
    n1 = h.count('measured_pressure')
    wait_for(lambda: h.count('measured_pressure') > n1 + 5, what='more measured pressures')
    np.testing.assert_allclose(h.last('measured_pressure').data, p, atol=1.0)

    # a payload set at run time: the robot sinks (its own equilibrium with the load)
    assert not sim_set(node, -1.0), 'negative payload must be refused'
    assert sim_set(node, 0.05)
    loaded = solve_forward(node.robot.model, p, payload_kg=0.05).position
    assert loaded[2] < own.position[2] - 0.2e-3

    def sank():
        n = h.count('measured_pose')
        return n > 40 and np.linalg.norm(
            positions(h, 'measured_pose', 30).mean(axis=0) - loaded) < 0.15e-3
    wait_for(sank, what='measured pose at the loaded equilibrium')

    # a push at run time: the robot yields towards it, as its own model says
    from rclpy.parameter import Parameter
    push = [0.1, 0.0, 0.0]
    for bad in ([math.nan, 0.0, 0.0], [0.0, 0.0], [5000.0, 0.0, 0.0]):
        assert not node.set_parameters([Parameter('tip_force_n', value=bad)])[0].successful
    assert node.set_parameters([Parameter('tip_force_n', value=push)])[0].successful
    pushed = solve_forward(node.robot.model, p, payload_kg=0.05, tip_force_n=push).position
    assert pushed[0] > loaded[0] + 0.3e-3

    def yielded():
        return np.linalg.norm(positions(h, 'measured_pose', 30).mean(axis=0) - pushed) < 0.15e-3
    wait_for(yielded, what='measured pose at the pushed equilibrium')


def test_realistic_robot_node_stamps_capture_times_drops_and_corrupts_poses(h):
    """Latency in the stamps, true_pose beside measured_pose, dropouts and outliers seeded."""
    h.record(PoseStamped, 'measured_pose')
    h.record(PoseStamped, 'true_pose')
    node = h.add(SimulatedRobotNode, seed=3, mocap_latency_s=0.05, mocap_dropout_every_s=1.0,
                 mocap_dropout_duration_s=0.3, mocap_outlier_probability=0.2,
                 position_noise_mm=0.0, angle_noise_deg=0.0)
    wait_for(lambda: h.count('true_pose') >= 400, timeout=20.0, what='400 true poses')
    assert node.robot.effects.mocap_latency_s == 0.05
    st = dict(node.stats)
    # 30 % of the time in a dropout: the true pose keeps coming, the measured one does not
    assert 0.2 < st['dropped_poses'] / (st['dropped_poses'] + st['published_poses']) < 0.4
    assert 0.1 < st['outliers'] / st['published_poses'] < 0.3
    with h.lock:
        meas = list(h.msgs['measured_pose'])
        true = list(h.msgs['true_pose'])
    # the robot stands still (vented): a clean sample equals the true pose, an outlier is 10-30 mm
    p_true = pose_of(true[-1][1])[0]
    off = np.array([np.linalg.norm(pose_of(m)[0] - p_true) for _, m in meas])
    assert np.all((off < 1e-9) | ((off > 9.9e-3) & (off < 30.1e-3)))
    # stamps: captured 50 ms before the sample was published (the true pose's stamp: now)

    def stamp(m):
        return m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
    clock = np.median([stamp(m) - t for t, m in true])    # ROS time - arrival (monotonic)
    lag = np.median([t + clock - stamp(m) for t, m in meas])
    assert 0.045 < lag < 0.06, lag


def test_bad_plant_parameters_name_the_key(h):
    from bellow_ancf_ros.nodes.ros_util import StartupParameterError
    with pytest.raises(StartupParameterError, match="parameter plant = 'kind'"):
        h.add(SimulatedRobotNode, plant='kind')
    with pytest.raises(StartupParameterError,
                       match=r'parameter mocap_dropout_duration_s = 20.0 .*'
                             r'shorter than mocap_dropout_every_s'):
        h.add(SimulatedRobotNode, mocap_dropout_duration_s=20.0)


def sim_set(node, payload):
    """Set the simulated robot's payload_kg through rclpy; True if accepted."""
    from rclpy.parameter import Parameter
    return node.set_parameters([Parameter('payload_kg', value=payload)])[0].successful


# ------------------------------------------------------------------ inverse feedback
def test_feedback_none_is_feedforward_without_measured_pose_subscription(h, one):
    node = h.add(InverseKinetostaticNode)
    assert node.get_parameter('feedback').value == 'none'
    assert not node._feedback.enabled
    pub = h.client.create_publisher(PoseStamped, 'measured_pose', command_qos())
    assert pub.get_subscription_count() == 0


def test_bad_feedback_parameter_refused(h):
    with pytest.raises(ValueError, match="parameter feedback = 'pid' is not allowed"):
        h.add(InverseKinetostaticNode, feedback='pid')


@pytest.mark.parametrize('clock', ['wall', 'simulation'])
def test_closed_loop_in_process_reaches_held_target(h, one, clock):
    """Inverse (feedback integral) -> simulated mismatched robot -> measured_pose -> inverse.

    On the wall clock, and on the simulated robot's clock in lockstep (both
    nodes with ``use_sim_time``, as ``sim:=true`` launches them).
    """
    sim_time = {} if clock == 'wall' else {'use_sim_time': True}
    h.record(Float64MultiArray, 'pressure_command')
    h.record(PoseStamped, 'true_pose')
    h.record(DiagnosticArray, '/diagnostics', command_qos())
    # the realistic robot (lag, dead time, hysteresis, creep, latency, outliers), no dropout
    # in this short run (a dropout's WARN is tested below)
    sim = h.add(SimulatedRobotNode, seed=9, mocap_dropout_every_s=0.0,
                mocap_dropout_duration_s=0.0, **sim_time,
                **({} if clock == 'wall' else {'publish_clock': True, 'lockstep': True}))
    # (lockstep: the keepalive is what a held target's simulation runs on)
    node = h.add(InverseKinetostaticNode, feedback='integral', **sim_time,
                 **({} if clock == 'wall' else {'command_rate_hz': 20.0}))
    assert node._feedback.enabled
    pub = h.publisher(PoseStamped, 'target_pose')
    wait_for(lambda: sim._sub.get_publisher_count() >= 1, what='inverse -> robot')
    target = solve_forward(one, [70e3, 10e3, -30e3]).position
    pub.publish(target_msg(target))   # once: the node keeps correcting the held target

    def converged():
        if h.count('true_pose') < 60:
            return False
        return np.linalg.norm(positions(h, 'true_pose', 20).mean(axis=0) - target) < 0.3e-3

    wait_for(converged, timeout=30.0, what='true pose within 0.3 mm of the target')

    def integrating():
        st = [s for s in diag_statuses(h, 'inverse') if kv(s).get('feedback') == 'integral'][-1]
        return (kv(st)['feedback_state'] == 'integrating' and st.level == DiagnosticStatus.OK
                and kv(st)['mocap_noise_mm'] != 'unknown')

    # a re-solve that used up its wall-clock budget on a loaded machine reports 'holding'
    # until the next one converges (honest: its answer was the best so far, not a solution);
    # the noise is read from 30 evenly spaced samples, which a loaded machine's simulated
    # robot (its capture times on the wall clock) took longer to give than the loop took to
    # converge: 'unknown' in one CI run
    wait_for(integrating, timeout=10.0,
             what="diagnostics: feedback 'integrating', OK, the motion capture's noise known")
    st = [s for s in diag_statuses(h, 'inverse') if kv(s).get('feedback') == 'integral'][-1]
    # feedforward alone leaves the mismatched robot 2.5 mm off this target; the loop
    # got within 0.3 mm, so it learned a correction (its size varies from run to run,
    # 0.3 to 2 mm: see the closed-loop core tests for the converged value)
    mis = RobotModel(load_robot('one_segment_mismatched'), 12)
    ff_error = np.linalg.norm(solve_forward(mis, [70e3, 10e3, -30e3]).position - target)
    assert ff_error > 1e-3
    assert float(kv(st)['feedback_correction_mm']) > 0.1
    # the motion capture's noise read from the samples (the robot's 0.15 mm, 120 Hz): a cap
    # about the one-segment automatic gain (5.67 /s against 5.674 in a fresh clone's
    # wall-clock run); the gain in use is never above the margins' safe gain, and at least
    # the lower of the two unless the watchdog cut it
    assert 0.1 < float(kv(st)['mocap_noise_mm']) < 0.2
    cap, safe = float(kv(st)['noise_gain_cap_per_s']), float(kv(st)['loop_safe_gain_per_s'])
    gain = float(kv(st)['feedback_gain_per_s'])
    assert cap > 3.0 and gain <= 1.001 * safe
    assert gain >= 0.999 * min(cap, safe) or int(kv(st)['oscillation_trips']) > 0
    cfg = load_robot('one_segment')
    with h.lock:
        for _, m in h.msgs['pressure_command']:
            assert_safe(m.data, cfg)
    if clock == 'simulation':   # the loop's stamps are the simulation's; the clock ran
        # (the held target keeps the simulation running: wait for it to pass 1 s rather
        # than read it at a moment set by how fast the loop converged)
        wait_for(lambda: sim.clock.time_s > 1.0, timeout=10.0, what='simulation time past 1 s')
        stamp = h.last('true_pose').header.stamp
        assert sim.clock.lockstep_timeouts == 0
        assert 0.0 < stamp.sec + 1e-9 * stamp.nanosec <= sim.clock.time_s + 1e-9


def test_the_model_frame_carries_the_correction_to_a_step_target(h, one):
    """``feedback_correction_frame: model``: a jump's goal gets the carried correction.

    The node hands the jump's move to the law and the answers of its
    commands; after a held target and a 10 mm step, the transfer ran once
    and the robot reaches the new target.
    """
    h.record(Float64MultiArray, 'pressure_command')
    h.record(PoseStamped, 'true_pose')
    h.add(SimulatedRobotNode, seed=9, mocap_dropout_every_s=0.0, mocap_dropout_duration_s=0.0)
    node = h.add(InverseKinetostaticNode, feedback='integral',
                 feedback_correction_frame='model')
    law = node._feedback._law
    assert law.transfer is not None and law.transfer.model is node._model
    pub = h.publisher(PoseStamped, 'target_pose')
    held = solve_forward(one, [70e3, 10e3, -30e3]).position
    goal = held + np.array([0.0, 0.01, 0.0])

    def near(target, n=20):
        def check():
            return (h.count('true_pose') >= 60 and np.linalg.norm(
                positions(h, 'true_pose', n).mean(axis=0) - target) < 0.3e-3)
        return check

    pub.publish(target_msg(held))
    wait_for(lambda: near(held)() and np.linalg.norm(law.correction_m) > 0.2e-3, timeout=30.0,
             what='a correction learned, the true pose within 0.3 mm of the held target')
    assert law.transfer.transfers == 0   # (the first target's move: nothing learned to carry)
    pub.publish(target_msg(goal))
    wait_for(lambda: law.transfer.transfers + law.transfer.refused >= 1, timeout=10.0,
             what='the correction carried to the step target')
    assert law.transfer.transfers == 1 and law.transfer.refused == 0
    wait_for(near(goal), timeout=30.0, what='true pose within 0.3 mm of the step target')
    cfg = load_robot('one_segment')
    with h.lock:
        for _, m in h.msgs['pressure_command']:
            assert_safe(m.data, cfg)


def test_feedback_refuses_bad_poses_ignores_outliers_and_holds_through_a_dropout(h, one):
    h.record(Float64MultiArray, 'pressure_command')
    h.record(PoseStamped, 'commanded_pose')
    h.record(DiagnosticArray, '/diagnostics', command_qos())
    node = h.add(InverseKinetostaticNode, feedback='integral', measured_pose_timeout_s=0.3)
    pub = h.publisher(PoseStamped, 'target_pose')
    meas = h.publisher(PoseStamped, 'measured_pose')
    target = solve_forward(one, [70e3, 10e3, -30e3]).position
    pub.publish(target_msg(target))
    wait_for(lambda: any(s.level == DiagnosticStatus.WARN and 'waiting for measured_pose'
                         in s.message for s in diag_statuses(h, 'inverse')),
             what='WARN: waiting for measured poses')
    # wrong frame, NaN, zero quaternion (one segment: orientation unused, so only frame/NaN)
    meas.publish(target_msg(target, frame='world'))
    meas.publish(target_msg([np.nan, 0.0, 0.1]))
    wait_for(lambda: node._feedback.refused >= 2, what='2 refused measured poses')
    wait_for(lambda: any('measured poses refused' in s.message and 'world' in s.message
                         for s in diag_statuses(h, 'inverse')), what='refusal diagnostics')
    # a robot 2 mm off in +x: the correction moves the handed target to -x
    offset = np.array([2e-3, 0.0, 0.0])

    def feed_and_check():
        meas.publish(target_msg(target + offset))
        if h.count('commanded_pose') == 0:
            return False
        shift = pose_of(h.last('commanded_pose'))[0] - target
        return shift[0] < -0.5e-3

    wait_for(feed_and_check, timeout=10.0, what='correction against the offset')
    # an outlier (25 mm off): never integrated, counted
    meas.publish(target_msg(target + offset + np.array([0.0, 0.025, 0.0])))
    wait_for(lambda: node._feedback.status()['measured_poses_outliers'] >= 1, what='outlier')
    # measurements stop (a dropout): WARN, the correction is held and still applied
    wait_for(lambda: any(s.level == DiagnosticStatus.WARN and 'too old' in s.message
                         for s in diag_statuses(h, 'inverse')), what='dropout WARN')
    held = pose_of(h.last('commanded_pose'))[0] - target
    assert held[0] < -0.5e-3 and abs(held[1]) < 0.2e-3   # the outlier moved nothing sideways
    time.sleep(0.3)
    np.testing.assert_allclose(pose_of(h.last('commanded_pose'))[0] - target, held, atol=1e-9)
    st = diag_statuses(h, 'inverse')[-1]
    assert float(kv(st)['feedback_correction_mm']) > 0.5   # frozen, not reset
    cfg = load_robot('one_segment')
    with h.lock:
        for _, m in h.msgs['pressure_command']:
            assert_safe(m.data, cfg)


def test_designed_dropouts_are_info_and_counted_a_long_one_is_a_warn(h, one, capfd):
    """A marker occlusion (0.5 s, every 15 s on the realistic robot) is no warning.

    Short dropouts: INFO at their start and end, counted on /diagnostics
    (feedback_dropouts); a dropout longer than DROPOUT_WARN_S: one WARN.
    """
    from bellow_ancf_ros.nodes.measured_feedback import DROPOUT_WARN_S
    h.record(DiagnosticArray, '/diagnostics', command_qos())
    node = h.add(InverseKinetostaticNode, feedback='integral', measured_pose_timeout_s=0.25,
                 feedback_rate_hz=50.0)
    pub = h.publisher(PoseStamped, 'target_pose')
    meas = h.publisher(PoseStamped, 'measured_pose')
    target = solve_forward(one, [70e3, 10e3, -30e3]).position
    pub.publish(target_msg(target))

    def feed(seconds):
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            meas.publish(target_msg(target))
            time.sleep(0.01)

    feed(1.0)
    for _ in range(2):   # two designed dropouts of 0.6 s
        time.sleep(0.6)
        feed(0.8)
    wait_for(lambda: node._feedback.dropouts >= 2, what='two dropouts counted')
    assert node._feedback.longest_dropout_s < DROPOUT_WARN_S
    out = capfd.readouterr().err
    assert out.count('integrator frozen, correction held') >= 2, out
    assert 'measured poses back after' in out, out
    assert not [line for line in out.splitlines()   # (a loaded machine may WARN of a budget)
                if line.startswith(('[WARN]', '[ERROR]')) and 'feedback' in line], out
    # (a loaded machine may stall this feeder past the 0.25 s timeout: a further short dropout)
    wait_for(lambda: any(int(kv(s).get('feedback_dropouts', 0)) >= 2
                         for s in diag_statuses(h, 'inverse_kinetostatic_node: status')),
             what='the count on /diagnostics')
    # a dropout far longer than designed: one WARN, naming how long
    time.sleep(DROPOUT_WARN_S + 1.0)
    feed(0.5)
    out = capfd.readouterr().err
    warns = [line for line in out.splitlines() if line.startswith('[WARN]')]
    assert len([w for w in warns if 'no fresh measured pose for' in w]) == 1, out
    assert all('feedback' not in w or 'no fresh measured pose for' in w for w in warns), out


def test_two_segment_measured_pose_with_zero_quaternion_refused(h, two):
    node = h.add(InverseKinetostaticNode, robot_config='two_segment', feedback='integral')
    meas = h.publisher(PoseStamped, 'measured_pose')
    fw = solve_forward(two, [0.0] * 6)
    meas.publish(target_msg(fw.position, quat=(0.0, 0.0, 0.0, 0.0)))
    wait_for(lambda: node._feedback.refused >= 1, what='refused zero quaternion')
    assert node._feedback.status()['measured_pose_age_s'] == 'none'   # never reached the law


def test_closed_loop_vents_on_deactivate_and_stays_vented(h, one):
    """With feedback on, the re-solve timer must not undo the vent; re-activation waits."""
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    h.record(Float64MultiArray, 'pressure_command')
    # the ideal robot: its poses come at a steady 100 Hz (no dropout), this test's clock
    sim = h.add(SimulatedRobotNode, seed=4, plant='ideal')
    node = h.add(InverseKinetostaticNode, feedback='integral')
    pub = h.publisher(PoseStamped, 'target_pose')
    wait_for(lambda: sim._sub.get_publisher_count() >= 1, what='inverse -> robot')
    target = solve_forward(one, [40e3, 40e3, 90e3]).position
    pub.publish(target_msg(target))
    wait_for(lambda: node.stats['published'] >= 10, what='closed-loop commands')
    change = h.service(ChangeState, f'{h.ns}/inverse_kinetostatic_node/change_state')
    req = ChangeState.Request()
    req.transition.id = Transition.TRANSITION_DEACTIVATE
    n_before = h.count('pressure_command')
    assert h.call(change, req).success
    # (a command sent just before the deactivate may arrive first; the vent then ends it)
    wait_for(lambda: h.count('pressure_command') > n_before
             and list(h.last('pressure_command').data) == [0.0, 0.0, 0.0], what='vent')
    time.sleep(0.1)   # anything the node published after its vent would be here by now
    vent_at = h.count('pressure_command')
    assert list(h.last('pressure_command').data) == [0.0, 0.0, 0.0]
    # the re-solve timer keeps running at 20 Hz: let it tick many times, nothing goes out

    def queued():   # (re-solves are queued again, never over a new target)
        return node._worker.submitted + node._worker.resubmitted
    resubmitted = queued()
    wait_for(lambda: queued() >= resubmitted + 6, what='re-solve ticks')
    assert h.count('pressure_command') == vent_at
    req.transition.id = Transition.TRANSITION_ACTIVATE
    assert h.call(change, req).success
    submitted, poses = queued(), sim.stats['published_poses']
    wait_for(lambda: sim.stats['published_poses'] >= poses + 30, what='0.3 s passing')
    assert queued() == submitted   # no re-solve of the old target
    assert h.count('pressure_command') == vent_at


def test_measured_pose_from_a_best_effort_publisher_is_used(h, one):
    """Motion-capture drivers publish best effort: the subscription must match them."""
    from rclpy.qos import qos_profile_sensor_data

    node = h.add(InverseKinetostaticNode, feedback='integral')
    pub = h.client.create_publisher(PoseStamped, 'measured_pose', qos_profile_sensor_data)
    wait_for(lambda: pub.get_subscription_count() >= 1, what='best-effort match')
    target = solve_forward(one, [70e3, 10e3, -30e3]).position
    wait_for(lambda: (pub.publish(target_msg(target)) or True)
             and node._feedback.status()['measured_pose_age_s'] != 'none',
             what='measured pose reaches the law')


# ------------------------------------------------------------------ a payload beyond buckling
def inv_set(node, payload):
    """Set the inverse node's payload_kg through rclpy: (accepted, reason)."""
    from rclpy.parameter import Parameter
    res = node.set_parameters([Parameter('payload_kg', value=payload)])[0]
    return res.successful, res.reason


def test_payload_beyond_buckling_names_the_cause_sends_nothing_and_does_not_wind_up(h, one):
    """payload_kg 1.0 on the one-segment robot (it buckles; 0.7 kg is carried).

    Started with it: every solve reports the unstable equilibrium and the
    payload, nothing is published, the integrator stays
    frozen although measured poses keep coming 2 mm off.  Set at run time:
    refused, naming the payload and the buckling.
    """
    h.record(Float64MultiArray, 'pressure_command')
    h.record(DiagnosticArray, '/diagnostics', command_qos())
    node = h.add(InverseKinetostaticNode, feedback='integral', payload_kg=1.0)
    target_pub = h.publisher(PoseStamped, 'target_pose')
    meas_pub = h.publisher(PoseStamped, 'measured_pose')
    target = solve_forward(one, [50e3, 0.0, 0.0]).position
    wait_for(lambda: node._sub.get_publisher_count() >= 1, what='target publisher matched')
    n_cmd = h.count('pressure_command')
    target_pub.publish(target_msg(target))
    for _ in range(40):    # 2 s of measured poses 2 mm beside the target, as if it had sagged
        meas_pub.publish(target_msg(target + [0.002, 0.0, 0.0]))
        time.sleep(0.05)
    wait_for(lambda: node.stats['failed'] >= 3, what='3 failed solves')
    errors = [s for s in diag_statuses(h, 'inverse') if s.level == DiagnosticStatus.ERROR]
    assert errors and 'unstable' in errors[-1].message and '1 kg' in errors[-1].message, \
        [s.message for s in errors[-3:]]
    # (on a machine loaded four times over its cores the wall-clock budget can run out first:
    # "no usable answer within the solve budget ...: converged to an unstable equilibrium ...
    # payload of 1 kg": still the cause, as asserted above)
    assert h.count('pressure_command') == n_cmd          # nothing went out
    assert np.linalg.norm(node._feedback._law.correction_m) < 0.1e-3   # not wound up
    assert node._feedback._law.state.startswith('frozen')

    ok, _ = inv_set(node, 0.7)            # carried: accepted, and commands go out again
    assert ok
    wait_for(lambda: h.count('pressure_command') > n_cmd, what='a command with 0.7 kg')
    for c in h.msgs['pressure_command'][n_cmd:]:
        assert_safe(np.array(c[1].data), one.cfg)
    ok, reason = inv_set(node, 1.0)       # beyond buckling at the current target: refused
    assert not ok and 'payload_kg 1' in reason and 'buckle' in reason, reason
    assert node.get_parameter('payload_kg').value == pytest.approx(0.7)


# ------------------------------------------------------------------ mocap in its own frame
MOCAP_T = [0.042, -0.027, 0.061]                     # base origin in the mocap frame [m]
MOCAP_ROTVEC = np.radians([4.0, -3.0, 6.0])          # base orientation in the mocap frame


def _mocap_quaternion():
    from scipy.spatial.transform import Rotation
    return Rotation.from_rotvec(MOCAP_ROTVEC).as_quat()


def _robot_file_with_mocap_frame(tmp_path, name='one_segment'):
    """The default robot file plus the mocap_frame entry ``bellow-ancf calibrate`` writes."""
    import yaml
    d = load_robot(name).to_dict()
    d['mocap_frame'] = {'frame_id': 'world', 'position_m': MOCAP_T,
                        'quaternion_xyzw': [float(v) for v in _mocap_quaternion()]}
    path = tmp_path / f'{name}_mocap.yaml'
    path.write_text(yaml.safe_dump(d))
    return str(path)


def _held_target_through_the_mocap_frame(h, one, robot_file):
    """The simulated robot seen by a mocap in 'world', the controller on ``robot_file``.

    Holds a target and waits until the robot's true pose (the mocap poses
    taken back to the base frame with the known transform) is within 0.3 mm
    of it; returns ``(inverse node, target)``.
    """
    from scipy.spatial.transform import Rotation
    h.record(PoseStamped, 'measured_pose')
    sim = h.add(SimulatedRobotNode, seed=9, mocap_frame_id='world', mocap_position_m=MOCAP_T,
                mocap_quaternion_xyzw=[float(v) for v in _mocap_quaternion()])
    node = h.add(InverseKinetostaticNode, feedback='integral', robot_config=robot_file)
    pub = h.publisher(PoseStamped, 'target_pose')
    wait_for(lambda: sim._sub.get_publisher_count() >= 1, what='inverse -> robot')
    wait_for(lambda: h.count('measured_pose') > 5, what='mocap poses')
    assert h.last('measured_pose').header.frame_id == 'world'
    target = solve_forward(one, [70e3, 10e3, -30e3]).position
    pub.publish(target_msg(target))
    R = Rotation.from_rotvec(MOCAP_ROTVEC).as_matrix()

    def converged():
        if h.count('measured_pose') < 60:
            return False
        base = (positions(h, 'measured_pose', 50) - MOCAP_T) @ R   # R^T (p - t), row-wise
        return np.linalg.norm(base.mean(axis=0) - target) < 0.3e-3

    wait_for(converged, timeout=30.0, what='true pose within 0.3 mm of the target')
    assert node._feedback.refused == 0
    return node, target


def test_closed_loop_with_measured_poses_in_the_mocap_frame(h, one, tmp_path):
    """The simulated robot seen by a mocap in 'world'; the robot file knows the transform.

    The loop converges as the base-frame loop does (held target within 0.3 mm,
    judged on the robot's true pose in the base frame); a pose in a frame the
    node does not know is refused, naming the frames it accepts.
    """
    h.record(Float64MultiArray, 'pressure_command')
    h.record(DiagnosticArray, '/diagnostics', command_qos())
    node, target = _held_target_through_the_mocap_frame(
        h, one, _robot_file_with_mocap_frame(tmp_path))
    # integrating (a solve cut by its budget on a loaded machine holds the correction for
    # that one step: the newest status may say so)
    n0 = len(diag_statuses(h, 'inverse'))
    wait_for(lambda: any(kv(s).get('feedback_state') == 'integrating'
                         for s in diag_statuses(h, 'inverse')[n0:]), what='integrating')
    # a pose in a frame the node cannot transform: refused with the accepted frames
    meas = h.publisher(PoseStamped, 'measured_pose', expect_subscribers=1)
    meas.publish(target_msg(target, frame='elsewhere'))
    wait_for(lambda: node._feedback.refused >= 1, what='refused pose in an unknown frame')
    wait_for(lambda: any('elsewhere' in s.message and 'world' in s.message
                         for s in diag_statuses(h, 'inverse')), what='refusal naming the frames')
    cfg = load_robot('one_segment')
    with h.lock:
        for _, m in h.msgs['pressure_command']:
            assert_safe(m.data, cfg)


def test_mocap_relay_republishes_in_the_base_frame(h, tmp_path):
    from bellow_ancf_ros.nodes.mocap_relay import MocapRelay
    from scipy.spatial.transform import Rotation
    h.record(PoseStamped, 'measured_pose')
    relay = h.add(MocapRelay, robot_config=_robot_file_with_mocap_frame(tmp_path))
    pub = h.publisher(PoseStamped, 'mocap_pose')
    R = Rotation.from_rotvec(MOCAP_ROTVEC).as_matrix()
    p_base = np.array([0.005, -0.01, 0.1])
    R_ee = Rotation.from_rotvec([0.1, 0.2, 0.0]).as_matrix()     # end-effector in base
    msg = target_msg(R @ p_base + MOCAP_T, Rotation.from_matrix(R @ R_ee).as_quat(),
                     frame='world')
    msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 345
    pub.publish(msg)
    wait_for(lambda: h.count('measured_pose') >= 1, what='relayed pose')
    out = h.last('measured_pose')
    assert out.header.frame_id == 'base'
    assert (out.header.stamp.sec, out.header.stamp.nanosec) == (12, 345)
    pos, quat = pose_of(out)
    np.testing.assert_allclose(pos, p_base, atol=1e-12)
    np.testing.assert_allclose(Rotation.from_quat(quat).as_matrix(), R_ee, atol=1e-12)
    pub.publish(target_msg(p_base, frame='elsewhere'))
    wait_for(lambda: relay.stats['refused'] >= 1, what='refused unknown frame')


def test_closed_loop_through_the_mocap_frame_bellow_ancf_calibrate_wrote(h, one, tmp_path):
    """Record (simulated, in world), bellow-ancf calibrate, then close the loop with its file.

    The calibrated file's ``mocap_frame`` is the only thing that tells the
    controller where the mocap sees the robot: held target within 0.3 mm.
    """
    from bellow_ancf_ros import cli
    from bellow_ancf_ros.core.fit import excitation_sequence, simulate_recording, write_csv
    plant = load_robot('one_segment_mismatched')
    rec, _, _ = simulate_recording(plant, excitation_sequence(one.cfg, 2, 6, seed=3), MOCAP_T,
                                   MOCAP_ROTVEC, 0.15e-3, np.radians(0.1), seed=4)
    csv_path, robot_file = tmp_path / 'rec.csv', tmp_path / 'calibrated.yaml'
    write_csv(csv_path, rec)
    assert cli.main(['calibrate', '--config', 'one_segment', '--csv', str(csv_path), '--out',
                     str(robot_file), '--json']) == 0
    mf = load_robot(str(robot_file)).mocap_frame
    assert mf.frame_id == 'world'
    np.testing.assert_allclose(mf.position, MOCAP_T, atol=1e-3)

    _held_target_through_the_mocap_frame(h, one, str(robot_file))


def test_loop_margins_with_the_robots_mode_on_diagnostics(h, two):
    """Two segments carrying 50 g: a fixed 2.5 /s is a WARN naming the safe gain; 'auto' is it.

    The automatic gain (the default) is computed at configure for the vented
    robot with its payload, before any command, and stays the safe gain.
    """
    h.record(DiagnosticArray, '/diagnostics', command_qos())
    node = h.add(InverseKinetostaticNode, robot_config='two_segment', feedback='integral',
                 payload_kg=0.05, feedback_gain_per_s=2.5, name='margins_fixed',
                 allow_other_publishers=True)
    auto = h.add(InverseKinetostaticNode, robot_config='two_segment', feedback='integral',
                 payload_kg=0.05, name='margins_auto', allow_other_publishers=True)
    assert auto.get_parameter('feedback_gain_per_s').value == 'auto'
    gain0 = auto._feedback.status()['feedback_gain_per_s']
    assert 0.35 < float(gain0) < 0.45          # set at configure: 50 g, vented
    fw = solve_forward(two, [0.0] * 6, payload_kg=0.05)
    tgt = h.publisher(PoseStamped, 'target_pose')
    wait_for(lambda: tgt.get_subscription_count() >= 2, what='both nodes subscribed')
    tgt.publish(target_msg(fw.position))   # vertical z-axis: the vented pose

    def warned():
        return any(s.level == DiagnosticStatus.WARN and 'loop margins' in s.message
                   and 'safe gain' in s.message for s in diag_statuses(h, 'margins_fixed'))
    wait_for(warned, timeout=30.0, what='a WARN naming the safe gain')
    st = [s for s in diag_statuses(h, 'margins_fixed') if 'loop margins' in s.message][-1]
    values = kv(st)
    assert float(values['loop_gain_margin']) < 1.0
    assert abs(float(values['loop_first_mode_hz']) - 1.454) < 0.002
    assert 0.35 < float(values['loop_safe_gain_per_s']) < 0.45
    assert values['feedback_gain_setting'] == 'fixed'
    assert 'unstable' in node._feedback.margin_warning

    def auto_checked():
        st = [s for s in diag_statuses(h, 'margins_auto') if kv(s).get('loop_margins_ok')]
        return st and kv(st[-1])['loop_margins_ok'] == 'true'
    wait_for(auto_checked, timeout=30.0, what='the automatic gain checked')
    values = kv([s for s in diag_statuses(h, 'margins_auto') if kv(s).get('loop_margins_ok')][-1])
    assert values['feedback_gain_setting'] == 'auto' and values['feedback_gain_per_s'] == gain0
    assert float(values['loop_gain_margin']) >= 2.999
    assert auto._feedback.margin_warning is None


def test_bad_feedback_gain_refused(h):
    for bad in ('fast', 0.0, 80.0):
        with pytest.raises(ValueError, match="parameter feedback_gain_per_s = .* is not allowed"
                           "; allowed: 'auto' or a number from 0.01 to 50"):
            h.add(InverseKinetostaticNode, feedback='integral', feedback_gain_per_s=bad)


def test_a_ringing_loop_trips_the_watchdog_with_one_error(h, one):
    """Measured poses swinging 2 mm at 9 Hz (near the one-segment robot's 10.6 Hz mode)."""
    h.record(DiagnosticArray, '/diagnostics', command_qos())
    node = h.add(InverseKinetostaticNode, feedback='integral', feedback_gain_per_s=2.5,
                 name='ringing')
    fw = solve_forward(one, [40e3, 0.0, 0.0])
    tgt = h.publisher(PoseStamped, 'target_pose')
    meas = h.publisher(PoseStamped, 'measured_pose')
    wait_for(lambda: tgt.get_subscription_count() >= 1 and meas.get_subscription_count() >= 1,
             what='subscribed')
    tgt.publish(target_msg(fw.position))
    wait_for(lambda: node._feedback.status().get('loop_first_mode_hz') is not None,
             timeout=30.0, what='the first mode found')
    t0 = time.monotonic()
    while node._feedback.trips() == 0 and time.monotonic() - t0 < 20.0:
        t = time.monotonic() - t0
        swing = 2e-3 * math.sin(2 * math.pi * 9.0 * t)
        meas.publish(target_msg(fw.position + np.array([swing, 0.0, 0.0])))
        time.sleep(1 / 120)
    assert node._feedback.trips() >= 1
    wait_for(lambda: any(s.level == DiagnosticStatus.ERROR and 'oscillation at' in s.message
                         for s in diag_statuses(h, 'ringing')), what='ERROR on /diagnostics')
    values = node._feedback.status()
    assert values['oscillation_trips'] >= 1 and float(values['feedback_gain_per_s']) <= 1.25
    seen = float(values['oscillation_seen'].split('oscillation at ')[1].split(' Hz')[0])
    assert abs(seen - 9.0) < 0.5   # the frequency it saw
