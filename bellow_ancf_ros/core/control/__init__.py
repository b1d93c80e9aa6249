"""Closing the loop without ROS: the feedback law and the simulated robot's physics.

* :class:`IntegralFeedback`, :class:`FeedbackSettings`: the measured-pose
  correction of the target (integral action, anti-windup, jump test);
* :class:`SimulatedRobot`, :class:`PressureRegulators`: a robot that is not
  the model (its own robot file), regulators with lag and slew, motion
  capture with noise;
* :class:`TipForceEstimator`, :class:`ForceEstimate`: the tip force (or an
  unknown payload) from measured poses and the applied pressures.
The ROS nodes only feed these.
"""

from ._feedback import FEEDBACK_MODES, FeedbackSettings, IntegralFeedback
from ._force_estimator import ESTIMATOR_MODES, ForceEstimate, TipForceEstimator
from ._simulated_robot import (DEFAULT_ANGLE_NOISE_RAD, DEFAULT_POSITION_NOISE_M,
                               DEFAULT_SLEW_RATE_PA_PER_S, DEFAULT_TIME_CONSTANT_S,
                               PressureRegulators, SimulatedRobot)

__all__ = [
    "DEFAULT_ANGLE_NOISE_RAD", "DEFAULT_POSITION_NOISE_M", "DEFAULT_SLEW_RATE_PA_PER_S",
    "DEFAULT_TIME_CONSTANT_S", "ESTIMATOR_MODES", "FEEDBACK_MODES", "FeedbackSettings",
    "ForceEstimate", "IntegralFeedback", "PressureRegulators", "SimulatedRobot",
    "TipForceEstimator",
]
