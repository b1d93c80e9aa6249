"""Template of a pressure-regulator driver that vents on its own: the safe pattern for a lab.

A terminal's Ctrl-C reaches every process of a launch at once, and a killed
controller sends nothing: no controller can guarantee that its last
message (the vent) reaches a driver that is exiting too.  So the driver
itself vents, in three cases:

* on its own shutdown (Ctrl-C, SIGTERM, the end of a launch);
* when no ``pressure_command`` arrived for ``command_timeout_s`` (the
  inverse node republishes its current command at ``command_rate_hz``,
  20 Hz by default, so a held target keeps the driver fed: silence means
  the controller is dead, stopped or disconnected);
* never with a bad command: a message with the wrong count, NaN/inf or a
  pressure outside the robot file's ``[p_min, p_max]`` is refused (the
  regulators keep the last good set-points) and reported.

Use: write the function that talks to your regulators and hand it to
:func:`run` (or subclass :class:`RegulatorDriver`)::

    from bellow_ancf_ros.nodes.regulator_driver import run

    def write(pressures_pa):          # numpy array, gauge Pa, actuator order of the robot file
        my_bus.send(pressures_pa)     # your hardware

    if __name__ == '__main__':
        run(write)

``ros2 run bellow_ancf_ros regulator_driver`` runs the template with a
stand-in ``write`` that only logs (at most once a second) what it would
send.  Diagnostics on ``/diagnostics`` at 1 Hz: the command's age, the
state (``waiting``, ``commanding``, ``vented: ...``), counters.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import ParameterType
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from ..core import load_robot
from . import contract
from .diagnostics import Refusals, publish_diagnostic
from .ros_util import (Param, Topic, command_qos, control_clock, declare_all, descriptor,
                       diagnostics_qos, main_for)

__all__ = ['RegulatorDriver', 'main', 'run']

#: Default command timeout [s]: ten periods of the inverse node's 20 Hz republishing.
COMMAND_TIMEOUT_S = 0.5


S, D = ParameterType.PARAMETER_STRING, ParameterType.PARAMETER_DOUBLE
#: The node's parameters: what it declares and what ``--help`` prints.
PARAMETERS = (
    Param('robot_config', 'one_segment', descriptor(
        'Robot file (shipped name or YAML path): the actuator count and pressure limits.', S,
        read_only=True)),
    Param('command_timeout_s', COMMAND_TIMEOUT_S, descriptor(
        'Vent when no pressure_command arrived for this long [s] (the controller republishes '
        'at command_rate_hz).', D, lo=0.01, hi=60.0, read_only=True)),
)
TOPICS = (
    Topic('subscribes', 'pressure_command', 'std_msgs/Float64MultiArray',
          'set-points for the regulators (unit from the layout label)'),
    Topic('publishes', '/diagnostics', 'diagnostic_msgs/DiagnosticArray',
          '1 Hz: command age, state, counters'),
)


class RegulatorDriver(Node):
    """``pressure_command`` -> ``write(pressures_pa)``; vents on timeout and on shutdown."""

    NODE_NAME = 'regulator_driver'
    PARAMETERS = PARAMETERS
    TOPICS = TOPICS

    def __init__(self, write: Callable[[np.ndarray], None] | None = None,
                 node_name: str = NODE_NAME, **kwargs: Any) -> None:
        """``write``: sends gauge pressures [Pa] to the regulators (default: logs them)."""
        super().__init__(node_name, **kwargs)
        declare_all(self, PARAMETERS)
        cfg = load_robot(self.get_parameter('robot_config').value)
        self.cfg = cfg
        self.n = cfg.n_actuators_total
        self.timeout_s = float(self.get_parameter('command_timeout_s').value)
        self._write = write or self._log_write
        self._lock = threading.Lock()
        self._control = control_clock(self)   # the timeout: control time (simulation time too)
        self._last_cmd_t: float | None = None
        self.state = 'waiting for pressure_command'
        self.last_written: np.ndarray | None = None
        self.stats = {'commands': 0, 'refused': 0, 'vents': 0, 'timeouts': 0}
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', diagnostics_qos())
        self._refusals = Refusals(self, 'pressure commands', self._diag)
        self._sub = self.create_subscription(Float64MultiArray, 'pressure_command',
                                             self._on_command, command_qos())
        self._watchdog = self.create_timer(min(0.05, self.timeout_s / 4), self._check_timeout)
        self._status_timer = self.create_timer(1.0, self._status)
        self._logged_t = 0.0
        self.get_logger().info(
            f'regulator driver for {cfg.name!r} ({self.n} actuators, '
            f'[{cfg.p_min / 1e3:g}, {cfg.p_max / 1e3:g}] kPa gauge): vents after '
            f'{self.timeout_s:g} s without pressure_command and on shutdown')

    # ------------------------------------------------------------ the hardware call
    def _log_write(self, p: np.ndarray) -> None:
        now = time.monotonic()   # a log line's throttle: the wall clock
        if now - self._logged_t >= 1.0 or not np.any(p):
            self._logged_t = now
            self.get_logger().info('regulators <- ' + ' '.join(f'{v / 1e3:.2f}' for v in p)
                                   + ' kPa gauge')

    def _send(self, p: np.ndarray) -> None:
        self._write(p)
        self.last_written = p

    # ------------------------------------------------------------ inputs
    def _on_command(self, msg: Float64MultiArray) -> None:
        try:
            label = msg.layout.dim[0].label if msg.layout.dim else ''
            unit = contract.unit_from_label(label) or 'Pa'
            p = contract.safe_pressures(contract.from_unit(np.asarray(msg.data), unit),
                                        self.cfg.p_min, self.cfg.p_max, self.n)
        except ValueError as exc:   # UnsafePressureError: count, NaN/inf, beyond the limits
            self.stats['refused'] += 1
            self._refusals.report(f'refused pressure_command ({exc}); set-points unchanged',
                                  self.stats['refused'])
            return
        with self._lock:
            self._last_cmd_t = self._control.now()
            self.stats['commands'] += 1
            self.state = 'commanding'
            self._send(p)

    def _check_timeout(self) -> None:
        with self._lock:
            t = self._last_cmd_t
            if t is None or self._control.now() - t <= self.timeout_s:
                return
            self._last_cmd_t = None   # vent once; wait for the controller again
            self.stats['timeouts'] += 1
        self.vent(f'no pressure_command for {self.timeout_s:g} s (controller dead or stopped)',
                  timeout=True)

    def vent(self, why: str, timeout: bool = False) -> None:
        """Send 0 Pa gauge to every regulator, log and report why (``timeout``: a WARN)."""
        with self._lock:
            self._send(contract.vent_pressures(self.n, self.cfg.p_min, self.cfg.p_max))
            self.stats['vents'] += 1
            self.state = f'vented: {why}'
        self._log_vent(why, timeout)
        self._diag(DiagnosticStatus.ERROR if timeout else DiagnosticStatus.OK,
                   f'vented: {why}', {})

    def _log_vent(self, why: str, timeout: bool) -> None:
        """A vent on the command timeout is a WARN; on the driver's own shutdown, INFO."""
        if timeout:
            self.get_logger().warning(f'vented: {why}')
        else:
            self.get_logger().info(f'vented: {why}')

    # ------------------------------------------------------------ diagnostics
    def _status(self) -> None:
        with self._lock:
            t, state = self._last_cmd_t, self.state
        level = DiagnosticStatus.OK if state == 'commanding' else DiagnosticStatus.WARN
        age = 'none' if t is None else f'{self._control.now() - t:.3f}'
        self._diag(level, state, {'command_age_s': age})

    def _diag(self, level: bytes, message: str, values: dict) -> None:
        written = ('' if self.last_written is None
                   else ' '.join(f'{v:.6g}' for v in self.last_written))
        publish_diagnostic(self, self._pub_diag, f'{self.get_name()}: regulators', self.cfg.name,
                           level, message, dict(values, **self.stats, written_pa=written))

    def destroy_node(self):
        """Vent before the node goes (Ctrl-C, SIGTERM, the end of a launch)."""
        try:
            self.vent('driver shutdown')
        except Exception as exc:  # noqa: BLE001 - the hardware call failed: say so
            self.get_logger().error(f'vent at shutdown failed: {exc}')
        return super().destroy_node()


def run(write: Callable[[np.ndarray], None]) -> None:
    """Run a :class:`RegulatorDriver` with your ``write`` (as ``ros2 run`` does the template)."""
    main_for(RegulatorDriver, factory=lambda: RegulatorDriver(write))()


main = main_for(RegulatorDriver)


if __name__ == '__main__':
    main()
