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
The lead-in starts once the controller can follow it: when the lifecycle node
``controller_node`` (default ``inverse_kinetostatic_node``, asked through its
``get_state`` service) is active, or a ``commanded_pose`` or
``predicted_pose`` shows a controller at work, or after
``controller_timeout_s`` (default 300 s, a warning); a controller that
starts slowly (two segments: loading the compiled kernels, warm-up) would
otherwise miss the lead-in and see the path's start as its first target.
The lead-in's first point is then held until the controller's
``commanded_pose`` answers one of them (by its stamp; at most
:data:`ANSWER_WAIT_S`): a controller just active may not have discovered
this publisher yet, and would otherwise start further along the lead-in.
Where the robot is (for the lead-in): the target another node holds it at
(``target_pose``), else its ``measured_pose``, else the controller's
``commanded_pose``, else the forward node's ``predicted_pose``; with none of
them seen, the robot at rest: vented (0 Pa gauge), carrying ``payload_kg``.
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
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from lifecycle_msgs.srv import GetState
from rcl_interfaces.msg import ParameterType, SetParametersResult
from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node

from ..core import ConfigError, RobotModel, load_robot, solve_forward
from ..core.experiments import (TRAJECTORY_NAMES, lead_in, spin_up, trajectory,
                                trajectory_parameters, trajectory_target)
from ..core import geometry
from . import contract
from .diagnostics import Heartbeat
from .lockstep import LockstepReport
from .measured_feedback import measured_pose_qos
from .ros_util import (
    Param,
    StartupParameterError,
    Topic,
    command_qos,
    control_clock,
    declare_all,
    descriptor,
    diagnostics_qos,
    main_for,
    pose_message,
)

__all__ = ['TrajectoryPublisher', 'main']

_TRAJ_PARAMS = ('trajectory', 'period_s', 'radius_m', 'height_m', 'bending_angle_deg')
#: Shortest wait for a pose of the robot before the lead-in [s]: a live controller
#: republishes its ``commanded_pose`` at its ``command_rate_hz`` (20 Hz by default).
POSE_WAIT_S = 0.5
#: Time between two questions to the controller about its lifecycle state [s].
CONTROLLER_POLL_S = 0.5
#: Longest hold of the lead-in's first point until the controller answers it [s].
ANSWER_WAIT_S = 5.0


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
        'Wait this long after start-up before publishing [s]. On simulation time a publisher '
        'that starts earlier than this much simulated time starts its path at exactly this '
        'simulated time (every run of a simulation started paused starts alike).', D,
        lo=0.0, hi=3600.0)),
    Param('preview_s', 0.0, descriptor(
        'Publish the pose wanted this far ahead, stamped with the time it is wanted at [s] '
        '(compensates the regulators\' known lag: their dead time + time constant + half '
        'a control period); 0 = the pose wanted now.', D, lo=0.0, hi=2.0, read_only=True)),
    Param('ramp_in_s', 2.0, descriptor(
        'Lead the target from where the robot is (a held target_pose, measured_pose, '
        'commanded_pose, predicted_pose, else the robot at rest, vented) onto the path over '
        'this long [s], instead of a jump, once the controller is active; 0 = off.', D,
        lo=0.0, hi=60.0, read_only=True)),
    Param('controller_node', 'inverse_kinetostatic_node', descriptor(
        'Lifecycle node the lead-in waits for (its get_state service): the first target goes '
        'out once it is active (or a commanded_pose or predicted_pose is seen, or '
        'controller_timeout_s has passed); empty: no wait.', S, read_only=True)),
    Param('controller_timeout_s', 300.0, descriptor(
        'Longest wait for controller_node to be active before the lead-in [s] (a first start '
        'compiles the kernels: about a minute on 2 cores); then it starts anyway, with a '
        'warning.', D, lo=0.0, hi=3600.0, read_only=True)),
    Param('payload_kg', 0.0, descriptor(
        'Payload the robot carries [kg]: where the robot rests, vented, when no pose of it '
        'is seen (the lead-in starts there).', D, lo=0.0, hi=contract.PAYLOAD_MAX_KG)),
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
    Topic('subscribes', 'target_pose, measured_pose, commanded_pose, predicted_pose',
          'geometry_msgs/PoseStamped', 'where the robot is, for the lead-in (ramp_in_s)'),
    Topic('calls', '<controller_node>/get_state', 'lifecycle_msgs/GetState',
          'the lead-in waits for the controller to be active'),
    Topic('publishes', 'lockstep_clock', 'std_msgs/Header',
          'use_sim_time: the simulation time just before its next target (a lockstep)'),
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
        self._path = (None, None)   # (the kwargs it is of, trajectory_target): pose_at
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
        # every time here is control time (ros_util.ControlClock: simulation time under
        # use_sim_time); stamps are the ROS clock's.  The path's clock starts now, or under
        # use_sim_time at the first tick: the clock reads 0 until the first /clock arrives
        self._control = control_clock(self)
        self._t0 = (None if self._control.simulated
                    else self._control.now() + float(self.get_parameter('start_delay_s').value))
        # where the robot is, newest of each source: (position, z-axis, arrival time)
        self._seen = {'target_pose': None, 'measured_pose': None, 'commanded_pose': None,
                      'predicted_pose': None}
        self._ramp = None      # (start position, start z-axis, duration), False: none
        self._waited = 0.0     # time spent waiting for a pose of the robot before the path
        self._subs = [self.create_subscription(PoseStamped, topic,
                                               lambda m, topic=topic: self._on_pose(topic, m),
                                               qos)
                      for topic, qos in (('target_pose', command_qos()),
                                         ('measured_pose', measured_pose_qos()),
                                         ('commanded_pose', command_qos()),
                                         ('predicted_pose', command_qos()))]
        # the controller the lead-in waits for: its lifecycle state, asked every CONTROLLER_POLL_S
        controller = self.get_parameter('controller_node').value.strip().rstrip('/')
        try:
            self._state_client = (self.create_client(GetState, f'{controller}/get_state')
                                  if controller else None)
        except Exception as exc:  # noqa: BLE001 - rclpy's InvalidServiceNameException
            raise StartupParameterError(
                'controller_node', controller, "a node name (e.g. 'inverse_kinetostatic_node') "
                "or '' (no wait)", type(exc).__name__) from None
        self._controller = (self._state_client.service_name.rsplit('/get_state', 1)[0]
                            if controller else '')
        self._controller_state = ''          # its lifecycle state as last answered
        self._state_future, self._state_asked = None, -math.inf
        self._said_waiting = False
        self._expect_answer = False   # a controller answers our targets on commanded_pose
        self._hold_since = None       # holding the lead-in's first point since (control time)
        self._hold_stamp_ns = None    # the stamp of its first copy
        self._answered = False        # a commanded_pose answered one of them
        self.published = 0
        self.finished = False
        rate = float(self.get_parameter('rate_hz').value)
        self._period_ns = int(round(1e9 / rate))
        self._due_ns = None   # on simulation time: the next tick [ns]
        if self._control.simulated:
            # a tick at the first clock update at or after it is due (rcl's timers on /clock
            # can fire twice at one time and skip the next tick: a target stamped twice, the
            # next one missing, and the dynamic feedforward took a new stream for a jump)
            self._timer = None
            self._time_hook = self.get_clock().create_jump_callback(
                JumpThreshold(min_forward=Duration(nanoseconds=1),
                              min_backward=Duration(nanoseconds=-1), on_clock_change=False),
                post_callback=self._on_time)
        else:
            self._timer = self.create_timer(1.0 / rate, self._tick)
        # on simulation time: no simulated step passes a tick before its target is out
        self._lockstep = LockstepReport(self, follow_clock=False)
        self.get_logger().info(
            f"publishing {self.get_parameter('trajectory').value!r} for robot {self.cfg.name!r} "
            f'at {rate:g} Hz: {self._describe()}')

    def _heartbeat_status(self) -> tuple:
        """Heartbeat: trajectory, its parameters, targets published, finished."""
        values = {'robot': self.cfg.name, 'trajectory': self._kwargs['name'],
                  'targets_published': self.published, 'finished': str(self.finished).lower(),
                  'parameters': self._describe()}
        message = ('finished (loop is false)' if self.finished
                   else f'waiting for {self._controller} to be active'
                   if self._ramp is None and self._said_waiting else 'publishing')
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
        kw = self._kwargs
        if self._path[0] is not kw:   # checked and merged once per change
            args = dict(kw)
            name = args.pop('name')
            self._path = (kw, trajectory_target(name, self.cfg, **args))
        pos, z = self._path[1](t)
        q = np.array([0.0, 0.0, 0.0, 1.0]) if z is None else geometry.quaternion_from_z_axis(z)
        return pos, q

    def _period(self) -> float:
        return float(self._effective()['period'])

    def _on_pose(self, topic: str, msg: PoseStamped) -> None:
        if topic == 'commanded_pose' and self._hold_stamp_ns is not None and (
                msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec >= self._hold_stamp_ns):
            self._answered = True   # the controller's pose for one of our targets (its stamp)
        if self._ramp is not None or msg.header.frame_id != self.get_parameter('base_frame').value:
            return   # decided already (target_pose: then also our own), or another frame
        p, o = msg.pose.position, msg.pose.orientation
        try:
            z = geometry.z_axis_from_quaternion((o.x, o.y, o.z, o.w))
        except ValueError:
            return
        pos = np.array([p.x, p.y, p.z])
        if np.all(np.isfinite(pos)):
            self._seen[topic] = (pos, z, self._control.now())

    #: The sources of where the robot is, in order, with the age [s] up to which each counts.
    _SOURCES = (('target_pose', math.inf), ('measured_pose', 1.0), ('commanded_pose', 2.0),
                ('predicted_pose', 2.0))

    def _fresh(self, topic: str) -> bool:
        seen, max_age = self._seen[topic], dict(self._SOURCES)[topic]
        return seen is not None and self._control.now() - seen[2] <= max_age

    def _held_pose(self):
        """Where the robot is, seen on a topic: ``(topic, (position, z-axis, time))`` or None.

        The held target first (the controller, closed loop or not, keeps the
        robot there); the measured pose (fresh) when no target was sent; the
        controller's commanded pose (fresh); the forward node's prediction for
        the pressures commanded (fresh) last.  None: nothing seen.
        """
        for topic, _ in self._SOURCES:
            if self._fresh(topic):
                return topic, self._seen[topic]
        return None

    def _rest_pose(self):
        """The robot at rest: vented (0 Pa gauge), carrying ``payload_kg``; None if unsolved.

        ``(position, z-axis, time)`` as :meth:`_held_pose` gives it.  The forward
        solve has its iteration budget and reports failure.
        """
        model = RobotModel(self.cfg)
        payload = float(self.get_parameter('payload_kg').value)
        fw = solve_forward(model, contract.vent_pressures(model.A, self.cfg.p_min,
                                                          self.cfg.p_max), payload_kg=payload)
        if not fw.success:
            self.get_logger().warning(f'the robot at rest (vented, payload {payload:g} kg) '
                                      f'was not solved ({fw.message})')
            return None
        return fw.position, fw.z_axis, self._control.now()

    def _poll_controller(self) -> None:
        """Ask ``controller_node`` its lifecycle state (one question at a time, throttled)."""
        fut = self._state_future
        if fut is not None:
            if not fut.done():
                return
            self._state_future = None
            res = fut.result()
            if res is not None:
                self._controller_state = res.current_state.label
                if self._controller_state == 'active':
                    return
        now = self._control.now()
        if now - self._state_asked >= CONTROLLER_POLL_S and self._state_client.service_is_ready():
            self._state_asked = now
            self._state_future = self._state_client.call_async(GetState.Request())

    def _controller_subscribed(self) -> bool:
        """Whether ``controller_node``'s subscription of our targets has been discovered."""
        namespace, _, name = self._controller.rpartition('/')
        return any(i.node_name == name and i.node_namespace == (namespace or '/')
                   for i in self.get_subscriptions_info_by_topic(self._pub.topic_name))

    def _controller_ready(self, t: float) -> bool:
        """Whether a controller follows targets now (else wait, up to ``controller_timeout_s``).

        Ready: ``controller_node`` answered that it is active (and its
        subscription of ``target_pose`` is discovered), or a fresh
        ``commanded_pose`` or ``predicted_pose`` shows a controller at work, or
        no controller is named.  After ``controller_timeout_s`` of waiting: a
        warning, and ready.  Sets ``_expect_answer`` when a controller will
        answer the targets on ``commanded_pose`` (:meth:`_hold_first_point`).
        """
        self._expect_answer = self._fresh('commanded_pose')
        if self._state_client is None or self._expect_answer or self._fresh('predicted_pose'):
            return True
        self._poll_controller()
        if self._controller_state == 'active' and self._controller_subscribed():
            if self._said_waiting:
                self.get_logger().info(f'{self._controller} is active (after {t:.1f} s)')
            self._expect_answer = True
            return True
        timeout = float(self.get_parameter('controller_timeout_s').value)
        if t >= timeout:
            state = self._controller_state or 'no answer to get_state'
            self.get_logger().warning(
                f'{self._controller} not active after {timeout:g} s ({state}): leading in '
                'anyway; targets sent before it is active are ignored by it')
            return True
        if not self._said_waiting:
            self._said_waiting = True
            self.get_logger().info(
                f'waiting for {self._controller} to be active before the first target (at most '
                f'{timeout:g} s, controller_timeout_s), so that it follows the lead-in')
        return False

    def _ramp_in(self, t: float):
        """Decide once, at the first target: lead in from where the robot is (if off the path).

        None: undecided yet.  Waits :data:`POSE_WAIT_S` for a pose of the robot
        (unless one was seen) and for the controller (:meth:`_controller_ready`);
        then leads in from :meth:`_held_pose`, else from :meth:`_rest_pose`.
        """
        duration = float(self.get_parameter('ramp_in_s').value)
        if duration <= 0:
            return False
        if self._held_pose() is None and t < POSE_WAIT_S:
            return None
        if not self._controller_ready(t):
            return None
        held = self._held_pose()
        if held is not None:
            where, pose = f'the pose on {held[0]}', held[1]
        else:
            where, pose = 'the robot at rest (vented; no pose of it seen)', self._rest_pose()
            if pose is None:
                self.get_logger().info('the path starts without a lead-in')
                return False
        start, _ = self.pose_at(0.0)
        distance = np.linalg.norm(pose[0] - start)
        if distance < 0.5e-3:
            return False
        self.get_logger().info(f'leading in from {where} over {duration:g} s '
                               f'({distance * 1e3:.1f} mm to the path)')
        return (pose[0], pose[1], duration)

    @staticmethod
    def _stamp(now, ahead_s: float):
        """``now`` plus ``ahead_s``, as a message stamp."""
        return (now + Duration(nanoseconds=int(ahead_s * 1e9))).to_msg()

    def _publish_lead_in(self, fraction: float, stamp) -> None:
        """The lead-in's target at ``fraction`` (0: where the robot is, 1: the path's start)."""
        p0, z0, _ = self._ramp
        end, q_end = self.pose_at(0.0)
        multi = self.cfg.n_segments >= 2
        pos, z = lead_in(p0, z0 if multi else None, end,
                         geometry.z_axis_from_quaternion(q_end) if multi else None, fraction)
        q = geometry.quaternion_from_z_axis(z) if multi else np.array([0, 0, 0, 1.0])
        self._lockstep.publish(self._pub, pose_message(
            pos, q, self.get_parameter('base_frame').value, stamp))

    def _hold_first_point(self, now, preview: float) -> bool:
        """Publish the lead-in's first point until the controller answers one (True: held).

        A controller that has just become active may not have discovered this
        publisher yet: the targets sent meanwhile are lost to it, and its
        first would be one further along the lead-in (a jump).  Its
        ``commanded_pose`` stamped with one of ours says that it follows.  At
        most :data:`ANSWER_WAIT_S` (then a warning); False: the lead-in moves on now.
        """
        waited = self._control.now() - self._hold_since
        if not self._answered and waited < ANSWER_WAIT_S:
            stamp = self._stamp(now, preview)
            if self._hold_stamp_ns is None:
                self._hold_stamp_ns = stamp.sec * 10**9 + stamp.nanosec
            self._publish_lead_in(0.0, stamp)
            return True
        if self._answered:
            self.get_logger().info(f'the controller answered the lead-in\'s first point after '
                                   f'{waited:.2f} s: leading in')
        else:
            self.get_logger().warning(f'no commanded_pose answered the lead-in\'s first point '
                                      f'within {ANSWER_WAIT_S:g} s: leading in all the same')
        self._hold_since = None
        return False

    def _on_time(self, jump) -> None:
        """Simulation time moved: a tick if due (the first a period after start or reset)."""
        now = self.get_clock().now().nanoseconds
        if self._due_ns is None or jump.delta.nanoseconds < 0:   # (back: a reset, a looped bag)
            self._due_ns = now
        if now < self._due_ns:
            return
        # the next tick: on the path's grid once it has a start (the same stamps in every run)
        base = self._due_ns if self._t0 is None else int(round(self._t0 * 1e9))
        self._due_ns = base + self._period_ns * (1 + (now - base) // self._period_ns)
        self._tick()

    def _tick(self) -> None:
        try:
            self._publish_target()
        finally:
            if self._lockstep.active:
                if self.finished:
                    self._lockstep.destroy()   # no more targets: the simulation waits no longer
                elif self._due_ns is not None:   # done until just before the next tick
                    self._lockstep.report(1e-9 * self._due_ns - 1e-6)

    def destroy_node(self):
        """Leave the simulation's lockstep, then destroy the node."""
        if getattr(self, '_lockstep', None) is not None:
            self._lockstep.destroy()
        return super().destroy_node()

    def _publish_target(self) -> None:
        # one instant for the path's clock and the stamp: the pose is the one wanted at it
        now = self.get_clock().now()
        if self._t0 is None:
            start, delay = self._control.now(), float(self.get_parameter('start_delay_s').value)
            self._t0 = delay if self._control.simulated and start < delay else start + delay
        t = self._control.now() - self._t0
        if t < 0 or self.finished:
            return
        if self._ramp is None:
            decision = self._ramp_in(t)
            if decision is None:
                return
            # the lead-in (or the path) starts now: after the decision (a forward solve)
            now, t = self.get_clock().now(), self._control.now() - self._t0
            self._ramp, self._waited = decision, t
            if decision and self._expect_answer:
                self._hold_since = self._control.now()
        preview = float(self.get_parameter('preview_s').value)
        if self._hold_since is not None:
            if self._hold_first_point(now, preview):
                return
            self._waited = t   # the lead-in's clock starts now
        t += preview - self._waited   # the pose wanted `preview` from now
        if self._ramp:
            duration = self._ramp[2]
            if t < duration:
                self._publish_lead_in(t / duration, self._stamp(now, preview))
                return
            t -= duration
        t = spin_up(t, float(self.get_parameter('spin_up_s').value))
        if not self.get_parameter('loop').value and t > self._period():
            self.finished = True
            self.get_logger().info('trajectory finished (loop is false)')
            return
        pos, q = self.pose_at(t)
        self._lockstep.publish(self._pub, pose_message(
            pos, q, self.get_parameter('base_frame').value, self._stamp(now, preview)))
        self.published += 1


main = main_for(TrajectoryPublisher)


if __name__ == '__main__':
    main()
