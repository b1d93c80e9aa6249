"""An oscillation watchdog for the closed loop: a sustained or growing swing near the first mode.

An integral loop whose gain is too high for the robot's lightly damped first
mode (module ``_loop_margins``) rings itself up into a limit cycle near that
mode: the measured error swings with a growing, then a constant amplitude.
:class:`OscillationWatchdog` looks at the measured error one window of two
periods of the watched mode at a time: it fits, for each frequency of a band
around the mode (0.75 to 1.5 times it: a limit cycle sits near the mode), a
sinusoid per axis together with a quadratic trend (the slow error of a
tracked trajectory) to the error of the window, and keeps the largest
amplitude and its frequency.  It
trips when that amplitude

* stays above ``sustained_m`` (1 mm: seven times the motion capture's noise
  of 0.15 mm, above what a loop that tracks leaves) for ``sustained_windows``
  windows in a row (3: six periods) without dying out (the last at least
  0.8 of the first: the free swing after a step decays, a limit cycle
  does not), or
* grows by ``growth`` (1.4) from window to window ``growing_windows`` times
  in a row (3) and is above ``floor_m`` (0.3 mm), both as the window's
  largest amplitude and as its largest peak inside the band (an amplitude
  at least its neighbours'; the band's lowest frequency against one more
  step below it).  A loop that rings up does so at one frequency near the
  mode, a peak that soon is the window's largest amplitude; what is left
  in a window of a slow error is largest at the band's low end (a circle
  of 2 s, noise-free: its largest peak in the band is 0.48 of that).  The
  largest amplitude alone read a circle at 10x the paper's speed as a
  swing growing while it spun up (0.40-0.63 mm "growing 3 times in a row"
  at 0.75 times a 2.8-3.0 Hz mode, three two-segment robots of the
  family); the peak alone tripped on a robot whose 0.5 mm swing at its
  mode, driven by the circle, grew under that leak and stayed after the
  gain was cut (one two-segment robot of the family).

A tracked trajectory's own error is slow (a circle of 2 s and more is below
the band of every shipped robot's first mode), so it does not count.  The
caller decides what to do on a trip (the loop cuts its gain and holds its
correction: module ``_feedback``).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

__all__ = ['OscillationWatchdog', 'WatchdogTrip']

#: The band searched around the watched mode, as factors of its frequency.
BAND = np.linspace(0.75, 1.5, 16)
#: A new watched frequency within this fraction of the old one keeps the windows.
SAME_MODE = 0.05
#: A sustained swing keeps at least this share of its amplitude over its windows: a free
#: swing after a step dies out (damping ratio 0.04: to 0.36 over two windows) and is no trip.
SUSTAINED_RATIO = 0.8


class WatchdogTrip:
    """What the watchdog saw when it tripped."""

    __slots__ = ('time_s', 'frequency_hz', 'amplitude_m', 'reason')

    def __init__(self, time_s, frequency_hz, amplitude_m, reason):
        self.time_s, self.frequency_hz = float(time_s), float(frequency_hz)
        self.amplitude_m, self.reason = float(amplitude_m), reason

    @property
    def message(self) -> str:
        """One line: what it saw."""
        return (f'oscillation at {self.frequency_hz:.2f} Hz, {self.amplitude_m * 1e3:.2f} mm '
                f'({self.reason})')


class OscillationWatchdog:
    """Watches a measured error signal for a sustained or growing swing (module docstring).

    Parameters
    ----------
    frequency_hz : the watched mode (the robot's first mode at the held
        equilibrium); :meth:`set_mode` changes it.
    """

    def __init__(self, frequency_hz: float, sustained_m: float = 1e-3,
                 sustained_windows: int = 3, growth: float = 1.4, growing_windows: int = 3,
                 floor_m: float = 0.3e-3) -> None:
        self.sustained_m, self.sustained_windows = float(sustained_m), int(sustained_windows)
        self.growth, self.growing_windows = float(growth), int(growing_windows)
        self.floor_m = float(floor_m)
        self.amplitudes: deque = deque(maxlen=8)   # (frequency, amplitude) per window
        self._peaks: deque = deque(maxlen=8)       # the largest peak's amplitude per window
        self._samples: list = []
        self._start: float | None = None
        self.trips = 0
        self.last_trip: WatchdogTrip | None = None
        self.set_mode(frequency_hz)

    def set_mode(self, frequency_hz: float) -> None:
        """Watch another mode (a payload moved it); the windows start again.

        A move within :data:`SAME_MODE` of the watched frequency (the
        equilibrium drifting as the loop corrects; recomputed every two
        seconds) keeps the windows: a reset on every such move kept a
        ringing loop's windows from ever adding up to a trip.
        """
        f = float(frequency_hz)
        if not (math.isfinite(f) and f > 0):
            raise ValueError(f'watched frequency must be > 0, got {frequency_hz!r}')
        old = getattr(self, 'frequency_hz', None)
        self.frequency_hz = f
        self.window_s = 2.0 / f
        if old is None or abs(f - old) > SAME_MODE * old:
            self.reset()

    def reset(self) -> None:
        """Forget the samples and the windows (after a trip, or a new target)."""
        self._samples = []
        self._start = None
        self.amplitudes.clear()
        self._peaks.clear()
        self._recent = deque(maxlen=3)

    def _fit(self, t: np.ndarray, e: np.ndarray, band=BAND):
        """Largest sinusoid amplitude over the band, its frequency, and the largest peak's.

        Returns ``(amplitude, frequency, peak amplitude)``; a peak is an
        amplitude at least its neighbours' on the band, the band's lowest
        frequency compared with one more step below it (0 when there is
        none: the window's content rises below the band).  The trend's
        columns are scaled to the window (conditioning), and no amplitude
        counts beyond the error's own largest deviation: a fit on samples
        bunched in a corner of the window cannot invent a swing.
        """
        t = t - t[0]
        u = t / max(t[-1], 1e-12)
        base = np.column_stack([np.ones_like(u), u, u * u])
        cap = float(np.max(np.linalg.norm(e - e.mean(axis=0), axis=1)))
        factors = np.concatenate([[2 * band[0] - band[1]], band])   # one step below the band
        amps = np.empty(len(factors))
        for i, factor in enumerate(factors):
            w = 2 * math.pi * factor * self.frequency_hz
            X = np.column_stack([base, np.cos(w * t), np.sin(w * t)])
            coef, *_ = np.linalg.lstsq(X, e, rcond=1e-8)
            amps[i] = min(float(np.sqrt((coef[3:] ** 2).sum())), cap)   # all axes together
        inner = amps[1:]
        right = np.append(inner[1:], -np.inf)   # (the band's top: against its left only)
        peaks = inner[(inner >= amps[:-1]) & (inner >= right)]
        k = int(np.argmax(inner))
        return (float(inner[k]), float(band[k] * self.frequency_hz),
                float(peaks.max()) if peaks.size else 0.0)

    def feed(self, t: float, error) -> WatchdogTrip | None:
        """One measured error (3-vector [m]) at time ``t``; a :class:`WatchdogTrip` on a trip."""
        if self._start is None:
            self._start = float(t)
        self._samples.append((float(t), np.asarray(error, dtype=float).reshape(-1)))
        if t - self._start < self.window_s:
            return None
        ts = np.array([s[0] for s in self._samples])
        es = np.array([s[1] for s in self._samples])
        self._samples, self._start = [], float(t)
        self._recent.append((ts, es))
        # a window the samples do not cover (a dropout, a late burst) is not judged
        gaps = np.diff(np.concatenate([[ts[0]], ts, [ts[0] + self.window_s]]))
        if len(ts) < 8 or ts[-1] - ts[0] < 0.75 * self.window_s or gaps.max() > 0.25 * (
                self.window_s):
            return None
        amp, freq, peak = self._fit(ts, es)
        self.amplitudes.append((freq, amp))
        self._peaks.append(peak)
        a = [x[1] for x in self.amplitudes]
        reason = None
        n = self.sustained_windows
        if (len(a) >= n and min(a[-n:]) > self.sustained_m
                and a[-1] >= SUSTAINED_RATIO * a[-n]):   # not a free swing dying out
            reason = f'above {self.sustained_m * 1e3:g} mm for {2 * n} periods'
        g = self.growing_windows
        pk = list(self._peaks)
        if len(pk) > g and pk[-1] > self.floor_m and all(
                pk[-i] > self.growth * pk[-i - 1] and a[-i] > self.growth * a[-i - 1]
                for i in range(1, g + 1)):
            reason = f'growing {g} times in a row'
        if reason is None:
            return None
        # the frequency seen, over the last windows (a finer resolution than one window's)
        ts = np.concatenate([w[0] for w in self._recent])
        es = np.concatenate([w[1] for w in self._recent])
        freq = self._fit(ts, es, np.linspace(BAND[0], BAND[-1], 76))[1]
        self.trips += 1
        self.last_trip = WatchdogTrip(t, freq, amp, reason)
        self.amplitudes.clear()
        self._peaks.clear()
        return self.last_trip
