"""The bellows' creep from a recorded pressure step: its fraction and time constant.

The creep model (the simulated robot's
:class:`~bellow_ancf_ros.core.sim.BellowCreep`): with ``x(p)`` the stage-1
elongation, a slow part ``s`` follows ``T ds/dt = x(p) - s`` and the bellows
stand at ``(1 - c) x(p) + c s``.  After a pressure step held still, the tip
therefore moves quickly (the regulators' rise, the first mode ringing) by
``(1 - c)`` of its total displacement ``D`` and creeps the rest as
``c D exp(-t/T)`` decaying.  :func:`fit_creep` measures ``c`` and ``T``:

* the pose before the step, ``y0``: the median of the poses of the last
  :data:`PRE_STEP_S` before ``t_step``; the direction of the motion: from
  ``y0`` to the median of the last :data:`END_S` of the window; the positions
  are projected on it (``y = 0`` at ``y0``); a displacement below
  :data:`MOTION_NOISE_FACTOR` times the noise of those two still stretches
  (1.4826 x the median absolute deviation about their medians) is no motion;
* outliers (a swapped marker): poses farther from the median of the five
  around them than :data:`OUTLIER_NOISE_FACTOR` times that noise and
  :data:`OUTLIER_MOTION_SHARE` of the displacement are dropped;
* the fit: ``y(t) = y_inf - B exp(-(t - t_step)/T)`` on ``[t_step + settle,
  t_end]`` by ``scipy.optimize.least_squares`` with a ``soft_l1`` loss (its
  scale twice the noise), ``T`` bounded to :data:`T_BOUNDS_S`, at most
  :data:`MAX_NFEV` evaluations, started from the best of a grid of ``T``
  (for a fixed ``T`` the curve is linear in ``y_inf`` and ``B``); standard
  errors from its Jacobian and the residuals' robust spread;
* the noise along the motion and the default ``settle``: a first fit from
  :data:`MIN_SETTLE_S` after the step (past the regulators' rise); the noise
  is its residuals' robust spread after :data:`MAX_SETTLE_S` (or half the
  window); the final fit starts at the end of the last :data:`RING_WINDOW_S`
  window whose residuals' robust spread exceeds :data:`RING_NOISE_FACTOR`
  times the noise (the first mode ringing; at least :data:`MIN_SETTLE_S`, at
  most :data:`MAX_SETTLE_S` and half the window);
* the fast move's time: the regulators' dead time and lag move the bellows
  some 0.05-0.1 s after the command, and the creep starts with them, so
  ``B`` taken at the command overstates the creep by ``exp(delay/T)`` (8 %
  at ``T = 1 s``).  The delay is the mean time of the fast move: where an
  instantaneous step onto the fitted curve encloses the same area as the
  recorded motion, ``int_{t_step}^{t_step + settle} (fit - y) dt =
  int_{t_step}^{t_step + delay} fit dt`` (for a linear plant right to the
  first order in the rise time over ``T``, whatever the regulators' shape;
  the ringing integrates to nearly nothing); a gap longer than
  :data:`MAX_GAP_S` in the poses of the fast move is refused (one in the
  first :data:`MIN_SETTLE_S` after the step is the fast move's unless the
  pose before it is already on the first fit, within :data:`GAP_NOISE_FACTOR`
  times the noise or :data:`GAP_MOTION_SHARE` of the move);
* ``c = B exp(-delay/T) / y_inf``, ``D = y_inf``;
* a robot whose first mode rings longer than the creep lasts (a lightly
  damped two-segment robot: a 40 kPa step rang by 2.7 mm peak to peak 3 s
  after the step, where a creep of 1.1 s had decayed to 7 %) leaves nothing
  to fit past the ringing: the fit above fails (no convergence, ``T`` at its
  bound, ``c`` far outside ``[0, 1)``: 10 of the family's 100 two-segment
  robots), or, worse, ends on a wrong ``c`` (0.034 for 0.17 on synthetic
  ringing).  When the first fit's
  residuals rang, the fit is made from :data:`MIN_SETTLE_S` with the
  ringing in the curve:
  ``y_inf - B exp(-tau/T) + exp(-sigma tau) (a cos(w tau) + b sin(w tau))``,
  ``w`` started at the strongest frequency of the first fit's residuals and
  kept within :data:`RING_W_RANGE` of it, ``sigma`` within
  :data:`RING_SIGMA_BOUNDS`; the delay is read with the fitted ringing taken
  out; the same checks apply, and when they refuse, the fit past the
  ringing is made, and its refusal is what is raised.

Every failure is a ``ValueError`` with a one-line reason: too few poses, no
motion, a fit that did not converge, no measurable creep, ``T`` at a bound or
longer than the recording resolves (record at least ~4 time constants after
the step), ``c`` outside ``[0, 1)``.  :func:`pressure_step_time` finds the
step in a recording's pressures (the largest change of the command).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq, least_squares

from ._recordings import samples_around

__all__ = ['CreepFit', 'fit_creep', 'pressure_step_time']

#: The pose before the step: the median of this long a stretch before it [s] ...
PRE_STEP_S = 0.5
#: ... and the end of the motion: the median of this long a stretch at the window's end [s].
END_S = 1.0
#: Poses needed before the step and in the fitted window.
MIN_PRE_SAMPLES = 5
MIN_FIT_SAMPLES = 20
#: A displacement below this many times the noise is no motion.
MOTION_NOISE_FACTOR = 5.0
#: Outliers: farther from the running median of five than this many times the noise ...
OUTLIER_NOISE_FACTOR = 10.0
#: ... and than this share of the displacement (the fast move's samples stay).
OUTLIER_MOTION_SHARE = 0.5
#: The fit's time constant lies in this range [s] ...
T_BOUNDS_S = (0.05, 100.0)
#: ... and a fit this close to a bound (relative) has hit it.
BOUND_SHARE = 0.01
#: The window after the step must hold this many fitted time constants.
MIN_TIME_CONSTANTS = 2.5
#: A longer gap in the poses in the first MIN_SETTLE_S after the step [s] is refused ...
MAX_GAP_S = 0.05
#: ... unless the pose before it is on the first fit, within this many times the noise or
#: this share of the move (the fast move was over).
GAP_NOISE_FACTOR = 3.0
GAP_MOTION_SHARE = 0.05
#: Function evaluations of the nonlinear fit.
MAX_NFEV = 200
#: Creep amplitudes within this many standard errors of zero are not measured.
SIGNIFICANCE = 3.0
#: The default settle time: at least this after the step (the regulators' rise) [s] ...
MIN_SETTLE_S = 0.5
#: ... at most this (and half the window) [s] ...
MAX_SETTLE_S = 3.0
#: ... the end of the last window of this length [s] ...
RING_WINDOW_S = 0.25
#: ... whose residual spread is above this many times the noise (and this share of the move).
RING_NOISE_FACTOR = 2.0
RING_MOTION_SHARE = 1e-3
#: The robust loss's scale: twice the noise, at least this share of the move.
MIN_SCALE_SHARE = 1e-4
#: The ringing's angular frequency stays within these factors of its starting value ...
RING_W_RANGE = (0.7, 1.4)
#: ... and its decay rate within these [1/s] (damping ratios of about 0.001 to 1 at 1-3 Hz).
RING_SIGMA_BOUNDS = (0.01, 20.0)
#: The ringing's start: the strongest frequency of the residuals over this long a stretch [s].
RING_SPECTRUM_S = 4.0
#: Starting time constants of the fit (log grid over T_BOUNDS_S).
_T_GRID = np.geomspace(T_BOUNDS_S[0] * 1.5, T_BOUNDS_S[1] / 1.5, 40)


@dataclass(frozen=True)
class CreepFit:
    """The creep measured from a recorded pressure step (SI units; module doc).

    ``creep_fraction`` and ``creep_time_constant_s`` are the creep model's
    ``c`` and ``T`` (their standard errors beside them); ``displacement_m``
    the tip's total move, from the pose before the step to the fitted end,
    along ``direction`` (a unit vector in the recording's frame);
    ``rms_residual_m`` the fit's RMS residual without the outliers; the fit
    covers ``n_samples`` poses in ``[t_start_s, t_end_s]`` with ``t_start_s =
    t_step_s + settle_s``; ``delay_s`` the fast move's mean time after
    ``t_step_s``; ``noise_m`` the noise along the motion, ``outliers`` the
    poses dropped; :meth:`curve` the fitted position along ``direction``
    from ``start_position_m``, the pose before the step.
    """

    creep_fraction: float
    creep_time_constant_s: float
    displacement_m: float
    direction: tuple
    rms_residual_m: float
    n_samples: int
    t_start_s: float
    t_end_s: float
    t_step_s: float
    settle_s: float
    delay_s: float
    noise_m: float
    outliers: int
    creep_fraction_stderr: float
    creep_time_constant_stderr_s: float
    final_m: float       # y_inf: the fitted end along the direction (from the pose before)
    amplitude_m: float   # B: the creep's amplitude at t_step_s
    start_position_m: tuple  # the pose before the step (position, the recording's frame)

    def curve(self, times_s) -> np.ndarray:
        """The fitted position along :attr:`direction` (from the pose before) at ``times_s``."""
        t = np.asarray(times_s, dtype=float)
        return self.final_m - self.amplitude_m * np.exp(-(t - self.t_step_s)
                                                        / self.creep_time_constant_s)

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict."""
        return {'creep_fraction': self.creep_fraction,
                'creep_time_constant_s': self.creep_time_constant_s,
                'displacement_m': self.displacement_m,
                'direction': [float(v) for v in self.direction],
                'rms_residual_m': self.rms_residual_m, 'n_samples': self.n_samples,
                't_start_s': self.t_start_s, 't_end_s': self.t_end_s,
                't_step_s': self.t_step_s, 'settle_s': self.settle_s, 'delay_s': self.delay_s,
                'noise_m': self.noise_m, 'outliers': self.outliers,
                'creep_fraction_stderr': self.creep_fraction_stderr,
                'creep_time_constant_stderr_s': self.creep_time_constant_stderr_s,
                'final_m': self.final_m, 'amplitude_m': self.amplitude_m,
                'start_position_m': [float(v) for v in self.start_position_m]}


def pressure_step_time(times_s, pressures_pa) -> float:
    """The time of the recorded pressure command's largest change [s].

    ``times_s`` (m,), ``pressures_pa`` (m, A): the recorded commands; the
    step is at the first command after the largest change (2-norm over the
    actuators).  Raises ValueError (one line) when there are fewer than two
    commands or they never change.
    """
    t = np.asarray(times_s, dtype=float).ravel()
    p = np.asarray(pressures_pa, dtype=float).reshape(len(t), -1)
    keep = np.isfinite(t) & np.all(np.isfinite(p), axis=1)
    t, p = t[keep], p[keep]
    order = np.argsort(t, kind='stable')
    t, p = t[order], p[order]
    if len(t) < 2 or p.shape[1] == 0:
        raise ValueError(f'{len(t)} recorded pressure command(s): need at least two to find '
                         'a step')
    jumps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    k = int(np.argmax(jumps))
    if not jumps[k] > 0:
        raise ValueError('the recorded pressures never change: no step')
    return float(t[k + 1])


def _robust_std(r) -> float:
    r = np.asarray(r, dtype=float)
    return float(1.4826 * np.median(np.abs(r - np.median(r)))) if r.size else 0.0


def _model(p, tau):
    y_inf, b, T = p
    return y_inf - b * np.exp(-tau / T)


def _linear_fit(tau, y, T):
    """``(y_inf, B, sum of squares)`` of the curve with the time constant ``T`` fixed."""
    a = np.column_stack([np.ones_like(tau), -np.exp(-tau / T)])
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    return coef[0], coef[1], float(np.sum((a @ coef - y) ** 2))


def _fit(tau, y, f_scale):
    """The robust fit on ``tau`` (time after the step) and ``y``: least_squares' result."""
    best = min((_linear_fit(tau, y, T) + (T,) for T in _T_GRID), key=lambda r: r[2])
    y_inf, b, _, T = best
    scale = max(abs(y_inf), abs(b), 1e-12)
    return least_squares(lambda p: _model(p, tau) - y, [y_inf, b, T],
                         bounds=([-np.inf, -np.inf, T_BOUNDS_S[0]],
                                 [np.inf, np.inf, T_BOUNDS_S[1]]),
                         x_scale=[scale, scale, T], loss='soft_l1', f_scale=f_scale,
                         max_nfev=MAX_NFEV, method='trf')


def _ring_model(p, tau):
    y_inf, b, T, a_c, a_s, sigma, w = p
    return (y_inf - b * np.exp(-tau / T)
            + np.exp(-sigma * tau) * (a_c * np.cos(w * tau) + a_s * np.sin(w * tau)))


def _ringing(p, tau):
    """The ringing part of :func:`_ring_model` alone."""
    _, _, _, a_c, a_s, sigma, w = p
    return np.exp(-sigma * tau) * (a_c * np.cos(w * tau) + a_s * np.sin(w * tau))


def _ring_start(tau, r) -> tuple:
    """``(w, sigma)`` to start from: the residuals' strongest frequency, their decay."""
    sel = tau < tau[0] + RING_SPECTRUM_S
    grid = np.linspace(tau[sel][0], tau[sel][-1], 1024)
    rg = np.interp(grid, tau[sel], r[sel])
    rg = (rg - rg.mean()) * np.hanning(len(rg))
    spec = np.abs(np.fft.rfft(rg))
    freqs = np.fft.rfftfreq(len(rg), grid[1] - grid[0])
    w = 2.0 * np.pi * freqs[1 + int(np.argmax(spec[1:]))]
    half = 0.5 * (grid[0] + grid[-1])
    early = _robust_std(r[sel & (tau < half)])
    late = _robust_std(r[sel & (tau >= half)])
    sigma = np.log(early / late) / (half - grid[0]) if early > 0 and late > 0 else 1.0
    lo, hi = RING_SIGMA_BOUNDS
    return float(w), float(min(max(sigma, 2.0 * lo), 0.5 * hi))


def _ring_fit(tau, y, first, f_scale):
    """The fit with the first mode's ringing in the curve (module doc): least_squares' result."""
    w0, sigma0 = _ring_start(tau, y - _model(first.x, tau))

    def linear(T):
        e = np.exp(-sigma0 * tau)
        a = np.column_stack([np.ones_like(tau), -np.exp(-tau / T), e * np.cos(w0 * tau),
                             e * np.sin(w0 * tau)])
        coef, *_ = np.linalg.lstsq(a, y, rcond=None)
        return coef, float(np.sum((a @ coef - y) ** 2))
    T = min(_T_GRID, key=lambda T: linear(T)[1])
    (y_inf, b, a_c, a_s), _ = linear(T)
    scale = max(abs(y_inf), abs(b), 1e-12)
    amp = max(abs(a_c), abs(a_s), 1e-3 * scale)
    lo = [-np.inf, -np.inf, T_BOUNDS_S[0], -np.inf, -np.inf, RING_SIGMA_BOUNDS[0],
          RING_W_RANGE[0] * w0]
    hi = [np.inf, np.inf, T_BOUNDS_S[1], np.inf, np.inf, RING_SIGMA_BOUNDS[1],
          RING_W_RANGE[1] * w0]
    return least_squares(lambda p: _ring_model(p, tau) - y,
                         [y_inf, b, T, a_c, a_s, sigma0, w0], bounds=(lo, hi),
                         x_scale=[scale, scale, T, amp, amp, sigma0, w0], loss='soft_l1',
                         f_scale=f_scale, max_nfev=MAX_NFEV, method='trf')


def _ring_settle(tau, y, res, level, span) -> float:
    """The default settle time: the end of the first fit's last ringing window (module doc)."""
    r = y - _model(res.x, tau)
    limit = min(MAX_SETTLE_S, 0.5 * span)
    settle = MIN_SETTLE_S
    start = MIN_SETTLE_S
    while start < limit:
        sel = (tau >= start) & (tau < start + RING_WINDOW_S)
        if np.count_nonzero(sel) >= 3 and _robust_std(r[sel]) > level:
            settle = start + RING_WINDOW_S
        start += RING_WINDOW_S
    return float(min(settle, limit))


def _delay(t_grid, y_grid, t_step, res, settle) -> float:
    """The fast move's mean time after the step (module doc), in ``[0, settle]``."""
    y_inf, b, T = res.x[:3]
    tau = t_grid - t_step
    gap = _model(res.x[:3], tau) - y_grid
    area = float(np.sum(0.5 * (gap[1:] + gap[:-1]) * np.diff(tau)))   # trapezoidal rule

    def enclosed(d):   # int_0^d of the fitted curve
        return y_inf * d - b * T * (1.0 - np.exp(-d / T))

    if not area > 0 or y_inf == 0:
        return 0.0
    if area >= enclosed(settle):
        return float(settle)
    return float(brentq(lambda d: enclosed(d) - area, 0.0, settle, xtol=1e-6))


def _check_gaps(t, y, t_step, first, tolerance) -> None:
    """Refuse a gap in the poses during the fast move (module doc)."""
    gaps = np.diff(t)
    for k in np.flatnonzero((gaps > MAX_GAP_S) & (t[1:] > t_step)
                            & (t[:-1] < t_step + MIN_SETTLE_S)):
        done = t[k] > t_step and abs(y[k] - _model(first.x, t[k] - t_step)) <= tolerance
        if not done:
            raise ValueError(f'no poses for {gaps[k]:.3g} s from {t[k]:.6g} s, during the fast '
                             'move after the step (its delay cannot be measured): record the '
                             'step again')


def fit_creep(times_s, positions_m, t_step_s: float, t_end_s: float | None = None,
              settle_s: float | None = None) -> CreepFit:
    """Fit the creep of a pressure step at ``t_step_s`` held still up to ``t_end_s`` (module doc).

    Parameters
    ----------
    times_s : (n,) pose times [s].
    positions_m : (n, 3) or (n,) positions [m].
    t_step_s : when the pressure command stepped [s].
    t_end_s : the end of the window (default: the last pose).
    settle_s : the fit starts this long after the step (default: after the ringing, module doc).

    Raises ValueError with a one-line reason when the recording cannot give
    the creep (module doc).
    """
    t = np.asarray(times_s, dtype=float).ravel()
    x = np.asarray(positions_m, dtype=float).reshape(len(t), -1)
    t_step = float(t_step_s)
    if not np.isfinite(t_step):
        raise ValueError(f't_step_s = {t_step_s!r} is not a finite time')
    if settle_s is not None and not (np.isfinite(settle_s) and settle_s >= 0):
        raise ValueError(f'settle_s = {settle_s!r} must be a finite time >= 0')
    keep = np.isfinite(t) & np.all(np.isfinite(x), axis=1)
    if t_end_s is not None:
        keep &= t <= t_end_s
    t, x = t[keep], x[keep]
    order = np.argsort(t, kind='stable')
    t, x = t[order], x[order]
    pre = (t >= t_step - PRE_STEP_S) & (t < t_step)
    if np.count_nonzero(pre) < MIN_PRE_SAMPLES:
        raise ValueError(f'only {np.count_nonzero(pre)} poses in the {PRE_STEP_S:g} s before '
                         f'the step at {t_step:.6g} s; need at least {MIN_PRE_SAMPLES} (record '
                         'the robot still before the step)')
    t_end = float(t[-1])
    span = t_end - t_step
    if not span > END_S + MIN_SETTLE_S:
        raise ValueError(f'the window ends {span:.3g} s after the step at {t_step:.6g} s; '
                         'record at least ~4 time constants after the step')
    end = t >= t_end - END_S
    y0 = np.median(x[pre], axis=0)
    y_end = np.median(x[end], axis=0)
    spread = np.concatenate([x[pre] - y0, x[end] - y_end])
    noise = float(np.sqrt(np.mean([_robust_std(c) ** 2 for c in spread.T])))
    move = float(np.linalg.norm(y_end - y0))
    if not move > MOTION_NOISE_FACTOR * noise:
        raise ValueError(f'the tip does not move: {move * 1e3:.3g} mm from before the step to '
                         f'the end, not above {MOTION_NOISE_FACTOR:g} x the noise '
                         f'({noise * 1e3:.3g} mm)')
    d = (y_end - y0) / move
    # outliers: far from the median of the five poses around them
    after = t >= t_step - PRE_STEP_S
    t, x = t[after], x[after]
    off = np.linalg.norm(x - np.median(samples_around(x, 2), axis=1), axis=1)
    good = off <= max(OUTLIER_NOISE_FACTOR * noise, OUTLIER_MOTION_SHARE * move)
    n_out = int(np.count_nonzero(~good))
    t, y = t[good], (x[good] - y0) @ d
    tau_all = t - t_step
    # the noise: the residual spread of a first fit late in the window (else before the step)
    noise_y = _robust_std(y[t < t_step])
    sel = tau_all >= MIN_SETTLE_S
    if np.count_nonzero(sel) < MIN_FIT_SAMPLES:
        raise ValueError(f'only {np.count_nonzero(sel)} poses from {MIN_SETTLE_S:g} s after '
                         f'the step to {t_end:.6g} s; need at least {MIN_FIT_SAMPLES}')
    first = _fit(tau_all[sel], y[sel], max(2.0 * noise_y, MIN_SCALE_SHARE * move))
    late = tau_all >= min(MAX_SETTLE_S, 0.5 * span)
    if np.count_nonzero(late) >= MIN_FIT_SAMPLES:
        noise_y = _robust_std(y[late] - _model(first.x, tau_all[late]))
    f_scale = max(2.0 * noise_y, MIN_SCALE_SHARE * move)
    _check_gaps(t, y, t_step, first, max(GAP_NOISE_FACTOR * noise_y, GAP_MOTION_SHARE * move))
    if settle_s is None:
        settle = _ring_settle(tau_all[sel], y[sel], first,
                              max(RING_NOISE_FACTOR * noise_y, RING_MOTION_SHARE * move), span)
    else:
        settle = float(settle_s)
    sel = tau_all >= settle
    n = int(np.count_nonzero(sel))
    if n < MIN_FIT_SAMPLES:
        raise ValueError(f'only {n} poses from {settle:.3g} s after the step to {t_end:.6g} s; '
                         f'need at least {MIN_FIT_SAMPLES}')
    common = dict(t=t, y=y, t_step=t_step, t_end=t_end, span=span, d=d, y0=y0, move=move,
                  noise_y=noise_y, n_out=n_out)
    if settle_s is None and settle > MIN_SETTLE_S:   # it rang: first with the ringing
        ring = tau_all >= MIN_SETTLE_S
        try:
            return _creep(_ring_fit(tau_all[ring], y[ring], first, f_scale), tau_all[ring],
                          y[ring], MIN_SETTLE_S, ring=True, moved_by=settle, **common)
        except ValueError:
            pass   # (the fit past the ringing says why not)
    return _creep(_fit(tau_all[sel], y[sel], f_scale), tau_all[sel], y[sel], settle,
                  ring=False, **common)


def _creep(res, tau, ys, settle, ring, t, y, t_step, t_end, span, d, y0, move, noise_y,
           n_out, moved_by=None) -> CreepFit:
    """The creep of a fit ``res`` on ``tau``, ``ys`` (``ring``: :func:`_ring_fit`'s), checked.

    The fast move's delay is read over ``[t_step, t_step + moved_by]``
    (default ``settle``, the fit's start); with the ringing fitted, over the
    ringing (``moved_by``), the fitted ringing taken out from ``settle`` on:
    what is left of it before then integrates to nearly nothing.
    """
    n = len(tau)
    if not res.success or res.status <= 0:
        raise ValueError(f'the creep fit did not converge within {MAX_NFEV} evaluations '
                         f'({res.message})')
    y_inf, b, T = (float(v) for v in res.x[:3])
    r = (_ring_model(res.x, tau) if ring else _model(res.x, tau)) - ys
    # standard errors: the plain Jacobian (of the creep's terms, the ringing held) and the
    # residuals' robust spread
    e = np.exp(-tau / T)
    jac = np.column_stack([np.ones_like(tau), -e, -b * tau * e / T ** 2])
    s2 = _robust_std(r) ** 2
    cov = s2 * np.linalg.pinv(jac.T @ jac)
    se_b_fixed_t = float(np.sqrt(s2 * np.linalg.pinv(jac[:, :2].T @ jac[:, :2])[1, 1]))
    measured = abs(b) > SIGNIFICANCE * se_b_fixed_t
    lo, hi = T_BOUNDS_S
    record = 'record at least ~4 time constants after the step'
    if T >= hi * (1 - BOUND_SHARE) or T > span / MIN_TIME_CONSTANTS:
        if not measured:
            raise ValueError(f'no creep resolved in the {span:.3g} s recorded after the step: '
                             f'none measurable (amplitude {b * 1e3:.3g} mm, standard error '
                             f'{se_b_fixed_t * 1e3:.3g} mm) or slower than the recording; '
                             f'{record}')
        raise ValueError(f'the creep time constant ({T:.3g} s) is too long for the '
                         f'{span:.3g} s recorded after the step: {record}')
    if not measured:
        raise ValueError(f'no measurable creep: its amplitude {b * 1e3:.3g} mm is within '
                         f'{SIGNIFICANCE:g} standard errors ({se_b_fixed_t * 1e3:.3g} mm) of 0, '
                         f'the creep fraction below ~{SIGNIFICANCE * se_b_fixed_t / move:.2g} '
                         '(set creep_fraction 0)')
    if T <= lo * (1 + BOUND_SHARE):
        raise ValueError(f'the creep time constant hit its lower bound ({lo:g} s): no creep '
                         'slower than the fast move to fit')
    window = settle if moved_by is None else moved_by
    grid_t = np.concatenate([[t_step], t[(t > t_step) & (t < t_step + window)],
                             [t_step + window]])
    y_grid = np.interp(grid_t, t, y)
    if ring:
        fitted = grid_t - t_step >= settle
        y_grid[fitted] -= _ringing(res.x, grid_t[fitted] - t_step)
    delay = _delay(grid_t, y_grid, t_step, res, window)
    shrink = np.exp(-delay / T)
    c = b * shrink / y_inf
    grad = np.array([-c / y_inf, shrink / y_inf, c * delay / T ** 2])
    c_se = float(np.sqrt(max(grad @ cov @ grad, 0.0)))
    if not 0.0 <= c < 1.0:
        raise ValueError(f'creep fraction {c:.3g} is outside [0, 1): the tip '
                         + ('moves back after the step (not creep)' if c < 0 else
                            'creeps more than its whole move'))
    return CreepFit(creep_fraction=float(c), creep_time_constant_s=T,
                    displacement_m=y_inf, direction=tuple(float(v) for v in d),
                    rms_residual_m=float(np.sqrt(np.mean(r ** 2))), n_samples=n,
                    t_start_s=t_step + settle, t_end_s=t_end, t_step_s=t_step,
                    settle_s=settle, delay_s=delay, noise_m=noise_y, outliers=n_out,
                    creep_fraction_stderr=c_se,
                    creep_time_constant_stderr_s=float(np.sqrt(max(cov[2, 2], 0.0))),
                    final_m=y_inf, amplitude_m=b,
                    start_position_m=tuple(float(v) for v in y0))
