"""A participant's side of a simulation's lockstep: the time up to which it has done its work.

Under ``use_sim_time`` a participant publishes ``lockstep_clock``
(std_msgs/Header: ``stamp`` the simulation time its work is done until,
``frame_id`` its fully qualified node name).  A ``simulated_robot_node`` in
``lockstep`` takes no step beyond the oldest of the participants' newest
reports (:meth:`~bellow_ancf_ros.core.sim.SimulationClock.done_until`): their
computation takes no simulated time, and a busy computer slows the
simulation instead of delaying what they publish in it.  Two kinds:

* a controller (``follow_clock``: the inverse node) reports each ``/clock``
  tick it has received, once no work is pending or running and none of its
  timers is due (at once when idle, else when the work ends,
  :meth:`LockstepReport.work_done`, or at the next look every
  :data:`RETRY_S` of wall time): a re-solve or a shaper's level due at a
  tick goes out before the simulation passes it;
* a publisher on a timer (the trajectory publisher) reports, after each
  tick, the time just before its next one (:meth:`LockstepReport.report`),
  so that no step passes a tick before it is published.

A participant that stops says so (``stamp`` :data:`LEAVE_SEC` s,
:meth:`LockstepReport.destroy`), and the simulation no longer waits for it.
Nothing is published on the wall clock.

**Messages owed.**  A report also counts the messages the participant has
sent and received on reliable topics (:meth:`LockstepReport.sent`,
:meth:`LockstepReport.received`; the trajectory publisher's targets, the
inverse node's targets and commands), written after the node's name in
``frame_id``: ``/trajectory_publisher sent:/target_pose=812``.  The
simulation takes no step while a receiver has counted fewer messages on a
topic than were sent on it (it counts the commands it receives itself), so
a target or a command is seen at the same simulated time however late the
computer delivers it: without this, targets reached the inverse node up to
0.1 s of simulated time after their stamp on a busy machine, and the same
closed-loop run gave 0.08 mm in one run and 0.45 mm (a 2.4 mm swing) in
another.
"""

from __future__ import annotations

import threading
import time
from typing import Callable
import weakref

from builtin_interfaces.msg import Time
from rclpy.clock import Clock as RosClock, ClockType
from rclpy.duration import Duration
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Header

__all__ = ['HOLD_LIMIT_S', 'LEAVE_SEC', 'TOPIC', 'UNBOUNDED_SEC', 'LockstepReport',
           'create_timer', 'report_of']

#: The topic (in the node's namespace) a simulated robot's lockstep listens to.
TOPIC = 'lockstep_clock'
#: A report stamped this many seconds: the participant no longer holds the simulation.
LEAVE_SEC = 2 ** 31 - 1
#: How often [wall s] a controller looks again whether a held-back tick may be reported.
RETRY_S = 0.005
#: A report stamped this many seconds holds no time, only counts messages
#: (:meth:`LockstepReport.report_counts`: a publisher without a cadence of its own).
UNBOUNDED_SEC = LEAVE_SEC - 1
#: How long [wall s] a watched timer's call may hold the reports before its callback starts
#: (:meth:`LockstepReport.create_timer`; a bound in case rcl skips a call it advanced past).
HOLD_LIMIT_S = 0.25

_REPORTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()   # node -> its controller's


def create_timer(node, period_s: float, callback: Callable[[], None], **kw):
    """``node.create_timer``, watched by the node's controller lockstep when it has one.

    (:meth:`LockstepReport.create_timer`: the re-solve timers of the inverse
    node's parts, which do not hold its :class:`LockstepReport` themselves.)
    """
    report = _REPORTS.get(node)
    if report is None:
        return node.create_timer(period_s, callback, **kw)
    return report.create_timer(period_s, callback, **kw)


def report_of(msg: Header) -> tuple[str, float | None, dict, dict]:
    """``(participant, done until [s], sent, received)`` of a report.

    Done until None: the participant leaves.  ``sent`` / ``received``: the
    messages counted per topic (empty when the report counts none).
    """
    who, *counts = msg.frame_id.split(' ')
    books: dict = {'sent': {}, 'received': {}}
    for item in counts:
        kind, _, rest = item.partition(':')
        topic, _, n = rest.rpartition('=')
        if kind in books and topic and n.isdigit():
            books[kind][topic] = int(n)
    if msg.stamp.sec >= LEAVE_SEC:
        return who, None, books['sent'], books['received']
    return who, msg.stamp.sec + 1e-9 * msg.stamp.nanosec, books['sent'], books['received']


def _time(t: float) -> Time:
    ns = max(int(round(t * 1e9)), 0)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


class LockstepReport:
    """Publish ``lockstep_clock`` for ``node`` while it runs on simulation time.

    ``follow_clock``: report each ``/clock`` tick once ``idle()`` (no work
    pending or running); :meth:`work_done` (any thread): a piece of work
    ended, the newest tick held back goes out if now idle.  Without it the
    node reports its own times with :meth:`report`.
    """

    def __init__(self, node, idle: Callable[[], bool] = lambda: True,
                 follow_clock: bool = True) -> None:
        self._node, self._idle = node, idle
        self._lock = threading.Lock()
        self._tick: Time | None = None   # the newest /clock tick received
        self._counts: dict[str, dict[str, int]] = {'sent': {}, 'received': {}}
        self._last = None   # what the newest report said (frame_id, stamp)
        self._pub = self._sub = self._retry = None
        self._watched: list = []   # (timer, period [ns], [end of its last callback, ns; running])
        self._stuck: dict = {}     # (timer id, call [ns]) -> since [monotonic s]
        self._name = node.get_fully_qualified_name()
        if node.get_parameter('use_sim_time').value:
            self._pub = node.create_publisher(Header, TOPIC, 10)
            if follow_clock:
                self._sub = node.create_subscription(
                    Clock, '/clock', self._on_clock,
                    QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                               history=HistoryPolicy.KEEP_LAST))
                self._retry = node.create_timer(RETRY_S, self.work_done,
                                                clock=RosClock(clock_type=ClockType.STEADY_TIME))
                _REPORTS[node] = self

    @property
    def active(self) -> bool:
        """True while reporting (the node is on simulation time)."""
        return self._pub is not None

    def _on_clock(self, msg: Clock) -> None:
        with self._lock:
            self._tick = msg.clock
        self.work_done()

    def publish(self, pub, msg) -> None:
        """Publish ``msg`` on ``pub`` and count it as sent (said in the next report)."""
        pub.publish(msg)
        self.sent(pub.topic_name)

    def sent(self, topic: str, n: int = 1) -> None:
        """``n`` more messages were published on ``topic`` (resolved; in the next report)."""
        self._count('sent', topic, n)

    def received(self, topic: str, n: int = 1) -> None:
        """``n`` more messages were taken from ``topic`` (a controller reports it once idle)."""
        self._count('received', topic, n)
        if self._sub is not None:
            self.work_done()

    def _count(self, kind: str, topic: str, n: int) -> None:
        if self._pub is not None:
            with self._lock:
                book = self._counts[kind]
                book[topic] = book.get(topic, 0) + int(n)

    def _frame_id(self) -> str:
        """The node's name and its counts (called with the lock held)."""
        return ' '.join([self._name] + [f'{kind}:{topic}={n}'
                                        for kind, book in self._counts.items()
                                        for topic, n in sorted(book.items())])

    def _publish(self, stamp: Time | None) -> None:
        """Report ``stamp`` (None: the newest tick) with the counts, unless said already."""
        pub = self._pub
        if pub is None:
            return
        with self._lock:
            stamp = self._tick if stamp is None else stamp
            if stamp is None:
                return
            frame = self._frame_id()
            said = (frame, stamp.sec, stamp.nanosec)
            if said == self._last:
                return
            self._last = said
        try:
            pub.publish(Header(stamp=stamp, frame_id=frame))
        except Exception:  # noqa: BLE001 - publisher gone at shutdown
            pass

    def work_done(self) -> None:
        """Report the newest tick received, unless a timer is due or work pending or running.

        In that order, and for the tick read once: a timer's callback (on the
        executor's thread) submits its work before it counts as run, while
        this may run on the worker's thread.
        """
        tick = self._tick
        if self._pub is None or tick is None or self._timer_due(tick) or not self._idle():
            return
        self._publish(tick)

    def create_timer(self, period_s: float, callback: Callable[[], None], **kw):
        """``node.create_timer`` whose calls hold the reports until their callback has run.

        rcl takes a timer's call (its next call moves on) before the executor
        runs its callback: rclpy's EventsExecutor queues the callback, and
        the worker's thread may report meanwhile.  A watched timer counts as
        due from its call until its callback has returned (from its call
        to the callback's start at most :data:`HOLD_LIMIT_S` of wall time;
        while the callback runs, however long).  A plain timer without a
        controller's lockstep.  ``kw``: as ``create_timer`` takes them.
        """
        node = self._node
        if self._sub is None:
            return node.create_timer(period_s, callback, **kw)
        done = [node.get_clock().now().nanoseconds, 0]   # end of its last callback, running

        def run():
            with self._lock:
                done[1] += 1
            try:
                callback()
            finally:
                with self._lock:
                    done[0] = node.get_clock().now().nanoseconds
                    done[1] -= 1
            self.work_done()   # at once (else at the next retry): the simulation waits for it
        timer = node.create_timer(period_s, run, **kw)
        with self._lock:
            self._watched = [w for w in self._watched if not _gone(w[0])]
            self._watched.append((timer, int(round(period_s * 1e9)), done))
        return timer

    def _called_not_run(self, now: int) -> bool:
        """A watched timer was called (by rcl) and its callback has not returned yet."""
        with self._lock:
            watched = list(self._watched)
            if any(done[1] for _, _, done in watched):
                return True   # a callback is running (however long: its work is not done)
        for timer, period, done in watched:
            try:
                left = None if timer.is_canceled() else timer.time_until_next_call()
            except Exception:  # noqa: BLE001 - destroyed meanwhile
                continue
            if left is None:
                continue
            called = now + left - period
            if called <= done[0]:
                continue
            since = self._stuck.setdefault((id(timer), called), time.monotonic())
            if time.monotonic() - since < HOLD_LIMIT_S:
                return True
        if len(self._stuck) > 64:
            self._stuck.clear()
        return False

    def _timer_due(self, tick: Time) -> bool:
        """One of the node's timers is due by ``tick`` and has not run yet.

        Due by the tick, not by the node's clock: the node's time source may
        not have taken the same ``/clock`` message yet, and its timers would
        then look not due.  A watched timer (:meth:`create_timer`) also from
        its call until its callback returns.  If one is, :data:`RETRY_S`
        later it looks again.
        """
        now = self._node.get_clock().now().nanoseconds
        ahead = max(tick.sec * 1_000_000_000 + tick.nanosec - now, 0)
        if self._called_not_run(now):
            return True
        for timer in list(self._node.timers):
            if timer is self._retry or timer.is_canceled():
                continue
            try:
                left = timer.time_until_next_call()
                ros = timer.clock.clock_type == ClockType.ROS_TIME
            except Exception:  # noqa: BLE001 - a timer destroyed meanwhile
                continue
            if left is not None and left <= (ahead if ros else 0):
                return True
        return False

    def report(self, t: float) -> None:
        """Report the work done until simulation time ``t`` [s]."""
        self._publish(_time(t))

    def report_counts(self) -> None:
        """Report the counts only (:data:`UNBOUNDED_SEC`: this node holds no time back)."""
        self._publish(Time(sec=UNBOUNDED_SEC, nanosec=0))

    def destroy(self) -> None:
        """Stop reporting (on cleanup): a last report that this node leaves, then the topics go."""
        self._publish(Time(sec=LEAVE_SEC, nanosec=0))   # (its counts: owed no more)
        if _REPORTS.get(self._node) is self:
            del _REPORTS[self._node]
        pub, sub, self._pub, self._sub = self._pub, self._sub, None, None
        if self._retry is not None:
            self._node.destroy_timer(self._retry)
            self._retry = None
        if pub is not None:   # the leave must arrive, or the simulation waits its timeout
            try:
                pub.wait_for_all_acked(Duration(seconds=0.5))
            except Exception:  # noqa: BLE001 - context gone at shutdown
                pass
        if sub is not None:
            self._node.destroy_subscription(sub)
        if pub is not None:
            self._node.destroy_publisher(pub)


def _gone(timer) -> bool:
    """The timer was destroyed or cancelled."""
    try:
        return timer.is_canceled()
    except Exception:  # noqa: BLE001 - destroyed
        return True
