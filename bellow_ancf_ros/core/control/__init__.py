"""Closing the loop without ROS: the feedback law and the simulated robot's physics.

* :class:`IntegralFeedback`, :class:`FeedbackSettings`: the measured-pose
  correction of the target (integral action, anti-windup, outlier gate,
  hold through dropouts, capture-time matching); :func:`loop_margins`: its
  stability margins with the loop's lag and delay and the robot's modes,
  :func:`safe_gain`: the largest gain that keeps the documented margins;
  :class:`ModeCheck`: those margins with the model's first mode at the held
  equilibrium, recomputed as it moves;
* :class:`SimulatedRobot`: a robot that is not the model (its own robot
  file), with the hardware's effects of :class:`PlantEffects` (regulators
  :class:`PressureRegulators` with dead time, hysteresis and lag; bellows
  creep :class:`BellowCreep`; :class:`MotionCapture` with noise, latency,
  outliers and dropouts);
* :class:`JumpTransition`: a jump of the target stream becomes a
  minimum-jerk move over two periods of the slowest mode the robot may have
  (``target_shaping: smooth``, the default; the closed loop holds through
  it); :class:`TargetShaper`, :func:`shaped`: ZV/ZVD input shaping of the
  target stream at the first mode (a step leaves no residual swing);
* :class:`DynamicFeedforward`, :func:`dynamic_path`,
  :class:`StreamFeedforward`: the target shifted by the inertial and damping
  loads of its motion through the first mode and the regulators' lag
  (dynamic feedforward of a planned path); :class:`TargetFilter`: both on a
  target stream, as the inverse node applies them;
* :class:`PlayCompensation`: commands at the edge of the regulators' play
  band (the backlash inverse); :class:`CreepCompensation`: commands that
  lead the bellows' creep (its inverse); :class:`CommandOutput`: both, what
  the regulators are sent for the pressures wanted;
* :class:`OscillationWatchdog`: a sustained or growing swing of the measured
  error near the first mode (:meth:`IntegralFeedback.watch`: the loop cuts
  its gain and holds its correction);
* :class:`LoopSimulation`: controller and simulated robot in simulated time
  (tests, benchmark); :func:`held_case`, :func:`circle_case`,
  :func:`step_case`: the closed loop's goals measured on it, at the inverse
  node's defaults (:func:`default_loop`);
* :func:`draw_robot`: a robot of the documented family
  (:data:`FAMILY_RANGES`: mode, damping, regulators, creep, motion capture,
  stiffness and geometry), what the loop's defaults are measured on;
* :class:`TipForceEstimator`, :class:`ForceEstimate`: the tip force (or an
  unknown payload) from measured poses and the applied pressures.
The ROS nodes only feed these.
"""

from ._feedback import FEEDBACK_MODES, FeedbackSettings, IntegralFeedback
from ._loop_margins import (MIN_GAIN_MARGIN, MIN_PHASE_MARGIN_DEG, LoopMargins, loop_delay_s,
                            loop_margins, safe_gain)
from ._dynamic_feedforward import DynamicFeedforward, StreamFeedforward, dynamic_path
from ._force_estimator import ESTIMATOR_MODES, ForceEstimate, TipForceEstimator
from ._loop_simulation import LoopRecord, LoopSimulation
from ._loop_cases import (LOOP_DELAY_S, LOOP_LAG_S, STEP_M, circle_case, default_loop,
                          held_case, paper_circle, step_case)
from ._mode_check import (AUTO_GAIN, GAIN_RANGE_PER_S, RETUNE_FRACTION, ModeCheck,
                          ModeCheckResult, gain_setting)
from ._motion_capture import MocapSample, MotionCapture
from ._plant_effects import EFFECTS, MIN_SAMPLES_PER_PERIOD, PlantEffects
from ._play import PlayCompensation
from ._command_output import CommandOutput, CreepCompensation
from ._regulators import BellowCreep, PressureRegulators
from ._robot_family import FAMILY_RANGES, RobotDraw, draw_robot, first_mode
from ._shaping import SHAPERS, TargetShaper, shaped, shaper_impulses
from ._simulated_robot import SimulatedRobot
from ._target_filter import TARGET_SHAPINGS, TargetFilter
from ._jumps import JumpTransition
from ._watchdog import OscillationWatchdog, WatchdogTrip

__all__ = [
    "EFFECTS", "ESTIMATOR_MODES", "FEEDBACK_MODES", "BellowCreep", "FeedbackSettings",
    "ForceEstimate", "IntegralFeedback", "LoopMargins", "LoopRecord", "LoopSimulation",
    "MIN_GAIN_MARGIN", "MIN_PHASE_MARGIN_DEG", "MIN_SAMPLES_PER_PERIOD", "MocapSample",
    "ModeCheck", "ModeCheckResult", "RETUNE_FRACTION", "AUTO_GAIN", "GAIN_RANGE_PER_S",
    "gain_setting",
    "MotionCapture", "PlantEffects", "PressureRegulators", "SHAPERS", "SimulatedRobot",
    "TargetShaper", "shaped", "shaper_impulses", "OscillationWatchdog", "WatchdogTrip",
    "TipForceEstimator", "loop_delay_s", "loop_margins", "safe_gain",
    "DynamicFeedforward", "StreamFeedforward", "dynamic_path", "TargetFilter",
    "PlayCompensation", "STEP_M", "circle_case", "default_loop", "held_case", "step_case",
    "LOOP_LAG_S", "LOOP_DELAY_S", "paper_circle",
    "FAMILY_RANGES", "RobotDraw", "draw_robot", "first_mode", "TARGET_SHAPINGS",
    "JumpTransition", "CommandOutput", "CreepCompensation",
]
