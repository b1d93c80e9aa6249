"""Time integration of the constrained dynamics: generalized-alpha for index 3 (docs/dynamics.md).

The equations (docs/dynamics.md section 2), in material coordinates::

    M q'' + beta K_m(q) q' + alpha M q' + Q(q, lam(t), load(t)) + C_q^T mu = 0,   C(q) = 0,

with ``Q + C_q^T mu`` the static residual of eq. (25) seen through the
coordinate map ``q_static = T(lam)^-1 q`` (module ``_inertia``): at constant
pressures the rest state is exactly the static solution.

Integrator: the generalized-alpha method of Chung & Hulbert (1993) in the
form of Arnold & Bruels (2007, "Convergence of the generalized-alpha scheme
for constrained mechanical systems", Multibody System Dynamics 18), which
keeps the equations of motion and the position constraints at ``t_{n+1}``
(index 3, no drift) and is second-order accurate in the positions.  Its
high-frequency dissipation is set by the spectral radius ``rho_inf``
(``alpha_m = (2 rho - 1)/(rho + 1)``, ``alpha_f = rho/(rho + 1)``,
``gamma = 1/2 + alpha_f - alpha_m``, ``beta = (gamma + 1/2)^2 / 4``).

Each step solves its nonlinear equations by Newton's method on the KKT
matrix of the static solver (eq. 27: the compiled residual and Jacobian
kernel) plus ``beta' M + gamma' D``, scaled as Arnold & Bruels advise (the
dynamic rows by ``1/beta'``, the multipliers by ``beta'``) so that its
conditioning does not degrade as ``h -> 0``.  The factorisation is kept
from step to step (a chord method) and refreshed only when the iterations
slow down or the step or the mass changes.  A step that does not converge
within its budget is retried as two half steps, down to a limit; past it
the integration stops with a :class:`~bellow_ancf_ros.core.status.DynamicsStatus`
that says why, and the state stays at the last converged step: never a
silently wrong answer.

Cost (issue 26: one segment at 10x real time needs a step in 0.24 ms): the
iterations of a step run in one compiled call (``_kernels.chord_iterations``:
static residual, dynamic right-hand side, triangular solves with the kept
factors, no allocation); the predictor extrapolates the accelerations and
multipliers of the last three states (quadratic); a step has converged when the update,
or the error it leaves at the observed contraction rate (``size c/(1-c)``),
is within ``tol`` (about three iterations a step instead of four); a
refactorisation reuses the pivots of an earlier SuperLU factorisation of
the same pattern (``_kernels.refactor``).  Against runs at ``tol`` 1e-13
the end effector moves by at most 1.9e-10 m (one and two segments, release
and a pressure sine over eight periods; 2.6e-11 m with the former test of
the update alone and a constant-acceleration predictor): five times inside
the 1e-9 m the tests ask, and three orders below the time discretisation's
own error (step halving, docs/dynamics.md: some 1e-7 m at these steps).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..model import RobotModel, TipLoad, as_tip_load
from ..status import DynamicsStatus
from ._inertia import Inertia
from ._kernels import (chord_iterations, compact_factors, refactor, split_factors,
                       state_checks, symbolic_factors)

__all__ = ["DynamicState", "GeneralizedAlpha", "StepReport", "DynamicsError",
           "STEPS_PER_PERIOD", "MIN_STEPS_PER_PERIOD", "MAX_DEFAULT_STEP_S", "default_step",
           "warm_up_dynamics"]

#: Default steps per period of the first mode: period error of the scheme about
#: ``(2 pi / 40)^2 / 12 = 0.2 %`` (Chung & Hulbert 1993).
STEPS_PER_PERIOD = 40
#: Fewest steps per first-mode period a simulated robot accepts (period error about 0.8 %).
MIN_STEPS_PER_PERIOD = 20
#: Longest default step [s], whatever the first mode (higher modes still matter).
MAX_DEFAULT_STEP_S = 0.01
#: Largest backward error of a refactorised chord matrix along old pivots (a fresh
#: SuperLU factorisation shows some 1e-17); beyond it SuperLU pivots afresh.
REFACTOR_ERROR = 1e-13


def default_step(first_mode_hz: float) -> float:
    """The default step [s]: ``1 / (STEPS_PER_PERIOD f1)``, at most :data:`MAX_DEFAULT_STEP_S`."""
    return min(MAX_DEFAULT_STEP_S, 1.0 / (STEPS_PER_PERIOD * float(first_mode_hz)))


class DynamicsError(RuntimeError):
    """An integration that could not continue (``status``: a DynamicsStatus)."""

    def __init__(self, status: DynamicsStatus, detail: str = ""):
        self.status = DynamicsStatus(status)
        super().__init__(self.status.message + (f" ({detail})" if detail else ""))


@dataclass
class DynamicState:
    """The robot's state at time ``t`` (material coordinates, SI units).

    ``q, v, acc``: coordinates, velocities, accelerations; ``aux``: the
    generalized-alpha acceleration-like variable; ``mu``: multipliers;
    ``stretch``: stage-1 stretches; ``load``: payload and tip force.
    """

    t: float
    q: np.ndarray
    v: np.ndarray
    acc: np.ndarray
    aux: np.ndarray
    mu: np.ndarray
    stretch: np.ndarray
    load: TipLoad

    def copy(self) -> "DynamicState":
        return DynamicState(self.t, self.q.copy(), self.v.copy(), self.acc.copy(),
                            self.aux.copy(), self.mu.copy(), self.stretch.copy(), self.load)


@dataclass
class StepReport:
    """What :meth:`GeneralizedAlpha.advance` did: status, steps, iterations, refreshes."""

    status: DynamicsStatus = DynamicsStatus.COMPLETED
    message: str = ""
    steps: int = 0
    iterations: int = 0
    factorizations: int = 0
    halvings: int = 0
    wall_s: float = 0.0
    history: list = field(default_factory=list, repr=False)

    @property
    def success(self) -> bool:
        return self.status == DynamicsStatus.COMPLETED


class GeneralizedAlpha:
    """Generalized-alpha integrator of one robot (module docstring).

    Parameters
    ----------
    model : RobotModel
    step_s : the step [s]; default :func:`default_step` of the first mode at
        the start equilibrium (set by :meth:`start`).
    rho_inf : spectral radius at infinite frequency (1: no numerical
        dissipation; 0.9 by default damps only what the step does not resolve).
    inertia : an :class:`Inertia` (default: the robot file's damping), or
    damping_time_s, mass_damping_per_s : to override the robot file's.
    tol : convergence of a step: the Newton update, or the error it leaves
        at the iterations' contraction rate, positions relative to the
        robot's length, slopes and plate axes as they are.
    max_iter : Newton iterations per step (factorisations included).
    max_halvings : how often a failing step may be halved.
    """

    def __init__(self, model: RobotModel, step_s: float | None = None, rho_inf: float = 0.9,
                 inertia: Inertia | None = None, damping_time_s: float | None = None,
                 mass_damping_per_s: float | None = None, tol: float = 1e-10,
                 max_iter: int = 12, max_halvings: int = 6):
        if not 0.0 <= rho_inf <= 1.0:
            raise ValueError(f"rho_inf = {rho_inf!r} is not allowed; allowed: 0 to 1")
        if step_s is not None and not (np.isfinite(step_s) and step_s > 0):
            raise ValueError(f"step_s = {step_s!r} is not allowed; allowed: a positive time [s]")
        self.model = model
        self.inertia = inertia or Inertia(model, damping_time_s, mass_damping_per_s)
        self.step_s = None if step_s is None else float(step_s)
        r = float(rho_inf)
        self.rho_inf = r
        self.alpha_m = (2 * r - 1) / (r + 1)
        self.alpha_f = r / (r + 1)
        self.gamma = 0.5 + self.alpha_f - self.alpha_m
        self.beta = 0.25 * (self.gamma + 0.5) ** 2
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        self.max_halvings = int(max_halvings)
        self.state: DynamicState | None = None
        self._inv_scale = 1.0 / np.where(model.position_dof, model.length_scale, 1.0)
        self._build_pattern()
        self._lu = None       # the chord matrix's factors (the tuple of _kernels.lu_solve)
        self._lu_key = None
        # factors of the identity: for the call that runs the predictor alone
        self._lu_dummy = split_factors(spla.splu(sp.identity(model.N, format="csc")))
        self._work = tuple(np.empty(model.N) for _ in range(4))
        st1, cfg = model.stage1, model.cfg
        ia = self.inertia
        self._stage1_args = (
            np.where(ia.slope_dof, ia.slope_act, -1).astype(np.int64),
            np.ascontiguousarray(st1.k_coefficients, dtype=float),
            np.ascontiguousarray(st1.dk_coefficients, dtype=float), float(cfg.l0),
            float(model.n), float(cfg.d_a), float(cfg.rho0),
            np.asarray(model.gravity, dtype=float) * 1.0)
        self._mass_cache, self._load_cache = {}, {}
        self._mass_values = (None, None)
        self._hist = None   # the predictor's history (_extrapolation)
        self._stretch_kept = None   # (pressures, their stretches): _stretch_input
        self.counters = {"steps": 0, "iterations": 0, "factorizations": 0}

    # ------------------------------------------------------------ pattern
    def _build_pattern(self):
        """The union of the KKT pattern (eq. 27) and the mass pattern, with index maps."""
        m = self.model
        N = m.N
        Js = sp.csc_matrix((np.ones(m.nnz), m.csc_indices, m.csc_indptr), shape=(N, N)).tocoo()
        M1 = self.inertia.mass_matrix(1.0).tocoo()  # a 1 kg payload: its entries are in too
        rows = np.concatenate([Js.row, M1.row])
        cols = np.concatenate([Js.col, M1.col])
        key = np.unique(cols.astype(np.int64) * N + rows)
        self._key = key
        self._indices = (key % N).astype(np.int32)
        ucol = key // N
        self._indptr = np.searchsorted(ucol, np.arange(N + 1)).astype(np.int32)
        self._nnz = len(key)

        def where(r, c):
            return np.searchsorted(key, c.astype(np.int64) * N + r)

        # the static matrix's CSC entries, in its data order
        sc = np.repeat(np.arange(N), np.diff(m.csc_indptr))
        sr = np.asarray(m.csc_indices)
        self._map_static = where(sr, sc)
        self._static_rows, self._static_cols = sr, sc
        ed = m.elem_dofs
        self._elem_rows = np.repeat(ed, 12, axis=1).ravel()
        self._elem_cols = np.tile(ed, (1, 12)).ravel()
        self._map_elem = where(self._elem_rows, self._elem_cols)
        self._indptr64 = self._indptr.astype(np.int64)
        self._indices64 = self._indices.astype(np.int64)
        self._check_b = np.random.default_rng(26).standard_normal(N)  # refactor's test vector

    def _mass_map(self, M):
        Mc = M.tocoo()
        return np.searchsorted(self._key, Mc.col.astype(np.int64) * self.model.N + Mc.row), Mc.data

    # -------------------------------------------------------------- start
    def start(self, fw, t0: float = 0.0) -> DynamicState:
        """Start at rest at the equilibrium ``fw`` (a converged ForwardResult) at time ``t0``.

        Sets the default step from the first mode of ``fw`` when none was
        given.  The consistent accelerations are those of the rest state
        under ``fw``'s own loads: zero.
        """
        if not fw.converged:
            raise DynamicsError(DynamicsStatus.NONFINITE, "the start equilibrium did not converge")
        lam = np.asarray(fw.stretch, dtype=float).copy()
        q = self.inertia.to_material(fw.q, lam)
        nq = self.model.nq
        self.state = DynamicState(t=float(t0), q=q, v=np.zeros(nq), acc=np.zeros(nq),
                                  aux=np.zeros(nq), mu=np.asarray(fw.x[nq:], float).copy(),
                                  stretch=lam, load=fw.load)
        if self.step_s is None:
            from ._modes import natural_modes  # noqa: PLC0415 (only for the default step)
            f1 = natural_modes(fw, 1, inertia=self.inertia).first.frequency_hz
            self.step_s = default_step(f1)
        return self.state

    def start_released(self, fw, load_after=None, t0: float = 0.0) -> DynamicState:
        """Start at rest at ``fw`` and change the load at ``t0`` (a release).

        ``load_after``: the payload and tip force from ``t0`` on (default: the
        payload of ``fw`` without its tip force).  The accelerations are made
        consistent with the new load: ``[M C_q^T; C_q 0] [q''; mu] = [-f; 0]``.
        """
        st = self.start(fw, t0)
        new = TipLoad(fw.load.payload_kg, (0.0, 0.0, 0.0)) if load_after is None \
            else as_tip_load(load_after)
        st.load = new
        m = self.model
        nq = m.nq
        s = self.inertia.scale(st.stretch)
        ev = m.evaluate(np.concatenate([st.q / s, st.mu]), st.stretch, 1.0, new, jacobian=True)
        Ti = 1.0 / s
        f = Ti * (ev.residual[:nq] - ev.jacobian[:nq, nq:] @ st.mu)  # forces without C^T mu
        Cq = ev.jacobian[nq:, :nq] @ sp.diags(Ti)
        M = self.inertia.mass_matrix(new)
        K = sp.bmat([[M, Cq.T], [Cq, None]], format="csc")
        sol = spla.spsolve(K, np.concatenate([-f, np.zeros(m.nc)]))
        st.acc = sol[:nq]
        st.aux = st.acc.copy()
        st.mu = sol[nq:]
        return st

    # ---------------------------------------------------------------- step
    def _mass_arrays(self, payload_kg: float):
        """CSR arrays of the mass matrix and its map into the chord pattern, per payload."""
        got = self._mass_cache.get(payload_kg)
        if got is None:
            M = self.inertia.mass_matrix_csr(payload_kg)
            got = ((M.indptr, M.indices, M.data), self._mass_map(self.inertia.mass_matrix(
                payload_kg)))
            if len(self._mass_cache) > 16:
                self._mass_cache.clear()
            self._mass_cache[payload_kg] = got
        return got

    def _inputs(self, lam: np.ndarray, load: TipLoad):
        """The kernel's inputs at stretch ``lam`` and ``load`` (point forces kept per load)."""
        q_point = self._load_cache.get(load)
        if q_point is None:
            q_point = np.ascontiguousarray(self.model.point_forces(load), dtype=float)
            if len(self._load_cache) > 16:
                self._load_cache.clear()
            self._load_cache[load] = q_point
        return (lam,) + self._stage1_args + (q_point,)

    def _factor(self, st: DynamicState, h: float):
        """Factorise the chord matrix at the state ``st`` (its stretch, load and step ``h``)."""
        m = self.model
        bp = (1 - self.alpha_m) / ((1 - self.alpha_f) * h * h * self.beta)
        gp = self.gamma / (h * self.beta)
        Ti = 1.0 / self.inertia.scale(st.stretch)
        x_static = np.concatenate([st.q * Ti, st.mu])
        ev = m.evaluate(x_static, st.stretch, 1.0, st.load, jacobian=True)
        rs = np.concatenate([Ti / bp, np.ones(m.nc)])
        cs = np.concatenate([Ti, np.full(m.nc, bp)])
        data = np.zeros(self._nnz)
        data[self._map_static] = ev.jacobian.data * rs[self._static_rows] * cs[self._static_cols]
        c = gp / bp
        key = (float(st.load.payload_kg), c)
        if self._mass_values[0] != key:   # the mass's entries, per payload and step
            Mmap, Mdata = self._mass_arrays(key[0])[1]
            self._mass_values = (key, np.bincount(
                Mmap, Mdata * (1.0 + c * self.inertia.mass_damping), minlength=self._nnz))
        data += self._mass_values[1]
        if self.inertia.damping_time:
            blocks = self.inertia.damping_blocks(st.q, st.stretch).ravel()
            blocks = blocks * Ti[self._elem_rows] * Ti[self._elem_cols] * c
            data += np.bincount(self._map_elem, blocks, minlength=self._nnz)
        self._lu = self._decompose(data)
        self._lu_key = (h, float(st.load.payload_kg))
        self.counters["factorizations"] += 1

    def _decompose(self, data):
        """LU factors of the chord matrix with the values ``data`` (the tuple of ``lu_solve``).

        A numeric refactorisation along the pivots of an earlier SuperLU
        factorisation of this pattern (kept with the model, so a new
        integrator of the same robot starts with it) costs a fraction of a
        new one (0.2 against 1.1 ms, one segment); its backward error is
        checked, and pivots that no longer suit the matrix
        (:data:`REFACTOR_ERROR`) make SuperLU choose new ones.
        """
        m = self.model
        work = self._work[0]
        kept = m.cached(("chord pattern", self._key.tobytes()), lambda _: {})
        sym = kept.get("symbolic")
        if sym is not None:
            lu, err = refactor(self._indptr64, self._indices64, data, sym, self._check_b, work)
            if err <= REFACTOR_ERROR:
                return compact_factors(lu)
        A = sp.csc_matrix((data, self._indices, self._indptr), shape=(m.N, m.N))
        try:
            superlu = spla.splu(A, permc_spec="COLAMD")
        except RuntimeError as exc:
            raise DynamicsError(DynamicsStatus.SINGULAR, str(exc)) from exc
        sym = symbolic_factors(self._indptr64, self._indices64, superlu.perm_r, superlu.perm_c)
        lu, err = refactor(self._indptr64, self._indices64, data, sym, self._check_b, work)
        if err <= REFACTOR_ERROR:
            kept["symbolic"] = sym
            return compact_factors(lu)
        return split_factors(superlu)   # SuperLU's own factors (not expected)

    def _extrapolation(self, h: float):
        """The predictor's earlier states and weights for a step ``h`` from ``self.state``.

        Returns ``(prev, weights, back)``: the accelerations and multipliers
        of the two states before (``(acc, mu, acc, mu)``), the weights of the
        values at ``t_n, t_{n-1}, t_{n-2}`` (Lagrange extrapolation to
        ``t_n + h``: quadratic when both are known, linear after one step,
        constant after a start) and what the next step's history keeps.
        Quadratic against linear: 14 % fewer iterations under a pressure sine,
        3 % more in a release's first periods, where the scheme's alternating
        high-frequency transient (damped by ``rho_inf``) is extrapolated too.
        """
        st0 = self.state
        hist = self._hist   # (state, its step, the state before, (step, state) before that)
        if hist is None or hist[0] is not st0:
            return (st0.acc, st0.mu, st0.acc, st0.mu), (1.0, 0.0, 0.0), None
        h1, s1 = hist[1], hist[2]
        if hist[3] is None:
            r = h / h1
            return (s1.acc, s1.mu, s1.acc, s1.mu), (1.0 + r, -r, 0.0), (h1, s1)
        h2, s2 = hist[3]
        w0 = (h + h1) * (h + h1 + h2) / (h1 * (h1 + h2))
        w1 = -h * (h + h1 + h2) / (h1 * h2)
        w2 = h * (h + h1) / ((h1 + h2) * h2)
        return (s1.acc, s1.mu, s2.acc, s2.mu), (w0, w1, w2), (h1, s1)

    def _try_step(self, h: float, lam_next, load_next) -> DynamicState | None:
        """One step of length ``h`` from ``self.state``; None if Newton does not converge.

        The iterations run compiled (:func:`chord_iterations`); Python only
        refactors when they ask for it.  Predictor: the accelerations and
        multipliers extrapolated from the last three states
        (:meth:`_extrapolation`), which follows a smoothly changing input (a
        pressure ramp or sine) that a constant acceleration misses.
        """
        m = self.model
        nq, nc = m.nq, m.nc
        st0 = self.state
        lam = np.ascontiguousarray(lam_next, dtype=float)
        load = as_tip_load(load_next)
        payload = float(load.payload_kg)
        inputs = self._inputs(lam, load)
        mass = self._mass_arrays(payload)[0]
        st = DynamicState(st0.t + h, np.empty(nq), np.empty(nq), np.empty(nq), np.empty(nq),
                          np.empty(nc), lam, load)
        key = self._lu_key
        if self._lu is None or key[1] != payload or abs(key[0] - h) > 0.25 * h:
            self._lu = None   # the chord matrix of a near step is kept
        prev, weights, back = self._extrapolation(h)
        ia = self.inertia
        coef = (float(h), self.alpha_m, self.alpha_f, self.beta, self.gamma,
                ia.damping_time, ia.mass_damping)
        s0 = (st0.q, st0.v, st0.acc, st0.aux, st0.mu)
        s1 = (st.q, st.v, st.acc, st.aux, st.mu)
        kargs = self.model.kernel_args
        predict, refreshed, it, last = True, False, 0, np.inf
        while True:
            if self._lu is None:
                if predict:   # the predictor alone (no iteration): the point to factor at
                    chord_iterations(s0, prev, weights, True, s1, coef, inputs, kargs, mass,
                                     self._lu_dummy, (self._inv_scale, self.tol, 0, 0, last,
                                                      refreshed), self._work)
                    predict = False
                self._factor(st, h)
                refreshed = True
            code, n, last = chord_iterations(
                s0, prev, weights, predict, s1, coef, inputs, kargs, mass, self._lu,
                (self._inv_scale, self.tol, it, self.max_iter, last, refreshed), self._work)
            predict = False
            it += n
            self.counters["iterations"] += n
            if code == 0:
                self._hist = (st, h, st0, back)
                return st
            if code == 5:
                raise DynamicsError(DynamicsStatus.NONFINITE, "a converged step is not finite")
            if code != 1 or it >= self.max_iter:
                return None
            self._lu = None   # slow chord iterations: refactor at the current iterate

    def advance(self, t_end: float, stretch=None, load=None, pressures_pa=None,
                time_budget_s: float | None = None) -> StepReport:
        """Integrate from the current state to ``t_end``.

        ``stretch`` or ``pressures_pa``: the stage-1 input, a constant or a
        function of time (``f(t) -> array``); the default keeps the current
        stretches.  ``load``: payload and tip force, a constant (a mass, a
        :class:`TipLoad`) or a function of time; default: unchanged.  The
        inputs are sampled at the end of every step (a pressure change moves
        the stress-free length; the material curve stays continuous).

        Returns a :class:`StepReport`; on failure the state is the last
        converged step and ``status`` says why.
        """
        st = self.state
        if st is None:
            raise RuntimeError("call start(fw) first")
        rep = StepReport()
        t0 = time.perf_counter()
        counters = self.counters
        c0 = (counters["steps"], counters["iterations"], counters["factorizations"])
        stretch_at = self._stretch_input(stretch, pressures_pa)
        load_at = self._load_input(load)
        # equal steps of about step_s (up to 10 % longer rather than one more step: a physics
        # tick of one step's length, with its jitter, stays one step); a span that repeats
        # repeats the step, and the factorisation made for it is reused
        span = t_end - st.t
        n = max(1, math.ceil(span / self.step_s - 0.1))
        h = span / n
        start = st.t
        for k in range(n if span > 0 else 0):
            if time_budget_s is not None and time.perf_counter() - t0 > time_budget_s:
                rep.status = DynamicsStatus.TIME_BUDGET
                break
            if k == n - 1:
                h = t_end - self.state.t   # land exactly on t_end
            elif k:
                h = (t_end - start) / n
            status = self._step_halving(h, stretch_at, load_at, rep)
            if status != DynamicsStatus.COMPLETED:
                rep.status = status
                break
        rep.steps = counters["steps"] - c0[0]
        rep.iterations = counters["iterations"] - c0[1]
        rep.factorizations = counters["factorizations"] - c0[2]
        rep.wall_s = time.perf_counter() - t0
        rep.message = rep.status.message if rep.success else (
            f"{rep.status.message} at t = {self.state.t:.6g} s")
        return rep

    def _stretch_input(self, stretch, pressures_pa):
        """``f(t)``: the stretches at ``t`` (:meth:`advance`); constant pressures map once.

        The stretches of the last constant pressures are kept (a run advanced
        sample by sample maps them once, not at every step); each call gets
        its own copy, which the states of its steps share.
        """
        if pressures_pa is not None:
            stage1 = self.model.stage1
            if callable(pressures_pa):
                return lambda t: np.asarray(
                    stage1.stretch(np.asarray(pressures_pa(t), dtype=float)), dtype=float)
            p = np.asarray(pressures_pa, dtype=float)
            key = (p.shape, p.tobytes())
            kept = self._stretch_kept
            if kept is None or kept[0] is not stage1 or kept[1] != key:
                kept = self._stretch_kept = (stage1, key, np.array(stage1.stretch(p), dtype=float))
            lam = kept[2].copy()
            return lambda t: lam
        if stretch is not None:
            if callable(stretch):
                return lambda t: np.asarray(stretch(t), dtype=float)
            lam = np.asarray(stretch, dtype=float)
            return lambda t: lam
        return lambda t: self.state.stretch

    def _load_input(self, load):
        """``f(t)``: the payload and tip force at ``t`` (:meth:`advance`)."""
        if load is None:
            return lambda t: self.state.load
        if callable(load):
            return lambda t: as_tip_load(load(t))
        fixed = as_tip_load(load)
        return lambda t: fixed

    def _step_halving(self, h, stretch_at, load_at, rep, depth=0) -> DynamicsStatus:
        t = self.state.t
        try:
            new = self._try_step(h, stretch_at(t + h), load_at(t + h))
        except DynamicsError as exc:
            return exc.status
        if new is not None:   # finite: _try_step checked
            self.state = new
            self.counters["steps"] += 1
            return DynamicsStatus.COMPLETED
        self._lu = None
        if depth >= self.max_halvings:
            return DynamicsStatus.STEP_TOO_SMALL
        rep.halvings += 1
        for _ in range(2):
            status = self._step_halving(0.5 * h, stretch_at, load_at, rep, depth + 1)
            if status != DynamicsStatus.COMPLETED:
                return status
        self._lu = None  # the next full step needs its own factorisation
        return DynamicsStatus.COMPLETED

    # ------------------------------------------------------------ read-outs
    def static_coordinates(self, state: DynamicState | None = None) -> np.ndarray:
        """The state's coordinates in the static (stretched) convention (``nq``)."""
        st = state or self.state
        return self.inertia.to_static(st.q, st.stretch)

    def end_effector(self, state: DynamicState | None = None):
        """End-effector position and rotation (columns x, y, z) of the state."""
        st = state or self.state
        # the plates' coordinates are the same in both conventions (Inertia.scale: 1 on them)
        return self.model.end_effector(st.q)

    def checks(self, state: DynamicState | None = None) -> tuple[dict, float]:
        """:meth:`energy` and :meth:`constraint_violation` of the state in one compiled call."""
        st = state or self.state
        load = as_tip_load(st.load)
        lam = np.ascontiguousarray(st.stretch, dtype=float)
        kin, pot, worst = state_checks(st.q, st.v, st.mu, self._inputs(lam, load),
                                       self.model.kernel_args,
                                       self._mass_arrays(float(load.payload_kg))[0])
        return {"kinetic_j": kin, "potential_j": pot, "total_j": kin + pot}, worst

    def constraint_violation(self, state: DynamicState | None = None) -> float:
        """Largest constraint residual ``max |C(q)|`` (metres for the attachments)."""
        return self.checks(state)[1]

    def energy(self, state: DynamicState | None = None) -> dict:
        """Kinetic, potential (elastic plus gravity and loads, eqs. 15-17) and total energy [J].

        ``Inertia.kinetic_energy`` plus ``RobotModel.potential`` at the static
        coordinates, computed by a compiled kernel (``_kernels.state_checks``).
        """
        return self.checks(state)[0]


def warm_up_dynamics(model: RobotModel) -> None:
    """Compile (or load) the integrator's kernels: two short steps from the vent equilibrium.

    Then the read-outs' kernel (:meth:`GeneralizedAlpha.checks`).
    """
    from ..solve import solve_forward  # noqa: PLC0415 (the vent equilibrium, once)
    fw = solve_forward(model, np.zeros(model.A), check_stability=False)
    if fw.converged:
        ig = GeneralizedAlpha(model, step_s=1e-3)
        ig.start(fw)
        ig.advance(2e-3)
        ig.checks()
