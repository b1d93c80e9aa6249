"""The paper's experiments (section VI) as studies of the model.

* :mod:`.trajectories`: the paper's trajectories (circle, lemniscate, ...)
  at its speed, scaled to a robot's workspace;
* :mod:`.studies`: element-count convergence, workspace schemes, PCC
  comparison and feedforward tracking studies.
"""

from . import studies, trajectories
from .studies import (ConvergenceResult, ConvergenceRow, Scheme, TrackResult, compare_pcc,
                      convergence_study, tracking_study, workspace_schemes, workspace_study)
from .trajectories import (TRAJECTORY_NAMES, lead_in, spin_down, spin_up, trajectory,
                           trajectory_parameters, trajectory_target)

__all__ = [
    "ConvergenceResult", "ConvergenceRow", "Scheme", "TRAJECTORY_NAMES", "TrackResult",
    "compare_pcc", "convergence_study", "lead_in", "spin_down", "spin_up", "studies",
    "trajectories",
    "trajectory",
    "trajectory_parameters", "trajectory_target", "tracking_study", "workspace_schemes",
    "workspace_study",
]
