"""Inverse kinetostatic problem (paper section IV.C, eqs. 28-30).

Target -> stretches ``lam`` -> pressures by eq. (24).

The paper solves eq. (29) for ``[lam, q, alpha]`` at once.  Here, from a
warm start (the previous solution along a trajectory), exactly that is done:
full-space Newton on eq. (29) with the bordered Jacobian (eq. 30) eliminated
by its Schur complement (one factorisation per iteration).  Without a usable
warm start, or when that path meets a pressure limit, the same equations are
solved in reduced form: ``lam`` is the unknown, eq. (25) is solved for
``q(lam)`` by the forward solver (warm-started), and the objective (eq. 28)
``O(lam) = O(q(lam))`` is differentiated exactly with the implicit function
theorem, ``dx/dlam = -J^{-1} dR/dlam``, using the factorised Jacobian
(eq. 27) and the analytic ``dR/dlam`` (first block column of eq. 30).  The
pressure limits are box bounds on ``lam`` (stage 1 is monotone, so
``p_min <= P <= p_max`` iff ``lam_min <= lam <= lam_max``).

* One segment: ``O = (p_ee - p_target)/L``; three equations, three stretches,
  Newton's method.
* Two or more segments: ``O = [(p_ee - p_target)/L, t1.z_ee, t2.z_ee]`` with
  ``t1, t2`` orthonormal to the target axis (the end effector has 5 DOF,
  eq. 28; ``gamma`` = 1 after scaling the position by the robot length ``L``).
  There are more stretches than equations; the answer is made unique as the
  stretch vector closest to a fixed reference ``lam_ref`` (the stretches at
  mid-range pressure) among all exact solutions:
  ``min |lam - lam_ref|^2  s.t.  O(lam) = 0``.  Its optimality condition
  ``(I - J^+ J)(lam - lam_ref) = 0`` is met by the iteration
  ``dlam = -J^+ O + (I - J^+ J)(lam_ref - lam)``; the answer depends on the
  target only (not on the path), so it is smooth and repeatable along a
  trajectory.
* Limits: an interior Newton step is cut back to stay inside the bounds; if
  the solution is not interior (target unreachable, or the step stalls at a
  bound), a bound-constrained least-squares problem (scipy
  ``least_squares``, trust-region reflective) gives the best reachable
  stretches, and ``active_limits`` tells which pressures sit at a limit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from .assembly import RobotModel
from . import solver
from .forward import UNSTABLE, ForwardResult, assess_stability, solve_forward

__all__ = ["InverseResult", "solve_inverse"]

REACHED = 0
UNREACHABLE = 1
FAILED = 2  # UNSTABLE (6) is shared with the forward problem


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
        return self.forward is not None and self.forward.converged

    def to_dict(self):
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


class _Target:
    """Objective equations (eq. 28), linear in the end-plate coordinates.

    ``O = [(p_ee - p_target)/L, t1.z_ee, t2.z_ee]`` (axis rows only with a target
    z-axis; ``t1, t2`` span the plane normal to it).  ``linear(v)`` applies the
    linear map to a state vector or to the columns of a matrix.
    """

    def __init__(self, model, position, z_axis):
        self.L = model.length_scale
        self.pd = model.plate_dofs[model.ee_plate]
        self.tool = model.cfg.tool_length
        self.T = None
        if z_axis is not None:
            a = np.eye(3)[np.argmin(np.abs(z_axis))]
            t1 = np.cross(z_axis, a)
            t1 /= np.linalg.norm(t1)
            self.T = np.stack([t1, np.cross(z_axis, t1)])
        self.offset = np.concatenate([position / self.L] + ([np.zeros(2)] if z_axis is not None else []))

    def linear(self, v):
        pd = self.pd
        o = [(v[pd[0:3]] + self.tool * v[pd[9:12]]) / self.L]
        if self.T is not None:
            o.append(self.T @ v[pd[9:12]])
        return np.concatenate(o)

    def __call__(self, x):
        return self.linear(x) - self.offset


class _Objective:
    """Objective (eq. 28) as a function of the stretches, with warm-started forward solves."""

    def __init__(self, model, position, z_axis, payload, warm, tol):
        self.model = model
        self.target = _Target(model, position, z_axis)
        self.payload = payload
        self.warm = warm
        self.tol = tol
        self.last = None  # (lam, ForwardResult, O, J)

    def _forward(self, lam):
        m = self.model
        p = m.stage1.pressure(lam)
        p = np.clip(p, m.cfg.p_min, m.cfg.p_max)
        fw = solve_forward(m, p, self.payload, warm_start=self.warm, check_stability=False, tol=self.tol)
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
        self.last = (lam.copy(), fw, self.target(fw.x), self.target.linear(dx))
        return self.last


def _errors(fw, position, z_axis):
    pos_err = float(np.linalg.norm(fw.position - position))
    ang = None
    if z_axis is not None:
        ang = float(np.arctan2(np.linalg.norm(np.cross(fw.z_axis, z_axis)), np.dot(fw.z_axis, z_axis)))
    return pos_err, ang


def _max_step_into_box(lam, d, lo, hi):
    """Largest ``t <= 1`` with ``lo <= lam + t d <= hi``."""
    t = 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        up = np.where(d > 0, (hi - lam) / d, np.inf)
        dn = np.where(d < 0, (lo - lam) / d, np.inf)
    return float(min(t, np.min(up), np.min(dn)))


def _iterate(obj, lam, free, lo, hi, lam_ref, multi, done, max_iter):
    """Newton / minimum-norm Gauss-Newton on the free stretches (the others stay fixed).

    Minimises the residual of the optimality conditions: the target
    equations ``O`` and, when there are more free stretches than equations,
    the null-space condition ``(I - J^+ J)(lam - lam_ref) = 0``.  Returns
    ``(lam, fw, O, J, reached, iterations)``; ``reached`` is false when the
    iteration stalls (a bound, an unreachable target, a failed forward solve).
    """
    free = free.copy()
    nf = int(free.sum())

    def merit_of(lam_v, O_v, J_v):
        Jf = J_v[:, free]
        Jp = np.linalg.pinv(Jf)
        null = None
        val = float(np.dot(O_v, O_v))
        if multi and nf > len(O_v):
            null = (np.eye(nf) - Jp @ Jf) @ (lam_ref - lam_v)[free]
            val += float(np.dot(null, null))
        return val, Jp, null

    _, fw, O, J = obj.evaluate(lam)
    if O is None or nf == 0:
        return lam, fw, O, J, O is not None and done(fw), 0
    merit, Jp, null = merit_of(lam, O, J)
    for it in range(max_iter):
        if done(fw) and (null is None or np.max(np.abs(null)) <= 1e-9):
            return lam, fw, O, J, True, it
        d = np.zeros_like(lam)
        d[free] = -Jp @ O + (0.0 if null is None else null)
        d *= min(1.0, 0.05 / max(np.max(np.abs(d)), 1e-300))  # trust limit on the stretch change
        t = _max_step_into_box(lam, d, lo, hi)
        if t < 1e-12:
            # blocked by a bound: those stretches become active (held at the limit)
            span = hi - lo
            block = ((lam <= lo + 1e-10 * span) & (d < 0)) | ((lam >= hi - 1e-10 * span) & (d > 0))
            if not block.any() or not (free & ~block).any():
                return lam, fw, O, J, False, it
            lam = np.where(block & (d < 0), lo, np.where(block & (d > 0), hi, lam))
            free = free & ~block
            nf = int(free.sum())
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
    return lam, fw, O, J, done(fw), max_iter


def _full_space_newton(model, position, z_axis, payload, warm_fw, lam_ref, lo, hi, done, tol, max_iter=8):
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
    pressure box and gives up on any sign of trouble.
    """
    multi = z_axis is not None
    target = _Target(model, position, z_axis)

    x, lam = warm_fw.x.copy(), warm_fw.stretch.copy()
    null_norm = [np.inf]

    def stretch_step(w0, W):
        """Stretch increment of the Schur-complement Newton step (None: leave the fast path)."""
        JO = -target.linear(W)
        Ot = target(x) - target.linear(w0)
        if multi:
            Jp = np.linalg.pinv(JO)
            null = (np.eye(model.A) - Jp @ JO) @ (lam_ref - lam)
            d = -Jp @ Ot + null
            null_norm[0] = float(np.max(np.abs(null)))
        else:
            null_norm[0] = 0.0
            try:
                d = -np.linalg.solve(JO, Ot)
            except np.linalg.LinAlgError:
                return None
        if np.max(np.abs(d)) > 0.05 or np.any(lam + d < lo) or np.any(lam + d > hi):
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
            sol = ev.solve(np.column_stack([R, ev.dres_dlam]))  # banded LU (core.linsolve)
        except np.linalg.LinAlgError:
            return None
        w0, W = sol[:, 0], sol[:, 1:]
        dlam = stretch_step(w0, W)
        if dlam is None:
            return None
        x = x - (w0 + W @ dlam)
        lam = lam + dlam
    return None


def solve_inverse(model: RobotModel, position, z_axis=None, payload_kg=0.0, warm_start=None,
                  position_tol=None, angle_tol=None, max_iter=30, tol=1e-10) -> InverseResult:
    """Inverse kinetostatic problem: pressures for a target pose.

    Parameters
    ----------
    position : (3,) target end-effector position [m] in the base frame.
    z_axis : (3,) target end-effector z-axis (required for two or more
        segments, ignored for one).  Normalised here.
    warm_start : InverseResult or ForwardResult, optional
        The previous solution along a trajectory.
    position_tol, angle_tol : a target counts as reached (``reachable``)
        within these errors; defaults ``1e-8 * L`` and ``1e-8`` rad.
    """
    cfg = model.cfg
    position = np.asarray(position, dtype=float).reshape(3)
    if not np.all(np.isfinite(position)):
        raise ValueError("target position must be finite")
    multi = cfg.n_segments >= 2
    if multi:
        if z_axis is None:
            raise ValueError("a robot with two or more segments needs a target z-axis")
        z_axis = np.asarray(z_axis, dtype=float).reshape(3)
        nz = np.linalg.norm(z_axis)
        if not np.isfinite(nz) or nz < 1e-12:
            raise ValueError("target z-axis must be a finite non-zero vector")
        z_axis = z_axis / nz
    else:
        z_axis = None
    payload = float(payload_kg)
    if not np.isfinite(payload) or payload < 0:
        raise ValueError(f"payload must be a finite non-negative mass in kg, got {payload_kg}")
    L = model.length_scale
    ptol = 1e-8 * L if position_tol is None else float(position_tol)
    atol = 1e-8 if angle_tol is None else float(angle_tol)
    st = model.stage1
    lo, hi = np.full(model.A, st.lam_min), np.full(model.A, st.lam_max)
    lam_ref = np.full(model.A, float(st.stretch(0.5 * (cfg.p_min + cfg.p_max))))

    warm_fw = warm_start.forward if isinstance(warm_start, InverseResult) else warm_start
    if warm_fw is not None and not warm_fw.converged:
        warm_fw = None
    if warm_fw is not None and warm_fw.payload_kg != payload:
        warm_fw = solve_forward(model, warm_fw.pressures_pa, payload, warm_start=warm_fw, check_stability=False)
        warm_fw = warm_fw if warm_fw.converged else None
    lam = np.clip(warm_fw.stretch if warm_fw is not None else (lam_ref if multi else np.ones(model.A)), lo, hi)
    obj = _Objective(model, position, z_axis, payload, warm_fw, tol)

    def done(fw):
        pe, ae = _errors(fw, position, z_axis)
        return pe <= ptol and (ae is None or ae <= atol)

    # 0) fast path: full-space Newton from a warm start
    fw = None
    if warm_fw is not None:
        fw = _full_space_newton(model, position, z_axis, payload, warm_fw, lam_ref, lo, hi, done, tol)
    if fw is not None:
        lam, O, reached, iters = fw.stretch, 0.0, True, fw.iterations
    else:
        # 1) reduced iteration from the warm start (forward solves nested in the stretch iteration)
        free = np.ones(model.A, bool)
        lam, fw, O, J, reached, iters = _iterate(obj, lam, free, lo, hi, lam_ref, multi, done, max_iter)
    if not reached:
        # 2) best reachable stretches inside the pressure limits (trust-region reflective) ...
        eps = 1e-4 if multi else 0.0

        def fun(v):
            _, _, Ov, _ = obj.evaluate(v)
            if Ov is None:
                raise _ForwardFailure()
            return np.concatenate([Ov, eps * (v - lam_ref)]) if multi else Ov

        def jac(v):
            Jv = obj.evaluate(v)[3]
            return np.vstack([Jv, eps * np.eye(model.A)]) if multi else Jv

        try:
            ls = least_squares(fun, np.clip(lam, lo + 1e-12, hi - 1e-12), jac=jac, bounds=(lo, hi),
                               method="trf", ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=50)
            iters += int(ls.nfev)
            # ... 3) then polished exactly on the face it found: variables at a bound stay there
            lam = ls.x.copy()
            lam[ls.active_mask < 0] = lo[ls.active_mask < 0]
            lam[ls.active_mask > 0] = hi[ls.active_mask > 0]
            span = hi - lo
            free = (ls.active_mask == 0) & (lam > lo + 1e-10 * span) & (lam < hi - 1e-10 * span)
            lam, fw, O, J, reached, it2 = _iterate(obj, lam, free, lo, hi, lam_ref, multi, done, max_iter)
            iters += it2
        except _ForwardFailure:
            fw, O = None, None

    if fw is None or O is None or not fw.converged:
        # never hand out NaN: fall back to the last good pressures (or vent)
        base = warm_fw.pressures_pa if warm_fw is not None else np.zeros(model.A)
        p = np.clip(np.nan_to_num(base), cfg.p_min, cfg.p_max)
        return InverseResult(
            pressures_pa=p, stretch=st.stretch(p), reachable=False, position_error_m=float("inf"),
            angle_error_rad=None if z_axis is None else float("inf"), active_limits=np.zeros(model.A, int),
            forward=None, success=False, status=FAILED,
            message="forward solve failed during the inverse iteration", iterations=iters,
            target_position=position, target_z_axis=z_axis,
        )

    pressures = np.clip(st.pressure(lam), cfg.p_min, cfg.p_max)
    fw.pressures_pa = pressures
    assess_stability(fw)
    pe, ae = _errors(fw, position, z_axis)
    active = np.where(lam <= lo, -1, np.where(lam >= hi, 1, 0))
    if not fw.stable:
        status, msg = UNSTABLE, fw.message
    elif reached:
        status, msg = REACHED, "target reached"
    else:
        status = UNREACHABLE
        msg = (f"target unreachable within the pressure limits: best position error {pe * 1e3:.4g} mm"
               + ("" if ae is None else f", angle error {np.degrees(ae):.4g} deg"))
    return InverseResult(
        pressures_pa=pressures, stretch=lam.copy(), reachable=bool(reached), position_error_m=pe,
        angle_error_rad=ae, active_limits=active.astype(int), forward=fw,
        success=bool(reached and fw.stable), status=status, message=msg, iterations=iters,
        target_position=position, target_z_axis=z_axis,
    )


class _ForwardFailure(RuntimeError):
    pass
