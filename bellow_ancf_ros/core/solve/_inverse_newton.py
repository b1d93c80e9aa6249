"""Exact solutions of the inverse problem (eqs. 28-30): objective, Newton iterations, budget.

Used by :func:`bellow_ancf_ros.core.solve._inverse.solve_inverse` (see its module
docstring for the method): the objective ``O`` of eq. (28) as a function of
the stretches with exact sensitivities (implicit function theorem), the
reduced Newton / minimum-norm Gauss-Newton iteration with its active set on
the pressure limits and the solve's budget.  The warm-started full-space
Newton method on ``[lam, q, alpha]`` (eqs. 29, 30) is :mod:`core.solve._inverse_warm`.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from ..status import ForwardStatus
from . import _newton as solver
from ._forward import solve_forward

__all__ = [
    "Budget",
    "OutOfBudget",
    "Target",
    "Objective",
    "cost",
    "norm",
    "pose_errors",
    "iterate",
    "cold_solution",
]

TIME_BUDGET = ForwardStatus.TIME_BUDGET
ITERATION_BUDGET = ForwardStatus.ITERATION_BUDGET
RCOND = 1e-8  # z_ee - z_target has rank 2 in 3 rows: cut the round-off direction
# cold forward solves (done, or cut short by a budget), kept with the model:
# {(tip load, tol, P): result} (RobotModel.cached)
_COLD_CACHE_SIZE = 8


class OutOfBudget(Exception):
    """The solve ran out of its wall-clock or forward-solve budget."""

    def __init__(self, code):
        """Set up; see the class docstring."""
        super().__init__(ForwardStatus(code).message)
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
    that runs out of budget, the point an interrupted solve continues
    from (``resume``: the last accepted iterate, with its sensitivities),
    and the least-squares runs its search for the best answer has still to
    do (``search``).
    """

    def __init__(self, model, position, z_axis, load, warm, tol, budget):
        """Set up; see the class docstring (``load``: the TipLoad)."""
        self.model = model
        self.target = Target(model, position, z_axis)
        self.load = load
        self.warm = warm
        self.tol = tol
        self.budget = budget
        self.last = None  # (lam, ForwardResult, O, J)
        self.best = None  # (cost, lam, ForwardResult)
        self.resume = None  # (lam, ForwardResult, dx/dlam) of the last accepted iterate
        self._last_dx = None
        self.cut = None  # (lam, ForwardResult) of a forward solve the budget cut short
        self.pending = {}  # stretches -> cut ForwardResult of an earlier call, to continue
        # the least-squares runs of the search for the best answer still to do, as
        # (lam, ForwardResult) starts: the running one (from its best iterate) first
        # (None: the search has not chosen its starts; _inverse_limits.best_in_limits)
        self.search = None

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

        Only results of a solve that ran out of budget carry them (``WarmState.sensitivity``).
        """
        W = None if fw._warm is None else fw._warm.sensitivity
        if W is None or not fw.converged or fw.load != self.load:
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
            fw = cold_solution(m, p, self.load, self.tol, self.budget)
        else:
            fw = solve_forward(
                m,
                p,
                self.load.payload_kg,
                warm_start=self.pending.pop(np.asarray(lam, dtype=float).tobytes(), self.warm),
                check_stability=False,
                tol=self.tol,
                time_budget_s=self.budget.remaining_s(),
                tip_force_n=self.load.force_n,
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
        ev = m.evaluate(fw.x, lam, 1.0, self.load, jacobian=False, lam_derivative=True)
        dx = -fw.lu.solve(ev.dres_dlam)  # (N, A) implicit function theorem
        self._last_dx = dx
        self.last = (lam.copy(), fw, self.offer(lam, fw), self.target.linear(dx))
        return self.last


def cold_solution(model, pressures, load, tol, budget):
    """Cold-started forward solve (no stability check), cached per model, tip load and pressures.

    The inverse solves cold only at its canonical start (the same pressures
    every time), so the solution is kept (a copy is returned), and a solve
    cut short by the budget keeps its last equilibrium for the next call
    (``ForwardResult.resume_state``): cold solves progress across budget slices.
    """
    cache = model.cached("cold_solutions", lambda m: {})
    key = (load, float(tol), np.asarray(pressures, dtype=float).tobytes())
    entry = cache.get(key)
    if entry is not None and entry.converged:
        return dataclasses.replace(entry)
    fw = solve_forward(model, pressures, load.payload_kg, warm_start=entry, check_stability=False,
                       tol=tol, time_budget_s=budget.remaining_s(), tip_force_n=load.force_n)
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
    mu = -np.linalg.pinv(J[:, free].T, rcond=RCOND) @ r[free]
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
        Jp = np.linalg.pinv(Jf, rcond=RCOND)
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
