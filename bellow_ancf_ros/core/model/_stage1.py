"""Stage 1 of the kinetostatic model: elongation of each actuator.

Paper equations (10) / (24) with the external axial force ``F_e = 0``
(docs/model.md section 2: external loads act in stage 2 only)::

    (pi/4) * P * D_eff**2 - k(lam) * (lam - 1) * l0 = 0            (10), (24)

``k(lam)`` is the structural stiffness of eq. (1), a polynomial in the stretch
``lam`` with ascending-power coefficients ``c0 + c1*lam + c2*lam**2 + ...``
[N/m].  Solved for ``P`` the equation is explicit (the inverse of stage 1)::

    P(lam) = 4 * l0 * k(lam) * (lam - 1) / (pi * D_eff**2)

Solved for ``lam`` it is a polynomial equation.  Stage 1 uses the root on the
*monotone branch through* ``lam = 1`` (``P = 0``): the largest interval
``(lam_lo, lam_hi)`` containing 1 on which ``dP/dlam > 0`` and ``lam > 0``.
Construction refuses a stiffness polynomial for which the admissible
pressure range ``[p_min, p_max]`` does not map one-to-one onto a part of that
branch, so a wrong root can never be returned silently.

Note: on the branch ``k(lam) > 0`` holds automatically: ``dP/dlam`` at
``lam = 1`` is proportional to ``k(1)``, and ``k(lam) * (lam - 1)`` has the sign
of ``lam - 1`` on an increasing branch through its zero at ``lam = 1``.  The
stiffnesses of stage 2 (``k_t = k*l0``, eq. 2; ``k_b = D_a**2*l0*lam*k/8``,
eq. 4) are therefore positive for every admissible pressure.

Internally the unknown is ``x = lam - 1`` and the left-hand side is kept in
factored form, ``h(x) = k(1 + x) * x`` (never the expanded product), so that
``P = 0`` gives exactly ``lam = 1`` and small pressures keep full relative
precision.  The expansion of ``k`` about ``lam = 1`` is used only to locate
the critical points of ``h`` and for the closed form of a linear ``k``.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
from numpy.polynomial import polynomial as npoly

__all__ = ['Stage1']

_EPS = np.finfo(float).eps

# A root of dh/dx whose imaginary part is below this (relative) size is taken
# as real: numerical roots of an exact double root come out as a complex pair
# with an imaginary part of order sqrt(eps).
_IMAG_TOL = 1e-6


def _horner(a: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
    """``sum_i coeffs[i] a**i`` (ascending coefficients), as ``numpy.polynomial.polyval``.

    The same operations in the same order as ``polyval``, without its
    argument handling: stage 1 is evaluated at every Newton iterate.
    """
    out = np.full(a.shape, coeffs[-1]) if a.ndim else coeffs[-1] + 0.0 * a
    for c in coeffs[-2::-1]:
        out = out * a + c
    return out


#: Pressure arrays up to this size take the plain-float path of :meth:`Stage1.stretch`.
_SMALL = 16


def _as_output(values: np.ndarray, scalar: bool) -> Any:
    """Return a Python float for scalar input, the array otherwise."""
    return float(values) if scalar else values


def _roots(coeffs: np.ndarray) -> np.ndarray:
    """All (complex) roots of the polynomial with ascending ``coeffs``.

    Leading coefficients below ``1e-250`` of the largest one are dropped
    first: they would overflow the companion matrix and only matter at
    astronomically large stretches.
    """
    c = np.asarray(coeffs, dtype=float)
    scale = np.max(np.abs(c)) if c.size else 0.0
    n = c.size
    while n > 1 and abs(c[n - 1]) <= 1e-250 * scale:
        n -= 1
    if n < 2:
        return np.empty(0, dtype=complex)
    return npoly.polyroots(c[:n])


def _real_roots(coeffs: np.ndarray) -> np.ndarray:
    """Real roots (sorted) of the polynomial with ascending ``coeffs``.

    Roots with a small imaginary part (numerical double roots) count as real.
    """
    roots = _roots(coeffs)
    real = np.abs(roots.imag) <= _IMAG_TOL * (1.0 + np.abs(roots.real))
    return np.sort(roots.real[real])


class Stage1:
    """Pressure <-> stretch map of one actuator (paper eqs. 10 and 24, F_e = 0).

    Parameters
    ----------
    coeffs:
        Stiffness polynomial ``k(lam)`` [N/m], ascending powers of ``lam``
        (paper V.A: ``(28.9, 576.94)``).  Any order.
    l0:
        Unpressurised actuator length [m].
    d_eff:
        Effective actuation diameter ``D_eff`` [m].
    p_min, p_max:
        Admissible gauge pressure range [Pa] (hardware limits).

    Raises
    ------
    ValueError
        On non-finite or non-positive geometry, an empty stiffness polynomial,
        ``p_min >= p_max``, or when ``P -> lam`` is not strictly monotonic over
        ``[p_min, p_max]`` (``dP/dlam <= 0`` somewhere on the way from
        ``lam = 1``, the polynomial saturates before reaching a limit, or a
        limit would need ``lam <= 0``), or if the stretch at a limit cannot be
        computed within the solver's budget.

    Attributes
    ----------
    coeffs: tuple of float
        The stiffness coefficients as given.
    l0, d_eff, p_min, p_max: float
        As given (SI).
    area: float
        Effective actuation area ``pi/4 * D_eff**2`` [m^2].
    lam_min, lam_max, lam_mid: float
        Stretches at ``p_min``, ``p_max`` and mid-range pressure.
    lam_branch: tuple of float
        Open interval ``(lam_lo, lam_hi)`` of the monotone branch through
        ``lam = 1``; ``lam_hi`` may be ``inf``.  ``stretch`` accepts every
        pressure whose stretch lies inside it.
    """

    def __init__(self, coeffs: Sequence[float], l0: float, d_eff: float,
                 p_min: float, p_max: float) -> None:
        c = np.asarray(coeffs, dtype=float)
        if c.ndim != 1 or c.size == 0:
            raise ValueError('stiffness polynomial k(lam) must have at least one coefficient')
        if not np.all(np.isfinite(c)):
            raise ValueError(f'stiffness coefficients must be finite, got {c.tolist()}')
        for name, value in (('l0', l0), ('d_eff', d_eff)):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a positive finite length, got {value!r}')
        if not (math.isfinite(p_min) and math.isfinite(p_max)):
            raise ValueError(f'pressure limits must be finite, got [{p_min!r}, {p_max!r}]')
        if not p_min < p_max:
            raise ValueError(f'p_min ({p_min} Pa) must be smaller than p_max ({p_max} Pa)')

        self.coeffs = tuple(float(v) for v in c)
        self.l0 = float(l0)
        self.d_eff = float(d_eff)
        self.p_min = float(p_min)
        self.p_max = float(p_max)
        try:                                          # (a float's ** raises on overflow)
            self.area = math.pi / 4.0 * self.d_eff ** 2
        except OverflowError:
            self.area = math.inf
        # P = _p_per_h * h(x): pressure per unit of k(lam)*(lam-1) [N/m -> Pa]
        self._p_per_h = self.l0 / self.area if self.area > 0.0 else math.inf
        if not (self.area < math.inf and 0.0 < self._p_per_h < math.inf):
            raise ValueError(
                f'l0 = {self.l0!r} m and d_eff = {self.d_eff!r} m leave the floating-point '
                f'range: the area pi/4 D_eff**2 = {self.area!r} m^2 and l0/area = '
                f'{self._p_per_h!r} 1/m must be positive and finite')

        # Coefficients too large for floating point overflow here: _find_branch refuses them.
        with np.errstate(over='ignore', invalid='ignore'):
            self._k = npoly.polytrim(c, tol=0)          # k(lam), ascending in lam
            self._k_list = self._k.tolist()
            self._dk = npoly.polyder(self._k)
            # k about lam = 1:  kx(x) = k(1 + x)
            self._kx = npoly.polytrim(np.polynomial.Polynomial(self._k)(
                np.polynomial.Polynomial([1.0, 1.0])).coef, tol=0)
            self._h = npoly.polymulx(self._kx)            # h(x) = kx(x) * x
            self._dh = npoly.polyder(self._h)
            self._k1 = float(self._kx[0])                 # k(1) = dh/dx at x = 0
            try:                                          # (a float's ** raises on overflow)
                self._k1sq = self._k1 ** 2
            except OverflowError:
                self._k1sq = math.inf
            # Closed form when h is at most quadratic (k at most linear).
            self._quadratic = self._kx.size <= 2
            self._c1 = float(self._kx[1]) if self._kx.size > 1 else 0.0   # h's x**2 term

            # Rounding-error bound of the computed residual h(x) - t (see _noise).
            self._kl_abs = np.abs(self._k) * np.arange(1, self._k.size + 1)   # (1 + i) |c_i|
            self._noise_factor = 2 * self._k.size * _EPS       # (2n + 2) eps, n = degree

        with np.errstate(over='ignore'):  # huge turning points: h(x_hi) may overflow to inf
            self._find_branch()
        limits = np.array([self.p_min, self.p_max, 0.5 * (self.p_min + self.p_max)])
        try:
            lam_lim = self.stretch(limits)
        except RuntimeError as exc:      # the solver's honest failure (budget spent)
            raise ValueError(
                f'stiffness polynomial k(lam) = {self._poly_str()} N/m: the stretch at '
                f'the pressure limits cannot be computed: {exc}') from None
        if not np.all(np.isfinite(lam_lim)):
            raise ValueError(
                f'stiffness polynomial k(lam) = {self._poly_str()} N/m: the stretch at the '
                f'pressure limits overflows (lam = {lam_lim[:2].tolist()}); the coefficients '
                f'or pressures are too large for floating point')
        self.lam_min = float(lam_lim[0])
        self.lam_max = float(lam_lim[1])
        self.lam_mid = float(lam_lim[2])  # at mid-range pressure
        self._check_monotone(self.lam_min - 1.0, self.lam_max - 1.0)

    @classmethod
    def from_config(cls, cfg: Any) -> 'Stage1':
        """Build from a :class:`~bellow_ancf_ros.core.model._config.RobotConfig`."""
        return cls(cfg.stiffness_coeffs, cfg.l0, cfg.d_eff, cfg.p_min, cfg.p_max)

    def __repr__(self) -> str:
        return (f'Stage1(coeffs={self.coeffs}, l0={self.l0}, d_eff={self.d_eff}, '
                f'p_min={self.p_min}, p_max={self.p_max})')

    # ------------------------------------------------------------------ setup
    def _h_val(self, x: np.ndarray) -> np.ndarray:
        """h(x) = k(1+x) * x in factored form (exact zero at x = 0).

        ``k`` is evaluated with the original coefficients at ``lam = 1 + x``,
        so that ``pressure(lam)`` is eq. (24) term by term.
        """
        return _horner(1.0 + x, self._k) * x

    def _dh_val(self, x: np.ndarray) -> np.ndarray:
        """dh/dx = k'(1+x) * x + k(1+x)."""
        lam = 1.0 + x
        return _horner(lam, self._dk) * x + _horner(lam, self._k)

    def _noise(self, x: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Bound on the rounding error of the computed residual ``h(x) - t``.

        ``lam = fl(1 + x)`` (relative error ``u = eps/2``), Horner's rule for
        ``k`` of degree ``n`` (error at most ``gamma_2n * sum |c_i| lam**i``),
        the product with ``x`` and the difference with ``t`` (``u`` each) give
        to first order ``(2n + 2) u |x| K + u |x| L + u |t|`` with
        ``K = sum |c_i| |lam|**i`` and ``L = sum i |c_i| |lam|**i``; returned
        with a margin of two, ``(2n + 2) eps (|x| (K + L) + |t|)``
        (``K + L`` in one Horner pass over ``(1 + i) |c_i|``).  A residual
        below it says nothing about the sign of the exact one: the iterate is
        as good as the arithmetic allows.
        """
        return self._noise_factor * (np.abs(x) * _horner(np.abs(1.0 + x), self._kl_abs)
                                     + np.abs(t))

    def _kpa(self, h: float) -> str:
        return f'{h * self._p_per_h / 1e3:.6g} kPa'

    def _find_branch(self) -> None:
        """Delimit the monotone branch through x = 0 and check the limits reach it."""
        where = (f'stiffness polynomial k(lam) = {self._poly_str()} N/m '
                 f'(l0 = {self.l0} m, D_eff = {self.d_eff} m)')
        if not (np.all(np.isfinite(self._dh)) and np.all(np.isfinite(self._kl_abs))):
            raise ValueError(
                f'{where}: the coefficients are too large for floating point: '
                f'k(1 + x) x or its derivative overflows')
        if not self._k1 > 0.0:
            raise ValueError(
                f'{where}: dP/dlam <= 0 at lam = 1 (k(1) = {self._k1:.6g} N/m must be '
                f'positive); the pressure-to-stretch map is not monotonic')
        # Critical points of h: real roots of dh/dx, plus the real parts of
        # complex roots at which dh/dx is not positive in floating point.
        roots = _roots(self._dh)
        crit = [z.real for z in roots
                if abs(z.imag) <= _IMAG_TOL * (1.0 + abs(z.real))
                or self._dh_val(np.array(z.real)) <= 0.0]
        crit = np.asarray(crit, dtype=float)
        above = crit[crit > 0.0]
        if not above.size and self._h[-1] < 0.0:
            # h -> -inf, so dh/dx has a positive root: the companion matrix lost
            # it to round-off (coefficients of very different sizes).
            above = self._first_turn()
        elif above.size:
            # roots of coefficients of very different sizes may be spurious (far out) while
            # the first turn is lost: a grid up to the first root, or to p_max, confirms it
            above = np.append(above, self._first_turn(float(above.min()),
                                                      self.p_max / self._p_per_h))
        below = crit[(crit < 0.0) & (crit > -1.0)]
        below = np.append(below, self._last_turn(below.max() if below.size else -1.0))
        self._x_hi = float(above.min()) if above.size else math.inf
        self._x_lo = float(below.max()) if below.size else -1.0     # lam > 0
        self._h_hi = float(self._h_val(np.array(self._x_hi))) if above.size else math.inf
        self._h_lo = float(self._h_val(np.array(self._x_lo)))
        self.lam_branch = (1.0 + self._x_lo, 1.0 + self._x_hi)

        h_max = self.p_max / self._p_per_h
        h_min = self.p_min / self._p_per_h
        if not h_max < self._h_hi:
            raise ValueError(
                f'{where}: the pressure-to-stretch map is not monotonic over '
                f'[p_min, p_max]: dP/dlam = 0 at lam = {1.0 + self._x_hi:.6g} '
                f'(P = {self._kpa(self._h_hi)}), below p_max = {self.p_max / 1e3:.6g} kPa')
        if not h_min > self._h_lo:
            if below.size:
                reason = (f'dP/dlam = 0 at lam = {1.0 + self._x_lo:.6g} '
                          f'(P = {self._kpa(self._h_lo)})')
            else:
                reason = (f'the branch through lam = 1 reaches lam = 0 at '
                          f'P = {self._kpa(self._h_lo)}')
            raise ValueError(
                f'{where}: p_min = {self.p_min / 1e3:.6g} kPa cannot be reached on the '
                f'monotonic pressure-to-stretch branch: {reason}')

    def _first_turn(self, x_stop: float = 1e300, h_stop: float = math.inf) -> np.ndarray:
        """The first ``x > 0`` with ``dh/dx <= 0`` on a grid, refined by bisection.

        Used when the roots of ``dh/dx`` missed a turning point that its
        negative leading coefficient proves, and to confirm the first positive
        root (coefficients of very different sizes give spurious roots).
        Grids of 256 steps over ``[0, 1], [1, 2], [2, 4], ...``, up to
        ``x_stop`` or the first grid whose end has ``h`` past ``h_stop`` (the
        pressure limit: a turn beyond it does not matter); empty if none is
        found (then the stretch search reports a failure).  A dip of ``dh/dx``
        between two grid points inside ``[p_min, p_max]`` is still refused by
        :meth:`_check_monotone`.
        """
        a, b = 0.0, 1.0
        with np.errstate(over='ignore', invalid='ignore'):  # inf - inf: not positive
            while a < min(x_stop, 1e300):
                xs = np.linspace(a, b, 257)
                ok = self._dh_val(xs) > 0.0
                ok[0] = True                            # dh(0) = k(1) > 0; a: last grid's
                bad = np.flatnonzero(~ok)
                if bad.size:
                    return np.array([self._turn(float(xs[bad[0] - 1]), float(xs[bad[0]]))])
                if self._h_val(np.array(b)) > h_stop:
                    break
                a, b = b, 2.0 * b
        return np.empty(0)

    def _last_turn(self, x_lo: float) -> np.ndarray:
        """The last ``x`` in ``(x_lo, 0)`` with ``dh/dx <= 0`` on a 256-step grid, or none.

        A turning point between ``lam = 0`` (or the largest negative root of
        ``dh/dx``) and ``lam = 1`` that the roots of ``dh/dx`` missed.
        """
        xs = np.linspace(x_lo, 0.0, 257)[1:]
        ok = self._dh_val(xs) > 0.0
        ok[-1] = True                                   # dh(0) = k(1) > 0
        bad = np.flatnonzero(~ok)
        if not bad.size:
            return np.empty(0)
        return np.array([self._turn(float(xs[bad[-1] + 1]), float(xs[bad[-1]]))])

    def _turn(self, x_pos: float, x_neg: float) -> float:
        """Bisect between ``dh/dx(x_pos) > 0`` and ``dh/dx(x_neg) <= 0``; the positive end.

        Budget 200 halvings: about 60 reach adjacent floats unless the turn
        sits within ``1e-40`` of ``x = 0``; then the end kept is still a point
        with ``dh/dx > 0``.
        """
        for _ in range(200):
            mid = 0.5 * (x_pos + x_neg)
            if mid in (x_pos, x_neg):
                break
            if self._dh_val(np.array(mid)) > 0.0:
                x_pos = mid
            else:
                x_neg = mid
        return x_pos

    def _check_monotone(self, x_a: float, x_b: float) -> None:
        """Independent check that dh/dx > 0 on [x_a, x_b] (minimum of dh there).

        The minimum of a polynomial on an interval sits at an end point or at a
        root of its derivative; a dense sample guards against roots lost to
        round-off.
        """
        cand = [x_a, x_b]
        cand += [r for r in _real_roots(npoly.polyder(self._dh)) if x_a < r < x_b]
        pts = np.concatenate([np.asarray(cand), np.linspace(x_a, x_b, 2049)])
        d = self._dh_val(pts)
        i = int(np.argmin(d))
        if not d[i] > 0.0:
            raise ValueError(
                f'stiffness polynomial k(lam) = {self._poly_str()} N/m: the pressure-to-'
                f'stretch map is not monotonic over [p_min, p_max]: dP/dlam <= 0 at '
                f'lam = {1.0 + pts[i]:.6g}')

    def _poly_str(self) -> str:
        """Human-readable ``k(lam)`` for error messages."""
        out = f'{self.coeffs[0]:.6g}'
        for i, c in enumerate(self.coeffs[1:], start=1):
            power = 'lam' if i == 1 else f'lam**{i}'
            out += f' {"-" if c < 0 else "+"} {abs(c):.6g}*{power}'
        return out

    # ------------------------------------------------------------- evaluation
    @property
    def k_coefficients(self) -> np.ndarray:
        """``k(lam)`` [N/m] as ascending power coefficients in ``lam`` (trimmed)."""
        return self._k

    @property
    def dk_coefficients(self) -> np.ndarray:
        """``dk/dlam`` [N/m] as ascending power coefficients in ``lam``."""
        return self._dk

    def k(self, lam: Any) -> Any:
        """Return the structural stiffness at stretch ``lam`` [N/m] (paper eq. 1)."""
        a = np.asarray(lam, dtype=float)
        return _as_output(_horner(a, self._k), a.ndim == 0)

    def dk(self, lam: Any) -> Any:
        """``dk/dlam`` [N/m]."""
        a = np.asarray(lam, dtype=float)
        return _as_output(_horner(a, self._dk), a.ndim == 0)

    def pressure(self, lam: Any) -> Any:
        """Gauge pressure [Pa] giving stretch ``lam``: eq. (24) solved for P.

        ``P = k(lam) * (lam - 1) * l0 / (pi/4 * D_eff**2)``, explicit, for any
        ``lam`` (no branch check).
        """
        a = np.asarray(lam, dtype=float)
        if a.ndim == 1 and a.size <= _SMALL:   # a robot's few actuators: plain floats
            return np.array([self._p_per_h * (self._k_of(v) * (v - 1.0)) for v in a.tolist()])
        g = _horner(a, self._k) * (a - 1.0)
        return _as_output(self._p_per_h * g, a.ndim == 0)

    def _k_of(self, lam: float) -> float:
        """``k(lam)`` of one stretch with plain floats: :func:`_horner`'s operations, in order."""
        k = self._k_list
        out = k[-1]
        for c in k[-2::-1]:
            out = out * lam + c
        return out

    def dpressure(self, lam: Any) -> Any:
        """``dP/dlam`` [Pa] = ``l0 * (k'(lam) (lam - 1) + k(lam)) / (pi/4 D_eff**2)``."""
        a = np.asarray(lam, dtype=float)
        dg = npoly.polyval(a, self._dk) * (a - 1.0) + npoly.polyval(a, self._k)
        return _as_output(self._p_per_h * dg, a.ndim == 0)

    def dstretch(self, p: Any) -> Any:
        """``dlam/dP`` [1/Pa] at pressure ``p`` (inverse of :meth:`dpressure`)."""
        a = np.asarray(p, dtype=float)
        lam = np.asarray(self.stretch(a), dtype=float)
        return _as_output(1.0 / np.asarray(self.dpressure(lam)), a.ndim == 0)

    def stretch(self, p: Any) -> Any:
        """Stretch ``lam`` at gauge pressure ``p`` [Pa]: eq. (10)/(24) solved for lam.

        Exact for the polynomial: closed form for a linear (or constant)
        ``k``, otherwise a vectorised safeguarded Newton iteration to machine
        precision inside a bracket of the monotone branch.  Pressures outside
        ``[p_min, p_max]`` are accepted as long as their stretch lies on the
        monotone branch (``lam_branch``); only the admissible range is
        guaranteed by construction.

        Raises
        ------
        ValueError
            For NaN or infinite pressures, or pressures beyond the branch.
        RuntimeError
            If the iteration spends its budget (:meth:`_solve_newton`); a
            pressure on the branch converges in about 5-20 iterations.
        """
        a = np.asarray(p, dtype=float)
        if self._quadratic and a.ndim == 1 and a.size <= _SMALL:
            lam = self._stretch_small(a)
            if lam is not None:
                return lam
        if not np.all(np.isfinite(a)):
            raise ValueError(f'pressure must be finite (got NaN or inf): {a!r}')
        target = a / self._p_per_h                       # h(x) = target
        bad = (target <= self._h_lo) | (target >= self._h_hi)
        if np.any(bad):
            raise ValueError(
                f'pressure {np.asarray(a[bad]).ravel()[0]!r} Pa lies beyond the monotone '
                f'branch of stage 1 (stretch range {self.lam_branch}); admissible '
                f'range is [{self.p_min}, {self.p_max}] Pa')
        x = self._solve_quadratic(target) if self._quadratic else self._solve_newton(target)
        return _as_output(1.0 + x, a.ndim == 0)

    # ---------------------------------------------------------------- solvers
    def _stretch_small(self, a: np.ndarray) -> np.ndarray | None:
        """:meth:`stretch` of a few pressures on the branch with plain floats, else None.

        The same operations as :meth:`_solve_quadratic` in the same order
        (the same result to the bit) without the overhead of a dozen numpy
        calls on a robot's handful of actuators: a simulation asks at every
        step.  None (a pressure not finite or beyond the branch) leaves the
        checks and their messages to :meth:`stretch`.
        """
        c1, k1, k1sq, pph = self._c1, self._k1, self._k1sq, self._p_per_h
        lo, hi = self._h_lo, self._h_hi
        out = []
        for v in a.tolist():
            t = v / pph
            if not lo < t < hi:
                return None
            out.append(1.0 + 2.0 * t / (k1 + math.sqrt(max(k1sq + 4.0 * c1 * t, 0.0))))
        return np.array(out)

    def _solve_quadratic(self, t: np.ndarray) -> np.ndarray:
        """Root of ``k1*x + c1*x**2 = t`` on the branch (dh/dx = sqrt(disc) > 0).

        Written as ``x = 2 t / (k1 + sqrt(k1**2 + 4 c1 t))``, free of
        cancellation for every ``t`` on the branch (also ``c1 = 0`` or ``< 0``).
        """
        c1 = float(self._kx[1]) if self._kx.size > 1 else 0.0
        disc = np.maximum(self._k1sq + 4.0 * c1 * t, 0.0)
        return 2.0 * t / (self._k1 + np.sqrt(disc))

    #: Iteration budget of :meth:`_solve_newton` (per pressure).  A root takes
    #: about 5-10 Newton steps; bisection halves a bracket of width ``w`` to
    #: the stop tolerance in about ``52 + log2(w)`` steps.
    _MAX_ITER = 200

    def _solve_newton(self, t: np.ndarray, max_iter: int | None = None) -> np.ndarray:
        """Vectorised safeguarded Newton for ``h(x) = t`` on the monotone branch.

        ``h`` is strictly increasing on ``(x_lo, x_hi)`` and ``h(0) = 0``, so
        ``[x_lo, 0]`` brackets negative targets and ``[0, x_hi]`` positive
        ones (``x_hi = inf`` is replaced by a doubling search).  Each iterate
        moves one end of the bracket; a Newton step leaving the bracket, or
        landing on one of its ends (two iterates swinging between each other
        would never shrink it), is replaced by bisection.

        A pressure is done when the Newton step is below ``2 eps (1 + |x|)``,
        the bracket is that narrow, the residual is zero, or the residual is
        at the rounding level of its own evaluation (:meth:`_noise`): then
        ``x - r/h'(x)`` is returned, as good as the arithmetic allows (further
        steps would only chase rounding noise, and may swing between two
        iterates forever).

        Raises
        ------
        RuntimeError
            If a pressure is not done after ``max_iter`` iterations (default
            :attr:`_MAX_ITER`) or cannot be bracketed; the message names the
            pressure, the bracket and the residual.
        """
        max_iter = self._MAX_ITER if max_iter is None else max_iter
        t = np.array(t, dtype=float)
        shape = t.shape
        t = t.ravel()
        lo = np.where(t >= 0.0, 0.0, self._x_lo)
        hi = np.where(t >= 0.0, self._x_hi, 0.0)
        if math.isinf(self._x_hi):
            grow = np.isinf(hi)
            step = 1.0
            while np.any(grow):
                cand = np.full(grow.sum(), step)
                with np.errstate(over='ignore'):        # inf reaches any target
                    reached = self._h_val(cand) >= t[grow]
                idx = np.flatnonzero(grow)
                hi[idx[reached]] = step
                lo[idx[~reached]] = step
                grow[idx[reached]] = False
                step *= 2.0
                if step > 1e300:            # unreachable for a finite target
                    raise RuntimeError(
                        f'stage 1: failed to bracket the stretch at '
                        f'{t[grow][0] * self._p_per_h:.6g} Pa')
        x = np.clip(t / self._k1, lo, hi)   # first-order guess, h'(0) = k(1)
        x = np.where(np.isfinite(x), x, 0.5 * (lo + hi))
        active = np.ones(t.shape, dtype=bool)
        for _ in range(max_iter):
            if not np.any(active):
                break
            xa, ta = x[active], t[active]
            r = self._h_val(xa) - ta
            lo_a = np.where(r < 0.0, xa, lo[active])
            hi_a = np.where(r > 0.0, xa, hi[active])
            d = self._dh_val(xa)
            with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
                xn = xa - r / d
            on_end = (xn != xa) & ((xn == lo_a) | (xn == hi_a))
            bisect = ~((xn >= lo_a) & (xn <= hi_a)) | on_end
            quiet = np.abs(r) <= self._noise(xa, ta)     # residual at rounding level
            xn = np.where(bisect, np.where(quiet, xa, 0.5 * (lo_a + hi_a)), xn)
            xn = np.where(r == 0.0, xa, xn)
            tol = 2.0 * _EPS * (1.0 + np.abs(xa))
            done = (np.abs(xn - xa) <= tol) | (hi_a - lo_a <= tol) | (r == 0.0) | quiet
            x[active] = xn
            lo[active], hi[active] = lo_a, hi_a
            active[np.flatnonzero(active)[done]] = False
        if np.any(active):
            i = int(np.flatnonzero(active)[0])
            res = float(self._h_val(x[i:i + 1])[0] - t[i]) / abs(t[i])
            raise RuntimeError(
                f'stage 1: the stretch at {t[i] * self._p_per_h:.6g} Pa did not converge in '
                f'{max_iter} iterations (stretch bracket [{float(1.0 + lo[i])!r}, '
                f'{float(1.0 + hi[i])!r}], relative residual {res:.3g})')
        return x.reshape(shape)
