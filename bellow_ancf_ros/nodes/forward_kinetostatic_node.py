"""Forward-kinetostatic prediction node.

Pressures -> forward kinetostatics (core
:func:`~bellow_ancf_ros.core.solve_forward`) -> predicted end-effector pose
and robot shape for RViz.

Topics
------
subscribes
    ``pressure_command`` (std_msgs/Float64MultiArray): one gauge pressure per
    actuator, segment by segment, in ``pressure_unit`` (Pa by default).
    Remap it to a measured-pressure topic to predict from measurements
    (``--ros-args -r pressure_command:=measured_pressure``).  An array whose
    ``layout.dim[0].label`` names the other unit (``..._pa`` vs ``..._kpa``)
    is refused rather than misread by a factor of 1000.
publishes
    ``predicted_pose`` (geometry_msgs/PoseStamped) in ``base_frame``.
    ``predicted_shape`` (visualization_msgs/MarkerArray) in ``base_frame``:
    namespace ``backbones``, one LINE_STRIP per actuator (width = the
    actuator diameter D_a); namespace ``plates``, one CYLINDER per plate (base,
    constraint and top plates of every segment).
    ``/diagnostics`` (diagnostic_msgs/DiagnosticArray): the status of the
    solves (solve time, iterations, residual; a new level or message at once,
    an unchanged one at most at 10 Hz with the newest values), of refused
    input (WARN), and a 1 Hz heartbeat ``'<node>: status'`` (robot, age of
    the last solve, solve-time statistics, counters).

QoS: reliable, keep-last, depth 5 for the pressures and the outputs;
``/diagnostics`` keep-last 10.  Like the inverse node it works on the latest
input only (one-item slot, worker thread, at most ``max_rate_hz`` solves per
second, of simulation time under ``use_sim_time``), warm-started from the
previous solution.  Under ``use_sim_time`` it
is in a simulated robot's lockstep (:mod:`.lockstep`): it counts the
pressures it takes and reports each ``/clock`` tick once its solve is done,
so the prediction from a pressure goes out at the same simulated time
however busy the computer is.

Bad input (wrong length, NaN/inf, outside the robot's pressure limits, wrong
unit label): refused with a throttled warning and a WARN diagnostic; the
node keeps running and the last prediction stands.  A solve that does not
converge to a stable equilibrium publishes nothing and reports ERROR.  A bad
start-up parameter (a robot file that does not load, a value outside its
range) ends the process with one line naming it and what is allowed (exit
status 2).
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Point, PoseStamped
from rcl_interfaces.msg import ParameterType
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import Marker, MarkerArray

from ..core import ConfigError, RobotModel, load_robot, solve_forward
from ..core import geometry
from . import contract, worker
from .diagnostics import Heartbeat, Refusals, ThrottledStatus, solve_values
from .lockstep import LockstepReport
from .ros_util import (
    WARN_THROTTLE_S,
    Param,
    StartupParameterError,
    Topic,
    command_qos,
    declare_all,
    descriptor,
    diagnostics_qos,
    guard_parameters,
    main_for,
    pose_message,
)

__all__ = ['ForwardKinetostaticNode', 'main', 'shape_markers']

PLATE_THICKNESS_M = 0.002


def shape_markers(fw, frame_id: str, stamp, n_points: int = 20) -> MarkerArray:
    """Build the MarkerArray of a forward result: backbones (LINE_STRIP), plates (CYLINDER)."""
    cfg = fw.model.cfg
    arr = MarkerArray()
    backbones = fw.backbones(n_points)
    for i, line in enumerate(backbones):
        m = Marker()
        m.header.frame_id = frame_id
        m.header.stamp = stamp
        m.ns = 'backbones'
        m.id = i
        m.type = Marker.LINE_STRIP
        m.action = Marker.ADD
        m.pose.orientation.w = 1.0
        m.scale.x = float(cfg.d_a)
        m.color.r, m.color.g, m.color.b, m.color.a = 0.85, 0.55, 0.2, 0.8
        m.points = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in line]
        arr.markers.append(m)
    for k, (seg, _frac, pos, R) in enumerate(fw.plate_poses()):
        seg_cfg = cfg.segments[int(seg)]
        q = geometry.quaternion_from_rotation(R)
        m = Marker()
        m.header.frame_id = frame_id
        m.header.stamp = stamp
        m.ns = 'plates'
        m.id = k
        m.type = Marker.CYLINDER
        m.action = Marker.ADD
        m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in pos)
        (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
         m.pose.orientation.w) = (float(v) for v in q)
        diameter = 2.0 * seg_cfg.pitch_radius + cfg.d_a
        m.scale.x = m.scale.y = float(diameter)
        m.scale.z = PLATE_THICKNESS_M
        m.color.r, m.color.g, m.color.b, m.color.a = 0.3, 0.5, 0.8, 0.6
        arr.markers.append(m)
    return arr


D, S, INT = (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_STRING,
             ParameterType.PARAMETER_INTEGER)
#: The node's parameters: what it declares and what ``--help`` prints.
PARAMETERS = (
    Param('robot_config', 'one_segment', descriptor(
        'Robot description: a shipped robot name (one_segment, two_segment, three_segment, '
        '...: the files in '
        'share/bellow_ancf_ros/config) or a path to a robot YAML file. Read at start-up.', S,
        read_only=True, constraints='a shipped robot name or a robot YAML path')),
    Param('payload_kg', 0.0, descriptor(
        'Payload mass at the end effector [kg]; may be changed at run time.', D,
        lo=0.0, hi=contract.PAYLOAD_MAX_KG)),
    Param('base_frame', 'base', descriptor(
        'Frame of predicted_pose and predicted_shape (robot base).', S,
        constraints='a non-empty frame name')),
    Param('pressure_unit', 'Pa', descriptor(
        'Unit of the incoming gauge pressures: Pa (default, REP-103) or kPa.', S,
        constraints="one of: 'Pa', 'kPa'")),
    Param('max_rate_hz', 100.0, descriptor(
        'Maximum prediction rate [Hz]; only the newest pressure array is solved (under '
        'use_sim_time: per second of simulation time).', D, lo=0.1, hi=1000.0)),
    Param('backbone_points', 20, descriptor(
        'Points per actuator backbone in predicted_shape.', INT, lo=2, hi=200)),
)


TOPICS = (
    Topic('subscribes', 'pressure_command', 'std_msgs/Float64MultiArray',
          'gauge pressures in pressure_unit (remap to measured_pressure to predict from '
          'measurements)'),
    Topic('publishes', 'predicted_pose', 'geometry_msgs/PoseStamped', 'in base_frame'),
    Topic('publishes', 'predicted_shape', 'visualization_msgs/MarkerArray',
          'backbones and plates, for RViz'),
    Topic('publishes', '/diagnostics', 'diagnostic_msgs/DiagnosticArray',
          'per-solve status and 1 Hz heartbeat'),
    Topic('publishes', 'lockstep_clock', 'std_msgs/Header',
          'use_sim_time: the simulation time its predictions are done until (a lockstep)'),
)


class ForwardKinetostaticNode(Node):
    """Predicts the robot's pose and shape from pressures."""

    NODE_NAME = 'forward_kinetostatic_node'
    PARAMETERS = PARAMETERS
    TOPICS = TOPICS

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        declare_all(self, PARAMETERS)
        robot = self.get_parameter('robot_config').value
        guard_parameters(self, ('payload_kg', 'pressure_unit', 'max_rate_hz', 'base_frame'))

        try:
            self.cfg = load_robot(robot)   # read at start-up: a bad one stops the node
        except ConfigError as exc:
            raise StartupParameterError(
                'robot_config', robot, 'a shipped robot name or a robot YAML path',
                str(exc)) from None
        self.model = RobotModel(self.cfg)
        self._lock = threading.Lock()
        self._warm = solve_forward(self.model, contract.vent_pressures(
            self.model.A, self.cfg.p_min, self.cfg.p_max))
        if not self._warm.success:
            self._warm = None
        self.stats = {'received': 0, 'refused': 0, 'solved': 0, 'published': 0, 'failed': 0}
        self.last_refusal_reason = ''
        self._refusals = Refusals(self, 'pressures', self._publish_diag)
        self.solve_stats = worker.SolveStats()
        qos = command_qos()
        self._pub_pose = self.create_publisher(PoseStamped, 'predicted_pose', qos)
        self._pub_shape = self.create_publisher(MarkerArray, 'predicted_shape', qos)
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', diagnostics_qos())
        self._status = ThrottledStatus(self, self._pub_diag,
                                       f'{self.get_name()}: forward kinetostatics')
        self.heartbeat = Heartbeat(self, self._pub_diag, self._heartbeat_status,
                                   lambda: self.cfg.name)
        self._worker = worker.LatestWorker(self._solve, self._min_period, self._on_worker_error,
                                           name='forward-solver',
                                           on_done=lambda: self._lockstep.work_done())
        # use_sim_time: a simulation's lockstep waits for the prediction from each pressure
        self._lockstep = LockstepReport(self, self._worker.idle)
        self._last_due_ns = -(1 << 62)   # the newest prediction's simulation time (lockstep)
        self._sub = self.create_subscription(Float64MultiArray, 'pressure_command',
                                             self._on_pressures, qos)
        self._lockstep.received(self._sub.topic_name, 0)   # (a receiver of them)
        self.get_logger().info(
            f'robot {self.cfg.name!r}: {self.model.A} actuators, limits '
            f'[{self.cfg.p_min / 1e3:g}, {self.cfg.p_max / 1e3:g}] kPa gauge; listening on '
            f'{self._sub.topic_name!r} in {self.get_parameter("pressure_unit").value}')

    def _heartbeat_status(self) -> tuple:
        """Heartbeat: robot, input topic, solve statistics, counters."""
        values = {'robot': self.cfg.name, 'input_topic': self._sub.topic_name,
                  'pressure_unit': self.get_parameter('pressure_unit').value,
                  'payload_kg': self.get_parameter('payload_kg').value}
        values.update(solve_values(self.solve_stats))
        values.update({f'pressures_{k}': v for k, v in self.stats.items()})
        if self.solve_stats.summary()['last_ok'] is False:
            return DiagnosticStatus.WARN, 'running; the last prediction failed', values
        return DiagnosticStatus.OK, 'running', values

    # ------------------------------------------------------------ params
    def _period(self) -> float:
        return 1.0 / float(self.get_parameter('max_rate_hz').value)

    def _min_period(self) -> float:
        """The worker's wall-clock spacing of solves (none in a lockstep: :meth:`_due`)."""
        return 0.0 if self._lockstep.active else self._period()

    def _due(self) -> bool:
        """A prediction is due: always on the wall clock (the worker's token bucket).

        Under use_sim_time at most ``max_rate_hz`` per second of simulation
        time, the pressures between skipped: in a simulation's lockstep a
        solve waiting for wall-clock credit would hold the simulation (at
        5 Hz: 0.05x real time).
        """
        if not self._lockstep.active:
            return True
        now = self.get_clock().now().nanoseconds
        if 0 <= now - self._last_due_ns < 1e9 * self._period():
            return False   # (a clock that jumped back: due at once)
        self._last_due_ns = now
        return True

    # ------------------------------------------------------------ input
    def _on_pressures(self, msg: Float64MultiArray) -> None:
        self.stats['received'] += 1
        label = msg.layout.dim[0].label if len(msg.layout.dim) else None
        try:
            p = contract.validate_pressure_input(
                msg.data, self.get_parameter('pressure_unit').value, self.model.A,
                self.cfg.p_min, self.cfg.p_max, label)
        except contract.InputError as exc:
            self._refuse(str(exc))
        else:
            if self._due():
                self._worker.submit(p)
        self._lockstep.received(self._sub.topic_name)   # (its prediction: when the worker idles)

    def _refuse(self, reason: str) -> None:
        self.stats['refused'] += 1
        self.last_refusal_reason = reason
        self._refusals.report(reason, self.stats['refused'])

    # ------------------------------------------------------------ solving
    def _on_worker_error(self, exc: BaseException) -> None:
        self.stats['failed'] += 1
        self.get_logger().error(f'forward solve raised {type(exc).__name__}: {exc}',
                                throttle_duration_sec=WARN_THROTTLE_S)
        self._publish_diag(DiagnosticStatus.ERROR,
                           f'solver exception: {type(exc).__name__}: {exc}', {})

    def _solve(self, pressures_pa: np.ndarray) -> None:
        payload = float(self.get_parameter('payload_kg').value)
        t0 = time.perf_counter()
        fw = solve_forward(self.model, pressures_pa, payload_kg=payload, warm_start=self._warm)
        dt = time.perf_counter() - t0
        self.stats['solved'] += 1
        self.solve_stats.record(dt, ok=bool(fw.success))
        values = {
            'solve_time_ms': f'{dt * 1e3:.3f}',
            'iterations': fw.iterations,
            'residual_norm': f'{fw.residual_norm:.3e}',
            'converged': str(bool(fw.converged)).lower(),
            'stable': str(fw.stable).lower(),
            'payload_kg': payload,
        }
        if not fw.success:
            self.stats['failed'] += 1
            msg = f'forward solve failed: {fw.message}'
            self.get_logger().error(msg, throttle_duration_sec=WARN_THROTTLE_S)
            self._publish_diag(DiagnosticStatus.ERROR, msg, values)
            return
        self._warm = fw
        frame = self.get_parameter('base_frame').value
        stamp = self.get_clock().now().to_msg()
        pos, R = fw.position, fw.rotation
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(R))):
            self._publish_diag(DiagnosticStatus.ERROR, 'non-finite pose from the solver', values)
            return
        quat = geometry.quaternion_from_rotation(R)
        self._pub_pose.publish(pose_message(pos, quat, frame, stamp))
        self._pub_shape.publish(shape_markers(fw, frame, stamp,
                                              int(self.get_parameter('backbone_points').value)))
        self.stats['published'] += 1
        values['position_m'] = ' '.join(f'{v:.6g}' for v in pos)
        self._publish_diag(DiagnosticStatus.OK, 'prediction published', values)

    def _publish_diag(self, level: bytes, message: str, values: dict) -> None:
        self._status.submit(self.cfg.name, level, message, values)

    def destroy_node(self):
        """Leave a simulation's lockstep, stop the worker, then destroy the node."""
        self._lockstep.destroy()
        self._worker.stop()
        return super().destroy_node()


main = main_for(ForwardKinetostaticNode)


if __name__ == '__main__':
    main()
