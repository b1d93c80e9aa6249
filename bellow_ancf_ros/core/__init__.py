"""Pure-Python core of the model (numpy/scipy only, no ROS imports).

Typical use::

    from bellow_ancf_ros.core import load_robot, RobotModel, solve_forward, solve_inverse
    model = RobotModel(load_robot("one_segment"))
    fw = solve_forward(model, [150e3, -50e3, -50e3], payload_kg=0.05)
    inv = solve_inverse(model, fw.position, payload_kg=0.05, warm_start=fw)
"""

from . import numba_cache  # noqa: F401  (first: where the compiled kernels are cached)
from .assembly import RobotModel
from .config import ConfigError, RobotConfig, SegmentConfig, load_robot, robot_from_dict
from .forward import ForwardResult, solve_forward
from .inverse import InverseResult, solve_inverse
from .stage1 import Stage1

__all__ = [
    "ConfigError", "ForwardResult", "InverseResult", "RobotConfig", "RobotModel", "SegmentConfig",
    "Stage1", "load_robot", "robot_from_dict", "solve_forward", "solve_inverse",
]
