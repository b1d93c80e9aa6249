"""Tip compliance and stiffness at an equilibrium (implicit-function theorem, eqs. 14, 25, 27).

At an equilibrium ``R(x, F) = 0`` of eq. (25) under a tip force ``F`` (a
dead load at the end effector, :class:`~bellow_ancf_ros.core.model.TipLoad`),
the change of the state with the force is ``dx/dF = -J^{-1} dR/dF`` with the
equilibrium's own Jacobian ``J`` (eq. 27, the KKT matrix of the constrained
potential); ``dR/dF = -B^T`` on the end plate's rows (``x_p = r + h d3``).
The end effector moves by ``dp = B dq`` and its z-axis by ``dd3``, so

* translational compliance ``C = dp/dF = B J^{-1} B^T`` [m/N]: symmetric
  (``J`` is), positive definite at a stable equilibrium (the reduced
  Hessian is);
* axis compliance ``dz/dF`` [1/N] (the z-axis turns, its length stays 1 to
  first order);
* stiffness ``K = C^{-1}`` [N/m]: the force that holds the tip displaced
  by a small ``dp`` with the pressures fixed.

Exact: no re-solve, one factorisation (the one the forward solve left, or a
new one at the equilibrium) and three solves.  ``[i][j]`` = d(output i) /
d(force j), base frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..linalg import kkt_solver
from ..model import TipLoad

__all__ = ["TipCompliance", "tip_compliance"]


@dataclass(frozen=True)
class TipCompliance:
    """The end effector's compliance and stiffness at an equilibrium (SI, base frame)."""

    translational_m_per_n: np.ndarray  # (3, 3) d position / d force
    axis_per_n: np.ndarray  # (3, 3) d z-axis / d force
    stiffness_n_per_m: np.ndarray  # (3, 3) inverse of the translational block

    @property
    def vertical_stiffness_n_per_m(self) -> float:
        """Vertical force per metre of vertical tip motion under a vertical force alone."""
        return float(1.0 / self.translational_m_per_n[2, 2])

    def to_dict(self) -> dict:
        """JSON-ready: nested 3x3 lists, ``[i][j]`` = d(output i)/d(force j)."""
        return {
            "translational_compliance_m_per_n": self.translational_m_per_n.tolist(),
            "axis_compliance_per_n": self.axis_per_n.tolist(),
            "stiffness_n_per_m": self.stiffness_n_per_m.tolist(),
        }


def tip_compliance(fw) -> TipCompliance:
    """Compliance of the end effector at the converged equilibrium ``fw`` (ForwardResult).

    Raises ValueError for an equilibrium that did not converge (there is no
    compliance to speak of).  At an unstable one the numbers are those of
    the equilibrium, not of a robot that stays there: check ``fw.success``.
    """
    if not fw.converged:
        raise ValueError(f"no compliance without a converged equilibrium ({fw.message})")
    model = fw.model
    load = fw.load
    if fw.jacobian is not None:
        lu = fw.lu
    else:
        ev = model.evaluate(fw.x, fw.stretch, 1.0, load, jacobian=True)
        lu = kkt_solver(model).bound(ev.jacobian)
    # dR/dF = -B^T on the coordinate rows, 0 on the constraint rows: the generalised force
    # of a unit force along each axis (model.point_forces, eq. 14), exact since Q is linear in F
    dR = np.zeros((model.N, 3))
    q0 = model.point_forces(load)
    for j in range(3):
        f = np.array(load.force_n, dtype=float)
        f[j] += 1.0
        dR[:model.nq, j] = q0 - model.point_forces(TipLoad(load.payload_kg, tuple(f)))
    dx = -lu.solve(dR)
    pd = model.plate_dofs[model.ee_plate]
    dd3 = dx[pd[9:12], :]
    dp = dx[pd[0:3], :] + model.cfg.tool_length * dd3
    return TipCompliance(translational_m_per_n=dp, axis_per_n=dd3,
                         stiffness_n_per_m=np.linalg.inv(dp))
