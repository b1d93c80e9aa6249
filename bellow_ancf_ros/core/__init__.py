"""The core library: the paper's model and its problems in numpy/scipy/numba, no ROS imports.

Typical use::

    from bellow_ancf_ros.core import load_robot, RobotModel, solve_forward, solve_inverse
    model = RobotModel(load_robot("one_segment"))
    fw = solve_forward(model, [150e3, -50e3, -50e3], payload_kg=0.05)
    inv = solve_inverse(model, fw.position, payload_kg=0.05, warm_start=fw)

This package's ``__all__`` is the public API: what the nodes, the CLI, the
demos, the benchmarks and users import.  The subpackages, in the order they
import each other (only downwards):

* :mod:`.status`, :mod:`.geometry`, :mod:`.history`: status codes; rotations and
  quaternions; time-stamped histories (leaves);
* :mod:`.linalg`: the KKT matrix's patterns and factorisations;
* :mod:`.model`: the robot file and the model (paper section III);
* :mod:`.solve`: forward and inverse problems, stability, budgets (section IV);
* :mod:`.experiments`: the paper's trajectories and studies (section VI);
* :mod:`.dynamics`: mass, damping, natural modes and time integration (the
  robot in motion, beyond the paper);
* :mod:`.sim`: the simulated robot and its hardware's effects (a robot that is
  not the model), beside :mod:`.control`: the control laws (feedback, targets,
  commands, watchdog, force estimate); neither imports the other;
* :mod:`.loop`: the two closed around each other (closing the loop without ROS);
* :mod:`.fit`: identification and calibration (section V).

Modules named ``_name.py`` are private: import their names from the
subpackage.
"""

from . import numba_cache  # noqa: F401  (first: where the compiled kernels are cached)
from . import (control, dynamics, experiments, fit, geometry, history, linalg, loop, model, sim,
               solve, status)
from .sim import PressureRegulators, SimulatedRobot
from .control import FEEDBACK_MODES, FeedbackSettings, IntegralFeedback
from .dynamics import GeneralizedAlpha, Inertia, ModalAnalysis, natural_modes
from .experiments import studies, trajectories
from .fit import (CalibrationError, CalibrationResult, Recording, RecordingError, calibrate,
                  calibration, identification, read_recording)
from .linalg import limit_blas_threads
from .model import (ConfigError, PccModel, RobotConfig, RobotModel, SegmentConfig, Stage1,
                    TipLoad, load_robot, parameter_keys, robot_from_dict)
from .solve import (ForwardResult, InverseResult, TipCompliance, payload_problem,
                    precompute_corners, solve_forward, solve_inverse, tip_compliance, warm_up)
from .status import DynamicsStatus, ForwardStatus, InverseStatus

__all__ = [
    "CalibrationError", "CalibrationResult", "ConfigError", "DynamicsStatus", "FEEDBACK_MODES",
    "GeneralizedAlpha", "Inertia", "ModalAnalysis", "dynamics", "natural_modes",
    "FeedbackSettings", "ForwardResult", "ForwardStatus", "IntegralFeedback", "InverseResult",
    "InverseStatus", "PccModel", "PressureRegulators", "Recording", "RecordingError",
    "RobotConfig", "RobotModel", "SegmentConfig", "SimulatedRobot", "Stage1", "TipCompliance",
    "TipLoad", "calibrate", "calibration", "control", "experiments", "fit", "geometry",
    "history", "identification", "limit_blas_threads", "linalg", "load_robot", "loop", "model",
    "numba_cache", "sim",
    "parameter_keys", "payload_problem", "precompute_corners", "read_recording",
    "robot_from_dict", "solve", "solve_forward", "solve_inverse", "status", "studies",
    "tip_compliance", "trajectories", "warm_up",
]
