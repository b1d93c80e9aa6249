"""Mass and damping of the robot in material coordinates (docs/dynamics.md; paper eqs. 5-7, 17).

The static model (paper section III) works in *stretched* coordinates: an
actuator of stretch ``lam`` is a curve ``r(x)``, ``x in [0, lam l0]``, with
nodal coordinates ``[r, r_x]``.  Its dynamics lives on the *material* line
``X in [0, l0]`` instead: ``x = lam X``, so the nodal slopes are
``r_X = lam r_x`` and every other coordinate (nodal positions, plate natural
coordinates ``[p, d1, d2, d3]``) is the same.  The map is diagonal::

    q_mat = T(lam) q_static,   T = diag(1 on positions and plates, lam_a on slopes of actuator a)

In material coordinates

* the **mass matrix** is constant: per element the consistent ANCF mass
  ``M_e = rho0 int_0^{l0/n} S^T S dX`` (eqs. 6, 7 with the material element
  length), the same mass ``rho0 l0`` per actuator that the static gravity
  carries as ``rho0/lam`` per stretched length (eq. 15); plates are thin
  uniform discs of radius ``r_p`` moving with their frames
  ``r = p + a1 d1 + a2 d2`` (``int a1^2 dm = int a2^2 dm = m r_p^2/4``), so
  a disc adds ``m`` on ``p`` and ``m r_p^2/4`` on ``d1`` and ``d2``; the
  connectors and the payload are points ``r = p + h d3`` of their plate
  frames (``m [I, h I; h I, h^2 I]`` on ``(p, d3)``);
* a **pressure change** moves the stress-free length (stage 1, eq. 10), not
  the material: ``r(X, t)`` stays continuous while ``lam`` jumps;
* **Kelvin-Voigt damping** of the actuator strains with one retardation time
  ``beta``: the dissipation function
  ``D = beta/2 int (k_t epsdot^2 + k_b |r_xx dot|^2) dx`` (the strain rates of
  eq. 17 at fixed ``lam``) gives the damping force ``beta K_m(q) qdot`` with
  ``K_m`` the material part of the elastic tangent (no geometric term, no
  gravity); optional mass-proportional (air) damping ``alpha M qdot``.

A mode of angular frequency ``w`` whose energy is mostly bending then has a
damping ratio of about ``beta w / 2``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..model import GAUSS_W, GAUSS_XI, RobotModel, as_tip_load, hermite

__all__ = ["Inertia"]

_H0 = hermite(GAUSS_XI, 0)  # (G, 4)
_H1 = hermite(GAUSS_XI, 1)
_H2 = hermite(GAUSS_XI, 2)


class Inertia:
    """Mass matrix, coordinate map and damping of one :class:`RobotModel`.

    Parameters
    ----------
    model : RobotModel
    damping_time_s : Kelvin-Voigt retardation time ``beta`` [s] (default: the
        robot file's ``dynamics.damping_time_s``).
    mass_damping_per_s : mass-proportional damping ``alpha`` [1/s] (default:
        the robot file's ``dynamics.mass_damping_per_s``).
    """

    def __init__(self, model: RobotModel, damping_time_s: float | None = None,
                 mass_damping_per_s: float | None = None):
        cfg = model.cfg
        self.model = model
        self.damping_time = float(cfg.damping_time if damping_time_s is None else damping_time_s)
        self.mass_damping = float(cfg.mass_damping if mass_damping_per_s is None
                                  else mass_damping_per_s)
        for name, v in (("damping_time_s", self.damping_time),
                        ("mass_damping_per_s", self.mass_damping)):
            if not (np.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} = {v!r} is not allowed; allowed: a finite number >= 0")
        n = model.n
        # slope dofs of the actuators (material slope = lam * static slope)
        act = np.zeros((model.A, model.n_nodes, 6), dtype=int)
        act[...] = np.arange(model.A)[:, None, None]
        slope = np.zeros((model.A, model.n_nodes, 6), bool)
        slope[..., 3:] = True
        self.slope_dof = np.concatenate([slope.ravel(), np.zeros(12 * model.P, bool)])
        self.slope_act = np.concatenate([act.ravel(), np.zeros(12 * model.P, int)])
        # element mass in material coordinates, (4, 4) scalar blocks of the 12 x 12 matrix
        L = cfg.l0 / n
        f = np.array([1.0, L, 1.0, L])
        w = _H0 * f  # (G, 4)
        em = cfg.rho0 * L * np.einsum("g,ga,gb->ab", GAUSS_W, w, w)
        self.element_mass = 0.5 * (em + em.T)  # exactly symmetric
        rows, cols, vals = [], [], []
        blk = np.kron(self.element_mass, np.eye(3))  # (12, 12)
        ed = model.elem_dofs
        rows.append(np.repeat(ed, 12, axis=1).ravel())
        cols.append(np.tile(ed, (1, 12)).ravel())
        vals.append(np.tile(blk.ravel(), model.E))
        # plates as thin discs, connectors as points
        radii = [cfg.plate_radius_of(j) for j in range(cfg.n_segments)]
        pd = model.plate_dofs
        eye = np.arange(3)

        def add(u, a, b, value):  # value * I3 on the (a, b) 3-blocks of plate u (0=p, 1..3=d)
            rows.append(pd[u, 3 * a + eye])
            cols.append(pd[u, 3 * b + eye])
            vals.append(np.full(3, float(value)))

        self._add = add
        for j, seg in enumerate(cfg.segments):
            plist = model.seg_plates[j]
            for k in plist[1:]:
                u = model.plates[k]["unknown"]
                m = seg.top_plate_mass if k == plist[-1] else seg.constraint_plate_mass
                add(u, 0, 0, m)
                add(u, 1, 1, m * radii[j] ** 2 / 4.0)
                add(u, 2, 2, m * radii[j] ** 2 / 4.0)
            if j > 0:
                u = model.plates[model.seg_plates[j - 1][-1]]["unknown"]
                self._point(add, u, 0.5 * seg.connector_height, seg.connector_mass)
        self._base = (np.concatenate(rows), np.concatenate(cols), np.concatenate(vals))
        # the mass matrices are the model's (the damping settings do not enter them): kept
        # with it, so a new integrator of the same robot does not assemble them again
        self._mass_cache = model.cached(("mass matrices",), lambda _: {})

    @staticmethod
    def _point(add, u, h, m):
        add(u, 0, 0, m)
        add(u, 0, 3, m * h)
        add(u, 3, 0, m * h)
        add(u, 3, 3, m * h * h)

    # ---------------------------------------------------------------- mass
    def mass_matrix(self, payload=0.0) -> sp.csc_matrix:
        """The constant mass matrix in material coordinates (``nq x nq``, sparse).

        ``payload``: a mass [kg] or a :class:`~bellow_ancf_ros.core.model.TipLoad`
        (its mass is a point at the end effector; its force has no mass).
        """
        m_p = float(as_tip_load(payload).payload_kg)
        M = self._mass_cache.get(m_p)
        if M is None:
            r, c, v = self._base
            if m_p:
                extra = []
                self._point(lambda u, a, b, val: extra.append(
                    (self.model.plate_dofs[u, 3 * a + np.arange(3)],
                     self.model.plate_dofs[u, 3 * b + np.arange(3)], np.full(3, val))),
                    self.model.ee_plate, self.model.cfg.tool_length, m_p)
                r = np.concatenate([r] + [e[0] for e in extra])
                c = np.concatenate([c] + [e[1] for e in extra])
                v = np.concatenate([v] + [e[2] for e in extra])
            nq = self.model.nq
            M = sp.csc_matrix((v, (r, c)), shape=(nq, nq))
            M.sum_duplicates()
            if len(self._mass_cache) > 16:
                self._mass_cache.clear()
            self._mass_cache[m_p] = M
        return M

    def mass_matrix_csr(self, payload=0.0) -> sp.csr_matrix:
        """:meth:`mass_matrix` in CSR storage (kept: the integrator's products)."""
        m_p = float(as_tip_load(payload).payload_kg)
        key = ("csr", m_p)
        M = self._mass_cache.get(key)
        if M is None:
            M = self.mass_matrix(m_p).tocsr()
            M.sort_indices()
            self._mass_cache[key] = M
        return M

    # ---------------------------------------------------------- coordinates
    def scale(self, lam) -> np.ndarray:
        """Diagonal of ``T(lam)``: ``q_mat = T q_static`` (1 on positions and plates)."""
        lam = np.asarray(lam, dtype=float)
        return np.where(self.slope_dof, lam[self.slope_act], 1.0)

    def to_material(self, q_static, lam) -> np.ndarray:
        """Static (stretched) nodal coordinates -> material coordinates."""
        return self.scale(lam) * np.asarray(q_static, dtype=float)

    def to_static(self, q_mat, lam) -> np.ndarray:
        """Material coordinates -> static (stretched) nodal coordinates for stretch ``lam``."""
        return np.asarray(q_mat, dtype=float) / self.scale(lam)

    # -------------------------------------------------------------- damping
    def _gauss(self, q_static, lam):
        m = self.model
        par = m.element_parameters(lam)
        ea = m.elem_act
        le, kt, kb = par["le"][ea], par["kt"][ea], par["kb"][ea]
        f1 = np.stack([1.0 / le, np.ones_like(le), 1.0 / le, np.ones_like(le)], axis=1)
        f2 = np.stack([le**-2, 1.0 / le, le**-2, 1.0 / le], axis=1)
        Nx = _H1[None] * f1[:, None, :]  # (E, G, 4)
        Nxx = _H2[None] * f2[:, None, :]
        qe = q_static[m.elem_dofs].reshape(m.E, 4, 3)
        rx = Nx @ qe  # (E, G, 3)
        w = GAUSS_W[None, :] * le[:, None]
        return Nx, Nxx, rx, w * kt[:, None], w * kb[:, None]

    def dissipation(self, q_mat, v_mat, lam) -> float:
        """Rayleigh dissipation function ``D(q, qdot)`` (Kelvin-Voigt plus air), material."""
        m = self.model
        s = self.scale(lam)
        qs, us = q_mat / s, v_mat / s
        Nx, Nxx, rx, wt, wb = self._gauss(qs, lam)
        ue = us[m.elem_dofs].reshape(m.E, 4, 3)
        epsdot = (rx * (Nx @ ue)).sum(-1)
        kdot = Nxx @ ue
        kv = 0.5 * self.damping_time * ((wt * epsdot**2).sum() + (wb * (kdot**2).sum(-1)).sum())
        air = 0.5 * self.mass_damping * v_mat @ (self.mass_matrix() @ v_mat)
        return float(kv + air)

    def damping_force(self, q_mat, v_mat, lam, payload=0.0) -> np.ndarray:
        """``dD/dqdot``: ``beta T^-1 K_m(q) T^-1 qdot + alpha M qdot`` (material coordinates)."""
        m = self.model
        s = self.scale(lam)
        qs, us = q_mat / s, v_mat / s
        out = np.zeros(m.nq)
        if self.damping_time:
            Nx, Nxx, rx, wt, wb = self._gauss(qs, lam)
            ue = us[m.elem_dofs].reshape(m.E, 4, 3)
            epsdot = (rx * (Nx @ ue)).sum(-1)  # (E, G)
            ft = (Nx * (wt * epsdot)[:, :, None]).transpose(0, 2, 1) @ rx  # (E, 4, 3)
            fb = (Nxx * wb[:, :, None]).transpose(0, 2, 1) @ (Nxx @ ue)
            np.add.at(out, m.elem_dofs.ravel(), self.damping_time * (ft + fb).ravel())
            out /= s
        if self.mass_damping:
            out += self.mass_damping * (self.mass_matrix(payload) @ v_mat)
        return out

    def damping_blocks(self, q_mat, lam) -> np.ndarray:
        """Element blocks ``(E, 12, 12)`` of ``beta K_m`` in *static* coordinates."""
        m = self.model
        qs = q_mat / self.scale(lam)
        Nx, Nxx, rx, wt, wb = self._gauss(qs, lam)
        E = m.E
        B = (Nx[:, :, :, None] * rx[:, :, None, :]).reshape(E, -1, 12)
        K = (B * wt[:, :, None]).transpose(0, 2, 1) @ B
        S = (Nxx * wb[:, :, None]).transpose(0, 2, 1) @ Nxx  # (E, 4, 4)
        K = K.reshape(E, 4, 3, 4, 3)
        for i in range(3):
            K[:, :, i, :, i] += S
        return self.damping_time * K.reshape(E, 12, 12)

    def damping_matrix(self, q_mat, lam, payload=0.0) -> sp.csc_matrix:
        """Damping matrix ``dD/dqdot dqdot`` in material coordinates (sparse, symmetric)."""
        m = self.model
        blocks = self.damping_blocks(q_mat, lam)
        ed = m.elem_dofs
        Ks = sp.csc_matrix((blocks.ravel(), (np.repeat(ed, 12, axis=1).ravel(),
                                             np.tile(ed, (1, 12)).ravel())), shape=(m.nq, m.nq))
        Ti = sp.diags(1.0 / self.scale(lam))
        D = (Ti @ Ks @ Ti).tocsc()
        if self.mass_damping:
            D = D + self.mass_damping * self.mass_matrix(payload)
        return D.tocsc()

    # --------------------------------------------------------------- checks
    def kinetic_energy(self, v_mat, payload=0.0) -> float:
        """``1/2 qdot^T M qdot``."""
        return 0.5 * float(v_mat @ (self.mass_matrix(payload) @ v_mat))

    def total_mass(self, payload=0.0) -> float:
        """Moving mass of the robot [kg]: actuators, plates, connectors, payload."""
        cfg = self.model.cfg
        m = cfg.rho0 * cfg.l0 * self.model.A + float(as_tip_load(payload).payload_kg)
        for j, seg in enumerate(cfg.segments):
            m += seg.top_plate_mass + len(seg.plate_fractions) * seg.constraint_plate_mass
            if j > 0:
                m += seg.connector_mass
        return m
