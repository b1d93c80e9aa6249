"""What the simulated robot's hardware does besides the model: the settings and their sources.

The model is quasi-static and exact; real hardware is neither.  These
settings add to the simulated robot the effects that a controller meets on a
real bellow robot, each with a value from a vendor's data sheet or the
literature, and each can be switched off on its own (zero).

Regulators (proportional pressure regulators, e.g. Festo VPPM / SMC ITV):

* ``regulator_time_constant_s`` = 0.06 s: first-order response, 50-100 ms
  to settle a step in vendors' data (Festo VPPM: "response time" 30-100 ms
  depending on volume; SMC ITV0000/1000: 0.1 s);
* ``regulator_dead_time_s`` = 0.015 s: the serial bus and the valve's
  electronics before the spool moves (a few ms to 20 ms);
* ``regulator_hysteresis_pa`` = 1 kPa: about 0.5-1 % of the full scale
  (Festo VPPM: hysteresis 0.5 % FS; SMC ITV: 0.5 % FS, linearity 1 %); modelled
  as a play (backlash) operator on the set-point (Visintin, *Differential
  Models of Hysteresis*, 1994, ch. III): the valve moves only once the
  set-point has left a band of this width around where it stopped, so that the
  same set-point approached from below and from above gives pressures this far
  apart.

Bellows (elastomer, viscoelastic):

* ``creep_fraction`` = 0.15, ``creep_time_constant_s`` = 2 s: a part of the
  elongation (stage 1, eq. 10) follows a pressure change with a first-order
  lag, the rest at once: a one-term Prony series, the standard linear solid of
  quasi-linear viscoelasticity (Fung, *Biomechanics*, 1993, ch. 7); creep of
  this size and seconds-long time constants is what soft pneumatic actuators
  show (the paper sees dynamic effects above 2.67 mm/s).  Bellow hysteresis
  is not modelled: no published model with parameters for such bellows was
  at hand, and the regulators' play already exercises the same protection.

Robot dynamics:

* ``dynamics`` = True: the robot has mass and rings (docs/dynamics.md): the
  robot file's damping (``dynamics.damping_time_s``, 5 ms by default: a loss
  factor of about 0.1 at a few Hz, typical of Shore 30-60 A elastomers) and
  the generalized-alpha integrator instead of a jump from equilibrium to
  equilibrium.  The physics rate must resolve the first mode
  (:data:`MIN_SAMPLES_PER_PERIOD` samples per period).

Motion capture (OptiTrack/Vicon class systems):

* ``mocap_rate_hz`` = 120, ``mocap_latency_s`` = 0.008 (100-240 Hz, 4-10 ms
  from the exposure to the sample on the network, in vendors' data);
* ``position_noise_m`` = 0.15 mm per axis (the paper's OptiTrack accuracy),
  ``angle_noise_rad`` = 0.1 deg per axis (assumed);
* ``outlier_probability`` = 0.005 per sample, ``outlier_min_m`` = 10 mm,
  ``outlier_max_m`` = 30 mm: a swapped or ghost marker moves a rigid body's
  sample by about a marker spacing;
* ``dropout_every_s`` = 15, ``dropout_duration_s`` = 0.5: an occluded marker
  set delivers nothing for a while.

:meth:`PlantEffects.ideal` is the robot of earlier versions: a clean 0.1 s
first-order regulator, no dead time, hysteresis or creep, quasi-static
physics (no inertia), motion capture at 100 Hz with noise only, delivered at
once.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields

__all__ = ['EFFECTS', 'MIN_SAMPLES_PER_PERIOD', 'PlantEffects']

#: Fewest physics steps per period of the robot's first mode (the pose history the motion
#: capture interpolates, and the regulators' and creep's update, resolve it).
MIN_SAMPLES_PER_PERIOD = 20

#: The effects one by one (the benchmark's rows): name -> the settings it switches on
#: (with their realistic values) over :meth:`PlantEffects.ideal`.
EFFECTS = {
    'regulator lag 60 ms': ('regulator_time_constant_s',),
    'regulator dead time': ('regulator_dead_time_s',),
    'regulator hysteresis': ('regulator_hysteresis_pa',),
    'bellows creep': ('creep_fraction', 'creep_time_constant_s'),
    'mocap 120 Hz, latency': ('mocap_rate_hz', 'mocap_latency_s'),
    'mocap outliers': ('outlier_probability', 'outlier_min_m', 'outlier_max_m'),
    'mocap dropouts': ('dropout_every_s', 'dropout_duration_s'),
    'robot dynamics': ('dynamics',),
}


@dataclass(frozen=True)
class PlantEffects:
    """The simulated hardware's settings (SI units; defaults: realistic, see the module)."""

    regulator_time_constant_s: float = 0.06
    regulator_dead_time_s: float = 0.015
    regulator_hysteresis_pa: float = 1.0e3
    regulator_slew_rate_pa_per_s: float = 1.0e6
    creep_fraction: float = 0.15
    creep_time_constant_s: float = 2.0
    mocap_rate_hz: float = 120.0
    mocap_latency_s: float = 0.008
    position_noise_m: float = 0.15e-3
    angle_noise_rad: float = math.radians(0.1)
    outlier_probability: float = 0.005
    outlier_min_m: float = 0.010
    outlier_max_m: float = 0.030
    dropout_every_s: float = 15.0
    dropout_duration_s: float = 0.5
    dynamics: bool = True

    def __post_init__(self) -> None:
        """Refuse a setting out of its range, naming it, its value and what is allowed."""
        positive = ('regulator_slew_rate_pa_per_s', 'mocap_rate_hz', 'creep_time_constant_s')
        if not isinstance(self.dynamics, bool):
            raise ValueError(f'plant setting dynamics: {self.dynamics!r} is not true or false')
        for f in fields(self):
            if f.name == 'dynamics':
                continue
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise ValueError(f'plant setting {f.name}: {v!r} is not a finite number')
            if f.name in positive and not v > 0:
                raise ValueError(f'plant setting {f.name}: {v!r} must be > 0')
            if v < 0:
                raise ValueError(f'plant setting {f.name}: {v!r} must be >= 0')
        if self.creep_fraction >= 1:
            raise ValueError(f'plant setting creep_fraction: {self.creep_fraction!r} must be '
                             'in [0, 1) (a part of the elongation creeps, not all of it)')
        if self.outlier_probability > 1:
            raise ValueError(f'plant setting outlier_probability: {self.outlier_probability!r} '
                             'must be in [0, 1]')
        if self.outlier_max_m < self.outlier_min_m:
            raise ValueError(f'plant setting outlier_max_m: {self.outlier_max_m!r} must be >= '
                             f'outlier_min_m ({self.outlier_min_m!r})')
        if 0 < self.dropout_every_s <= self.dropout_duration_s:
            raise ValueError(f'plant setting dropout_duration_s: {self.dropout_duration_s!r} '
                             f'must be shorter than dropout_every_s ({self.dropout_every_s!r})')

    @classmethod
    def ideal(cls, **changes: float) -> 'PlantEffects':
        """The kind robot of earlier versions (see the module), with ``changes`` applied."""
        base = dict(regulator_time_constant_s=0.1, regulator_dead_time_s=0.0,
                    regulator_hysteresis_pa=0.0, creep_fraction=0.0, mocap_rate_hz=100.0,
                    mocap_latency_s=0.0, outlier_probability=0.0, dropout_every_s=0.0,
                    dropout_duration_s=0.0, dynamics=False)
        base.update(changes)
        return cls(**base)

    def only(self, effect: str) -> 'PlantEffects':
        """:meth:`ideal` with one of :data:`EFFECTS` switched on at this object's values."""
        if effect not in EFFECTS:
            raise ValueError(f'effect {effect!r}: not one of {list(EFFECTS)}')
        return PlantEffects.ideal(**{k: getattr(self, k) for k in EFFECTS[effect]})

    def preview_s(self, target_rate_hz: float) -> float:
        """How far ahead to command a trajectory: dead time + time constant + half a period.

        The regulators' known lag, and half the period of a target stream at
        ``target_rate_hz`` (a target holds for one period); what
        ``trajectory_publisher``'s ``preview_s`` compensates.
        """
        return (self.regulator_dead_time_s + self.regulator_time_constant_s
                + 0.5 / float(target_rate_hz))

    def min_physics_rate_hz(self, first_mode_hz: float) -> float:
        """Slowest physics rate that resolves a first mode [Hz] (0 without dynamics)."""
        return MIN_SAMPLES_PER_PERIOD * float(first_mode_hz) if self.dynamics else 0.0

    def replace(self, **changes: float) -> 'PlantEffects':
        """A copy with ``changes`` (checked like the constructor)."""
        return dataclasses.replace(self, **changes)
