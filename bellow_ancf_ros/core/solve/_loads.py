"""Whether the robot can carry a payload where it is asked to (the buckling check of a load).

A payload beyond what the robot can carry has no stable equilibrium near
the target: the load path of eq. (25) reaches a limit point, or the
equilibrium it converges to is unstable (the reduced Hessian of the
Lagrangian is not positive definite, paper section IV).  A controller asked
for such a payload would fail every solve; :func:`payload_problem` tells
beforehand, where the model can tell, so that a node can refuse the change.
"""

from __future__ import annotations

import math

import numpy as np

from ..status import ForwardStatus, InverseStatus
from ._forward import solve_forward
from ._inverse import solve_inverse

__all__ = ["payload_problem"]


def payload_problem(model, payload_kg, position=None, z_axis=None, pressures=None,
                    warm_start=None, time_budget_s=1.0) -> str:
    """Why the robot cannot carry ``payload_kg`` at the target (or the pressures), or ''.

    With a target ``position`` (and ``z_axis`` for two or more segments):
    the inverse is solved for it with the payload; an unstable answer (no
    stable equilibrium reaches the target: the robot would buckle) is a
    problem.  Without a target, the forward problem at ``pressures`` (the
    command in effect; default: vented) with the payload: an unstable
    equilibrium, or a limit point on the load path, is a problem.  '' when
    the robot carries the payload, and when the model cannot tell within
    ``time_budget_s`` (a budget status is no verdict).
    """
    m = float(payload_kg)
    if not (math.isfinite(m) and m >= 0):
        return f"payload_kg {payload_kg!r}: must be a finite mass >= 0 kg"
    if position is not None:
        inv = solve_inverse(model, position, z_axis, payload_kg=m, warm_start=warm_start,
                            time_budget_s=time_budget_s)
        if inv.status == InverseStatus.UNSTABLE:
            return (f"payload_kg {m:g}: the robot cannot carry it at the current target "
                    f"({inv.message})")
        return ""
    p = np.zeros(model.A) if pressures is None else np.asarray(pressures, dtype=float)
    p = np.clip(p, model.cfg.p_min, model.cfg.p_max)
    fw = solve_forward(model, p, payload_kg=m, time_budget_s=time_budget_s)
    if fw.status in (ForwardStatus.UNSTABLE, ForwardStatus.STEP_TOO_SMALL):
        return (f"payload_kg {m:g}: the robot cannot carry it at the current pressures "
                f"({fw.message})")
    return ""
