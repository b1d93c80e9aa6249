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
from step to step (a chord method) and refreshed when the iterations slow
down, when the iterations its steps took beyond those of its first step
add up to about what a factorisation costs (``_kernels.FACTOR_ITERATIONS``:
a matrix made far from where the robot now is), or when the step or the
mass changes.  A step that does not converge
within its budget is retried as two half steps, down to a limit; past it
the integration stops with a :class:`~bellow_ancf_ros.core.status.DynamicsStatus`
that says why, and the state stays at the last converged step: never a
silently wrong answer.

Cost (issue 26: one segment at 10x real time needs a step in 0.24 ms): the
iterations of a step run in one compiled call (``_kernels.chord_iterations``:
static residual, dynamic right-hand side, triangular solves with the kept
factors, no allocation), and the steps of a run one after the other in
another (``_kernels.run_steps``: predictor, history, the records of
:meth:`GeneralizedAlpha.advance_through`; issue 36: Python around each step
cost as much as the step); Python plans the steps and the inputs at their
ends beforehand, factorises when the iterations ask, and halves a step that
fails; the predictor extrapolates the accelerations and
multipliers of the last three states (quadratic); a step has converged when the update,
or the error it leaves at the observed contraction rate (``size c/(1-c)``),
is within ``tol`` (about three iterations a step instead of four); a
refactorisation reuses the pivots of an earlier SuperLU factorisation of
the same pattern (``_kernels.refactor``), and the matrix's values are
assembled in one compiled call (``_kernels.chord_values``: 0.33 against
0.46 ms for the whole factorisation, one segment at twice the model's
elements).  Against runs at ``tol`` 1e-13
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
from ._kernels import (NEED_FACTOR, chord_values, compact_factors, refactor, run_steps,
                       split_factors, state_checks, symbolic_factors)

__all__ = ["DynamicState", "GeneralizedAlpha", "Passage", "PressureRamp", "StepReport",
           "DynamicsError",
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
#: Steps of a run between two looks at its time budget (:meth:`GeneralizedAlpha.advance`).
BUDGET_STEPS = 8


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

    The integrator replaces its state whole after a run (``q`` to ``mu``:
    views of one block of their own) and keeps what it knows of it (the
    predictor's history, its working copy) by identity: a state is changed
    by assigning a new one, or new arrays, not in place.
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


@dataclass
class Passage:
    """What :meth:`GeneralizedAlpha.advance_through` recorded at each end it reached.

    ``times_s`` (n,); ``plate`` (n, 12): the end plate's coordinates
    (``RobotModel.end_effectors`` turns them into poses); ``checks`` (n, 3):
    kinetic and potential energy [J] and the largest constraint residual
    where asked (NaN elsewhere); ``pressures_pa`` (n, A): the input there
    when the pressures were a function of time, else None.
    """

    times_s: np.ndarray
    plate: np.ndarray
    checks: np.ndarray
    pressures_pa: np.ndarray | None


class PressureRamp:
    """Pressures linear in time from ``p0`` at ``t0`` to ``p1`` at ``t1``, held at ``p1`` after.

    A ``pressures_pa`` function of time for :meth:`GeneralizedAlpha.advance`
    (``ramp(t)``: ``p0 + (min(t, t1) - t0) / span * (p1 - p0)``, ``span`` at
    least 1e-12 s) whose values at many times :meth:`table` computes in one
    go, with the same arithmetic: the integrator asks for it instead of
    calling the function at every step (a simulated robot's physics tick).
    """

    __slots__ = ("t0", "t1", "span", "p0", "p1")

    def __init__(self, t0: float, t1: float, p0, p1):
        self.t0, self.t1 = float(t0), float(t1)
        self.span = max(self.t1 - self.t0, 1e-12)
        self.p0 = np.asarray(p0, dtype=float)
        self.p1 = np.asarray(p1, dtype=float)

    def __call__(self, t: float) -> np.ndarray:
        return self.p0 + (min(t, self.t1) - self.t0) / self.span * (self.p1 - self.p0)

    def table(self, times: np.ndarray) -> np.ndarray:
        """The pressures at each time of ``times`` (n,): an (n, A) array.

        With plain floats (a physics tick's few steps and actuators), the
        operations of :meth:`__call__` in the same order.
        """
        t0, t1, span = self.t0, self.t1, self.span
        p0 = self.p0.ravel().tolist()
        dp = (self.p1 - self.p0).ravel().tolist()
        rows = []
        for t in times.tolist():
            f = (min(t, t1) - t0) / span
            rows.append([a + f * d for a, d in zip(p0, dp)])
        return np.array(rows).reshape(len(rows), len(p0))


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
        self._stale = np.zeros(3, dtype=np.int64)   # run_steps' count against the factors
        # factors of the identity: for the call that runs the predictor alone
        self._lu_dummy = split_factors(spla.splu(sp.identity(model.N, format="csc")))
        self._work = tuple(np.empty(model.N) for _ in range(4))
        # run_steps' state: five views of one block (a state after a run copies it in one go)
        ends = np.cumsum((0,) + (model.nq,) * 4 + (model.nc,))
        self._cur_parts = tuple(slice(a, b) for a, b in zip(ends[:-1], ends[1:]))
        self._cur_block = np.empty(ends[-1])
        self._cur = tuple(self._cur_block[part] for part in self._cur_parts)
        self._nxt = tuple(np.empty(k) for k in (model.nq,) * 4 + (model.nc,))
        # (state, its five arrays) when self._cur holds that state's values (_run), else None
        self._cur_of = None
        self._no_record = ((np.full(1, -1, dtype=np.int64), np.zeros(1, dtype=np.bool_),
                            np.zeros(12, dtype=np.int64)), (np.zeros((1, 12)), np.zeros((1, 3))))
        st1, cfg = model.stage1, model.cfg
        ia = self.inertia
        self._stage1_args = (
            np.where(ia.slope_dof, ia.slope_act, -1).astype(np.int64),
            np.ascontiguousarray(st1.k_coefficients, dtype=float),
            np.ascontiguousarray(st1.dk_coefficients, dtype=float), float(cfg.l0),
            float(model.n), float(cfg.d_a), float(cfg.rho0),
            np.asarray(model.gravity, dtype=float) * 1.0)
        # the mass's CSR arrays and map into the chord pattern, per payload: the model's
        self._mass_cache = model.cached(("chord mass", self._key.tobytes()), lambda _: {})
        self._load_cache = {}
        self._mass_values = (None, None)
        self._hist = None   # the predictor's history (_history)
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
        # each element's 12 x 12 block, rows first (_kernels.chord_values)
        self._map_elem = where(np.repeat(ed, 12, axis=1).ravel(), np.tile(ed, (1, 12)).ravel())
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

    def _point_forces(self, load: TipLoad) -> np.ndarray:
        """The point forces of ``load`` in the kernels' form (kept per load)."""
        q_point = self._load_cache.get(load)
        if q_point is None:
            q_point = np.ascontiguousarray(self.model.point_forces(load), dtype=float)
            if len(self._load_cache) > 16:
                self._load_cache.clear()
            self._load_cache[load] = q_point
        return q_point

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
        c = gp / bp
        key = (float(st.load.payload_kg), c)
        if self._mass_values[0] != key:   # the mass's entries, per payload and step
            Mmap, Mdata = self._mass_arrays(key[0])[1]
            self._mass_values = (key, np.bincount(
                Mmap, Mdata * (1.0 + c * self.inertia.mass_damping), minlength=self._nnz))
        par = m.element_parameters(st.stretch)
        data = np.empty(self._nnz)
        kargs = m.kernel_args
        chord_values(ev.jacobian.data, self._map_static, self._static_rows, self._static_cols,
                     rs, cs, self._mass_values[1], st.q, Ti, par["le"], par["kt"], par["kb"],
                     *kargs[:5], self.inertia.damping_time * c, self._map_elem, data)
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

    def _history(self):
        """The predictor's history (:func:`run_steps`' ``hist``) of ``self.state``.

        Kept from step to step; a state set from outside (:meth:`start`, an
        assignment) starts without one (a constant predictor first).
        """
        hist = self._hist
        if hist is None or hist[0] is not self.state:
            m = self.model
            arrays = (np.zeros((2, m.nq)), np.zeros((2, m.nc)), np.zeros(2),
                      np.zeros(1, dtype=np.int64))
            hist = self._hist = (self.state, arrays)
        return hist[1]

    def _plan(self, t: float, ends: np.ndarray):
        """The steps from ``t`` through each time of ``ends`` in turn.

        Each span is cut into equal steps of about ``step_s`` (up to 10 %
        longer rather than one more step: a physics tick of one step's
        length, with its jitter, stays one step; a span that repeats repeats
        the step, and the factorisation made for it is reused); its last step
        lands on its end.  Returns ``(times, steps, last)``: each step's end
        time and length, and the index of the step that ends each span (-1:
        none yet, for a span that is not positive).
        """
        times, steps, last = [], [], []
        for end in ends.tolist():
            span = end - t
            if span > 0:
                n = max(1, math.ceil(span / self.step_s - 0.1))
                h = span / n
                for _ in range(n - 1):
                    t = t + h
                    times.append(t)
                    steps.append(h)
                h = end - t
                t = t + h
                times.append(t)
                steps.append(h)
            last.append(len(steps) - 1)
        return np.array(times), np.array(steps), np.array(last, dtype=np.int64)

    def _input_tables(self, times, stretch, pressures_pa, load):
        """Stretches (n, A), pressures (n, A or None) and loads at the steps' ends.

        ``loads``: one :class:`TipLoad` when constant, else one per step.
        """
        n, st, stage1 = len(times), self.state, self.model.stage1
        pres = None
        if callable(pressures_pa):
            if isinstance(pressures_pa, PressureRamp):   # all the steps' pressures at once
                pres = pressures_pa.table(times)
            else:
                pres = np.array([np.asarray(pressures_pa(t), dtype=float)
                                 for t in times.tolist()],
                                dtype=float).reshape(n, -1) if n else np.zeros((0, self.model.A))
            lams = np.asarray(stage1.stretch(pres.ravel()), dtype=float).reshape(n, self.model.A)
        else:
            if pressures_pa is not None:   # constant pressures: mapped once, kept
                p = np.asarray(pressures_pa, dtype=float)
                key = (p.shape, p.tobytes())
                kept = self._stretch_kept
                if kept is None or kept[0] is not stage1 or kept[1] != key:
                    kept = self._stretch_kept = (stage1, key,
                                                 np.array(stage1.stretch(p), dtype=float))
                lam = kept[2]
            elif stretch is not None and callable(stretch):
                lam = None
                lams = np.array([np.asarray(stretch(t), dtype=float) for t in times.tolist()],
                                dtype=float).reshape(n, self.model.A)
            else:
                lam = st.stretch if stretch is None else np.asarray(stretch, dtype=float)
            if lam is not None:
                lams = np.tile(np.asarray(lam, dtype=float).ravel(), (n, 1))
        if load is None:
            loads = st.load
        elif callable(load):
            loads = [as_tip_load(load(t)) for t in times.tolist()]
        else:
            loads = as_tip_load(load)
        return np.ascontiguousarray(lams), pres, loads

    def _state_after(self, k, times, lams, load) -> DynamicState:
        """The state after step ``k`` of a run: ``self._cur`` copied (``k < 0``: unchanged)."""
        if k < 0:
            return self.state
        block = self._cur_block.copy()   # (the new state's arrays: views of its own block)
        q, v, acc, aux, mu = (block[part] for part in self._cur_parts)
        return DynamicState(float(times[k]), q, v, acc, aux, mu, lams[k].copy(), load)

    def _run(self, times, steps, lams, load, stretch_at, load_at, rep, rec, deadline,
             depth=0) -> tuple[DynamicsStatus, int]:
        """Steps ``steps`` (ending at ``times``, stretches ``lams``) under one ``load``.

        Compiled (:func:`run_steps`); Python only factorises the chord matrix
        when the iterations ask for it, and halves a step that fails
        (:meth:`_step_halving`, down to ``max_halvings``).  ``rec``: the
        records of :func:`run_steps` (``(rec, out)``); ``deadline``: the
        ``perf_counter`` time after which no further step starts (looked at
        every :data:`BUDGET_STEPS` steps).  ``self.state`` ends at the last
        converged step; returns the status and the number of the steps done.
        """
        n = len(steps)
        payload = float(load.payload_kg)
        mass = self._mass_arrays(payload)[0]
        ia = self.inertia
        coef = (self.alpha_m, self.alpha_f, self.beta, self.gamma, ia.damping_time,
                ia.mass_damping)
        qpoint = self._point_forces(load)
        kargs = self.model.kernel_args
        ctl = (self._inv_scale, self.tol, self.max_iter)
        rec_in, out = rec
        k = 0
        while k < n:
            st = self.state
            cur = self._cur
            arrays = (st.q, st.v, st.acc, st.aux, st.mu)
            held = self._cur_of
            if held is None or held[0] is not st or any(
                    a is not b for a, b in zip(held[1], arrays)):
                for a, b in zip(cur, arrays):
                    a[:] = b
            self._cur_of = None   # run_steps moves cur on
            hist = self._history()
            resume = (True, 0, math.inf, False)
            first = k
            code = 0
            while k < n:
                if deadline is not None and resume[0] and time.perf_counter() > deadline:
                    code = -1
                    failed = DynamicsStatus.TIME_BUDGET
                    break
                stop = n if deadline is None else min(n, k + BUDGET_STEPS)
                if self._lu is not None and self._lu_key[1] != payload:
                    self._lu = None
                lu, lu_step = ((self._lu_dummy, 0.0) if self._lu is None
                               else (self._lu, self._lu_key[0]))
                before = k
                code, k, it, last, its = run_steps(
                    cur, self._nxt, hist, steps if stop == n else steps[:stop],
                    lams if stop == n else lams[:stop], k, resume, coef,
                    self._stage1_args, qpoint, kargs, mass, lu,
                    ctl + (lu_step, self._stale), self._work, rec_in, out)
                self.counters["iterations"] += its
                self.counters["steps"] += k - before
                if code == NEED_FACTOR:
                    at = DynamicState(float(times[k]), *self._nxt, lams[k], load)
                    try:
                        self._factor(at, float(steps[k]))
                    except DynamicsError as exc:
                        code = -1
                        failed = exc.status
                        break
                    resume = (False, it, last, True)
                    continue
                resume = (True, 0, math.inf, False)
                if code != 0:
                    break
            if k > first:
                st = self.state = self._state_after(k - 1, times, lams, load)
                self._hist = (st, hist)
                self._cur_of = (st, (st.q, st.v, st.acc, st.aux, st.mu))
            if code == -1:
                return failed, k
            if code == 5:
                return DynamicsStatus.NONFINITE, k
            if code == 0:
                return DynamicsStatus.COMPLETED, k
            # step k failed: two half steps instead (each halved again if it fails)
            self._lu = None
            if depth >= self.max_halvings:
                return DynamicsStatus.STEP_TOO_SMALL, k
            rep.halvings += 1
            for _ in range(2):
                status = self._step_halving(0.5 * float(steps[k]), stretch_at, load_at, rep,
                                            depth + 1)
                if status != DynamicsStatus.COMPLETED:
                    return status, k
            self._lu = None  # the next full step needs its own factorisation
            self.state.t = float(times[k])   # on the planned time (not a rounding off it)
            self._record(k, rec)
            k += 1
        return DynamicsStatus.COMPLETED, k

    def _step_halving(self, h, stretch_at, load_at, rep, depth) -> DynamicsStatus:
        """One step of length ``h`` from ``self.state`` (halved again if it fails)."""
        t = self.state.t + h
        lam = np.asarray(stretch_at(t), dtype=float).reshape(1, -1)
        return self._run(np.array([t]), np.array([h]), np.ascontiguousarray(lam),
                         as_tip_load(load_at(t)), stretch_at, load_at, rep, self._no_record,
                         None, depth)[0]

    def _record(self, k, rec):
        """:func:`run_steps`' record of step ``k`` for a step Python made (halved)."""
        (row, check, dofs), (out_q, out_checks) = rec
        if k < len(row) and row[k] >= 0:
            out_q[row[k]] = self.state.q[dofs]
            if check[k]:
                e, worst = self.checks()
                out_checks[row[k]] = (e["kinetic_j"], e["potential_j"], worst)

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
        return self._advance(np.array([float(t_end)]), stretch, load, pressures_pa,
                             time_budget_s, None)[0]

    def advance_through(self, ends, stretch=None, load=None, pressures_pa=None,
                        time_budget_s: float | None = None, check=None):
        """Integrate through each time of ``ends`` in turn, as :meth:`advance` to each would.

        One compiled run for all of them (:func:`run_steps`): a run sampled
        at every step costs no Python per step.  The inputs as
        :meth:`advance` takes them.  ``check``: per end, whether to compute
        the energy and the constraint violation there (:meth:`checks`).

        Returns ``(report, passage)``: the :class:`StepReport` and a
        :class:`Passage` of the ends reached.
        """
        check = np.zeros(np.size(ends), dtype=bool) if check is None else check
        return self._advance(np.asarray(ends, dtype=float).ravel(), stretch, load, pressures_pa,
                             time_budget_s, np.asarray(check, dtype=bool).ravel())

    def _advance(self, ends, stretch, load, pressures_pa, time_budget_s, check):
        """:meth:`advance_through`; ``check`` None: nothing recorded (:meth:`advance`)."""
        st = self.state
        if st is None:
            raise RuntimeError("call start(fw) first")
        rep = StepReport()
        t0 = time.perf_counter()
        counters = self.counters
        c0 = (counters["steps"], counters["iterations"], counters["factorizations"])
        times, steps, last = self._plan(st.t, ends)
        lams, pres, loads = self._input_tables(times, stretch, pressures_pa, load)
        n, n_ends = len(steps), len(ends)
        if check is None:
            (row, checked, dofs), out = self._no_record
            if len(row) < n:   # (kept: no allocation per call)
                row = np.full(max(n, 2 * len(row)), -1, dtype=np.int64)
                self._no_record = ((row, checked, dofs), out)
        else:
            dofs = np.ascontiguousarray(self.model.end_effector_dofs, dtype=np.int64)
            row = np.full(n, -1, dtype=np.int64)
            checked = np.zeros(n, dtype=np.bool_)
            own = last >= 0
            row[last[own]] = np.flatnonzero(own)
            checked[last[own]] = check[own]
            out = (np.full((n_ends, len(dofs)), np.nan), np.full((n_ends, 3), np.nan))

        def stretch_at(t):   # a halved step's input between the planned ones
            return self._input_tables(np.array([t]), stretch, pressures_pa, load)[0][0]

        def load_at(t):
            got = self._input_tables(np.array([t]), stretch, None, load)[2]
            return got[0] if isinstance(got, list) else got

        deadline = None if time_budget_s is None else t0 + time_budget_s
        status = DynamicsStatus.COMPLETED
        a = done = 0
        while a < n and status == DynamicsStatus.COMPLETED:   # runs of one load
            ld, b = loads, n
            if isinstance(loads, list):
                ld, b = loads[a], a + 1
                while b < n and loads[b] == ld:
                    b += 1
            status, k = self._run(times[a:b], steps[a:b], lams[a:b], ld, stretch_at, load_at,
                                  rep, ((row[a:b], checked[a:b] if check is not None else
                                         checked, dofs), out), deadline)
            done += k
            a = b
        rep.status = status
        rep.steps = counters["steps"] - c0[0]
        rep.iterations = counters["iterations"] - c0[1]
        rep.factorizations = counters["factorizations"] - c0[2]
        rep.wall_s = time.perf_counter() - t0
        rep.message = rep.status.message if rep.success else (
            f"{rep.status.message} at t = {self.state.t:.6g} s")
        if check is None:
            return rep, None
        reached = int(np.searchsorted(last, done - 1, side="right"))   # the ends reached
        plate = out[0][:reached]
        for j in range(reached):   # an end without a step of its own: the state before
            if last[j] < 0:
                plate[j] = st.q[dofs]
            elif row[last[j]] != j:
                plate[j] = out[0][row[last[j]]]
                out[1][j] = out[1][row[last[j]]]
        at = np.where(last[:reached] >= 0, times[np.maximum(last[:reached], 0)], st.t) \
            if n else np.full(reached, st.t)
        p_rows = None if pres is None else pres[np.maximum(last[:reached], 0)]
        return rep, Passage(at, plate, out[1][:reached], p_rows)

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
        inputs = (lam,) + self._stage1_args + (self._point_forces(load),)
        kin, pot, worst = state_checks(st.q, st.v, st.mu, inputs,
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
