"""A simulated robot that is not the model: regulators, creep, dynamics, mocap.

Plays the real robot for the closed loop and the main demo, without ROS.
:class:`SimulatedRobot` chains

* :class:`~._regulators.PressureRegulators`: dead time, play hysteresis,
  first-order lag, slew and hardware limits per actuator;
* :class:`~._regulators.BellowCreep`: a part of each bellow's elongation
  follows a pressure change over seconds;
* the robot's motion: with ``effects.dynamics`` (the realistic default) the
  dynamic model of :mod:`bellow_ancf_ros.core.dynamics` (mass, Kelvin-Voigt
  damping of the robot file's ``dynamics.damping_time_s``, generalized-alpha
  steps of at most the default step inside each physics step, the
  effective pressures interpolated linearly across it); without it the
  quasi-static equilibrium (eq. 25, :func:`~bellow_ancf_ros.core.solve_forward`,
  warm-started from the previous one); either of the robot's *own* robot file
  (shipped examples: ``config/one_segment_mismatched.yaml``,
  ``config/two_segment_mismatched.yaml``, whose pitch radius, ``D_a``,
  stiffness and masses differ from the default model by 6-10 %) at a finer
  element count than the controller's model;
* :class:`~._motion_capture.MotionCapture`: the end-effector pose with noise,
  latency, outliers and dropouts (:meth:`SimulatedRobot.capture`), or with
  noise only (:meth:`SimulatedRobot.measure`), from one seeded generator.

Every effect is a field of :class:`~._plant_effects.PlantEffects` (defaults:
realistic hardware, with sources; ``PlantEffects.ideal()``: the clean robot
of earlier versions).  Pressures are gauge pressures in Pa throughout.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np

from ..dynamics import GeneralizedAlpha, PressureRamp, default_step, natural_modes
from ..geometry import rotation_from_vector, rotation_vector
from ..history import bracket
from ..model import (ConfigError, RobotConfig, RobotModel, TipLoad, load_robot,
                     shipped_robot_names, tip_load)
from ..solve import ForwardResult, solve_forward
from ._motion_capture import MocapSample, MotionCapture
from ._plant_effects import MIN_SAMPLES_PER_PERIOD, PlantEffects
from ._regulators import BellowCreep, PressureRegulators

__all__ = ['MISMATCHED', 'SimulatedRobot', 'simulated_robot_file']

#: ``<robot>`` + this names the shipped robot that is not ``<robot>``'s model.
MISMATCHED = '_mismatched'


def simulated_robot_file(name: str) -> tuple[RobotConfig, str | None]:
    """The simulated robot's own file for ``name``, and a note when it is not that file.

    ``<robot>_mismatched`` is the shipped robot that differs from
    ``<robot>``'s model (``one_segment_mismatched``,
    ``two_segment_mismatched``); where no such robot is shipped or on disk
    (``three_segment_mismatched``, ``lab/arm.yaml_mismatched``: what a
    launch's default makes of any ``robot_config``) the simulated robot is
    ``<robot>`` itself, and the note says so.  Any other name loads as it
    is; a :class:`ConfigError` of a file that exists is raised as it is.
    """
    try:
        return load_robot(name), None
    except ConfigError:
        base = name[:-len(MISMATCHED)] if name.endswith(MISMATCHED) else ''
        if not base or name in shipped_robot_names() or Path(name).expanduser().is_file():
            raise
    return load_robot(base), (f"robot_config '{name}': no such robot; simulating '{base}' "
                              'itself (no mismatch from the model)')


#: Effective pressures that moved less than this since the last equilibrium [Pa] reuse it.
RESOLVE_THRESHOLD_PA = 1.0
#: Past equilibria kept for delayed motion-capture samples [s].
POSE_HISTORY_S = 1.0
#: The integrator's iterations stop within this fraction of the robot's length (about 1e-8 m):
#: a tenth of the time discretisation's own error at the default step (some 1e-7 m), three
#: orders below the quietest motion capture.  1e-8 took 2.8 (one segment) and 3.4 (two)
#: iterations a step instead of 2.7 and 2.6, for end-effector paths 1 and 26 nm apart over 3 s
#: of changing commands.
ITERATION_TOL = 1e-7


class _Pose:
    """An end-effector pose of the history (what :meth:`SimulatedRobot.pose_at` reads)."""

    __slots__ = ('position', 'rotation')

    def __init__(self, position: np.ndarray, rotation: np.ndarray) -> None:
        self.position, self.rotation = position, rotation


class SimulatedRobot:
    """The simulated robot: regulators -> creep -> motion (or equilibrium) -> motion capture.

    Parameters
    ----------
    config : robot name, robot file path or :class:`RobotConfig` of the *robot*
        (not the controller's model); default the shipped
        ``one_segment_mismatched``.
    n_elements : ANCF elements per actuator; default the file's
        ``model.n_elements`` (12 in the shipped mismatched files, twice the
        model's 6).
    payload_kg : payload at the end effector [kg] (default: the file's).
    effects : :class:`PlantEffects` (default: realistic hardware;
        ``PlantEffects.ideal()`` for the clean robot).
    seed : seed of the motion capture's generator (None: a fresh random one).
    stability_every : run the stability check on every n-th equilibrium (and
        on any solve that needed continuation); it costs as much as the solve.

    Threads: :meth:`step` from one thread only; :meth:`measure`,
    :meth:`capture`, :meth:`command`, :meth:`set_payload` and
    :meth:`set_tip_force` may be called from others (the state, the
    set-points and the loads are replaced whole, never mutated; the pose
    history is locked).

    A failed equilibrium solve (not converged, or unstable when checked)
    keeps the last good state and is counted in :attr:`failures` with its
    message in :attr:`last_failure`: the robot never reports a configuration
    it could not compute.  With dynamics, a step the integrator cannot take
    is counted the same way, and the robot restarts at rest from the
    equilibrium at the pressures of that moment (a jump it reports).

    ``state``: the last equilibrium (quasi-static physics); with dynamics
    the vent equilibrium it started from, and :attr:`dynamics` holds the
    moving state (:class:`~bellow_ancf_ros.core.dynamics.GeneralizedAlpha`).
    ``first_mode_hz``: the robot's first natural frequency at the vent
    equilibrium with its payload (None without dynamics).
    """

    def __init__(self, config: Any = 'one_segment_mismatched', n_elements: int | None = None,
                 payload_kg: float | None = None, effects: PlantEffects | None = None,
                 seed: int | None = None, stability_every: int = 10) -> None:
        """Load the robot, solve its vent equilibrium (``RuntimeError`` if there is none)."""
        cfg = config if isinstance(config, RobotConfig) else load_robot(config)
        self.cfg = cfg
        self.effects = e = PlantEffects() if effects is None else effects
        self.model = RobotModel(cfg, n_elements=n_elements)
        self.payload_kg = float(cfg.payload if payload_kg is None else payload_kg)
        if not (math.isfinite(self.payload_kg) and self.payload_kg >= 0):
            raise ValueError(f'payload_kg must be a finite non-negative mass, got {payload_kg}')
        self.regulators = PressureRegulators(
            self.model.A, cfg.p_min, cfg.p_max, e.regulator_time_constant_s,
            e.regulator_slew_rate_pa_per_s, dead_time_s=e.regulator_dead_time_s,
            hysteresis_pa=e.regulator_hysteresis_pa)
        p0 = self.regulators.pressures_pa
        self.creep = (BellowCreep(self.model.stage1, e.creep_fraction, e.creep_time_constant_s,
                                  p0) if e.creep_fraction > 0 else None)
        self.mocap = MotionCapture(e, seed)
        self.stability_every = max(1, int(stability_every))
        self.tip_force_n = (0.0, 0.0, 0.0)  # a push on the end effector [N], set_tip_force
        self.failures = 0
        self.last_failure = ''
        self.solves = 0
        self.time_s = 0.0
        self._lock = threading.Lock()
        self._history: deque = deque()   # (time_s, ForwardResult) of past steps
        self.state: ForwardResult = self._solve(p0, None, True)
        if not self.state.success:
            raise RuntimeError(f'robot {cfg.name!r}: no stable equilibrium at vent pressure: '
                               f'{self.state.message}')
        self._p_eff = np.asarray(p0, dtype=float).copy()
        self.dynamics: GeneralizedAlpha | None = None
        self.first_mode_hz: float | None = None
        if e.dynamics:
            self.first_mode_hz = natural_modes(self.state, 1).first.frequency_hz
            self.dynamics = GeneralizedAlpha(self.model, step_s=default_step(self.first_mode_hz),
                                             tol=ITERATION_TOL)
            self.dynamics.start(self.state)
        self._pose = _Pose(self.state.position.copy(), self.state.rotation.copy())
        self._history.append((0.0, self._pose))

    @property
    def auto_physics_rate_hz(self) -> float:
        """The physics rate to use when none is given [Hz].

        With dynamics: 5 % above the slowest rate that resolves the first mode
        (:meth:`check_physics_rate`), at least 100 Hz; the integrator takes its
        own steps inside (two per physics step for the one-segment robot).  A
        node's physics step costs more than an integrator step (the tick, the
        clock, the publications): at one integrator step per physics step the
        one-segment node used 70 % of a core at rest, at this rate 35 %.
        Quasi-static: 100 Hz.
        """
        if self.dynamics is None:
            return 100.0
        return max(100.0, math.ceil(1.05 * self.effects.min_physics_rate_hz(
            self.first_mode_hz)))

    def check_physics_rate(self, rate_hz: float, name: str = 'physics_rate_hz') -> None:
        """Refuse a physics rate that does not resolve the first mode (one line, ValueError).

        The pose history the motion capture interpolates and the regulators'
        and creep's updates need :data:`MIN_SAMPLES_PER_PERIOD` steps per
        period of the robot's first mode (the integrator itself takes its
        own, shorter steps inside).
        """
        need = self.effects.min_physics_rate_hz(self.first_mode_hz or 0.0)
        if not float(rate_hz) >= need:
            raise ValueError(
                f'{name} = {float(rate_hz):g} is too coarse for this robot\'s first mode '
                f'({self.first_mode_hz:.3g} Hz); allowed: at least {need:.0f} Hz '
                f'({MIN_SAMPLES_PER_PERIOD} steps per period)')

    # ------------------------------------------------------------ physics
    def _solve(self, p: np.ndarray, warm: ForwardResult | None, check: bool) -> ForwardResult:
        self.solves += 1
        return solve_forward(self.model, p, payload_kg=self.payload_kg, warm_start=warm,
                             check_stability=check, tip_force_n=self.tip_force_n)

    def command(self, pressures_pa: Any, after_s: float = 0.0) -> None:
        """Hand set-points [Pa] to the regulators (clipped into the hardware limits).

        ``after_s``: they arrived this long after the robot's current time
        (between two steps), and take effect then (plus the dead time).
        """
        self.regulators.set_command(pressures_pa, after_s)

    def set_payload(self, payload_kg: float) -> None:
        """Change the payload [kg]; the next :meth:`step` solves the new equilibrium."""
        m = float(payload_kg)
        if not (math.isfinite(m) and m >= 0):
            raise ValueError(f'payload_kg must be a finite non-negative mass, got {payload_kg}')
        self.payload_kg = m

    def set_tip_force(self, force_n: Any) -> None:
        """Push the end effector with ``force_n`` [N, base frame]; the next :meth:`step` solves."""
        self.tip_force_n = tip_load(0.0, force_n).force_n

    def step(self, dt: float):
        """Advance regulators, creep and the robot by ``dt``.

        Returns the equilibrium at the effective pressures (quasi-static), or
        the integrator's state (dynamics).
        """
        p = self.regulators.step(dt)
        if self.creep is not None:
            p = self.creep.step(p, dt)
        t0 = self.time_s
        self.time_s += float(dt)
        if self.dynamics is None:
            st = self._equilibrium(p)
            pose = _Pose(st.position.copy(), st.rotation.copy())
        else:
            st = self._move(t0, self._p_eff, p)
            pos, rot = self.dynamics.end_effector()
            pose = _Pose(pos, rot)
        self._p_eff = p   # (a new array: the regulators' and the creep's outputs are)
        self._pose = pose
        with self._lock:
            self._history.append((self.time_s, pose))
            while len(self._history) > 2 and self._history[1][0] < self.time_s - POSE_HISTORY_S:
                self._history.popleft()
        return st

    def _move(self, t0: float, p0: np.ndarray, p1: np.ndarray):
        """Integrate the dynamics over ``[t0, self.time_s]``, pressures linear from p0 to p1."""
        ig = self.dynamics
        t1 = self.time_s
        rep = ig.advance(t1, pressures_pa=PressureRamp(t0, t1, p0, p1),
                         load=TipLoad(self.payload_kg, tuple(self.tip_force_n)))
        if not rep.success:
            self.failures += 1
            self.last_failure = rep.message
            fw = self._solve(p1, self.state, True)
            if fw.success:   # restart at rest at the equilibrium of these pressures
                self.state = fw
                ig.start(fw, t0=t1)
        return ig.state

    def _equilibrium(self, p: np.ndarray) -> ForwardResult:
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
        """Regulated pressures [Pa], as the regulators' sensors measure them."""
        return self.regulators.pressures_pa.copy()

    def true_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Exact end-effector ``(position (3,), rotation (3, 3))`` now."""
        pose = self._pose
        return pose.position.copy(), pose.rotation.copy()

    def pose_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Exact end-effector pose at robot time ``t``, interpolated between the steps around it.

        The robot moves continuously; its poses are computed at the
        physics steps.  Position: linear; rotation: along the geodesic.
        Before the oldest kept step: that step; after the newest: the newest.
        """
        with self._lock:
            before, after = bracket(self._history, t)
        if before is None:
            before = after
        if after is None or after[0] <= before[0]:
            return before[1].position.copy(), before[1].rotation.copy()
        a = (t - before[0]) / (after[0] - before[0])
        p0, p1 = before[1].position, after[1].position
        R0, R1 = before[1].rotation, after[1].rotation
        turn = rotation_vector(R0.T @ R1)
        return p0 + a * (p1 - p0), R0 @ rotation_from_vector(a * turn)

    def measure(self) -> tuple[np.ndarray, np.ndarray]:
        """The current pose with the motion capture's noise only: ``(position, rotation)``."""
        return self.mocap.noisy(*self.true_pose())

    def capture(self, now_s: float | None = None) -> MocapSample | None:
        """The motion-capture sample delivered at ``now_s``; None in a dropout.

        ``now_s``: robot time of the delivery (default: the last step's); the
        pose was captured one latency earlier.  Noise, latency, outliers and
        dropouts as set in :attr:`effects`; ``captured_s`` is robot time.
        """
        t = (self.time_s if now_s is None else float(now_s)) - self.effects.mocap_latency_s
        return self.mocap.observe(t, *self.pose_at(t))
