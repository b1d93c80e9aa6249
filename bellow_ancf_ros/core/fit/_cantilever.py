"""A single actuator clamped horizontally: the test rig of paper section V.C.

The same ANCF elements as the robot (eqs. 5-8, 17, 18), gravity (eqs. 15,
16) and an end load (eq. 14); the clamp fixes the base point and makes the
base gradient parallel to the clamp axis ``+x`` with its length free, as at
every plate (docs/model.md section 3).  Gravity acts along ``-z``.  Used to
identify the cross-sectional diameter ``D_a`` (eq. 31) and to validate the
element against beam theory.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..model import Evaluation, element_forces, gravity_weights
from ..solve import continuation

__all__ = ["Cantilever", "CantileverResult"]


@dataclass
class CantileverResult:
    x: np.ndarray
    tip: np.ndarray
    converged: bool
    iterations: int
    message: str

    @property
    def tip_drop(self) -> float:
        """Downward displacement of the free end [m] (positive down)."""
        return float(-self.tip[2])


class Cantilever:
    """Horizontally clamped actuator of length ``length`` with ``n`` elements.

    Parameters: ``length`` [m], ``kt`` [N], ``kb`` [N m^2], linear density
    ``rho`` [kg/m] of the current configuration, ``tip_mass`` [kg], gravity
    ``g`` [m/s^2] (magnitude, acting along -z).
    """

    def __init__(self, length, kt, kb, rho, tip_mass=0.0, n=20, g=9.81):
        self.n = int(n)
        self.le = length / self.n
        self.kt, self.kb = float(kt), float(kb)
        self.nq = 6 * (self.n + 1)
        self.nc = 5
        self.N = self.nq + self.nc
        self.elem_dofs = 6 * np.arange(self.n)[:, None] + np.arange(12)[None, :]
        w, _ = gravity_weights(np.full(self.n, self.le))
        gvec = np.array([0.0, 0.0, -g])
        Q = np.zeros(self.nq)
        np.add.at(Q, self.elem_dofs.ravel(), (rho * w[:, :, None] * gvec).ravel())
        Q[self.nq - 6:self.nq - 3] += tip_mass * gvec
        self.Q = Q
        # constraints: r(0) = 0 (3), r_x(0).e_y = 0, r_x(0).e_z = 0
        Cq = np.zeros((5, self.nq))
        Cq[0:3, 0:3] = np.eye(3)
        Cq[3, 4] = 1.0
        Cq[4, 5] = 1.0
        self.Cq = Cq
        F = kb / length**2 + rho * g * length + tip_mass * g
        s = np.ones(self.N)
        node = np.ones((self.n + 1, 6))
        node[:, :3] = 1.0 / F
        node[:, 3:] = 1.0 / (F * length)
        s[: self.nq] = node.ravel()
        s[self.nq:self.nq + 3] = 1.0 / length
        self.scale = s
        self.scale_load = 1.0

    def straight(self):
        x = np.zeros(self.N)
        nodes = x[: self.nq].reshape(self.n + 1, 6)
        nodes[:, 0] = np.arange(self.n + 1) * self.le
        nodes[:, 3] = 1.0
        return x

    def evaluate(self, x, jacobian=True, load_scale=1.0):
        q, alpha = x[:self.nq], x[self.nq:]
        n = self.n
        qe = q[self.elem_dofs].reshape(n, 4, 3)
        le = np.full(n, self.le)
        ef = element_forces(qe, le, np.full(n, self.kt), np.full(n, self.kb),
                            stiffness=jacobian)
        fe = self.kt * ef["ft"] + self.kb * ef["fb"]
        R = np.bincount(self.elem_dofs.ravel(), weights=fe.ravel(), minlength=self.nq)
        R += self.Cq.T @ alpha - load_scale * self.Q
        res = np.concatenate([R, self.Cq @ q])
        ev = Evaluation(residual=res)
        if jacobian:
            K = np.zeros((self.nq, self.nq))
            idx = self.elem_dofs
            for e in range(n):
                K[np.ix_(idx[e], idx[e])] += ef["K"][e]
            J = np.zeros((self.N, self.N))
            J[: self.nq, : self.nq] = K
            J[:self.nq, self.nq:] = self.Cq.T
            J[self.nq:, :self.nq] = self.Cq
            ev.jacobian = sp.csc_matrix(J)
        return ev

    def solve(self, tol=1e-11, max_iter=30) -> CantileverResult:
        """Equilibrium under own weight and end load (continuation in the load)."""
        res = continuation(
            lambda t: (lambda x, jacobian=True: self.evaluate(x, jacobian, load_scale=t)),
            self.straight(), self.scale, tol=tol, max_iter=max_iter,
        )
        tip = res.x[self.nq - 6:self.nq - 3].copy()
        return CantileverResult(res.x, tip, res.converged, res.iterations, res.message)
