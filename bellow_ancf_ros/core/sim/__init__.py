"""The simulated robot: a robot that is not the model, with its hardware's effects (no ROS).

* :class:`SimulatedRobot`: a robot with its own robot file
  (:func:`simulated_robot_file`: ``<robot>_mismatched``, or the robot
  itself where none is shipped), quasi-static or
  swinging (its dynamics integrated), driven by pressure commands and seen
  through a motion capture, on the caller's time (wall clock or simulation
  time: the clock belongs to whoever steps it);
* :class:`PlantEffects`, :data:`EFFECTS`: the hardware's effects, switched
  one by one: regulators :class:`PressureRegulators` (dead time,
  hysteresis, play, lag), bellows creep :class:`BellowCreep`,
  :class:`MotionCapture` (rate, latency, noise, outliers, dropouts;
  :class:`MocapSample`);
* :func:`draw_robot`, :data:`FAMILY_RANGES`, :class:`RobotDraw`: a robot of
  the documented family (mode, damping, regulators, creep, motion capture,
  stiffness and geometry), what the loop's defaults are measured on;
  :func:`first_mode`: a robot's first mode at rest;
* :class:`SimulationClock`: when the simulation's next fixed step may be
  taken (paced by a real-time factor, in lockstep with a controller's
  commands, paused or stepped): the simulated robot's node as ``/clock``.

Nothing here knows the controller: :mod:`..loop` closes the two.
"""

from ._clock import CATCH_UP, SimulationClock
from ._motion_capture import MocapSample, MotionCapture
from ._plant_effects import EFFECTS, MIN_SAMPLES_PER_PERIOD, PlantEffects
from ._regulators import BellowCreep, PressureRegulators
from ._robot_family import FAMILY_RANGES, RobotDraw, draw_robot, first_mode
from ._simulated_robot import MISMATCHED, SimulatedRobot, simulated_robot_file

__all__ = [
    "BellowCreep", "CATCH_UP", "EFFECTS", "FAMILY_RANGES", "MISMATCHED", "MIN_SAMPLES_PER_PERIOD",
    "MocapSample",
    "MotionCapture", "PlantEffects", "PressureRegulators", "RobotDraw", "SimulatedRobot",
    "SimulationClock",
    "draw_robot", "first_mode", "simulated_robot_file",
]
