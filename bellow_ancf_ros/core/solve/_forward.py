"""Forward kinetostatic problem (paper section IV.B).

Pressures (gauge, Pa, one per actuator, segment by segment), payload and tip
force -> stretches by stage 1 (eq. 24) -> equilibrium of eq. (25) by Newton's
method -> end-effector pose, plate poses, backbones, stability.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..linalg import kkt_solver, one_thread_call
from ..model import RobotModel, TipLoad, arc_state, tip_load
from ..status import ForwardStatus, usable
from . import _newton as solver
from ._stability import StabilityCheck

__all__ = ["ForwardResult", "ResumeState", "WarmState", "solve_forward", "check_pressures",
           "assess_stability"]

_STABILITY_RTOL = 1e-10


@dataclass(frozen=True)
class WarmState:
    """Solver state an inverse answer leaves for the next warm-started solve.

    ``sensitivity``: ``W = -dx/dlam = J^{-1} dR/dlam`` near ``x`` (the
    predictor); ``exact``: ``W`` was made at ``x``'s last iterate;
    ``chord``: (factorisation, its ``W``) from a point near ``x`` (the chord
    steps); ``step_maps``: the stretch-step maps made of ``W``; ``path``:
    the :class:`~._inverse_warm.PathRecord` of the answer (second-order
    predictor).  Internal to the solvers: a caller passes the whole result.
    """

    sensitivity: object = None
    exact: bool = False
    chord: object = None
    step_maps: object = None
    path: object = None


@dataclass
class ForwardResult:
    """Converged (or not) configuration of the robot; SI units throughout.

    ``success`` (:func:`~bellow_ancf_ros.core.status.usable`) is true for a
    converged equilibrium that was not found unstable: with the stability
    check (the default) a converged and stable one; with
    ``check_stability=False`` (``stable`` None) any converged one.
    ``status`` is a :class:`~bellow_ancf_ros.core.status.ForwardStatus`.
    """

    model: RobotModel
    pressures_pa: np.ndarray
    stretch: np.ndarray
    payload_kg: float
    x: np.ndarray
    converged: bool
    stable: bool | None
    status: int
    message: str
    iterations: int
    residual_norm: float
    history: list = field(default_factory=list, repr=False)
    #: force at the end effector [N, base frame] on top of the payload's weight
    tip_force_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    jacobian: object = field(default=None, repr=False)
    _lu: object = field(default=None, repr=False)
    _reduced_hessian: object = field(default=None, repr=False)
    # what the next warm-started inverse solve reuses (WarmState), None for a plain forward solve
    _warm: WarmState | None = field(default=None, repr=False)
    # a solve that ran out of budget: where it stopped (a warm start continues it)
    resume_state: ResumeState | None = field(default=None, repr=False)

    @property
    def min_eigenvalue(self) -> float | None:
        """Smallest eigenvalue of the reduced Hessian (scaled coordinates).

        None before the stability check.
        """
        return None if self._reduced_hessian is None else self._reduced_hessian.min_eigenvalue

    @property
    def load(self) -> TipLoad:
        """The payload and tip force the equilibrium is under."""
        return TipLoad(float(self.payload_kg), tuple(float(f) for f in self.tip_force_n))

    @property
    def lu(self):
        """Solver with the Jacobian (eq. 27) at the solution (``.solve(b)``; core.linsolve)."""
        if self._lu is None and self.jacobian is not None:
            self._lu = kkt_solver(self.model).bound(self.jacobian)
        return self._lu

    @property
    def success(self) -> bool:
        """A usable configuration: converged, and not found unstable (class docstring)."""
        return usable(self.converged, self.stable)

    @property
    def q(self):
        return self.x[: self.model.nq]

    @property
    def position(self) -> np.ndarray:
        return self.model.end_effector(self.q)[0]

    @property
    def rotation(self) -> np.ndarray:
        """Columns: end-effector x, y, z axes in the base frame."""
        return self.model.end_effector(self.q)[1]

    @property
    def z_axis(self) -> np.ndarray:
        return self.rotation[:, 2]

    def plate_poses(self):
        """``[(segment, fraction, position, rotation), ...]`` for every plate, base first."""
        return self.model.plate_poses(self.q)

    def backbones(self, n_points=20):
        """Each actuator's centre line at ``n_points`` points: ``(A, n_points, 3)``."""
        return self.model.backbones(self.q, self.stretch, n_points)

    def to_dict(self):
        """JSON-ready dictionary (the CLI's forward contract)."""
        return {
            "position_m": self.position.tolist(),
            "rotation": self.rotation.tolist(),
            "z_axis": self.z_axis.tolist(),
            "stretch": self.stretch.tolist(),
            "pressures_pa": self.pressures_pa.tolist(),
            "payload_kg": float(self.payload_kg),
            "tip_force_n": [float(f) for f in self.tip_force_n],
            "converged": bool(self.converged),
            "stable": None if self.stable is None else bool(self.stable),
            "status": int(self.status),
            "message": self.message,
            "iterations": int(self.iterations),
            "residual_norm": float(self.residual_norm),
        }


def check_pressures(model: RobotModel, pressures, limit_tol=1e-9):
    """Validate a pressure vector: length, finiteness, limits.  Returns a float array."""
    p = np.asarray(pressures, dtype=float).ravel()
    if p.size != model.A:
        raise ValueError(f"expected {model.A} pressures (one per actuator), got {p.size}")
    if not np.all(np.isfinite(p)):
        raise ValueError("pressures must be finite numbers")
    cfg = model.cfg
    span = cfg.p_max - cfg.p_min
    bad = (p < cfg.p_min - limit_tol * span) | (p > cfg.p_max + limit_tol * span)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"pressure {i + 1} = {p[i] / 1e3:.6g} kPa is outside the limits "
            f"[{cfg.p_min / 1e3:g}, {cfg.p_max / 1e3:g}] kPa"
        )
    return np.clip(p, cfg.p_min, cfg.p_max)


@dataclass
class ResumeState:
    """Where a forward solve that ran out of budget stopped, for the next call to go on.

    ``x`` is an exact equilibrium at ``(stretch, load_scale, load)`` (the
    last one of its continuation, or its start; ``load`` a
    :class:`~bellow_ancf_ros.core.model.TipLoad`); ``step`` the continuation
    step to try next from there; ``guess`` the Newton iterate of the step (or
    of the direct attempt, ``step`` 1) that was cut short, valid for the
    final ``target = (stretch, load)`` only.
    """

    x: np.ndarray
    stretch: np.ndarray
    load_scale: float
    load: TipLoad
    step: float = 1.0
    guess: np.ndarray | None = None
    target: tuple | None = None

    def start(self):
        """The equilibrium as the ``(x, lam, load_scale, load)`` start of a continuation."""
        return self.x, self.stretch, self.load_scale, self.load


def _stage2(model, lam, load, warm, tol, max_iter, iteration_budget=None, deadline=None):
    """Solve eq. (25) for given stretches from ``warm = (x, lam, scale, load)``, an equilibrium.

    ``warm`` may also be a :class:`ResumeState`: then the interrupted
    continuation goes on (its direct attempt had failed or was cut short; an
    interrupted Newton run continues from its iterate when the target is the
    same).  Returns ``(NewtonResult, ResumeState or None)``: a resume state
    when a budget ran out.
    """
    scale = model.residual_scale

    def make(lam_t, load_t, pay_t):
        return lambda x, jacobian=True: model.evaluate(x, lam_t, load_t, pay_t, jacobian=jacobian)

    def same_target(rs):
        return (rs.target is not None and rs.guess is not None and rs.target[1] == load
                and np.array_equal(rs.target[0], lam))

    first_max = max_iter if iteration_budget is None else min(max_iter, iteration_budget)
    first_step, first_iters, guess = 1.0, 0, None
    if isinstance(warm, ResumeState):
        start, first_step = warm.start(), warm.step
        guess = warm.guess if same_target(warm) else None
        direct = guess is not None and first_step >= 1.0  # a cut direct attempt goes on
    else:
        direct = True
        if warm is None:
            # cold start: the PCC arcs of the target stretches as the guess, then (if Newton
            # fails from there) continuation from the exactly solved unloaded straight robot
            guess = arc_state(model, lam)
            start = (model.straight_state(np.ones(model.A)), np.ones(model.A), 0.0, TipLoad())
        else:
            guess, start = warm[0], warm
    if direct:
        res = solver.newton(make(lam, 1.0, load), guess, scale, tol, first_max,
                            deadline=deadline)
        if res.converged:
            return res, None
        if res.status == ForwardStatus.TIME_BUDGET:
            return res, ResumeState(*start, 1.0, res.x, (lam, load))
        first_iters, guess = res.iterations, None
        if isinstance(warm, ResumeState):
            first_step = 0.5  # the full step has failed now
    x0, lam0, s0, m0 = start

    def point(t):
        return lam0 + t * (lam - lam0), s0 + t * (1.0 - s0), m0.toward(load, t)

    def make_t(t):
        return make(*point(t))

    left = None if iteration_budget is None else iteration_budget - first_iters
    res = solver.continuation(make_t, x0, scale, tol, max_iter, iteration_budget=left,
                              deadline=deadline, first_step=first_step, first_guess=guess)
    res.iterations += first_iters
    resume = None
    if res.reached is not None:  # out of budget: the last equilibrium on the way
        t, x_t, dt, x_cut = res.reached
        lam_t, s_t, m_t = point(t)
        resume = ResumeState(x_t, lam_t, s_t, m_t, min(1.0, dt / (1.0 - t)), x_cut,
                             (lam, load))
    return res, resume


def check_warm_start(model: RobotModel, warm_start) -> None:
    """``ValueError`` unless ``warm_start`` (a ForwardResult or None) has ``model``'s size.

    (The compiled kernels would read and write past the end of a shorter one.)
    """
    if warm_start is not None and np.size(warm_start.x) != model.N:
        raise ValueError(f'warm_start has {np.size(warm_start.x)} coordinates, this model '
                         f'{model.N} ({model.n} elements per actuator): allowed: a solution '
                         'of a model with the same robot layout and element count')


@one_thread_call
def solve_forward(model: RobotModel, pressures, payload_kg=0.0, warm_start=None,
                  check_stability=True, tol=1e-10, max_iter=25, time_budget_s=None,
                  iteration_budget=500, tip_force_n=None) -> ForwardResult:
    """Forward kinetostatic problem.

    Parameters
    ----------
    model : RobotModel
    pressures : array_like, Pa (gauge), one per actuator, segment by segment;
        must lie in ``[p_min, p_max]``.
    payload_kg : mass at the end effector.
    tip_force_n : optional force at the end effector [N, base frame], a dead
        load on top of the payload's weight (eq. 14 at the end effector);
        non-finite values and magnitudes above ``MAX_TIP_FORCE_N`` raise
        ValueError.  A force the robot cannot carry ends in a limit point of
        the load path or an unstable equilibrium, reported by the status.
    warm_start : ForwardResult, optional
        A previous converged result (e.g. the last sample of a trajectory);
        the solve starts from it and falls back to continuation from it.  A
        result that ran out of budget carries the last exact equilibrium of
        its continuation (``resume_state``): passed as ``warm_start`` (with
        the same or other pressures) the solve continues from there, so a
        cold solve can be done in budget slices without losing work.
        It must come from a model of the same layout and element count
        (``ValueError`` otherwise).
    check_stability : compute the reduced-Hessian stability test.
    tol : tolerance on the scaled residual (forces relative to the robot's
        bending/weight force scale, constraints relative to its length).
    max_iter : Newton iterations per Newton run (the direct attempt and each
        continuation step).
    iteration_budget : Newton iterations in all, continuation included; when
        they run out the result says so (``status`` ``ForwardStatus.ITERATION_BUDGET``).
    time_budget_s : optional wall-clock budget in seconds; when it runs out the
        solve stops with ``converged`` false and ``status`` ``ForwardStatus.TIME_BUDGET``
        (the stability check, about a millisecond, is not cut short).  The
        deadline is checked before every Newton iteration, so the overshoot is
        at most one iteration (one factorisation and its line search).  BLAS
        runs on one thread inside (``core.blas``).
    """
    deadline = solver.deadline_after(time_budget_s)
    p = check_pressures(model, pressures)
    load = tip_load(payload_kg, tip_force_n)
    lam = model.stage1.stretch(p)
    warm = None
    check_warm_start(model, warm_start)
    if warm_start is not None and warm_start.converged:
        warm = (warm_start.x, warm_start.stretch, 1.0, warm_start.load)
    elif warm_start is not None and warm_start.resume_state is not None:
        warm = warm_start.resume_state  # continue a solve that ran out of budget
    res, resume = _stage2(model, lam, load, warm, tol, max_iter, int(iteration_budget),
                          deadline)
    message = res.message
    if res.status == ForwardStatus.STEP_TOO_SMALL and (load.payload_kg > 0 or load.has_force):
        message += (f"; a limit point of the load path to {load.describe()}: "
                    "the robot may buckle under it")
    out = ForwardResult(
        model=model, pressures_pa=p, stretch=lam, payload_kg=load.payload_kg,
        tip_force_n=np.array(load.force_n), x=res.x,
        converged=res.converged, stable=None, status=res.status,
        message=message, iterations=res.iterations, residual_norm=res.residual_norm,
        history=res.history, jacobian=res.jacobian, resume_state=resume,
    )
    if res.converged and check_stability:
        assess_stability(out)
    return out


def assess_stability(result: ForwardResult):
    """Fill ``stable``; an unstable equilibrium gets status UNSTABLE.

    Stable: the Hessian of the Lagrangian is positive definite on the
    constraint tangent space (smallest eigenvalue above a relative 1e-10).
    """
    red = StabilityCheck(result.jacobian, result.model)  # banded proof, dense test as fallback
    result._reduced_hessian = red
    result.stable = red.is_positive_definite(_STABILITY_RTOL)
    if not result.stable:
        result.status = ForwardStatus.UNSTABLE
        result.message = (
            f"{ForwardStatus.UNSTABLE.message}: "
            f"smallest reduced-Hessian eigenvalue {red.min_eigenvalue:.3g}"
        )
    return result
