"""simulated_robot_node as the clock: /clock, simulation-time stamps, pause, step, reset, lockstep.

Real rclpy nodes in one process on an isolated ROS_DOMAIN_ID (the harness of
test_ros_nodes); the simulated robot steps in its own thread.
"""

import sys
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bellow_ancf_ros.core import solve_forward  # noqa: E402
from bellow_ancf_ros.core.sim import CATCH_UP  # noqa: E402
from bellow_ancf_ros.nodes.forward_kinetostatic_node import ForwardKinetostaticNode  # noqa: E402
from bellow_ancf_ros.nodes.inverse_kinetostatic_node import InverseKinetostaticNode  # noqa: E402
from bellow_ancf_ros.nodes.simulated_robot_node import SimulatedRobotNode  # noqa: E402
from bellow_ancf_ros.nodes.trajectory_publisher import TrajectoryPublisher  # noqa: E402
import test_ros_nodes as _rn  # noqa: E402
from test_ros_nodes import pressure_msg, target_msg, wait_for  # noqa: E402

pytestmark = pytest.mark.ros
h = _rn.h
RATE_HZ = 200.0   # a physics step of exactly 5 ms
LATENCY_S = 0.01
DEEP = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                  depth=10000)


def seconds(stamp):
    return stamp.sec + 1e-9 * stamp.nanosec


def ns(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def clock_sim(h, **params):
    """A simulated robot that is the clock (200 Hz physics, 120 Hz mocap, 10 ms latency)."""
    for topic, kind in (('/clock', Clock), ('measured_pose', PoseStamped),
                        ('true_pose', PoseStamped), ('/diagnostics', DiagnosticArray),
                        ('measured_pressure', Float64MultiArray)):
        h.record(kind, topic, DEEP)   # every message: none dropped by a busy test process
    params = dict(dict(publish_clock=True, physics_rate_hz=RATE_HZ, seed=5,
                       mocap_latency_s=LATENCY_S, mocap_dropout_every_s=0.0,
                       mocap_outlier_probability=0.0), **params)
    sim = h.add(SimulatedRobotNode, **params)
    sim.set_parameters([Parameter('use_sim_time', value=True)])
    return sim


def last_clock(h):
    return seconds(h.last('/clock').clock)


def test_it_publishes_the_clock_and_stamps_everything_in_simulation_time(h):
    sim = clock_sim(h, real_time_factor=2.0)
    wait_for(lambda: h.count('/clock') > 10, what='/clock')
    t0_wall, t0_sim = time.monotonic(), last_clock(h)
    time.sleep(2.0)
    factor = (last_clock(h) - t0_sim) / (time.monotonic() - t0_wall)
    assert 1.0 < factor < 2.25, factor   # paced at 2x (a delay caught up; slower when busy)
    # the node's own /diagnostics run on the clock it publishes (use_sim_time)
    wait_for(lambda: any(s.name.endswith('simulated robot') for _, a in h.msgs['/diagnostics']
                         for s in a.status), what='a status')
    with h.lock:   # (taken while it runs: a status after the pause below says paused)
        statuses = [(seconds(a.header.stamp), s) for _, a in h.msgs['/diagnostics']
                    for s in a.status if s.name.endswith('simulated robot')]
    # paused, so that no pose or clock arrives between the snapshots below (on a busy
    # machine the statements between them can take longer than a physics step)
    h.call(h.service(Trigger, 'simulated_robot_node/pause'), Trigger.Request())
    time.sleep(0.3)   # what was in flight arrives
    clocks = [ns(m.clock) for _, m in h.msgs['/clock']]
    # every step exactly 5 ms of simulation time, in order, from 0
    assert clocks[0] % 5_000_000 == 0 and np.all(np.diff(clocks) == 5_000_000)
    end = clocks[-1]
    # the motion capture delivers at exact multiples of 1/120 s, captured one latency earlier
    true = np.array([seconds(m.header.stamp) for _, m in h.msgs['true_pose']])
    measured = np.array([seconds(m.header.stamp) for _, m in h.msgs['measured_pose']])
    assert len(true) > 100 and np.all(true * 1e9 <= end + 1)
    np.testing.assert_allclose(true * 120.0, np.round(true * 120.0), atol=1e-6)
    np.testing.assert_allclose(np.diff(true), 1 / 120.0, atol=1e-8)
    np.testing.assert_allclose((measured + LATENCY_S) * 120.0,
                               np.round((measured + LATENCY_S) * 120.0), atol=1e-6)
    stamps = [t for t, _ in statuses]
    assert all(0.0 < s <= last_clock(h) + 1e-9 for s in stamps), (stamps, last_clock(h))
    status = statuses[-1][1]
    values = {kv.key: kv.value for kv in status.values}
    assert values['real_time_factor'] == '2.0' and values['paused'] == 'False'
    # (over the newest second: a delay is caught up at up to CATCH_UP times the factor)
    assert 0.9 < float(values['achieved_real_time_factor']) < 2.0 * CATCH_UP + 0.1
    assert 0 <= sim.stats['published_poses'] - len(h.msgs['measured_pose']) <= 3   # in flight


def test_pause_freezes_the_clock_step_takes_exactly_the_steps_and_reset_vents(h):
    sim = clock_sim(h)
    pressures = h.publisher(Float64MultiArray, 'pressure_command')
    pub_p = np.array([60e3, 0.0, 20e3])
    pressures.publish(pressure_msg(pub_p))
    wait_for(lambda: h.count('measured_pressure') > 0
             and h.last('measured_pressure').data[0] > 30e3, what='the regulators to follow')
    pause = h.service(Trigger, 'simulated_robot_node/pause')
    step = h.service(Trigger, 'simulated_robot_node/step')
    unpause = h.service(Trigger, 'simulated_robot_node/unpause')
    reset = h.service(Trigger, 'simulated_robot_node/reset')
    res = h.call(step, Trigger.Request())
    assert not res.success and 'pause it first' in res.message
    assert h.call(pause, Trigger.Request()).success
    time.sleep(0.2)
    held, poses = ns(h.last('/clock').clock), h.count('measured_pose')
    time.sleep(0.5)
    assert ns(h.last('/clock').clock) == held and h.count('measured_pose') == poses
    assert sim.clock.time_s * 1e9 == pytest.approx(held, abs=1)
    sim.set_parameters([Parameter('step_count', value=12)])
    res = h.call(step, Trigger.Request())
    assert res.success, res.message
    wait_for(lambda: ns(h.last('/clock').clock) == held + 12 * 5_000_000, what='12 steps')
    time.sleep(0.3)
    assert ns(h.last('/clock').clock) == held + 12 * 5_000_000   # still paused
    # 60 ms: 7 or 8 motion-capture deliveries, never more
    assert 7 <= h.count('measured_pose') - poses <= 8
    assert h.call(unpause, Trigger.Request()).success
    wait_for(lambda: ns(h.last('/clock').clock) > held + 100 * 5_000_000, what='running again')
    start = sim._new_robot().true_pose()[0]
    res = h.call(reset, Trigger.Request())
    assert res.success and 'vented' in res.message, res.message
    assert sim.stats['resets'] == 1
    np.testing.assert_array_equal(sim.robot.pressures_pa, np.zeros(3))
    np.testing.assert_allclose(sim.robot.true_pose()[0], start, atol=1e-9)
    after = ns(h.last('/clock').clock)
    wait_for(lambda: ns(h.last('/clock').clock) > after, what='the clock runs on after a reset')


def test_lockstep_holds_the_simulation_to_the_newest_command_and_lets_go_of_a_dead_one(h):
    sim = clock_sim(h, real_time_factor=0.0, lockstep=True, lockstep_period_s=0.1,
                    lockstep_timeout_s=1.0)
    wait_for(lambda: h.count('/clock') > 0 and last_clock(h) > 2.0,
             what='running free before any command')
    pressures = h.publisher(Float64MultiArray, 'pressure_command')
    pressures.publish(pressure_msg(np.zeros(3)))
    wait_for(lambda: sim.clock.lockstep_waits >= 1, what='a wait for the next command')
    time.sleep(0.3)
    held = last_clock(h)
    time.sleep(0.3)
    assert last_clock(h) == held   # one period past the command, no further
    for _ in range(5):   # a slow controller: a command every 0.25 wall seconds
        pressures.publish(pressure_msg(np.zeros(3)))
        time.sleep(0.25)
    advanced = last_clock(h) - held
    assert 0.4 <= advanced <= 0.6 + 1e-9, advanced   # 0.1 s of simulation per command
    assert sim.clock.lockstep_timeouts == 0
    wait_for(lambda: sim.clock.lockstep_timeouts == 1, timeout=5.0,
             what='the lockstep to give up on a controller that stopped')
    wait_for(lambda: last_clock(h) > held + advanced + 2.0, what='running free again')


def test_a_reporting_controller_holds_the_simulation_step_by_step(h, one):
    """The inverse node on simulation time reports its work done; the lockstep follows it."""
    sim = clock_sim(h, real_time_factor=0.0, lockstep=True)
    node = h.add(InverseKinetostaticNode, feedback='integral', command_rate_hz=20.0,
                 use_sim_time=True)
    pub = h.publisher(PoseStamped, 'target_pose')
    wait_for(lambda: sim._sub.get_publisher_count() >= 1, what='inverse -> robot')
    pub.publish(target_msg(solve_forward(one, [70e3, 10e3, -30e3]).position))
    wait_for(lambda: sim.clock.done_s is not None, what="the controller's first report")
    assert sim.clock.participants == [node.get_fully_qualified_name()]
    # (before its first report the simulation ran on its own: that lead is caught up first)
    wait_for(lambda: sim.clock.time_s - sim.clock.done_s <= 1.0 / RATE_HZ + 1e-9,
             what='the controller caught up')
    ahead = []
    t_end = time.monotonic() + 3.0
    while time.monotonic() < t_end:
        with sim.clock._cond:   # the time reached against the newest report, at one instant
            ahead.append(sim.clock.time_s - sim.clock.done_s)
        time.sleep(0.003)
    # never more than one physics step beyond what the controller has done
    assert max(ahead) <= 1.0 / RATE_HZ + 1e-9, max(ahead)
    assert sim.clock.time_s > 1.0 and sim.clock.lockstep_timeouts == 0
    assert node.stats['published'] > 10


def test_the_trajectory_publisher_holds_the_simulation_to_its_ticks_and_leaves_when_gone(h, one):
    """As fast as the controller allows, no 50 Hz target is skipped; one that stops leaves.

    And every target reaches the inverse node at the simulated time it was
    published (the messages owed: the simulation waits for it however long
    delivery takes), every command reaches the simulated robot.
    """
    sim = clock_sim(h, real_time_factor=0.0, lockstep=True)
    targets = h.record(PoseStamped, 'target_pose', DEEP)
    node = h.add(InverseKinetostaticNode, feedback='integral', command_rate_hz=20.0,
                 use_sim_time=True)
    late, take = [], node._take_target

    def timed(msg):   # the clock the node sees when it takes a target, against its stamp
        late.append(node.get_clock().now().nanoseconds * 1e-9 - seconds(msg.header.stamp))
        take(msg)
    node._take_target = timed
    traj = h.add(TrajectoryPublisher, trajectory='planar_circle', rate_hz=50.0, period_s=2.0,
                 start_delay_s=0.0, ramp_in_s=0.0, controller_node='', use_sim_time=True)
    wait_for(lambda: len(sim.clock.participants) == 2, what='both reports')
    assert sim.clock.participants == sorted([node.get_fully_qualified_name(),
                                             traj.get_fully_qualified_name()])
    wait_for(lambda: h.count('target_pose') > 0, timeout=30.0, what='the first target')
    first = seconds(targets[0][1].header.stamp)
    wait_for(lambda: seconds(h.last('target_pose').header.stamp) > first + 2.0, timeout=30.0,
             what='2 s of targets recorded')
    with h.lock:
        stamps = np.array([seconds(m.header.stamp) for _, m in targets])
    gaps = np.diff(stamps[1:])   # (the first tick comes when the timer was created)
    # a tick comes at most one physics step after it is due: never skipped, never doubled
    assert gaps.size > 90 and gaps.max() <= 0.02 + 1.0 / RATE_HZ + 1e-6, gaps.max()
    assert gaps.min() >= 0.02 - 1.0 / RATE_HZ - 1e-6, gaps.min()
    assert len(late) > 90 and max(np.abs(late)) <= 1.0 / RATE_HZ + 1e-6, max(np.abs(late))
    cmd, target = node._pub_cmd.topic_name, traj._pub.topic_name
    me = node.get_fully_qualified_name()

    def balanced():   # what was sent on each topic was received (the newest may be in flight)
        sent, received = sim.clock.ledger()
        return (received[''][cmd] >= sent[cmd] >= node.stats['published']
                and received[me][target] >= sent[target] >= len(stamps))
    wait_for(balanced, what='the messages counted sent and received')
    h.executor.remove_node(traj)
    h.nodes.remove(traj)
    traj.destroy_node()
    wait_for(lambda: sim.clock.participants == [node.get_fully_qualified_name()],
             what='the publisher leaving')
    t_left = sim.clock.time_s
    wait_for(lambda: sim.clock.time_s > t_left + 1.0, timeout=20.0, what='1 s more')
    assert sim.clock.lockstep_timeouts == 0


def test_a_demo_hold_stops_the_simulation_at_its_time_until_the_demo_acts(h, one):
    """``TargetSender.hold(t)``: the robot waits at ``t``; a target sent then is taken at ``t``.

    (A report of ``t`` itself let the robot step past ``t`` before the
    demo's target reached the inverse node: make demo's ZVD-shaped step went
    out one physics step late in about one run in seven.)
    """
    from rclpy.node import Node

    from bellow_ancf_ros.demos.pipeline import TargetSender
    sim = clock_sim(h, real_time_factor=0.0, lockstep=True)
    node = h.add(InverseKinetostaticNode, use_sim_time=True)
    taken, take = [], node._take_target

    def timed(msg):
        taken.append(node.get_clock().now().nanoseconds * 1e-9)
        take(msg)
    node._take_target = timed
    wait_for(lambda: sim.clock.participants == [node.get_fully_qualified_name()],
             what="the inverse node's report")
    sim.clock.pause()
    t_hold = sim.clock.time_s + 0.5
    sender = TargetSender(h.add(Node, name='demo_sender', use_sim_time=True))
    sender.hold(t_hold)
    wait_for(lambda: len(sim.clock.participants) == 2, what="the sender's report")
    sim.clock.unpause()
    wait_for(lambda: sim.clock.time_s >= t_hold - 1e-9, what='the hold reached')
    time.sleep(0.3)   # the demo acts late: the robot waits
    assert sim.clock.time_s == pytest.approx(t_hold, abs=1e-9)
    wait_for(sender.inverse_matched, what='the inverse node matched')
    fw = solve_forward(one, [20e3, 0.0, 0.0])
    sender.send(target_msg(fw.position))
    sender.hold(None)
    wait_for(lambda: taken and sim.clock.time_s > t_hold + 0.1, what='the target taken')
    assert taken[0] == pytest.approx(t_hold, abs=1e-9)
    sender.close()


def test_the_forward_node_holds_the_simulation_until_it_predicted_from_each_pressure(h):
    """A forward node slowed to 30 ms a prediction (a busy computer) still predicts them all.

    Without the lockstep, the simulation (as fast as it can) would send
    pressures far faster than it predicts, and its one-item slot would drop
    most of them; with it, each prediction goes out at its simulated time.
    """
    sim = clock_sim(h, real_time_factor=0.0, lockstep=True)
    predicted = h.record(PoseStamped, 'predicted_pose', DEEP)
    fwd = h.add(ForwardKinetostaticNode, use_sim_time=True, max_rate_hz=1000.0,
                remap={'pressure_command': 'measured_pressure'})
    me = fwd.get_fully_qualified_name()
    wait_for(lambda: sim.clock.participants == [me], what="the forward node's report")
    solve = fwd._worker._process

    def slow(p):
        time.sleep(0.03)
        solve(p)
    fwd._worker._process = slow   # (once it is in: a node slower than the stream joins no
    dropped = fwd._worker.dropped  # simulation that runs free as fast as it can)
    first = h.count('predicted_pose') + 2
    wait_for(lambda: h.count('predicted_pose') >= first + 40, timeout=30.0,
             what='40 predictions')
    t0, n0 = sim.clock.time_s, fwd._worker.submitted
    time.sleep(1.5)
    with sim.clock._cond:
        t1, n1 = sim.clock.time_s, fwd._worker.submitted
    # the simulation ran at the forward node's pace: one pressure (every 10 ms) per prediction
    assert 20 <= n1 - n0 <= 1.5 / 0.03 + 2, n1 - n0
    assert abs((t1 - t0) - 0.01 * (n1 - n0)) <= 0.02, (t1 - t0, n1 - n0)
    assert fwd._worker.dropped - dropped <= 1 and sim.clock.lockstep_timeouts == 0
    with h.lock:
        stamps = np.array([seconds(m.header.stamp) for _, m in predicted[first:]])
    gaps = np.diff(stamps)
    assert gaps.size > 30 and 0.005 - 1e-6 <= gaps.min() and gaps.max() <= 0.015 + 1e-6, gaps
    sent, received = sim.clock.ledger()
    assert received[me][fwd._sub.topic_name] >= sent[fwd._sub.topic_name] - 1
    h.executor.remove_node(fwd)
    h.nodes.remove(fwd)
    fwd.destroy_node()
    wait_for(lambda: sim.clock.participants == [], what='the forward node leaving')
    t_left = sim.clock.time_s
    wait_for(lambda: sim.clock.time_s > t_left + 1.0, timeout=20.0, what='1 s more')
    assert sim.clock.lockstep_timeouts == 0


def test_the_forward_nodes_rate_counts_simulation_time_and_holds_nothing_back(h):
    """``max_rate_hz`` 20 on simulation time: 0.05 s apart, the simulation not held to it.

    A rate kept on the wall clock held the simulation while a pressure waited
    for its credit: ``make demo``'s forward nodes at 5 Hz ran it at 0.05x real
    time.
    """
    sim = clock_sim(h, real_time_factor=0.0, lockstep=True)
    predicted = h.record(PoseStamped, 'predicted_pose', DEEP)
    fwd = h.add(ForwardKinetostaticNode, use_sim_time=True, max_rate_hz=20.0,
                remap={'pressure_command': 'measured_pressure'})
    wait_for(lambda: sim.clock.participants == [fwd.get_fully_qualified_name()],
             what="the forward node's report")
    first = h.count('predicted_pose') + 1
    t0, wall0 = sim.clock.time_s, time.monotonic()
    wait_for(lambda: h.count('predicted_pose') >= first + 20, timeout=30.0,
             what='20 predictions')
    # 20 predictions a second of simulation time; held to 20 a second of wall time it ran at
    # 0.2x real time (a pressure every 10 ms; measured 0.196x); free, at 0.9-2x in this process
    assert sim.clock.time_s - t0 > 0.5 * (time.monotonic() - wall0)
    with h.lock:
        stamps = np.array([seconds(m.header.stamp) for _, m in predicted[first:]])
    gaps = np.diff(stamps)
    assert gaps.min() >= 0.05 - 1.0 / RATE_HZ - 1e-6, gaps
    assert gaps.max() <= 0.06 + 1.0 / RATE_HZ + 1e-6, gaps
    assert sim.clock.lockstep_timeouts == 0


def test_pause_freezes_the_controller_too_no_command_no_dropout_after_it(h, one):
    """Paused 1.5 s of wall time (six times the pose timeout): the loop just resumes."""
    sim = clock_sim(h, lockstep=True)
    node = h.add(InverseKinetostaticNode, feedback='integral', command_rate_hz=20.0,
                 use_sim_time=True)
    pub = h.publisher(PoseStamped, 'target_pose')
    wait_for(lambda: sim._sub.get_publisher_count() >= 1, what='inverse -> robot')
    pub.publish(target_msg(solve_forward(one, [70e3, 10e3, -30e3]).position))
    wait_for(lambda: sim.clock.time_s > 2.0, timeout=20.0, what='2 s of simulation')
    pause = h.service(Trigger, 'simulated_robot_node/pause')
    unpause = h.service(Trigger, 'simulated_robot_node/unpause')
    assert h.call(pause, Trigger.Request()).success
    time.sleep(0.3)   # what was in flight
    commands, t_paused = node.stats['published'], sim.clock.time_s
    time.sleep(1.5)
    assert node.stats['published'] == commands   # no keepalive, no re-solve while paused
    assert sim.clock.time_s == t_paused
    assert h.call(unpause, Trigger.Request()).success
    wait_for(lambda: sim.clock.time_s > t_paused + 1.0, timeout=20.0, what='1 s more')
    assert node.stats['published'] > commands
    assert node._feedback.dropouts == 0 and node._feedback.trips() == 0


def test_without_the_clock_its_settings_do_nothing_and_its_services_say_why(h, capfd):
    sim = h.add(SimulatedRobotNode, seed=2, real_time_factor=2.0, lockstep=True)
    assert sim.clock is None
    assert ('real_time_factor = 2.0, lockstep = True ignored: without publish_clock'
            in capfd.readouterr().err)
    res = h.call(h.service(Trigger, 'simulated_robot_node/pause'), Trigger.Request())
    assert not res.success and 'needs publish_clock: true' in res.message
    res = h.call(h.service(Trigger, 'simulated_robot_node/reset'), Trigger.Request())
    assert res.success and sim.stats['resets'] == 1


def test_a_report_says_who_until_when_and_the_messages_counted():
    from std_msgs.msg import Header

    from bellow_ancf_ros.nodes.lockstep import LEAVE_SEC, UNBOUNDED_SEC, report_of
    msg = Header(frame_id='/ns/inverse_kinetostatic_node received:/ns/target_pose=12 '
                          'sent:/ns/pressure_command=30')
    msg.stamp.sec, msg.stamp.nanosec = 3, 500_000_000
    assert report_of(msg) == ('/ns/inverse_kinetostatic_node', 3.5,
                              {'/ns/pressure_command': 30}, {'/ns/target_pose': 12})
    msg = Header(frame_id='/trajectory_publisher')   # a report without counts (older nodes)
    msg.stamp.sec = LEAVE_SEC
    assert report_of(msg) == ('/trajectory_publisher', None, {}, {})
    msg.stamp.sec = UNBOUNDED_SEC   # counts only: holds no time
    assert report_of(msg)[1] == UNBOUNDED_SEC


def test_a_path_that_starts_before_its_delay_starts_at_exactly_that_simulated_time(h, one):
    """Every run of a simulation started paused starts its path alike (the same stamps)."""
    sim = clock_sim(h, real_time_factor=0.0, lockstep=True, start_paused=True)
    targets = h.record(PoseStamped, 'target_pose', DEEP)
    h.add(InverseKinetostaticNode, feedback='none', use_sim_time=True)
    h.add(TrajectoryPublisher, trajectory='planar_circle', rate_hz=50.0, period_s=2.0,
          start_delay_s=0.5, ramp_in_s=0.0, controller_node='', use_sim_time=True)
    time.sleep(1.0)   # every node up and on the clock
    h.call(h.service(Trigger, 'simulated_robot_node/unpause'), Trigger.Request())
    wait_for(lambda: h.count('target_pose') > 20, timeout=30.0, what='20 targets')
    with h.lock:
        stamps = np.array([seconds(m.header.stamp) for _, m in targets])
    # the first at the first physics step at or after 0.5 s, then on the path's 20 ms grid
    assert 0.5 <= stamps[0] < 0.5 + 1.0 / RATE_HZ + 1e-9, stamps[:3]
    grid = 0.5 + 0.02 * np.round((stamps - 0.5) / 0.02)
    assert np.all((stamps >= grid - 1e-9) & (stamps < grid + 1.0 / RATE_HZ)), stamps[:10]
    assert sim.clock.lockstep_timeouts == 0
