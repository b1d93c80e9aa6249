"""Fitting the model to a robot (paper section V) and calibrating it from recordings.

* :mod:`.identification`: stiffness, effective diameter and actuator
  distance from the paper's test rigs (eqs. 31-33);
* :class:`Cantilever`: the cantilever rig's beam model;
* :class:`Recording` and its readers and writers (CSV, rosbag2 through
  ``rosbags``); :class:`PoseStream`, :func:`read_pose_stream`: the raw poses
  of a recorded release or step;
* :mod:`.calibration`: a robot file's parameters and the base-in-mocap
  transform from recorded pressures and poses;
* :func:`excitation_sequence`, :func:`simulate_recording`: what to record;
* :func:`fit_free_vibration`, :func:`identify_damping`: the first mode's
  frequency and damping from a recorded release or step, and the damping
  time that reproduces them; :func:`ringdown_window`: which part of a
  recording to fit;
* :func:`fit_creep`: the bellows' creep fraction and time constant from a
  recorded pressure step held still; :func:`pressure_step_time`: when a
  recording's pressure command stepped;
* :func:`fit_play`: the pressure regulators' play from a staircase of
  set-points (:func:`play_staircase`) and their own pressure sensors.
"""

from . import calibration, identification
from ._cantilever import Cantilever, CantileverResult
from ._creep import CreepFit, fit_creep, pressure_step_time
from ._excitation import excitation_sequence, random_pressures, simulate_recording
from ._regulator_play import SETTLE_S as PLAY_SETTLE_S
from ._regulator_play import PlayFit, fit_play, play_staircase, staircase_recording
from ._recordings import (FLOAT64_MULTI_ARRAY, POSE_STAMPED, POSE_STREAM_COLUMNS, POSE_TOPIC,
                          PRESSURE_TOPIC, BagWriter, PoseStream, Recording, RecordingError,
                          csv_header, numeric_csv_rows, pressure_unit, read_bag, read_csv,
                          read_pose_stream,
                          read_pose_stream_bag, read_pose_stream_csv, read_recording,
                          settled_samples, write_bag, write_csv, MEASURED_PRESSURE_TOPIC,
                          PressureRecording, pressure_csv_header, read_pressure_recording)
from ._sensitivities import RecordingModel
from ._vibration import (DampingIdentification, FreeVibrationFit, RingdownWindow,
                         fit_free_vibration, identify_damping, ringdown_window)
from .calibration import CalibrationError, CalibrationResult, calibrate

__all__ = [
    "BagWriter", "CalibrationError", "DampingIdentification", "FreeVibrationFit",
    "fit_free_vibration", "identify_damping", "RingdownWindow", "ringdown_window",
    "CalibrationResult", "Cantilever", "CreepFit", "fit_creep", "pressure_step_time",
    "CantileverResult", "PLAY_SETTLE_S", "PlayFit", "fit_play", "play_staircase",
    "staircase_recording",
    "MEASURED_PRESSURE_TOPIC",
    "PressureRecording", "pressure_csv_header", "read_pressure_recording",
    "FLOAT64_MULTI_ARRAY", "POSE_STAMPED", "POSE_STREAM_COLUMNS", "POSE_TOPIC",
    "PRESSURE_TOPIC", "PoseStream", "Recording", "read_pose_stream", "read_pose_stream_bag",
    "read_pose_stream_csv",
    "RecordingError", "RecordingModel", "numeric_csv_rows", "calibrate", "calibration",
    "csv_header",
    "excitation_sequence", "identification", "pressure_unit", "random_pressures", "read_bag",
    "read_csv", "read_recording", "settled_samples", "simulate_recording", "write_bag",
    "write_csv",
]
