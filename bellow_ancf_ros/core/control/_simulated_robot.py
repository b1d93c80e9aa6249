"""A simulated robot that is not the model: regulators, quasi-static physics, motion capture.

Plays the real robot for the closed loop and the main demo, without ROS:

* :class:`PressureRegulators`: one proportional pressure regulator per
  actuator, a first-order lag ``tau dp/dt = p_cmd - p`` (exact discrete step
  for any ``dt``), a slew-rate limit and the hardware limits
  ``[p_min, p_max]`` of the robot file.
* :class:`SimulatedRobot`: the regulated pressures drive the quasi-static
  equilibrium (eq. 25, :func:`~bellow_ancf_ros.core.solve_forward`,
  warm-started from the previous equilibrium) of the robot's *own* robot file
  (shipped examples: ``config/one_segment_mismatched.yaml``,
  ``config/two_segment_mismatched.yaml``, whose pitch radius, ``D_a``,
  stiffness and masses differ from the default model by 6-10 %) at a finer
  element count than the controller's model.
* :meth:`SimulatedRobot.measure`: the end-effector pose as a motion-capture
  system reports it, with Gaussian position noise (default 0.15 mm per axis,
  the paper's OptiTrack accuracy) and a small rotation noise, from a seeded
  random generator (repeatable runs).

Pressures are gauge pressures in Pa throughout.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..geometry import rotation_from_vector
from ..model import RobotConfig, RobotModel, load_robot, tip_load
from ..solve import ForwardResult, solve_forward

__all__ = [
    'DEFAULT_ANGLE_NOISE_RAD',
    'DEFAULT_POSITION_NOISE_M',
    'DEFAULT_SLEW_RATE_PA_PER_S',
    'DEFAULT_TIME_CONSTANT_S',
    'PressureRegulators',
    'SimulatedRobot',
]

#: Regulator time constant [s] (first-order lag).
DEFAULT_TIME_CONSTANT_S = 0.1
#: Regulator slew-rate limit [Pa/s] (a full 200 kPa swing takes at least 0.2 s).
DEFAULT_SLEW_RATE_PA_PER_S = 1.0e6
#: Motion-capture position noise, standard deviation per axis [m] (paper: OptiTrack 0.15 mm).
DEFAULT_POSITION_NOISE_M = 0.15e-3
#: Motion-capture orientation noise, standard deviation per axis of a small rotation [rad]
#: (assumed; the paper states only the position accuracy).
DEFAULT_ANGLE_NOISE_RAD = math.radians(0.1)
#: Regulated pressures that moved less than this since the last equilibrium [Pa] reuse it.
RESOLVE_THRESHOLD_PA = 1.0


class PressureRegulators:
    """First-order-lag pressure regulators with a slew limit and hardware limits.

    ``set_command(p)`` sets the set-points (clipped into ``[p_min, p_max]``,
    as a regulator cannot exceed its supply); ``step(dt)`` advances the
    output pressures by ``dt`` seconds: the exact response of
    ``tau dp/dt = p_cmd - p`` over ``dt``, its change limited to
    ``slew_rate * dt``, clipped into the limits.  ``tau = 0`` follows the
    set-point at once (still slew-limited).
    """

    def __init__(self, n: int, p_min: float, p_max: float,
                 time_constant_s: float = DEFAULT_TIME_CONSTANT_S,
                 slew_rate_pa_per_s: float = DEFAULT_SLEW_RATE_PA_PER_S,
                 initial_pa: Any = None) -> None:
        """Regulators at ``initial_pa`` (default: vent, 0 Pa gauge) with that set-point."""
        if not (math.isfinite(p_min) and math.isfinite(p_max) and p_min < p_max):
            raise ValueError(f'pressure limits must be finite with p_min < p_max, got '
                             f'[{p_min}, {p_max}] Pa')
        if not (math.isfinite(time_constant_s) and time_constant_s >= 0):
            raise ValueError(f'time_constant_s must be >= 0, got {time_constant_s}')
        if not (slew_rate_pa_per_s > 0):
            raise ValueError(f'slew_rate_pa_per_s must be > 0, got {slew_rate_pa_per_s}')
        self.n, self.p_min, self.p_max = int(n), float(p_min), float(p_max)
        self.time_constant_s = float(time_constant_s)
        self.slew_rate_pa_per_s = float(slew_rate_pa_per_s)
        start = np.clip(np.zeros(self.n), p_min, p_max) if initial_pa is None else initial_pa
        self.pressures_pa = self._checked(start)
        self.command_pa = self.pressures_pa.copy()

    def _checked(self, p: Any) -> np.ndarray:
        arr = np.array(p, dtype=float).ravel()
        if arr.size != self.n:
            raise ValueError(f'expected {self.n} pressures (one per actuator), got {arr.size}')
        if not np.all(np.isfinite(arr)):
            raise ValueError('pressures must be finite numbers')
        return np.clip(arr, self.p_min, self.p_max)

    def set_command(self, p: Any) -> None:
        """New set-points [Pa] (clipped into the hardware limits; NaN/inf raise ``ValueError``)."""
        self.command_pa = self._checked(p)

    def step(self, dt: float) -> np.ndarray:
        """Advance by ``dt`` >= 0 seconds; returns the output pressures [Pa]."""
        dt = float(dt)
        if not (math.isfinite(dt) and dt >= 0):
            raise ValueError(f'dt must be a finite non-negative time, got {dt}')
        p, c = self.pressures_pa, self.command_pa
        decay = math.exp(-dt / self.time_constant_s) if self.time_constant_s > 0 else 0.0
        target = c + (p - c) * decay
        max_step = self.slew_rate_pa_per_s * dt
        self.pressures_pa = np.clip(p + np.clip(target - p, -max_step, max_step),
                                    self.p_min, self.p_max)
        return self.pressures_pa.copy()


class SimulatedRobot:
    """The simulated robot: regulators -> quasi-static equilibrium -> (noisy) pose.

    Parameters
    ----------
    config : robot name, robot file path or :class:`RobotConfig` of the *robot*
        (not the controller's model); default the shipped
        ``one_segment_mismatched``.
    n_elements : ANCF elements per actuator; default the file's
        ``model.n_elements`` (12 in the shipped mismatched files, twice the
        model's 6).
    payload_kg : payload at the end effector [kg] (default: the file's).
    time_constant_s, slew_rate_pa_per_s : regulator settings.
    position_noise_m, angle_noise_rad : motion-capture noise (standard
        deviations per axis); 0 for exact measurements.
    seed : seed of the noise generator (None: a fresh random one).
    stability_every : run the stability check on every n-th equilibrium (and
        on any solve that needed continuation); it costs as much as the solve.

    Threads: :meth:`step` from one thread only; :meth:`measure`,
    :meth:`command`, :meth:`set_payload` and :meth:`set_tip_force` may be called from
    others (the state, the set-points and the loads are replaced whole, never mutated).

    A failed equilibrium solve (not converged, or unstable when checked)
    keeps the last good state and is counted in :attr:`failures` with its
    message in :attr:`last_failure`: the robot never reports a configuration
    it could not compute.
    """

    def __init__(self, config: Any = 'one_segment_mismatched', n_elements: int | None = None,
                 payload_kg: float | None = None,
                 time_constant_s: float = DEFAULT_TIME_CONSTANT_S,
                 slew_rate_pa_per_s: float = DEFAULT_SLEW_RATE_PA_PER_S,
                 position_noise_m: float = DEFAULT_POSITION_NOISE_M,
                 angle_noise_rad: float = DEFAULT_ANGLE_NOISE_RAD,
                 seed: int | None = None, stability_every: int = 10) -> None:
        """Load the robot, solve its vent equilibrium (``RuntimeError`` if there is none)."""
        cfg = config if isinstance(config, RobotConfig) else load_robot(config)
        self.cfg = cfg
        self.model = RobotModel(cfg, n_elements=n_elements)
        self.payload_kg = float(cfg.payload if payload_kg is None else payload_kg)
        if not (math.isfinite(self.payload_kg) and self.payload_kg >= 0):
            raise ValueError(f'payload_kg must be a finite non-negative mass, got {payload_kg}')
        for name, v in (('position_noise_m', position_noise_m),
                        ('angle_noise_rad', angle_noise_rad)):
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f'{name} must be >= 0, got {v}')
        self.position_noise_m = float(position_noise_m)
        self.angle_noise_rad = float(angle_noise_rad)
        self.regulators = PressureRegulators(self.model.A, cfg.p_min, cfg.p_max,
                                             time_constant_s, slew_rate_pa_per_s)
        self.rng = np.random.default_rng(seed)
        self.stability_every = max(1, int(stability_every))
        self.tip_force_n = (0.0, 0.0, 0.0)  # a push on the end effector [N], set_tip_force
        self.failures = 0
        self.last_failure = ''
        self.solves = 0
        self.time_s = 0.0
        self.state: ForwardResult = self._solve(self.regulators.pressures_pa, None, True)
        if not self.state.success:
            raise RuntimeError(f'robot {cfg.name!r}: no stable equilibrium at vent pressure: '
                               f'{self.state.message}')

    # ------------------------------------------------------------ physics
    def _solve(self, p: np.ndarray, warm: ForwardResult | None, check: bool) -> ForwardResult:
        self.solves += 1
        return solve_forward(self.model, p, payload_kg=self.payload_kg, warm_start=warm,
                             check_stability=check, tip_force_n=self.tip_force_n)

    def command(self, pressures_pa: Any) -> None:
        """Set the regulators' set-points [Pa] (clipped into the hardware limits)."""
        self.regulators.set_command(pressures_pa)

    def set_payload(self, payload_kg: float) -> None:
        """Change the payload [kg]; the next :meth:`step` solves the new equilibrium."""
        m = float(payload_kg)
        if not (math.isfinite(m) and m >= 0):
            raise ValueError(f'payload_kg must be a finite non-negative mass, got {payload_kg}')
        self.payload_kg = m

    def set_tip_force(self, force_n: Any) -> None:
        """Push the end effector with ``force_n`` [N, base frame]; the next :meth:`step` solves."""
        self.tip_force_n = tip_load(0.0, force_n).force_n

    def step(self, dt: float) -> ForwardResult:
        """Advance the regulators by ``dt`` and return the equilibrium at their pressures."""
        p = self.regulators.step(dt)
        self.time_s += float(dt)
        st = self.state
        if (np.max(np.abs(p - st.pressures_pa)) < RESOLVE_THRESHOLD_PA
                and st.load == (self.payload_kg, self.tip_force_n)):
            return st
        check = (self.solves % self.stability_every) == 0
        fw = self._solve(p, st, check)
        if fw.converged and fw.iterations > 8 and not check:   # continuation was needed
            fw = self._solve(p, st, True)
        if not fw.success:
            self.failures += 1
            self.last_failure = fw.message
            return st
        self.state = fw
        return fw

    # ------------------------------------------------------------ sensing
    @property
    def pressures_pa(self) -> np.ndarray:
        """Regulated (measured) pressures [Pa]."""
        return self.regulators.pressures_pa.copy()

    def true_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Exact end-effector ``(position (3,), rotation (3, 3))`` of the current equilibrium."""
        return self.state.position.copy(), self.state.rotation.copy()

    def measure(self) -> tuple[np.ndarray, np.ndarray]:
        """Motion-capture sample: ``(position, rotation)`` with Gaussian noise."""
        pos, R = self.true_pose()
        if self.position_noise_m > 0:
            pos = pos + self.rng.normal(0.0, self.position_noise_m, 3)
        if self.angle_noise_rad > 0:
            R = rotation_from_vector(self.rng.normal(0.0, self.angle_noise_rad, 3)) @ R
        return pos, R
