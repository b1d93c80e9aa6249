"""When a solve's command goes out: on the target stream's own grid, not when its solve ends.

A node that publishes each command as soon as its solve ends sends the
robot a staircase whose steps come at the times its computer allowed: the
target's transport, the queue and the solve time, 6-7 ms median and up to
20-40 ms at the 99th percentile on a shared 2-core machine.  Even with each
step's pressures right for the time it goes out, the irregular steps are a
broadband input that rings a lightly damped mode: simulated on the
two-segment robot's 10x circle, a solve time of 6 ms plus an exponential
3 ms gave 0.24-0.28 mm RMSE against 0.06 mm for a constant delay of 6 or
20 ms; publishing the same solves at a fixed 20 ms after their targets gave
0.06-0.14 mm.

:class:`CommandPacer` gives each command of a stream its time: the target's
*regular intake* (its pose's time on the stream's grid,
:meth:`StreamFeedforward.stream_tick`, plus the stream's usual age when it
arrived: the median of the last
:data:`~._dynamic_feedforward.AGES_KEPT`) plus a margin, the
:data:`QUANTILE` of how long after its regular intake each of the last
:data:`WINDOW` commands was ready (at most :data:`MAX_MARGIN_S`, and at most
the stream's interval).  A command ready before its time waits for it; a
late one goes out when ready.  The margin is known when the solve starts,
so the pose solved is the one wanted when the command goes out (the
feedforward carries it there).  The margin follows the computer's load
slowly (a quantile over two seconds of a 50 Hz stream).  A command's wait
never enters its own timing: the ages are taken at the targets' arrival
(when the solve of one started after the previous command's wait, taking
that start for its intake fed the wait back into the next command's time:
a margin past the stream's interval then grew by itself, in ROS to 25 ms at
50 Hz, and the commands came every 40 ms).
"""

from __future__ import annotations

import statistics
from collections import deque

import numpy as np

from ._dynamic_feedforward import AGES_KEPT   # (the usual age: the carry's and the pacer's)

__all__ = ['CommandPacer']

#: Commands whose readiness the margin is taken over.
WINDOW = 100
#: The share of them that should be ready by their time (0.9: a tenth late, and a mode
#: rang 1.1-1.6x as much as at 0.95 in test_pacing.py's trials).
QUANTILE = 0.95
#: Readiness samples before the first paced command (until then: at once).
MIN_SAMPLES = 10
#: The largest margin [s]: beyond it a busy computer's commands go out when ready.
MAX_MARGIN_S = 0.04


class CommandPacer:
    """Commands of a stream at its regular intake plus a margin (the module's docstring)."""

    def __init__(self, window: int = WINDOW, quantile: float = QUANTILE,
                 max_margin_s: float = MAX_MARGIN_S, min_samples: int = MIN_SAMPLES) -> None:
        if not 0.0 < quantile <= 1.0 or window < 1 or max_margin_s < 0 or min_samples < 1:
            raise ValueError(f'CommandPacer: quantile {quantile!r} must be in (0, 1], window '
                             f'{window!r} and min_samples {min_samples!r} at least 1, '
                             f'max_margin_s {max_margin_s!r} at least 0')
        self.quantile, self.max_margin_s = float(quantile), float(max_margin_s)
        self.min_samples = int(min_samples)
        self._ready: deque = deque(maxlen=int(window))
        self._ages: deque = deque(maxlen=AGES_KEPT)
        self._margin: float | None = None
        self.paced = self.late = 0

    def reset(self) -> None:
        """Forget the readiness and the ages seen (a new stream, another computer load)."""
        self._ready.clear()
        self._ages.clear()
        self._margin = None

    @property
    def margin_s(self) -> float | None:
        """The current margin after the regular intake [s] (None: too few samples yet)."""
        return self._margin

    def due(self, pose_t: float, arrived: float, interval: float) -> tuple:
        """``(regular intake, due)`` of a new target of the stream (due None: at once).

        ``pose_t``: its pose's time (on the grid); ``arrived``: when it
        arrived, on the same clock; ``interval``: the stream's (the margin's
        cap).  Due is None while there are too few readiness samples.
        """
        self._ages.append(float(arrived) - float(pose_t))
        regular = float(pose_t) + statistics.median(self._ages)
        if self._margin is None:
            return regular, None
        return regular, regular + min(self._margin, max(float(interval), 0.0))

    def ready(self, regular: float, at: float, due: float | None) -> float:
        """A command of the target regularly taken in at ``regular`` is ready at ``at``.

        ``regular``, ``due``: as :meth:`due` gave them when its solve started.  Returns how
        long to wait before it goes out [s] (0: now).
        """
        self._ready.append(float(at) - float(regular))
        if len(self._ready) >= self.min_samples:
            q = float(np.quantile(np.fromiter(self._ready, float), self.quantile))
            self._margin = min(max(q, 0.0), self.max_margin_s)
        if due is None:
            return 0.0
        self.paced += 1
        if at > due:
            self.late += 1
            return 0.0
        return float(due) - float(at)
