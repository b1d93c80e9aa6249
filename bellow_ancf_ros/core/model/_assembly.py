"""Robot assembly: degrees of freedom, rigid plates, constraints and loads.

This is stage 2 of the model (paper section III.C-E) for a chain of ``m``
segments with ``n_a`` actuators each:

* every actuator is a chain of ``n`` gradient-deficient ANCF elements of
  length ``le = lam*l0/n`` (eqs. 5-7, 19); elastic forces from
  :mod:`bellow_ancf_ros.core.model._ancf` (eqs. 17, 18), gravity of the actuators
  (eqs. 15, 16, linear density ``rho0/lam``) and point forces (eq. 14) are
  summed over elements (eqs. 20, 21);
* every plate except the fixed base plate is a rigid body with *natural
  coordinates* ``[p, d1, d2, d3]`` (its centre and its three frame axes,
  12 numbers) tied by six orthonormality constraints ``d_i.d_j = delta_ij``;
  the base plate of segment ``j+1`` is the top plate of segment ``j`` moved by
  the connector height ``h_c`` along its normal (paper eq. 23: same position,
  fixed angle between gradients);
* each actuator ``i`` is bonded to every plate of its segment at material
  fraction ``s_k``: its point ``r(s_k l)`` coincides with the plate point
  ``p + c_x d1 + c_y d2`` (3 equations) and its gradient is parallel to the
  plate normal, written as ``d1.r_x = 0`` and ``d2.r_x = 0`` (2 equations)
  (docs/model.md section 3).  Unlike the paper's squared parallel condition
  (eq. 22) these rows keep full rank at the solution, so Newton's method
  stays quadratic.

Everything in these constraints is linear or bilinear in the unknowns, which
keeps the constraint Hessian in the KKT Jacobian (eq. 27) exact and cheap.

Unknowns ``x = [q, alpha]``: actuator nodal coordinates (actuator by
actuator, node by node, ``[r, r_x]``), then plate coordinates, then the
Lagrange multipliers.  The residual is eq. (25)::

    R = [ dPi/dq + C_q^T alpha ;  C(q) ]

with the potential ``Pi = sum W_e - Q_g.q - Q_f.q``.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..geometry import rotation_z
from ..linalg import coordinates_envelope, kkt_solver
from . import _ancf as ancf, _kernels as kernels
from ._config import RobotConfig, check_element_count
from ._stage1 import Stage1
from ._tip_load import as_tip_load

__all__ = ["RobotModel", "Evaluation"]

_NODE_TOL = 1e-9
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


@dataclass
class Evaluation:
    """Residual (eq. 25) and, on request, its Jacobian (eq. 27) at one point."""

    residual: np.ndarray
    jacobian: sp.csc_matrix | None = None
    dres_dlam: np.ndarray | None = None  # (N, A) partial derivative w.r.t. stretches
    model: object = None  # the RobotModel whose KKT solver serves ``solve`` (core.linsolve)
    _lu: object = field(default=None, repr=False)  # the factorisation, made on first solve

    def solve(self, b):
        """Solve ``J x = b`` with the Jacobian (factorised once, then reused; core.linsolve).

        Raises ``numpy.linalg.LinAlgError`` when the Jacobian is singular.
        """
        if self.model is not None:
            if self._lu is None:
                self._lu = kkt_solver(self.model).bound(self.jacobian)
            return self._lu.solve(b)
        try:  # a Jacobian without the model's pattern (e.g. the cantilever rig)
            if self._lu is None:
                self._lu = spla.splu(sp.csc_matrix(self.jacobian), permc_spec="COLAMD")
            return self._lu.solve(b)
        except RuntimeError as exc:
            raise np.linalg.LinAlgError(str(exc)) from exc


class RobotModel:
    """Discretised robot: layout, residual, analytic Jacobians and read-outs.

    Parameters
    ----------
    cfg : RobotConfig
    n_elements : int, optional
        ANCF elements per actuator (default: ``cfg.n_elements``).  A count
        that cannot carry the plates is refused with a
        :class:`~bellow_ancf_ros.core.model._config.ConfigError` naming the smallest
        count that works (:func:`~bellow_ancf_ros.core.model._config.plate_support_problem`).
    """

    def __init__(self, cfg: RobotConfig, n_elements: int | None = None):
        n = int(cfg.n_elements if n_elements is None else n_elements)
        if n < 1:
            raise ValueError(f"n_elements must be >= 1, got {n}")
        check_element_count(cfg, n)  # ConfigError (a ValueError) naming model.n_elements
        self.cfg = cfg
        self.n = n
        self.stage1 = Stage1.from_config(cfg)
        self._derived = {}  # what solvers build once per model: see cached()
        self._build_layout()
        self._build_pattern()
        self._build_kernel_args()
        self._warm_up()

    def cached(self, key, make):
        """``make(self)``, built on first use and kept with this model (the one per-model cache).

        Patterns, factorisation plans and solutions the solvers reuse for
        one model live here, so they go when the model goes (a value may
        refer back to the model: the garbage collector frees the cycle).
        ``make`` returning None is not cached.
        """
        value = self._derived.get(key)
        if value is None:
            value = make(self)
            if value is not None:
                self._derived[key] = value
        return value

    def _warm_up(self):
        """Compile (or load from the disk cache) the kernels of a solve; build the patterns.

        Run when a model is built (node configure), so that no compilation
        and no pattern analysis happens inside a control loop: the residual
        and Jacobian kernel, both KKT factorisations with their one- and
        multi-column solves, and the stability test's factorisation.
        """
        x = self.straight_state(np.ones(self.A))
        ev = self.evaluate(x, np.ones(self.A), 1.0, 0.0, jacobian=True, lam_derivative=True)
        try:
            coordinates_envelope(self).positive_definite(
                ev.jacobian, np.ascontiguousarray(self.dof_scale, dtype=float), 10.0, 1e-10)
            f = kkt_solver(self).bound(ev.jacobian)
            f.solve(ev.residual)
            f.solve(np.column_stack([ev.residual, ev.dres_dlam]))  # the multi-column solve too
        except (np.linalg.LinAlgError, ValueError):  # e.g. one element per actuator: singular
            pass

    # ------------------------------------------------------------------ layout
    def _build_layout(self):
        cfg, n = self.cfg, self.n
        seg_of_act, ang = [], []
        for j, seg in enumerate(cfg.segments):
            for i in range(seg.n_actuators):
                seg_of_act.append(j)
                ang.append(seg.theta0 + 2.0 * np.pi * i / seg.n_actuators)
        self.A = A = len(seg_of_act)
        self.seg_of_act = np.array(seg_of_act)
        self.act_angle = np.array(ang)
        radius = np.array([cfg.segments[j].pitch_radius for j in seg_of_act])
        self.act_offset = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.zeros(A)],
                                   axis=1)

        self.n_nodes = n + 1
        self.nq_act = A * self.n_nodes * 6
        # element dofs: element e of actuator a uses nodes e, e+1 -> 12 contiguous dofs
        a_idx, e_idx = np.meshgrid(np.arange(A), np.arange(n), indexing="ij")
        self.elem_act = a_idx.ravel()
        start = (a_idx * self.n_nodes + e_idx).ravel() * 6
        self.elem_dofs = start[:, None] + np.arange(12)[None, :]  # (E, 12)
        self.E = A * n

        # plates: per segment, [base, intermediate..., top]; base of segment 0 is fixed
        plates = []  # dicts with segment, fraction, unknown index
        self.seg_plates = []
        n_unknown = 0
        for j, seg in enumerate(cfg.segments):
            rows = []
            for s in (0.0, *seg.plate_fractions, 1.0):
                if s == 0.0:
                    if j == 0:
                        ref = (-1, 0.0)  # fixed world frame
                    else:
                        ref = (plates[self.seg_plates[j - 1][-1]]["unknown"], seg.connector_height)
                    plates.append({"segment": j, "fraction": 0.0, "unknown": ref[0], "h": ref[1]})
                else:
                    plates.append({"segment": j, "fraction": s, "unknown": n_unknown, "h": 0.0})
                    n_unknown += 1
                rows.append(len(plates) - 1)
            self.seg_plates.append(rows)
        self.plates = plates
        self.P = n_unknown
        self.nq = self.nq_act + 12 * n_unknown
        self.plate_dofs = self.nq_act + 12 * np.arange(n_unknown)[:, None] + np.arange(12)[None, :]

        # attachments: actuator a at plate k of its segment
        g_act, g_elem, g_xi, g_frame, g_h = [], [], [], [], []
        for a in range(A):
            for k in self.seg_plates[self.seg_of_act[a]]:
                pl = plates[k]
                e, xi = self._locate(pl["fraction"])
                g_act.append(a)
                g_elem.append(a * n + e)
                g_xi.append(xi)
                g_frame.append(pl["unknown"])
                g_h.append(pl["h"])
        self.G = len(g_act)
        self.att_act = np.array(g_act)
        self.att_elem = np.array(g_elem)
        self.att_xi = np.array(g_xi)
        self.att_frame = np.array(g_frame)
        self.att_h = np.array(g_h)
        self.att_c = self.act_offset[self.att_act]
        self.att_free = self.att_frame >= 0
        self.nc = 5 * self.G + 6 * self.P
        self.N = self.nq + self.nc
        self.h_att = ancf.hermite(self.att_xi, 0)
        self.h1_att = ancf.hermite(self.att_xi, 1)

        # point masses in plate frames: (unknown plate, offset along d3, mass)
        masses = []
        for j, seg in enumerate(cfg.segments):
            rows = self.seg_plates[j]
            for k in rows[1:-1]:
                masses.append((plates[k]["unknown"], 0.0, seg.constraint_plate_mass))
            masses.append((plates[rows[-1]]["unknown"], 0.0, seg.top_plate_mass))
            if j > 0:
                prev_top = plates[self.seg_plates[j - 1][-1]]["unknown"]
                masses.append((prev_top, 0.5 * seg.connector_height, seg.connector_mass))
        self.point_masses = masses
        self.ee_plate = plates[self.seg_plates[-1][-1]]["unknown"]
        self.ee_theta = cfg.segments[-1].theta0
        self._ee_rot = rotation_z(self.ee_theta)
        self.gravity = np.asarray(cfg.gravity, dtype=float)
        self.length_scale = (sum(cfg.l0 for _ in cfg.segments)
                             + sum(s.connector_height for s in cfg.segments))
        self._build_scales()

    def _locate(self, s):
        """Element and local coordinate of material fraction ``s`` (eq. 6)."""
        n = self.n
        sn = s * n
        k = round(sn)
        if abs(sn - k) < _NODE_TOL:  # on a node
            return (k, 0.0) if k < n else (n - 1, 1.0)
        e = int(np.floor(sn))
        return e, sn - e

    def _build_scales(self):
        """Residual scaling so that tolerances are relative to the robot."""
        cfg = self.cfg
        L = self.length_scale
        k1 = self.stage1.k(1.0)
        kb = cfg.d_a**2 * cfg.l0 * k1 / 8.0
        weight = np.linalg.norm(self.gravity) * (
            cfg.rho0 * cfg.l0 * self.A + sum(m for _, _, m in self.point_masses)
        )
        self.force_scale = F = kb / cfg.l0**2 + weight
        s = np.empty(self.N)
        act = np.zeros((self.A, self.n_nodes, 6))
        act[..., :3] = 1.0 / F
        act[..., 3:] = 1.0 / (F * L)
        s[: self.nq_act] = act.ravel()
        pl = np.full((self.P, 12), 1.0 / (F * L))
        pl[:, :3] = 1.0 / F
        s[self.nq_act:self.nq] = pl.ravel()
        c = np.ones((self.G, 5))
        c[:, :3] = 1.0 / L
        s[self.nq:self.nq + 5 * self.G] = c.ravel()
        s[self.nq + 5 * self.G:] = 1.0
        self.residual_scale = s
        # coordinate scale: positions by the robot length, gradients/axes as they are
        pos = np.zeros((self.A, self.n_nodes, 6), bool)
        pos[..., :3] = True
        ppos = np.zeros((self.P, 12), bool)
        ppos[:, :3] = True
        self.position_dof = np.concatenate([pos.ravel(), ppos.ravel()])
        self.dof_scale = np.where(self.position_dof, L, 1.0)

    # --------------------------------------------------------- sparsity pattern
    def _build_pattern(self):
        """Fixed COO pattern of the KKT matrix and its map to CSC storage."""
        nq, G, P = self.nq, self.G, self.P
        free = self.att_free
        ed = self.elem_dofs
        aed = ed[self.att_elem].reshape(G, 4, 3)  # (G, 4, 3) element dofs at attachments
        fr = np.where(free, self.att_frame, 0)
        pdofs = self.plate_dofs[fr].reshape(G, 4, 3)  # [p, d1, d2, d3] dofs
        r0 = 5 * np.arange(G)
        rows, cols = [], []
        # (1) element stiffness
        rows.append(np.repeat(ed, 12, axis=1).ravel())
        cols.append(np.tile(ed, (1, 12)).ravel())
        # constraint Jacobian blocks, in the order kernels.evaluate_kernel produces their values
        crow, ccol = [], []
        xyz = np.arange(3)[None, None, :]
        crow.append(np.broadcast_to(r0[:, None, None] + xyz, (G, 4, 3)).ravel())
        ccol.append(aed.ravel())  # (a) position rows / element dofs
        crow.append(np.broadcast_to(r0[free, None, None] + xyz, (free.sum(), 4, 3)).ravel())
        ccol.append(pdofs[free].ravel())  # (b) position rows / frame dofs
        prow = r0[:, None] + 3 + np.arange(2)[None, :]  # (G, 2)
        crow.append(np.broadcast_to(prow[:, :, None, None], (G, 2, 4, 3)).ravel())
        # (c) parallel rows / element dofs
        ccol.append(np.broadcast_to(aed[:, None], (G, 2, 4, 3)).ravel())
        crow.append(np.broadcast_to(prow[free][:, :, None], (free.sum(), 2, 3)).ravel())
        ccol.append(pdofs[free][:, 1:3].ravel())  # (d) parallel rows / d1, d2
        orow = 5 * G + 6 * np.arange(P)[:, None] + np.arange(6)[None, :]  # (P, 6)
        pd = self.plate_dofs.reshape(P, 4, 3)
        oc = np.empty((P, 6, 2, 3), dtype=int)
        for m, (i, j) in enumerate(_PAIRS):
            oc[:, m, 0] = pd[:, 1 + i]
            oc[:, m, 1] = pd[:, 1 + j]
        crow.append(np.broadcast_to(orow[:, :, None, None], (P, 6, 2, 3)).ravel())
        ccol.append(oc.ravel())  # (e) orthonormality rows
        self._c_rows = np.concatenate(crow)
        self._c_cols = np.concatenate(ccol)
        rows += [nq + self._c_rows, self._c_cols]
        cols += [self._c_cols, nq + self._c_rows]
        # Hessian of alpha.C: (f) parallel rows, (g) orthonormality rows
        fe = np.broadcast_to(aed[free][:, None], (free.sum(), 2, 4, 3))
        fd = np.broadcast_to(pdofs[free][:, 1:3, None, :], (free.sum(), 2, 4, 3))
        rows += [fe.ravel(), fd.ravel()]
        cols += [fd.ravel(), fe.ravel()]
        rows += [oc[:, :, 0].ravel(), oc[:, :, 1].ravel()]
        cols += [oc[:, :, 1].ravel(), oc[:, :, 0].ravel()]
        rows = np.concatenate(rows)
        cols = np.concatenate(cols)
        key = cols * self.N + rows  # column-major order for CSC
        uniq, inv = np.unique(key, return_inverse=True)
        self._coo_map = inv
        self.nnz = len(uniq)
        self.csc_indices = (uniq % self.N).astype(np.int32)
        ucols = uniq // self.N
        self.csc_indptr = np.searchsorted(ucols, np.arange(self.N + 1)).astype(np.int32)
        # shared by every Jacobian: read-only, so that no in-place sparse operation can alter them
        self.csc_indices.flags.writeable = False
        self.csc_indptr.flags.writeable = False
        self._csc_template = sp.csc_matrix(
            (np.zeros(self.nnz), self.csc_indices, self.csc_indptr), shape=(self.N, self.N))
        self._aed = aed
        self._pdofs = pdofs

    def structural_nonzeros(self):
        """Mask of the CSC pattern's entries that can be non-zero (built once, cached).

        The pattern holds every element dof of an attachment's element; when
        the attachment sits on a node the other node's weights are exactly zero
        (``h(0) = [1, 0, 0, 0]``).  Two evaluations at random states with
        random multipliers mark the entries that are exactly zero in both.
        """
        mask = getattr(self, "_structural_nonzeros", None)
        if mask is None:
            rng = np.random.default_rng(12345)
            mask = np.zeros(self.nnz, bool)
            for _ in range(2):
                lam = rng.uniform(0.9, 1.1, self.A)
                x = self.straight_state(lam)
                x += 1e-2 * rng.standard_normal(self.N)
                mask |= self.evaluate(x, lam, 1.0, 0.1, jacobian=True).jacobian.data != 0.0
            self._structural_nonzeros = mask
        return mask

    # -------------------------------------------------------------- parameters
    def element_parameters(self, lam):
        """Per-actuator ``le, k_t, k_b`` and their derivatives w.r.t. ``lam`` (eqs. 2, 4)."""
        cfg = self.cfg
        lam = np.asarray(lam, dtype=float)
        key = lam.tobytes()
        cached = getattr(self, "_par_cache", None)
        if cached is not None and cached[0] == key:
            return cached[1]  # Newton iterations at fixed stretches ask again and again
        st = self.stage1
        le, kt, kb, dle, dkt, dkb = kernels.element_parameters(
            lam, st.k_coefficients, st.dk_coefficients, float(cfg.l0), float(self.n),
            float(cfg.d_a))
        for v in (le, kt, kb, dle, dkt, dkb):
            v.flags.writeable = False  # shared by the cache
        par = {"le": le, "kt": kt, "kb": kb, "dle": dle, "dkt": dkt, "dkb": dkb}
        self._par_cache = (key, par)
        return par

    # ------------------------------------------------------------------ loads
    def point_forces(self, payload=0.0):
        """Generalised point forces (eq. 14) at full gravity: plates, connectors, tip load.

        ``payload`` is a mass [kg] or a :class:`~._tip_load.TipLoad` (a mass
        and a force at the end effector, ``Q = B^T F``, module ``_tip_load``).
        """
        load = as_tip_load(payload)
        Q = self.q_masses
        if load.payload_kg:
            Q = Q + load.payload_kg * self.q_payload
        if load.has_force:
            Q = Q.copy()
            F = np.asarray(load.force_n, dtype=float)
            Q[self.plate_dofs[self.ee_plate, 0:3]] += F
            Q[self.plate_dofs[self.ee_plate, 9:12]] += self.cfg.tool_length * F
        return Q

    def external_forces(self, lam, load_scale=1.0, payload=0.0):
        """Generalised gravity (eq. 16) and point forces (eq. 14), and their lam-derivative.

        ``payload``: a mass [kg] or a :class:`~._tip_load.TipLoad`.  Returns
        ``(Q, dQ_dlam)`` with ``Q`` of length ``nq`` and ``dQ_dlam`` of shape
        ``(nq, A)``; the tip force is scaled by ``load_scale`` like gravity.
        """
        cfg = self.cfg
        lam = np.asarray(lam, dtype=float)
        g = self.gravity * load_scale
        par = self.element_parameters(lam)
        Q = np.zeros(self.nq)
        dQ = np.zeros((self.nq, self.A))
        le_e = par["le"][self.elem_act]
        rho_e = cfg.rho0 / lam[self.elem_act]
        w, dw = ancf.gravity_weights(le_e)  # (E, 4)
        qg = (rho_e[:, None] * w)[:, :, None] * g[None, None, :]
        np.add.at(Q, self.elem_dofs.ravel(), qg.ravel())
        dwl = ((-rho_e / lam[self.elem_act])[:, None] * w
               + (rho_e * par["dle"][self.elem_act])[:, None] * dw)
        dqg = (dwl[:, :, None] * g[None, None, :]).reshape(self.E, 12)
        np.add.at(dQ, (self.elem_dofs.ravel(), np.repeat(self.elem_act, 12)), dqg.ravel())
        Q += load_scale * self.point_forces(payload)
        return Q, dQ

    # ------------------------------------------------------------- evaluation
    def _build_kernel_args(self):
        """Static arrays of the compiled evaluation kernel and the unit point forces (eq. 14)."""
        i64 = np.int64
        self.kernel_args = (
            self.elem_dofs.astype(i64), self.elem_act.astype(i64), np.ascontiguousarray(ancf._H1),
            np.ascontiguousarray(ancf._H2), np.ascontiguousarray(ancf.GAUSS_W),
            self._aed.astype(i64), self._pdofs.astype(i64), self.att_act.astype(i64),
            self.att_free.copy(), np.ascontiguousarray(self.att_c, dtype=float),
            self.att_h.astype(float), np.ascontiguousarray(self.h_att),
            np.ascontiguousarray(self.h1_att),
            self.plate_dofs.astype(i64), self._c_rows.astype(i64), self._c_cols.astype(i64),
            self._coo_map.astype(i64), int(self.nnz),
        )
        Qm = np.zeros(self.nq)  # plate, connector masses per unit gravity
        for u, h, m in self.point_masses:
            Qm[self.plate_dofs[u, 0:3]] += m * self.gravity
            Qm[self.plate_dofs[u, 9:12]] += h * m * self.gravity
        Qp = np.zeros(self.nq)  # payload of 1 kg per unit gravity
        Qp[self.plate_dofs[self.ee_plate, 0:3]] += self.gravity
        Qp[self.plate_dofs[self.ee_plate, 9:12]] += self.cfg.tool_length * self.gravity
        self.q_masses, self.q_payload = Qm, Qp

    def evaluate(self, x, lam, load_scale=1.0, payload=0.0, jacobian=True, lam_derivative=False):
        """Residual of eq. (25) at ``x = [q, alpha]``; Jacobian eq. (27); ``dR/dlam`` (eq. 30).

        ``payload``: a mass [kg] or a :class:`~._tip_load.TipLoad` (:meth:`point_forces`).

        Computed by the compiled kernel :func:`core.model._kernels.evaluate_kernel`; the
        Jacobian's values go straight into the fixed CSC pattern.
        """
        nq = self.nq
        x = np.ascontiguousarray(x, dtype=float)
        lam = np.ascontiguousarray(lam, dtype=float)
        par = self.element_parameters(lam)
        g = self.gravity * load_scale
        Qpoint = load_scale * self.point_forces(payload)
        res, data, d = kernels.evaluate_kernel(
            x[:nq], x[nq:], lam, par["le"], par["kt"], par["kb"],
            par["dle"], par["dkt"], par["dkb"],
            float(self.cfg.rho0), g, Qpoint, *self.kernel_args, bool(jacobian),
            bool(lam_derivative))
        ev = Evaluation(residual=res)
        if jacobian:
            # a shallow copy of the pattern's matrix with these values: the same matrix as
            # csc_matrix((data, indices, indptr)) sharing the read-only pattern, without its checks
            ev.jacobian = copy.copy(self._csc_template)
            ev.jacobian.data = data
            ev.model = self
        if lam_derivative:
            ev.dres_dlam = d
        return ev

    def potential(self, q, lam, load_scale=1.0, payload=0.0):
        """Total potential ``Pi = sum W_e - Q.q`` (eqs. 15, 17): used by tests."""
        par = self.element_parameters(lam)
        ea = self.elem_act
        qe = q[self.elem_dofs].reshape(self.E, 4, 3)
        W = ancf.element_energy(qe, par["le"][ea], par["kt"][ea], par["kb"][ea]).sum()
        Q, _ = self.external_forces(lam, load_scale, payload)
        return W - Q @ q

    # ------------------------------------------------------------ states
    def straight_state(self, lam):
        """Straight configuration with each segment at its mean stretch.

        All constraints hold exactly; with ``lam = 1`` and no load it is the
        exact equilibrium (alpha = 0).  Used as the cold start.
        """
        lam = np.asarray(lam, dtype=float)
        q = np.zeros(self.nq)
        act = q[: self.nq_act].reshape(self.A, self.n_nodes, 6)
        pl = q[self.nq_act:].reshape(self.P, 12)
        z0 = 0.0
        frac = np.arange(self.n_nodes) / self.n
        for j, seg in enumerate(self.cfg.segments):
            if j > 0:
                z0 += seg.connector_height
            acts = np.flatnonzero(self.seg_of_act == j)
            Lseg = lam[acts].mean() * self.cfg.l0
            for a in acts:
                act[a, :, 0:2] = self.act_offset[a, :2]
                act[a, :, 2] = z0 + frac * Lseg
                act[a, :, 5] = Lseg / (lam[a] * self.cfg.l0)
            for k in self.seg_plates[j]:
                u = self.plates[k]["unknown"]
                if self.plates[k]["fraction"] > 0:
                    pl[u, 2] = z0 + self.plates[k]["fraction"] * Lseg
                    pl[u, 3:] = np.eye(3).ravel()
            z0 += Lseg
        return np.concatenate([q, np.zeros(self.nc)])

    # ------------------------------------------------------------ read-outs
    def plate_frame(self, q, u):
        """Centre and rotation matrix (columns d1, d2, d3) of unknown plate ``u``."""
        c = q[self.plate_dofs[u]]
        return c[:3].copy(), c[3:].reshape(3, 3).T.copy()

    def end_effector(self, q):
        """End-effector position and rotation (docs/model.md section 1)."""
        p, D = self.plate_frame(q, self.ee_plate)
        return p + self.cfg.tool_length * D[:, 2], D @ self._ee_rot

    @property
    def end_effector_dofs(self) -> np.ndarray:
        """The end plate's 12 coordinates (centre, then d1, d2, d3) in ``q``."""
        return self.plate_dofs[self.ee_plate]

    def end_effectors(self, c):
        """:meth:`end_effector` of many states at once: positions (n, 3), rotations (n, 3, 3).

        ``c`` (n, 12): each state's ``q[end_effector_dofs]``.
        """
        c = np.asarray(c, dtype=float).reshape(-1, 12)
        D = c[:, 3:].reshape(-1, 3, 3).transpose(0, 2, 1)
        return c[:, :3] + self.cfg.tool_length * D[:, :, 2], D @ self._ee_rot

    def plate_poses(self, q):
        """List of ``(segment, fraction, position, rotation)`` for every plate, base first."""
        out = []
        for pl in self.plates:
            u, h = pl["unknown"], pl["h"]
            if u < 0:
                p, D = np.zeros(3), np.eye(3)
            else:
                p, D = self.plate_frame(q, u)
                p = p + h * D[:, 2]
            out.append((pl["segment"], pl["fraction"], p, D))
        return out

    def backbones(self, q, lam, n_points=20):
        """Actuator centre lines sampled at ``n_points`` equally spaced material points.

        Returns an array ``(A, n_points, 3)`` (eq. 6).
        """
        n_points = int(n_points)
        if n_points < 2:
            raise ValueError("n_points must be >= 2")
        s = np.linspace(0.0, 1.0, n_points) * self.n
        e = np.minimum(np.floor(s).astype(int), self.n - 1)
        xi = s - e
        h = ancf.hermite(xi, 0)  # (n_points, 4)
        le = self.element_parameters(lam)["le"]
        out = np.empty((self.A, n_points, 3))
        for a in range(self.A):
            qe = q[self.elem_dofs[a * self.n + e]].reshape(n_points, 4, 3)
            w = h * np.array([1.0, le[a], 1.0, le[a]])
            out[a] = np.einsum("pa,pai->pi", w, qe)
        return out
