"""Compile the solvers' kernels before a control loop needs them (above the solvers it runs).

Building a :class:`~bellow_ancf_ros.core.RobotModel` compiles (or loads
from the disk cache) the residual kernel and the factorisations.  The warm
inverse path has kernels of its own (the chord loop, the stretch step, the
pseudo-inverse), which only a warm-started inverse solve reaches: this
module runs one, so that the inverse node's configure and ``make venv``
compile them, not the first target of a control loop.
"""

from __future__ import annotations

import numpy as np

from ._forward import solve_forward
from ._inverse import solve_inverse

__all__ = ["warm_up"]


def warm_up(model, payload_kg=0.0):
    """Compile (or load from the disk cache) the kernels of the warm inverse; True when it ran.

    Three warm-started solves along 1 mm steps from the robot at mid
    pressure: the chord loop, the stretch step and the pseudo-inverse get
    compiled here (node configure, set-up), not at the first target of a
    control loop.  Once they are in the disk cache: 50-100 ms in a new process
    (loading them), under 10 ms after.
    """
    cfg = model.cfg
    fw = solve_forward(model, np.full(model.A, 0.5 * (cfg.p_min + cfg.p_max)), payload_kg)
    if not fw.success:
        return False
    z = fw.z_axis if cfg.n_segments > 1 else None
    prev = fw
    for k in range(3):
        prev = solve_inverse(model, fw.position + [1e-3 * k, 0.0, 0.0], z, payload_kg,
                             warm_start=prev)
    return bool(prev.success)
