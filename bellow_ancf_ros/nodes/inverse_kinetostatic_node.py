"""Inverse-kinetostatic controller (managed / lifecycle node): target poses -> pressures.

``target_pose`` (geometry_msgs/PoseStamped in ``base_frame``; one segment:
the position; two or more: the position and the local z-axis) -> the
target's shaping for the robot's mode (:class:`~.target_link.TargetLink`)
-> the closed loop's correction from ``measured_pose``, with ``feedback:
integral`` (:class:`~.measured_feedback.FeedbackLink`) -> inverse
kinetostatics (core :func:`~bellow_ancf_ros.core.solve_inverse`) -> the
safety gate (:func:`~.contract.safe_pressures`: never NaN, inf or outside
``[p_min, p_max]``) -> ``pressure_command`` (std_msgs/Float64MultiArray, one
gauge pressure per actuator, in Pa or kPa as its layout label says) and
``commanded_pose`` (the model's pose for it); ``/diagnostics``: a status per
solve and a 1 Hz heartbeat in every lifecycle state.

The newest target only is solved, on a worker thread
(:class:`~.worker.LatestWorker`), at most ``max_rate_hz`` times a second,
each solve within a wall-clock budget of ``BUDGET_PERIODS / max_rate_hz``:
a solve that needs more sends the best in-limit pressures so far and goes on
in the next slice (at most ``MAX_CONTINUATIONS``).  Pressures go out only
while active; deactivate, shutdown, Ctrl-C, SIGTERM, the end of the process
that started it and another publisher of ``pressure_command``
(:mod:`.ownership`) each bring the vent command (0 Pa gauge), once, and
shutdown waits for its acknowledgement.  A bad target, an unreachable one,
a failed solve: a throttled log line and a diagnostics status, the last
good command stands, the node keeps serving.

Behaviour, parameters and their reasons: docs/ros.md ("The inverse node's
behaviour"); ``--help`` lists the parameters and topics.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from rclpy.lifecycle import Node as LifecycleNode
from rclpy.lifecycle import State, TransitionCallbackReturn
from std_msgs.msg import Float64MultiArray

from ..core import ConfigError, InverseStatus, RobotModel, payload_problem, solve_inverse
from ..core import geometry
from ..core.control import CommandOutput
from . import contract, diagnostics, lockstep, worker
from .external_force import ExternalForce
from .measured_feedback import FEEDBACK_PARAMETER_TABLE, FeedbackLink
from .mode_watch import ModeWatch
from .target_link import TARGET_PARAMETER_TABLE, TargetLink
from .target_sources import TargetSources, publisher_names
from .ownership import TopicOwner
from .diagnostics import Heartbeat, Refusals, ThrottledStatus, inverse_values, solve_values
from .inverse_interface import CONFIGURE_PARAMETERS, PARAMETERS, TOPICS
from .ros_util import (VENT_ACK_TIMEOUT_S, WARN_THROTTLE_S, command_qos, control_clock,
                       declare_all, diagnostics_qos, guard_parameters, main_for, pose_message,
                       pressure_message, publish_and_wait_acked)

__all__ = ['CONFIGURE_PARAMETERS', 'InverseKinetostaticNode', 'VENT_ACK_TIMEOUT_S', 'main']

BUDGET_PERIODS = 5.0   # wall-clock budget of one solve, in periods of max_rate_hz
PAYLOAD_CHECK_BUDGET_S = 1.0  # wall-clock budget of the buckling check of a new payload_kg
BUDGET_STATUSES = (InverseStatus.TIME_BUDGET, InverseStatus.ITERATION_BUDGET)
MAX_CONTINUATIONS = 40  # budget slices one target may take before the node gives up on it
OWNER_CHECK_PERIOD_S = 0.1  # the ownership check while configured (ownership.py)


class InverseKinetostaticNode(LifecycleNode):
    """Managed feedforward controller: target poses -> actuator pressures."""

    NODE_NAME = 'inverse_kinetostatic_node'
    # (the feedback ones: FeedbackLink; shaping and dynamic feedforward: TargetLink)
    PARAMETERS = PARAMETERS + FEEDBACK_PARAMETER_TABLE + TARGET_PARAMETER_TABLE
    TOPICS = TOPICS

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        declare_all(self, PARAMETERS)
        guard_parameters(self, ('payload_kg', 'pressure_unit', 'max_rate_hz', 'base_frame'),
                         extra_check=self._configure_time_check)
        self._feedback = FeedbackLink(self, self._publish_diag)  # parameter feedback
        self._targets = TargetLink(self)   # target_shaping, dynamic_feedforward
        self._output = None                # the play's and the creep's inverses: CommandOutput
        self._modes: ModeWatch | None = None   # the first mode, when something needs it
        self.add_post_set_parameters_callback(self._after_set)

        self._lock = threading.RLock()    # active flag + publishing + warm start
        self._solve_lock = threading.Lock()   # one solve of the model at a time (worker, checks)
        self._last_target = None   # newest accepted target (position, z-axis), uncorrected
        self._held_item = None     # its worker item (re-solved when the payload changes)
        self._active = self._configured = False
        self._configure_error = ''
        self._model: RobotModel | None = None
        self._cfg = self._warm = self._start_pose = None
        # made on configure: solver thread, topics, ExternalForce, TopicOwner, timers, lockstep
        self._worker: worker.LatestWorker | None = None
        self._pub_cmd = self._pub_pose = self._sub = self._force = self._owner = None
        self._owner_timer = self._republish_timer = self._lockstep = None
        self._yield_requested = self._said_orientation_ignored = False
        self._refusals = Refusals(self, 'targets', self._publish_diag)
        self.last_command_pa: np.ndarray | None = None
        self.last_refusal_reason = ''
        self.last_vent_acked: bool | None = None
        self.stats = {'received': 0, 'refused': 0, 'ignored_inactive': 0, 'solved': 0,
                      'published': 0, 'failed': 0, 'unreachable': 0, 'vents': 0,
                      'over_budget': 0, 'republished': 0}
        self._last_publish_t = -float('inf')   # control time (ControlClock), as every window
        self._now = control_clock(self).now   # (solve budgets, the vent's ack: the wall clock)
        self._last_pose = None   # the commanded_pose of the current command
        self.solve_stats = worker.SolveStats()
        self._slices = worker.BudgetSlices(MAX_CONTINUATIONS)   # budget slices of one target
        # diagnostics in every lifecycle state: per-solve statuses and the 1 Hz heartbeat
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', diagnostics_qos())
        # per-solve statuses: a new level or message at once, an unchanged one at most at 10 Hz
        self._status = ThrottledStatus(self, self._pub_diag,
                                       f'{self.get_name()}: inverse kinetostatics')
        self.heartbeat = Heartbeat(self, self._pub_diag, self._heartbeat_status,
                                   lambda: self._cfg.name if self._cfg is not None else '')
        self.heartbeat.add_source(lambda: self._feedback.heartbeat(self._active,
                                                                   self._targets.status()))
        self.heartbeat.add_source(lambda: {} if self._force is None else self._force.status())

        if self.get_parameter('autostart').value:
            if self.trigger_configure() == TransitionCallbackReturn.SUCCESS:
                self.trigger_activate()
        else:
            path = self._node_path()
            self.get_logger().info(
                f'autostart false: waiting unconfigured (no pressure commands); to start: '
                f'ros2 lifecycle set {path} configure, then ros2 lifecycle set {path} activate')

    # ---------------------------------------------------------- parameters
    def _min_period(self) -> float:
        return 1.0 / float(self.get_parameter('max_rate_hz').value)

    def _time_budget(self) -> float:
        """Wall-clock budget of one inverse solve: ``BUDGET_PERIODS / max_rate_hz``."""
        return BUDGET_PERIODS * self._min_period()

    def _node_path(self) -> str:
        return self.get_fully_qualified_name()

    def _configure_time_check(self, param) -> str:
        """Refuse a change of a parameter read on configure unless unconfigured.

        Refuses a ``feedback_gain_per_s`` or ``target_shaping`` value that
        is not allowed, at any time (an unconfigured node would only find out
        at its next configure).  Also refuses a ``payload_kg`` the configured
        robot cannot carry at the current target (or the current command),
        where the model can tell (core :func:`~bellow_ancf_ros.core.payload_problem`).
        """
        refused = FeedbackLink.refusal(param) or TargetLink.refusal(param)
        if refused:
            return refused
        if not getattr(self, '_configured', False):   # (declaring parameters in __init__)
            return ''
        if param.name == 'payload_kg':
            return self._payload_check(float(param.value))
        if param.name not in CONFIGURE_PARAMETERS:
            return ''
        state = 'active' if self._active else 'inactive'
        return contract.configure_time_refusal(param.name, self._node_path(), state,
                                               self.get_parameter(param.name).value)

    def _after_set(self, params) -> None:
        """Run-time changes in effect: say so; a new payload re-solves the held target."""
        for p in params:
            if p.name == 'max_rate_hz':
                self.get_logger().info(
                    f'max_rate_hz {p.value:g}: at most {p.value:g} solves/s, solve budget '
                    f'{self._time_budget() * 1e3:g} ms, from the next solve')
            elif p.name == 'payload_kg':
                self.get_logger().info(f'payload_kg {p.value:g}: the held target is re-solved')
                self._resolve_held()

    def _resolve_held(self) -> None:
        """Solve the held target again (a new payload or force at the end effector)."""
        item = self._held_item
        if item is not None and self._worker is not None and self.is_active:
            self._worker.submit(item)

    def _payload_check(self, payload: float) -> str:
        """Why the configured robot cannot carry ``payload`` where it is, or ''."""
        with self._lock:
            model, warm, target = self._model, self._warm, self._last_target
            command = self.last_command_pa
        if model is None:
            return ''
        with self._solve_lock:
            if target is not None:
                return payload_problem(model, payload, target[0], target[1], warm_start=warm,
                                       time_budget_s=PAYLOAD_CHECK_BUDGET_S)
            return payload_problem(model, payload, pressures=command,
                                   time_budget_s=PAYLOAD_CHECK_BUDGET_S)

    # ---------------------------------------------------------- lifecycle
    def on_configure(self, state: State) -> TransitionCallbackReturn:
        name = self.get_parameter('robot_config').value
        try:   # fw0: the straight robot at vent pressure (first warm start); start: with payload
            cfg, model, fw0, start = worker.ready_model(
                name, float(self.get_parameter('payload_kg').value))
        except (ConfigError, ValueError, OSError) as exc:
            self._configure_error = f'robot_config {name!r}: {exc}'
            self.get_logger().error(f'configure failed: {self._configure_error}')
            self.get_logger().error(contract.configure_failed_hint(self._node_path()))
            self.heartbeat.publish()
            return TransitionCallbackReturn.FAILURE
        self._configure_error = ''
        with self._lock:
            self._cfg, self._model = cfg, model
            self._warm = fw0 if fw0.success else None
            # the first target after activate moves from here (the robot vented)
            self._start_pose = None if not start.success else (
                start.position, start.z_axis if cfg.n_segments >= 2 else None)
            g = self.get_parameter
            self._output = CommandOutput(model, 1e3 * float(g('regulator_play_kpa').value), (
                float(g('creep_fraction').value), float(g('creep_time_constant_s').value)))
        qos = command_qos()
        self._pub_cmd = self.create_publisher(Float64MultiArray, 'pressure_command', qos)
        self._owner = TopicOwner(self, 'pressure_command',
                                 f'ros2 lifecycle set {self._node_path()} activate')
        self._yield_requested = False
        self._owner_timer = self.create_timer(OWNER_CHECK_PERIOD_S, self._watch_owner)
        self._pub_pose = self.create_publisher(PoseStamped, 'commanded_pose', qos)
        self._sub = self.create_subscription(PoseStamped, 'target_pose', self._on_target, qos)
        self._sources = TargetSources(lambda: self.count_publishers(self._sub.topic_name),
                                      lambda: publisher_names(self, self._sub.topic_name))
        self._force = ExternalForce(
            self, self.get_parameter('base_frame').value,
            self.get_parameter('external_force_timeout_s').value,
            self.get_parameter('use_estimated_force').value, self._refuse, self._resolve_held)
        self._worker = worker.LatestWorker(self._solve, self._min_period, self._on_worker_error,
                                           'inverse-solver', lambda: self._lockstep.work_done())
        self._lockstep = lockstep.LockstepReport(self, self._worker.idle)   # use_sim_time
        rate = float(self.get_parameter('command_rate_hz').value)
        self._republish_timer = (self._lockstep.create_timer(1.0 / rate, self._republish)
                                 if rate > 0 else None)
        if self._feedback.wanted or self._targets.wanted:
            self._modes = ModeWatch(self, self._feedback.mode_check())
            self._modes.start(start)   # the first answer now, at the start equilibrium
        self._feedback.configure(model, self._worker.resubmit, self._modes)   # (re-solves: never
        lag_s = float(self.get_parameter('feedback_loop_lag_s').value)   # over a new target)
        self._targets.configure(self._modes, self._worker.resubmit, lag_s, cfg.first_mode_error)
        self._configured = True
        self.get_logger().info(
            f'configured: robot {cfg.name!r} ({cfg.n_segments} segment(s), {model.A} actuators, '
            f'pressure limits [{cfg.p_min / 1e3:g}, {cfg.p_max / 1e3:g}] kPa gauge), '
            f'targets in {self.get_parameter("base_frame").value!r}, pressure_command in '
            f'{self._unit()} gauge, at most {self.get_parameter("max_rate_hz").value:g} solves/s')
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        owner = self._owner
        if owner is not None and not owner.may_publish():   # one owner (ownership.py)
            self.get_logger().error(
                f'activate refused: {", ".join(owner.others)} publishes {owner.topic}; stop it '
                f'first (or set {owner.allow_param}:=true)')
            return TransitionCallbackReturn.FAILURE
        if owner is not None:
            owner.clear()
        self._worker.clear()   # re-solves queued while inactive: not after this (the old target)
        with self._lock:
            self._active = True
        self._feedback.reset()
        self._targets.reset(self._start_pose)
        self.get_logger().info('active: pressure commands enabled')
        return super().on_activate(state)

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        why = 'yielding pressure_command' if self._owner and self._owner.yielded else 'deactivate'
        self._go_inactive_and_vent(why, wait_acked=False)   # the node lives on
        return super().on_deactivate(state)

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        self._release()
        return super().on_cleanup(state)

    def on_shutdown(self, state: State) -> TransitionCallbackReturn:
        if self._configured:
            self._go_inactive_and_vent('shutdown', wait_acked=True)
        self._release()
        return super().on_shutdown(state)

    def on_error(self, state: State) -> TransitionCallbackReturn:
        if self._configured:
            self._go_inactive_and_vent('error', wait_acked=True)
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def _go_inactive_and_vent(self, why: str, wait_acked: bool) -> None:
        """Disable commands and publish the vent command.

        ``wait_acked``: then wait until every matched subscriber acknowledged
        it (bounded; before the process may exit).
        """
        with self._lock:
            self._active = False
            if self._worker is not None:
                self._worker.clear()
            cfg = self._cfg
            vent = contract.vent_pressures(self._model.A, cfg.p_min, cfg.p_max)
            msg = pressure_message(vent, self._unit())
            self.last_command_pa = vent
            self._output.vent(self._now())
            self._last_pose = None   # (the vented robot's pose is not a solve's)
            self.stats['vents'] += 1
            # under the lock: no solve result can be published after the vent
            what = f'{why}: vent command (0 {self._unit()} gauge)'
            if wait_acked:
                self.last_vent_acked = publish_and_wait_acked(self, self._pub_cmd, msg, what,
                                                              VENT_ACK_TIMEOUT_S)
            else:
                self._pub_cmd.publish(msg)
                self.get_logger().info(f'{what} published')
        self.get_logger().info(f'{why}: commands disabled')

    def _release(self) -> None:
        with self._lock:
            self._active = False
            self._configured = False
        self._owner = None
        for attr, end in (('_modes', 'stop'), ('_worker', 'stop'), ('_force', 'destroy'),
                          ('_republish_timer', self.destroy_timer),
                          ('_owner_timer', self.destroy_timer), ('_lockstep', 'destroy'),
                          ('_sub', self.destroy_subscription),
                          ('_pub_cmd', self.destroy_publisher),
                          ('_pub_pose', self.destroy_publisher)):
            ent = getattr(self, attr, None)
            if ent is not None:
                getattr(ent, end)() if isinstance(end, str) else end(ent)
                setattr(self, attr, None)
        self._feedback.release()   # (no solve runs any more: the worker has stopped)
        self._targets.release()
        with self._lock:
            self._model = self._cfg = self._warm = self._last_pose = None
            self._last_target = self._held_item = None

    def vent_and_shutdown(self) -> None:
        """Shutdown transition from any primary state (vents if configured)."""
        try:
            self.trigger_shutdown()
        except Exception as exc:  # noqa: BLE001 - already finalized etc.
            self.get_logger().debug(f'shutdown transition: {exc}')

    def destroy_node(self):
        """Stop the worker, then destroy the node."""
        if self._worker is not None:
            self._worker.stop()
        return super().destroy_node()

    # ---------------------------------------------------------- heartbeat
    def _heartbeat_status(self) -> tuple:
        """Base heartbeat: lifecycle state, robot, solve statistics, counters."""
        state = diagnostics.lifecycle_state(self, self._active, self._configured)
        cfg = self._cfg
        values = {
            'lifecycle_state': state, 'pressure_unit': self._unit(),
            'robot': cfg.name if cfg is not None else '',
            'robot_config': self.get_parameter('robot_config').value,
            'payload_kg': self.get_parameter('payload_kg').value,
            'pressure_command_subscribers': diagnostics.matched_subscribers(self._pub_cmd),
        }
        values.update(solve_values(self.solve_stats))
        values.update({f'targets_{k}': v for k, v in self.stats.items()})
        if self.last_vent_acked is not None:
            values['last_vent_acked'] = str(self.last_vent_acked).lower()
        owner = getattr(self, '_owner', None)
        level, message = diagnostics.lifecycle_level(
            state, owner.status() if owner is not None and owner.yielded else '',
            self.solve_stats.summary()['last_ok'], self._configure_error,
            contract.configure_failed_hint(self._node_path()),
            values['pressure_command_subscribers'])
        return level, message, values

    @property
    def is_active(self) -> bool:
        with self._lock:
            return self._active

    @property
    def model(self) -> RobotModel | None:
        return self._model

    def _unit(self) -> str:
        return self.get_parameter('pressure_unit').value

    # ---------------------------------------------------------- input
    def _on_target(self, msg: PoseStamped) -> None:
        self._take_target(msg)   # then counted: on simulation time, after its solve is queued
        self._lockstep.received(self._sub.topic_name)

    def _take_target(self, msg: PoseStamped) -> None:
        with self._lock:
            active, cfg = self._active, self._cfg
        if not active or cfg is None:
            self.stats['ignored_inactive'] += 1
            self.get_logger().info('target ignored: node not active',
                                   throttle_duration_sec=WARN_THROTTLE_S)
            return
        self.stats['received'] += 1
        use_orientation = cfg.n_segments >= 2
        if not use_orientation and not self._said_orientation_ignored:
            self._said_orientation_ignored = True
            self.get_logger().info('one-segment robot: target orientation is ignored '
                                   '(position control only)')
        o = msg.pose.orientation
        try:
            pos, z = contract.validate_target(
                (msg.pose.position.x, msg.pose.position.y, msg.pose.position.z),
                (o.x, o.y, o.z, o.w), msg.header.frame_id,
                self.get_parameter('base_frame').value, use_orientation)
        except contract.InputError as exc:
            return self._refuse(str(exc))
        held = self._sources.holds(pos, time.monotonic())   # one publisher at a time
        if held:
            return self._refuse(held)
        item = (pos, z, msg.header.stamp, self._now())
        with self._lock:
            self._last_target = (pos, z)
            self._held_item = item
        self._feedback.remember(item)
        self._worker.submit(item)
        time.sleep(0)   # the GIL to the solver now (0.5 ms of latency: bench/ros_latency.py)

    def _republish(self) -> None:
        """The current command again (``command_rate_hz``), unless a new one just went out.

        Only while active, and only a command that passed the safety gate
        (the last solve's, or the vent): a driver's watchdog sees a live
        controller even while the target is held.
        """
        with self._lock:
            p = self.last_command_pa
            if not self._active or p is None or self._pub_cmd is None:
                return
            if self._owner is None or not self._owner.may_publish():
                self._yield_requested = True   # _watch_owner vents and deactivates
                return
            now, rate = self._now(), float(self.get_parameter('command_rate_hz').value)
            if now - self._last_publish_t < 0.5 / rate:
                return
            if self._output.timed and self._output.wanted is not None:   # (the creep's lead)
                p = self.last_command_pa = contract.safe_pressures(
                    self._output.again(now), self._cfg.p_min, self._cfg.p_max, self._model.A)
            self._lockstep.publish(self._pub_cmd, pressure_message(p, self._unit()))
            if self._last_pose is not None:   # the model's pose for it (stamp: its target's)
                self._pub_pose.publish(self._last_pose)
            self._last_publish_t = self._now()
            self.stats['republished'] += 1

    def _watch_owner(self) -> None:
        """One owner of pressure_command (:mod:`.ownership`): yield once, never resume alone.

        While active, another publisher of the topic makes the node vent once
        and deactivate itself; only ``activate`` resumes.  Then the yield's
        ERROR (once the graph names the other node), the reminder and the
        INFO when it has left (``TopicOwner.poll``).
        """
        owner = self._owner
        if owner is None:
            return
        if self.is_active and (self._yield_requested or not owner.may_publish()):
            owner.start_yield()
            try:
                self.trigger_deactivate()   # the vent, once (on_deactivate)
            except Exception as exc:  # noqa: BLE001 - a transition under way: next tick
                self.get_logger().debug(f'deactivate on yield: {exc}')
                return
        self._yield_requested = False
        error = owner.report()
        if error:
            self._publish_diag(DiagnosticStatus.ERROR, error, {})

    def _refuse(self, reason: str) -> None:
        self.stats['refused'] += 1
        self.last_refusal_reason = reason
        self._refusals.report(reason, self.stats['refused'])

    # ---------------------------------------------------------- solving
    def _on_worker_error(self, exc: BaseException, values: dict | None = None) -> None:
        """A solve raised: ERROR (log and status), the last command stands."""
        self.stats['failed'] += 1
        msg = f'solver exception ({type(exc).__name__}: {exc}); last command kept'
        self.get_logger().error(msg, throttle_duration_sec=WARN_THROTTLE_S)
        self._publish_diag(DiagnosticStatus.ERROR, msg, values or {})

    def _solve(self, item) -> None:
        pos, z, stamp, _t_recv = item
        with self._lock:
            model, cfg, warm, active = self._model, self._cfg, self._warm, self._active
        if model is None or not active:
            return
        warm = self._slices.warm_start(item, warm)   # (a solve with no usable answer yet)
        payload = float(self.get_parameter('payload_kg').value)
        force = None if self._force is None else self._force.current()
        t0 = time.perf_counter()
        try:
            # shaped and shifted for the robot's mode, then corrected by the closed loop
            # (which measures against the shaped pose wanted, not the shifted command)
            cmd, ref = self._targets.targets(item, control_clock(self).time_of(stamp, True))
            pos, z = self._feedback.correct(ref[0], ref[1], stamp, command=cmd,
                                            hold_until=self._targets.hold_until(),
                                            move=self._targets.move())
            with self._solve_lock:
                inv = solve_inverse(model, pos, z, payload_kg=payload, warm_start=warm,
                                    time_budget_s=self._time_budget(), tip_force_n=force)
        except Exception as exc:  # noqa: BLE001 - keep serving (RecursionError too)
            dt = time.perf_counter() - t0
            self.solve_stats.record(dt, ok=False)
            self._on_worker_error(exc, {'solve_time_ms': f'{dt * 1e3:.3f}', 'payload_kg': payload})
            return
        dt = time.perf_counter() - t0
        self.stats['solved'] += 1
        fw = inv.forward
        usable = fw is not None and fw.success
        self.solve_stats.record(dt, ok=usable)
        p, unsafe = None, None
        if usable:
            try:
                p = contract.safe_pressures(inv.pressures_pa, cfg.p_min, cfg.p_max, model.A)
            except contract.UnsafePressureError as exc:
                unsafe = exc
        owner = self._owner
        if p is not None and (owner is None or not owner.may_publish()):
            self._yield_requested = True   # _watch_owner vents and deactivates
            self._feedback.no_command()
            return
        unit = self._unit()
        if p is not None:   # the command first (at its time on a stream's grid), then the rest
            self._targets.pace()
            with self._lock:
                if not self._active or self._model is not model:
                    return   # deactivated while solving: the vent command stands
                self._warm = inv
                if stamp.sec == 0 and stamp.nanosec == 0:
                    stamp = self.get_clock().now().to_msg()
                # past the regulators' play, ahead of the creep (as configured)
                p = contract.safe_pressures(self._output.command(p, self._now()), cfg.p_min,
                                            cfg.p_max, model.A)
                self._lockstep.publish(self._pub_cmd, pressure_message(p, unit))   # (counted)
                self._last_publish_t = self._now()
                self._last_pose = pose_message(
                    fw.position, geometry.quaternion_from_rotation(fw.rotation),
                    self.get_parameter('base_frame').value, stamp)
                self._pub_pose.publish(self._last_pose)
                self.last_command_pa = p
                self.stats['published'] += 1
        self._report(item, inv, dt, payload, unit, p, unsafe, usable)

    def _report(self, item, inv, dt, payload, unit, p, unsafe, usable) -> None:
        """Counters, log line and status of one solve (after its command went out).

        ``p``: the published pressures (None: nothing published, because the
        solve was not ``usable`` or the safety gate refused it, ``unsafe``).
        A budget-limited answer queues the same target again (its next
        slice, :class:`~.worker.BudgetSlices`, :meth:`_queue_slice`).
        """
        values = inverse_values(inv, dt, payload, unit)
        if usable and unsafe is None:
            self._feedback.after_solve(inv)
            if self._modes is not None:
                self._modes.offer(inv.forward)
        else:
            self._feedback.no_command()   # nothing goes out: the integrator freezes
        values.update(self._feedback.status())
        values.update(self._targets.status())
        budget = inv.status in BUDGET_STATUSES
        more = budget and unsafe is None and self._slices.next(
            item, self._queue_slice, None if usable else inv)   # (unusable: goes on from it)
        if p is not None:
            values['pressures'] = ' '.join(f'{v:.6g}' for v in contract.to_unit(p, unit))
        level, msg, counter, logged = diagnostics.solve_outcome(
            inv, usable, budget, more, unsafe,
            values.get('feedback_state', '') if self._feedback.fallback else None)
        if counter is not None:
            self.stats[counter] += 1
        if logged and level == DiagnosticStatus.ERROR:   # (rclpy: one severity per call site)
            self.get_logger().error(msg, throttle_duration_sec=WARN_THROTTLE_S)
        elif logged:
            self.get_logger().warning(msg, throttle_duration_sec=WARN_THROTTLE_S)
        self._publish_diag(level, msg, values)

    def _queue_slice(self, item) -> bool:
        """Queue ``item`` again for its next budget slice (unless a newer one waits); queued."""
        with self._lock:   # deactivated meanwhile: no slice (the vent stands; an old target
            if not self._active:   # must not be solved after a later activate)
                return False
            return self._worker is not None and self._worker.resubmit(item)

    def _publish_diag(self, level: bytes, message: str, values: dict) -> None:
        cfg = self._cfg
        self._status.submit(cfg.name if cfg is not None else '', level, message, values)


main = main_for(InverseKinetostaticNode, before_destroy=lambda n: n.vent_and_shutdown())


if __name__ == '__main__':
    main()
