"""The outlier gate of the motion-capture inputs: far from the median of the recent samples.

A swapped or ghost marker moves one sample by centimetres; a real motion moves
the samples together.  :class:`MedianGate` refuses a sample farther than its
limit from the (component-wise) median of the last ``window`` received
samples, this one excluded; every received sample joins the window, so a
lasting change moves the median and is accepted a few samples later.  Used by
the closed loop (:class:`~._feedback.IntegralFeedback`) and the force
estimator (:class:`~._force_estimator.TipForceEstimator`).
"""

from __future__ import annotations

from collections import deque
from typing import Callable

import numpy as np

__all__ = ['MedianGate', 'WINDOW']

#: Received samples whose median a new one is compared with.
WINDOW = 5


def _euclidean(x: np.ndarray, median: np.ndarray) -> float:
    return float(np.linalg.norm(x - median))


def _median(values) -> float:
    """The median of a few floats, as ``np.median`` gives it (the mean of the middle two).

    Sorted in Python: ``np.median`` of a handful of values cost some 40 us,
    at every motion-capture sample of the closed loop.
    """
    v = sorted(values)
    n = len(v)
    return v[n // 2] if n % 2 else (v[n // 2 - 1] + v[n // 2]) / 2.0


class MedianGate:
    """Refuses a sample farther than ``limit`` from the median of the last ``window`` received.

    ``distance(sample, median)`` measures it (default: Euclidean); no sample
    is refused before three have been received.
    """

    def __init__(self, limit: float, window: int = WINDOW,
                 distance: Callable[[np.ndarray, np.ndarray], float] = _euclidean) -> None:
        """An empty gate."""
        self.limit = float(limit)
        self._distance = distance
        self._recent: deque = deque(maxlen=int(window))   # the samples, as tuples of floats

    def refuses(self, sample: np.ndarray) -> bool:
        """True when ``sample`` is an outlier; it joins the window either way."""
        x = np.asarray(sample, dtype=float).ravel()
        far = (len(self._recent) >= 3 and self._distance(
            x, np.array([_median(c) for c in zip(*self._recent)])) > self.limit)
        self._recent.append(tuple(x.tolist()))
        return far
