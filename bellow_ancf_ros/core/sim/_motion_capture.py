"""The simulated motion capture: noise, latency, outliers and dropouts, seeded.

:class:`MotionCapture` turns the true end-effector pose at the capture time
into what a motion-capture system delivers (settings and sources:
:mod:`bellow_ancf_ros.core.sim._plant_effects`):

* Gaussian position noise per axis and a small random rotation;
* latency: a sample delivered at ``t`` was captured at ``t - latency``
  (:class:`MocapSample` carries both, as a driver's stamp does);
* outliers: with probability ``outlier_probability`` a sample is moved by
  ``outlier_min_m`` to ``outlier_max_m`` in a random direction (a swapped
  marker); :attr:`MocapSample.outlier` says so (ground truth for tests);
* dropouts: every ``dropout_every_s`` (first one at a seeded phase) nothing
  is delivered for ``dropout_duration_s`` (an occluded marker set).

One seeded generator drives all of it: the same seed and the same calls give
the same samples.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..geometry import rotation_from_vector
from ._plant_effects import PlantEffects

__all__ = ['MocapSample', 'MotionCapture']


class MocapSample(NamedTuple):
    """One delivered motion-capture sample (base frame)."""

    captured_s: float        #: when the pose was taken (the message stamp)
    position: np.ndarray     #: (3,) [m]
    rotation: np.ndarray     #: (3, 3)
    outlier: bool            #: the sample was corrupted (a swapped marker)


class MotionCapture:
    """Noisy, late, sometimes wrong, sometimes silent pose samples (see the module)."""

    def __init__(self, effects: PlantEffects, seed: int | None = None) -> None:
        """Use ``effects``' mocap settings; ``seed`` for repeatable samples (None: random)."""
        self.effects = effects
        self.rng = np.random.default_rng(seed)
        every = effects.dropout_every_s
        self.dropout_phase_s = float(self.rng.uniform(0.0, every)) if every > 0 else 0.0
        self.outliers = 0

    @property
    def period_s(self) -> float:
        """Time between samples [s]."""
        return 1.0 / self.effects.mocap_rate_hz

    def in_dropout(self, t: float) -> bool:
        """True when a sample captured at ``t`` is lost (occlusion)."""
        e = self.effects
        if e.dropout_every_s <= 0 or e.dropout_duration_s <= 0 or t < self.dropout_phase_s:
            return False
        return (t - self.dropout_phase_s) % e.dropout_every_s < e.dropout_duration_s

    def noisy(self, position: np.ndarray, rotation: np.ndarray):
        """``(position, rotation)`` with the measurement noise added."""
        e = self.effects
        pos, R = np.array(position, dtype=float), np.array(rotation, dtype=float)
        if e.position_noise_m > 0:
            pos = pos + self.rng.normal(0.0, e.position_noise_m, 3)
        if e.angle_noise_rad > 0:
            R = rotation_from_vector(self.rng.normal(0.0, e.angle_noise_rad, 3)) @ R
        return pos, R

    def observe(self, captured_s: float, position: np.ndarray,
                rotation: np.ndarray) -> MocapSample | None:
        """The sample of the true pose at ``captured_s``; None when it is lost in a dropout."""
        if self.in_dropout(captured_s):
            return None
        pos, R = self.noisy(position, rotation)
        e = self.effects
        outlier = e.outlier_probability > 0 and self.rng.random() < e.outlier_probability
        if outlier:
            d = self.rng.normal(size=3)
            pos = pos + d / np.linalg.norm(d) * self.rng.uniform(e.outlier_min_m,
                                                                 e.outlier_max_m)
            self.outliers += 1
        return MocapSample(float(captured_s), pos, R, bool(outlier))
