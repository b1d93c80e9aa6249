"""Excitation for calibration: steps ``pressure_command`` through the workspace, then vents.

The first step of calibrating a robot (README: record, calibrate, use): this
node drives the actuators directly (no controller) through
:func:`bellow_ancf_ros.core.fit.excitation_sequence`: the paper's
workspace schemes (section VI.B) at ``points_per_scheme`` points each, then
``n_random`` random in-limit vectors (seed ``seed``).  Each step is held for
``dwell_s`` seconds and republished at ``rate_hz`` (a repeated command is not a
new step for ``bellow-ancf calibrate``).  After the last step, and on shutdown
(Ctrl-C/SIGTERM), it publishes the vent command (0 Pa gauge on every actuator)
once and stops; the process then ends (``exit_when_done``).  When another
node publishes ``pressure_command`` it yields (:mod:`bellow_ancf_ros.nodes.ownership`):
the vent once (if it had commanded), the sequence aborted, never resumed;
with ``exit_when_done`` the process ends with status 1.  With ``wait_for_subscribers`` it
starts only once that many subscribers listen on ``pressure_command``.  Record meanwhile, e.g.
``ros2 bag record /pressure_command /measured_pose``; choose ``dwell_s`` well above
calibrate's ``--settle-s``.

Publishes ``pressure_command`` (std_msgs/Float64MultiArray, reliable, keep-last
5, unit ``pressure_unit`` with the labelled layout of the other nodes) and
``/diagnostics`` (step count).  Every published vector passes
:func:`~bellow_ancf_ros.nodes.contract.safe_pressures`.
"""

from __future__ import annotations

import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import ParameterType
from rclpy.duration import Duration
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from ..core import load_robot
from ..core.fit import excitation_sequence
from . import contract
from .diagnostics import publish_diagnostic
from .ros_util import (
    Param,
    StartupParameterError,
    Topic,
    VENT_ACK_TIMEOUT_S,
    command_qos,
    control_clock,
    declare_all,
    descriptor,
    diagnostics_qos,
    guard_parameters,
    main_for,
    pressure_message,
    request_stop,
)
from .ownership import TopicOwner

__all__ = ['ExcitationPublisher', 'main']


D, S, INT, B = (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_STRING,
                ParameterType.PARAMETER_INTEGER, ParameterType.PARAMETER_BOOL)
#: The node's parameters: what it declares and what ``--help`` prints.
PARAMETERS = (
    Param('robot_config', 'one_segment', descriptor(
        'Robot description (shipped name or YAML path): actuator count and pressure limits.',
        S, read_only=True)),
    Param('dwell_s', 3.0, descriptor(
        'Time each step is held [s].', D, lo=0.01, hi=3600.0, read_only=True)),
    Param('rate_hz', 10.0, descriptor(
        'Republishing rate of the current step [Hz].', D, lo=0.1, hi=1000.0, read_only=True)),
    Param('points_per_scheme', 4, descriptor(
        'Points per workspace scheme, p_min to p_max (>= 2).', INT, read_only=True)),
    Param('n_random', 40, descriptor(
        'Random in-limit pressure vectors after the schemes (>= 0).', INT, read_only=True)),
    Param('seed', 0, descriptor('Seed of the random vectors.', INT, read_only=True)),
    Param('pressure_unit', 'Pa', descriptor(
        'Unit of pressure_command: Pa or kPa (gauge; the layout label says the unit).', S,
        constraints="one of: 'Pa', 'kPa'")),
    Param('start_delay_s', 1.0, descriptor(
        'Wait this long before the first step [s] (for recorders to connect).', D,
        lo=0.0, hi=3600.0, read_only=True)),
    Param('wait_for_subscribers', 0, descriptor(
        'Start (then wait start_delay_s) only once pressure_command has this many '
        'subscribers, e.g. 2 for the robot and a recorder.', INT, read_only=True)),
    Param('allow_other_publishers', False, descriptor(
        'Publish pressure_command even while another node publishes it (default false: '
        'vent once and stop, ERROR diagnostics; see ownership in docs/ros.md).', B)),
    Param('exit_when_done', True, descriptor(
        'End the process once the sequence and the vent are done (the vent acknowledged, '
        f'at most {VENT_ACK_TIMEOUT_S:g} s).', B, read_only=True)),
)
TOPICS = (
    Topic('publishes', 'pressure_command', 'std_msgs/Float64MultiArray',
          'the excitation steps, then the vent (0 Pa gauge)'),
    Topic('publishes', '/diagnostics', 'diagnostic_msgs/DiagnosticArray', 'step count'),
)


class ExcitationPublisher(Node):
    """Steps the actuator pressures through the excitation sequence, then vents."""

    NODE_NAME = 'excitation_publisher'
    PARAMETERS = PARAMETERS
    TOPICS = TOPICS

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        """Declare the parameters, build the sequence and start the step timer."""
        super().__init__(node_name, **kwargs)
        declare_all(self, PARAMETERS)
        guard_parameters(self, ('pressure_unit', 'robot_config'))

        self.cfg = load_robot(self.get_parameter('robot_config').value)
        pps = int(self.get_parameter('points_per_scheme').value)
        try:
            self.sequence = excitation_sequence(
                self.cfg, pps, int(self.get_parameter('n_random').value),
                int(self.get_parameter('seed').value))
        except ValueError as exc:   # e.g. points_per_scheme < 2: one line, exit status 2
            raise StartupParameterError('points_per_scheme', pps, 'an integer >= 2',
                                        str(exc)) from None
        for p in self.sequence:       # refuse at start-up rather than mid-run
            contract.safe_pressures(p, self.cfg.p_min, self.cfg.p_max, self.cfg.n_actuators_total)
        self.dwell = float(self.get_parameter('dwell_s').value)
        self.step = -1
        self.published = 0
        self.refused = 0
        self.finished = False
        self.aborted = False   # yielded pressure_command to another node (ownership.py)
        self.vented = False
        self._ack_waited = False
        self._pub = self.create_publisher(Float64MultiArray, 'pressure_command', command_qos())
        self._owner = TopicOwner(self, 'pressure_command',
                                 'start the excitation again once the other node has stopped')
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', diagnostics_qos())
        self._control = control_clock(self)   # the steps' clock: control time (use_sim_time)
        self._t0 = None   # (set at the first tick with the subscribers wanted)
        rate = float(self.get_parameter('rate_hz').value)
        self._timer = self.create_timer(1.0 / rate, self._tick)
        self.get_logger().info(
            f'excitation of robot {self.cfg.name!r}: {len(self.sequence)} steps of '
            f'{self.dwell:g} s ({len(self.sequence) * self.dwell:.0f} s), then vent')

    def _publish(self, pressures_pa, vent: bool = False) -> None:
        p = contract.safe_pressures(pressures_pa, self.cfg.p_min, self.cfg.p_max,
                                    self.cfg.n_actuators_total)
        if not vent and not self._owner.may_publish():   # the vent always goes out
            self.refused += 1
            self._yield()
            return
        self._pub.publish(pressure_message(p, self.get_parameter('pressure_unit').value))
        self.published += 1

    def _yield(self) -> None:
        """Another node publishes pressure_command: vent once, abort, never resume by itself."""
        self._owner.start_yield(vented=self.published > 0)
        self.aborted = self.finished = True
        if self.published:   # it commanded the regulators: they go to the vent
            self.vent(f'yielding pressure_command at step {self.step + 1} of '
                      f'{len(self.sequence)}')
        else:                # it never did: a vent now would only disturb the other node
            self.vented = True

    def _report_yield(self) -> None:
        """After a yield: the ERROR naming the other node, reminders; then exit (status 1)."""
        error = self._owner.report()
        if error:
            self._diag(DiagnosticStatus.ERROR, f'aborted: {error}')
            if self.get_parameter('exit_when_done').value:
                self._timer.cancel()
                self._wait_acked()
                self.get_logger().info('excitation aborted: exiting (status 1)')
                request_stop(exit_status=1)

    def _tick(self) -> None:
        if self.aborted:
            self._report_yield()
            return
        if self.finished:
            return
        if self._t0 is None:
            wanted = int(self.get_parameter('wait_for_subscribers').value)
            if self._pub.get_subscription_count() < wanted:
                return
            self._t0 = self._control.now() + float(self.get_parameter('start_delay_s').value)
        t = self._control.now() - self._t0
        if t < 0:
            return
        step = int(t // self.dwell)
        if step > self.step + 1:   # a stall (a busy CPU) would skip a step: each is sent, and
            step = self.step + 1   # held for its whole dwell from when it went out
            self._t0 = self._control.now() - step * self.dwell
        if step >= len(self.sequence):
            self.vent('excitation finished')
            self.finished = True
            self._timer.cancel()
            if self.get_parameter('exit_when_done').value:
                self._wait_acked()
                self.get_logger().info('sequence and vent done: exiting')
                request_stop()
            return
        if step != self.step:
            self.step = step
            self._diag(DiagnosticStatus.OK, f'step {step + 1} of {len(self.sequence)}')
        self._publish(self.sequence[step])

    def vent(self, why: str) -> None:
        """Publish the vent command (0 Pa gauge on every actuator) once."""
        if self.vented:
            return
        self._publish(contract.vent_pressures(self.cfg.n_actuators_total, self.cfg.p_min,
                                              self.cfg.p_max), vent=True)
        self.vented = True
        self._diag(DiagnosticStatus.OK, f'{why}: vented')
        unit = self.get_parameter('pressure_unit').value
        self.get_logger().info(f'{why}: vent command (0 {unit} gauge) published')

    def vent_and_wait(self) -> None:
        """Vent on shutdown and wait (bounded) until subscribers have it."""
        self.vent('shutdown')
        self._wait_acked()

    def _wait_acked(self) -> None:
        """Wait (once, at most ``VENT_ACK_TIMEOUT_S``) until the subscribers have the vent.

        Fast DDS readers acknowledge on the writer's heartbeat, every 3 s by
        default (ros_util.VENT_ACK_TIMEOUT_S, 4 s): a wait of 1 s ended before
        the acknowledgement in 8 of 10 trials between two processes.  Logs the
        outcome, a subscriber that did not acknowledge as a WARN.
        """
        if self._ack_waited or not self.published:   # nothing sent: nothing to acknowledge
            return
        self._ack_waited = True
        try:
            n = self._pub.get_subscription_count()
            if n == 0:
                return
            t0 = time.monotonic()   # the vent's acknowledgement: real seconds, whatever the clock
            ok = self._pub.wait_for_all_acked(Duration(seconds=VENT_ACK_TIMEOUT_S))
        except Exception:  # noqa: BLE001 - best effort on the way out
            return
        if ok:
            self.get_logger().info(f'vent acknowledged by all {n} matched subscriber(s) in '
                                   f'{(time.monotonic() - t0) * 1e3:.0f} ms')
        else:
            self.get_logger().warning(
                f'vent NOT acknowledged by all {n} matched subscriber(s) within '
                f'{VENT_ACK_TIMEOUT_S:g} s: a subscriber may have missed it')

    def _diag(self, level: bytes, message: str) -> None:
        publish_diagnostic(self, self._pub_diag, f'{self.get_name()}: excitation',
                           self.cfg.name, level, message,
                           {'step': self.step + 1, 'steps': len(self.sequence),
                            'published': self.published, 'refused': self.refused})


main = main_for(ExcitationPublisher, before_destroy=lambda n: n.vent_and_wait())


if __name__ == '__main__':
    main()
