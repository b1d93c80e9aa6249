"""The control laws (no ROS): feedback, targets, commands, the watchdog, the force estimate.

* :class:`IntegralFeedback`, :class:`FeedbackSettings`: the measured-pose
  correction of the target (integral action, anti-windup, outlier gate,
  hold through dropouts, capture-time matching); :func:`loop_margins`: its
  stability margins with the loop's lag and delay and the robot's modes,
  :func:`safe_gain`: the largest gain that keeps the documented margins;
  :class:`ModeCheck`: those margins with the model's first mode at the held
  equilibrium, recomputed as it moves; :class:`MocapNoise`: the motion
  capture's noise read from its samples, which holds the automatic gain down;
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
  the regulators are sent for the pressures wanted; :class:`CommandPacer`:
  when each command of a target stream goes out (on the stream's grid);
* :class:`OscillationWatchdog`: a sustained or growing swing of the measured
  error near the first mode (:meth:`IntegralFeedback.watch`: the loop cuts
  its gain and holds its correction, and doubles it back after
  :data:`RESTORE_S` without a trip unless it rang again right after that);
* :class:`TipForceEstimator`, :class:`ForceEstimate`: the tip force (or an
  unknown payload) from measured poses and the applied pressures.
The ROS nodes only feed these; the simulated robot is :mod:`..sim`, the two
closed around each other :mod:`..loop`.
"""

from ._feedback import FEEDBACK_MODES, RESTORE_S, FeedbackSettings, IntegralFeedback
from ._loop_margins import (LOOP_DELAY_S, LOOP_LAG_S, MIN_GAIN_MARGIN, MIN_PHASE_MARGIN_DEG,
                            LoopMargins, loop_delay_s, loop_margins, safe_gain)
from ._dynamic_feedforward import DynamicFeedforward, StreamFeedforward, dynamic_path
from ._force_estimator import ESTIMATOR_MODES, ForceEstimate, TipForceEstimator
from ._mode_check import (AUTO_GAIN, GAIN_RANGE_PER_S, RETUNE_FRACTION, ModeCheck,
                          ModeCheckResult, gain_setting)
from ._play import PlayCompensation
from ._command_output import CommandOutput, CreepCompensation
from ._pacing import CommandPacer
from ._shaping import SHAPERS, TargetShaper, shaped, shaper_impulses
from ._target_filter import TARGET_SHAPINGS, TargetFilter
from ._jumps import JUMP_M, KNOWN_MODE_ERROR, JumpTransition
from ._mismatch import MismatchTransfer
from ._mocap_noise import NOISE_BUDGET_M, MocapNoise
from ._watchdog import OscillationWatchdog, WatchdogTrip

__all__ = [
    "AUTO_GAIN", "ESTIMATOR_MODES", "FEEDBACK_MODES", "GAIN_RANGE_PER_S", "JUMP_M", "LOOP_DELAY_S",
    "LOOP_LAG_S", "MIN_GAIN_MARGIN", "MIN_PHASE_MARGIN_DEG", "NOISE_BUDGET_M", "RESTORE_S",
    "RETUNE_FRACTION",
    "SHAPERS",
    "TARGET_SHAPINGS", "CommandOutput", "CommandPacer", "CreepCompensation", "DynamicFeedforward",
    "FeedbackSettings", "ForceEstimate", "IntegralFeedback", "JumpTransition", "KNOWN_MODE_ERROR",
    "LoopMargins",
    "MismatchTransfer", "MocapNoise", "ModeCheck", "ModeCheckResult", "OscillationWatchdog",
    "PlayCompensation",
    "StreamFeedforward", "TargetFilter", "TargetShaper", "TipForceEstimator", "WatchdogTrip",
    "dynamic_path", "gain_setting", "loop_delay_s", "loop_margins", "safe_gain", "shaped",
    "shaper_impulses",
]
