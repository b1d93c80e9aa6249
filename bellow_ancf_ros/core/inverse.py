"""Inverse kinetostatic problem (paper section IV.C, eqs. 28-30).

Target -> stretches ``lam`` -> pressures by eq. (24).

Objective (eq. 28, ``gamma`` = 1 after scaling positions by the robot length
``L``): ``O = (p_ee - p_target)/L`` for one segment, and
``O = [(p_ee - p_target)/L, z_ee - z_target]`` for two or more segments
(position and end-effector z-axis; the tip has 5 DOF, and ``z_ee - z_target``
tells ``z`` from ``-z``).  A target is reached when ``O = 0`` to the
tolerances; otherwise the answer is the best one inside the pressure limits,
the minimiser of ``|O|^2`` over the box ``p_min <= P <= p_max`` (stage 1 is
monotone, so that is a box ``lam_min <= lam <= lam_max`` on the stretches).

* From a warm start (the previous solution along a trajectory) the paper's
  eq. (29) is solved for ``[lam, q, alpha]`` at once: full-space Newton with
  the bordered Jacobian (eq. 30) eliminated by its Schur complement (one
  factorisation per iteration).
* Otherwise, or when that path meets a pressure limit, the same equations
  are solved in reduced form: ``lam`` is the unknown, eq. (25) is solved for
  ``q(lam)`` by the forward solver (warm-started) and ``O(lam)`` is
  differentiated exactly with the implicit function theorem,
  ``dx/dlam = -J^{-1} dR/dlam`` (first block column of eq. 30).
* Two or more segments have more stretches than equations.  The answer is
  made unique as the stretches closest to those at mid-range pressure,
  ``lam_ref``, among all exact solutions inside the limits:
  ``min |lam - lam_ref|^2  s.t.  O(lam) = 0, lam_min <= lam <= lam_max``.
  The iteration ``dlam = -J^+ O + (I - J^+ J)(lam_ref - lam)`` on the free
  stretches meets its optimality conditions; a stretch that reaches a limit
  is held there, and released again when its Lagrange multiplier says that
  moving it inwards brings the stretches closer to ``lam_ref`` (an
  active-set method), so the answer does not depend on the start.
* Unreachable targets: bound-constrained least squares (scipy
  ``least_squares``, trust-region reflective) from a small fixed set of
  starts (the local answer, the warm start, vent and mid-range pressures,
  and the best corners of the pressure box, whose forward solutions are
  computed once per model and payload), each polished exactly on the face of
  its active limits; the answer is the best of all of them by ``|O|``, so it
  is never worse than any of those pressures.
* Budgets: every stage has an iteration limit, the whole solve a limit on
  forward solves (``max_forward_solves``) and optionally a wall-clock budget
  (``time_budget_s``).  When a budget runs out the best pressures found so
  far come back with status ``TIME_BUDGET`` / ``ITERATION_BUDGET``.
"""

from __future__ import annotations

from dataclasses import dataclass
import itertools
import time
import weakref

import numpy as np
import scipy.sparse.linalg as spla
from scipy.optimize import least_squares

from .assembly import RobotModel
from . import solver
from .forward import UNSTABLE, ForwardResult, assess_stability, solve_forward

__all__ = ["InverseResult", "solve_inverse", "REACHED", "UNREACHABLE", "FAILED", "UNSTABLE",
           "TIME_BUDGET", "ITERATION_BUDGET", "MAX_TARGET_LENGTHS"]

REACHED = 0
UNREACHABLE = 1
FAILED = 2
TIME_BUDGET = solver.TIME_BUDGET            # 7 (UNSTABLE, 6, is shared with the forward problem)
ITERATION_BUDGET = solver.ITERATION_BUDGET  # 8
MAX_TARGET_LENGTHS = 1e3  # targets farther from the base than this many robot lengths are refused

_RCOND = 1e-8        # z_ee - z_target has rank 2 in 3 rows: cut the round-off direction
_N_STARTS = 3        # least-squares runs for an unreachable target
_CORNER_CACHE_PAYLOADS = 4


@dataclass
class InverseResult:
    """Pressures for a target, with the pose they produce (the model's prediction)."""

    pressures_pa: np.ndarray
    stretch: np.ndarray
    reachable: bool
    position_error_m: float
    angle_error_rad: float | None
    active_limits: np.ndarray  # -1 at p_min, +1 at p_max, 0 free
    forward: ForwardResult | None
    success: bool
    status: int
    message: str
    iterations: int
    target_position: np.ndarray
    target_z_axis: np.ndarray | None

    @property
    def converged(self):
        """Whether the returned pressures come with a converged forward solution."""
        return self.forward is not None and self.forward.converged

    def to_dict(self):
        """JSON-ready dictionary (the CLI's inverse contract)."""
        d = self.forward.to_dict() if self.forward is not None else {
            "position_m": None, "rotation": None, "z_axis": None, "stretch": self.stretch.tolist(),
            "pressures_pa": self.pressures_pa.tolist(), "converged": False, "stable": None,
            "iterations": self.iterations, "residual_norm": None,
        }
        d.update({
            "pressures_pa": self.pressures_pa.tolist(),
            "stretch": self.stretch.tolist(),
            "status": int(self.status),
            "message": self.message,
            "iterations": int(self.iterations),
            "success": bool(self.success),
            "reachable": bool(self.reachable),
            "position_error_m": float(self.position_error_m),
            "angle_error_rad": None if self.angle_error_rad is None else float(self.angle_error_rad),
            "active_limits": [int(v) for v in self.active_limits],
            "target_position_m": self.target_position.tolist(),
            "target_z_axis": None if self.target_z_axis is None else self.target_z_axis.tolist(),
        })
        return d


class _OutOfBudget(Exception):
    """The solve ran out of its wall-clock or forward-solve budget."""

    def __init__(self, code):
        super().__init__(solver.MESSAGES[code])
        self.code = code


class _Budget:
    """Wall-clock deadline and number of forward solves left."""

    def __init__(self, time_budget_s, max_forward_solves):
        self.deadline = solver.deadline_after(time_budget_s)
        self.time_budget_s = time_budget_s
        self.max_forward_solves = int(max_forward_solves)
        self.used = 0

    def take(self):
        """Account for one forward solve; raise :class:`_OutOfBudget` when none is left."""
        if solver.expired(self.deadline):
            raise _OutOfBudget(TIME_BUDGET)
        if self.used >= self.max_forward_solves:
            raise _OutOfBudget(ITERATION_BUDGET)
        self.used += 1

    def remaining_s(self):
        """Seconds left (None: no wall-clock budget)."""
        if self.deadline is None:
            return None
        return max(self.deadline - time.perf_counter(), 1e-9)


def _norm(v):
    """Euclidean norm that cannot overflow."""
    v = np.asarray(v, dtype=float)
    m = float(np.max(np.abs(v))) if v.size else 0.0
    if m == 0.0 or not np.isfinite(m):
        return m
    return m * float(np.sqrt(np.sum((v / m) ** 2)))


class _Target:
    """Objective equations (eq. 28), linear in the end-plate coordinates.

    ``O = [(p_ee - p_target)/L, z_ee - z_target]`` (axis rows only with a
    target z-axis).  ``linear(v)`` applies the linear map to a state vector or
    to the columns of a matrix.
    """

    def __init__(self, model, position, z_axis):
        self.L = model.length_scale
        self.pd = model.plate_dofs[model.ee_plate]
        self.tool = model.cfg.tool_length
        self.axis = z_axis is not None
        self.offset = np.concatenate([position / self.L] + ([z_axis] if self.axis else []))

    def linear(self, v):
        pd = self.pd
        o = [(v[pd[0:3]] + self.tool * v[pd[9:12]]) / self.L]
        if self.axis:
            o.append(v[pd[9:12]])
        return np.concatenate(o)

    def __call__(self, x):
        return self.linear(x) - self.offset


def _cost(O):
    return 0.5 * float(np.dot(O, O))


class _Objective:
    """Objective (eq. 28) as a function of the stretches, with warm-started forward solves.

    Remembers the best converged evaluation (lowest ``|O|``) for a solve
    that runs out of budget.
    """

    def __init__(self, model, position, z_axis, payload, warm, tol, budget):
        self.model = model
        self.target = _Target(model, position, z_axis)
        self.payload = payload
        self.warm = warm
        self.tol = tol
        self.budget = budget
        self.last = None  # (lam, ForwardResult, O, J)
        self.best = None  # (cost, lam, ForwardResult)

    def offer(self, lam, fw):
        """Record a converged forward result as a candidate answer; return its objective."""
        O = self.target(fw.x)
        c = _cost(O)
        if self.best is None or c < self.best[0]:
            self.best = (c, np.array(lam, dtype=float), fw)
        return O

    def _forward(self, lam):
        m = self.model
        p = np.clip(m.stage1.pressure(lam), m.cfg.p_min, m.cfg.p_max)
        self.budget.take()
        fw = solve_forward(m, p, self.payload, warm_start=self.warm, check_stability=False, tol=self.tol,
                           time_budget_s=self.budget.remaining_s())
        if fw.status == TIME_BUDGET:
            raise _OutOfBudget(TIME_BUDGET)
        fw.stretch = np.array(lam, dtype=float)  # exact stretches (pressure round trip aside)
        return fw

    def evaluate(self, lam):
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
        self.last = (lam.copy(), fw, self.offer(lam, fw), self.target.linear(dx))
        return self.last


def _errors(fw, position, z_axis):
    pos_err = _norm(fw.position - position)
    ang = None
    if z_axis is not None:
        ang = float(np.arctan2(_norm(np.cross(fw.z_axis, z_axis)), np.dot(fw.z_axis, z_axis)))
    return pos_err, ang


def _max_step_into_box(lam, d, lo, hi):
    """Largest ``t <= 1`` with ``lo <= lam + t d <= hi``."""
    t = 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        up = np.where(d > 0, (hi - lam) / d, np.inf)
        dn = np.where(d < 0, (lo - lam) / d, np.inf)
    return float(min(t, np.min(up), np.min(dn)))


def _to_release(lam, free, J, lo, hi, lam_ref):
    """Index of a stretch held at a limit whose release brings ``lam`` closer to ``lam_ref`` (or None).

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


def _iterate(obj, lam, free, lo, hi, lam_ref, multi, done, max_iter):
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
            k = _to_release(lam, free, J, lo, hi, lam_ref) if multi and releases < obj.model.A else None
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
    return lam, fw, O, J, False, max_iter


def _full_space_newton(model, target, multi, payload, warm_fw, lam_ref, lo, hi, done, tol, max_iter=8):
    """Newton's method on all unknowns ``[lam, q, alpha]`` at once (eqs. 29, 30).

    The bordered Jacobian is eliminated by its Schur complement: with
    ``J_x`` factorised once per iteration, ``J_x^{-1}[R, dR/dlam]`` gives the
    reduced objective Jacobian ``J_O`` and the equilibrium correction, the
    stretch step solves ``J_O dlam = -(O - O_x J_x^{-1} R)`` (minimum-norm
    plus null-space term for redundant robots, as in the reduced iteration)
    and ``dx = -J_x^{-1}(R + dR/dlam dlam)``.  One factorisation per
    iteration and quadratic convergence: the fast path for warm-started
    targets along a trajectory.  Returns a converged ForwardResult or None
    (then the robust reduced iteration takes over): it never leaves the
    interior of the pressure box and gives up on any sign of trouble.
    """
    x, lam = warm_fw.x.copy(), warm_fw.stretch.copy()
    null_norm = [np.inf]

    def stretch_step(w0, W):
        """Stretch increment of the Schur-complement Newton step (None: leave the fast path)."""
        JO = -target.linear(W)
        Ot = target(x) - target.linear(w0)
        if multi:
            Jp = np.linalg.pinv(JO, rcond=_RCOND)
            null = (np.eye(model.A) - Jp @ JO) @ (lam_ref - lam)
            d = -Jp @ Ot + null
            null_norm[0] = float(np.max(np.abs(null)))
        else:
            null_norm[0] = 0.0
            try:
                d = -np.linalg.solve(JO, Ot)
            except np.linalg.LinAlgError:
                return None
        if not np.all(np.isfinite(d)) or np.max(np.abs(d)) > 0.05 or np.any(lam + d <= lo) \
                or np.any(lam + d >= hi):
            return None
        return d

    hist, W = [], None
    pred = warm_fw._sensitivity
    if pred is not None:
        # predictor: the warm start is an equilibrium (R ~ 0) and its sensitivities are known
        W = pred
        dlam = stretch_step(np.zeros(model.N), W)
        if dlam is None:
            return None
        x = x - W @ dlam
        lam = lam + dlam
    for it in range(max_iter + 1):
        ev = model.evaluate(x, lam, 1.0, payload, jacobian=True, lam_derivative=True)
        R = ev.residual
        rn = float(np.max(np.abs(R * model.residual_scale)))
        hist.append(rn)
        if not np.isfinite(rn) or (it >= 2 and rn > 1e-2):
            return None
        if rn <= tol and null_norm[0] <= 1e-9:
            fw = ForwardResult(
                model=model, pressures_pa=np.clip(model.stage1.pressure(lam), model.cfg.p_min, model.cfg.p_max),
                stretch=lam.copy(), payload_kg=payload, x=x, converged=True, stable=None,
                status=solver.CONVERGED, message=solver.MESSAGES[solver.CONVERGED], iterations=it,
                residual_norm=rn, history=hist, jacobian=ev.jacobian, _sensitivity=W)
            if done(fw):
                return fw
        if it == max_iter:
            break
        try:
            lu = spla.splu(ev.jacobian, permc_spec="COLAMD")
        except RuntimeError:
            return None
        sol = lu.solve(np.column_stack([R, ev.dres_dlam]))
        w0, W = sol[:, 0], sol[:, 1:]
        dlam = stretch_step(w0, W)
        if dlam is None:
            return None
        x = x - (w0 + W @ dlam)
        lam = lam + dlam
    return None


# ------------------------------------------------------- unreachable targets
_CORNERS = weakref.WeakKeyDictionary()  # model -> {payload: [(lam, ForwardResult), ...] or partial}


def _corner_solutions(model, payload, budget):
    """Stable forward solutions at the corners of the pressure box, computed once per model and payload.

    Work done before a budget runs out is kept for the next call.
    """
    per_model = _CORNERS.setdefault(model, {})
    entry = per_model.get(payload)
    if entry is None:
        while len(per_model) >= _CORNER_CACHE_PAYLOADS:
            per_model.pop(next(iter(per_model)))
        entry = per_model[payload] = {"next": 0, "items": []}
    cfg, st = model.cfg, model.stage1
    corners = list(itertools.product((cfg.p_min, cfg.p_max), repeat=model.A))
    while entry["next"] < len(corners):
        p = np.array(corners[entry["next"]])
        budget.take()
        fw = solve_forward(model, p, payload, time_budget_s=budget.remaining_s())
        if fw.status == TIME_BUDGET:
            raise _OutOfBudget(TIME_BUDGET)
        entry["next"] += 1
        if fw.success:
            fw.stretch = np.where(p == cfg.p_max, st.lam_max, st.lam_min).astype(float)
            entry["items"].append((fw.stretch.copy(), fw))
    return entry["items"]


def _best_in_limits(obj, candidates, lo, hi, lam_ref, multi, done, max_iter):
    """Best stretches inside the limits from a fixed set of starts (see the module docstring).

    ``candidates`` are converged ``(lam, ForwardResult)`` pairs; the best
    ``_N_STARTS`` distinct ones by ``|O|`` start a bound-constrained least-squares
    run each, polished on the face of its active limits.  Returns
    ``(lam, fw, reached, iterations)`` of the best answer seen.
    """
    A = obj.model.A
    eps = 1e-4 if multi else 0.0
    scored = sorted(((_cost(obj.offer(lam, fw)), i, lam, fw) for i, (lam, fw) in enumerate(candidates)),
                    key=lambda t: t[:2])
    starts, iters = [], 0
    for c, _, lam, fw in scored:
        if all(np.max(np.abs(lam - s[0])) > 1e-6 for s in starts):
            starts.append((lam, fw))
        if len(starts) == _N_STARTS:
            break

    def fun(v):
        _, _, Ov, _ = obj.evaluate(v)
        if Ov is None:
            raise _ForwardFailure()
        return np.concatenate([Ov, eps * (v - lam_ref)]) if multi else Ov

    def jac(v):
        Jv = obj.evaluate(v)[3]
        return np.vstack([Jv, eps * np.eye(A)]) if multi else Jv

    for lam0, fw0 in starts:
        obj.warm = fw0
        try:
            ls = least_squares(fun, np.clip(lam0, lo + 1e-12, hi - 1e-12), jac=jac, bounds=(lo, hi),
                               method="trf", ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=50)
        except _ForwardFailure:
            continue
        iters += int(ls.nfev)
        lam = ls.x.copy()
        lam[ls.active_mask < 0] = lo[ls.active_mask < 0]
        lam[ls.active_mask > 0] = hi[ls.active_mask > 0]
        span = hi - lo
        free = (ls.active_mask == 0) & (lam > lo + 1e-10 * span) & (lam < hi - 1e-10 * span)
        lam, fw, O, _, reached, it2 = _iterate(obj, lam, free, lo, hi, lam_ref, multi, done, max_iter)
        iters += it2
        if reached:
            return lam, fw, True, iters
    c, lam, fw = obj.best
    return lam, fw, done(fw), iters


class _ForwardFailure(RuntimeError):
    pass


# ------------------------------------------------------------------ driver
def _check_target(model, position, z_axis):
    """Validated target position and unit z-axis (None for one segment)."""
    position = np.asarray(position, dtype=float).reshape(3)
    if not np.all(np.isfinite(position)):
        raise ValueError("target position must be finite")
    L = model.length_scale
    dist = _norm(position)
    if dist > MAX_TARGET_LENGTHS * L:
        raise ValueError(f"target position is {dist:.3g} m from the base, more than "
                         f"{MAX_TARGET_LENGTHS:g} robot lengths ({MAX_TARGET_LENGTHS * L:.3g} m): "
                         "refused as absurd")
    if model.cfg.n_segments < 2:
        return position, None
    if z_axis is None:
        raise ValueError("a robot with two or more segments needs a target z-axis")
    z_axis = np.asarray(z_axis, dtype=float).reshape(3)
    m = float(np.max(np.abs(z_axis)))
    if not np.all(np.isfinite(z_axis)) or m == 0.0:
        raise ValueError("target z-axis must be a finite non-zero vector")
    z_axis = z_axis / m  # any finite non-zero vector is a direction, whatever its length
    return position, z_axis / np.linalg.norm(z_axis)


def solve_inverse(model: RobotModel, position, z_axis=None, payload_kg=0.0, warm_start=None,
                  position_tol=None, angle_tol=None, max_iter=30, tol=1e-10, time_budget_s=None,
                  max_forward_solves=400) -> InverseResult:
    """Inverse kinetostatic problem: pressures for a target pose.

    Parameters
    ----------
    position : (3,) target end-effector position [m] in the base frame
        (refused beyond ``MAX_TARGET_LENGTHS`` robot lengths from the base).
    z_axis : (3,) target end-effector z-axis (required for two or more
        segments, ignored for one); any finite non-zero vector.
    warm_start : InverseResult or ForwardResult, optional
        The previous solution along a trajectory.
    position_tol, angle_tol : a target counts as reached (``reachable``)
        within these errors; defaults ``1e-8 * L`` and ``1e-8`` rad.
    max_iter : iteration limit of each stage (Newton / Gauss-Newton steps).
    max_forward_solves : budget of forward solves for the whole call.
    time_budget_s : optional wall-clock budget [s].  When a budget runs out,
        the best pressures found so far come back (finite, in limits, with
        their true errors; ``forward`` None if there were none yet) with
        status ``TIME_BUDGET`` or ``ITERATION_BUDGET`` and ``success`` false.
    """
    budget = _Budget(time_budget_s, max_forward_solves)
    cfg = model.cfg
    position, z_axis = _check_target(model, position, z_axis)
    multi = z_axis is not None
    payload = float(payload_kg)
    if not np.isfinite(payload) or payload < 0:
        raise ValueError(f"payload must be a finite non-negative mass in kg, got {payload_kg}")
    L = model.length_scale
    ptol = 1e-8 * L if position_tol is None else float(position_tol)
    atol = 1e-8 if angle_tol is None else float(angle_tol)
    st = model.stage1
    lo, hi = np.full(model.A, st.lam_min), np.full(model.A, st.lam_max)
    lam_ref = np.full(model.A, float(st.stretch(0.5 * (cfg.p_min + cfg.p_max))))

    def done(fw):
        pe, ae = _errors(fw, position, z_axis)
        return pe <= ptol and (ae is None or ae <= atol)

    warm_fw = warm_start.forward if isinstance(warm_start, InverseResult) else warm_start
    if warm_fw is not None and not warm_fw.converged:
        warm_fw = None
    obj = _Objective(model, position, z_axis, payload, None, tol, budget)
    iters = 0
    try:
        if warm_fw is not None and warm_fw.payload_kg != payload:
            budget.take()
            warm_fw = solve_forward(model, warm_fw.pressures_pa, payload, warm_start=warm_fw,
                                    check_stability=False, time_budget_s=budget.remaining_s())
            warm_fw = warm_fw if warm_fw.converged else None
        obj.warm = warm_fw
        if warm_fw is not None:
            obj.offer(warm_fw.stretch, warm_fw)
        # 0) fast path: full-space Newton from a warm start (interior solutions only)
        fw = None
        if warm_fw is not None:
            fw = _full_space_newton(model, obj.target, multi, payload, warm_fw, lam_ref, lo, hi, done, tol)
        if fw is not None:
            lam, reached, iters = fw.stretch, True, fw.iterations
        else:
            # 1) reduced iteration from the warm start (or the canonical cold start)
            start = warm_fw.stretch if warm_fw is not None else (lam_ref if multi else np.ones(model.A))
            lam = np.clip(start, lo, hi)
            lam, fw, O, _, reached, iters = _iterate(obj, lam, np.ones(model.A, bool), lo, hi, lam_ref,
                                                     multi, done, max_iter)
            if not reached:
                # 2) best answer inside the limits from a fixed set of starts
                candidates = [] if O is None else [(lam, fw)]
                if warm_fw is not None:
                    candidates.append((warm_fw.stretch, warm_fw))
                for seed in (np.ones(model.A), lam_ref):
                    _, fw_s, O_s, _ = obj.evaluate(np.clip(seed, lo, hi))
                    if O_s is not None:
                        candidates.append((np.clip(seed, lo, hi), fw_s))
                candidates += _corner_solutions(model, payload, budget)
                if candidates:
                    lam, fw, reached, it2 = _best_in_limits(obj, candidates, lo, hi, lam_ref, multi, done,
                                                            max_iter)
                    iters += it2
                else:
                    fw = None
    except _OutOfBudget as exc:
        return _budget_result(model, obj, exc.code, budget, iters, position, z_axis, warm_fw, done)

    if fw is None or not fw.converged:
        return _failed_result(model, warm_fw, iters, position, z_axis,
                              "forward solve failed during the inverse iteration")
    return _result(model, lam, fw, reached, iters, position, z_axis)


def _result(model, lam, fw, reached, iters, position, z_axis, status=None, note=""):
    cfg, st = model.cfg, model.stage1
    lo, hi = st.lam_min, st.lam_max
    pressures = np.clip(st.pressure(lam), cfg.p_min, cfg.p_max)
    fw.pressures_pa = pressures
    assess_stability(fw)
    pe, ae = _errors(fw, position, z_axis)
    near = 1e-9 * (hi - lo)  # least squares keeps its iterates 1e-12 inside the box
    active = np.where(lam <= lo + near, -1, np.where(lam >= hi - near, 1, 0))
    errors = (f"position error {pe * 1e3:.4g} mm"
              + ("" if ae is None else f", angle error {np.degrees(ae):.4g} deg"))
    if status is not None:
        msg = f"{note}; best pressures so far: {errors}"
    elif not fw.stable:
        status, msg = UNSTABLE, fw.message
    elif reached:
        status, msg = REACHED, "target reached"
    else:
        status = UNREACHABLE
        msg = f"target unreachable within the pressure limits: best {errors}"
    return InverseResult(
        pressures_pa=pressures, stretch=np.array(lam, dtype=float), reachable=bool(reached),
        position_error_m=pe, angle_error_rad=ae, active_limits=active.astype(int), forward=fw,
        success=bool(reached and fw.stable and status == REACHED), status=status, message=msg,
        iterations=iters, target_position=position, target_z_axis=z_axis,
    )


def _failed_result(model, warm_fw, iters, position, z_axis, message, status=FAILED):
    """Never hand out NaN: the last good pressures (or vent), flagged."""
    cfg = model.cfg
    base = warm_fw.pressures_pa if warm_fw is not None else np.zeros(model.A)
    p = np.clip(np.nan_to_num(base), cfg.p_min, cfg.p_max)
    return InverseResult(
        pressures_pa=p, stretch=model.stage1.stretch(p), reachable=False, position_error_m=float("inf"),
        angle_error_rad=None if z_axis is None else float("inf"), active_limits=np.zeros(model.A, int),
        forward=None, success=False, status=status, message=message, iterations=iters,
        target_position=position, target_z_axis=z_axis,
    )


def _budget_result(model, obj, code, budget, iters, position, z_axis, warm_fw, done):
    """The best pressures found before a budget ran out, with status ``code``."""
    if code == TIME_BUDGET:
        note = f"wall-clock budget of {budget.time_budget_s:g} s exhausted"
    else:
        note = f"budget of {budget.max_forward_solves} forward solves exhausted"
    note += f" after {budget.used} forward solves"
    if obj.best is None:
        return _failed_result(model, warm_fw, iters, position, z_axis, note + "; no solution yet", code)
    _, lam, fw = obj.best
    return _result(model, lam, fw, done(fw), iters, position, z_axis, status=code, note=note)
