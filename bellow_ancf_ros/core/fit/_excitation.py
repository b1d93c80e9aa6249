"""Excitation for calibration: pressure steps through the workspace, and synthetic recordings.

:func:`excitation_sequence` is what the ``excitation_publisher`` node steps
through: the paper's workspace schemes (section VI.B; 18 schemes for one
segment of three actuators, the paper's four for two segments, see
:func:`bellow_ancf_ros.core.studies.workspace_schemes`), each sampled at a few
points from ``p_min`` to ``p_max``, then random in-limit vectors (uniform,
seeded).  Consecutive duplicates are removed (a repeated command is not a new
step).

:func:`simulate_recording` makes a recording of a (mismatched) robot with a
motion-capture frame and noise, for tests, benchmarks and demos without a
robot.  No ROS import.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..experiments import workspace_schemes
from ..model import RobotConfig, RobotModel
from ..solve import solve_forward
from ._recordings import Recording

__all__ = ['excitation_sequence', 'random_pressures', 'simulate_recording']


def random_pressures(cfg: RobotConfig, n: int, seed: int = 0) -> np.ndarray:
    """``n`` uniformly random in-limit pressure vectors [Pa] (n, A)."""
    rng = np.random.default_rng(seed)
    return rng.uniform(cfg.p_min, cfg.p_max, size=(int(n), cfg.n_actuators_total))


def excitation_sequence(cfg: RobotConfig, points_per_scheme: int = 4, n_random: int = 40,
                        seed: int = 0) -> np.ndarray:
    """Workspace schemes then random vectors, in Pa (rows: steps, columns: actuators)."""
    if points_per_scheme < 2:
        raise ValueError(f'points_per_scheme must be >= 2, got {points_per_scheme}')
    if n_random < 0:
        raise ValueError(f'n_random must be >= 0, got {n_random}')
    rows = [s.pressures(cfg, points_per_scheme) for s in workspace_schemes(cfg)]
    rows.append(random_pressures(cfg, n_random, seed))
    P = np.concatenate(rows)
    keep = np.ones(len(P), bool)
    keep[1:] = np.any(P[1:] != P[:-1], axis=1)
    return P[keep]


def simulate_recording(cfg: RobotConfig, pressures_pa, translation_m=(0.0, 0.0, 0.0),
                       rotation_vector=(0.0, 0.0, 0.0), position_noise_m: float = 0.0,
                       angle_noise_rad: float = 0.0, seed: int = 0, source: str = '<simulated>'):
    """Settled poses of robot ``cfg`` seen by a motion-capture system.

    In the mocap frame the base frame sits at ``translation_m`` with orientation
    ``rotation_vector`` [rad]; Gaussian noise per position component and a random
    rotation of ``angle_noise_rad`` per axis.

    Returns ``(recording, true_base_positions (n, 3), true_base_z_axes (n, 3))``.
    """
    model = RobotModel(cfg)
    P = np.atleast_2d(np.asarray(pressures_pa, dtype=float))
    rng = np.random.default_rng(seed)
    Rb = Rotation.from_rotvec(rotation_vector)
    pos, rot, prev = [], [], None
    for p in P:
        fw = solve_forward(model, p, cfg.payload, warm_start=prev)
        if not fw.success:
            raise RuntimeError(f'simulated robot: forward solve failed at {p / 1e3} kPa: '
                               f'{fw.message}')
        prev = fw
        pos.append(fw.position)
        rot.append(fw.rotation)
    pos, rot = np.array(pos), np.array(rot)
    noise = Rotation.from_rotvec(rng.normal(0.0, angle_noise_rad, size=(len(P), 3)))
    meas_rot = noise * Rb * Rotation.from_matrix(rot)
    meas_pos = Rb.apply(pos) + np.asarray(translation_m, float) + rng.normal(
        0.0, position_noise_m, size=pos.shape)
    rec = Recording(P, meas_pos, meas_rot.as_quat(), np.arange(len(P), dtype=float), source=source)
    return rec, pos, rot[:, :, 2]
