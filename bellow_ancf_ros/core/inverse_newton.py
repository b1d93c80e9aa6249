"""Exact solutions of the inverse problem (eqs. 28-30): objective, Newton iterations, budget.

Used by :func:`bellow_ancf_ros.core.inverse.solve_inverse` (see its module
docstring for the method): the objective ``O`` of eq. (28) as a function of
the stretches with exact sensitivities (implicit function theorem), the
reduced Newton / minimum-norm Gauss-Newton iteration with its active set on
the pressure limits, the full-space Newton method on ``[lam, q, alpha]``
(eqs. 29, 30) and the solve's budget.
"""

from __future__ import annotations

import dataclasses
import math
import time
import weakref

import numpy as np

from . import linsolve, solver
from .chord import CONVERGED as CHORD_CONVERGED, NONFINITE, chord_steps
from .forward import ForwardResult, solve_forward

__all__ = [
    "Budget",
    "OutOfBudget",
    "Target",
    "Objective",
    "cost",
    "norm",
    "pose_errors",
    "iterate",
    "full_space_newton",
    "cold_solution",
]

TIME_BUDGET = solver.TIME_BUDGET
ITERATION_BUDGET = solver.ITERATION_BUDGET
_RCOND = 1e-8  # z_ee - z_target has rank 2 in 3 rows: cut the round-off direction
# cold forward solves (done, or cut short by a budget): model -> {(payload, tol, P): result}
_COLD = weakref.WeakKeyDictionary()
_COLD_CACHE_SIZE = 8


class OutOfBudget(Exception):
    """The solve ran out of its wall-clock or forward-solve budget."""

    def __init__(self, code):
        """Set up; see the class docstring."""
        super().__init__(solver.MESSAGES[code])
        self.code = code


class Budget:
    """Wall-clock deadline and number of forward solves left.

    Progress guarantee (so that budget slices converge): while ``grace`` is
    on, the deadline does not stop the solve; the solve turns it off
    (:meth:`progress`) as soon as it has a new accepted iterate, and it ends
    anyway ``GRACE_BUDGETS`` budgets past the deadline (``strict``: ignore it).
    """

    GRACE_BUDGETS = 4.0

    def __init__(self, time_budget_s, max_forward_solves):
        """Set up; see the class docstring."""
        self.deadline = solver.deadline_after(time_budget_s)
        self.time_budget_s = time_budget_s
        self.max_forward_solves = int(max_forward_solves)
        self.used = 0
        self.grace = False
        self._grace_end = (None if self.deadline is None
                           else self.deadline + self.GRACE_BUDGETS * float(time_budget_s))

    def progress(self):
        """The solve has made progress: from now on the deadline holds."""
        self.grace = False

    def current_deadline(self, strict=False):
        """Deadline in force (``time.perf_counter()``; None: none)."""
        if self.deadline is None:
            return None
        if self.grace and not strict:
            if time.perf_counter() > self._grace_end:
                self.grace = False
            else:
                return self._grace_end
        return self.deadline

    def expired(self, strict=False):
        """Whether the deadline in force has passed."""
        return solver.expired(self.current_deadline(strict))

    def take(self):
        """Account for one forward solve; raise :class:`OutOfBudget` when none is left."""
        if self.expired():
            raise OutOfBudget(TIME_BUDGET)
        if self.used >= self.max_forward_solves:
            raise OutOfBudget(ITERATION_BUDGET)
        self.used += 1

    def remaining_s(self, strict=False):
        """Seconds left (None: no wall-clock budget)."""
        deadline = self.current_deadline(strict)
        if deadline is None:
            return None
        return max(deadline - time.perf_counter(), 1e-9)


def norm(v):
    """Euclidean norm that cannot overflow (nor underflow)."""
    v = np.asarray(v, dtype=float).ravel()
    if v.size <= 8:
        return math.hypot(*v.tolist())  # scaled internally: no overflow, no underflow
    m = float(np.max(np.abs(v))) if v.size else 0.0
    if m == 0.0 or not np.isfinite(m):
        return m
    return m * float(np.sqrt(np.sum((v / m) ** 2)))


class Target:
    """Objective equations (eq. 28), linear in the end-plate coordinates.

    ``O = [(p_ee - p_target)/L, z_ee - z_target]`` (axis rows only with a
    target z-axis).  ``linear(v)`` applies the linear map to a state vector or
    to the columns of a matrix.
    """

    def __init__(self, model, position, z_axis):
        """Set up; see the class docstring."""
        self.L = model.length_scale
        self.pd = model.plate_dofs[model.ee_plate]
        self.tool = model.cfg.tool_length
        self.axis = z_axis is not None
        self.offset = np.concatenate([position / self.L] + ([z_axis] if self.axis else []))

    def linear(self, v):
        """The linear part of ``O`` applied to ``v`` (a state or the columns of a matrix)."""
        pd = self.pd
        o = [(v[pd[0:3]] + self.tool * v[pd[9:12]]) / self.L]
        if self.axis:
            o.append(v[pd[9:12]])
        return np.concatenate(o)

    def __call__(self, x):
        """Objective ``O`` at the state ``x``."""
        return self.linear(x) - self.offset


def cost(O):  # noqa: E741 - the paper's name
    """Least-squares cost ``|O|^2 / 2``."""
    return 0.5 * float(np.dot(O, O))


class Objective:
    """Objective (eq. 28) as a function of the stretches, with warm-started forward solves.

    Remembers the best converged evaluation (lowest ``|O|``) for a solve
    that runs out of budget, and the point an interrupted solve continues
    from (``resume``: the last accepted iterate, with its sensitivities).
    """

    def __init__(self, model, position, z_axis, payload, warm, tol, budget):
        """Set up; see the class docstring."""
        self.model = model
        self.target = Target(model, position, z_axis)
        self.payload = payload
        self.warm = warm
        self.tol = tol
        self.budget = budget
        self.last = None  # (lam, ForwardResult, O, J)
        self.best = None  # (cost, lam, ForwardResult)
        self.resume = None  # (lam, ForwardResult, dx/dlam) of the last accepted iterate
        self._last_dx = None
        self.cut = None  # (lam, ForwardResult) of a forward solve the budget cut short
        self.pending = {}  # stretches -> cut ForwardResult of an earlier call, to continue

    def offer(self, lam, fw):
        """Record a converged forward result as a candidate answer; return its objective."""
        O = self.target(fw.x)  # noqa: E741
        c = cost(O)
        if self.best is None or c < self.best[0]:
            self.best = (c, np.array(lam, dtype=float), fw)
        return O

    def advance(self, lam):
        """The iterate at ``lam`` (the last evaluation) is accepted: progress of the solve."""
        if self.last is None or self.last[2] is None or not np.array_equal(self.last[0], lam):
            return
        self.resume = (self.last[0], self.last[1], self._last_dx)
        self.budget.progress()

    def seed(self, fw):
        """Use a converged ``fw`` that carries its sensitivities as the evaluation at its stretch.

        Only results of a solve that ran out of budget carry them (``_sensitivity``).
        """
        W = fw._sensitivity
        if W is None or not fw.converged or fw.payload_kg != self.payload:
            return
        lam = np.array(fw.stretch, dtype=float)
        self.warm = fw
        self._last_dx = -W
        self.last = (lam, fw, self.offer(lam, fw), self.target.linear(-W))

    def _forward(self, lam):
        m = self.model
        p = np.clip(m.stage1.pressure(lam), m.cfg.p_min, m.cfg.p_max)
        self.budget.take()
        if self.warm is None:
            fw = cold_solution(m, p, self.payload, self.tol, self.budget)
        else:
            fw = solve_forward(
                m,
                p,
                self.payload,
                warm_start=self.pending.pop(np.asarray(lam, dtype=float).tobytes(), self.warm),
                check_stability=False,
                tol=self.tol,
                time_budget_s=self.budget.remaining_s(),
            )
        if fw.status == TIME_BUDGET:
            if fw.resume_state is not None and self.warm is not None:
                self.cut = (np.array(lam, dtype=float), fw)  # the next call goes on with it
            raise OutOfBudget(TIME_BUDGET)
        fw.stretch = np.array(lam, dtype=float)  # exact stretches (pressure round trip aside)
        return fw

    def evaluate(self, lam):
        """``(lam, ForwardResult, O, dO/dlam)`` at ``lam`` (``O`` None: no convergence)."""
        lam = np.asarray(lam, dtype=float)
        if self.last is not None and np.array_equal(self.last[0], lam):
            return self.last
        m = self.model
        fw = self._forward(lam)
        if not fw.converged:
            self.last = (lam.copy(), fw, None, None)
            return self.last
        self.warm = fw
        ev = m.evaluate(fw.x, lam, 1.0, self.payload, jacobian=False, lam_derivative=True)
        dx = -fw.lu.solve(ev.dres_dlam)  # (N, A) implicit function theorem
        self._last_dx = dx
        self.last = (lam.copy(), fw, self.offer(lam, fw), self.target.linear(dx))
        return self.last


def cold_solution(model, pressures, payload, tol, budget):
    """Cold-started forward solve (no stability check), cached per model, payload and pressures.

    The inverse solves cold only at its canonical start (the same pressures
    every time), so the solution is kept (a copy is returned), and a solve
    cut short by the budget keeps its last equilibrium for the next call
    (``ForwardResult.resume_state``): cold solves progress across budget slices.
    """
    cache = _COLD.setdefault(model, {})
    key = (float(payload), float(tol), np.asarray(pressures, dtype=float).tobytes())
    entry = cache.get(key)
    if entry is not None and entry.converged:
        return dataclasses.replace(entry)
    fw = solve_forward(model, pressures, payload, warm_start=entry, check_stability=False,
                       tol=tol, time_budget_s=budget.remaining_s())
    if fw.converged or fw.resume_state is not None:
        while key not in cache and len(cache) >= _COLD_CACHE_SIZE:
            cache.pop(next(iter(cache)))
        cache[key] = fw
    return dataclasses.replace(fw) if fw.converged else fw


def pose_errors(fw, position, z_axis):
    """Position error [m] and angle error [rad] (None without a target axis) of ``fw``."""
    p_ee, rot = fw.model.end_effector(fw.q)
    pos_err = norm(p_ee - position)
    ang = None
    if z_axis is not None:
        z = rot[:, 2]
        cross = (z[1] * z_axis[2] - z[2] * z_axis[1], z[2] * z_axis[0] - z[0] * z_axis[2],
                 z[0] * z_axis[1] - z[1] * z_axis[0])
        ang = float(np.arctan2(norm(cross), z @ z_axis))
    return pos_err, ang


def _max_step_into_box(lam, d, lo, hi):
    """Largest ``t <= 1`` with ``lo <= lam + t d <= hi``."""
    t = 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        up = np.where(d > 0, (hi - lam) / d, np.inf)
        dn = np.where(d < 0, (lo - lam) / d, np.inf)
    return float(min(t, np.min(up), np.min(dn)))


def _to_release(lam, free, J, lo, hi, lam_ref):
    """Index of a held stretch whose release brings ``lam`` closer to ``lam_ref`` (or None).

    KKT conditions of ``min |lam - lam_ref|^2/2  s.t.  O(lam) = 0`` with the
    held stretches as bound constraints: with ``mu`` from the free rows,
    ``g = (lam - lam_ref) + J^T mu`` is the bound multiplier; it must be
    ``>= 0`` at ``lam_min`` and ``<= 0`` at ``lam_max``.
    """
    held = ~free
    if not held.any():
        return None
    r = lam - lam_ref
    mu = -np.linalg.pinv(J[:, free].T, rcond=_RCOND) @ r[free]
    g = r + J.T @ mu
    at_lo = held & (lam <= lo + 1e-12)
    at_hi = held & (lam >= hi - 1e-12)
    violation = np.where(at_lo, -g, np.where(at_hi, g, 0.0))
    k = int(np.argmax(violation))
    return k if violation[k] > 1e-9 else None


def iterate(obj, lam, free, lo, hi, lam_ref, multi, done, max_iter):
    """Newton / minimum-norm Gauss-Newton on the free stretches (the others stay fixed).

    Minimises the residual of the optimality conditions: the target
    equations ``O`` and, when there are more free stretches than equations,
    the null-space condition ``(I - J^+ J)(lam - lam_ref) = 0``.  A stretch
    that blocks the step at a limit is held there; for redundant robots a
    held stretch is released when the KKT conditions ask for it.  Returns
    ``(lam, fw, O, J, reached, iterations)``; ``reached`` is false when the
    iteration stalls (a bound, an unreachable target, a failed forward solve).
    """
    free = free.copy()
    span = hi - lo

    def merit_of(lam_v, O_v, J_v):
        Jf = J_v[:, free]
        Jp = np.linalg.pinv(Jf, rcond=_RCOND)
        null = None
        val = float(np.dot(O_v, O_v))
        if multi and free.any():
            null = (np.eye(int(free.sum())) - Jp @ Jf) @ (lam_ref - lam_v)[free]
            val += float(np.dot(null, null))
        return val, Jp, null

    _, fw, O, J = obj.evaluate(lam)
    if O is None:
        return lam, fw, O, J, False, 0
    if not free.any():
        return lam, fw, O, J, done(fw), 0
    merit, Jp, null = merit_of(lam, O, J)
    releases = 0
    for it in range(max_iter):
        if done(fw) and (null is None or np.max(np.abs(null)) <= 1e-9):
            k = (
                _to_release(lam, free, J, lo, hi, lam_ref)
                if multi and releases < obj.model.A
                else None
            )
            if k is None:
                return lam, fw, O, J, True, it
            free[k] = True
            releases += 1
            merit, Jp, null = merit_of(lam, O, J)
            continue
        d = np.zeros_like(lam)
        d[free] = -Jp @ O + (0.0 if null is None else null)
        d *= min(1.0, 0.05 / max(np.max(np.abs(d)), 1e-300))  # trust limit on the stretch change
        t = _max_step_into_box(lam, d, lo, hi)
        if t < 1e-12:
            # blocked by a bound: those stretches become active (held at the limit)
            block = ((lam <= lo + 1e-10 * span) & (d < 0)) | ((lam >= hi - 1e-10 * span) & (d > 0))
            block &= free
            if not block.any() or not (free & ~block).any():
                return lam, fw, O, J, False, it
            lam = np.where(block & (d < 0), lo, np.where(block & (d > 0), hi, lam))
            free = free & ~block
            _, fw, O, J = obj.evaluate(lam)
            if O is None:
                return lam, fw, O, J, False, it
            merit, Jp, null = merit_of(lam, O, J)
            continue
        if np.max(np.abs(d)) < 1e-15:
            return lam, fw, O, J, False, it
        step = t
        while step > t / 64:
            lam_try = np.clip(lam + step * d, lo, hi)
            _, fw_t, O_t, J_t = obj.evaluate(lam_try)
            if O_t is not None:
                merit_t, Jp_t, null_t = merit_of(lam_try, O_t, J_t)
                if merit_t < merit:
                    break
            step *= 0.5
        else:
            return lam, fw, O, J, False, it + 1
        lam, fw, O, J, merit, Jp, null = lam_try, fw_t, O_t, J_t, merit_t, Jp_t, null_t
        obj.advance(lam)
    return lam, fw, O, J, False, max_iter


# chord steps (a factorisation from an earlier point, reused): each must cut the residual by
# this factor at least, and at most this many in a row; then Newton with a new factorisation
CHORD_RATE = 0.1
MAX_CHORD = 12
# redundant robots: a refined W (one step with the last factorisation) counts as the W of its
# iterate when the refinement changed it by less than REFINE_TOL (relative); up to REFINE_MAX
# it is used and refined again at the next iterate; beyond, a new factorisation
REFINE_TOL = 1e-6
REFINE_MAX = 1e-2


class _StretchStep:
    """The stretch part of the Schur-complement step for one sensitivity matrix ``W``.

    ``J_O = -T W`` (``T``: the objective's linear map, the same for every
    target of a model) and its (pseudo-)inverse and null-space projector are
    made once per ``W`` and kept with it (``of``), so that chord steps and
    predictors with the same ``W`` cost a few matrix-vector products each.
    """

    def __init__(self, target, multi, W, lam_ref, lo, hi):
        """Set up; see the class docstring."""
        self.W, self.lam_ref, self.lo, self.hi = W, lam_ref, lo, hi
        JO = -target.linear(W)
        self.inv, self.proj = None, None
        if np.all(np.isfinite(JO)):
            if multi:
                self.inv = np.linalg.pinv(JO, rcond=_RCOND)
                self.proj = np.eye(W.shape[1]) - self.inv @ JO
            else:
                try:
                    self.inv = np.linalg.inv(JO)
                except np.linalg.LinAlgError:
                    pass
        self.null_norm = np.inf

    @classmethod
    def of(cls, cache, target, multi, W, lam_ref, lo, hi):
        """The step map of ``W`` from ``cache`` (a dict kept with ``W``), made on first use."""
        key = (target.axis, multi)
        sm = cache.get(key)
        if sm is None or sm.W is not W:
            sm = cache[key] = cls(target, multi, W, lam_ref, lo, hi)
        return sm

    def __call__(self, target, x, lam, w0):
        """Stretch increment at the state ``x``, ``w0 = J^{-1} R`` (None: leave the fast path)."""
        if self.inv is None:
            return None
        Ot = target(x) - target.linear(w0)
        d = -self.inv @ Ot
        if self.proj is not None:
            null = self.proj @ (self.lam_ref - lam)
            d = d + null
            self.null_norm = float(np.max(np.abs(null)))
        else:
            self.null_norm = 0.0
        if (
            not np.all(np.isfinite(d))
            or np.max(np.abs(d)) > 0.05
            or np.any(lam + d <= self.lo)
            or np.any(lam + d >= self.hi)
        ):
            return None
        return d


def _second_order(path, t_new, W, x, lam, lo, hi):
    """The linear predictor ``(x, lam)`` plus the last target's correction, scaled (or as is).

    ``path`` (``ForwardResult._path`` of the warm start): its target ``t_w``,
    the target before ``t_prev`` and what the iteration added to its own
    linear prediction, made with the sensitivities ``(W_w, fresh_w)``, and
    whether the warm start's own ``W`` is fresh (made near it, not inherited).
    Along a path sampled at a steady rate, the targets step alike and the
    second-order term of the prediction is nearly the same: when the new
    step ``t_new - t_w`` is within 25 % of the last one and the prediction
    uses the same ``W`` or a fresh one like the last, the correction is
    added, scaled by the squared ratio of the steps (a start only: the
    iteration's answer does not depend on it).
    """
    if path is None or path[1] is None or path[2] is None:
        return x, lam
    t_w, t_prev, cx, cl, (W_w, fresh_w), fresh = path
    if not (W_w is W or (fresh_w and fresh)):
        return x, lam
    last = norm(t_w - t_prev)
    if not last > 0 or norm(t_new - t_w - (t_w - t_prev)) > 0.25 * last:
        return x, lam
    s = (norm(t_new - t_w) / last) ** 2
    lam_c = lam + s * cl
    if np.any(lam_c <= lo) or np.any(lam_c >= hi):
        return x, lam
    return x + s * cx, lam_c


def full_space_newton(
    model, target, multi, payload, warm_fw, lam_ref, lo, hi, done, tol, max_iter=8,
    budget=None,
):
    """Newton's method on all unknowns ``[lam, q, alpha]`` at once (eqs. 29, 30), chord first.

    The bordered Jacobian is eliminated by its Schur complement: with
    ``J_x`` factorised, ``W = J_x^{-1} dR/dlam`` gives the reduced objective
    Jacobian ``J_O = -T W`` and the equilibrium correction, the stretch step
    solves ``J_O dlam = -(O - T J_x^{-1} R)`` (minimum-norm plus null-space
    term for redundant robots, as in the reduced iteration) and
    ``dx = -J_x^{-1}(R + dR/dlam dlam)``.

    The predictor is the linear step with the warm start's ``W`` (plus, along
    a steady path, the last target's second-order correction:
    :func:`_second_order`).  Then the factorisation of an earlier answer
    (carried by the warm start, ``ForwardResult._chord``) is reused: compiled
    chord steps (:mod:`core.chord`), one single-column banded solve each,
    linear convergence at a rate that grows with the distance to where it
    was made (measured 0.015 to 0.05 per millimetre of target motion).  They
    must cut the residual by ``CHORD_RATE`` each; when they do not (or after
    ``MAX_CHORD`` of them) a Newton step with a new factorisation follows,
    and the chord steps go on with it.  The answer does not depend on the
    factorisation used: for one segment (as many target equations as
    stretches) the iteration solves ``R = 0, O = 0`` whatever ``J_x``
    approximates it; for redundant robots the null-space condition needs the
    exact ``W``, so the answer is accepted only after a step whose ``W`` is
    the one of its iterate (a new factorisation there, or ``W`` refined with
    the last one to ``REFINE_TOL``) and whose null-space correction is below
    1e-9.  A held target is accepted at once when the warm start's ``W`` was
    such a one (``ForwardResult._sensitivity_exact``).

    Returns a converged ForwardResult or None (then the robust reduced
    iteration takes over): it never leaves the interior of the pressure box
    and gives up on any sign of trouble, or when the ``budget``'s deadline
    has passed (checked before every factorisation).
    """
    x, lam = warm_fw.x.copy(), warm_fw.stretch.copy()

    def step_map(W, cache):
        return _StretchStep.of(cache, target, multi, W, lam_ref, lo, hi)

    def result(ev, rn, its):
        return ForwardResult(
            model=model,
            pressures_pa=np.clip(model.stage1.pressure(lam), model.cfg.p_min, model.cfg.p_max),
            stretch=lam.copy(), payload_kg=payload, x=x, converged=True, stable=None,
            status=solver.CONVERGED, message=solver.MESSAGES[solver.CONVERGED],
            iterations=its, residual_norm=rn, history=hist, jacobian=ev.jacobian,
            _sensitivity=W, _sensitivity_exact=exact, _chord=chord, _step_maps=maps,
            _path=(target.offset, t_warm, None if lin is None else x - lin[0],
                   None if lin is None else lam - lin[1], lin_W, W is not warm_fw._sensitivity),
        )

    hist, sm, lin, lin_W = [], None, None, None
    t_warm = None if warm_fw._path is None else warm_fw._path[0]
    chord = warm_fw._chord  # (factorisation, its W) from an earlier answer, or None
    W = warm_fw._sensitivity
    maps = warm_fw._step_maps if warm_fw._step_maps is not None else {}  # step maps of W
    if W is not None:
        # predictor: the warm start is an equilibrium (R ~ 0) and its sensitivities are known
        sm = step_map(W, maps)
        dlam = sm(target, x, lam, np.zeros(model.N))
        if dlam is None:
            return None
        x = x - W @ dlam
        lam = lam + dlam
        lin, lin_W = (x, lam), W
        x, lam = _second_order(warm_fw._path, target.offset, W, x, lam, lo, hi)
        lin_W = (W, warm_fw._path is not None and warm_fw._path[5])
    n_chord, newton_its, n_refine, refine, first = 0, 0, 0, False, True
    # exact: the last step's W is the one at its own iterate (factorised there, or refined);
    # the predictor's is when the warm start's was (a held target is accepted at once)
    exact = multi and sm is not None and bool(warm_fw._sensitivity_exact)
    while True:
        lu = None if chord is None else getattr(chord[0], "lu", None)
        if first or not exact or not multi:
            first = False
            if isinstance(lu, linsolve.BandedLU):
                chord_map = step_map(chord[1], maps if chord[1] is W else {})
                if chord_map.inv is not None:
                    # compiled chord steps (core.chord) with the factorisation of an earlier point
                    x, lam, status, steps, h, rn = chord_steps(
                        model, payload, target, lu, chord[1], chord_map, x, lam, tol,
                        CHORD_RATE, MAX_CHORD)
                    hist += h
                    n_chord += steps
                    exact = exact and steps == 0
                    if status == NONFINITE:
                        return None
                    if status == CHORD_CONVERGED and not multi:
                        ev = model.evaluate(x, lam, 1.0, payload, jacobian=True)
                        fw = result(ev, rn, newton_its + n_chord)
                        if done(fw):
                            return fw
                    hist.pop()  # evaluated again below, with its Jacobian
        ev = model.evaluate(x, lam, 1.0, payload, jacobian=True, lam_derivative=True)
        rn = float(np.max(np.abs(ev.residual * model.residual_scale)))
        hist.append(rn)
        if not np.isfinite(rn):
            return None
        if rn <= tol and (not multi or (exact and sm.null_norm <= 1e-9)):
            fw = result(ev, rn, newton_its + n_chord + n_refine)
            if done(fw):
                return fw
        if (newton_its >= 2 and rn > 1e-2) or newton_its >= max_iter:
            return None
        if budget is not None and budget.expired():
            return None
        if refine and n_refine < max_iter:
            # redundant robot after a Newton step: W at this iterate by one refinement with the
            # last factorisation; it counts as this iterate's W when the refinement changed it
            # by less than REFINE_TOL, is refined again at the next iterate when by less than
            # REFINE_MAX, else a new factorisation is made
            sol = chord[0].solve(np.column_stack([ev.residual, ev.dres_dlam - ev.jacobian @ W]))
            dW = sol[:, 1:]
            W_new = W + dW
            change = np.max(np.abs(dW)) / max(np.max(np.abs(W_new)), 1e-300)
            if change <= REFINE_MAX:
                n_refine += 1
                w0, W, maps = sol[:, 0], W_new, {}
                chord = (chord[0], W)
                sm = step_map(W, maps)
                dlam = sm(target, x, lam, w0)
                if dlam is None:
                    return None
                x = x - (w0 + W @ dlam)
                lam = lam + dlam
                exact = change <= REFINE_TOL
                continue
        factorised = linsolve.kkt_solver(model).bound(ev.jacobian)
        try:
            sol = factorised.solve(np.column_stack([ev.residual, ev.dres_dlam]))  # banded LU
        except np.linalg.LinAlgError:
            return None
        newton_its += 1
        w0, W = sol[:, 0], sol[:, 1:]
        chord, maps = (factorised, W), {}
        sm = step_map(W, maps)
        dlam = sm(target, x, lam, w0)
        if dlam is None:
            return None
        x = x - (w0 + W @ dlam)
        lam = lam + dlam
        exact, refine = True, multi
