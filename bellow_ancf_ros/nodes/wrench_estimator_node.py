"""The robot as a force sensor: ``measured_pose`` + pressures -> ``estimated_wrench``.

Feeds :class:`~bellow_ancf_ros.core.control.TipForceEstimator` (an extended
Kalman filter of the tip force, or of an unknown payload, on the robot's own
compliance) and publishes its reading:

* subscribes ``measured_pose`` (geometry_msgs/PoseStamped in ``base_frame``,
  the robot file's mocap frame, or any frame tf2 knows), ``measured_pressure``
  (the regulators' measured pressures, std_msgs/Float64MultiArray in
  ``pressure_unit``) and ``pressure_command`` (used while no measured
  pressures younger than ``pressure_timeout_s`` arrived);
* publishes ``estimated_wrench`` (geometry_msgs/WrenchStamped in
  ``base_frame``: the force in N, torque zero: the model has no tip torque)
  at ``rate_hz``, once the first sample is in;
* ``estimated_wrench_marker`` (visualization_msgs/Marker): the force as an
  arrow from the newest measured tip position (``marker_scale_m_per_n``,
  default 0.1 m per newton), for RViz;
* ``~/tare`` (std_srvs/Trigger): zero the reading at the current estimate;
* ``/diagnostics`` heartbeat: the force and its standard deviations, the
  directions the data cannot see yet (WARN), samples and refusals;
* under ``use_sim_time``, in a simulated robot's lockstep
  (:mod:`.lockstep`): it counts the pressures it takes and reports each
  ``/clock`` tick, so each pose meets the pressures of its simulated time
  however busy the computer is.

Use the calibrated robot file: the estimator reads any model error as a force.

    ros2 run bellow_ancf_ros wrench_estimator_node --ros-args -p robot_config:=my_robot.yaml
"""

from __future__ import annotations

import collections
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rcl_interfaces.msg import ParameterType
from rclpy.node import Node
from geometry_msgs.msg import Point
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker

from ..core import ConfigError, RobotModel, load_robot
from ..core.control import ESTIMATOR_MODES, TipForceEstimator
from ..core.geometry import z_axis_from_quaternion
from . import contract
from .diagnostics import Heartbeat, Refusals, publish_diagnostic
from .frames import PoseFrames
from .lockstep import LockstepReport
from .measured_feedback import measured_pose_qos
from .ros_util import (WARN_THROTTLE_S, Param, StartupParameterError, Topic, command_qos,
                       control_clock, declare_all, descriptor, diagnostics_qos, main_for)

__all__ = ['WrenchEstimatorNode', 'main']

NODE_NAME = 'wrench_estimator_node'
#: An outlier (a swapped marker: about 0.5 % of a motion capture's samples) is counted on
#: /diagnostics and logged at INFO (at most every OUTLIER_INFO_S); above this share of the
#: last OUTLIER_WINDOW pose samples it is a WARN (log and heartbeat): the markers need a look.
OUTLIER_WARN_FRACTION = 0.05
OUTLIER_WINDOW = 240
OUTLIER_INFO_S = 30.0
D, S, B = (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_STRING,
           ParameterType.PARAMETER_BOOL)
ro = dict(read_only=True)

#: The node's parameters: what it declares and what ``--help`` prints.
PARAMETERS = (
    Param('robot_config', 'one_segment', descriptor(
        'The calibrated robot file (shipped name or YAML path): its model error reads as '
        'a force.', S, constraints='a shipped robot name or a robot YAML path', **ro)),
    Param('mode', 'force', descriptor(
        "'force': the tip force (3 components); 'mass': an unknown payload along gravity.",
        S, constraints="one of: 'force', 'mass'", **ro)),
    Param('payload_kg', 0.0, descriptor(
        "The known payload [kg] (mode 'force'), or the first guess (mode 'mass').", D,
        lo=0.0, hi=contract.PAYLOAD_MAX_KG, **ro)),
    Param('position_noise_m', 0.15e-3, descriptor(
        'Motion-capture position noise, standard deviation per axis [m].', D,
        lo=1e-7, hi=0.1, **ro)),
    Param('angle_noise_rad', 0.0017453292519943296, descriptor(
        'Motion-capture orientation noise, standard deviation per axis [rad].', D,
        lo=1e-7, hi=1.0, **ro)),
    Param('force_rate', 0.01, descriptor(
        'How fast the force may change: random-walk spectral density [N^2/s] '
        '(0.01: about 0.1 N in a second).', D, lo=0.0, hi=100.0, **ro)),
    Param('use_z_axis', True, descriptor(
        'Use the measured z-axis as well as the position.', B, **ro)),
    Param('rate_hz', 20.0, descriptor(
        'estimated_wrench publication rate [Hz].', D, lo=0.1, hi=1000.0, **ro)),
    Param('marker_scale_m_per_n', 0.1, descriptor(
        'Length of the estimated_wrench_marker arrow per newton [m/N].', D,
        lo=1e-4, hi=100.0, **ro)),
    Param('pressure_timeout_s', 0.5, descriptor(
        'Measured pressures older than this give way to pressure_command [s].', D,
        lo=0.01, hi=60.0, **ro)),
    Param('pressure_unit', 'Pa', descriptor(
        'Unit of measured_pressure and pressure_command: Pa or kPa (gauge).', S,
        constraints="one of: 'Pa', 'kPa'", **ro)),
    Param('base_frame', 'base', descriptor(
        'Frame of estimated_wrench (the robot base).', S, **ro)),
)


TOPICS = (
    Topic('subscribes', 'measured_pose', 'geometry_msgs/PoseStamped',
          'base_frame, the robot file\'s mocap frame or any frame tf2 knows (best effort)'),
    Topic('subscribes', 'measured_pressure', 'std_msgs/Float64MultiArray',
          'the regulators\' measured pressures, in pressure_unit'),
    Topic('subscribes', 'pressure_command', 'std_msgs/Float64MultiArray',
          'used while no fresh measured_pressure arrives'),
    Topic('publishes', 'estimated_wrench', 'geometry_msgs/WrenchStamped',
          'the tip force in base_frame [N], at rate_hz'),
    Topic('publishes', 'estimated_wrench_marker', 'visualization_msgs/Marker',
          'the force as an arrow, for RViz'),
    Topic('publishes', '/diagnostics', 'diagnostic_msgs/DiagnosticArray', '1 Hz heartbeat'),
    Topic('publishes', 'lockstep_clock', 'std_msgs/Header',
          'use_sim_time: the simulation time its samples are taken until (a lockstep)'),
    Topic('services', '~/tare', 'std_srvs/Trigger', 'zero the reading'),
)


class WrenchEstimatorNode(Node):
    """Tip force from poses and pressures (module docstring)."""

    NODE_NAME = NODE_NAME
    PARAMETERS = PARAMETERS
    TOPICS = TOPICS

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        """Declare the parameters (read at start-up), build the estimator, wire the topics."""
        super().__init__(node_name, **kwargs)
        declare_all(self, PARAMETERS)
        robot = self.get_parameter('robot_config').value
        mode = self.get_parameter('mode').value
        payload = self.get_parameter('payload_kg').value
        sigma_p = self.get_parameter('position_noise_m').value
        sigma_a = self.get_parameter('angle_noise_rad').value
        rate = self.get_parameter('force_rate').value
        if mode not in ESTIMATOR_MODES:
            raise StartupParameterError('mode', mode, "one of: 'force', 'mass'")
        try:
            contract.check_unit(self.get_parameter('pressure_unit').value)
        except ValueError:
            raise StartupParameterError('pressure_unit', self.get_parameter('pressure_unit').value,
                                        "one of: 'Pa', 'kPa'") from None
        try:
            self.cfg = load_robot(robot)
        except ConfigError as exc:
            raise StartupParameterError('robot_config', robot,
                                        'a shipped robot name or a robot YAML path',
                                        str(exc)) from None
        self.estimator = TipForceEstimator(RobotModel(self.cfg), mode=mode, payload_kg=payload,
                                           position_noise_m=sigma_p, angle_noise_rad=sigma_a,
                                           force_rate=rate)
        self.unit = self.get_parameter('pressure_unit').value
        self.use_z = bool(self.get_parameter('use_z_axis').value)
        self.timeout = float(self.get_parameter('pressure_timeout_s').value)
        self.frames = PoseFrames(self, self.get_parameter('base_frame').value,
                                 self.cfg.mocap_frame)
        self._control = control_clock(self)   # every time here: control time (use_sim_time)
        self._pressures = {'measured': (None, -np.inf), 'command': (None, -np.inf)}
        self.stats = {'poses': 0, 'refused': 0, 'outliers': 0, 'published': 0}
        self._recent = collections.deque(maxlen=OUTLIER_WINDOW)   # outlier or not, per pose
        self._pub = self.create_publisher(WrenchStamped, 'estimated_wrench', command_qos())
        self._pub_marker = self.create_publisher(Marker, 'estimated_wrench_marker', command_qos())
        self._marker_scale = float(self.get_parameter('marker_scale_m_per_n').value)
        self._tip = None   # newest measured tip position in the base frame (the arrow's tail)
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', diagnostics_qos())
        self._refusals = Refusals(self, 'samples', self._publish_diag)
        self.heartbeat = Heartbeat(self, self._pub_diag, self._status, lambda: self.cfg.name)
        # use_sim_time: a simulation's lockstep waits until it has taken every pressure sent
        # (its work runs in its callbacks: idle between them)
        self._lockstep = LockstepReport(self)
        self.create_subscription(PoseStamped, 'measured_pose', self._on_pose, measured_pose_qos())
        self._topics = {}
        for topic, key in (('measured_pressure', 'measured'), ('pressure_command', 'command')):
            sub = self.create_subscription(Float64MultiArray, topic,
                                           lambda m, key=key: self._on_pressures(m, key),
                                           command_qos())
            self._topics[key] = sub.topic_name
            self._lockstep.received(sub.topic_name, 0)   # (a receiver of them)
        self.create_service(Trigger, '~/tare', self._on_tare)
        self.create_timer(1.0 / float(self.get_parameter('rate_hz').value), self._publish)
        self.get_logger().info(
            f"estimating the tip {'force' if mode == 'force' else 'payload'} of robot "
            f"{self.cfg.name!r} from measured_pose and measured_pressure (else pressure_command) "
            f"in {self.unit}; publishing estimated_wrench in {self.frames.base_frame!r}")

    # -------------------------------------------------------------- inputs
    def _on_pressures(self, msg: Float64MultiArray, key: str) -> None:
        self._lockstep.received(self._topics[key])
        label = msg.layout.dim[0].label if msg.layout.dim else None
        try:
            p = contract.validate_pressure_input(msg.data, self.unit, self.estimator.model.A,
                                                 self.cfg.p_min, self.cfg.p_max, label)
        except contract.InputError as exc:
            self._refuse(f'{key} pressures: {exc}')
            return
        self._pressures[key] = (p, self._control.now())

    def _current_pressures(self):
        now = self._control.now()
        p, t = self._pressures['measured']
        if p is not None and now - t <= self.timeout:
            return p
        return self._pressures['command'][0]

    def _on_pose(self, msg: PoseStamped) -> None:
        self.stats['poses'] += 1
        p = self._current_pressures()
        if p is None:
            self._refuse('no pressures yet (measured_pressure or pressure_command)')
            return
        try:
            xyz, quat = self.frames.pose_in_base(msg, self.use_z)
            z = z_axis_from_quaternion(quat) if self.use_z else None
        except ValueError as exc:   # contract.InputError, or a bad quaternion
            self._refuse(str(exc))
            return
        self._tip = xyz
        outliers = self.estimator.outliers
        ok = self.estimator.update(p, xyz, z, time_s=self._control.now())
        outlier = self.estimator.outliers > outliers
        self._recent.append(outlier)
        if outlier:
            self._outlier()
        elif not ok:
            self._refuse(self.estimator.last_reason)

    def outlier_share(self) -> float:
        """Share of outliers among the last OUTLIER_WINDOW pose samples (0 with few samples)."""
        n = len(self._recent)
        return sum(self._recent) / n if n >= OUTLIER_WINDOW // 4 else 0.0

    def _outlier(self) -> None:
        """Count an outlier; INFO now and then, a WARN only at an abnormal share."""
        self.stats['outliers'] += 1
        share, n = self.outlier_share(), len(self._recent)
        if share > OUTLIER_WARN_FRACTION:
            self.get_logger().warning(
                f'samples refused as outliers: {share:.0%} of the last {n} poses (a motion '
                f'capture gives about 0.5 %): check the markers',
                throttle_duration_sec=WARN_THROTTLE_S)
        else:
            self.get_logger().info(
                f'{self.stats["outliers"]} sample(s) refused as outliers so far '
                f'({share:.1%} of the last {n} poses; counted on /diagnostics)',
                throttle_duration_sec=OUTLIER_INFO_S)

    def _refuse(self, reason: str) -> None:
        self.stats['refused'] += 1
        self._refusals.report(reason, self.stats['refused'])

    def _on_tare(self, request, response):
        self.estimator.tare()
        response.success = True
        response.message = 'estimated_wrench zeroed at the current estimate'
        self.get_logger().info('tare: ' + response.message)
        return response

    # -------------------------------------------------------------- output
    def _publish(self) -> None:
        if self.estimator.samples == 0:
            return
        e = self.estimator.estimate()
        msg = WrenchStamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.frames.base_frame
        msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z = (float(v) for v in e.force_n)
        self._pub.publish(msg)
        self.stats['published'] += 1
        if self._tip is not None:
            self._pub_marker.publish(self._arrow(msg.header, self._tip, e.force_n))

    def _arrow(self, header, tip, force) -> Marker:
        """The force as an arrow from the measured tip (RViz)."""
        m = Marker()
        m.header = header
        m.ns, m.id, m.type, m.action = 'estimated_force', 0, Marker.ARROW, Marker.ADD
        head = np.asarray(tip) + self._marker_scale * np.asarray(force)
        m.points = [Point(x=float(a), y=float(b), z=float(c)) for a, b, c in (tip, head)]
        m.scale.x, m.scale.y, m.scale.z = 0.002, 0.004, 0.004   # shaft, head diameter, length
        m.color.r, m.color.g, m.color.b, m.color.a = 1.0, 0.4, 0.0, 1.0
        m.pose.orientation.w = 1.0
        return m

    def _status(self) -> tuple:
        e = self.estimator.estimate()
        values = dict(self.stats, samples=e.samples, mode=self.estimator.mode,
                      force_n=np.round(e.force_n, 5).tolist(),
                      std_n=np.round(e.std_n, 5).tolist(),
                      blind_directions=[np.round(v, 3).tolist() for v in e.blind])
        if e.payload_kg is not None:
            values.update(payload_kg=round(e.payload_kg, 5),
                          payload_std_kg=round(e.payload_std_kg, 5))
        values['outlier_share'] = round(self.outlier_share(), 4)
        if e.samples == 0:
            return DiagnosticStatus.WARN, 'no sample yet', values
        if self.outlier_share() > OUTLIER_WARN_FRACTION:
            return (DiagnosticStatus.WARN, f'{self.outlier_share():.0%} of the recent poses '
                    'are outliers: check the markers', values)
        if e.blind:
            return (DiagnosticStatus.WARN, f'{len(e.blind)} direction(s) not seen yet '
                    f'(std above {self.estimator.blind_std_n:g} N)', values)
        return DiagnosticStatus.OK, 'estimating', values

    def _publish_diag(self, level: bytes, message: str, values: dict) -> None:
        publish_diagnostic(self, self._pub_diag, f'{self.get_name()}: samples', self.cfg.name,
                           level, message, dict(values, **self.stats))

    def destroy_node(self):
        """Leave a simulation's lockstep, then destroy the node."""
        self._lockstep.destroy()
        return super().destroy_node()


main = main_for(WrenchEstimatorNode)


if __name__ == '__main__':
    main()
