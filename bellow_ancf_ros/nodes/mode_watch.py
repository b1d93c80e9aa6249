"""The robot's first mode where it is held, computed off the control path for the inverse node.

The closed loop (its margins, automatic gain and watchdog band), the target
shaper and the dynamic feedforward all need the first lateral mode of the
controller's model at the equilibrium of its newest solve (a payload, a tip
force or a bent pose move it).  :class:`ModeWatch` runs the core
:class:`~bellow_ancf_ros.core.control.ModeCheck` (a modal analysis: tens to
hundreds of milliseconds) in one thread of its own, when the payload or the
force changes and every two seconds while the robot moves, and hands each
answer to its listeners.  The first answer is computed at start, before any
command, at the equilibrium the node starts from.  :meth:`ModeWatch.quiet`
holds the thread off for a while: a modal analysis holds the interpreter for
tens of milliseconds, and during a shaped step's staircase that would delay
one of its levels (a level 10-25 ms late left 0.24-0.41 mm of swing after a
10 mm step where 0.034 mm was measured without the stall).
:meth:`ModeWatch.defer` holds it off while a target stream moves, for at
most :data:`MAX_DEFER_S` since the last answer and never after a change of
the load: an analysis of two segments took 47-66 ms of CPU beside the
solves, which then took 25-36 ms instead of 7 and sent their commands 5-24
ms late (logged on a 10x circle in ROS, once every 2 s).
"""

from __future__ import annotations

import threading
from typing import Callable

from ..core.control import ModeCheck, ModeCheckResult
from .realtime import background
from .ros_util import control_clock

__all__ = ['MAX_DEFER_S', 'ModeWatch']

#: How often the thread looks for a new equilibrium [s of wall time].
_POLL_S = 0.2
#: Longest wall-clock wait between two looks at the control time while held off [s].
_QUIET_POLL_S = 0.01
#: A moving stream defers the analyses at most this long after the last answer [s].
MAX_DEFER_S = 10.0


class ModeWatch:
    """First mode and loop margins at the newest equilibrium, in a thread (module docstring)."""

    def __init__(self, node, check: ModeCheck) -> None:
        self.node, self.check = node, check
        self._clock = control_clock(node)   # when an analysis is due, and the quiet: control time
        self.result: ModeCheckResult | None = None
        self._listeners: list[Callable] = []
        self._fw = None
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._quiet_until = -float('inf')
        self._defer_until = -float('inf')
        self._answered_at = -float('inf')   # control time of the last answer
        self._answered_load = None

    def listen(self, fn: Callable[[ModeCheckResult | None, ModeCheckResult], None]) -> None:
        """Call ``fn(before, result)`` with every new answer (in the watch's thread)."""
        self._listeners.append(fn)

    def start(self, start_fw=None) -> None:
        """Answer for ``start_fw`` now (if given and converged), then watch in the thread."""
        self._stop.clear()   # (before the first answer: a stopped watch's answers reach nobody)
        if start_fw is not None and start_fw.converged:
            self._answer(start_fw)
        self._thread = threading.Thread(target=self._loop, name='first-mode', daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> bool:
        """End the thread: joined for up to ``timeout`` [s]; False if it still runs.

        An analysis cannot be interrupted: one still running after the join
        is let finish, but its answer reaches no listener and it logs
        nothing (the node it would log on is being destroyed).
        """
        self._stop.set()
        self._wake.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout)
            return not thread.is_alive()
        return True

    def quiet(self, until: float) -> None:
        """No modal analysis starts before ``until`` (control time, ``ControlClock``)."""
        self._quiet_until = max(self._quiet_until, float(until))

    def defer(self, until: float) -> None:
        """No analysis before ``until`` while the load stays (a moving stream; module docstring).

        Control time; ignored :data:`MAX_DEFER_S` after the last answer.
        """
        self._defer_until = max(self._defer_until, float(until))

    def _held_off_until(self, fw) -> float:
        """Until when (control time) no analysis starts: quiet, or deferred within its bounds."""
        deferred = (fw is not None and fw.load == self._answered_load
                    and self._clock.now() - self._answered_at < MAX_DEFER_S)
        return max(self._quiet_until, self._defer_until if deferred else -float('inf'))

    def offer(self, fw) -> None:
        """The newest usable equilibrium (the thread takes the newest when it wakes)."""
        if fw is not None and fw.success:
            self._fw = fw
            self._wake.set()

    def _answer(self, fw) -> None:
        before = self.result
        self._answered_at, self._answered_load = self._clock.now(), fw.load
        res = self.check.update(fw, self._answered_at)
        if res is None or self._stop.is_set():   # (stopped meanwhile: nobody listens)
            return
        self.result = res
        for fn in self._listeners:
            fn(before, res)

    def _loop(self) -> None:
        background()   # (not on the command path: the normal scheduler, whatever the node's)
        log = self.node.get_logger()
        while not self._stop.is_set():
            self._wake.wait(_POLL_S)
            self._wake.clear()
            # the thread waits on the wall clock; what it waits for is in control time
            while not self._stop.is_set():   # (looked at again: simulated time, a new load)
                left = self._held_off_until(self._fw) - self._clock.now()
                if left <= 0.0:
                    break
                self._stop.wait(min(left, _QUIET_POLL_S))
            fw = self._fw
            if self._stop.is_set() or fw is None or not self.check.due(fw, self._clock.now()):
                continue
            try:
                self._answer(fw)
            except Exception as exc:  # noqa: BLE001 - a modal analysis never stops the node
                if self._stop.is_set():
                    return
                log.error(f'first mode not computed: {type(exc).__name__}: {exc}',
                          throttle_duration_sec=10.0)
