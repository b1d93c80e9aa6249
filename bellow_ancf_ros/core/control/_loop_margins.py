"""Stability margins of the integral loop, with the robot's own modes (docs/closed_loop.md).

Seen from the integral correction, the robot answers like the regulators (a
first-order lag ``tau`` after a delay ``T``: regulator dead time, mocap
latency, half a control period, half a measurement period) followed by the
robot's structure: each lateral mode of natural frequency ``w_i`` and
damping ratio ``zeta_i`` (:func:`~bellow_ancf_ros.core.dynamics.natural_modes`
at the held equilibrium) is a second-order factor of unit static gain.  The
open loop is::

    L(s) = k exp(-s T) / (s (tau s + 1)) * prod_i w_i^2 / (s^2 + 2 zeta_i w_i s + w_i^2)

Every factor's phase falls monotonically with frequency, so the phase
crosses -180 deg (and -540, ...) exactly once each; the largest stable gain
is ``k_max = min over those crossings of 1 / |L_1(jw)|`` (``L_1``: the loop
at unit gain), which is exact for this loop (stable at small gains: a
stable plant under a slow integrator).  A lightly damped mode puts a peak of
about ``1 / (2 zeta)`` into ``|L|`` near its frequency, where the phase is
already past -180 deg: the gain margin falls by that factor, and a gain that
is safe for the regulators alone can ring the robot up (a limit cycle near
the mode).  Without modes the closed forms of the first-order loop are used.

:data:`MIN_GAIN_MARGIN` and :data:`MIN_PHASE_MARGIN_DEG` are the margins the
package asks of a loop (a gain margin of 3 leaves room for a model-robot
mismatch of the static gain and of the mode's peak; 45 deg for the lag and
delay the loop does not know exactly); :func:`safe_gain` is the largest gain
that keeps both.  No third-party control library: the exact delay has no
rational transfer function, and the analytic phase above needs none.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import numpy as np
from scipy.optimize import brentq

__all__ = ['LOOP_DELAY_S', 'LOOP_LAG_S', 'LoopMargins', 'MIN_GAIN_MARGIN', 'MIN_PHASE_MARGIN_DEG',
           'loop_delay_s', 'loop_margins', 'safe_gain']

#: The smallest gain margin the package accepts for the integral loop.
MIN_GAIN_MARGIN = 3.0
#: The smallest phase margin the package accepts for the integral loop [deg].
MIN_PHASE_MARGIN_DEG = 45.0
#: The loop's lag and delay for its margins: the inverse node's ``feedback_loop_lag_s`` and
#: ``feedback_loop_delay_s`` defaults.
LOOP_LAG_S, LOOP_DELAY_S = 0.06, 0.05


class LoopMargins(NamedTuple):
    """Stability margins of the integral loop (see :func:`loop_margins`)."""

    phase_margin_deg: float       #: phase lag that puts a gain crossover on -1 (< 0: unstable)
    gain_margin: float            #: factor on the gain that puts the loop at its limit (inf: none)
    crossover_rad_s: float        #: gain crossover frequency (the lowest, if several)
    max_gain_per_s: float         #: the gain at the stability limit (``gain * gain_margin``)
    delay_margin_s: float         #: extra delay the loop tolerates (``phase margin / crossover``)
    limit_rad_s: float = math.inf  #: where the loop oscillates at the limit gain (inf: never)

    @property
    def limit_hz(self) -> float:
        """Frequency of the oscillation at the stability limit [Hz]."""
        return self.limit_rad_s / (2 * math.pi)


def loop_delay_s(dead_time_s: float, latency_s: float, control_rate_hz: float,
                 measurement_rate_hz: float) -> float:
    """The loop's delay ``T``: dead time, latency, half a control and half a measurement period."""
    return (float(dead_time_s) + float(latency_s) + 0.5 / float(control_rate_hz)
            + 0.5 / float(measurement_rate_hz))


def _checked(k, tau, T, modes):
    if not (math.isfinite(k) and k > 0):
        raise ValueError(f'gain_per_s must be > 0, got {k}')
    for name, v in (('lag_s', tau), ('delay_s', T)):
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f'{name} must be >= 0, got {v}')
    out = []
    for f, z in modes:
        f, z = float(f), float(z)
        if not (math.isfinite(f) and f > 0 and math.isfinite(z) and z >= 0):
            raise ValueError(f'a mode needs a frequency > 0 and a damping ratio >= 0, '
                             f'got ({f}, {z})')
        out.append((2 * math.pi * f, z))
    return out


def _phase(w, tau, T, modes):
    ph = -math.pi / 2 - np.arctan(w * tau) - w * T
    for wn, z in modes:
        ph = ph - np.arctan2(2 * z * wn * w, wn * wn - w * w)
    return ph


def _log_gain(w, tau, T, modes):
    """``log |L_1(jw)|`` (unit gain)."""
    g = -np.log(w) - 0.5 * np.log1p((w * tau) ** 2)
    for wn, z in modes:
        g = g + 2 * np.log(wn) - 0.5 * np.log((wn * wn - w * w) ** 2 + (2 * z * wn * w) ** 2)
    return g


def _w_top(tau, T, ms) -> float:
    """The top of the frequency range searched [rad/s]: far above the modes, lag and delay."""
    w = max(max(wn for wn, _ in ms) * 50.0, 50.0 / max(tau, 1e-3), 1e3)
    return max(w, 20 * math.pi / T) if T > 0 else w


def loop_margins(gain_per_s: float, lag_s: float, delay_s: float,
                 modes: Sequence[tuple[float, float]] = ()) -> LoopMargins:
    """Margins of the integral loop (module docstring).

    Parameters
    ----------
    gain_per_s : integral gain ``k`` [1/s].
    lag_s, delay_s : the regulators' time constant and the loop's delay
        (:func:`loop_delay_s`).
    modes : ``(frequency_hz, damping_ratio)`` of the robot's modes that the
        correction excites (its first lateral modes at the held equilibrium);
        empty: the quasi-static robot.
    """
    k, tau, T = float(gain_per_s), float(lag_s), float(delay_s)
    ms = _checked(k, tau, T, modes)
    if not ms:
        w_c = brentq(lambda w: w * math.hypot(1.0, w * tau) - k, 0.0, k) if tau > 0 else k
        pm = math.pi / 2 - math.atan(w_c * tau) - w_c * T
        if T > 0:
            w_180 = brentq(lambda w: math.atan(w * tau) + w * T - math.pi / 2, 0.0,
                           math.pi / (2 * T))
            gm = w_180 * math.hypot(1.0, w_180 * tau) / k
        else:
            w_180, gm = math.inf, math.inf
        return LoopMargins(math.degrees(pm), gm, w_c, k * gm, pm / w_c if pm > 0 else 0.0,
                           w_180)
    w_top = _w_top(tau, T, ms)
    # phase crossings of -180, -540, ... deg: each exactly once (the phase falls monotonically)
    k_max, w_lim = math.inf, math.inf
    n = 0
    while True:
        level = -math.pi * (2 * n + 1)
        f = lambda w: _phase(w, tau, T, ms) - level  # noqa: E731
        if f(w_top) > 0:
            break
        w_n = brentq(f, 1e-9, w_top, xtol=1e-12, rtol=1e-12)
        g = math.exp(-_log_gain(w_n, tau, T, ms))
        if g < k_max:
            k_max, w_lim = g, w_n
        n += 1
        if n > 50:
            break
    return _with_crossovers(k, tau, T, ms, w_top, k_max, w_lim)


def _with_crossovers(k, tau, T, ms, w_top, k_max, w_lim) -> LoopMargins:
    """The margins at gain ``k`` given the stability limit ``(k_max, w_lim)``."""
    # gain crossovers (|L| = 1): |L| need not fall monotonically near a mode
    grid = np.geomspace(1e-6, w_top, 20000)
    lg = _log_gain(grid, tau, T, ms) + math.log(k)
    idx = np.flatnonzero(np.sign(lg[:-1]) != np.sign(lg[1:]))
    crossings = [brentq(lambda w: _log_gain(w, tau, T, ms) + math.log(k), grid[i],
                        grid[i + 1], xtol=1e-12, rtol=1e-12) for i in idx]
    # phase margin of each crossover: the extra phase lag that would put it on -1, i.e. down
    # to the next odd multiple of -180 deg (a crossover past -180 near a mode's peak, at
    # -300 deg say, is 240 deg from -540); an unstable loop gets its most negative wrapped one
    stable = k < k_max
    pms = []
    for wc in crossings:
        ph = float(_phase(wc, tau, T, ms)) + math.pi
        pm = ph % (2 * math.pi) if stable else (ph + math.pi) % (2 * math.pi) - math.pi
        pms.append((pm, wc))
    pm, w_c = min(pms) if pms else (math.pi, math.nan)
    dm = min((p / w for p, w in pms if p > 0), default=0.0) if pm > 0 else 0.0
    return LoopMargins(math.degrees(pm), k_max / k, crossings[0] if crossings else math.nan,
                       k_max, dm, w_lim)


def safe_gain(lag_s: float, delay_s: float, modes: Sequence[tuple[float, float]] = (),
              min_gain_margin: float = MIN_GAIN_MARGIN,
              min_phase_margin_deg: float = MIN_PHASE_MARGIN_DEG) -> float:
    """The largest integral gain [1/s] with both margins at least the given ones.

    The gain-margin bound is exact (``k_max / min_gain_margin``); below it
    the gains are scanned from the top (the phase margin need not fall
    monotonically with the gain when a mode's peak is near the crossover)
    and the largest that keeps the phase margin is refined by bisection.
    """
    k_gm = loop_margins(1.0, lag_s, delay_s, modes).max_gain_per_s / float(min_gain_margin)
    if not math.isfinite(k_gm):
        k_gm = 100.0
    ks = np.geomspace(k_gm, k_gm * 1e-4, 120)

    def ok(k):
        m = loop_margins(k, lag_s, delay_s, modes)
        return m.phase_margin_deg >= min_phase_margin_deg and m.gain_margin >= min_gain_margin

    for i, k in enumerate(ks):
        if ok(k):
            if i == 0:
                return float(k)
            lo, hi = float(k), float(ks[i - 1])
            for _ in range(40):
                mid = math.sqrt(lo * hi)
                lo, hi = (mid, hi) if ok(mid) else (lo, mid)
            return lo
    return float(ks[-1])
