"""Motion-capture poses re-expressed in the robot's base frame, for any consumer.

``mocap_pose`` (geometry_msgs/PoseStamped in the mocap frame, e.g. a
mocap4r2 rigid body; remap it to your driver's topic) -> ``measured_pose``
(the same pose in ``base_frame``, the stamp kept).  The transform is the
robot file's ``mocap_frame`` (the pose of the base in the mocap frame,
written by ``bellow-ancf calibrate``) or, on a ROS install, any transform
tf2 knows (:class:`~bellow_ancf_ros.nodes.frames.PoseFrames`).  The inverse
node accepts the mocap frame itself; this relay serves everything else (a
recorder, rviz, a lab's own tools).  Poses it cannot transform, or with
NaN/inf, are refused (throttled warning, diagnostics WARN).

    ros2 run bellow_ancf_ros mocap_relay --ros-args -p robot_config:=my_robot.yaml
        -r mocap_pose:=/rigid_bodies/robot/pose   (one line)
"""

from __future__ import annotations

from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import ParameterType
from rclpy.node import Node

from ..core import load_robot
from .diagnostics import Refusals, publish_diagnostic
from .frames import PoseFrames
from .measured_feedback import measured_pose_qos
from .ros_util import (Param, Topic, command_qos, declare_all, descriptor, diagnostics_qos,
                       main_for, pose_message)

__all__ = ['MocapRelay', 'main']


S = ParameterType.PARAMETER_STRING
#: The node's parameters: what it declares and what ``--help`` prints.
PARAMETERS = (
    Param('robot_config', 'one_segment', descriptor(
        'Robot file (shipped name or YAML path) whose mocap_frame gives the transform '
        '(a calibrated robot file).', S, read_only=True)),
    Param('base_frame', 'base', descriptor(
        'Frame of measured_pose (the robot base).', S, read_only=True)),
)
TOPICS = (
    Topic('subscribes', 'mocap_pose', 'geometry_msgs/PoseStamped',
          'in the mocap frame (remap it to your mocap topic; best effort)'),
    Topic('publishes', 'measured_pose', 'geometry_msgs/PoseStamped',
          'in base_frame, the stamp kept'),
    Topic('publishes', '/diagnostics', 'diagnostic_msgs/DiagnosticArray', 'refused poses'),
)


class MocapRelay(Node):
    """``mocap_pose`` in the mocap frame -> ``measured_pose`` in the base frame."""

    NODE_NAME = 'mocap_relay'
    PARAMETERS = PARAMETERS
    TOPICS = TOPICS

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        """Read the robot file's mocap frame; subscribe and publish."""
        super().__init__(node_name, **kwargs)
        declare_all(self, PARAMETERS)
        cfg = load_robot(self.get_parameter('robot_config').value)
        self.frames = PoseFrames(self, self.get_parameter('base_frame').value, cfg.mocap_frame)
        self.stats = {'received': 0, 'relayed': 0, 'refused': 0}
        self._pub = self.create_publisher(PoseStamped, 'measured_pose', command_qos())
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', diagnostics_qos())
        self._refusals = Refusals(self, 'mocap poses', self._publish_diag)
        self._sub = self.create_subscription(PoseStamped, 'mocap_pose', self._on_pose,
                                             measured_pose_qos())
        self.get_logger().info(f'relaying mocap_pose -> measured_pose in '
                               f'{self.frames.base_frame!r}; accepted frames: '
                               f'{self.frames.accepted}')

    def _on_pose(self, msg: PoseStamped) -> None:
        self.stats['received'] += 1
        try:
            pos, quat = self.frames.pose_in_base(msg)
        except ValueError as exc:   # InputError, or a quaternion that cannot be normalised
            self.stats['refused'] += 1
            self._refusals.report(str(exc), self.stats['refused'])
            return
        self._pub.publish(pose_message(pos, quat, self.frames.base_frame, msg.header.stamp))
        self.stats['relayed'] += 1

    def _publish_diag(self, level: bytes, message: str, values: dict) -> None:
        publish_diagnostic(self, self._pub_diag, f'{self.get_name()}: mocap relay',
                           self.frames.base_frame, level, message, dict(values, **self.stats))


main = main_for(MocapRelay)


if __name__ == '__main__':
    main()
