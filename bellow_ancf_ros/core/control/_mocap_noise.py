"""The motion capture's noise, read from its own samples, and the gain it allows.

An integral loop on measured poses passes the measurement noise on to the
robot: with gain ``k`` [1/s] and the mean of the samples of each control
step integrated, a white noise of ``sigma`` per axis at ``f`` samples per
second moves the correction, and with it the robot, by about
``sigma sqrt(k / (2 f))`` per axis (the variance of a first-order low-pass
of bandwidth ``k`` fed with ``f`` independent samples a second), ``sigma
sqrt(3 k / (2 f))`` in position.  On the robot family (``bench/family_bench.py``)
the one-segment robots with a 0.25-0.3 mm motion capture at 60-100 Hz held
their target at 0.11-0.14 mm RMSE under the automatic gain of about 6.4 /s,
all of it noise (seed 56: 0.135 mm, 0.000 mm with the noise taken out),
while the margins allowed the gain.

:class:`MocapNoise` estimates ``sigma`` from the samples themselves: the
second difference ``x[i+1] - 2 x[i] + x[i-1]`` of evenly spaced samples
cancels a smooth motion (what is left of it is the acceleration times the
period squared: 0.03 mm for the paper's circle at ten times its speed at
60 Hz) and has the variance ``6 sigma^2`` for white noise; its median
absolute value over the three axes (times 1.4826, the normal's factor) is
robust against outliers, a dropout's gap and the start of a step.
:meth:`MocapNoise.gain_cap` is the gain at which that noise moves the robot
by :data:`NOISE_BUDGET_M` RMS: the automatic gain is held below it
(:meth:`~._feedback.IntegralFeedback.gain_per_s`), a gain set by hand is
not, and it never goes below :data:`NOISE_GAIN_FLOOR_PER_S` (a correction
that still learns within seconds: a motion capture too noisy for the budget
then costs more than it).  A quiet motion capture (0.05 mm at 120 Hz)
allows 80 /s, far above what the margins allow: the cap only acts on a
noisy or slow one.

The cap is for an error that is noise.  An error the robot really has (a
step's remainder, a creep the controller does not know, the lag of a fast
path) is larger than the noise of its own mean, and a capped gain only
corrects it later: on the uncalibrated one-segment robots of the family the
cap alone took the circle at ten times the paper's speed from 0.264 to
0.311 mm (95th percentile).  :meth:`MocapNoise.allowed_gain` therefore
gives the full automatic gain while the mean error over
:data:`NOISE_GATE_S` is more than twice :data:`GATE_NOISE_FACTOR` times the
RMS that noise alone gives that mean, the cap while it is within
:data:`GATE_NOISE_FACTOR` times it, and a gain in proportion between.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

__all__ = ['GATE_NOISE_FACTOR', 'MocapNoise', 'NOISE_BUDGET_M', 'NOISE_GAIN_FLOOR_PER_S',
           'NOISE_GATE_S', 'NOISE_WINDOW']

#: The RMS position error [m] the motion capture's noise may cause through the automatic gain
#: (half the one-segment held-target goal of 0.1 mm: the other half is the loop's own).
NOISE_BUDGET_M = 0.05e-3
#: The noise never holds the automatic gain below this [1/s] (a correction time of 1 s).
NOISE_GAIN_FLOOR_PER_S = 1.0
#: The time constant [s] of the mean error the cap is gated on (:meth:`MocapNoise.allowed_gain`).
NOISE_GATE_S = 0.5
#: The mean error is noise while within this many times the RMS noise alone gives it.
GATE_NOISE_FACTOR = 2.0
#: Samples the noise is estimated from (0.5 s at 240 Hz, 2 s at 60 Hz).
NOISE_WINDOW = 120
#: Samples (second differences) needed before the estimate is used.
_MIN_TRIPLES = 30
#: New samples between two estimates (the median of a window is not free).
_EVERY = 10
#: A gap between samples longer than this many median periods (a dropout) ends a triple.
_GAP = 1.5


class MocapNoise:
    """The noise of the accepted measured positions (per axis) and their rate."""

    def __init__(self, window: int = NOISE_WINDOW) -> None:
        """No samples yet."""
        self._t: deque = deque(maxlen=int(window))
        self._p: deque = deque(maxlen=int(window))
        self._new = 0
        self.sigma_m: float | None = None    #: noise per axis [m] (None: too few samples)
        self.rate_hz: float | None = None    #: samples per second (median period)

    def add(self, t: float, position: np.ndarray) -> None:
        """One accepted sample captured at ``t`` [s]."""
        if self._t and t <= self._t[-1]:    # out of order or repeated: not a new sample
            return
        self._t.append(float(t))
        self._p.append(np.asarray(position, dtype=float).reshape(3))
        self._new += 1
        if self._new >= _EVERY:
            self._new = 0
            self._estimate()

    def _estimate(self) -> None:
        t = np.fromiter(self._t, dtype=float)
        if t.size < 3:
            return
        dt = np.diff(t)
        period = float(np.median(dt))
        even = (dt[:-1] < _GAP * period) & (dt[1:] < _GAP * period)
        if np.count_nonzero(even) < _MIN_TRIPLES:
            return
        p = np.asarray(self._p)
        d2 = (p[2:] - 2.0 * p[1:-1] + p[:-2])[even]
        self.sigma_m = 1.4826 * float(np.median(np.abs(d2))) / math.sqrt(6.0)
        self.rate_hz = 1.0 / period

    def gain_cap(self, budget_m: float = NOISE_BUDGET_M) -> float:
        """The largest integral gain [1/s] whose noise stays within ``budget_m`` RMS.

        At least :data:`NOISE_GAIN_FLOOR_PER_S`; ``inf`` while the noise is
        not known yet (or is zero).
        """
        if self.sigma_m is None or self.sigma_m <= 0.0:
            return math.inf
        return max(2.0 * self.rate_hz * budget_m ** 2 / (3.0 * self.sigma_m ** 2),
                   NOISE_GAIN_FLOOR_PER_S)

    def mean_error_noise_m(self, tau_s: float = NOISE_GATE_S) -> float | None:
        """The RMS [m] of a position error's mean over ``tau_s`` when the error is noise alone.

        The mean is an exponential one with time constant ``tau_s`` of the
        samples' errors (``f`` a second): per axis ``sigma / sqrt(2 f tau)``,
        over the three axes ``sqrt(3)`` times that.  None while the noise is
        not known.
        """
        if self.sigma_m is None:
            return None
        return self.sigma_m * math.sqrt(3.0 / (2.0 * self.rate_hz * float(tau_s)))

    def allowed_gain(self, gain_per_s: float, mean_error_m: float | None,
                     tau_s: float = NOISE_GATE_S) -> float:
        """The automatic gain ``gain_per_s`` [1/s] as the noise allows it, given the error.

        ``mean_error_m``: the norm of the position error's mean over
        ``tau_s`` (None: not known yet).  The cap (:meth:`gain_cap`) while
        that mean is within :data:`GATE_NOISE_FACTOR` times its noise
        (:meth:`mean_error_noise_m`), ``gain_per_s`` from twice that on,
        linear between; never above ``gain_per_s``.
        """
        cap = self.gain_cap()
        if gain_per_s <= cap:
            return gain_per_s
        s = self.mean_error_noise_m(tau_s)
        if mean_error_m is None or not s:
            return cap
        w = min(max(mean_error_m / (GATE_NOISE_FACTOR * s) - 1.0, 0.0), 1.0)
        return cap + w * (gain_per_s - cap)

    def status(self) -> dict:
        """Diagnostics values: the noise and the gain it allows."""
        cap = self.gain_cap()
        return {'mocap_noise_mm': 'unknown' if self.sigma_m is None
                else f'{self.sigma_m * 1e3:.3f}',
                'noise_gain_cap_per_s': 'none' if math.isinf(cap) else f'{cap:.3g}'}
