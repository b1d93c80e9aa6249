"""The robot and its model (paper section III): robot files, stage 1, ANCF elements, assembly.

* :func:`load_robot`, :class:`RobotConfig`, :class:`SegmentConfig`,
  :class:`ConfigError`: the YAML robot file, validated (one-line errors
  naming the key);
* :mod:`.parameter_keys`: the robot's parameters by key (identification,
  calibration);
* :class:`Stage1`: the pressure <-> stretch map of an actuator (eqs. 10, 24);
* the ANCF beam element (eqs. 1-9) and its compiled residual and Jacobian
  kernel (eqs. 25, 27);
* :class:`RobotModel`: the discretised robot, its residual, Jacobians and
  read-outs, and the one per-model cache (:meth:`RobotModel.cached`);
* :class:`PccModel`, :func:`arc_state`: the piecewise-constant-curvature
  reference (cold starts, comparison study);
* :class:`TipLoad`, :func:`tip_load`: a payload and a force at the end
  effector (eq. 14), as the solvers take them.
"""

from . import parameter_keys
from ._ancf import (GAUSS_W, GAUSS_XI, element_energy, element_forces, gravity_weights, hermite,
                    shape_weights)
from ._assembly import Evaluation, RobotModel
from ._config import (FIRST_MODE_ERROR_RANGE, ConfigError, MocapFrame, RobotConfig,
                      SegmentConfig, check_element_count, config_dirs,
                      find_shipped, load_robot, plate_support_problem, robot_from_dict,
                      shipped_robot_names, smallest_element_count)
from ._kernels import element_parameters, evaluate_kernel, horner
from ._pcc import PccModel, PccPose, arc_parameters, arc_state, arc_transform
from ._stage1 import Stage1
from ._tip_load import MAX_TIP_FORCE_N, TipLoad, as_tip_load, tip_load

__all__ = [
    "FIRST_MODE_ERROR_RANGE", "ConfigError", "Evaluation", "MAX_TIP_FORCE_N", "MocapFrame",
    "TipLoad", "as_tip_load",
    "tip_load", "GAUSS_W", "GAUSS_XI", "PccModel", "PccPose",
    "RobotConfig", "RobotModel", "SegmentConfig", "Stage1", "arc_parameters", "arc_state",
    "arc_transform", "check_element_count", "config_dirs", "element_energy", "element_forces",
    "element_parameters", "evaluate_kernel", "find_shipped", "gravity_weights", "hermite",
    "horner", "load_robot", "parameter_keys", "plate_support_problem", "robot_from_dict",
    "shape_weights", "shipped_robot_names", "smallest_element_count",
]
