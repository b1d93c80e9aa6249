"""Input shaping of the target stream at the robot's first mode: ZV and ZVD shapers.

A step target excites the robot's first mode (docs/dynamics.md): the
two-segment robot rings at 2.4 Hz with a damping ratio of 0.05, for seconds.
An input shaper (Singer & Seering, "Preshaping command inputs to reduce
system vibration", J. Dyn. Sys. Meas. Control 112, 1990) replaces the target
by a sum of delayed copies whose vibrations cancel at the mode:
with ``K = exp(-zeta pi / sqrt(1 - zeta^2))`` and the damped period
``T_d = 1 / (f sqrt(1 - zeta^2))``,

* ZV: amplitudes ``[1, K] / (1 + K)`` at ``[0, T_d/2]``: no residual
  vibration at the exact mode;
* ZVD: ``[1, 2K, K^2] / (1 + K)^2`` at ``[0, T_d/2, T_d]``: also a zero
  derivative with respect to the frequency, so a mode known to +-20 %
  leaves a few percent of the swing (ZV: about 30 %), for twice the delay.

The shaped target is a convex combination of past targets (positions
averaged; z-axes averaged and renormalised), so it never leaves the segment
between them, and it reaches the final target after the shaper's duration.
The added delay (its centroid, ``sum A_i t_i``) is reported.
:class:`TargetShaper` follows a stream of stamped targets and may be given a
new mode at any time (a payload changes the first mode).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Callable

import numpy as np

__all__ = ['SHAPERS', 'TargetShaper', 'shaper_impulses', 'shaped']

SHAPERS = ('none', 'zv', 'zvd')


def shaper_impulses(kind: str, frequency_hz: float, damping_ratio: float):
    """``(times [s], amplitudes)`` of a shaper at a mode; ``none``: one impulse at 0."""
    if kind not in SHAPERS:
        raise ValueError(f'target_shaping = {kind!r} is not allowed; allowed: {list(SHAPERS)}')
    if kind == 'none':
        return np.zeros(1), np.ones(1)
    f, z = float(frequency_hz), float(damping_ratio)
    if not (math.isfinite(f) and f > 0 and math.isfinite(z) and 0 <= z < 1):
        raise ValueError(f'a shaper needs a frequency > 0 and a damping ratio in [0, 1), '
                         f'got ({f}, {z})')
    root = math.sqrt(1.0 - z * z)
    K = math.exp(-z * math.pi / root)
    td = 1.0 / (f * root)
    if kind == 'zv':
        return np.array([0.0, td / 2]), np.array([1.0, K]) / (1.0 + K)
    return np.array([0.0, td / 2, td]), np.array([1.0, 2 * K, K * K]) / (1.0 + K) ** 2


def _combine(amplitudes, positions, z_axes):
    p = np.einsum('i,ij->j', amplitudes, positions)
    if z_axes is None:
        return p, None
    z = np.einsum('i,ij->j', amplitudes, z_axes)
    return p, z / np.linalg.norm(z)


def shaped(target: Callable[[float], tuple], kind: str, frequency_hz: float,
           damping_ratio: float) -> Callable[[float], tuple]:
    """A target function ``t -> (position, z_axis or None)`` shaped at a mode."""
    times, amps = shaper_impulses(kind, frequency_hz, damping_ratio)

    def f(t):
        vals = [target(t - ti) for ti in times]
        zs = None if vals[0][1] is None else np.array([np.asarray(v[1], float) for v in vals])
        return _combine(amps, np.array([np.asarray(v[0], float) for v in vals]), zs)
    return f


class TargetShaper:
    """Shapes a stream of stamped targets at the current first mode (module docstring).

    :meth:`push` each target with the time it is wanted at; :meth:`at` gives
    the shaped target for any time (the newest target before each impulse's
    delayed time: a stream holds its last value).  :meth:`set_mode` changes
    the mode (the impulses change at once; the history is kept).
    """

    def __init__(self, kind: str = 'zvd', frequency_hz: float | None = None,
                 damping_ratio: float = 0.0) -> None:
        shaper_impulses(kind, 1.0, 0.0)   # checks the kind
        self.kind = kind
        self._hist: deque = deque()
        self.times, self.amplitudes = np.zeros(1), np.ones(1)
        self.frequency_hz = None
        self.damping_ratio = None
        if frequency_hz is not None:
            self.set_mode(frequency_hz, damping_ratio)

    def set_mode(self, frequency_hz: float, damping_ratio: float) -> None:
        """Shape at this mode from now on."""
        self.times, self.amplitudes = shaper_impulses(self.kind, frequency_hz, damping_ratio)
        self.frequency_hz, self.damping_ratio = float(frequency_hz), float(damping_ratio)

    @property
    def delay_s(self) -> float:
        """The shaper's added delay: the centroid of its impulses [s]."""
        return float(self.amplitudes @ self.times)

    @property
    def duration_s(self) -> float:
        """Time from a step of the target to the shaped target's arrival [s]."""
        return float(self.times[-1])

    def push(self, t: float, position, z_axis=None) -> None:
        """A target wanted from time ``t`` on (times must not decrease)."""
        z = None if z_axis is None else np.asarray(z_axis, dtype=float)
        self._hist.append((float(t), np.asarray(position, dtype=float), z))
        keep = self.duration_s + 1.0
        while len(self._hist) > 2 and self._hist[1][0] < t - keep:
            self._hist.popleft()

    def reset(self) -> None:
        """Forget the history (a new target stream starts unshaped from its first target)."""
        self._hist.clear()

    def _value(self, t: float):
        h = self._hist
        if t <= h[0][0]:
            return h[0]
        lo, hi = 0, len(h) - 1
        while lo < hi:   # the newest entry at or before t
            mid = (lo + hi + 1) // 2
            if h[mid][0] <= t:
                lo = mid
            else:
                hi = mid - 1
        return h[lo]

    def at(self, t: float):
        """The shaped target at time ``t``: ``(position, z_axis or None)``."""
        if not self._hist:
            raise ValueError('no target pushed yet')
        vals = [self._value(t - ti) for ti in self.times]
        zs = None if vals[0][2] is None else np.array([v[2] for v in vals])
        return _combine(self.amplitudes, np.array([v[1] for v in vals]), zs)
