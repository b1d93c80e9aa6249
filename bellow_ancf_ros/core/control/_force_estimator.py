"""The robot as a force sensor: the tip force (or an unknown payload) from measured poses.

The robot's compliance makes a force visible in its pose: about 8 mm per
newton sideways for the default one-segment robot, so a lateral force of a
few hundredths of a newton shows in a single motion-capture sample (0.15 mm
noise).  The estimator is an extended Kalman filter on the force:

* state: the tip force ``F`` [N, base frame] (or, ``mode='mass'``, the mass
  ``m`` [kg] of an unknown payload, ``F = m g``), a random walk with
  spectral density ``force_rate`` (N^2/s; 0 for a constant force);
* measurement of a sample: the end-effector position (and z-axis, when
  given) against the model's equilibrium at the applied pressures under the
  current estimate (:func:`~bellow_ancf_ros.core.solve.solve_forward`,
  warm-started), with the exact sensitivity ``H = dy/dF``: the tip
  compliance (:func:`~bellow_ancf_ros.core.solve.tip_compliance`; for the
  mass ``H = C g``);
* noise: ``position_noise_m`` per axis and ``angle_noise_rad`` per axis of
  the z-axis (motion capture).

The covariance is the filter's own: honest when the model is the robot's
(use the calibrated robot file: with the uncalibrated default a 1 mm model
error reads as about 0.1 N sideways) and the noise is white.  A direction
whose standard deviation stays above ``blind_std_n`` is reported as not
seen (:meth:`TipForceEstimator.blind_directions`); for one segment that is
the vertical force for the first samples (0.55 mm/N against 8.2 mm/N
sideways).  :meth:`TipForceEstimator.tare` zeroes the reading at the
current estimate, as a force sensor's tare does.  A sample whose model
solve fails is refused (counted), never folded in; so is an outlier (a
swapped marker): a position farther than ``outlier_gate_m`` from the median
of the last five received, the same gate as the closed loop's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model import RobotModel, tip_load
from ..solve import solve_forward, tip_compliance
from ._median_gate import MedianGate

__all__ = ["ESTIMATOR_MODES", "ForceEstimate", "TipForceEstimator"]

ESTIMATOR_MODES = ("force", "mass")


@dataclass(frozen=True)
class ForceEstimate:
    """The reading: force [N, base frame] after the tare, its covariance and what it cannot see."""

    force_n: np.ndarray            # (3,) the estimate minus the tare
    covariance_n2: np.ndarray      # (3, 3)
    payload_kg: float | None       # mode 'mass': the estimated payload (tare applied)
    payload_std_kg: float | None
    samples: int                   # samples folded in
    refused: int                   # samples refused (model solve failed, bad input)
    blind: list                    # unit vectors of directions with std above blind_std_n

    @property
    def std_n(self) -> np.ndarray:
        """Standard deviation of each force component [N]."""
        return np.sqrt(np.clip(np.diag(self.covariance_n2), 0.0, None))


class TipForceEstimator:
    """Extended Kalman filter of the tip force from poses and pressures (module docstring).

    ``model``: the robot as the lab trusts it (its calibrated robot file);
    ``payload_kg``: the known payload (mode ``'force'``), or the starting
    guess of the unknown one (mode ``'mass'``).
    """

    def __init__(self, model: RobotModel, mode: str = "force", payload_kg: float = 0.0,
                 position_noise_m: float = 0.15e-3, angle_noise_rad: float = math.radians(0.1),
                 initial_std_n: float = 1.0, force_rate: float = 0.0,
                 blind_std_n: float = 0.05, outlier_gate_m: float = 0.005) -> None:
        """Set up; raises ValueError naming a bad argument, its value and what is allowed."""
        if mode not in ESTIMATOR_MODES:
            raise ValueError(f"mode {mode!r} is not allowed; allowed: "
                             f"{', '.join(ESTIMATOR_MODES)}")
        for name, v, lo in (("position_noise_m", position_noise_m, 0.0),
                            ("angle_noise_rad", angle_noise_rad, 0.0),
                            ("initial_std_n", initial_std_n, 0.0),
                            ("force_rate", force_rate, -1.0), ("blind_std_n", blind_std_n, 0.0),
                            ("outlier_gate_m", outlier_gate_m, 0.0)):
            if not (math.isfinite(float(v)) and float(v) > lo):
                raise ValueError(f"{name} = {v!r} is not allowed; allowed: a finite number "
                                 f"{'>= 0' if lo < 0 else '> 0'}")
        self.model, self.mode = model, mode
        self.payload_kg = tip_load(payload_kg).payload_kg
        self.sigma_p, self.sigma_a = float(position_noise_m), float(angle_noise_rad)
        self.force_rate, self.blind_std_n = float(force_rate), float(blind_std_n)
        self.g = np.asarray(model.gravity, dtype=float)
        n = 3 if mode == "force" else 1
        if mode == "force":
            self.x, self.P = np.zeros(3), np.eye(3) * initial_std_n**2
        else:  # initial_std_n is a force: its mass along gravity
            gn = float(np.linalg.norm(self.g))
            self.x, self.P = np.array([self.payload_kg]), np.eye(1) * (initial_std_n / gn) ** 2
        self._n = n
        self.tare_offset = np.zeros(n)
        self.samples = self.refused = self.outliers = 0   # outliers: part of refused
        self.outlier_gate_m = float(outlier_gate_m)
        self._gate = MedianGate(self.outlier_gate_m)   # received positions
        self.last_reason = ""
        self._fw = None
        self._t = None

    # ---------------------------------------------------------------- model
    def _load(self):
        """(payload, force) of the current estimate."""
        if self.mode == "force":
            return self.payload_kg, self.x
        return max(0.0, float(self.x[0])), None

    def _equilibrium(self, pressures):
        m, f = self._load()
        fw = solve_forward(self.model, pressures, payload_kg=m, tip_force_n=f,
                           warm_start=self._fw, check_stability=False)
        if not fw.converged and self._fw is not None:
            fw = solve_forward(self.model, pressures, payload_kg=m, tip_force_n=f,
                               check_stability=False)
        return fw

    # --------------------------------------------------------------- update
    def update(self, pressures_pa, position, z_axis=None, time_s: float | None = None) -> bool:
        """Fold in one sample: applied pressures [Pa], measured position [m] (and z-axis).

        ``time_s`` (monotonic) sets the random walk's step since the last
        sample.  Returns False (and counts it) for a sample that was refused:
        non-finite values, pressures outside the limits, or no equilibrium.
        """
        try:
            p = np.asarray(pressures_pa, dtype=float).reshape(self.model.A)
            y = np.asarray(position, dtype=float).reshape(3)
            z = None if z_axis is None else np.asarray(z_axis, dtype=float).reshape(3)
        except ValueError as exc:
            return self._refuse(f"bad sample: {exc}")
        cfg = self.model.cfg
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(y))
                and (z is None or (np.all(np.isfinite(z)) and np.linalg.norm(z) > 0))):
            return self._refuse("non-finite sample")
        if np.any(p < cfg.p_min - 1.0) or np.any(p > cfg.p_max + 1.0):
            return self._refuse("pressures outside the limits")
        if self._gate.refuses(y):
            self.outliers += 1
            return self._refuse("outlier: the position is far from the recent ones")
        p = np.clip(p, cfg.p_min, cfg.p_max)
        if time_s is not None:
            if self._t is not None and self.force_rate > 0:
                dt = max(0.0, float(time_s) - self._t)
                q = self.force_rate * dt
                self.P = self.P + (q * np.eye(self._n) if self.mode == "force"
                                   else q / float(self.g @ self.g) * np.eye(1))
            self._t = float(time_s)
        fw = self._equilibrium(p)
        if not fw.converged:
            return self._refuse(f"no equilibrium at these pressures: {fw.message}")
        self._fw = fw
        c = tip_compliance(fw)
        H, r, noise = [c.translational_m_per_n], [y - fw.position], [self.sigma_p**2] * 3
        if z is not None:
            z = z / np.linalg.norm(z)
            H.append(c.axis_per_n)
            r.append(z - fw.z_axis)
            noise += [self.sigma_a**2] * 3
        H, r = np.vstack(H), np.concatenate(r)
        if self.mode == "mass":
            H = H @ self.g[:, None]
        S = H @ self.P @ H.T + np.diag(noise)
        K = np.linalg.solve(S, H @ self.P).T
        self.x = self.x + K @ r
        IKH = np.eye(self._n) - K @ H
        self.P = IKH @ self.P @ IKH.T + K @ np.diag(noise) @ K.T   # Joseph form: stays SPD
        self.samples += 1
        return True

    def _refuse(self, reason: str) -> bool:
        self.refused += 1
        self.last_reason = reason
        return False

    # --------------------------------------------------------------- output
    def tare(self) -> None:
        """Zero the reading at the current estimate (a force sensor's tare)."""
        self.tare_offset = self.x.copy()

    def blind_directions(self) -> list:
        """Unit vectors (base frame) along which the force's std is above ``blind_std_n``."""
        cov = self._force_covariance()
        w, v = np.linalg.eigh(0.5 * (cov + cov.T))
        return [v[:, k].copy() for k in range(3) if w[k] > self.blind_std_n**2]

    def _force_covariance(self):
        if self.mode == "force":
            return self.P.copy()
        return float(self.P[0, 0]) * np.outer(self.g, self.g)

    def estimate(self) -> ForceEstimate:
        """The current reading (tare applied)."""
        if self.mode == "force":
            force, m, m_std = self.x - self.tare_offset, None, None
        else:
            m = float(self.x[0] - self.tare_offset[0])
            force, m_std = m * self.g, float(math.sqrt(max(self.P[0, 0], 0.0)))
        return ForceEstimate(force_n=np.array(force, dtype=float),
                             covariance_n2=self._force_covariance(), payload_kg=m,
                             payload_std_kg=m_std, samples=self.samples, refused=self.refused,
                             blind=self.blind_directions())
