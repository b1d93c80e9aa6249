"""Chord steps of the warm-started inverse solve, compiled (eqs. 25, 28-30).

Along a trajectory, :func:`core.solve._inverse_warm.full_space_newton` first
reuses the factorisation of the KKT matrix (eq. 27) made near an
earlier answer: each chord step is one residual evaluation, one
single-column solve and a few small products, so that the loop of
such steps runs here, compiled, with no Python call per step.  The step is
the one of ``full_space_newton`` (Schur complement of the bordered
Jacobian, with ``J_x`` and ``W = J_x^{-1} dR/dlam`` frozen)::

    w0   = J_x^{-1} R(x, lam)
    dlam = -J_O^{-1} (O(x) - T w0)   [+ (I - J_O^+ J_O)(lam_ref - lam), redundant]
    x   <- x - (w0 + W dlam),   lam <- lam + dlam

The loop stops when the residual is below the tolerance, when a step cuts
it by less than ``rate``, after ``max_steps``, or when a step would leave
the trust region or the pressure box; the caller goes on with Newton's
method from there.  The factorisation is the envelope LDL^T of
:mod:`core.linalg._ldlt` or, where that was refused, the banded LU of ``dgbtrf``:
:func:`banded_solve` is LAPACK's ``dgbtrs`` (no transpose, one right-hand
side) for it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..linalg import EnvelopeLDL, ldl_solve_vector
from ..model import as_tip_load, element_parameters, evaluate_kernel

__all__ = ["banded_solve", "chord_steps", "stretch_step", "CONVERGED", "STALLED", "LEFT_BOX",
           "MAX_STEPS", "NONFINITE"]

CONVERGED, STALLED, LEFT_BOX, MAX_STEPS, NONFINITE = 0, 1, 2, 3, 4

# the factorisation not used by a call of the loop (the same types: one compiled loop)
_NO_LU = (np.zeros((1, 1), order="F"), np.zeros(1, dtype=np.int32), 0, 0,
          np.zeros(1, dtype=np.int64))
_NO_LDL = (np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0), 0.0)
_NO_LDL[2].flags.writeable = False  # as a pattern's packed integers


@njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def banded_solve(lub, piv, kl, ku, b):
    """Solve ``A x = b`` with the banded LU of scipy's ``dgbtrf`` (``lub``, ``piv``); a copy.

    ``piv`` is 0-based, as scipy's wrapper returns it.  The column sweeps of
    ``dgbtrs`` (sums reassociated for speed: equal to it to round-off).
    """
    n = b.shape[0]
    x = b.copy()
    kd = kl + ku
    lubT = lub.T  # column j of the band storage, contiguous (dgbtrf's output is Fortran-ordered)
    for j in range(n - 1):  # L: row interchanges and unit lower band
        p = piv[j]
        if p != j:
            t = x[p]
            x[p] = x[j]
            x[j] = t
        m = min(kl, n - 1 - j)
        xj = x[j]
        if xj != 0.0:
            xs = x[j + 1:j + 1 + m]
            ls = lubT[j, kd + 1:kd + 1 + m]
            for i in range(m):
                xs[i] -= ls[i] * xj
    for j in range(n - 1, -1, -1):  # U: upper band of width kl + ku
        xj = x[j] / lubT[j, kd]
        x[j] = xj
        if xj != 0.0:
            m = min(kd, j)
            xs = x[j - m:j]
            us = lubT[j, kd - m:kd]
            for i in range(m):
                xs[i] -= us[i] * xj
    return x


@njit(cache=True, nogil=True)
def _target(v, pd, tool, L, axis, offset):
    """Objective of eq. (28) at the state ``v`` (``offset`` subtracted; zeros: linear part)."""
    k = 6 if axis else 3
    o = np.empty(k)
    for i in range(3):
        o[i] = (v[pd[i]] + tool * v[pd[9 + i]]) / L - offset[i]
        if axis:
            o[3 + i] = v[pd[9 + i]] - offset[3 + i]
    return o


@njit(cache=True, nogil=True)
def stretch_step(x, w0, lam, pd, tool, L, axis, offset, JOinv, proj, use_proj, lam_ref, lo, hi):
    """Stretch increment of the Schur-complement step (eqs. 28, 30); ``(d, null_norm, ok)``.

    ``d = -J_O^{-1} (O(x) - T w0)`` plus, for a redundant robot
    (``use_proj``), the null-space term ``(I - J_O^+ J_O)(lam_ref - lam)``
    whose largest entry is ``null_norm``.  ``ok`` is false when ``d`` is not
    finite, larger than 0.05 in any stretch, or leaves the open box
    ``(lo, hi)``.
    """
    zero = np.zeros(offset.shape[0])
    Ot = _target(x, pd, tool, L, axis, offset) - _target(w0, pd, tool, L, axis, zero)
    d = -(JOinv @ Ot)
    null_norm = 0.0
    if use_proj:
        null = proj @ (lam_ref - lam)
        for i in range(null.shape[0]):
            a = abs(null[i])
            if a != a:
                null_norm = np.inf  # NaN
            elif a > null_norm:
                null_norm = a
        d = d + null
    ok = True
    for i in range(d.shape[0]):
        if not (abs(d[i]) <= 0.05 and lo[i] < lam[i] + d[i] < hi[i]):
            ok = False
    return d, null_norm, ok


@njit(cache=True, nogil=True)
def _solve(lu, ldl, b):
    """``J^{-1} b`` with the envelope LDL^T (``ldl[0]`` non-empty) or else the banded LU."""
    if ldl[0].shape[0] > 0:
        return ldl_solve_vector(ldl[0], ldl[1], ldl[2], ldl[3], ldl[4], b)
    lub, piv, kl, ku, perm = lu
    N = b.shape[0]
    bp = np.empty(N)
    for i in range(N):
        bp[i] = b[perm[i]]
    sol = banded_solve(lub, piv, kl, ku, bp)
    w0 = np.empty(N)
    for i in range(N):
        w0[perm[i]] = sol[i]
    return w0


@njit(cache=True, nogil=True)
def _chord_loop(x, lam, rn_prev, lu, ldl, W, JOinv, proj, use_proj, lam_ref,
                lo, hi, pd, tool, L, axis, offset, scale, kcoef, dkcoef, l0, n_el, d_a, rho0,
                g, Qpoint, kargs, tol, rate, max_steps):
    N = x.shape[0]
    nq = Qpoint.shape[0]
    hist = np.empty(max_steps + 1)
    n_steps = 0
    status = MAX_STEPS
    rn = np.inf
    while True:
        le, kt, kb, dle, dkt, dkb = element_parameters(lam, kcoef, dkcoef, l0, n_el, d_a)
        res, _, _ = evaluate_kernel(
            x[:nq], x[nq:], lam, le, kt, kb, dle, dkt, dkb, rho0, g, Qpoint,
            kargs[0], kargs[1], kargs[2], kargs[3], kargs[4], kargs[5], kargs[6], kargs[7],
            kargs[8], kargs[9], kargs[10], kargs[11], kargs[12], kargs[13], kargs[14],
            kargs[15], kargs[16], kargs[17], False, False)
        rn = 0.0
        for i in range(N):
            a = abs(res[i] * scale[i])
            if not a <= rn:  # also NaN
                rn = a
        hist[n_steps] = rn
        if not np.isfinite(rn):
            status = NONFINITE
            break
        if rn <= tol:
            status = CONVERGED
            break
        if rn > rate * rn_prev:
            status = STALLED
            break
        if n_steps >= max_steps:
            status = MAX_STEPS
            break
        w0 = _solve(lu, ldl, res)
        d, _, ok = stretch_step(x, w0, lam, pd, tool, L, axis, offset, JOinv, proj, use_proj,
                                lam_ref, lo, hi)
        if not ok:
            status = LEFT_BOX
            break
        x = x - (w0 + W @ d)
        lam = lam + d
        rn_prev = rn
        n_steps += 1
    return x, lam, status, n_steps, hist[: n_steps + 1], rn


def chord_steps(model, load, target, lu, W, step, x, lam, tol, rate, max_steps,
                rn_prev=np.inf, null_space=True):
    """Chord steps from ``(x, lam)`` with the factorisation ``lu`` and ``W``.

    ``lu``: an ``ldlt.EnvelopeLDL`` or a ``BandedLU``; ``load``: the
    :class:`~bellow_ancf_ros.core.model.TipLoad`.

    ``step`` is the ``inverse_warm._StretchStep`` of ``W`` (``J_O``'s
    inverse, the null-space projector; ``null_space`` False: the
    minimum-norm steps alone, without the null-space term).  Returns ``(x,
    lam, status, steps, history, rn)``: the last iterate (its residual norm
    ``rn``, evaluated), why the loop stopped, the steps taken and the
    residual norms seen.
    """
    proj = step.proj if null_space else None
    use_proj = proj is not None
    static = _static_args(model, as_tip_load(load), target)
    if isinstance(lu, EnvelopeLDL):
        ldl, lu_args = lu.args(), _NO_LU
    else:
        p = lu.p
        ldl, lu_args = _NO_LDL, (lu.lub, lu.piv, p.kl, p.ku, p.perm)
    out = _chord_loop(
        np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(lam, dtype=float),
        float(rn_prev), lu_args, ldl, np.ascontiguousarray(W),
        np.ascontiguousarray(step.inv), np.ascontiguousarray(proj) if use_proj else
        np.zeros((model.A, model.A)), use_proj, step.lam_ref, step.lo, step.hi,
        static[0], float(target.tool), float(target.L), bool(target.axis), target.offset,
        *static[1:], model.kernel_args, float(tol), float(rate), int(max_steps))
    x, lam, status, steps, hist, rn = out
    return x, lam, int(status), int(steps), [float(h) for h in hist], float(rn)


def _static_args(model, load, target):
    """The loop's arguments that depend on the model and tip load only (kept on the model)."""
    cache = model.cached("chord_static", lambda m: {})  # tip load -> arguments
    args = cache.get(load)
    if args is None:
        cfg, st = model.cfg, model.stage1
        Qpoint = model.point_forces(load)
        args = cache[load] = (
            target.pd.astype(np.int64), model.residual_scale,
            np.asarray(st.k_coefficients, dtype=float),
            np.asarray(st.dk_coefficients, dtype=float),
            float(cfg.l0), float(model.n), float(cfg.d_a), float(cfg.rho0), model.gravity, Qpoint)
        while len(cache) > 8:
            cache.pop(next(iter(cache)))
    return args
