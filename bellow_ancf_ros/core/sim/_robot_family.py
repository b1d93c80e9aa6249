"""A family of simulated robots around a model: what the closed loop must hold, drawn at random.

A controller tuned on one simulated robot is tuned on one robot.  A lab's
robot differs from the model in ways nobody measured; :func:`draw_robot`
draws one such robot from documented ranges (:data:`FAMILY_RANGES`), with
one seed, reproducibly:

* **the robot**: stiffness (every coefficient of ``k(lambda)``), the pitch
  radius and ``D_a`` each off by up to 10 %; its masses scaled so that its
  first natural frequency at the vent equilibrium is 0.7-1.4 times the
  model's (measured by the modal analysis, one correction); its damping
  (Kelvin-Voigt retardation time) set for a first-mode damping ratio of
  0.02-0.25; twice the model's elements;
* **the regulators**: lag 20-120 ms, dead time 5-40 ms, play 0-2 kPa;
* **the bellows**: creep 0-20 % of the elongation over 1-5 s;
* **the motion capture**: 60-240 Hz, 5-20 ms latency, 0.05-0.3 mm noise
  (the angle noise in proportion: 0.1 deg at 0.15 mm), outliers with a
  probability of 0-1 % per sample, a dropout of 0.1-0.5 s every 10-30 s.

Every parameter is drawn uniformly in its range.  :class:`RobotDraw` holds
the drawn values (for reports: which parameter drives a miss) and builds the
:class:`~._simulated_robot.SimulatedRobot`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..dynamics import natural_modes
from ..model import RobotConfig, RobotModel, load_robot
from ..solve import solve_forward
from ._plant_effects import PlantEffects
from ._simulated_robot import SimulatedRobot

__all__ = ['FAMILY_RANGES', 'RobotDraw', 'draw_robot', 'first_mode']

#: The family: parameter -> (low, high), drawn uniformly.  Scales are relative to the model.
FAMILY_RANGES = {
    'mode_scale': (0.7, 1.4),                  # first natural frequency / the model's
    'damping_ratio': (0.02, 0.25),             # of the first mode
    'stiffness_scale': (0.9, 1.1),             # every coefficient of k(lambda)
    'pitch_radius_scale': (0.9, 1.1),
    'd_a_scale': (0.9, 1.1),
    'regulator_time_constant_s': (0.02, 0.12),
    'regulator_dead_time_s': (0.005, 0.040),
    'regulator_hysteresis_pa': (0.0, 2.0e3),
    'creep_fraction': (0.0, 0.20),
    'creep_time_constant_s': (1.0, 5.0),
    'mocap_rate_hz': (60.0, 240.0),
    'mocap_latency_s': (0.005, 0.020),
    'position_noise_m': (0.05e-3, 0.3e-3),
    'outlier_probability': (0.0, 0.01),
    'dropout_every_s': (10.0, 30.0),
    'dropout_duration_s': (0.1, 0.5),
}
#: The robot's elements per actuator over the model's (the "real" robot finer).
ELEMENT_FACTOR = 2
#: Angle noise per metre of position noise (0.1 deg at 0.15 mm, the realistic default).
_ANGLE_PER_POSITION_NOISE = math.radians(0.1) / 0.15e-3


def first_mode(cfg: RobotConfig, payload_kg: float = 0.0,
               damping_time_s: float | None = None):
    """The first natural mode of ``cfg``'s robot at its vent equilibrium (``Mode``)."""
    model = RobotModel(cfg)
    fw = solve_forward(model, np.zeros(model.A), payload_kg=payload_kg)
    if not fw.success:
        raise RuntimeError(f'robot {cfg.name!r}: no vent equilibrium: {fw.message}')
    return natural_modes(fw, 1, damping_time_s=damping_time_s).first


def _masses_scaled(cfg: RobotConfig, s: float) -> RobotConfig:
    segs = tuple(dataclasses.replace(g, constraint_plate_mass=g.constraint_plate_mass * s,
                                     top_plate_mass=g.top_plate_mass * s,
                                     connector_mass=g.connector_mass * s)
                 for g in cfg.segments)
    return dataclasses.replace(cfg, rho0=cfg.rho0 * s, segments=segs)


@dataclass(frozen=True)
class RobotDraw:
    """One robot of the family: the drawn values, its robot file and its hardware."""

    seed: int
    values: dict           #: parameter of :data:`FAMILY_RANGES` -> the drawn value
    config: RobotConfig    #: the robot's own robot file (not the controller's model)
    effects: PlantEffects  #: its regulators, creep and motion capture
    first_mode_hz: float   #: its first natural frequency at the vent equilibrium, no payload
    model_mode_hz: float   #: the model's

    def robot(self, payload_kg: float = 0.0) -> SimulatedRobot:
        """Build the simulated robot; its motion capture is seeded with the draw's seed."""
        return SimulatedRobot(self.config, payload_kg=payload_kg, effects=self.effects,
                              seed=self.seed)


def draw_robot(model: str | RobotConfig, seed: int) -> RobotDraw:
    """Draw robot ``seed`` of the family around the robot file ``model`` (its name or config)."""
    base = model if isinstance(model, RobotConfig) else load_robot(model)
    rng = np.random.default_rng(seed)
    v = {k: float(rng.uniform(lo, hi)) for k, (lo, hi) in FAMILY_RANGES.items()}
    n_el = base.n_elements * ELEMENT_FACTOR
    f_model = first_mode(base).frequency_hz
    segs = tuple(dataclasses.replace(g, pitch_radius=g.pitch_radius * v['pitch_radius_scale'])
                 for g in base.segments)
    cfg = dataclasses.replace(
        base, name=f'{base.name}_family_{seed}', n_elements=n_el, segments=segs,
        stiffness_coeffs=tuple(c * v['stiffness_scale'] for c in base.stiffness_coeffs),
        d_a=base.d_a * v['d_a_scale'], source=f'draw_robot({base.name!r}, seed={seed})')
    f_goal = v['mode_scale'] * f_model
    scale = 1.0
    for _ in range(3):    # the frequency goes nearly as 1/sqrt(mass): three passes land on it
        f = first_mode(_masses_scaled(cfg, scale)).frequency_hz
        scale *= (f / f_goal) ** 2
    cfg = _masses_scaled(cfg, scale)
    mode = first_mode(cfg)
    # Kelvin-Voigt damping: zeta = pi f tau for a mode of frequency f; one correction
    tau = v['damping_ratio'] / (math.pi * mode.frequency_hz)
    zeta = first_mode(cfg, damping_time_s=tau).damping_ratio
    cfg = dataclasses.replace(cfg, damping_time=tau * v['damping_ratio'] / zeta)
    effects = PlantEffects(
        regulator_time_constant_s=v['regulator_time_constant_s'],
        regulator_dead_time_s=v['regulator_dead_time_s'],
        regulator_hysteresis_pa=v['regulator_hysteresis_pa'],
        creep_fraction=v['creep_fraction'], creep_time_constant_s=v['creep_time_constant_s'],
        mocap_rate_hz=v['mocap_rate_hz'], mocap_latency_s=v['mocap_latency_s'],
        position_noise_m=v['position_noise_m'],
        angle_noise_rad=v['position_noise_m'] * _ANGLE_PER_POSITION_NOISE,
        outlier_probability=v['outlier_probability'], dropout_every_s=v['dropout_every_s'],
        dropout_duration_s=v['dropout_duration_s'])
    return RobotDraw(seed=int(seed), values=v, config=cfg, effects=effects,
                     first_mode_hz=float(mode.frequency_hz), model_mode_hz=float(f_model))
