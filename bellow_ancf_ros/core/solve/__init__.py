"""The forward and inverse problems (paper section IV), their budgets and the stability test.

* :func:`solve_forward` -> :class:`ForwardResult`: pressures and payload ->
  equilibrium of eq. (25) (Newton with a chord phase and load continuation),
  stability of the equilibrium (reduced Hessian, proved by an LDL^T);
* :func:`solve_inverse` -> :class:`InverseResult`: target pose -> pressures
  (eqs. 28-30), warm-started along paths, cold from the PCC arcs, the
  best in-limit answer for unreachable targets, under a wall-clock and
  forward-solve budget;
* :func:`tip_compliance` -> :class:`TipCompliance`: the end effector's
  compliance and stiffness at an equilibrium (implicit-function theorem);
* :func:`payload_problem`: whether the robot can carry a payload at a
  target (or at pressures), before a controller is asked to;
* :func:`precompute_corners`, :func:`warm_up`: what a controller does once
  at start-up so that no solve of its loop compiles or searches corners;
* :func:`newton`, :func:`continuation`, :func:`deadline_after`,
  :func:`expired`: the Newton machinery other fits (the cantilever rig) use.

Statuses are :class:`~bellow_ancf_ros.core.status.ForwardStatus` and
:class:`~bellow_ancf_ros.core.status.InverseStatus`.
"""

from ._compliance import TipCompliance, tip_compliance
from ._forward import ForwardResult, ResumeState, assess_stability, check_pressures, solve_forward
from ._inverse import MAX_TARGET_LENGTHS, InverseResult, precompute_corners, solve_inverse
from ._inverse_limits import MAX_CORNERS
from ._loads import payload_problem
from ._newton import NewtonResult, ReducedHessian, continuation, deadline_after, expired, newton
from ._stability import StabilityCheck
from ._warmup import warm_up

__all__ = [
    "ForwardResult", "InverseResult", "MAX_CORNERS", "MAX_TARGET_LENGTHS", "NewtonResult",
    "ReducedHessian", "ResumeState", "StabilityCheck", "assess_stability", "check_pressures",
    "continuation", "deadline_after", "expired", "newton", "payload_problem", "precompute_corners",
    "solve_forward", "solve_inverse", "TipCompliance", "tip_compliance", "warm_up",
]
