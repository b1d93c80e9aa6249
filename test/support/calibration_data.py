"""Synthetic calibration data shared by the calibration tests: a mismatched robot seen by mocap."""

import numpy as np

from bellow_ancf_ros.core import parameter_keys as pk
from bellow_ancf_ros.core.model._config import robot_from_dict
from bellow_ancf_ros.core.fit._excitation import simulate_recording

#: the unknown mocap frame: base frame origin in the mocap frame [m], rotation vector [deg]
FRAME_T = np.array([0.031, -0.018, 0.052])
FRAME_ROTVEC_DEG = np.array([3.0, -2.0, 5.0])
NOISE_M = 0.15e-3
NOISE_RAD = np.radians(0.1)


def mismatch(cfg):
    """The 'real' robot: pitch radius, D_a, stiffness and top-plate masses off by a few %.

    Returns ``(true_cfg, {key: true value})`` for the keys that changed.
    """
    d = cfg.to_dict()
    changes = {'segments[*].pitch_radius_mm': 1.04, 'actuator.d_a_mm': 0.95,
               pk.STIFFNESS_SCALE: 1.06, 'segments[*].top_plate_mass_kg': 1.05}
    true = {k: pk.get_value(d, k) * f for k, f in changes.items()}
    return robot_from_dict(pk.with_values(d, list(true), list(true.values()))), true


def recording(true_cfg, pressures, seed=2):
    """Noisy recording of ``true_cfg`` in the mocap frame (and the true base-frame poses)."""
    return simulate_recording(true_cfg, pressures, FRAME_T, np.radians(FRAME_ROTVEC_DEG),
                              NOISE_M, NOISE_RAD, seed=seed)
