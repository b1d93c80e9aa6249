"""The nodes under ``use_sim_time``: their windows run on ``/clock``, not on the wall clock.

A fake ``/clock`` (rosgraph_msgs/Clock, published by the test every 2 ms of
wall time) runs the simulation at a chosen factor of the wall clock (0.25x,
4x), stops (a paused simulator publishes nothing) and jumps, forwards and
back.  Real rclpy nodes in one process on an isolated ROS_DOMAIN_ID (the
harness of test_ros_nodes), started with ``use_sim_time: true``: the inverse
node's command keepalive and a shaped step's timed levels, the trajectory
publisher's path and stamps, the regulator driver's command timeout.
Without ``use_sim_time`` the same driver keeps the wall clock whatever
``/clock`` says.  A jump back (a simulation reset, a bag that loops) wedges
none of them (:class:`~bellow_ancf_ros.nodes.ros_util.ControlClock`).
"""

import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.time import Time  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from bellow_ancf_ros.core import solve_forward  # noqa: E402
from bellow_ancf_ros.core.control import shaper_impulses  # noqa: E402
from bellow_ancf_ros.nodes.inverse_kinetostatic_node import InverseKinetostaticNode  # noqa: E402
from bellow_ancf_ros.nodes.regulator_driver import RegulatorDriver  # noqa: E402
from bellow_ancf_ros.nodes.ros_util import ControlClock, spin_until_closed  # noqa: E402
from bellow_ancf_ros.nodes.trajectory_publisher import TrajectoryPublisher  # noqa: E402
import test_ros_nodes as _rn  # noqa: E402
from test_ros_nodes import pose_of, pressure_msg, setup_inverse, target_msg, wait_for  # noqa: E402

pytestmark = pytest.mark.ros
h = _rn.h
DEEP = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                  depth=10000)


def seconds(stamp):
    return stamp.sec + 1e-9 * stamp.nanosec


class FakeClock:
    """``/clock`` from the test: simulation time at ``factor`` times the wall clock's pace."""

    PERIOD_S = 0.002   # wall time between two /clock messages

    def __init__(self, node, start_s: float, factor: float = 1.0) -> None:
        self._pub = node.create_publisher(Clock, '/clock', 10)
        self._lock = threading.Lock()
        self._sim0, self._wall0 = start_s, time.monotonic()
        self._factor, self._running = factor, True
        self._end = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _now(self) -> float:
        if not self._running:
            return self._sim0
        return self._sim0 + self._factor * (time.monotonic() - self._wall0)

    def now(self) -> float:
        """The simulation time now [s] (what the last /clock said, within 2 ms of wall time)."""
        with self._lock:
            return self._now()

    def _set(self, sim=None, factor=None, running=None) -> None:
        with self._lock:
            self._sim0 = self._now() if sim is None else sim
            self._wall0 = time.monotonic()
            self._factor = self._factor if factor is None else factor
            self._running = self._running if running is None else running
            self._publish(self._sim0)

    def run(self, factor: float) -> None:
        """Run on (or again) at ``factor`` simulated seconds per wall second."""
        self._set(factor=factor, running=True)

    def stop(self) -> None:
        """No /clock any more: the simulation pauses."""
        self._set(running=False)

    def jump(self, by_s: float) -> None:
        """Jump by ``by_s`` simulated seconds (one /clock at once, also while stopped)."""
        with self._lock:
            now = self._now()
        self._set(sim=now + by_s)

    def _publish(self, s: float) -> None:
        self._pub.publish(Clock(clock=Time(nanoseconds=round(s * 1e9)).to_msg()))

    def _run(self) -> None:
        while not self._end.wait(self.PERIOD_S):
            with self._lock:
                if self._running:
                    self._publish(self._now())

    def close(self) -> None:
        self._end.set()
        self._thread.join(2.0)


@pytest.fixture
def clock(h):
    clocks = []

    def make(start_s, factor=1.0):
        clocks.append(FakeClock(h.client, start_s, factor))
        return clocks[-1]
    yield make
    for c in clocks:
        c.close()


def add_sim(h, cls, **params):
    return h.add(cls, use_sim_time=True, **params)


class Written:
    """A stand-in regulator: what the driver wrote, with wall and simulation times."""

    def __init__(self, clock=None):
        self.calls, self.clock = [], clock

    def __call__(self, p):
        self.calls.append((time.monotonic(), None if self.clock is None else self.clock.now(),
                           np.array(p, dtype=float)))

    @property
    def vented(self):
        return bool(self.calls) and not np.any(self.calls[-1][2])


# ------------------------------------------------------------ without ROS
class _RosClock:
    def __init__(self):
        self.ros_time_is_active, self.ns = True, 0

    def now(self):
        return SimpleNamespace(nanoseconds=self.ns)


def test_control_clock_stands_still_across_a_jump_back_and_maps_stamps_by_their_age():
    ros = _RosClock()
    clock = ControlClock(SimpleNamespace(get_clock=lambda: ros))
    assert clock.simulated and clock.now() == 0.0        # before any /clock: 0, a time
    ros.ns = 100_000_000_000
    assert clock.now() == 100.0                           # the first /clock: a jump forwards
    ros.ns = 5_000_000_000                                # a reset: back to 5 s
    assert clock.now() == 100.0 and clock.jumps_back == 1
    ros.ns = 5_250_000_000
    assert clock.now() == pytest.approx(100.25)           # runs on from where it stood
    stamp = SimpleNamespace(sec=5, nanosec=0)             # taken 0.25 s ago on the ROS clock
    assert clock.time_of(stamp) == pytest.approx(100.0)
    ahead = SimpleNamespace(sec=6, nanosec=0)              # wanted 0.75 s from now
    assert clock.time_of(ahead) == pytest.approx(100.25)
    assert clock.time_of(ahead, future=True) == pytest.approx(101.0)
    assert clock.time_of(SimpleNamespace(sec=0, nanosec=0)) == pytest.approx(100.25)
    ros.ros_time_is_active = False                        # off simulation time: monotonic
    assert not clock.simulated
    assert ControlClock(None).now() == pytest.approx(time.monotonic(), abs=0.01)


class _WallClock:
    """The ROS clock off simulation time (system time); its first read is kept waiting."""

    ros_time_is_active = False

    def __init__(self, wait_s):
        self.wait_s = wait_s

    def now(self):
        if self.wait_s:   # (a thread kept off the CPU between reading the two clocks)
            time.sleep(self.wait_s)
            self.wait_s = 0.0
        return SimpleNamespace(nanoseconds=time.time_ns())


def test_a_stamp_is_dated_right_when_the_thread_waits_between_the_clocks():
    """A target stamped now is wanted now, though the reads were 30 ms apart.

    Read once each, the stamp came out 30 ms early: a target sent after
    another one could be wanted before it (an unshaped step, core TargetFilter).
    """
    for _ in range(5):   # (the test's own process may be held up too: the best of five)
        wall = _WallClock(0.03)
        clock = ControlClock(SimpleNamespace(get_clock=lambda: wall))
        ns, mono = time.time_ns(), time.monotonic()
        stamp = SimpleNamespace(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
        err = clock.time_of(stamp) - mono
        if abs(err) < 0.005:
            break
    assert abs(err) < 0.005


# ------------------------------------------------------------ the inverse node
def _republished_per_sim_s(node, clock, wall_s):
    n0, s0 = node.stats['republished'], clock.now()
    time.sleep(wall_s)
    n1, s1 = node.stats['republished'], clock.now()
    return (n1 - n0) / (s1 - s0), n1 - n0, s1 - s0


def test_the_command_keepalive_runs_at_its_rate_in_simulation_seconds(h, one, clock):
    sim = clock(500.0, factor=1.0)
    node, pub, _ = setup_inverse(h, command_rate_hz=20.0, use_sim_time=True)
    assert node.get_clock().ros_time_is_active
    pub.publish(target_msg(solve_forward(one, [60e3, 10e3, -20e3]).position))
    wait_for(lambda: node.stats['published'] >= 1, what='the first command')
    wait_for(lambda: node.stats['republished'] >= 3, what='the keepalive')
    found = {}
    sim.run(0.25)
    time.sleep(0.3)
    found['0.25x'] = _republished_per_sim_s(node, sim, 4.0)    # 1 simulated second
    sim.run(4.0)
    time.sleep(0.2)
    found['4x'] = _republished_per_sim_s(node, sim, 1.0)       # 4 simulated seconds
    sim.stop()
    time.sleep(0.3)
    n0 = node.stats['republished']
    time.sleep(1.2)
    found['stopped'] = node.stats['republished'] - n0
    sim.jump(5.0)                                              # and stays stopped
    time.sleep(0.5)
    found['jumped'] = node.stats['republished'] - n0
    sim.jump(-30.0)                                            # a reset: back, then on at 4x
    sim.run(4.0)
    time.sleep(0.3)
    found['after a jump back'] = _republished_per_sim_s(node, sim, 1.0)
    print(found)
    for case in ('0.25x', '4x', 'after a jump back'):
        rate, n, span = found[case]
        assert 15.0 <= rate <= 22.0, (case, found)             # 20 per simulated second
    assert found['stopped'] == 0, found                       # no /clock: no keepalive
    assert 1 <= found['jumped'] <= 2, found                   # one, not a catch-up burst
    assert node.stats['published'] == 1                       # the target was solved once


def test_a_watched_timers_call_holds_the_reports_until_its_callback_returned(h, clock):
    """A timer's call comes before its callback runs (rcl): no report slips in between.

    The timer's callback blocks on its own thread (a reentrant group) while
    the lockstep's 5 ms retries run beside it: no report of the tick it is due
    by until it returns (before: the timer looked not due, the node idle).
    """
    import rclpy
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.parameter import Parameter
    from std_msgs.msg import Header
    from bellow_ancf_ros.nodes import lockstep
    node = rclpy.create_node('watched', namespace=h.ns, context=h.ctx,
                             parameter_overrides=[Parameter('use_sim_time', value=True)])
    ex = MultiThreadedExecutor(num_threads=3, context=h.ctx)
    ex.add_node(node)
    done = threading.Event()
    spin = threading.Thread(target=spin_until_closed, args=(ex, h.ctx, done), daemon=True)
    spin.start()
    reports = h.record(Header, f'{h.ns}/lockstep_clock')
    entered, gate = threading.Event(), threading.Event()
    report = None
    try:
        report = lockstep.LockstepReport(node)
        c = clock(10.0, factor=0.0)   # 10 s, again every 2 ms
        wait_for(lambda: any(seconds(m.stamp) == 10.0 for _, m in list(reports)),
                 what='the report of 10 s')

        def slow():
            entered.set()
            gate.wait(5.0)
        lockstep.create_timer(node, 0.1, slow, callback_group=ReentrantCallbackGroup())
        c.jump(0.15)   # 10.15 s: the timer (due at 10.1 s) is called
        assert entered.wait(5.0)
        time.sleep(0.1)   # some 20 retries while the callback runs
        assert max(seconds(m.stamp) for _, m in list(reports)) == 10.0
        gate.set()
        wait_for(lambda: any(abs(seconds(m.stamp) - 10.15) < 1e-9 for _, m in list(reports)),
                 what='the report of 10.15 s once the callback returned')
    finally:
        # the spinning ends first, then the executor and the entities go: destroyed while a
        # spin thread built its wait set or a task ended, rclpy raised InvalidHandle there
        gate.set()
        done.set()
        spin.join(5.0)
        ex.shutdown(timeout_sec=2.0)
        if report is not None:
            report.destroy()
        node.destroy_node()


def test_a_shaped_steps_levels_are_solved_at_their_times_in_simulation_time(h, one, clock):
    """ZVD step at 0.25x: each level of the staircase is solved at its impulse time (sim s)."""
    clock(300.0, factor=0.25)
    h.record(PoseStamped, 'commanded_pose', DEEP)
    node = add_sim(h, InverseKinetostaticNode, target_shaping='zvd', dynamic_feedforward=False,
                   name='shaped')
    a = solve_forward(one, [40e3, 20e3, 0.0]).position
    b = a + np.array([0.01, 0.0, 0.0])
    pub = h.publisher(PoseStamped, 'target_pose')
    pub.publish(target_msg(a))
    wait_for(lambda: h.count('commanded_pose') > 0
             and np.linalg.norm(pose_of(h.last('commanded_pose'))[0] - a) < 1e-6,
             what='at the first target')
    time.sleep(0.5)
    n0 = h.count('commanded_pose')
    pub.publish(target_msg(b))                 # zero stamp: wanted on arrival
    wait_for(lambda: np.linalg.norm(pose_of(h.last('commanded_pose'))[0] - b) < 1e-6,
             what='at the step target')
    with h.lock:
        got = [(seconds(m.header.stamp), pose_of(m)[0]) for _, m in h.msgs['commanded_pose'][n0:]]
    times, amps = shaper_impulses('zvd', *node._targets._filter.mode)
    levels = np.cumsum(amps)
    first = {}   # level -> simulated time of its first solve (the commanded pose's stamp)
    for t, p in got:
        frac = float((p - a) @ (b - a) / ((b - a) @ (b - a)))
        k = int(np.argmin(abs(levels - frac)))
        assert abs(levels[k] - frac) < 1e-3, (frac, levels)
        first.setdefault(k, t)
    assert sorted(first) == list(range(len(levels))), (first, levels)
    after = np.array([first[k] - first[0] for k in range(len(levels))])
    print({'impulse times': np.round(times, 4), 'solved after (sim s)': np.round(after, 4)})
    # each level 1 ms after its impulse time, plus the solve: not a quarter of it (wall time)
    assert np.all(after[1:] >= times[1:] - 0.005), after
    assert np.all(after[1:] <= times[1:] + 0.015), after


# ------------------------------------------------------------ the trajectory publisher
def test_the_path_advances_by_simulation_time_and_is_stamped_with_it(h, clock):
    start = 1003.0
    sim = clock(start, factor=4.0)
    h.record(PoseStamped, 'target_pose', DEEP)
    node = add_sim(h, TrajectoryPublisher, rate_hz=50.0, period_s=8.0, ramp_in_s=0.0,
                   controller_node='')
    wait_for(lambda: h.count('target_pose') > 0, what='the first target')
    with h.lock:
        wall_first, first = h.msgs['target_pose'][0]
    s_first = seconds(first.header.stamp)
    # the path's clock starts at the first tick, not at the clock's 0 before /clock came
    np.testing.assert_allclose(pose_of(first)[0], node.pose_at(0.0)[0], atol=1e-9)
    wait_for(lambda: seconds(h.last('target_pose').header.stamp) >= s_first + 2.0,
             what='2 simulated seconds of path')
    with h.lock:
        msgs = list(h.msgs['target_pose'])
    wall_2s, at_2s = next((w, m) for w, m in msgs if seconds(m.header.stamp) >= s_first + 2.0)
    stamps = np.array([seconds(m.header.stamp) for _, m in msgs])
    assert start <= stamps[0] and stamps[-1] <= sim.now() + 1e-3, (stamps[[0, -1]], sim.now())
    assert np.all(np.diff(stamps) > 0)
    for _, m in msgs:   # every target: the path's point at its stamp's simulated time
        wanted = node.pose_at(seconds(m.header.stamp) - s_first)[0]
        np.testing.assert_allclose(pose_of(m)[0], wanted, atol=1e-9)
    t_2s = seconds(at_2s.header.stamp) - s_first
    assert 2.0 <= t_2s <= 2.0 + 0.02 + 0.05, t_2s              # one tick, a late one
    np.testing.assert_allclose(pose_of(at_2s)[0], node.pose_at(t_2s)[0], atol=1e-9)
    wall = wall_2s - wall_first
    rate = (len(stamps) - 1) / (stamps[-1] - stamps[0])
    print({'path time': t_2s, 'wall': wall, 'per simulated s': rate})
    assert 0.3 <= wall <= 1.2, wall                            # 2 s at 4x: 0.5 s of wall time
    assert 40.0 <= rate <= 52.0, rate                          # 50 per simulated second

    sim.run(0.25)
    time.sleep(0.2)
    s0, n0 = sim.now(), h.count('target_pose')
    time.sleep(2.0)                                            # half a simulated second
    s1, n1 = sim.now(), h.count('target_pose')
    print({'0.25x: targets': n1 - n0, 'simulated s': s1 - s0})
    assert 20 <= n1 - n0 <= 27, (n1 - n0, s1 - s0)             # 25: 50 Hz of simulation time
    last = h.last('target_pose')
    np.testing.assert_allclose(pose_of(last)[0], node.pose_at(
        seconds(last.header.stamp) - s_first)[0], atol=1e-9)

    p_before = pose_of(h.last('target_pose'))[0]
    speed = np.linalg.norm(node.pose_at(0.01)[0] - node.pose_at(0.0)[0]) / 0.01
    sim.jump(-500.0)                                           # a reset: the clock goes back
    sim.run(1.0)
    n2 = h.count('target_pose')
    wait_for(lambda: h.count('target_pose') >= n2 + 10, timeout=3.0,
             what='targets after the jump back')
    with h.lock:
        after = [m for _, m in h.msgs['target_pose'][n2:]]
    assert seconds(after[-1].header.stamp) < start            # stamped on the new clock
    # the path runs on from where it was: no jump of the target
    first_after = next(m for m in after if seconds(m.header.stamp) < start)
    print({'jump back: moved mm': 1e3 * np.linalg.norm(pose_of(first_after)[0] - p_before),
           'path mm/s': 1e3 * speed})
    assert np.linalg.norm(pose_of(first_after)[0] - p_before) <= speed * 0.3


# ------------------------------------------------------------ the regulator driver
def test_the_command_timeout_counts_simulation_time(h, clock):
    sim = clock(200.0, factor=0.25)
    wrote = Written(sim)
    drv = add_sim(h, lambda **kw: RegulatorDriver(wrote, **kw), command_timeout_s=0.5)
    assert drv.get_clock().ros_time_is_active
    pub = h.publisher(Float64MultiArray, 'pressure_command')
    found = {}

    # 0.25x: 0.5 simulated seconds are 2 s of wall time
    pub.publish(pressure_msg([70e3, 10e3, -30e3]))
    wait_for(lambda: wrote.calls and not wrote.vented, what='a write')
    w0, s0, _ = wrote.calls[-1]
    wait_for(lambda: wrote.vented, timeout=6.0, what='the vent on the timeout')
    w1, s1, _ = wrote.calls[-1]
    found['0.25x'] = (w1 - w0, s1 - s0)
    assert drv.stats['timeouts'] == 1

    # stopped for three timeouts of wall time: no vent; then 0.6 simulated seconds at once
    sim.stop()
    time.sleep(0.1)
    pub.publish(pressure_msg([50e3, 0.0, 0.0]))
    wait_for(lambda: not wrote.vented, what='a write')
    time.sleep(1.5)
    found['stopped'] = (drv.stats['timeouts'], wrote.vented)
    t_jump = time.monotonic()
    sim.jump(0.6)
    wait_for(lambda: wrote.vented, timeout=3.0, what='the vent after a jump forwards')
    found['jumped'] = time.monotonic() - t_jump

    # a jump back (a reset) does not hold the timeout off until the clock comes back
    sim.run(1.0)
    pub.publish(pressure_msg([40e3, 0.0, 0.0]))
    wait_for(lambda: not wrote.vented, what='a write')
    t_back = time.monotonic()
    sim.jump(-100.0)
    wait_for(lambda: wrote.vented, timeout=3.0, what='the vent after a jump back')
    found['jumped back'] = time.monotonic() - t_back
    print(found)
    wall, simulated = found['0.25x']
    assert 1.6 <= wall <= 4.0 and 0.45 <= simulated <= 0.7, found
    assert found['stopped'] == (1, False), found
    assert found['jumped'] <= 1.0, found
    assert found['jumped back'] <= 1.5, found
    assert drv.stats['timeouts'] == 3


def test_without_use_sim_time_the_timeout_is_wall_time_whatever_clock_says(h, clock):
    clock(200.0, factor=0.25)                 # a simulation runs slowly meanwhile
    wrote = Written()
    drv = h.add(lambda **kw: RegulatorDriver(wrote, **kw), command_timeout_s=0.5)
    assert not drv.get_clock().ros_time_is_active
    pub = h.publisher(Float64MultiArray, 'pressure_command')
    pub.publish(pressure_msg([70e3, 10e3, -30e3]))
    wait_for(lambda: wrote.calls and not wrote.vented, what='a write')
    w0 = wrote.calls[-1][0]
    wait_for(lambda: wrote.vented, timeout=3.0, what='the vent on the timeout')
    wall = wrote.calls[-1][0] - w0
    print({'wall': wall})
    assert 0.45 <= wall <= 1.0, wall          # 0.5 s of wall time (2 s on the slow /clock)
