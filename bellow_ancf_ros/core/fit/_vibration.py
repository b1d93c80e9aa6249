"""Frequency and damping of a recorded free vibration, and the damping time that reproduces them.

A released or stepped robot rings down in its first mode (docs/dynamics.md):
after the faster modes have died out, the end effector moves along one
direction as ``x(t) = c + A exp(-zeta w_n t) cos(w_d t + phi)``, ``w_d = w_n
sqrt(1 - zeta^2)``.  :func:`fit_free_vibration` projects the recorded
positions on their principal direction and fits that curve by nonlinear
least squares (``scipy.optimize.least_squares``), started from the spectrum's
peak and the envelope's logarithmic decrement.  :func:`identify_damping`
then finds the Kelvin-Voigt retardation time for which the model's first
mode at the recorded equilibrium has the measured damping ratio (the ratio
grows monotonically with it; ``scipy.optimize.brentq``).

Which part of a recording to fit (:func:`ringdown_window`): the motion starts
where the tip (a running median of five poses) has left its first recorded
position (the median of the first five) by a tenth of its largest excursion
from it, for the last time before that excursion (a noisy motion capture's
poses before the release crossed a tenth of a small push's excursion, and
the window began with the still push); the fit starts half a period of the
strongest oscillation later.  A release (or a step) starts at rest at a
turning point of the first mode, so this is about its first peak after the
release, by which time the faster modes, more damped (Kelvin-Voigt damping
grows with the frequency), have died out; the strongest oscillation's
frequency comes from a first fit from the motion's start.  The window ends
where that first fit's envelope has sunk to twice its RMS residual (the
noise, on a real recording; a long tail of noise alone can pull the
nonlinear fit off), after at least three periods, or at the recording's
end.

A motion capture's outliers (a marker swapped for a reflection: poses
centimetres off for one sample) are left out of every fit: a pose farther
from the median of the seven around it than :data:`OUTLIER_FACTOR` times
their own median distance from it (or the recording's typical distance,
where they are still).  Two of them (15 and 25 mm) in a 3 mm ring-down of a
two-segment robot of the family turned its principal direction, and the fit
read 11.9 Hz for its 1.6 Hz mode.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq, least_squares

from ..dynamics import reduced_system
from ..model import FIRST_MODE_ERROR_RANGE
from ._recordings import samples_around

__all__ = ["FreeVibrationFit", "DampingIdentification", "RingdownWindow", "fit_free_vibration",
           "identify_damping", "ringdown_window"]

#: The motion starts where the tip has left its first position by this share of its excursion.
MOTION_SHARE = 0.1
#: The window ends where the first fit's envelope is this many times its RMS residual ...
FADE_NOISE_FACTOR = 2.0
#: ... but holds at least this many periods after its start.
MIN_PERIODS = 3.0
#: A pose farther than this many times its neighbours' spread from their median is an outlier.
OUTLIER_FACTOR = 8.0


def _without_outliers(t: np.ndarray, x: np.ndarray):
    """``(t, x)`` without the motion capture's outliers (module docstring)."""
    if len(t) < 7:
        return t, x
    near = samples_around(x, 3)                                # (n, 7, axes)
    med = np.median(near, axis=1)
    r = np.linalg.norm(x - med, axis=1)
    spread = np.median(np.linalg.norm(near - med[:, None, :], axis=2), axis=1)
    scale = np.maximum(spread, np.median(r))
    keep = ~(r > OUTLIER_FACTOR * scale)
    return t[keep], x[keep]


@dataclass
class FreeVibrationFit:
    """A damped sinusoid fitted to a recorded motion (SI units)."""

    frequency_hz: float          # undamped natural frequency
    damped_frequency_hz: float
    damping_ratio: float
    amplitude_m: float
    direction: np.ndarray        # unit vector of the motion (base or mocap frame)
    rms_residual_m: float
    t_start_s: float
    n_samples: int

    def to_dict(self) -> dict:
        return {"frequency_hz": self.frequency_hz,
                "damped_frequency_hz": self.damped_frequency_hz,
                "damping_ratio": self.damping_ratio, "amplitude_m": self.amplitude_m,
                "direction": [float(v) for v in self.direction],
                "rms_residual_m": self.rms_residual_m, "t_start_s": self.t_start_s,
                "n_samples": self.n_samples}


def fit_free_vibration(times_s, positions_m, t_start_s: float | None = None,
                       t_end_s: float | None = None) -> FreeVibrationFit:
    """Fit ``c + A exp(-sigma t) cos(w_d t + phi)`` to the principal motion of ``positions_m``.

    Parameters
    ----------
    times_s : (n,) sample times.
    positions_m : (n, 3) or (n,) positions.
    t_start_s, t_end_s : the window to fit (default: everything).

    Raises ValueError with a one-line reason when the window holds too few
    samples or no oscillation.
    """
    t = np.asarray(times_s, dtype=float).ravel()
    x = np.asarray(positions_m, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    keep = np.isfinite(t) & np.all(np.isfinite(x), axis=1)
    if t_start_s is not None:
        keep &= t >= t_start_s
    if t_end_s is not None:
        keep &= t <= t_end_s
    t, x = t[keep], x[keep]
    order = np.argsort(t)
    t, x = _without_outliers(t[order], x[order])
    if len(t) < 20:
        raise ValueError(f"only {len(t)} samples in the window; need at least 20")
    t_first = float(t[0])
    t = t - t_first
    xc = x - x.mean(axis=0)
    _, _, vt = np.linalg.svd(xc, full_matrices=False)
    d = vt[0]
    d = d * (1.0 if d[np.argmax(np.abs(d))] >= 0 else -1.0)
    y = x @ d
    # start: the spectrum's peak (uniform resampling, the straight line through the ends taken
    # out: a creeping robot drifts while it rings), the envelope's decay
    n = len(t)
    tu = np.linspace(0.0, t[-1], n)
    yu = np.interp(tu, t, y - y.mean())
    yu = yu - np.polyval(np.polyfit(tu, yu, 1), tu)
    spec = np.abs(np.fft.rfft(yu * np.hanning(n)))
    freqs = np.fft.rfftfreq(n, tu[1] - tu[0])
    k = 1 + int(np.argmax(spec[1:]))
    f0 = freqs[k]
    if f0 * t[-1] < 1.5:
        raise ValueError(f"the window ({t[-1]:.3g} s) holds less than 1.5 periods of its "
                         f"strongest oscillation ({f0:.3g} Hz)")
    half = len(t) // 2
    a1 = np.std(y[:half] - y.mean())
    a2 = np.std(y[half:] - y.mean())
    sigma0 = max(np.log(max(a1, 1e-15) / max(a2, 1e-15)) / max(t[half] - t[0], 1e-9), 1e-3)
    w0 = 2 * np.pi * f0
    c0 = y[-max(5, n // 10):].mean()
    a0 = y[0] - c0

    def model(p):
        c, a, b, sigma, w = p
        e = np.exp(-sigma * t)
        return c + e * (a * np.cos(w * t) + b * np.sin(w * t))

    res = least_squares(lambda p: model(p) - y, [c0, a0, 0.0, sigma0, w0],
                        x_scale=[max(abs(a0), 1e-6), max(abs(a0), 1e-6), max(abs(a0), 1e-6),
                                 max(sigma0, 0.1), w0], method="lm", max_nfev=2000)
    c, a, b, sigma, w = res.x
    w = abs(w)
    zeta = sigma / np.hypot(sigma, w)
    wn = np.hypot(sigma, w)
    return FreeVibrationFit(frequency_hz=float(wn / (2 * np.pi)),
                            damped_frequency_hz=float(w / (2 * np.pi)),
                            damping_ratio=float(zeta), amplitude_m=float(np.hypot(a, b)),
                            direction=d, rms_residual_m=float(np.sqrt(np.mean(res.fun ** 2))),
                            t_start_s=t_first, n_samples=int(n))


@dataclass
class DampingIdentification:
    """The measured first mode and the retardation time that reproduces its damping."""

    fit: FreeVibrationFit
    damping_time_s: float
    model_frequency_hz: float
    model_damping_ratio: float

    def to_dict(self) -> dict:
        return {**self.fit.to_dict(), "damping_time_s": self.damping_time_s,
                "model_frequency_hz": self.model_frequency_hz,
                "model_damping_ratio": self.model_damping_ratio}


#: The fitted frequency over the model's first mode that is taken for that mode (a calibrated
#: file is within a few percent; a fit that latched onto the noise read 15-40 times it): 0.5
#: to 2, the robot file's ``dynamics.first_mode_error`` range, so that every accepted fit
#: gives a value the file takes.
FIRST_MODE_RANGE = (1.0 / (1.0 + FIRST_MODE_ERROR_RANGE[1]),
                    1.0 / (1.0 + FIRST_MODE_ERROR_RANGE[0]))


def identify_damping(fit: FreeVibrationFit, equilibrium, max_damping_time_s: float = 0.2
                     ) -> DampingIdentification:
    """The retardation time ``beta`` whose first mode at ``equilibrium`` has ``fit``'s damping.

    ``equilibrium``: the ForwardResult the robot rings about (its pressures,
    payload and tip force); the robot file's air damping is kept.  Raises
    ValueError when the fitted frequency is not the model's first mode
    (outside :data:`FIRST_MODE_RANGE` of it: a fit of the noise, not of a
    ring-down) or no ``beta`` in ``[0, max_damping_time_s]`` gives that ratio.
    """
    red = reduced_system(equilibrium)
    alpha = red.mass_damping
    target = fit.damping_ratio
    f_model = float(np.sqrt(red.w2[0]) / (2 * np.pi))
    if not FIRST_MODE_RANGE[0] <= fit.frequency_hz / f_model <= FIRST_MODE_RANGE[1]:
        raise ValueError(f"the fitted oscillation ({fit.frequency_hz:.4g} Hz) is not the "
                         f"model's first mode ({f_model:.4g} Hz at this equilibrium): no "
                         "ring-down of it above the noise")

    def gap(beta):
        return red.damped_first(beta, alpha)[1] - target

    lo, hi = gap(0.0), gap(max_damping_time_s)
    if not lo <= 0.0 <= hi:
        raise ValueError(f"damping ratio {target:.4g} is outside what damping_time_s in "
                         f"[0, {max_damping_time_s}] gives on this robot "
                         f"({lo + target:.4g} to {hi + target:.4g})")
    beta = brentq(gap, 0.0, max_damping_time_s, xtol=1e-7)
    return DampingIdentification(fit=fit, damping_time_s=float(beta),
                                 model_frequency_hz=f_model,
                                 model_damping_ratio=float(red.damped_first(beta, alpha)[1]))


@dataclass
class RingdownWindow:
    """The window of a recorded ring-down (module doc): motion start, fit start and end [s]."""

    t_motion_s: float
    t_start_s: float
    t_end_s: float
    frequency_hz: float      # damped frequency of the first fit, from the motion's start


def ringdown_window(times_s, positions_m, t_end_s: float | None = None) -> RingdownWindow:
    """The window to fit of a recorded release or step (module doc).

    Raises ValueError (one line) when the tip does not move or the motion
    holds no oscillation :func:`fit_free_vibration` can fit.
    """
    t = np.asarray(times_s, dtype=float).ravel()
    x = np.asarray(positions_m, dtype=float).reshape(len(t), -1)
    keep = np.isfinite(t) & np.all(np.isfinite(x), axis=1)
    if t_end_s is not None:
        keep &= t <= t_end_s
    t, x = t[keep], x[keep]
    order = np.argsort(t, kind="stable")
    t, x = t[order], x[order]
    if len(t) < 20:
        raise ValueError(f"only {len(t)} samples; need at least 20")
    # a running median of five poses: single noisy poses do not start the motion
    xs = np.median(samples_around(x, 2), axis=1)
    dist = np.linalg.norm(xs - np.median(x[:5], axis=0), axis=1)
    if not dist.max() > 0:
        raise ValueError("the tip does not move")
    # the motion that reaches the largest excursion starts after the tip was last within a
    # tenth of it of its first position (a noisy pose before it crossed a tenth and fell back)
    peak = int(np.argmax(dist))
    still = np.flatnonzero(dist[:peak + 1] <= MOTION_SHARE * dist[peak])
    t_motion = float(t[still[-1] + 1 if still.size else 0])
    first = fit_free_vibration(t, x, t_motion, t_end_s)
    period = 1.0 / max(first.damped_frequency_hz, 1e-9)
    t_start = t_motion + 0.5 * period
    t_end = float(t[-1])
    if t_start >= t_end:
        raise ValueError(f"the recording ends ({t_end:.4g} s) before half a period after the "
                         f"motion starts ({t_motion:.4g} s + {0.5 * period:.3g} s)")
    # end where the first fit's envelope has sunk to the noise (its RMS residual)
    sigma = 2 * np.pi * first.frequency_hz * first.damping_ratio
    level = FADE_NOISE_FACTOR * first.rms_residual_m
    if sigma > 0 and 0 < level < first.amplitude_m:
        t_fade = first.t_start_s + np.log(first.amplitude_m / level) / sigma
        t_end = min(t_end, max(t_fade, t_start + MIN_PERIODS * period))
    return RingdownWindow(t_motion_s=t_motion, t_start_s=float(t_start), t_end_s=t_end,
                          frequency_hz=first.damped_frequency_hz)
