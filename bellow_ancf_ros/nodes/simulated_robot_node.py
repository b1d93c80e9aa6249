"""Simulated robot node: plays the real robot (regulators, physics, motion capture).

The physics is :class:`~bellow_ancf_ros.core.sim.SimulatedRobot`
(core, no ROS): pressure regulators (dead time, hysteresis, first-order lag,
slew limit, hardware limits) and creeping bellows drive the quasi-static
equilibrium of the node's *own* robot file, by default the shipped
``one_segment_mismatched`` ("a robot that is not the model"), at that file's
(finer) element count; a motion capture with noise, latency, outliers and
dropouts sees it.  Parameter ``plant``: ``realistic`` (the default; every
effect at the figures of real hardware, each its own parameter, see
:mod:`bellow_ancf_ros.core.sim._plant_effects` and docs/closed_loop.md)
or ``ideal`` (the clean robot of earlier versions: a 0.1 s first-order
regulator, motion capture at 100 Hz with noise only; the effect parameters
are then ignored).

Topics
------
subscribes
    ``pressure_command`` (std_msgs/Float64MultiArray): the regulators'
    set-points, gauge, in ``pressure_unit``; an array whose layout label names
    the other unit, has the wrong length, NaN/inf or values outside the
    robot's limits is refused (throttled warning, diagnostics WARN) and the
    last set-points stay.
publishes
    ``measured_pose`` (geometry_msgs/PoseStamped) in ``base_frame`` at
    ``mocap_rate_hz`` (default 120 Hz): the end-effector pose with Gaussian
    noise (``position_noise_mm``, default 0.15 mm per axis; ``angle_noise_deg``,
    default 0.1 deg per axis), captured ``mocap_latency_s`` before it is
    published and stamped with that capture time; outliers and dropouts as set;
    seeded by ``seed``.
    ``true_pose`` (geometry_msgs/PoseStamped, ``base_frame``) at the same
    rate: the exact pose of the newest physics step, stamped with that step's
    time: the simulator's ground truth (for evaluation, never for control).
    ``measured_pressure`` (std_msgs/Float64MultiArray, same layout and unit as
    the commands) at ``physics_rate_hz``, at most 100 Hz (every n-th physics
    step above it): the regulated pressures.
    ``/diagnostics``: 1 Hz status (solves, failed solves, refusals; the
    publishers of ``pressure_command`` matched, as a regulator driver sees
    them: ``command_publishers``), WARN per refused input, ERROR when an
    equilibrium could not be computed (the last state is kept and published).

services (std_srvs/Trigger)
    ``~/pause``, ``~/unpause``, ``~/step`` (``step_count`` physics steps, while
    paused; answered when they are taken), ``~/reset`` (the start state:
    vented, at rest, the payload and force of the parameters; the clock runs
    on).  Pause and step need ``publish_clock``.

The simulated robot as the clock (``publish_clock``, as Gazebo and Chrono::ROS
are): the physics takes fixed steps of ``1/physics_rate_hz`` of simulation
time, publishes ``/clock`` (rosgraph_msgs/Clock) after every step, and
stamps everything with simulation time, which starts at 0; nodes started
with ``use_sim_time:=true`` (the simulated robot itself too: its
``/diagnostics``) run on it.  ``real_time_factor`` paces it against the wall
clock (1: real time, 0: as fast as it can).  With ``lockstep``, a
participant that reports the time up to which it has done its work on
``lockstep_clock`` (under ``use_sim_time`` the inverse node does after each
``/clock`` tick, the trajectory publisher before each of its ticks, the
forward node once it has predicted from every ``measured_pressure`` sent,
the wrench estimator once it has taken them) holds
the simulation to it step by step, the slowest of them: their computation
takes no simulated time, and a participant slowed by a busy computer slows
the simulation instead of changing its result; one that stops says so and
holds it no longer.  A controller that reports nothing (a lab's own) is
followed by its commands: the simulation runs at most ``lockstep_period_s``
ahead of the newest ``pressure_command`` (the inverse node republishes
every 0.05 s).  After ``lockstep_timeout_s`` (wall) without either it
forgets the participants that held it back until they report again, and
runs free if none is left (counted on ``/diagnostics``).  The motion
capture, the regulators, creep, dropouts and outliers and the command
timeout run on simulation time; the motion capture delivers at exact
multiples of its period.

Without ``publish_clock`` the physics runs in its own thread at
``physics_rate_hz`` (default automatic: with dynamics 5 % above the slowest
rate that resolves the first mode, at least 100 Hz: 181 Hz for the
mismatched one-segment robot, 100 Hz for the two-segment one; else 100 Hz),
each step advancing the regulators, the creep and the robot by the measured
wall-clock time since the last one, so a slow machine gives coarser steps,
never a wrong time scale.  With ``dynamics`` (default, realistic plant) the
robot has inertia and damping (docs/dynamics.md): the integrator takes its
own steps (at most 1/40 of the first mode's period) inside a longer physics
step, and a physics rate below 20 steps per period of the robot's first mode
is refused at start-up.
"""

from __future__ import annotations

import math
from collections import deque
import threading
import time
from typing import Any


from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import ParameterType, SetParametersResult
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray, Header
from std_srvs.srv import Trigger

from ..core.sim import PlantEffects, SimulatedRobot, SimulationClock, simulated_robot_file
from ..core.model import MocapFrame
from ..core import geometry
from . import contract
from .diagnostics import Refusals, publish_diagnostic
from .lockstep import TOPIC as LOCKSTEP_TOPIC, report_of
from .ros_util import (
    Param,
    StartupParameterError,
    Topic,
    declare_all,
    descriptor,
    diagnostics_qos,
    main_for,
    pose_message,
    pressure_message,
)

__all__ = ['EFFECT_PARAMETERS', 'MAX_PRESSURE_RATE_HZ', 'STEP_TIMEOUT_S', 'SimulatedRobotNode',
           'main', 'plant_effects']

#: History its readings keep for a reliable reader that falls behind [messages]: a recorder on a
#: busy computer kept 22-93 of a run's 241-255 true poses with the writers' depth of 5.
SENSOR_HISTORY = 1000
#: Highest rate of measured_pressure [Hz] (a physics rate above it publishes every n-th step).
MAX_PRESSURE_RATE_HZ = 100.0

#: The hardware effects as node parameters: (name, PlantEffects field, scale to SI, default,
#: description, lowest, highest).  Defaults: :class:`PlantEffects`' realistic figures.
_R = PlantEffects()
EFFECT_PARAMETERS = (
    ('regulator_time_constant_s', 'regulator_time_constant_s', 1.0, _R.regulator_time_constant_s,
     'Pressure regulator time constant [s] (first-order lag).', 0.0, 10.0),
    ('regulator_dead_time_s', 'regulator_dead_time_s', 1.0, _R.regulator_dead_time_s,
     'Pressure regulator dead time [s] (a set-point acts this much later).', 0.0, 1.0),
    ('regulator_hysteresis_kpa', 'regulator_hysteresis_pa', 1e3,
     _R.regulator_hysteresis_pa / 1e3,
     'Pressure regulator hysteresis, the width of its play [kPa].', 0.0, 50.0),
    ('regulator_slew_rate_kpa_per_s', 'regulator_slew_rate_pa_per_s', 1e3,
     _R.regulator_slew_rate_pa_per_s / 1e3,
     'Pressure regulator slew-rate limit [kPa/s].', 1.0, 1e6),
    ('creep_fraction', 'creep_fraction', 1.0, _R.creep_fraction,
     'Part of the bellows\' elongation that creeps after a pressure change (0: none).',
     0.0, 0.9),
    ('creep_time_constant_s', 'creep_time_constant_s', 1.0, _R.creep_time_constant_s,
     'Time constant of the bellows\' creep [s].', 0.01, 600.0),
    ('mocap_rate_hz', 'mocap_rate_hz', 1.0, _R.mocap_rate_hz,
     'measured_pose rate [Hz] (motion capture).', 1.0, 1000.0),
    ('mocap_latency_s', 'mocap_latency_s', 1.0, _R.mocap_latency_s,
     'Motion-capture latency [s]: a pose is published this long after it was captured, '
     'stamped with its capture time.', 0.0, 1.0),
    ('position_noise_mm', 'position_noise_m', 1e-3, _R.position_noise_m * 1e3,
     'Motion-capture position noise, standard deviation per axis [mm].', 0.0, 100.0),
    ('angle_noise_deg', 'angle_noise_rad', math.pi / 180.0, math.degrees(_R.angle_noise_rad),
     'Motion-capture orientation noise, standard deviation per axis [deg].', 0.0, 45.0),
    ('mocap_outlier_probability', 'outlier_probability', 1.0, _R.outlier_probability,
     'Probability that a pose sample is an outlier (a swapped marker).', 0.0, 1.0),
    ('mocap_outlier_min_mm', 'outlier_min_m', 1e-3, _R.outlier_min_m * 1e3,
     'Smallest displacement of an outlier [mm].', 0.0, 1000.0),
    ('mocap_outlier_max_mm', 'outlier_max_m', 1e-3, _R.outlier_max_m * 1e3,
     'Largest displacement of an outlier [mm].', 0.0, 1000.0),
    ('mocap_dropout_every_s', 'dropout_every_s', 1.0, _R.dropout_every_s,
     'A dropout (no poses) starts every this long [s]; 0: none.', 0.0, 3600.0),
    ('mocap_dropout_duration_s', 'dropout_duration_s', 1.0, _R.dropout_duration_s,
     'Length of a dropout [s]; 0: none.', 0.0, 60.0),
)
#: Longest wait of a ~/step call for its steps [wall s] (they go on after it).
STEP_TIMEOUT_S = 30.0
#: Parameters that still apply to the ideal plant (noise, slew).
_IDEAL_KEEPS = ('position_noise_mm', 'angle_noise_deg', 'regulator_slew_rate_kpa_per_s')


def plant_effects(get) -> PlantEffects:
    """The :class:`PlantEffects` of the node's parameters (``get``: name -> parameter).

    Raises :class:`StartupParameterError` naming the parameter for a bad
    ``plant`` or an inconsistent combination (e.g. a dropout as long as its
    period).
    """
    plant = get('plant').value
    if plant not in ('realistic', 'ideal'):
        raise StartupParameterError('plant', plant, "'realistic' or 'ideal'")
    values = {field: scale * float(get(name).value)
              for name, field, scale, *_ in EFFECT_PARAMETERS
              if plant == 'realistic' or name in _IDEAL_KEEPS}
    if plant == 'realistic':
        values['dynamics'] = bool(get('dynamics').value)
    if plant == 'realistic':   # the pairs, in the node's own units
        lo, hi = get('mocap_outlier_min_mm').value, get('mocap_outlier_max_mm').value
        if hi < lo:
            raise StartupParameterError('mocap_outlier_max_mm', hi,
                                        f'at least mocap_outlier_min_mm ({lo:g})')
        dur, every = get('mocap_dropout_duration_s').value, get('mocap_dropout_every_s').value
        if dur > 0 and every > 0 and dur >= every:
            raise StartupParameterError('mocap_dropout_duration_s', dur,
                                        f'shorter than mocap_dropout_every_s ({every:g})')
    try:
        return PlantEffects(**values) if plant == 'realistic' else PlantEffects.ideal(**values)
    except ValueError as exc:
        field, reason = str(exc).replace('plant setting ', '').split(': ', 1)
        name = next((n for n, f, *_ in EFFECT_PARAMETERS if f == field), field)
        for n, f, *_ in EFFECT_PARAMETERS:   # the reason in the node's own names
            reason = reason.replace(f'{f} (', f'{n} (')
        raise StartupParameterError(name, get(name).value, "see the parameter's description",
                                    reason) from None


def _simulation_clock(get, rate_hz: float, log) -> SimulationClock | None:
    """The :class:`SimulationClock` of ``publish_clock`` and its settings, or None (wall clock).

    ``real_time_factor`` and ``lockstep`` away from their defaults without
    ``publish_clock`` do nothing: ``log`` says so (a launch passes them whether
    or not it runs on simulation time).
    """
    if not get('publish_clock').value:
        ignored = [f'{name} = {get(name).value}' for name, default in
                   (('real_time_factor', 1.0), ('lockstep', False), ('start_paused', False))
                   if get(name).value != default]
        if ignored:
            log(f'{", ".join(ignored)} ignored: without publish_clock the simulation runs on '
                'the wall clock')
        return None
    clock = SimulationClock(1.0 / rate_hz, float(get('real_time_factor').value),
                            float(get('lockstep_period_s').value) if get('lockstep').value
                            else None, float(get('lockstep_timeout_s').value))
    if get('start_paused').value:
        clock.pause()
    return clock


def _stamp(t: float):
    """Simulation time ``t`` [s] as a message stamp."""
    return Time(nanoseconds=int(round(t * 1e9))).to_msg()


D, S, INT, A, B = (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_STRING,
                   ParameterType.PARAMETER_INTEGER, ParameterType.PARAMETER_DOUBLE_ARRAY,
                   ParameterType.PARAMETER_BOOL)
_RO = {'read_only': True}
#: The node's parameters: what it declares and what ``--help`` prints.
PARAMETERS = (
    Param('robot_config', 'one_segment_mismatched', descriptor(
        "The simulated robot's own description (shipped name or YAML path); default the "
        'mismatched one-segment example, a robot that is not the model.', S, **_RO)),
    Param('n_elements', 0, descriptor(
        "ANCF elements per actuator of the simulation; 0 = the robot file's.", INT, lo=0, hi=60,
        **_RO)),
    Param('payload_kg', 0.0, descriptor(
        'Payload the simulated robot carries [kg] (settable at run time).', D,
        lo=0.0, hi=contract.PAYLOAD_MAX_KG)),
    Param('tip_force_n', [0.0, 0.0, 0.0], descriptor(
        'A force pushing the end effector [N, base frame, 3 numbers] (settable at run '
        'time: a push, a tool pressing on a surface; the controller is not told).', A)),
    Param('base_frame', 'base', descriptor(
        'frame_id of measured_pose (unless mocap_frame_id is set).', S, **_RO)),
    Param('mocap_frame_id', '', descriptor(
        'Publish measured_pose in this motion-capture frame instead of base_frame (empty: '
        'base_frame); the base sits in it at mocap_position_m, mocap_quaternion_xyzw.', S,
        **_RO)),
    Param('mocap_position_m', [0.0, 0.0, 0.0], descriptor(
        'Position of the base frame in the mocap frame [m] (3 numbers).', A, **_RO)),
    Param('mocap_quaternion_xyzw', [0.0, 0.0, 0.0, 1.0], descriptor(
        'Orientation of the base frame in the mocap frame (x, y, z, w).', A, **_RO)),
    Param('pressure_unit', 'Pa', descriptor(
        'Unit of pressure_command and measured_pressure: Pa or kPa (gauge).', S,
        constraints="one of: 'Pa', 'kPa'", **_RO)),
    Param('plant', 'realistic', descriptor(
        "'realistic': every hardware effect below at its parameter; 'ideal': the clean "
        'robot (0.1 s first-order regulators, mocap 100 Hz with noise only; the effect '
        'parameters are ignored).', S, constraints="one of: 'realistic', 'ideal'", **_RO)),
) + tuple(Param(name, default, descriptor(text, D, lo=lo, hi=hi, **_RO))
          for name, _field, _scale, default, text, lo, hi in EFFECT_PARAMETERS) + (
    Param('dynamics', True, descriptor(
        "The robot's inertia and damping (the robot file's dynamics.damping_time_s): it "
        'swings and rings; false: it jumps from equilibrium to equilibrium.  Realistic '
        'plant only (the ideal plant is quasi-static).', B, **_RO)),
    Param('physics_rate_hz', 0.0, descriptor(
        'Regulator, creep and robot update rate [Hz]; also the measured_pressure rate (at '
        'most 100 Hz).  0 = automatic: with dynamics 5 % above the slowest rate that '
        'resolves the first mode (at least 100 Hz; the integrator steps inside), else '
        '100 Hz.  With dynamics a rate must resolve the first mode: at least 20 steps per '
        'period (checked at start).', D,
        lo=0.0, hi=1000.0, **_RO)),
    Param('command_timeout_s', 0.0, descriptor(
        'Vent (regulators to 0 Pa gauge) when no pressure_command arrived for this long [s], '
        'as a regulator driver does (the inverse node republishes at command_rate_hz); '
        '0 = off (a bench fed single commands).', D, lo=0.0, hi=60.0, **_RO)),
    Param('seed', -1, descriptor('Seed of the noise generator; -1 = random.', INT,
                                 lo=-1, hi=2**31 - 1, **_RO)),
    Param('publish_clock', False, descriptor(
        'Be the clock: fixed physics steps of simulation time, /clock after each, every stamp '
        'in simulation time (run the other nodes with use_sim_time:=true).', B, **_RO)),
    Param('real_time_factor', 1.0, descriptor(
        'With publish_clock: simulated seconds per wall second (1: real time; 0: as fast as '
        'the computer and the nodes allow).', D, lo=0.0, hi=1000.0, **_RO)),
    Param('lockstep', False, descriptor(
        'With publish_clock: run at most lockstep_period_s ahead of the newest '
        'pressure_command (a slow computer slows the simulation, not its result).', B, **_RO)),
    Param('lockstep_period_s', 0.1, descriptor(
        'How far the simulation may run ahead of the newest command [s of simulation time] '
        "(two periods of the inverse node's 20 Hz keepalive).", D, lo=0.001, hi=10.0, **_RO)),
    Param('lockstep_timeout_s', 1.0, descriptor(
        'Wall seconds lockstep waits for a command before it runs free until the next one '
        '(a stopped controller; counted on /diagnostics).', D, lo=0.01, hi=60.0, **_RO)),
    Param('start_paused', False, descriptor(
        'With publish_clock: start paused at time 0 (~/unpause starts it), so that every '
        'node is up before the first step (as Gazebo started paused).', B, **_RO)),
    Param('step_count', 1, descriptor(
        'Physics steps one ~/step call takes (settable at run time).', INT, lo=1,
        hi=1_000_000)),
)
TOPICS = (
    Topic('subscribes', 'pressure_command', 'std_msgs/Float64MultiArray',
          "the regulators' set-points, gauge, in pressure_unit"),
    Topic('publishes', 'measured_pose', 'geometry_msgs/PoseStamped',
          'the motion capture: noise, latency, outliers, dropouts'),
    Topic('publishes', 'true_pose', 'geometry_msgs/PoseStamped', 'the exact pose (ground truth)'),
    Topic('publishes', 'measured_pressure', 'std_msgs/Float64MultiArray',
          'the regulated pressures, at physics_rate_hz (at most 100 Hz)'),
    Topic('publishes', '/diagnostics', 'diagnostic_msgs/DiagnosticArray', '1 Hz status'),
    Topic('publishes', '/clock', 'rosgraph_msgs/Clock',
          'simulation time, after every physics step (publish_clock)'),
    Topic('subscribes', 'lockstep_clock', 'std_msgs/Header',
          "lockstep: a participant's work done until stamp (frame_id: its node)"),
    Topic('services', '~/pause', 'std_srvs/Trigger', 'stop the simulation (publish_clock)'),
    Topic('services', '~/unpause', 'std_srvs/Trigger', 'run it again'),
    Topic('services', '~/step', 'std_srvs/Trigger', 'take step_count physics steps, paused'),
    Topic('services', '~/reset', 'std_srvs/Trigger', 'the start state, vented'),
)


class SimulatedRobotNode(Node):
    """Subscribes pressure commands, publishes measured pose and pressures of a simulated robot."""

    NODE_NAME = 'simulated_robot_node'
    PARAMETERS = PARAMETERS
    TOPICS = TOPICS

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        """Declare the parameters, build the robot, start the physics thread and timers."""
        super().__init__(node_name, **kwargs)
        declare_all(self, PARAMETERS)
        g = self.get_parameter
        unit = g('pressure_unit').value
        contract.check_unit(unit)
        cfg, note = simulated_robot_file(g('robot_config').value)   # ConfigError: no start
        if note is not None:
            self.get_logger().warning(note)
        seed = int(g('seed').value)
        self.cfg, self._unit, self._frame = cfg, unit, g('base_frame').value
        self._robot_args = dict(n_elements=int(g('n_elements').value) or None,
                                effects=plant_effects(g), seed=None if seed < 0 else seed)
        self.robot = self._new_robot()
        rate = float(g('physics_rate_hz').value) or self.robot.auto_physics_rate_hz
        try:
            self.robot.check_physics_rate(rate)
        except ValueError:
            need = self.robot.effects.min_physics_rate_hz(self.robot.first_mode_hz or 0.0)
            raise StartupParameterError(
                'physics_rate_hz', rate, f'at least {need:.0f} Hz',
                f'too coarse for the robot\'s first mode ({self.robot.first_mode_hz:.3g} Hz; '
                f'20 steps per period)') from None
        self._mocap_frame = None   # MocapFrame: the base's pose in the mocap frame
        if g('mocap_frame_id').value:
            pos_m, quat = list(g('mocap_position_m').value), list(g('mocap_quaternion_xyzw').value)
            if len(pos_m) != 3 or not all(map(math.isfinite, pos_m)):
                raise StartupParameterError('mocap_position_m', pos_m, '3 finite numbers [m]',
                                            'not 3 finite numbers')
            try:
                self._mocap_frame = MocapFrame(g('mocap_frame_id').value, pos_m, quat)
            except ValueError as exc:
                raise StartupParameterError('mocap_quaternion_xyzw', quat,
                                            'a non-zero quaternion (x, y, z, w)', str(exc))
        # (INFO: a launch passes them on the wall clock too; a WARN there was noise in every
        # `sim:=true use_sim_time:=false` launch)
        self.clock = _simulation_clock(g, rate, self.get_logger().info)   # None: wall clock
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.stats = {'received': 0, 'refused': 0, 'published_poses': 0, 'failed_solves': 0,
                      'timeouts': 0, 'dropped_poses': 0, 'outliers': 0, 'resets': 0}
        self._timeouts_said = 0   # lockstep timeouts logged so far
        self._timeout_s = float(g('command_timeout_s').value)
        self._last_cmd_t: float | None = None
        self._commands: deque = deque()   # (pressures, arrival time): for the physics thread
        # held while the physics steps or a reset replaces the robot
        self._step_lock = threading.Lock()
        self._t_offset = 0.0   # simulation time of the robot's time 0 (the last reset's)
        self.last_refusal_reason = ''
        qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_LAST, depth=SENSOR_HISTORY)
        self._pub_pose = self.create_publisher(PoseStamped, 'measured_pose', qos)
        self._pub_true = self.create_publisher(PoseStamped, 'true_pose', qos)
        self._pub_p = self.create_publisher(Float64MultiArray, 'measured_pressure', qos)
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', diagnostics_qos())
        self._pub_clock = (self.create_publisher(Clock, '/clock', 10)
                           if self.clock is not None else None)
        self._refusals = Refusals(self, 'pressures', self._publish_diag)
        self._sub = self.create_subscription(Float64MultiArray, 'pressure_command',
                                             self._on_command, qos)
        if self.clock is not None and self.clock.lockstep_period_s is not None:
            self._sub_done = self.create_subscription(Header, LOCKSTEP_TOPIC,
                                                      self._on_lockstep, 10)
            self.clock.received_here(self._sub.topic_name, 0)   # commands are owed to it
        for name, handler in (('pause', self._on_pause), ('unpause', self._on_unpause),
                              ('step', self._on_step), ('reset', self._on_reset)):
            self.create_service(Trigger, f'~/{name}', handler)
        self._mocap_timer = (self.create_timer(1.0 / self.robot.effects.mocap_rate_hz,
                                               self._mocap) if self.clock is None else None)
        self._diag_timer = self.create_timer(1.0, self._status)
        self._factor_since = (time.monotonic(), 0.0)   # (wall, simulated) of the last status
        self._started = time.monotonic()
        self._stop = threading.Event()
        self._state_stamp = self.get_clock().now()   # when the robot reached its state
        self._physics_period = 1.0 / rate
        # measured_pressure at most MAX_PRESSURE_RATE_HZ: a regulator's sensor, not every step
        self._pressure_every = max(1, math.ceil(rate / MAX_PRESSURE_RATE_HZ - 1e-9))
        self._thread = threading.Thread(
            target=self._wall_loop if self.clock is None else self._clock_loop,
            name='physics', daemon=True)
        self._thread.start()
        e = self.robot.effects
        c = self.clock
        self.get_logger().info(
            f'simulating robot {cfg.name!r} ({self.robot.model.A} actuators, '
            f'{self.robot.model.n} elements per actuator), {g("plant").value} plant: '
            f'regulators tau {e.regulator_time_constant_s:g} s, dead time '
            f'{e.regulator_dead_time_s:g} s, hysteresis {e.regulator_hysteresis_pa / 1e3:g} kPa; '
            f'creep {e.creep_fraction:g} over {e.creep_time_constant_s:g} s; mocap '
            f'{e.mocap_rate_hz:g} Hz, latency {e.mocap_latency_s:g} s, '
            f'{e.position_noise_m * 1e3:g} mm noise, outliers {e.outlier_probability:g}, '
            f'dropouts {e.dropout_duration_s:g} s every {e.dropout_every_s:g} s; '
            + (f'dynamics: first mode {self.robot.first_mode_hz:.3g} Hz, damping time '
               f'{self.robot.dynamics.inertia.damping_time * 1e3:g} ms, step '
               f'{self.robot.dynamics.step_s * 1e3:.3g} ms; ' if self.robot.dynamics else
               'quasi-static; ')
            + f'physics {rate:g} Hz; commands in {unit}; '
            + ('wall clock' if c is None else
               f'publishing /clock, real-time factor {c.real_time_factor:g}'
               + (f', lockstep {c.lockstep_period_s:g} s' if c.lockstep_period_s else '')
               + (', paused until ~/unpause' if c.paused else '')))

    def _new_robot(self) -> SimulatedRobot:
        """The simulated robot at its start state: vented, at rest, the parameters' loads."""
        g = self.get_parameter
        robot = SimulatedRobot(self.cfg, payload_kg=contract.validate_payload(
            g('payload_kg').value), **self._robot_args)
        try:
            robot.set_tip_force(list(g('tip_force_n').value))
        except ValueError as exc:
            raise StartupParameterError('tip_force_n', list(g('tip_force_n').value),
                                        'three finite numbers [N], at most 1000 N',
                                        str(exc)) from None
        return robot

    # ------------------------------------------------------------ params
    def _on_set_parameters(self, params) -> SetParametersResult:
        for p in params:
            if p.name == 'payload_kg':
                reason = contract.parameter_problem('payload_kg', p.value)
                if reason:
                    self.get_logger().warning(f'refused parameter change: {reason}')
                    return SetParametersResult(successful=False, reason=reason)
                self.robot.set_payload(float(p.value))
            elif p.name == 'tip_force_n':
                try:
                    self.robot.set_tip_force(list(p.value))
                except ValueError as exc:
                    self.get_logger().warning(f'refused parameter change: {exc}')
                    return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------ input
    def _on_lockstep(self, msg) -> None:
        who, t, sent, received = report_of(msg)
        if t is None:
            self.clock.leave(who)
        else:
            self.clock.done_until(t, who, sent, received)

    def _on_command(self, msg: Float64MultiArray) -> None:
        self.stats['received'] += 1
        if self.clock is not None:   # (the lockstep's count of the commands owed to it)
            self.clock.received_here(self._sub.topic_name)
        label = msg.layout.dim[0].label if len(msg.layout.dim) else None
        try:
            p = contract.validate_pressure_input(msg.data, self._unit, self.robot.model.A,
                                                 self.cfg.p_min, self.cfg.p_max, label)
        except contract.InputError as exc:
            self.stats['refused'] += 1
            self.last_refusal_reason = str(exc)
            self._refusals.report(str(exc), self.stats['refused'])
            return
        if self.clock is not None:   # arrives at the simulation's time now
            now = self.clock.time_s
            self._commands.append((p, now))
            self._last_cmd_t = now
            self.clock.command_arrived()
            return
        now = time.monotonic()
        # handed to the physics thread with its arrival time: it takes effect then (plus the
        # dead time), not at a physics tick (a shaped step's levels would land on its grid)
        self._commands.append((p, now))
        self._last_cmd_t = now

    # ------------------------------------------------------------ physics
    def _physics_step(self, now: float, last: float) -> None:
        """Commands, the command timeout, one step of the robot from ``last`` to ``now``.

        Times on the physics' clock: monotonic wall seconds, or simulation
        seconds with ``publish_clock``.  Called with the step lock held.
        """
        t_cmd = self._last_cmd_t
        if self._timeout_s > 0 and t_cmd is not None and now - t_cmd > self._timeout_s:
            self._last_cmd_t = None   # vent once, as a driver does
            self.robot.command(contract.vent_pressures(self.robot.model.A, self.cfg.p_min,
                                                       self.cfg.p_max))
            self.stats['timeouts'] += 1
            self.get_logger().warning(f'vented: no pressure_command for '
                                      f'{self._timeout_s:g} s (controller dead or stopped)')
        while self._commands:   # in the order they arrived, each at its time
            p_cmd, t_arr = self._commands.popleft()
            self.robot.command(p_cmd, min(max(t_arr - last, 0.0), now - last))
        failures = self.robot.failures
        self.robot.step(now - last)   # only the physics thread steps the robot
        if self.robot.failures > failures:
            self.stats['failed_solves'] += 1
            msg = (f'robot state not computed ({self.robot.last_failure}); last state kept'
                   if self.robot.dynamics is None else
                   f'dynamics step failed ({self.robot.last_failure}); restarted at rest')
            self.get_logger().error(msg, throttle_duration_sec=2.0)
            self._publish_diag(DiagnosticStatus.ERROR, msg, {})

    def _wall_loop(self) -> None:
        last = time.monotonic()   # the instant the robot's state is at
        next_t = last
        tick = 0
        while not self._stop.is_set():
            next_t += self._physics_period
            wait = next_t - time.monotonic()
            if wait > 0:
                self._stop.wait(wait)
            else:
                next_t = time.monotonic()   # running late: no catch-up burst
            now = time.monotonic()
            with self._step_lock:
                self._physics_step(now, last)
                p = self.robot.pressures_pa
            # the state is the robot's at `now` (the tick), not when its computation ended
            self._state_stamp = self.get_clock().now() - Duration(
                nanoseconds=int((time.monotonic() - now) * 1e9))
            last = now
            tick += 1
            if tick % self._pressure_every == 0 and not self._publish_pressures(p):
                return

    def _clock_loop(self) -> None:
        clock, dt = self.clock, self.clock.step_s
        e = self.robot.effects
        mocap_dt = 1.0 / e.mocap_rate_hz
        # deliveries at exact multiples of the period, the first one latency after the start
        k_mocap = max(1, math.ceil(e.mocap_latency_s / mocap_dt - 1e-9))
        self._publish_clock(0.0)
        while clock.wait_for_step():
            last = clock.time_s
            now = last + dt
            with self._step_lock:
                self._physics_step(now, last)
                clock.advanced()
                now = clock.time_s   # steps times the step: no accumulated rounding
                while k_mocap * mocap_dt <= now + 1e-9:
                    self._deliver(k_mocap * mocap_dt)
                    k_mocap += 1
                p = self.robot.pressures_pa
            if not self._publish_clock(now):
                return
            if clock.steps % self._pressure_every == 0 and not self._publish_pressures(p):
                return

    def _publish_clock(self, t: float) -> bool:
        msg = Clock()
        msg.clock = _stamp(t)
        try:
            self._pub_clock.publish(msg)
        except Exception:  # noqa: BLE001 - publisher gone at shutdown
            return False
        return True

    def _publish_pressures(self, p) -> bool:
        try:
            self._pub_p.publish(pressure_message(p, self._unit))
        except Exception:  # noqa: BLE001 - publisher gone at shutdown
            return False
        if self.clock is not None and self.clock.lockstep_period_s is not None:
            # owed to a participant that counts them (the forward node): no step until taken
            self.clock.sent_here(self._pub_p.topic_name)
        return True

    def _deliver(self, t: float) -> None:
        """The motion capture's delivery at simulation time ``t`` (the step lock held)."""
        t_robot = t - self._t_offset
        pos, R = self.robot.pose_at(t_robot)
        self._publish_poses(pos, R, _stamp(t), self.robot.capture(t_robot),
                            lambda captured: _stamp(captured + self._t_offset))

    def _mocap(self) -> None:
        # the newest complete state (no lock needed) and when it was reached, on the ROS clock
        state_t, state_stamp = self.robot.time_s, self._state_stamp
        pos, R = self.robot.true_pose()
        self._publish_poses(pos, R, state_stamp.to_msg(), self.robot.capture(state_t),
                            lambda captured: (state_stamp - Duration(nanoseconds=int(
                                (state_t - captured) * 1e9))).to_msg())

    def _publish_poses(self, pos, R, stamp, sample, capture_stamp) -> None:
        """``true_pose`` (``pos``, ``R`` at ``stamp``), and ``sample`` on ``measured_pose``.

        ``sample``: the motion capture's (None: a dropout); stamped with
        ``capture_stamp(sample.captured_s)``.
        """
        try:
            self._pub_true.publish(pose_message(pos, geometry.quaternion_from_rotation(R),
                                                self._frame, stamp))
        except Exception:  # noqa: BLE001 - publisher gone at shutdown
            return
        if sample is None:   # a dropout: the motion capture delivers nothing
            self.stats['dropped_poses'] += 1
            return
        pos, R = sample.position, sample.rotation
        frame = self._frame
        if self._mocap_frame is not None:   # as a motion capture in its own frame sees it
            frame = self._mocap_frame.frame_id
            pos, R = self._mocap_frame.from_base(pos, R)
        self._pub_pose.publish(pose_message(pos, geometry.quaternion_from_rotation(R), frame,
                                            capture_stamp(sample.captured_s)))
        self.stats['published_poses'] += 1
        self.stats['outliers'] += int(sample.outlier)

    # ------------------------------------------------------------ services
    def _needs_clock(self, resp):
        resp.success = False
        resp.message = ('needs publish_clock: true (this simulation runs on the wall clock)')
        return resp

    def _on_pause(self, _req, resp):
        if self.clock is None:
            return self._needs_clock(resp)
        self.clock.pause()
        resp.success, resp.message = True, f'paused at {self.clock.time_s:.6f} s'
        self.get_logger().info(resp.message)
        return resp

    def _on_unpause(self, _req, resp):
        if self.clock is None:
            return self._needs_clock(resp)
        self.clock.unpause()
        resp.success, resp.message = True, f'running from {self.clock.time_s:.6f} s'
        self.get_logger().info(resp.message)
        return resp

    def _on_step(self, _req, resp):
        if self.clock is None:
            return self._needs_clock(resp)
        n = int(self.get_parameter('step_count').value)
        try:
            target = self.clock.step(n)
        except ValueError as exc:
            resp.success, resp.message = False, str(exc)
            return resp
        done = self.clock.wait_until(target, STEP_TIMEOUT_S)
        resp.success = done
        resp.message = (f'{n} steps taken: {self.clock.time_s:.6f} s' if done else
                        f'{n} steps asked, not all taken in {STEP_TIMEOUT_S:g} s: '
                        f'{self.clock.time_s:.6f} s (they go on)')
        return resp

    def _on_reset(self, _req, resp):
        with self._step_lock:
            try:
                robot = self._new_robot()
            except (ValueError, RuntimeError) as exc:
                resp.success, resp.message = False, f'not reset: {exc}'
                return resp
            self.robot = robot
            self._commands.clear()
            self._last_cmd_t = None
            self._t_offset = self.clock.time_s if self.clock is not None else 0.0
            self.stats['resets'] += 1
        resp.success = True
        resp.message = ('reset to the start state (vented, at rest)'
                        + (f' at {self._t_offset:.6f} s' if self.clock is not None else ''))
        self.get_logger().info(resp.message)
        return resp

    def _status(self) -> None:
        level = DiagnosticStatus.WARN if self.stats['failed_solves'] else DiagnosticStatus.OK
        p, solves, payload = self.robot.pressures_pa, self.robot.solves, self.robot.payload_kg
        values = dict(self.stats, solves=solves, payload_kg=payload,
                      dynamics=self.robot.dynamics is not None,
                      first_mode_hz=self.robot.first_mode_hz or 0.0,
                      command_publishers=self._sub.get_publisher_count(),
                      tip_force_n=' '.join(f'{v:g}' for v in self.robot.tip_force_n),
                      pressures=' '.join(f'{v:.6g}' for v in contract.to_unit(p, self._unit)))
        c, message = self.clock, 'simulating'
        if c is not None:
            factor, self._factor_since = c.measured_factor(self._factor_since)
            values.update(simulation_time_s=f'{c.time_s:.6f}', paused=c.paused,
                          real_time_factor=c.real_time_factor,
                          achieved_real_time_factor=f'{factor:.3g}',
                          lockstep_waits=c.lockstep_waits,
                          lockstep_timeouts=c.lockstep_timeouts,
                          lockstep_wait_s=f'{c.lockstep_wait_s:.3f}')
            message = ('paused' if c.paused else
                       f'simulating at {factor:.3g}x real time' if math.isfinite(factor)
                       else message)
            if c.lockstep_timeouts > self._timeouts_said:
                self._timeouts_said = c.lockstep_timeouts
                t, behind, owing = c.last_timeout
                self.get_logger().warn(
                    f'lockstep: waited {c.lockstep_timeout_s:g} s (wall) at {t:.3f} s for '
                    + ', '.join([f'{w} (its report)' for w in behind]
                                + [f'{w or "this node"} (a message owed)' for w in owing])
                    + f'; ran on without it ({c.lockstep_timeouts} timeouts so far)')
        self._publish_diag(level, message, values)

    def _publish_diag(self, level: bytes, message: str, values: dict) -> None:
        publish_diagnostic(self, self._pub_diag, f'{self.get_name()}: simulated robot',
                           self.cfg.name, level, message, values)

    def destroy_node(self):
        """Stop the physics thread, then destroy the node."""
        self._stop.set()
        c = self.clock
        if c is not None:
            c.stop()
            wall = time.monotonic() - self._started
            self.get_logger().info(
                f'simulated {c.time_s:.3f} s in {wall:.3f} s of wall time ('
                f'{c.time_s / wall if wall > 0 else float("nan"):.3g}x real time); lockstep: '
                f'{c.lockstep_waits} waits for a command, {c.lockstep_wait_s:.3f} s waited, '
                f'{c.lockstep_timeouts} timeouts')
        self._thread.join(5.0)
        return super().destroy_node()


main = main_for(SimulatedRobotNode)


if __name__ == '__main__':
    main()
