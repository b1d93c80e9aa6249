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
  the bordered Jacobian (eq. 30) eliminated by its Schur complement, chord
  steps with an earlier answer's factorisation first (:mod:`core.solve._inverse_warm`).
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
  computed once per model and tip load), each polished exactly on the face of
  its active limits; the answer is the best of all of them by ``|O|``, so it
  is never worse than any of those pressures.
* Three segments and more (more than ``MAX_CORNERS`` corners) get no
  corner starts: 512 corners for three segments are more forward solves than
  the whole budget of a solve (400), and the search never got past them
  (reachable targets ended on that budget tens of seconds later,
  centimetres away).  The minimum-norm iteration from
  mid-range often drives stretches to a limit early and stalls; the least
  squares from mid-range then finds the exact answer, and is stopped for the
  exact polish as soon as it is close (``polish_below`` of
  :func:`~bellow_ancf_ros.core.solve._inverse_limits.best_in_limits`: median
  0.17 s instead of 0.22 s per cold three-segment solve).  The polish
  applies the same rule (stretches closest to ``lam_ref``), so the answer is
  the one a warm start finds.
* Budgets: every stage has an iteration limit, the whole solve a limit on
  forward solves (``max_forward_solves``) and optionally a wall-clock budget
  (``time_budget_s``).  When a budget runs out the best pressures found so
  far come back with status ``TIME_BUDGET`` / ``ITERATION_BUDGET``, and the
  result carries the solve's progress: ``resume`` (the last accepted iterate,
  an exact equilibrium with its sensitivities), ``resume_stage`` (exact
  iteration, its retry from the cold start, or the search for the best
  answer in the limits), ``resume_search`` (that search's least-squares runs
  still to do: the one it was in, from its best iterate, and the starts not
  begun) and ``resume_cut`` (a forward solve the budget cut short, continued
  where it stopped).  Passed back as ``warm_start`` for the
  same target, the next call continues there instead of starting over, so
  repeated budgeted calls ("slices") end at the answer of one unbudgeted
  solve.  The deadline is checked before every Newton iteration (forward
  solves, continuation steps, the full-space Newton method) and every
  forward solve (least squares, corners); past it comes one stability check
  of the answer.  So that every slice makes progress, a warm-started call
  may go on past its deadline until it has a new accepted iterate, at most
  ``Budget.GRACE_BUDGETS`` (4) budgets longer.  Cold forward solves cut
  short keep their continuation for the next call (``cold_solution``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..linalg import one_thread_call
from ..model import RobotModel, tip_load
from ..status import InverseStatus
from ._forward import (ForwardResult, WarmState, assess_stability, check_warm_start,
                       solve_forward)
from ._inverse_limits import (
    MAX_CORNERS,
    POLISH_BELOW,
    best_in_limits,
    corner_solutions,
    stationary,
)
from ._inverse_newton import (
    Budget,
    Objective,
    OutOfBudget,
    cold_solution,
    cost,
    iterate,
    norm,
    pose_errors,
)
from ._inverse_warm import full_space_newton

__all__ = [
    "InverseResult",
    "solve_inverse",
    "MAX_TARGET_LENGTHS",
    "precompute_corners",
]

MAX_TARGET_LENGTHS = 1e3  # targets farther from the base than this many robot lengths are refused
_RETRY_BELOW = 1e-4  # |O|^2/2 below which a stalled warm start is retried from the cold start
_SURELY_OUT = 2.0  # targets this many times the largest reach away skip the exact iterations
# evaluations of one least-squares run for a robot without corner starts (three segments,
# 16 targets: a run to convergence took 93 to 210, one stopped for the polish 5 to 60)
_MANY_NFEV = 150
# stages a solve that ran out of budget continues in (resume_stage): the exact iteration from
# the warm start, its retry from the cold start (continued, or not started), the best answer
_EXACT, _RETRY, _BEST, _RETRY_COLD = 0, 1, 2, 3


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
    # out of budget: the converged iterate (with its sensitivities) the next call,
    # warm-started from this result, continues from (None otherwise)
    resume: ForwardResult | None = dataclasses.field(default=None, repr=False)
    resume_stage: int = dataclasses.field(default=0, repr=False)  # where it continues (_EXACT..)
    # (stretches, ForwardResult) of a forward solve cut short, continued if evaluated again
    resume_cut: tuple | None = dataclasses.field(default=None, repr=False)
    # the search for the best answer in the limits (resume_stage _BEST): its least-squares runs
    # still to do, as (stretches, ForwardResult) starts (None: it had not chosen its starts)
    resume_search: list | None = dataclasses.field(default=None, repr=False)

    @property
    def converged(self):
        """Whether the returned pressures come with a converged forward solution."""
        return self.forward is not None and self.forward.converged

    def to_dict(self):
        """JSON-ready dictionary (the CLI's inverse contract)."""
        d = (
            self.forward.to_dict()
            if self.forward is not None
            else {
                "position_m": None,
                "rotation": None,
                "z_axis": None,
                "stretch": self.stretch.tolist(),
                "pressures_pa": self.pressures_pa.tolist(),
                "converged": False,
                "stable": None,
                "iterations": self.iterations,
                "residual_norm": None,
            }
        )
        d.update(
            {
                "pressures_pa": self.pressures_pa.tolist(),
                "stretch": self.stretch.tolist(),
                "status": int(self.status),
                "message": self.message,
                "iterations": int(self.iterations),
                "success": bool(self.success),
                "reachable": bool(self.reachable),
                "position_error_m": float(self.position_error_m),
                "angle_error_rad": (
                    None if self.angle_error_rad is None else float(self.angle_error_rad)
                ),
                "active_limits": [int(v) for v in self.active_limits],
                "target_position_m": self.target_position.tolist(),
                "target_z_axis": (
                    None if self.target_z_axis is None else self.target_z_axis.tolist()
                ),
            }
        )
        return d


# ------------------------------------------------------------------ driver
def _check_target(model, position, z_axis):
    """Validated target position and unit z-axis (None for one segment)."""
    position = np.asarray(position, dtype=float).reshape(3)
    if not np.all(np.isfinite(position)):
        raise ValueError("target position must be finite")
    L = model.length_scale
    dist = norm(position)
    if dist > MAX_TARGET_LENGTHS * L:
        raise ValueError(
            f"target position is {dist:.3g} m from the base, more than "
            f"{MAX_TARGET_LENGTHS:g} robot lengths ({MAX_TARGET_LENGTHS * L:.3g} m): "
            "refused as absurd"
        )
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


def precompute_corners(model: RobotModel, payload_kg=0.0, time_budget_s=None, tol=1e-10,
                       tip_force_n=None) -> bool:
    """Solve the corners of the pressure box and the cold start now (cached); True when done.

    The first unreachable target of a payload needs the corners (2**A forward
    solves: 8 for one segment, 64 for two; none beyond ``MAX_CORNERS``, three
    segments and more), a cold or retried solve the canonical cold start (one
    cold forward solve; ``tol`` as in :func:`solve_inverse`).  A controller
    with a tight time budget calls this once at start-up for its payload;
    otherwise the work is spread over its first calls (progress is kept when
    a budget runs out).
    """
    budget = Budget(time_budget_s, 2**model.A + 1)
    load = tip_load(payload_kg, tip_force_n)
    st, cfg = model.stage1, model.cfg
    cold = st.stretch(0.5 * (cfg.p_min + cfg.p_max)) if cfg.n_segments > 1 else 1.0
    cold = np.clip(np.full(model.A, float(cold)), st.lam_min, st.lam_max)
    try:
        corner_solutions(model, load, budget)
        budget.take()
        fw = cold_solution(model, np.clip(st.pressure(cold), cfg.p_min, cfg.p_max), load,
                           tol, budget)
    except OutOfBudget:
        return False
    return bool(fw.converged)


@one_thread_call
def solve_inverse(
    model: RobotModel,
    position,
    z_axis=None,
    payload_kg=0.0,
    warm_start=None,
    position_tol=None,
    angle_tol=None,
    max_iter=30,
    tol=1e-10,
    time_budget_s=None,
    max_forward_solves=400,
    tip_force_n=None,
) -> InverseResult:
    """Inverse kinetostatic problem: pressures for a target pose.

    Parameters
    ----------
    position : (3,) target end-effector position [m] in the base frame
        (refused beyond ``MAX_TARGET_LENGTHS`` robot lengths from the base).
    z_axis : (3,) target end-effector z-axis (required for two or more
        segments, ignored for one); any finite non-zero vector.
    payload_kg, tip_force_n : the payload's mass [kg] and an optional force
        at the end effector [N, base frame] (dead loads, as in
        :func:`solve_forward`): the pressures reach the target under them.
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
        Such a result passed back as ``warm_start`` (same target) continues
        the solve where it stopped (see the module docstring, "Budgets"): call
        again until the status is not a budget status.  The time may exceed
        the budget until the call has made progress (at most
        ``Budget.GRACE_BUDGETS`` budgets more), plus one Newton iteration and
        one stability check.  With ``max_forward_solves`` alone slices are
        deterministic; a warm start that is not such a result needs 2 forward
        solves per call to make progress.  BLAS runs on one thread inside
        (``core.blas``: multithreaded BLAS on these small dense matrices can
        take hundreds of milliseconds on a loaded machine).
    """
    budget = Budget(time_budget_s, max_forward_solves)
    position, z_axis = _check_target(model, position, z_axis)
    multi = z_axis is not None
    load = tip_load(payload_kg, tip_force_n)
    L = model.length_scale
    ptol = 1e-8 * L if position_tol is None else float(position_tol)
    atol = 1e-8 if angle_tol is None else float(angle_tol)
    st = model.stage1
    lo, hi = np.full(model.A, st.lam_min), np.full(model.A, st.lam_max)
    lam_ref = np.full(model.A, st.lam_mid)

    def done(fw):
        pe, ae = pose_errors(fw, position, z_axis)
        return pe <= ptol and (ae is None or ae <= atol)

    warm_fw, prev_best, stage, search = warm_start, None, _EXACT, None
    if isinstance(warm_start, InverseResult):
        warm_fw = warm_start.forward
        if warm_start.resume is not None:  # continue an interrupted solve
            warm_fw, prev_best = warm_start.resume, warm_start.forward
            if _same_target(warm_start, position, z_axis, load):
                stage, search = warm_start.resume_stage, warm_start.resume_search
    check_warm_start(model, warm_fw)
    if warm_fw is not None and not warm_fw.converged:
        warm_fw, stage = None, _EXACT
    obj = Objective(model, position, z_axis, load, None, tol, budget)
    budget.grace = warm_fw is not None  # a warm start gets at least one step of progress
    iters = 0
    try:
        if warm_fw is not None and warm_fw.load != load:
            prev_best, stage = None, _EXACT
            budget.take()
            warm_fw = solve_forward(
                model,
                warm_fw.pressures_pa,
                load.payload_kg,
                warm_start=warm_fw,
                check_stability=False,
                time_budget_s=budget.remaining_s(),
                tip_force_n=load.force_n,
            )
            warm_fw = warm_fw if warm_fw.converged else None
        obj.warm = warm_fw
        if warm_fw is not None:
            obj.offer(warm_fw.stretch, warm_fw)
            if prev_best is not None:
                obj.seed(warm_fw)  # the resume point comes with its sensitivities
                if prev_best.converged and prev_best.load == load:
                    obj.offer(prev_best.stretch, prev_best)  # never worse than the last slice
                if warm_start.resume_cut is not None:  # a forward solve it had begun
                    obj.pending[warm_start.resume_cut[0].tobytes()] = warm_start.resume_cut[1]
        # 0) fast path: full-space Newton from a warm start (interior solutions only)
        fw = None
        obj.stage = stage
        if warm_fw is not None and stage == _EXACT:
            fw = full_space_newton(
                model, obj.target, multi, load, warm_fw, lam_ref, lo, hi, done, tol,
                budget=budget,
            )
        if stage != _EXACT:
            # an interrupted solve continues in the stage it was in
            lam, fw, reached, iters = _continue(obj, prev_best, warm_fw, search, lo, hi, lam_ref,
                                                multi, done, max_iter)
        elif fw is not None:
            lam, reached, iters = fw.stretch, True, fw.iterations
        elif norm(position) > _SURELY_OUT * _reach(model):
            obj.stage = _BEST
            # far out of reach: straight to the best answer inside the limits (which would still
            # find and polish an exact solution, were there one)
            lam, fw, reached, iters = _best_answer(obj, [], warm_fw, lo, hi, lam_ref, multi, done,
                                                   max_iter)
        else:
            # 1) reduced iteration from the warm start (or the canonical cold start)
            cold = np.clip(lam_ref if multi else np.ones(model.A), lo, hi)
            start = cold if warm_fw is None else np.clip(warm_fw.stretch, lo, hi)
            lam, fw, O, _, reached, iters = iterate(
                obj, start, np.ones(model.A, bool), lo, hi, lam_ref, multi, done, max_iter
            )
            if not reached and warm_fw is not None and (O is None or cost(O) < _RETRY_BELOW):
                # 1b) a near miss from the warm start: the canonical cold start may reach it
                obj.warm, obj.stage, obj.resume = None, _RETRY, None
                lam_c, fw_c, O_c, _, reached, it_c = iterate(
                    obj, cold, np.ones(model.A, bool), lo, hi, lam_ref, multi, done, max_iter
                )
                iters += it_c
                if reached or O is None:
                    lam, fw, O = lam_c, fw_c, O_c  # noqa: E741
            if not reached:
                # 2) best answer inside the limits from a fixed set of starts
                obj.stage = _BEST
                local = [] if O is None else [(lam, fw)]
                lam, fw, reached, it2 = _best_answer(obj, local, warm_fw, lo, hi, lam_ref, multi,
                                                     done, max_iter)
                iters += it2
    except OutOfBudget as exc:
        res = _budget_result(model, obj, exc.code, budget, iters, position, z_axis, warm_fw, done)
        res.resume = _resume_point(model, obj, warm_fw)
        res.resume_stage = obj.stage
        res.resume_cut = obj.cut
        if obj.stage == _BEST:
            res.resume_search = obj.search
        if obj.stage == _RETRY and obj.resume is None:
            res.resume_stage = _RETRY_COLD  # the cold retry has not got anywhere yet
        return res

    if fw is None or not fw.converged:
        return _failed_result(
            model,
            warm_fw,
            iters,
            position,
            z_axis,
            "forward solve failed during the inverse iteration",
        )
    return _result(model, lam, fw, reached, iters, position, z_axis)


def _reach(model):
    """Upper bound of the distance between the base centre and the end effector [m]."""
    cfg = model.cfg
    return (sum(model.stage1.lam_max * cfg.l0 + seg.connector_height + seg.pitch_radius
                for seg in cfg.segments) + cfg.tool_length)


def _continue(obj, prev_best, resume, search, lo, hi, lam_ref, multi, done, max_iter):
    """Continue an interrupted solve in its stage ``obj.stage``: ``(lam, fw, reached, its)``.

    ``resume`` is its last accepted iterate (or its warm start), ``prev_best``
    its best answer so far, ``search`` the least-squares runs its search for
    the best answer in the limits had still to do (None: it had not chosen
    its starts).  Work done already is not repeated: the retry from the cold
    start goes on from its iterate, the search from where each of its runs
    stands (the interrupted one from its best iterate, then the starts it had
    not begun).  The search ends, and its best answer is the answer, only
    when every one of its runs has ended, as in one unbudgeted call: a run at
    a first-order point of the least squares (:func:`stationary`) has ended
    when that point is a clear miss; a nearly exact one is polished first.
    """
    model = obj.model
    local, iters = [], 0
    if obj.stage in (_RETRY, _RETRY_COLD):
        start = np.clip(resume.stretch, lo, hi)
        if obj.stage == _RETRY_COLD:
            obj.warm = None
            start = np.clip(lam_ref if multi else np.ones(model.A), lo, hi)
        obj.stage, obj.resume = _RETRY, None
        lam, fw, O, _, reached, iters = iterate(
            obj, start, np.ones(model.A, bool), lo, hi, lam_ref, multi, done, max_iter)
        if reached:
            return lam, fw, True, iters
        obj.stage, search = _BEST, None   # a new search, from its seeds
        if O is not None:
            local.append((lam, fw))
    usable = prev_best is not None and prev_best.converged and prev_best.load == obj.load
    if search is None:
        # the search had not chosen its starts (or is new): all of it, its best answer so far
        # among the candidates
        if usable:
            local.append((prev_best.stretch, prev_best))
        lam, fw, reached, it2 = _best_answer(obj, local, resume, lo, hi, lam_ref, multi, done,
                                             max_iter)
        return lam, fw, reached, iters + it2
    runs = obj.search = [(lam, fw) for lam, fw in search if fw.converged and fw.load == obj.load]
    if runs and stationary(obj, runs[0][0], lo, hi, lam_ref, multi):
        # the interrupted run had arrived: ended, unless nearly exact (then its least squares
        # ends at once and the polish follows)
        O = obj.evaluate(runs[0][0])[2]  # noqa: E741
        if cost(O) > POLISH_BELOW:
            runs = obj.search = runs[1:]
    if not runs:
        # every run has ended: the best answer seen is the answer
        _, lam, fw = obj.best
        return lam, fw, done(fw), iters
    options = {}
    if 2**model.A > MAX_CORNERS:  # as _best_answer runs them
        options.update(max_nfev=_MANY_NFEV, polish_below=POLISH_BELOW)
    lam, fw, reached, it2 = best_in_limits(obj, runs, lo, hi, lam_ref, multi, done, max_iter,
                                           n_starts=len(runs), **options)
    return lam, fw, reached, iters + it2


def _same_target(prev, position, z_axis, load):
    """Whether the InverseResult ``prev`` was for this target and tip load."""
    fw = prev.forward if prev.forward is not None else prev.resume
    same_axis = (z_axis is None) == (prev.target_z_axis is None) and (
        z_axis is None or np.array_equal(z_axis, prev.target_z_axis))
    return (fw is not None and fw.load == load and same_axis
            and np.array_equal(position, prev.target_position))


def _best_answer(obj, local, warm_fw, lo, hi, lam_ref, multi, done, max_iter):
    """Best answer inside the limits from the local answer, the warm start, seeds and corners.

    Returns ``(lam, fw, reached, iterations)``; ``fw`` None when no forward solve converged.
    """
    model = obj.model
    candidates = list(local)
    if warm_fw is not None:
        candidates.append((warm_fw.stretch, warm_fw))
    for seed in (np.ones(model.A), lam_ref):  # vent and mid-range pressures
        seed = np.clip(seed, lo, hi)
        _, fw_s, O_s, _ = obj.evaluate(seed)
        if O_s is not None:
            candidates.append((seed, fw_s))
    candidates += corner_solutions(model, obj.load, obj.budget)
    if not candidates:
        return None, None, False, 0
    options = {}
    if 2**model.A > MAX_CORNERS:  # no corners: the least squares searches for exact answers too
        options.update(max_nfev=_MANY_NFEV, polish_below=POLISH_BELOW)
    return best_in_limits(obj, candidates, lo, hi, lam_ref, multi, done, max_iter, **options)


def _result(model, lam, fw, reached, iters, position, z_axis, status=None, note=""):
    """Result for the stretches ``lam`` with their forward solution ``fw`` (stability assessed)."""
    cfg, st = model.cfg, model.stage1
    lo, hi = st.lam_min, st.lam_max
    pressures = np.clip(st.pressure(lam), cfg.p_min, cfg.p_max)
    fw = dataclasses.replace(fw, pressures_pa=pressures)  # a copy: a warm start or cached corner
    assess_stability(fw)
    pe, ae = pose_errors(fw, position, z_axis)
    near = 1e-9 * (hi - lo)  # least squares keeps its iterates 1e-12 inside the box
    active = np.where(lam <= lo + near, -1, np.where(lam >= hi - near, 1, 0))
    errors = f"position error {pe * 1e3:.4g} mm" + (
        "" if ae is None else f", angle error {np.degrees(ae):.4g} deg"
    )
    buckled = f"the robot would buckle under {fw.load.describe()}"
    if status is not None:
        msg = f"{note}; best pressures so far: {errors}"
        if not fw.stable:
            msg += f"; every equilibrium so far is unstable ({buckled}?)"
    elif not fw.stable:
        status, msg = InverseStatus.UNSTABLE, f"{fw.message}; {buckled} at the best pressures"
    elif reached:
        status, msg = InverseStatus.REACHED, InverseStatus.REACHED.message
    else:
        status = InverseStatus.UNREACHABLE
        msg = f"{InverseStatus.UNREACHABLE.message}: best {errors}"
    return InverseResult(
        pressures_pa=pressures,
        stretch=np.array(lam, dtype=float),
        reachable=bool(reached),
        position_error_m=pe,
        angle_error_rad=ae,
        active_limits=active.astype(int),
        forward=fw,
        success=bool(reached and fw.stable and status == InverseStatus.REACHED),
        status=status,
        message=msg,
        iterations=iters,
        target_position=position,
        target_z_axis=z_axis,
    )


def _failed_result(model, warm_fw, iters, position, z_axis, message, status=InverseStatus.FAILED):
    """Never hand out NaN: the last good pressures (or vent), flagged."""
    cfg = model.cfg
    base = warm_fw.pressures_pa if warm_fw is not None else np.zeros(model.A)
    p = np.clip(np.nan_to_num(base), cfg.p_min, cfg.p_max)
    return InverseResult(
        pressures_pa=p,
        stretch=model.stage1.stretch(p),
        reachable=False,
        position_error_m=float("inf"),
        angle_error_rad=None if z_axis is None else float("inf"),
        active_limits=np.zeros(model.A, int),
        forward=None,
        success=False,
        status=status,
        message=message,
        iterations=iters,
        target_position=position,
        target_z_axis=z_axis,
    )


def _resume_point(model, obj, warm_fw):
    """The converged iterate a solve that ran out of budget continues from, with sensitivities.

    The last accepted iterate of the running iteration (by its own merit,
    which for redundant robots includes the distance to ``lam_ref``: not
    necessarily the best ``|O|``), else the call's own warm start.
    """
    if obj.resume is None:
        return warm_fw
    lam, fw, dx = obj.resume
    st, cfg = model.stage1, model.cfg
    return dataclasses.replace(
        fw, pressures_pa=np.clip(st.pressure(lam), cfg.p_min, cfg.p_max),
        stretch=np.array(lam, dtype=float), _warm=WarmState(sensitivity=-dx))


def _budget_result(model, obj, code, budget, iters, position, z_axis, warm_fw, done):
    """The best pressures found before a budget ran out, with status ``code``."""
    code = InverseStatus(int(code))  # the forward solver's TIME_BUDGET / ITERATION_BUDGET
    if code == InverseStatus.TIME_BUDGET:
        note = f"wall-clock budget of {budget.time_budget_s:g} s exhausted"
    else:
        note = f"budget of {budget.max_forward_solves} forward solves exhausted"
    note += f" after {budget.used} forward solves"
    if obj.best is None:
        return _failed_result(
            model, warm_fw, iters, position, z_axis, note + "; no solution yet", code
        )
    _, lam, fw = obj.best
    return _result(model, lam, fw, done(fw), iters, position, z_axis, status=code, note=note)
