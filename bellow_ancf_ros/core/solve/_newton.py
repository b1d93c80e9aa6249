"""Newton solver for the saddle-point equations (25) with load continuation.

The paper solves eq. (25) with Levenberg-Marquardt (eq. 26).  Here the same
residual and the same analytic Jacobian (eq. 27) drive a Newton method on
``x = [q, alpha]`` with a backtracking line search on the scaled residual
norm (the Newton direction is always a descent direction of ``|r|^2``), so the
convergence is quadratic near the solution.  When a step fails, the
actuation and the loads are applied in increments (continuation from the last
converged state), in the style of cardillo's static solver.

Stability: an equilibrium is stable when the Hessian of the Lagrangian
``d2Pi/dq2 + sum alpha_i d2C_i/dq2`` is positive definite on the tangent
space of the constraints, ``Z^T H Z > 0`` with ``C_q Z = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..status import ForwardStatus as _S

__all__ = ["NewtonResult", "newton", "continuation", "ReducedHessian", "deadline_after", "expired"]


def deadline_after(time_budget_s):
    """Absolute ``time.perf_counter()`` deadline for a budget in seconds (None: no deadline)."""
    if time_budget_s is None:
        return None
    budget = float(time_budget_s)
    if not budget > 0:  # also NaN
        raise ValueError("time_budget_s must be a positive number of seconds or None, "
                         f"got {time_budget_s!r}")
    return time.perf_counter() + budget


def expired(deadline):
    """Whether the ``deadline`` (from :func:`deadline_after`) has passed."""
    return deadline is not None and time.perf_counter() > deadline


@dataclass
class NewtonResult:
    x: np.ndarray
    converged: bool
    status: int
    message: str
    iterations: int
    residual_norm: float  # scaled infinity norm
    history: list = field(default_factory=list)
    jacobian: object = None  # Jacobian at x (when converged; factorised by whoever needs it)
    # continuation that ran out of budget: (t, x, next step, cut Newton iterate), see continuation
    reached: tuple | None = None


# chord phase of newton(): below this scaled residual the last factorisation is reused while
# each step cuts the residual at least by CHORD_CUT (one residual evaluation and one banded
# solve per step instead of a Jacobian and a factorisation)
# (from the PCC cold start: 1e-1 and 0.2 save a factorisation or two against 1e-2 and 0.05)
CHORD_BELOW = 1e-1
CHORD_CUT = 0.2


def newton(fun, x0, scale, tol=1e-10, max_iter=25, min_alpha=1.0 / 64, floor_tol=1e-7,
           deadline=None):
    """Damped Newton on ``fun(x, jacobian=True) -> Evaluation``, with a chord phase.

    ``scale`` multiplies the residual component-wise; convergence when the
    scaled infinity norm drops below ``tol``, or when it stops decreasing
    below ``floor_tol`` (round-off floor: fine meshes cannot reach ``tol``).
    Near the solution (scaled residual below ``CHORD_BELOW``) the last
    factorisation is reused as long as every such chord step cuts the
    residual by ``CHORD_CUT`` at least (else a Newton step again); the
    Newton steps converge quadratically (``CHORD_BELOW = 0`` switches the
    chord phase off).  ``history`` holds the scaled residual norm of every
    iterate.  At most ``max_iter`` Newton iterations (``iterations`` counts
    them; chord steps are extra, at most as many); past ``deadline``
    (``time.perf_counter()``) it stops with status ``TIME_BUDGET``.
    The Jacobian returned is the one at the solution.
    """
    x = np.array(x0, dtype=float)
    ev = fun(x, jacobian=True)
    r = ev.residual * scale
    if not np.all(np.isfinite(r)):
        return NewtonResult(x, False, _S.NONFINITE, _S.NONFINITE.message, 0, np.inf, [np.inf])
    norm = np.max(np.abs(r))
    hist = [norm]
    last = None  # the last Evaluation whose Jacobian was factorised (chord steps reuse it)
    it, n_chord = 0, 0  # Newton iterations (what ``iterations`` and budgets count), chord steps
    while True:
        # converged, or stagnating at the round-off floor of a fine discretisation
        # (the Jacobian at the solution is returned; it is factorised only if someone needs it)
        if norm <= tol or (norm <= floor_tol and len(hist) > 1 and norm > 0.25 * hist[-2]):
            if ev.jacobian is None:
                ev = fun(x, jacobian=True)
            return NewtonResult(x, True, _S.CONVERGED, _S.CONVERGED.message, it, norm, hist,
                                ev.jacobian)
        if it == max_iter:
            break
        if expired(deadline):
            return NewtonResult(x, False, _S.TIME_BUDGET, _S.TIME_BUDGET.message, it, norm, hist)
        if last is not None and norm <= CHORD_BELOW and n_chord < max_iter:
            try:
                xt = x - last.solve(ev.residual)
            except np.linalg.LinAlgError:
                xt = None
            if xt is not None:
                evt = fun(xt, jacobian=False)
                rt = evt.residual * scale
                nt = np.max(np.abs(rt)) if np.all(np.isfinite(rt)) else np.inf
                if nt <= CHORD_CUT * norm or nt <= tol:
                    x, ev, r, norm = xt, evt, rt, nt
                    hist.append(norm)
                    n_chord += 1
                    continue
            last = None  # the chord stalls here: a Newton step from x
        if ev.jacobian is None:
            ev = fun(x, jacobian=True)
        try:
            dx = -ev.solve(ev.residual)  # envelope LDL^T or banded LU (core.linsolve)
        except np.linalg.LinAlgError:
            return NewtonResult(x, False, _S.SINGULAR, _S.SINGULAR.message, it, norm, hist)
        if not np.all(np.isfinite(dx)):
            return NewtonResult(x, False, _S.SINGULAR, _S.SINGULAR.message, it, norm, hist)
        last = ev
        merit = np.dot(r, r)
        step = 1.0
        while True:
            xt = x + step * dx
            evt = fun(xt, jacobian=True)
            rt = evt.residual * scale
            if np.all(np.isfinite(rt)) and np.dot(rt, rt) <= (1.0 - 1e-4 * step) * merit:
                break
            step *= 0.5
            if step < min_alpha:
                return NewtonResult(x, False, _S.LINE_SEARCH, _S.LINE_SEARCH.message, it, norm,
                                    hist)
        x, ev, r = xt, evt, rt
        norm = np.max(np.abs(r))
        hist.append(norm)
        it += 1
    return NewtonResult(x, False, _S.MAX_ITER, _S.MAX_ITER.message, max_iter, norm, hist)


def continuation(make_fun, x_start, scale, tol=1e-10, max_iter=25, min_step=1.0 / 1024,
                 iteration_budget=None, deadline=None, first_step=1.0, first_guess=None):
    """Follow ``make_fun(t)`` from ``t = 0`` (solved by ``x_start``) to ``t = 1``.

    First tries the full step; on failure halves the increment, and doubles it
    again after successes.  Returns the :class:`NewtonResult` at ``t = 1``
    (``iterations`` counts all Newton iterations), or the failure.  At most
    ``iteration_budget`` Newton iterations in all (status ``ITERATION_BUDGET``)
    and nothing past ``deadline`` (status ``TIME_BUDGET``); a result that ran
    out of budget keeps its last converged point in ``reached = (t, x)`` (an
    exact solution of ``make_fun(t)``) and the step it would try next,
    ``reached = (t, x, dt, x_cut)`` (``x_cut``: the Newton iterate of the
    step to ``t + dt`` that was cut short, or None), so that a later call can
    continue (``first_step``, and ``first_guess``: the Newton start of the
    first step instead of ``x_start``).
    """
    t, dt, x = 0.0, float(first_step), np.array(x_start, dtype=float)
    total = 0
    hist = []
    while True:
        left = None if iteration_budget is None else iteration_budget - total
        if (left is not None and left <= 0) or expired(deadline):
            code = _S.TIME_BUDGET if expired(deadline) else _S.ITERATION_BUDGET
            return NewtonResult(x, False, code, f"{code.message} at load fraction {t:.4g} "
                                f"({total} Newton iterations)", total, np.inf, hist,
                                reached=(t, x, dt, None))
        tn = min(1.0, t + dt)
        its = max_iter if left is None else min(max_iter, left)
        guess, first_guess = (x if first_guess is None else first_guess), None
        res = newton(make_fun(tn), guess, scale, tol=tol, max_iter=its, deadline=deadline)
        total += res.iterations
        if res.converged:
            t, x = tn, res.x
            hist = res.history
            if t >= 1.0:
                res.iterations = total
                res.history = hist
                return res
            dt = min(2.0 * dt, 1.0 - t)
        elif res.status == _S.TIME_BUDGET:
            res.iterations = total
            res.reached = (t, x, dt, res.x)  # this step goes on from its Newton iterate
            res.message = (f"{_S.TIME_BUDGET.message} at load fraction {t:.4g} "
                           f"({total} Newton iterations)")
            return res
        else:
            dt *= 0.5
            if dt < min_step:
                res.iterations = total
                res.status = _S.STEP_TOO_SMALL
                res.message = (f"{_S.STEP_TOO_SMALL.message} at load fraction {t:.4g} "
                               f"(last: {res.message})")
                return res


class ReducedHessian:
    """Lagrangian Hessian on the constraint tangent space (stability, docs/model.md section 3).

    ``jacobian`` is the KKT matrix (eq. 27) ``[[H, C_q^T], [C_q, 0]]``.  A
    basis ``Z`` of the null space of ``C_q`` comes from an LU factorisation
    with partial pivoting ``P C_q^T = [L1; L2] U``: ``Z = P^T [-L1^{-T} L2^T; I]``
    (then ``C_q Z = 0``).  ``Z`` is not orthonormal, so the eigenvalues of
    the reduced Hessian are those of the pencil ``(Z^T H Z, Z^T Z)``; by
    Sylvester's law of inertia its definiteness is that of ``Q^T H Q`` for
    any orthonormal basis ``Q``.  ``dof_scale`` rescales the coordinates
    (``q = D y``) so that positions and gradients weigh alike.

    ``is_positive_definite(rtol)`` is one Cholesky factorisation (cheap);
    ``min_eigenvalue`` solves the small generalised eigenproblem on demand.
    """

    def __init__(self, jacobian, nq, dof_scale=None):
        J = jacobian.tocsc() if hasattr(jacobian, "tocsc") else sp.csc_matrix(jacobian)
        H = J[:nq, :nq]
        Cq = J[nq:, :nq]
        if dof_scale is not None:
            D = sp.diags(dof_scale)
            H = D @ H @ D
            Cq = Cq @ D
        nc = Cq.shape[0]
        perm, L, _ = sla.lu(Cq.toarray().T, p_indices=True)  # Cq^T = L[perm] @ U
        L1, L2 = L[:nc], L[nc:]
        W = np.empty((nq, nq - nc))
        W[:nc] = -sla.solve_triangular(L1, L2.T, trans="T", unit_diagonal=True, lower=True)
        W[nc:] = np.eye(nq - nc)
        Z = W[perm]  # then (L[perm])^T Z = L^T W = 0, i.e. C_q Z = 0
        Hr = Z.T @ (H @ Z)
        self.H = 0.5 * (Hr + Hr.T)
        self.B = Z.T @ Z
        self.ref = float(abs(H).max())

    def is_positive_definite(self, rtol=1e-10):
        """Return whether the smallest eigenvalue is above ``rtol * max|H|``."""
        try:
            sla.cholesky(self.H - rtol * self.ref * self.B, lower=True)
        except sla.LinAlgError:
            return False
        return True

    @property
    def min_eigenvalue(self):
        return float(sla.eigh(self.H, self.B, eigvals_only=True, subset_by_index=[0, 0])[0])
