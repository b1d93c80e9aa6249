"""Trajectory source: publishes ``target_pose`` along the paper's trajectories.

Publishes ``target_pose`` (geometry_msgs/PoseStamped, reliable, keep-last 5)
in ``base_frame`` at ``rate_hz``, following
:func:`bellow_ancf_ros.core.experiments.trajectory`: ``space_spiral``,
``space_rose``, ``planar_circle``, ``planar_spiral``, ``planar_rose`` and,
for robots with two or more segments, ``bending_circle`` (constant bending
angle ``bending_angle_deg``, paper: 0, 10 or 20 deg).  For one segment the
orientation is the identity (the controller ignores it); for two or more the
orientation is the smallest rotation taking base z onto the target z-axis.

Parameters (all with descriptors): ``trajectory``, ``rate_hz``, ``period_s``
(0 = the trajectory's default, derived from the robot), ``preview_s``, ``radius_m`` and
``height_m`` (0 = default), ``robot_config``, ``base_frame``,
``bending_angle_deg``, ``loop`` (repeat, default true; otherwise stop after
one period), ``start_delay_s`` (time to wait before the first target, e.g. for
the controller to come up), ``ramp_in_s`` (default 2 s: when the robot is
off the path's start, the targets lead in from where it is, onto the path
with minimum-jerk timing, instead of a jump; the path's clock starts after
it), ``spin_up_s`` (default 0: the path's speed rises from zero over this
long, :func:`~bellow_ancf_ros.core.experiments.spin_up`, so that a fast path
does not start with a jump of velocity that rings a robot's first mode).
Where it is (for the lead-in): the target another node holds it at
(``target_pose``), else its ``measured_pose``, else the controller's ``commanded_pose``.
``preview_s`` (default 0) publishes, at every tick, the pose wanted that far
ahead, stamped with the time it is wanted at (a stamp in the future): the
inverse node commands it at once, so that the robot, behind its regulators'
lag and dead time, is there when it is wanted, and its closed loop compares
each measured pose with the target wanted when the pose was captured.  Set
it to the regulators' dead time plus their time constant plus half a control
period (about 0.09 s for 15 ms + 60 ms at 50 Hz).
Trajectory parameters may be changed at run time; an invalid combination is
refused with the reason and the old one stays.
A bad start-up value ends the process with one line naming the parameter, the
value and what is allowed (exit status 2).  ``/diagnostics`` carries a 1 Hz
heartbeat ``'<node>: status'`` (trajectory, targets published, finished).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import ParameterType, SetParametersResult
from rclpy.duration import Duration
from rclpy.node import Node

from ..core import ConfigError, load_robot
from ..core.experiments import (TRAJECTORY_NAMES, lead_in, spin_up, trajectory,
                                trajectory_parameters)
from ..core import geometry
from .diagnostics import Heartbeat
from .measured_feedback import measured_pose_qos
from .ros_util import (
    Param,
    StartupParameterError,
    Topic,
    command_qos,
    declare_all,
    descriptor,
    diagnostics_qos,
    main_for,
    pose_message,
)

__all__ = ['TrajectoryPublisher', 'main']

_TRAJ_PARAMS = ('trajectory', 'period_s', 'radius_m', 'height_m', 'bending_angle_deg')


D, S, B = (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_STRING,
           ParameterType.PARAMETER_BOOL)
#: The node's parameters: what it declares and what ``--help`` prints.
PARAMETERS = (
    Param('robot_config', 'one_segment', descriptor(
        'Robot description (shipped name or YAML path); sets the default trajectory size. '
        'Read at start-up.', S, read_only=True)),
    Param('trajectory', 'planar_circle', descriptor(
        'Trajectory name: ' + ', '.join(TRAJECTORY_NAMES) + ' (bending_circle: two or more '
        'segments only).', S, constraints='one of: ' + ', '.join(TRAJECTORY_NAMES))),
    Param('rate_hz', 10.0, descriptor(
        'Publishing rate [Hz] (read at start-up).', D, lo=0.1, hi=1000.0, read_only=True)),
    Param('period_s', 0.0, descriptor(
        'Trajectory period [s]; 0 = the default (quasi-static speed, about 2 mm/s).', D,
        lo=0.0, hi=3600.0)),
    Param('radius_m', 0.0, descriptor(
        'Trajectory radius [m]; 0 = the default for the robot.', D, lo=0.0, hi=1.0)),
    Param('height_m', 0.0, descriptor(
        'Height of the trajectory centre above the base [m]; 0 = the default.', D,
        lo=0.0, hi=10.0)),
    Param('bending_angle_deg', 0.0, descriptor(
        'Bending angle of bending_circle [deg]: angle between the end-effector z-axis and '
        'the base z-axis, tilted radially outward (paper: 0, 10, 20). Two or more segments.',
        D, lo=0.0, hi=60.0)),
    Param('base_frame', 'base', descriptor(
        'frame_id of the published targets (robot base).', S)),
    Param('loop', True, descriptor(
        'Repeat the trajectory; false: stop publishing after one period.', B)),
    Param('start_delay_s', 0.0, descriptor(
        'Wait this long after start-up before publishing [s].', D, lo=0.0, hi=3600.0)),
    Param('preview_s', 0.0, descriptor(
        'Publish the pose wanted this far ahead, stamped with the time it is wanted at [s] '
        '(compensates the regulators\' known lag: their dead time + time constant + half '
        'a control period); 0 = the pose wanted now.', D, lo=0.0, hi=2.0, read_only=True)),
    Param('ramp_in_s', 2.0, descriptor(
        'Lead the target from the commanded pose the controller holds (commanded_pose) '
        'onto the path over this long [s], instead of a jump; 0 = off.', D, lo=0.0,
        hi=60.0, read_only=True)),
    Param('spin_up_s', 0.0, descriptor(
        'Start the path with a speed that rises from zero to full over this long [s] '
        '(minimum-jerk timing), instead of at full speed: a robot with a lightly damped '
        'mode then does not ring at a fast path\'s start; 0 = off.', D, lo=0.0, hi=600.0,
        read_only=True)),
)
TOPICS = (
    Topic('publishes', 'target_pose', 'geometry_msgs/PoseStamped',
          'the trajectory in base_frame at rate_hz'),
    Topic('publishes', '/diagnostics', 'diagnostic_msgs/DiagnosticArray', '1 Hz heartbeat'),
    Topic('subscribes', 'target_pose, measured_pose, commanded_pose',
          'geometry_msgs/PoseStamped', 'where the robot is, for the lead-in (ramp_in_s)'),
)


class TrajectoryPublisher(Node):
    """Publishes target poses along a reference trajectory."""

    NODE_NAME = 'trajectory_publisher'
    PARAMETERS = PARAMETERS
    TOPICS = TOPICS

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        declare_all(self, PARAMETERS)

        robot = self.get_parameter('robot_config').value
        try:
            self.cfg = load_robot(robot)
        except ConfigError as exc:
            raise StartupParameterError(
                'robot_config', robot, 'a shipped robot name or a robot YAML path',
                str(exc)) from None
        try:
            self._kwargs = self._trajectory_kwargs({})
        except (ValueError, TypeError) as exc:
            name = self.get_parameter('trajectory').value
            raise StartupParameterError(
                'trajectory', name, 'one of ' + ', '.join(TRAJECTORY_NAMES)
                + ' with valid trajectory parameters', str(exc)) from None
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._pub = self.create_publisher(PoseStamped, 'target_pose', command_qos())
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', diagnostics_qos())
        self.heartbeat = Heartbeat(self, self._pub_diag, self._heartbeat_status,
                                   lambda: self.cfg.name)
        self._t0 = time.monotonic() + float(self.get_parameter('start_delay_s').value)
        # where the robot is, newest of each source: (position, z-axis, arrival time)
        self._seen = {'target_pose': None, 'measured_pose': None, 'commanded_pose': None}
        self._ramp = None      # (start position, start z-axis, duration), False: none
        self._waited = 0.0     # time spent waiting for a pose of the robot before the path
        self._subs = [self.create_subscription(PoseStamped, topic,
                                               lambda m, topic=topic: self._on_pose(topic, m),
                                               qos)
                      for topic, qos in (('target_pose', command_qos()),
                                         ('measured_pose', measured_pose_qos()),
                                         ('commanded_pose', command_qos()))]
        self.published = 0
        self.finished = False
        rate = float(self.get_parameter('rate_hz').value)
        self._timer = self.create_timer(1.0 / rate, self._tick)
        self.get_logger().info(
            f"publishing {self.get_parameter('trajectory').value!r} for robot {self.cfg.name!r} "
            f'at {rate:g} Hz: {self._describe()}')

    def _heartbeat_status(self) -> tuple:
        """Heartbeat: trajectory, its parameters, targets published, finished."""
        values = {'robot': self.cfg.name, 'trajectory': self._kwargs['name'],
                  'targets_published': self.published, 'finished': str(self.finished).lower(),
                  'parameters': self._describe()}
        message = 'finished (loop is false)' if self.finished else 'publishing'
        return DiagnosticStatus.OK, message, values

    def _effective(self) -> dict:
        """The trajectory parameters in use (defaults with the overrides applied)."""
        kw = dict(self._kwargs)
        name = kw.pop('name')
        return trajectory_parameters(name, self.cfg, **kw)

    def _describe(self) -> str:
        p = self._effective()
        text = (f"period {p['period']:g} s, radius {p['radius'] * 1e3:.2f} mm, centre height "
                f"{p['center'][2] * 1e3:.2f} mm")
        if 'bending_angle_deg' in p:
            text += f", bending angle {p['bending_angle_deg']:g} deg"
        return text

    def _trajectory_kwargs(self, override: dict) -> dict:
        """Trajectory keyword arguments from the parameters (``override``: name -> new value)."""
        def val(name):
            return override[name] if name in override else self.get_parameter(name).value
        kw = {'name': val('trajectory')}
        if val('period_s') > 0:
            kw['period'] = float(val('period_s'))
        if val('radius_m') > 0:
            kw['radius'] = float(val('radius_m'))
        if val('height_m') > 0:
            kw['height'] = float(val('height_m'))
        if self.cfg.n_segments >= 2:
            kw['bending_angle_deg'] = float(val('bending_angle_deg'))
        elif val('bending_angle_deg') != 0.0:
            raise ValueError('bending_angle_deg needs a robot with two or more segments')
        args = dict(kw)
        name = args.pop('name')
        trajectory(name, 0.0, self.cfg, **args)   # validates: ValueError with the reason
        return kw

    def _on_set_parameters(self, params) -> SetParametersResult:
        override = {p.name: p.value for p in params if p.name in _TRAJ_PARAMS}
        if not override:
            return SetParametersResult(successful=True)
        try:
            kw = self._trajectory_kwargs(override)
        except (ValueError, TypeError) as exc:
            self.get_logger().warning(f'refused parameter change: {exc}')
            return SetParametersResult(successful=False, reason=str(exc))
        self._kwargs = kw
        return SetParametersResult(successful=True)

    def pose_at(self, t: float):
        """(position (3,), quaternion (4,)) of the target at time ``t`` [s]."""
        kw = dict(self._kwargs)
        name = kw.pop('name')
        pos, z = trajectory(name, t, self.cfg, **kw)
        q = np.array([0.0, 0.0, 0.0, 1.0]) if z is None else geometry.quaternion_from_z_axis(z[0])
        return pos[0], q

    def _period(self) -> float:
        return float(self._effective()['period'])

    def _on_pose(self, topic: str, msg: PoseStamped) -> None:
        if self._ramp is not None or msg.header.frame_id != self.get_parameter('base_frame').value:
            return   # decided already (target_pose: then also our own), or another frame
        p, o = msg.pose.position, msg.pose.orientation
        try:
            z = geometry.z_axis_from_quaternion((o.x, o.y, o.z, o.w))
        except ValueError:
            return
        pos = np.array([p.x, p.y, p.z])
        if np.all(np.isfinite(pos)):
            self._seen[topic] = (pos, z, time.monotonic())

    def _held_pose(self):
        """Where the robot is: the target another node holds it at, else measured, else commanded.

        The held target first (the controller, closed loop or not, keeps the
        robot there); the measured pose (fresh) when no target was sent; the
        controller's commanded pose (fresh) last.  None: nothing known.
        """
        now = time.monotonic()
        for topic, max_age in (('target_pose', math.inf), ('measured_pose', 1.0),
                               ('commanded_pose', 2.0)):
            seen = self._seen[topic]
            if seen is not None and now - seen[2] <= max_age:
                return seen
        return None

    def _ramp_in(self, t: float):
        """Decide once, at the first target: lead in from the held pose (if fresh and off).

        None: undecided yet (no pose seen; wait up to 0.5 s for one: a live controller
        republishes its ``commanded_pose`` at its ``command_rate_hz``).
        """
        duration = float(self.get_parameter('ramp_in_s').value)
        held = self._held_pose()
        start, z_start = self.pose_at(0.0)
        if duration <= 0:
            return False
        if held is None:
            if t < 0.5:
                return None
            self.get_logger().info('no pose of the robot seen (target_pose, measured_pose, '
                                   'commanded_pose): the path starts without a lead-in')
            return False
        if np.linalg.norm(held[0] - start) < 0.5e-3:
            return False
        self.get_logger().info(
            f'leading in from the held pose over {duration:g} s '
            f'({np.linalg.norm(held[0] - start) * 1e3:.1f} mm to the path)')
        return (held[0], held[1], duration)

    @staticmethod
    def _stamp(now, ahead_s: float):
        """``now`` plus ``ahead_s``, as a message stamp."""
        return (now + Duration(nanoseconds=int(ahead_s * 1e9))).to_msg()

    def _tick(self) -> None:
        # one instant for the path's clock and the stamp: the pose is the one wanted at it
        now = self.get_clock().now()
        t = time.monotonic() - self._t0
        if t < 0 or self.finished:
            return
        if self._ramp is None:
            decision = self._ramp_in(t)
            if decision is None:
                return
            self._ramp, self._waited = decision, t   # the lead-in (or the path) starts now
        preview = float(self.get_parameter('preview_s').value)
        t += preview - self._waited   # the pose wanted `preview` from now
        if self._ramp:
            p0, z0, duration = self._ramp
            if t < duration:
                end, q_end = self.pose_at(0.0)
                multi = self.cfg.n_segments >= 2
                pos, z = lead_in(p0, z0 if multi else None, end,
                                 geometry.z_axis_from_quaternion(q_end) if multi else None,
                                 t / duration)
                q = geometry.quaternion_from_z_axis(z) if multi else np.array([0, 0, 0, 1.0])
                self._pub.publish(pose_message(pos, q, self.get_parameter('base_frame').value,
                                               self._stamp(now, preview)))
                return
            t -= duration
        t = spin_up(t, float(self.get_parameter('spin_up_s').value))
        if not self.get_parameter('loop').value and t > self._period():
            self.finished = True
            self.get_logger().info('trajectory finished (loop is false)')
            return
        pos, q = self.pose_at(t)
        self._pub.publish(pose_message(pos, q, self.get_parameter('base_frame').value,
                                       self._stamp(now, preview)))
        self.published += 1


main = main_for(TrajectoryPublisher)


if __name__ == '__main__':
    main()
