"""Simulated robot node: plays the real robot (regulators, physics, motion capture).

The physics is :class:`~bellow_ancf_ros.core.control.SimulatedRobot`
(core, no ROS): pressure regulators (first-order lag, slew limit, hardware
limits) drive the quasi-static equilibrium of the node's *own* robot file,
by default the shipped ``one_segment_mismatched`` ("a robot that is not the
model"), at that file's (finer) element count.

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
    ``mocap_rate_hz`` (default 100 Hz): the end-effector pose with Gaussian
    noise (``position_noise_mm``, default 0.15 mm per axis; ``angle_noise_deg``,
    default 0.1 deg per axis), seeded by ``seed``.
    ``measured_pressure`` (std_msgs/Float64MultiArray, same layout and unit as
    the commands) at ``physics_rate_hz``: the regulated pressures.
    ``/diagnostics``: 1 Hz status (solves, failed solves, refusals), WARN per
    refused input, ERROR when an equilibrium could not be computed (the last
    state is kept and published).

The physics runs in its own thread at ``physics_rate_hz`` (default 50 Hz),
each step advancing the regulators by the measured wall-clock time since the
last one, so a slow machine gives coarser steps, never a wrong time scale.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any


from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import IntegerRange, ParameterType, SetParametersResult
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from ..core import load_robot
from ..core.control import SimulatedRobot
from ..core.model import MocapFrame
from ..core import geometry
from . import contract
from .diagnostics import Refusals, publish_diagnostic
from .ros_util import (
    StartupParameterError,
    command_qos,
    descriptor,
    diagnostics_qos,
    main_for,
    pose_message,
    pressure_message,
)

__all__ = ['SimulatedRobotNode', 'main']


class SimulatedRobotNode(Node):
    """Subscribes pressure commands, publishes measured pose and pressures of a simulated robot."""

    def __init__(self, node_name: str = 'simulated_robot_node', **kwargs: Any) -> None:
        """Declare the parameters, build the robot, start the physics thread and timers."""
        super().__init__(node_name, **kwargs)
        D, S, INT = (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_STRING,
                     ParameterType.PARAMETER_INTEGER)
        ro = {'read_only': True}
        self.declare_parameter('robot_config', 'one_segment_mismatched', descriptor(
            "The simulated robot's own description (shipped name or YAML path); default the "
            'mismatched one-segment example, a robot that is not the model.', S, **ro))
        d = descriptor('ANCF elements per actuator of the simulation; 0 = the robot file\'s.', INT,
                       **ro)
        d.integer_range = [IntegerRange(from_value=0, to_value=60, step=1)]
        self.declare_parameter('n_elements', 0, d)
        self.declare_parameter('payload_kg', 0.0, descriptor(
            'Payload the simulated robot carries [kg] (settable at run time).', D,
            lo=0.0, hi=contract.PAYLOAD_MAX_KG))
        self.declare_parameter('tip_force_n', [0.0, 0.0, 0.0], descriptor(
            'A force pushing the end effector [N, base frame, 3 numbers] (settable at run '
            'time: a push, a tool pressing on a surface; the controller is not told).',
            ParameterType.PARAMETER_DOUBLE_ARRAY))
        self.declare_parameter('base_frame', 'base', descriptor(
            'frame_id of measured_pose (unless mocap_frame_id is set).', S, **ro))
        self.declare_parameter('mocap_frame_id', '', descriptor(
            'Publish measured_pose in this motion-capture frame instead of base_frame (empty: '
            'base_frame); the base sits in it at mocap_position_m, mocap_quaternion_xyzw.', S,
            **ro))
        A = ParameterType.PARAMETER_DOUBLE_ARRAY
        self.declare_parameter('mocap_position_m', [0.0, 0.0, 0.0], descriptor(
            'Position of the base frame in the mocap frame [m] (3 numbers).', A, **ro))
        self.declare_parameter('mocap_quaternion_xyzw', [0.0, 0.0, 0.0, 1.0], descriptor(
            'Orientation of the base frame in the mocap frame (x, y, z, w).', A, **ro))
        self.declare_parameter('pressure_unit', 'Pa', descriptor(
            'Unit of pressure_command and measured_pressure: Pa or kPa (gauge).', S,
            constraints="one of: 'Pa', 'kPa'", **ro))
        self.declare_parameter('regulator_time_constant_s', 0.1, descriptor(
            'Pressure regulator time constant [s] (first-order lag).', D, lo=0.0, hi=10.0, **ro))
        self.declare_parameter('regulator_slew_rate_kpa_per_s', 1000.0, descriptor(
            'Pressure regulator slew-rate limit [kPa/s].', D, lo=1.0, hi=1e6, **ro))
        self.declare_parameter('mocap_rate_hz', 100.0, descriptor(
            'measured_pose rate [Hz] (motion capture).', D, lo=1.0, hi=1000.0, **ro))
        self.declare_parameter('physics_rate_hz', 50.0, descriptor(
            'Regulator and equilibrium update rate [Hz]; also the measured_pressure rate.', D,
            lo=1.0, hi=1000.0, **ro))
        self.declare_parameter('position_noise_mm', 0.15, descriptor(
            'Motion-capture position noise, standard deviation per axis [mm].', D,
            lo=0.0, hi=100.0, **ro))
        self.declare_parameter('angle_noise_deg', 0.1, descriptor(
            'Motion-capture orientation noise, standard deviation per axis [deg].', D,
            lo=0.0, hi=45.0, **ro))
        self.declare_parameter('command_timeout_s', 0.0, descriptor(
            'Vent (regulators to 0 Pa gauge) when no pressure_command arrived for this long [s], '
            'as a regulator driver does (the inverse node republishes at command_rate_hz); '
            '0 = off (a bench fed single commands).', D, lo=0.0, hi=60.0, **ro))
        d = descriptor('Seed of the noise generator; -1 = random.', INT, **ro)
        d.integer_range = [IntegerRange(from_value=-1, to_value=2**31 - 1, step=1)]
        self.declare_parameter('seed', -1, d)
        g = self.get_parameter
        unit = g('pressure_unit').value
        contract.check_unit(unit)
        cfg = load_robot(g('robot_config').value)   # ConfigError: the node does not start
        seed = int(g('seed').value)
        n_el = int(g('n_elements').value)
        self.robot = SimulatedRobot(
            cfg, n_elements=n_el or None,
            payload_kg=contract.validate_payload(g('payload_kg').value),
            time_constant_s=float(g('regulator_time_constant_s').value),
            slew_rate_pa_per_s=1e3 * float(g('regulator_slew_rate_kpa_per_s').value),
            position_noise_m=1e-3 * float(g('position_noise_mm').value),
            angle_noise_rad=math.radians(float(g('angle_noise_deg').value)),
            seed=None if seed < 0 else seed)
        try:
            self.robot.set_tip_force(list(g('tip_force_n').value))
        except ValueError as exc:
            raise StartupParameterError('tip_force_n', list(g('tip_force_n').value),
                                        'three finite numbers [N], at most 1000 N',
                                        str(exc)) from None
        self.cfg, self._unit, self._frame = cfg, unit, g('base_frame').value
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
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.stats = {'received': 0, 'refused': 0, 'published_poses': 0, 'failed_solves': 0,
                      'timeouts': 0}
        self._timeout_s = float(g('command_timeout_s').value)
        self._last_cmd_t: float | None = None
        self.last_refusal_reason = ''
        qos = command_qos()
        self._pub_pose = self.create_publisher(PoseStamped, 'measured_pose', qos)
        self._pub_p = self.create_publisher(Float64MultiArray, 'measured_pressure', qos)
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', diagnostics_qos())
        self._refusals = Refusals(self, 'pressures', self._publish_diag)
        self._sub = self.create_subscription(Float64MultiArray, 'pressure_command',
                                             self._on_command, qos)
        self._mocap_timer = self.create_timer(1.0 / float(g('mocap_rate_hz').value), self._mocap)
        self._diag_timer = self.create_timer(1.0, self._status)
        self._stop = threading.Event()
        self._physics_period = 1.0 / float(g('physics_rate_hz').value)
        self._thread = threading.Thread(target=self._physics_loop, name='physics', daemon=True)
        self._thread.start()
        self.get_logger().info(
            f'simulating robot {cfg.name!r} ({self.robot.model.A} actuators, '
            f'{self.robot.model.n} elements per actuator), '
            f'regulator tau {self.robot.regulators.time_constant_s:g} s, mocap '
            f'{g("mocap_rate_hz").value:g} Hz with {g("position_noise_mm").value:g} mm noise, '
            f'commands in {unit}')

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
    def _on_command(self, msg: Float64MultiArray) -> None:
        self.stats['received'] += 1
        label = msg.layout.dim[0].label if len(msg.layout.dim) else None
        try:
            p = contract.validate_pressure_input(msg.data, self._unit, self.robot.model.A,
                                                 self.cfg.p_min, self.cfg.p_max, label)
        except contract.InputError as exc:
            self.stats['refused'] += 1
            self.last_refusal_reason = str(exc)
            self._refusals.report(str(exc), self.stats['refused'])
            return
        self.robot.command(p)   # one array assignment: the physics thread reads it whole
        self._last_cmd_t = time.monotonic()

    # ------------------------------------------------------------ physics
    def _physics_loop(self) -> None:
        last = time.monotonic()
        next_t = last
        while not self._stop.is_set():
            next_t += self._physics_period
            wait = next_t - time.monotonic()
            if wait > 0:
                self._stop.wait(wait)
            else:
                next_t = time.monotonic()   # running late: no catch-up burst
            now = time.monotonic()
            t_cmd = self._last_cmd_t
            if self._timeout_s > 0 and t_cmd is not None and now - t_cmd > self._timeout_s:
                self._last_cmd_t = None   # vent once, as a driver does
                self.robot.command(contract.vent_pressures(self.robot.model.A, self.cfg.p_min,
                                                           self.cfg.p_max))
                self.stats['timeouts'] += 1
                self.get_logger().warning(f'vented: no pressure_command for '
                                          f'{self._timeout_s:g} s (controller dead or stopped)')
            failures = self.robot.failures
            self.robot.step(now - last)   # only this thread steps the robot
            failed = self.robot.failures > failures
            p = self.robot.pressures_pa
            last = now
            if failed:
                self.stats['failed_solves'] += 1
                msg = f'equilibrium not computed ({self.robot.last_failure}); last state kept'
                self.get_logger().error(msg, throttle_duration_sec=2.0)
                self._publish_diag(DiagnosticStatus.ERROR, msg, {})
            try:
                self._pub_p.publish(pressure_message(p, self._unit))
            except Exception:  # noqa: BLE001 - publisher gone at shutdown
                return

    def _mocap(self) -> None:
        pos, R = self.robot.measure()   # reads the newest complete state (no lock needed)
        frame = self._frame
        if self._mocap_frame is not None:   # as a motion capture in its own frame sees it
            frame = self._mocap_frame.frame_id
            pos, R = self._mocap_frame.from_base(pos, R)
        self._pub_pose.publish(pose_message(pos, geometry.quaternion_from_rotation(R), frame,
                                            self.get_clock().now().to_msg()))
        self.stats['published_poses'] += 1

    def _status(self) -> None:
        level = DiagnosticStatus.WARN if self.stats['failed_solves'] else DiagnosticStatus.OK
        p, solves, payload = self.robot.pressures_pa, self.robot.solves, self.robot.payload_kg
        values = dict(self.stats, solves=solves, payload_kg=payload,
                      tip_force_n=' '.join(f'{v:g}' for v in self.robot.tip_force_n),
                      pressures=' '.join(f'{v:.6g}' for v in contract.to_unit(p, self._unit)))
        self._publish_diag(level, 'simulating', values)

    def _publish_diag(self, level: bytes, message: str, values: dict) -> None:
        publish_diagnostic(self, self._pub_diag, f'{self.get_name()}: simulated robot',
                           self.cfg.name, level, message, values)

    def destroy_node(self):
        """Stop the physics thread, then destroy the node."""
        self._stop.set()
        self._thread.join(5.0)
        return super().destroy_node()


main = main_for(SimulatedRobotNode)


if __name__ == '__main__':
    main()
