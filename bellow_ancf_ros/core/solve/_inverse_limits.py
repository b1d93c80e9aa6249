"""Best answer inside the pressure limits for an unreachable target (eq. 28, least squares).

Bound-constrained least squares (scipy ``least_squares``, trust-region
reflective) on ``|O|^2`` from a small fixed set of starts: the local answer,
the warm start, vent and mid-range pressures and the corners of the pressure
box, whose stable forward solutions are computed once per model and tip load
(:func:`corner_solutions`).  The answer is the best of everything seen.

Robots with more than :data:`MAX_CORNERS` corners (three segments and more:
``2**9 = 512``) have no corner starts: their forward solves alone would
exceed the budget of a solve (400).  For them the same least squares is also
the search for the exact answer that the minimum-norm iteration from
mid-range missed (a stretch driven to a limit early stays held there and the
iteration stalls): with ``polish_below`` a run stops as soon as
``|O|^2/2`` is below ``POLISH_BELOW`` and the iterate is polished exactly,
which needs a fraction of the evaluations of a run to convergence.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.optimize import least_squares

from ..status import ForwardStatus
from ._forward import solve_forward
from ._inverse_newton import OutOfBudget, cost, iterate

__all__ = ["corner_solutions", "best_in_limits", "stationary", "MAX_CORNERS", "POLISH_BELOW"]

TIME_BUDGET = ForwardStatus.TIME_BUDGET
_N_STARTS = 2  # least-squares runs for an unreachable target
POLISH_BELOW = 1e-8  # |O|^2/2 below which a least-squares answer is polished exactly
_CORNER_CACHE_PAYLOADS = 4
_STATIONARY_GTOL = 1e-9  # scaled gradient of a finished least-squares answer (about 1e-3 Pa)
#: Largest number of corners of the pressure box used as starts (2**A: one and two segments).
MAX_CORNERS = 64


def corner_solutions(model, load, budget):
    """Stable forward solutions at the corners of the pressure box, once per model and tip load.

    Work done before a budget runs out is kept for the next call.  Kept
    with the model (:meth:`RobotModel.cached`), so they go when it goes.
    None (an empty list) for a robot with more than :data:`MAX_CORNERS` corners.
    """
    if 2**model.A > MAX_CORNERS:
        return []
    per_model = model.cached("corner_solutions", lambda m: {})  # tip load -> partial or done
    entry = per_model.get(load)
    if entry is None:
        while len(per_model) >= _CORNER_CACHE_PAYLOADS:
            per_model.pop(next(iter(per_model)))
        entry = per_model[load] = {"next": 0, "items": []}
    cfg, st = model.cfg, model.stage1
    corners = list(itertools.product((cfg.p_min, cfg.p_max), repeat=model.A))
    while entry["next"] < len(corners):
        p = np.array(corners[entry["next"]])
        budget.take()
        fw = solve_forward(model, p, load.payload_kg, time_budget_s=budget.remaining_s(),
                           tip_force_n=load.force_n)
        if fw.status == TIME_BUDGET:
            raise OutOfBudget(TIME_BUDGET)
        entry["next"] += 1
        if fw.success:
            fw.stretch = np.where(p == cfg.p_max, st.lam_max, st.lam_min).astype(float)
            entry["items"].append((fw.stretch.copy(), fw))
    return entry["items"]


class _NearEnough(Exception):
    """A least-squares iterate close enough to an exact solution to polish it (``args[0]``)."""


def best_in_limits(obj, candidates, lo, hi, lam_ref, multi, done, max_iter, n_starts=_N_STARTS,
                   max_nfev=50, polish_below=None):
    """Best stretches inside the limits from a fixed set of starts (see the module docstring).

    ``candidates`` are converged ``(lam, ForwardResult)`` pairs; the best
    ``n_starts`` distinct ones by ``|O|`` start a bound-constrained least-squares
    run each (at most ``max_nfev`` evaluations), polished on the face of its
    active limits.  With ``polish_below``, a run stops at the first iterate
    whose ``|O|^2/2`` is below it and that iterate is polished (inside the
    limits).  Returns ``(lam, fw, reached, iterations)`` of the best answer seen.

    ``obj.search`` holds the runs still to do while it works: the running one
    as its best iterate so far, then the starts not begun.  A budget that
    runs out leaves it there, and a continued solve does exactly those runs
    (passing them as ``candidates`` with ``n_starts=len(candidates)``), so
    that no start of the search is skipped: its best answer is a target's
    best in the limits only once every run has ended.
    """
    A = obj.model.A
    eps = 1e-4 if multi else 0.0
    scored = sorted(
        ((cost(obj.offer(lam, fw)), i, lam, fw) for i, (lam, fw) in enumerate(candidates)),
        key=lambda t: t[:2],
    )
    starts, iters = [], 0
    for c, _, lam, fw in scored:
        if all(np.max(np.abs(lam - s[0])) > 1e-6 for s in starts):
            starts.append((lam, fw))
        if len(starts) == n_starts:
            break

    run_best = [np.inf]  # the running least-squares run's best cost

    def fun(v):
        _, fw_v, Ov, _ = obj.evaluate(v)
        if Ov is None:
            raise ForwardFailure()
        if obj.best[2] is fw_v:
            obj.advance(v)  # a new best answer: progress, and the point to continue from
        c = cost(Ov)
        if c < run_best[0]:  # the run goes on from here if the budget runs out
            run_best[0] = c
            obj.search[0] = (np.array(v, dtype=float), fw_v)
        if polish_below is not None and c <= polish_below:
            raise _NearEnough(np.array(v, dtype=float))
        return np.concatenate([Ov, eps * (v - lam_ref)]) if multi else Ov

    def jac(v):
        Jv = obj.evaluate(v)[3]
        return np.vstack([Jv, eps * np.eye(A)]) if multi else Jv

    for k, (lam0, fw0) in enumerate(starts):
        obj.warm = fw0
        obj.search = list(starts[k:])  # this run, then the starts not begun
        run_best[0] = np.inf
        try:
            ls = least_squares(
                fun,
                np.clip(lam0, lo + 1e-12, hi - 1e-12),
                jac=jac,
                bounds=(lo, hi),
                method="trf",
                ftol=1e-12,
                xtol=1e-12,
                gtol=1e-12,
                max_nfev=max_nfev,
            )
        except ForwardFailure:
            continue
        except _NearEnough as near:
            lam = near.args[0]
            active = np.zeros(A, int)
        else:
            iters += int(ls.nfev)
            lam, active = ls.x.copy(), ls.active_mask
        lam[active < 0] = lo[active < 0]
        lam[active > 0] = hi[active > 0]
        _, fw, O, _ = obj.evaluate(lam)
        if O is None or cost(O) > POLISH_BELOW:
            continue  # a clear miss: least squares has found the best on its face already
        # nearly exact: polish on the face of the active limits (and release limits by KKT)
        span = hi - lo
        free = (active == 0) & (lam > lo + 1e-10 * span) & (lam < hi - 1e-10 * span)
        lam, fw, O, _, reached, it2 = iterate(
            obj, lam, free, lo, hi, lam_ref, multi, done, max_iter
        )
        iters += it2
        if reached:
            obj.search = []
            return lam, fw, True, iters
    obj.search = []  # every run has ended
    c, lam, fw = obj.best
    return lam, fw, done(fw), iters


def stationary(obj, lam, lo, hi, lam_ref, multi, gtol=_STATIONARY_GTOL):
    """Whether ``lam`` is a first-order point of the least squares of :func:`best_in_limits`.

    The gradient of its cost, scaled as trust-region reflective scales it
    (by the distance to the bound it points to, Coleman-Li), is below ``gtol``
    in every component.  Lets an interrupted search stop at its answer
    without a whole least-squares run in one budget slice.
    """
    _, _, O, J = obj.evaluate(lam)
    if O is None:
        return False
    eps = 1e-4 if multi else 0.0
    g = J.T @ O + eps**2 * (lam - lam_ref)
    v = np.where(g < 0, hi - lam, np.where(g > 0, lam - lo, 1.0))
    return bool(np.max(np.abs(g * v)) <= gtol)


class ForwardFailure(RuntimeError):
    pass
