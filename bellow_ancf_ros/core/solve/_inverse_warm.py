"""Warm-started inverse solve: full-space Newton on ``[lam, q, alpha]`` with chord steps.

Used by :func:`bellow_ancf_ros.core.solve._inverse.solve_inverse` as its fast path
along a trajectory (eqs. 29, 30).  The bordered Jacobian is eliminated by
its Schur complement: with ``J_x`` factorised, ``W = J_x^{-1} dR/dlam``
gives the reduced objective Jacobian ``J_O = -T W`` and the equilibrium
correction, the stretch step solves ``J_O dlam = -(O - T J_x^{-1} R)``
(minimum-norm plus null-space term for redundant robots, as in the reduced
iteration) and ``dx = -J_x^{-1}(R + dR/dlam dlam)``.

Per target:

1. predictor: the linear step with the warm start's ``W``, plus along a
   steady path the last target's second-order correction
   (:func:`_second_order`);
2. chord steps (:mod:`core.solve._chord`, compiled) with the factorisation of an
   earlier answer (``WarmState.chord``): one single-column solve
   each, linear convergence at a rate that grows with the distance to where
   it was made (measured 0.015 to 0.05 per millimetre of target motion);
   each must cut the residual by ``CHORD_RATE``, at most ``MAX_CHORD`` of
   them (redundant robots: down to ``CHORD_TOL_MULTI`` only, as a Newton
   step follows, and minimum-norm steps without the null-space term: the
   projector would be the earlier answer's, not the iterate's, and the Newton
   steps with their own ``W`` make the null-space correction; measured with
   it, three segments' chord steps stalled at a contraction of 0.77 and the
   first Newton step's null-space correction was 50x larger, interleaved
   without it 1.0 to 1.4x faster for two to four segments);
3. then Newton steps with a new factorisation; one segment goes back to
   chord steps with it, redundant robots refine ``W`` with it at the next
   iterates (``REFINE_TOL``, ``REFINE_MAX``).

The answer does not depend on the factorisation used: for one segment (as
many target equations as stretches) the iteration solves ``R = 0, O = 0``
whatever ``J_x`` approximates it; for redundant robots the null-space
condition needs the exact ``W``: the answer is an iterate with a ``W`` of its
own (a new factorisation there, or ``W`` refined there to ``REFINE_TOL``),
its residual within the tolerance and the null-space correction computed
with that ``W`` below 1e-9 (accepted before the step it would take,
:meth:`_WarmSolve.take`), or the iterate after a step made with such a
``W`` and a correction below 1e-9, its residual within the tolerance.
A held target is accepted at once when the warm start's ``W`` was such a one
(``WarmState.exact``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..linalg import BandedLU, EnvelopeLDL, kkt_solver
from ..status import ForwardStatus
from ._chord import CONVERGED as CHORD_CONVERGED, NONFINITE, chord_steps, stretch_step
from ._forward import ForwardResult, WarmState
from ._inverse_newton import RCOND, norm

__all__ = ["full_space_newton", "PathRecord", "CHORD_RATE", "CHORD_TOL_MULTI",
           "MAX_CHORD", "REFINE_TOL", "REFINE_MAX"]

# chord steps (a factorisation from an earlier point, reused): each must cut the residual by
# this factor at least, and at most this many in a row; then Newton with a new factorisation
# (one segment, 1 mm steps: 0.1 refactorised every 2nd target, 0.3 every 6th, ~20 % less time)
CHORD_RATE = 0.3
MAX_CHORD = 12
# redundant robots: their answer needs the W of a Newton step (or a refinement) anyway, so the
# chord steps only bring the residual to this (the Newton step then takes it below tol; one
# chord step fewer per two-segment target, the same acceptance tests)
CHORD_TOL_MULTI = 1e-7
# redundant robots: a refined W (one step with the last factorisation) counts as the W of its
# iterate when the refinement changed it by less than REFINE_TOL (relative); up to REFINE_MAX
# it is used and refined again at the next iterate; beyond, a new factorisation
REFINE_TOL = 1e-6
REFINE_MAX = 1e-2


@njit(cache=True, nogil=True)
def _pinv_projector(JO, rcond):
    """``J_O^+`` (singular values below ``rcond`` times the largest cut) and ``I - J_O^+ J_O``."""
    inv = np.linalg.pinv(JO, rcond)
    return inv, np.eye(JO.shape[1]) - inv @ JO


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
                self.inv, self.proj = _pinv_projector(np.ascontiguousarray(JO), RCOND)
            else:
                try:
                    self.inv = np.linalg.inv(JO)
                except np.linalg.LinAlgError:
                    pass
        self.null_norm = np.inf
        self._no_proj = np.zeros((W.shape[1], W.shape[1]))

    @classmethod
    def of(cls, cache, target, multi, W, lam_ref, lo, hi):
        """The step map of ``W`` from ``cache`` (a dict kept with ``W``), made on first use."""
        key = (target.axis, multi)
        sm = cache.get(key)
        if sm is None or sm.W is not W:
            sm = cache[key] = cls(target, multi, W, lam_ref, lo, hi)
        return sm

    def __call__(self, target, x, lam, w0):
        """Stretch increment at the state ``x``, ``w0 = J^{-1} R`` (None: leave the fast path).

        :func:`core.solve._chord.stretch_step`, the step of the compiled chord loop.
        """
        if self.inv is None:
            return None
        use_proj = self.proj is not None
        d, self.null_norm, ok = stretch_step(
            x, w0, lam, target.pd, float(target.tool), float(target.L), bool(target.axis),
            target.offset, self.inv, self.proj if use_proj else self._no_proj, use_proj,
            self.lam_ref, self.lo, self.hi)
        return d if ok else None


@dataclass(frozen=True)
class PathRecord:
    """What an answer along a path leaves for the next target's predictor (:func:`_second_order`).

    ``target``: its scaled target (``Target.offset``); ``previous``: the one
    before (None: none); ``dx, dlam``: what the iteration added to its linear
    prediction (None: no prediction), made with the sensitivities
    ``predicted_with`` and ``predicted_fresh`` (whether those were fresh);
    ``fresh``: whether the answer's own ``W`` was made in its solve (near
    it), not inherited from its warm start.
    """

    target: np.ndarray
    previous: np.ndarray | None = None
    dx: np.ndarray | None = None
    dlam: np.ndarray | None = None
    predicted_with: object = None
    predicted_fresh: bool = False
    fresh: bool = False


def _second_order(path, t_new, W, x, lam, lo, hi):
    """The linear predictor ``(x, lam)`` plus the last target's correction, scaled (or as is).

    ``path``: the warm start's :class:`PathRecord`.  Along a path sampled at
    a steady rate, the targets step alike and the second-order term of the
    prediction is nearly the same: when the new step ``t_new - t_w`` is
    within 25 % of the last one and the prediction uses the same ``W`` or a
    fresh one like the last, the correction is added, scaled by the squared
    ratio of the steps (a start only: the iteration's answer does not depend
    on it).
    """
    if path is None or path.previous is None or path.dx is None:
        return x, lam
    if not (path.predicted_with is W or (path.predicted_fresh and path.fresh)):
        return x, lam
    t_w, t_prev = path.target, path.previous
    last = norm(t_w - t_prev)
    if not last > 0 or norm(t_new - t_w - (t_w - t_prev)) > 0.25 * last:
        return x, lam
    s = (norm(t_new - t_w) / last) ** 2
    lam_c = lam + s * path.dlam
    if np.any(lam_c <= lo) or np.any(lam_c >= hi):
        return x, lam
    return x + s * path.dx, lam_c


class _WarmSolve:
    """State of one warm-started solve: iterate, sensitivities, factorisation, counters."""

    def __init__(self, model, target, multi, load, warm_fw, lam_ref, lo, hi, tol):
        """Set up from the warm start; see :func:`full_space_newton`."""
        self.model, self.target, self.multi, self.load = model, target, multi, load
        self.warm, self.lam_ref, self.lo, self.hi, self.tol = warm_fw, lam_ref, lo, hi, tol
        self.x, self.lam = warm_fw.x.copy(), warm_fw.stretch.copy()
        ws = self.warm_state = warm_fw._warm or WarmState()
        self.chord = ws.chord  # (factorisation, its W) from an earlier answer, or None
        self.W = ws.sensitivity
        self.maps = ws.step_maps if ws.step_maps is not None else {}  # of W
        self.t_warm = None if ws.path is None else ws.path.target
        self.hist, self.sm, self.lin, self.lin_W = [], None, None, (None, False)
        self.n_chord = self.newton_its = self.n_refine = 0
        # exact: the last step's W is the one at its own iterate (factorised there, or refined)
        self.exact = False

    def step_map(self, W, cache):
        return _StretchStep.of(cache, self.target, self.multi, W, self.lam_ref, self.lo, self.hi)

    def evaluate(self, jacobian=True, lam_derivative=True):
        return self.model.evaluate(self.x, self.lam, 1.0, self.load, jacobian=jacobian,
                                   lam_derivative=lam_derivative)

    def result(self, ev, rn):
        """The converged ForwardResult at the iterate, with what the next target reuses."""
        m, lin = self.model, self.lin
        return ForwardResult(
            model=m,
            pressures_pa=np.clip(m.stage1.pressure(self.lam), m.cfg.p_min, m.cfg.p_max),
            stretch=self.lam.copy(), payload_kg=self.load.payload_kg,
            tip_force_n=np.array(self.load.force_n), x=self.x, converged=True,
            stable=None, status=ForwardStatus.CONVERGED, message=ForwardStatus.CONVERGED.message,
            iterations=self.newton_its + self.n_chord + self.n_refine, residual_norm=rn,
            history=self.hist, jacobian=ev.jacobian,
            _warm=WarmState(
                sensitivity=self.W, exact=self.exact, chord=self.chord, step_maps=self.maps,
                path=PathRecord(self.target.offset, self.t_warm,
                                None if lin is None else self.x - lin[0],
                                None if lin is None else self.lam - lin[1], *self.lin_W,
                                fresh=self.W is not self.warm_state.sensitivity)),
        )

    def predict(self):
        """Predictor from the warm start (an equilibrium with known sensitivities); False: fail."""
        if self.W is None:
            return True
        sm = self.sm = self.step_map(self.W, self.maps)
        dlam = sm(self.target, self.x, self.lam, np.zeros(self.model.N))
        if dlam is None:
            return False
        self.x, self.lam = self.x - self.W @ dlam, self.lam + dlam
        self.lin = (self.x, self.lam)
        path = self.warm_state.path
        self.x, self.lam = _second_order(path, self.target.offset, self.W, self.x,
                                         self.lam, self.lo, self.hi)
        self.lin_W = (self.W, path is not None and path.fresh)
        # a held target is accepted at once when the warm start's W was its iterate's
        self.exact = self.multi and bool(self.warm_state.exact)
        return True

    def chord_phase(self, done):
        """Compiled chord steps with the stored factorisation: a converged result, or None.

        ``False`` as the first value: give up (a non-finite residual).
        """
        lu = None if self.chord is None else getattr(self.chord[0], "lu", None)
        if not isinstance(lu, (BandedLU, EnvelopeLDL)):
            return True, None
        W_c = self.chord[1]
        chord_map = self.step_map(W_c, self.maps if W_c is self.W else {})
        if chord_map.inv is None:
            return True, None
        # redundant robots: minimum-norm steps, no null-space term (see the module docstring)
        self.x, self.lam, status, steps, h, rn = chord_steps(
            self.model, self.load, self.target, lu, W_c, chord_map, self.x, self.lam,
            max(self.tol, CHORD_TOL_MULTI) if self.multi else self.tol, CHORD_RATE, MAX_CHORD,
            null_space=False)
        self.hist += h
        self.n_chord += steps
        self.exact = self.exact and steps == 0
        if status == NONFINITE:
            return False, None
        self.hist.pop()  # evaluated again by the Newton step, with its Jacobian
        if status == CHORD_CONVERGED and not self.multi:
            fw = self.result(self.evaluate(lam_derivative=False), rn)
            if done(fw):
                self.hist.append(rn)
                return True, fw
        return True, None

    def take(self, w0, W, sm, ev, rn, done):
        """Apply the step ``(w0, W)`` with the stretch map ``sm``; False: leave the fast path.

        A redundant robot's iterate is the answer already when its ``W`` is
        its own (``exact``), its residual ``rn`` within the tolerance and the
        null-space correction below 1e-9: then the converged ForwardResult
        comes back instead of the step.
        """
        dlam = sm(self.target, self.x, self.lam, w0)
        if dlam is None:
            return False
        if self.multi and self.exact and rn <= self.tol and sm.null_norm <= 1e-9:
            fw = self.result(ev, rn)
            if done(fw):
                return fw
        self.x, self.lam = self.x - (w0 + W @ dlam), self.lam + dlam
        return True

    def refine(self, ev, rn, done):
        """Redundant robot after a Newton step: W at this iterate by one refinement.

        With the last factorisation; it counts as this iterate's W when the
        refinement changed it by less than REFINE_TOL, is refined again at
        the next iterate when by less than REFINE_MAX.  Returns None when a
        new factorisation is needed, else what :meth:`take` returns.
        """
        F, W = self.chord[0], self.W
        sol = F.solve(np.column_stack([ev.residual, ev.dres_dlam - ev.jacobian @ W]))
        dW = sol[:, 1:]
        W_new = W + dW
        change = np.max(np.abs(dW)) / max(np.max(np.abs(W_new)), 1e-300)
        if change > REFINE_MAX:
            return None
        self.n_refine += 1
        self.W, self.maps = W_new, {}
        self.chord = (F, W_new)
        self.sm = self.step_map(W_new, self.maps)
        self.exact = change <= REFINE_TOL
        return self.take(sol[:, 0], W_new, self.sm, ev, rn, done)

    def newton(self, ev, rn, done):
        """A Newton step with a new factorisation at the iterate (what :meth:`take` returns)."""
        factorised = kkt_solver(self.model).bound(ev.jacobian)
        try:
            sol = factorised.solve(np.column_stack([ev.residual, ev.dres_dlam]))
        except np.linalg.LinAlgError:
            return False
        self.newton_its += 1
        self.W = sol[:, 1:]
        self.chord, self.maps = (factorised, self.W), {}
        self.sm = self.step_map(self.W, self.maps)
        self.exact = True
        return self.take(sol[:, 0], self.W, self.sm, ev, rn, done)


def full_space_newton(
    model, target, multi, load, warm_fw, lam_ref, lo, hi, done, tol, max_iter=8,
    budget=None,
):
    """Newton's method on all unknowns ``[lam, q, alpha]`` at once (eqs. 29, 30), chord first.

    See the module docstring.  Returns a converged ForwardResult or None
    (then the robust reduced iteration takes over): it never leaves the
    interior of the pressure box and gives up on any sign of trouble, or
    when the ``budget``'s deadline has passed (checked before every
    factorisation).
    """
    s = _WarmSolve(model, target, multi, load, warm_fw, lam_ref, lo, hi, tol)
    if not s.predict():
        return None
    first = True
    while True:
        if first or not s.exact or not multi:  # (redundant robots: not after an exact step)
            first = False
            ok, fw = s.chord_phase(done)
            if not ok:
                return None
            if fw is not None:
                return fw
        ev = s.evaluate()
        rn = float(np.max(np.abs(ev.residual * model.residual_scale)))
        s.hist.append(rn)
        if not np.isfinite(rn):
            return None
        if rn <= tol and (not multi or (s.exact and s.sm.null_norm <= 1e-9)):
            fw = s.result(ev, rn)
            if done(fw):
                return fw
        if (s.newton_its >= 2 and rn > 1e-2) or s.newton_its >= max_iter:
            return None
        if budget is not None and budget.expired():
            return None
        if multi and s.newton_its > 0 and s.n_refine < max_iter:
            ok = s.refine(ev, rn, done)
            if ok is not None:
                if ok is False:
                    return None
                if ok is not True:
                    return ok  # the iterate is the answer
                continue
        ok = s.newton(ev, rn, done)
        if ok is False:
            return None
        if ok is not True:
            return ok
