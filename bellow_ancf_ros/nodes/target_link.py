"""The inverse node's target stream made for a robot with a mode: shaping, dynamic feedforward.

:class:`TargetLink` declares parameters ``target_shaping`` (``smooth``, the
default, ``none``, ``zv`` or ``zvd``) and ``dynamic_feedforward`` (true by
default), and feeds the core
:class:`~bellow_ancf_ros.core.control.TargetFilter` with each new target (at
the time it is wanted at: its stamp, or its arrival for a zero stamp) and
with the robot's first mode at the held equilibrium
(:class:`~.mode_watch.ModeWatch`).  The node solves for what it returns.
While the output still moves after a new target (a jump's move, a shaper's
staircase), the newest target is re-solved at ``SHAPING_RATE_HZ``; after a
step (a new pose after a held one) with a ZV/ZVD shaper, at each of the
shaper's impulse times instead (a one-shot timer each, :data:`IMPULSE_LEAD_S`
after it, no re-solve in between): the staircase's levels reach the robot at
their times, not up to a re-solve period late (a level 10 ms late at the
two-segment robot's 2.4 Hz mode leaves 7 % of the swing the shaper cancels).

Defaults: ``smooth``: a jump of the targets (a step target, the first target
after a held one far away) becomes a minimum-jerk move over two periods of
the slowest first mode the robot may have (0.7 times the model's; a ramp
ZV-shaped at the robot's own mode, 1.5 of its periods, when its file gives
the measured ``dynamics.first_mode_error``), and the closed loop holds its
correction through it; a smooth stream passes
unchanged and undelayed (measured on the robot family: a 10 mm step
overshoots 0.1-0.4 mm instead of 0.4-9 mm; circles unchanged).  ZV/ZVD
shapers are shorter but need the mode within +-20 % and delay every target
by their centroid (0.1-0.2 s for the two-segment robot, which a streamed path
pays as lag).  Dynamic feedforward by default: a planner streams its poses
as it plans them, stamped when they are sent, and nobody previews the
regulators' lag or the mode's phase but the node (measured on 8 robots of
the family per segment count, targets not previewed: the two-segment
circle at 10x 0.489 mm median RMSE and 0.904 mm worst, against 0.553 and
1.422 mm without it; one segment unchanged).  A source that previews
(targets stamped in the future, e.g. ``trajectory_publisher``'s
``preview_s``) still does better: it should then preview the regulators'
dead time and half a target period, the node inverting the lag (a
preview is a pure delay, the lag also lowers the amplitude), or preview the
lag too with ``dynamic_feedforward: false``.

With the dynamic feedforward, a stream's commands go out on its own grid
(:class:`~bellow_ancf_ros.core.control.CommandPacer`; wall clock only):
each new target's command at its regular intake (its pose's time plus the
usual age at arrival) plus the 95th percentile of how late the last 100
were ready (at most one interval of the stream), its pose carried to that time
(:meth:`pace`, called by the node before it publishes), instead of when
its solve happened to end; re-solves and a held or braking stream's
commands go out at once.  And when a moving stream's next target is late
(:data:`EXPECT_MARGIN` of an interval after its regular intake; a planner
kept waiting by a busy computer), the newest is solved again then, carried
on along the stream, up to :data:`EXPECT_TICKS` times in a row: the
commands keep the grid instead of standing until the late target comes
and then stepping (measured with a planner that sent 15 % of its targets
late by 10 ms on average: the two-segment 10x circle 0.20-0.36 mm RMSE in
four runs, against 0.33 and 0.47 mm before and 0.14-0.19 mm on time).
Diagnostics: ``command_margin_ms`` and ``commands_paced_late`` (late / paced).
"""

from __future__ import annotations

import heapq
import itertools
import threading
import time
from typing import Any, Callable

from rcl_interfaces.msg import ParameterType

from ..core.control import TARGET_SHAPINGS, CommandPacer, TargetFilter
from . import lockstep
from .ros_util import Param, StartupParameterError, control_clock, declare_all, descriptor

__all__ = ['SHAPING_RATE_HZ', 'STREAM_DEFER_S', 'TARGET_PARAMETER_TABLE', 'TargetLink']

#: Re-solve rate of a shaped target while it moves [Hz].
SHAPING_RATE_HZ = 50.0
#: A shaper level is solved this long after its impulse time [s] (the level is then in).
IMPULSE_LEAD_S = 0.001
#: A moving stream's next target counts as late this many intervals after its regular intake.
EXPECT_MARGIN = 0.3
#: At most this many re-solves in a row for late targets of a moving stream.
EXPECT_TICKS = 3
#: No modal analysis until this long after a moving stream's newest target [s]
#: (:meth:`~.mode_watch.ModeWatch.defer`; longer than a stopped stream's brake).
STREAM_DEFER_S = 0.5
#: The parameters TargetLink declares (read on configure).
TARGET_PARAMETER_TABLE = (
    Param('target_shaping', 'smooth', descriptor(
        "What a jump of the targets becomes. 'smooth': a minimum-jerk move over two periods "
        "of the slowest first mode the robot may have (0.7x the model's; a ZV-shaped ramp "
        "of 1.5 periods of the measured one when the robot file gives "
        "dynamics.first_mode_error), the closed loop holding its correction through it; "
        "a smooth stream passes unchanged. 'zv' or 'zvd': input shaping at the first mode "
        "(Singer & Seering; zvd robust to a mode known to +-20 %), every target delayed by "
        "the shaper. 'none': targets as they come. Read on configure.",
        ParameterType.PARAMETER_STRING, constraints="one of: 'smooth', 'none', 'zv', 'zvd'")),
    Param('dynamic_feedforward', True, descriptor(
        "Shift each moving target by the inertial and damping loads of its motion through "
        "the first mode and by the regulators' lag (feedback_loop_lag_s): a fast path "
        'streamed as it is planned is tracked without waiting for feedback (a source that '
        "previews should then preview the regulators' dead time only). A step passes "
        'unshifted. Read on configure.',
        ParameterType.PARAMETER_BOOL)),
)


def _pose_key(item) -> tuple:
    """A target item's pose as a comparable key: (position, z-axis or None)."""
    return tuple(item[0]), None if item[1] is None else tuple(item[1])


class TargetLink:
    """Shaping and dynamic feedforward of the inverse node's targets (module docstring)."""

    def __init__(self, node) -> None:
        """Declare the parameters on ``node`` (refuses a bad ``target_shaping``)."""
        declare_all(node, TARGET_PARAMETER_TABLE)
        self.node = node
        self._clock = control_clock(node)   # every time here: control time (use_sim_time)
        self._kind = self._read_kind()
        self._lock = threading.Lock()
        self._filter: TargetFilter | None = None
        self._timer = None
        self._last_item = None
        self._resubmit: Callable[[Any], None] | None = None
        self._modes = None                          # the node's ModeWatch
        self._levels: list = []   # one-shot re-solves at impulse times (_level_timer)
        self._expect = None   # one-shot re-solve when a moving stream's next target is late
        self._last_pose = None
        self._last_pose_t: float | None = None     # when the newest pose was first wanted
        # a stream's commands on its grid (wall clock only: under use_sim_time the lockstep)
        self._pacer = None if self._clock.simulated else CommandPacer()
        self._due: tuple | None = None   # (regular intake, due) of the target being solved
        self.stale_resolves = 0   # older targets queued again after a newer one, re-solved as it
        self._wall = _WallTimers(   # (the wall clock's one-shot re-solves: one thread)
            lambda exc: node.get_logger().error(f'targets: a timed re-solve failed: {exc!r}'))

    def _read_kind(self) -> str:
        kind = self.node.get_parameter('target_shaping').value
        if kind not in TARGET_SHAPINGS:
            raise StartupParameterError('target_shaping', kind,
                                        "one of: 'smooth', 'none', 'zv', 'zvd'")
        return kind

    @property
    def wanted(self) -> bool:
        """True when shaping or dynamic feedforward is asked for (needs the first mode)."""
        g = self.node.get_parameter
        return g('target_shaping').value != 'none' or bool(g('dynamic_feedforward').value)

    def configure(self, modes, resubmit: Callable[[Any], None], lag_s: float,
                  mode_error: float | None = None) -> None:
        """Build the filter; listen to ``modes`` (a ModeWatch); re-solve while shaping.

        ``mode_error``: the robot file's ``dynamics.first_mode_error``.
        """
        self.release()
        g = self.node.get_parameter
        self._kind = self._read_kind()
        filt = TargetFilter(self._kind, bool(g('dynamic_feedforward').value), lag_s, mode_error)
        if not filt.enabled or modes is None:
            return
        with self._lock:
            self._filter = filt
        self._resubmit, self._modes = resubmit, modes
        modes.listen(self._on_mode)
        if modes.result is not None:
            self._on_mode(None, modes.result)
        if filt.enabled:   # (re-solves while shaping, moving through a jump or braking)
            def tick():
                item = self._last_item
                with self._lock:
                    busy = self._filter is not None and self._filter.busy(self._clock.now())
                    timed = any(t.is_alive() for t in self._levels)
                if item is not None and busy and not timed:   # (a step's levels are timed:
                    resubmit(item)   # a re-solve in between would only delay one of them)
            self._timer = lockstep.create_timer(self.node, 1.0 / SHAPING_RATE_HZ, tick)
        self.node.get_logger().info(
            f'targets: shaping {self._kind}, dynamic feedforward '
            f'{"on" if filt.feedforward is not None else "off"} (lag {lag_s:g} s)')

    def _on_mode(self, before, res) -> None:
        with self._lock:
            filt = self._filter
            if filt is None or not (before is None or res.moved or filt.mode is None):
                return
            filt.set_mode(res.frequency_hz, res.damping_ratio)
            delay = filt.delay_s
        if filt.shaper is not None:
            self.node.get_logger().info(
                f'targets: {self._kind} shaper at {res.frequency_hz:.3g} Hz (damping ratio '
                f'{res.damping_ratio:.3f}): adds {delay * 1e3:.0f} ms of delay, '
                f'{filt.shaper.duration_s * 1e3:.0f} ms to arrive')

    def release(self) -> None:
        """Drop the filter and the re-solve timers."""
        if self._timer is not None:
            self.node.destroy_timer(self._timer)
        self._timer = self._last_item = None
        with self._lock:
            self._filter = None
            self._cancel_levels()

    def _cancel_levels(self) -> None:
        for timer in self._levels + ([self._expect] if self._expect is not None else []):
            timer.cancel()
        self._levels, self._expect = [], None
        self._last_pose = self._last_pose_t = None

    def _schedule_levels(self, item, filt: TargetFilter, wanted_at: float) -> None:
        """One-shot re-solves of ``item`` at the shaper's impulse times (a step only).

        A step: a new pose after one held for at least the shaper's duration.
        A stream (a new pose more often) keeps the 50 Hz re-solves: timers for
        every target would only multiply the solves.
        """
        pose = _pose_key(item)
        if filt.shaper is None or filt.mode is None or pose == self._last_pose:
            return
        previous = self._last_pose_t
        self._cancel_levels()   # (they were for another pose)
        self._last_pose, self._last_pose_t = pose, wanted_at
        if previous is not None and wanted_at - previous < filt.shaper.duration_s:
            return   # a stream: the 50 Hz re-solves
        if self._modes is not None:   # no modal analysis stalls a level
            self._modes.quiet(wanted_at + filt.shaper.duration_s + 0.05)
        resubmit, now = self._resubmit, self._clock.now()

        def level() -> None:   # the newest item, if it still wants this pose (republished)
            cur = self._last_item
            if cur is not None and resubmit is not None and _pose_key(cur) == pose:
                resubmit(cur)
        for t_i in filt.shaper.times[1:]:
            self._levels.append(self._level_timer(
                max(wanted_at + float(t_i) + IMPULSE_LEAD_S - now, 0.0), level))

    def _expect_next(self, item, regular: float, interval: float, left: int) -> None:
        """Re-solve ``item`` if no newer target is taken by ``regular`` plus a margin.

        A moving stream's next target is regularly taken in at ``regular``;
        if it is late (a planner kept waiting by a busy computer), the newest
        is solved again then, carried on by the feedforward to that time,
        so the commands keep the stream's grid instead of waiting for the
        late target and then stepping (an irregular staircase rings the
        robot's mode).  At most ``left`` intervals in a row (then the
        stream's stale time and its brake take over).  Call with the lock held.
        """
        if self._expect is not None:
            self._expect.cancel()
        self._expect = None
        resubmit = self._resubmit
        if left <= 0 or resubmit is None:
            return

        def late() -> None:
            with self._lock:
                if self._last_item is not item or self._filter is None:
                    return
                self._expect_next(item, regular + interval, interval, left - 1)
            resubmit(item)
        self._expect = self._level_timer(
            max(regular + EXPECT_MARGIN * interval - self._clock.now(), 0.0), late)

    def _level_timer(self, delay_s: float, fn: Callable[[], None]):
        """Call ``fn`` once ``delay_s`` of control time from now (``is_alive``, ``cancel``).

        On the wall clock a deadline of :class:`_WallTimers` (exact to the
        millisecond), or under ``use_sim_time`` a one-shot timer on the node's
        clock: its simulation seconds.
        """
        if self._clock.simulated:
            return _OneShot(self.node, delay_s, fn)
        return self._wall.call_in(delay_s, fn)

    @staticmethod
    def refusal(param) -> str:
        """Why a new value of ``target_shaping`` is not allowed, or ''."""
        if param.name != 'target_shaping' or param.value in TARGET_SHAPINGS:
            return ''
        return (f'target_shaping = {param.value!r} is not allowed; allowed: '
                f'{", ".join(map(repr, TARGET_SHAPINGS))}')

    def reset(self, start=None) -> None:
        """Forget the stream (on activate); ``start``: the pose the robot is at (vented)."""
        self._last_item = self._due = None
        if self._pacer is not None:
            self._pacer.reset()
        with self._lock:
            if self._filter is not None:
                self._filter.reset(start)
            self._cancel_levels()

    def targets(self, item, wanted_at: float):
        """``(command, reference)`` for ``item`` (new or re-solved) wanted at ``wanted_at``.

        The command is shaped and shifted; the reference (shaped, not
        shifted) is the pose wanted, which the closed loop measures against.
        """
        pos, z = item[0], item[1]
        with self._lock:
            filt = self._filter
            if filt is None:
                return (pos, z), (pos, z)
            now, self._due = self._clock.now(), None
            last = self._last_item
            if last is not None and item is not last and item[3] < last[3]:
                # an older target queued again after a newer one was taken (a re-solve
                # tick that raced a new target): a re-solve of the newest, never a
                # stream going back in time (which starts the stream again)
                self.stale_resolves += 1
                return filt.targets(now)
            if item is not last:
                self._last_item = item
                filt.push(wanted_at, pos, z, at=now)   # (a late solve is no stop of the stream)
                self._schedule_levels(item, filt, wanted_at)
                tick = filt.stream_tick()   # (a moving stream: its pose's time, interval)
                if tick is not None and self._modes is not None:
                    self._modes.defer(now + STREAM_DEFER_S)
                if tick is not None and self._pacer is not None:   # (item[3]: its arrival)
                    self._due = self._pacer.due(tick[0], item[3], tick[1])
                    now = max(now, self._due[1] or now)   # (carried to when it goes out)
                    self._expect_next(item, self._due[0] + tick[1], tick[1], EXPECT_TICKS)
            return filt.targets(now)

    def pace(self) -> None:
        """Wait until the command just solved is due (:class:`CommandPacer`); else return.

        Only a new target of a stream has a time: re-solves, a held or
        braking stream's commands go out at once.
        """
        due, self._due = self._due, None
        if due is not None and self._pacer is not None:
            wait = self._pacer.ready(due[0], self._clock.now(), due[1])
            if wait > 0.0:
                time.sleep(wait)

    def hold_until(self) -> float | None:
        """Until when the closed loop holds its correction (a jump's move; control time)."""
        with self._lock:
            return None if self._filter is None else self._filter.hold_until

    def move(self) -> tuple | None:
        """The newest jump's move, as ``TargetFilter.move`` gives it (control time); or None."""
        with self._lock:
            return None if self._filter is None else self._filter.move

    def status(self) -> dict:
        """Diagnostics values."""
        with self._lock:
            filt = self._filter
            if filt is None:
                return {'target_shaping': self._kind, 'dynamic_feedforward': 'false'}
            move = filt.jumps.duration_s if filt.jumps is not None else 0.0
            pacer = self._pacer
            margin, late, paced = ((None, 0, 0) if pacer is None
                                   else (pacer.margin_s, pacer.late, pacer.paced))
            return {'target_shaping': self._kind,
                    'target_shaping_delay_s': f'{filt.delay_s:.3f}',
                    'target_move_s': f'{move:.3f}' if move > 0 else 'none',
                    'dynamic_feedforward': str(filt.feedforward is not None).lower(),
                    'target_mode_hz': 'none' if filt.mode is None else f'{filt.mode[0]:.4g}',
                    'command_margin_ms': 'none' if margin is None else f'{margin * 1e3:.1f}',
                    'commands_paced_late': f'{late}/{paced}'}


class _Deadline:
    """One call at a deadline: ``is_alive`` until it fired or was cancelled (once)."""

    def __init__(self, fn: Callable[[], None]) -> None:
        self._fn = fn
        self._lock = threading.Lock()
        self._done = False

    def _end(self) -> bool:
        """Mark it done; whether it was still pending."""
        with self._lock:
            pending, self._done = not self._done, True
        return pending

    def fire(self) -> None:
        """Call the function unless it was cancelled or has fired."""
        if self._end():
            self._fn()

    def is_alive(self) -> bool:
        """True until it fired or was cancelled."""
        return not self._done

    def cancel(self) -> None:
        """Do not fire (no-op once fired)."""
        self._end()


class _OneShot(_Deadline):
    """A deadline on ``node``'s clock (simulation time): a one-shot timer of the node's."""

    def __init__(self, node, delay_s: float, fn: Callable[[], None]) -> None:
        super().__init__(fn)
        self._node = node
        self._timer = lockstep.create_timer(node, delay_s, self.fire)   # (held for)

    def _destroy(self) -> None:
        self._timer.cancel()
        self._node.destroy_timer(self._timer)   # (safe from its own callback)

    def fire(self) -> None:
        """Call the function unless cancelled; then destroy the timer."""
        if self._end():
            try:
                self._fn()   # (its work submitted before the timer goes: a lockstep holds)
            finally:
                self._destroy()

    def cancel(self) -> None:
        """Do not fire (no-op once fired)."""
        if self._end():
            self._destroy()


class _WallTimers:
    """One-shot calls at deadlines on the monotonic clock, all from one thread.

    What ``threading.Timer`` does, without a thread per call: a moving
    stream's late-target re-solve is scheduled for every target (50 a second
    at 50 Hz) and cancelled by the next, and a thread started and ended for
    each cost some 0.3 ms of CPU (1.5 % of a core at 50 Hz) on this
    2-core machine, against a heap push here.  The thread starts with the
    first call (it inherits the scheduler of the thread that asks: the
    solver's, on the real-time scheduler where the node runs there) and waits
    on its condition between deadlines.  A call runs in that thread and must
    not block (the re-solves only queue an item).
    """

    def __init__(self, on_error: Callable[[BaseException], None]) -> None:
        self._on_error = on_error   # (a call that raised: the thread goes on with the next)
        self._cond = threading.Condition()
        self._heap: list = []
        self._order = itertools.count()   # (deadlines that tie fire in the order asked)
        self._thread: threading.Thread | None = None

    def call_in(self, delay_s: float, fn: Callable[[], None]) -> _Deadline:
        """Call ``fn`` once, ``delay_s`` [s] from now; the returned handle cancels it."""
        entry = _Deadline(fn)
        with self._cond:
            heapq.heappush(self._heap, (time.monotonic() + max(delay_s, 0.0),
                                        next(self._order), entry))
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name='target-timers',
                                                daemon=True)
                self._thread.start()
            self._cond.notify()
        return entry

    def _next(self) -> _Deadline:
        """Wait for the earliest deadline that is still pending; pop it."""
        with self._cond:
            while True:
                while self._heap and not self._heap[0][2].is_alive():
                    heapq.heappop(self._heap)   # (cancelled: dropped unseen)
                if not self._heap:
                    self._cond.wait()
                    continue
                wait = self._heap[0][0] - time.monotonic()
                if wait <= 0.0:
                    return heapq.heappop(self._heap)[2]
                self._cond.wait(wait)

    def _run(self) -> None:
        while True:
            entry = self._next()
            try:
                entry.fire()   # (outside the lock: a call may ask for the next one)
            except Exception as exc:   # noqa: BLE001 - reported, the other deadlines go on
                self._on_error(exc)
