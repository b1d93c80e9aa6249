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
        self._recent: deque = deque(maxlen=int(window))

    def refuses(self, sample: np.ndarray) -> bool:
        """True when ``sample`` is an outlier; it joins the window either way."""
        far = (len(self._recent) >= 3 and self._distance(
            sample, np.median(np.array(self._recent), axis=0)) > self.limit)
        self._recent.append(sample)
        return far
