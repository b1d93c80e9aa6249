"""The nodes' solve loop helpers (no rclpy import): model, latest-only worker, slices, statistics.

* :func:`ready_model`: a robot's model ready for a control loop (loaded, its
  vent equilibrium, nothing left to compile or search at the first target);
* :class:`LatestWorker`: a worker thread that always processes the newest
  item only (older ones are overwritten, so memory stays bounded) at a
  bounded rate;
* :class:`BudgetSlices`: the budget slices of one item (a solve its
  wall-clock budget stopped goes on in the next);
* :class:`SolveStats`: solve-time statistics and the age of the last solve
  for the status heartbeat.
"""

from __future__ import annotations

import gc
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from ..core import RobotModel, load_robot, precompute_corners, solve_forward, warm_up
from . import contract

__all__ = ['BURST', 'BudgetSlices', 'LatestWorker', 'SolveStats', 'ready_model']

#: Starts the latest-only worker may make back to back after an idle period (token bucket).
BURST = 2


# ------------------------------------------------------------ the model
def ready_model(robot_config: str, payload_kg: float = 0.0) -> tuple:
    """A robot's model ready for a control loop: ``(cfg, model, vented, start)``.

    ``robot_config``: a shipped robot name or a robot YAML path
    (:func:`~bellow_ancf_ros.core.load_robot`; ConfigError, ValueError or
    OSError when it cannot be used).  ``vented``: the straight robot at vent
    pressure, no payload (the forward result that is the first warm start);
    ``start``: the vented robot carrying ``payload_kg`` (``vented`` itself
    without payload), where the loop starts (its automatic gain).  The
    corners of the pressure box, needed by the first unreachable target, are
    precomputed and the warm-started path's kernels compiled (or loaded)
    now, not at the first target.
    """
    cfg = load_robot(robot_config)
    model = RobotModel(cfg)
    vent = contract.vent_pressures(model.A, cfg.p_min, cfg.p_max)
    vented = solve_forward(model, vent)   # (also warms caches)
    start = vented if payload_kg == 0.0 else solve_forward(model, vent, payload_kg=payload_kg)
    precompute_corners(model, payload_kg)
    warm_up(model)
    gc.freeze()   # out of the collector's full passes, as what start-up built (main_for)
    return cfg, model, vented, start


# ------------------------------------------------------------ latest-only
class LatestWorker:
    """Process only the newest submitted item, in a worker thread, at a bounded rate.

    ``submit(item)`` stores ``item`` in a single slot (overwriting an item not
    yet processed, which counts as dropped) and wakes the worker.  The worker
    calls ``process(item)`` for the newest item.  Memory is one item, whatever
    the input rate.

    The rate is bounded by a token bucket: a start takes a credit, credits
    come back one per ``min_period()`` seconds, at most :data:`BURST` held.
    So the long-run rate is at most ``1 / min_period()``, an item arriving
    after an idle period starts at once, and a stream at exactly the limit
    rate (with its jitter) is answered as it comes: a fixed spacing of one
    period after the previous *start* would instead carry every late
    arrival's lag over to the next (a queue at full load), measured as 8.5 ms
    median latency at 100 Hz against 1-2 ms of solve.
    Exceptions from ``process`` are passed to ``on_error`` (default: ignored) and
    the worker keeps running.
    """

    def __init__(self, process: Callable[[Any], None],
                 min_period: Callable[[], float] = lambda: 0.0,
                 on_error: Callable[[BaseException], None] | None = None,
                 name: str = 'latest-worker', on_done: Callable[[], None] | None = None) -> None:
        self._process = process
        self._on_done = on_done   # after each item, once idle or not (e.g. a lockstep report)
        self._min_period = min_period
        self._on_error = on_error
        self._cond = threading.Condition()
        self._item: Any = None
        self._has_item = False
        self._stop = False
        self._busy = False
        self._last_start = -math.inf
        # the start credit is the CPU's: wall clock even under use_sim_time (as its waits)
        self._credit, self._credit_t = float(BURST), time.monotonic()
        self.submitted = 0
        self.resubmitted = 0   # (queued again: a re-solve, a budget slice)
        self.dropped = 0
        self.processed = 0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, item: Any) -> None:
        with self._cond:
            if self._has_item:
                self.dropped += 1
            self._item = item
            self._has_item = True
            self.submitted += 1
            self._cond.notify_all()

    def resubmit(self, item: Any) -> bool:
        """Queue ``item`` again unless a newer item is pending; return whether queued."""
        with self._cond:
            if self._has_item or self._stop:
                return False
            self._item = item
            self._has_item = True
            self.resubmitted += 1
            self._cond.notify_all()
            return True

    def clear(self) -> None:
        """Drop a pending item (not yet started)."""
        with self._cond:
            if self._has_item:
                self.dropped += 1
            self._item = None
            self._has_item = False

    @property
    def pending(self) -> bool:
        with self._cond:
            return self._has_item

    def idle(self) -> bool:
        """True when no item is pending and none is being processed."""
        with self._cond:
            return not self._has_item and not self._busy

    def wait_idle(self, timeout: float) -> bool:
        """Wait until :meth:`idle` (or ``timeout`` seconds); return whether idle."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._has_item or self._busy:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.05))
            return True

    def _take_credit(self) -> float:
        """Take a start credit (returns 0), or return the seconds until one is due."""
        period = max(0.0, float(self._min_period()))
        now = time.monotonic()
        if period <= 0.0:
            return 0.0
        self._credit = min(float(BURST), self._credit + (now - self._credit_t) / period)
        self._credit_t = now
        if self._credit >= 1.0:
            self._credit -= 1.0
            return 0.0
        return (1.0 - self._credit) * period

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._has_item and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                # bounded rate (token bucket); newer items arriving meanwhile replace the
                # pending one
                while not self._stop:
                    left = self._take_credit()
                    if left <= 0:
                        break
                    self._cond.wait(left)
                if self._stop:
                    return
                if not self._has_item:
                    continue
                item = self._item
                self._item = None
                self._has_item = False
                self._busy = True
                self._last_start = time.monotonic()
            try:
                self._process(item)
            except BaseException as exc:  # noqa: BLE001 - the worker must survive
                if self._on_error is not None:
                    try:
                        self._on_error(exc)
                    except Exception:  # noqa: BLE001
                        pass
            finally:
                with self._cond:
                    self._busy = False
                    self.processed += 1
                    self._cond.notify_all()
                if self._on_done is not None:
                    self._on_done()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the worker (a running ``process`` call is waited for up to ``timeout``)."""
        with self._cond:
            self._stop = True
            self._item = None
            self._has_item = False
            self._cond.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)


# ------------------------------------------------------------ budget slices
class BudgetSlices:
    """The budget slices of one item: a solve its wall-clock budget stopped goes on in the next.

    After a budget-limited solve, :meth:`next` queues the same item again
    (``queue(item)``, which may refuse), as long as fewer than
    ``max_slices`` slices of it ran in a row.  A slice with no usable answer
    hands that answer on: the next slice of the same item starts from it
    (:meth:`warm_start`), not from the last good solve.  Used by one solve
    thread (not thread-safe).
    """

    def __init__(self, max_slices: int) -> None:
        self.max_slices = int(max_slices)
        self._item: Any = None
        self._count = 0          # slices of ``_item`` in a row
        self._resume: tuple | None = None   # (item, its unusable budget-limited answer)

    def warm_start(self, item: Any, warm: Any) -> Any:
        """The warm start of a solve of ``item``: ``warm``, or its previous slice's answer.

        The previous slice's answer only when it was not usable and ``item``
        is its item; taken once either way.
        """
        resume, self._resume = self._resume, None
        return resume[1] if resume is not None and resume[0] is item else warm

    def next(self, item: Any, queue: Callable[[Any], bool], unusable: Any = None) -> bool:
        """Queue the next slice of ``item`` after a budget-limited solve; whether queued.

        ``queue(item)``: queues it, or refuses (False); not called once
        ``max_slices`` slices of ``item`` ran in a row.  ``unusable``: the
        solve's answer when it was not usable (the next slice goes on from it).
        """
        self._count = self._count + 1 if item is self._item else 1
        self._item = item
        more = self._count < self.max_slices and bool(queue(item))
        if more and unusable is not None:
            self._resume = (item, unusable)
        return more


# ------------------------------------------------------------ statistics
class SolveStats:
    """Solve-time statistics over the last ``window`` solves, and the age of the last one.

    ``record(seconds, ok)`` after every solve; :meth:`summary` gives the count,
    the last/median/95th-percentile/maximum solve time over the window [s],
    the age of the last solve [s] (None before the first) and whether it
    succeeded.  Memory is bounded by ``window``.  Thread-safe.  Wall-clock
    seconds (``clock``), whatever the node's clock: they describe the computer.
    """

    def __init__(self, window: int = 1000, clock: Callable[[], float] = time.monotonic) -> None:
        self._times: deque = deque(maxlen=int(window))
        self._clock = clock
        self._lock = threading.Lock()
        self.count = 0
        self.failures = 0
        self._last_end: float | None = None
        self._last_ok: bool | None = None

    def record(self, seconds: float, ok: bool = True) -> None:
        """Record one solve that took ``seconds`` and ended now."""
        with self._lock:
            self._times.append(float(seconds))
            self.count += 1
            self.failures += 0 if ok else 1
            self._last_end = self._clock()
            self._last_ok = bool(ok)

    def times(self) -> list:
        """The solve times in the window [s], oldest first."""
        with self._lock:
            return list(self._times)

    def summary(self) -> dict:
        """Statistics as a dict (None where there is no solve yet).

        Keys: ``count``, ``failures``, ``window``, ``last_s``, ``median_s``,
        ``p95_s``, ``max_s``, ``last_solve_age_s``, ``last_ok``.
        """
        with self._lock:
            t = np.array(self._times, dtype=float)
            last_end, last_ok = self._last_end, self._last_ok
            count, failures = self.count, self.failures
        empty = t.size == 0
        return {
            'count': count,
            'failures': failures,
            'window': int(t.size),
            'last_s': None if empty else float(t[-1]),
            'median_s': None if empty else float(np.median(t)),
            'p95_s': None if empty else float(np.percentile(t, 95)),
            'max_s': None if empty else float(t.max()),
            'last_solve_age_s': None if last_end is None else self._clock() - last_end,
            'last_ok': last_ok,
        }
