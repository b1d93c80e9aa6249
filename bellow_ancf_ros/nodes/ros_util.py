"""rclpy helpers shared by the nodes.

QoS profiles, checked parameter declaration, message builders, the
vent-acknowledgement wait, and the start-up / spin / shutdown idiom of every
node executable.  Diagnostics (statuses, the 1 Hz heartbeat) live in
:mod:`bellow_ancf_ros.nodes.diagnostics`, the pure (rclpy-free) helpers in
:mod:`bellow_ancf_ros.nodes.contract`.
"""

from __future__ import annotations

import faulthandler
import gc
import os
import signal
import sys
import tempfile
import textwrap
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
import rclpy
import yaml
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.duration import Duration
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
)
from rclpy.executors import (
    ExternalShutdownException, ShutdownException, SingleThreadedExecutor)
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from ..core import ConfigError, limit_blas_threads, numba_cache
from . import contract
from .realtime import use_realtime

__all__ = [
    'ControlClock', 'EXECUTOR_ENV', 'EXECUTORS', 'QOS_DEPTH', 'STARTUP_ERROR_EXIT',
    'SWITCH_INTERVAL_S',
    'VENT_ACK_TIMEOUT_S', 'WARN_THROTTLE_S', 'Param', 'StartupEnvironmentError',
    'StartupParameterError', 'Topic', 'allowed_values', 'asks_for_help', 'command_qos',
    'declare', 'declare_all', 'descriptor', 'diagnostics_qos', 'executor_choice',
    'guard_parameters', 'init_rclpy', 'main_for', 'make_executor', 'control_clock',
    'control_now', 'node_help', 'pose_message', 'pressure_message',
    'publish_and_wait_acked', 'request_stop', 'run_node', 'spin_until_closed', 'watch_parent',
]

QOS_DEPTH = 5
WARN_THROTTLE_S = 2.0
#: Longest wait for the matched subscribers to acknowledge the vent command on shutdown [s].
#: Fast DDS readers acknowledge on the writer's heartbeat (every 3 s by default), so
#: an acknowledgement takes up to about 3 s; 4 s stays below ``ros2 launch``'s 5 s
#: between SIGINT and SIGTERM.
VENT_ACK_TIMEOUT_S = 4.0
#: Exit status of a node executable that cannot start with its parameters.
STARTUP_ERROR_EXIT = 2

_TYPE_NAMES = {
    ParameterType.PARAMETER_BOOL: 'true or false',
    ParameterType.PARAMETER_INTEGER: 'an integer',
    ParameterType.PARAMETER_DOUBLE: 'a floating-point number (write 1.0, not 1)',
    ParameterType.PARAMETER_STRING: 'a string',
    ParameterType.PARAMETER_DOUBLE_ARRAY: 'a list of floating-point numbers',
    ParameterType.PARAMETER_INTEGER_ARRAY: 'a list of integers',
    ParameterType.PARAMETER_STRING_ARRAY: 'a list of strings',
}


# ------------------------------------------------------------------ QoS
def command_qos() -> QoSProfile:
    """Reliable, keep-last, depth :data:`QOS_DEPTH` (targets, pressures, poses)."""
    return QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                      depth=QOS_DEPTH)


def diagnostics_qos() -> QoSProfile:
    """Reliable, keep-last 10 (``/diagnostics``)."""
    return QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                      depth=10)


# ------------------------------------------------------------ parameters
class StartupParameterError(ValueError):
    """A parameter value given at start-up that the node cannot run with.

    ``str()`` is one line naming the parameter, the value and what is allowed.
    """

    def __init__(self, name: str, value: Any, allowed: str, reason: str = '') -> None:
        self.name, self.value, self.allowed, self.reason = name, value, allowed, reason
        text = f'parameter {name} = {value!r} is not allowed'
        if reason:
            text += f' ({reason})'
        super().__init__(f'{text}; allowed: {allowed}')


class StartupEnvironmentError(StartupParameterError):
    """An environment variable the node cannot run with (one line: name, value, allowed)."""

    def __init__(self, name: str, value: Any, allowed: str) -> None:
        self.name, self.value, self.allowed, self.reason = name, value, allowed, ''
        ValueError.__init__(self, f'environment variable {name} = {value!r} is not allowed; '
                                  f'allowed: {allowed}')


def descriptor(description: str, ptype: int, *, lo: float | None = None,
               hi: float | None = None, read_only: bool = False,
               constraints: str = '', dynamic: bool = False) -> ParameterDescriptor:
    """Build a ParameterDescriptor with description, optional range and constraints text.

    ``lo``/``hi`` give a floating-point range for doubles and an integer range
    for integers.  ``dynamic``: the value may change type (e.g. ``'auto'`` or a
    number); the node checks it itself and ``constraints`` says what is allowed.
    """
    d = ParameterDescriptor(description=description, type=ptype, read_only=read_only,
                            additional_constraints=constraints, dynamic_typing=dynamic)
    if dynamic:
        d.type = ParameterType.PARAMETER_NOT_SET
    if lo is not None and hi is not None:
        if ptype == ParameterType.PARAMETER_INTEGER:
            d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
        else:
            d.floating_point_range = [FloatingPointRange(from_value=float(lo),
                                                         to_value=float(hi), step=0.0)]
    return d


def allowed_values(d: ParameterDescriptor) -> str:
    """What a descriptor allows, in words: type, range and constraints."""
    parts = [] if d.dynamic_typing else [_TYPE_NAMES.get(d.type, 'a value')]
    if d.floating_point_range:
        r = d.floating_point_range[0]
        parts.append(f'from {r.from_value:g} to {r.to_value:g}')
    if d.integer_range:
        r = d.integer_range[0]
        parts.append(f'from {r.from_value} to {r.to_value}')
    if d.additional_constraints:
        parts.append(d.additional_constraints)
    return ', '.join(parts)


def _descriptor_refusal(d: ParameterDescriptor, param) -> str:
    """What rclpy refuses in ``param`` (an rclpy ``Parameter``) against ``d``: 'type', 'range'.

    Or '' when it passes.  rclpy checks the type and the range itself, before
    any set-parameters callback, and its reply names neither the key nor the
    value: the nodes log their own line for it (:func:`_log_descriptor_refusals`).
    """
    kind = param.type_.value
    if kind == ParameterType.PARAMETER_NOT_SET or d.dynamic_typing:
        return ''
    if kind != d.type:
        return 'type'
    if kind in (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_INTEGER):
        for r in list(d.floating_point_range) + list(d.integer_range):
            if not (r.from_value <= param.value <= r.to_value):   # (NaN too)
                return 'range'
    return ''


def _log_descriptor_refusals(node) -> None:
    """Log a line naming key, value and what is allowed for each change rclpy refuses.

    rclpy refuses a wrong type or a value outside the descriptor's range before
    any set-parameters callback, with a reply that names neither the key nor
    the value (``Wrong parameter type, expected 'Type.DOUBLE' got
    'Type.INTEGER'``: ``ros2 param set ... payload_kg 1``) and nothing in the
    node's log.  A pre-set callback (once per node) sees every change first.
    """
    if getattr(node, '_bellow_refusals_logged', False):
        return
    node._bellow_refusals_logged = True

    def before_set(params):
        for p in params:
            d = _descriptor_of(node, p.name) if node.has_parameter(p.name) else None
            if d is None:   # (rclpy's reply: 'Invalid access to undeclared parameter(s): []')
                node.get_logger().warning(
                    f'refused parameter change: {p.name!r} is not a parameter of this node '
                    '(ros2 param list names them)')
            elif _descriptor_refusal(d, p):
                node.get_logger().warning(
                    f'refused parameter change: {p.name} = {p.value!r} is not allowed; '
                    f'allowed: {allowed_values(d)}')
        return params
    node.add_pre_set_parameters_callback(before_set)


def _override_value(node, name: str) -> Any:
    """The start-up value given for ``name`` (params file or ``-p``), or None."""
    p = getattr(node, '_parameter_overrides', {}).get(name)
    return None if p is None else p.value


def declare(node, name: str, default: Any, d: ParameterDescriptor) -> Any:
    """Declare a parameter; a bad start-up value raises :class:`StartupParameterError`.

    rclpy raises its own exceptions for a value outside the descriptor's range
    or of the wrong type; this turns them into one line with the allowed values.
    Returns the parameter's value.
    """
    _log_descriptor_refusals(node)
    try:
        return node.declare_parameter(name, default, d).value
    except (InvalidParameterValueException, InvalidParameterTypeException) as exc:
        value = _override_value(node, name)
        reason = 'wrong type' if isinstance(exc, InvalidParameterTypeException) else ''
        raise StartupParameterError(name, value, allowed_values(d), reason) from None


def spin_until_closed(executor, ctx, closed: threading.Event,
                      on_error: Callable[[Exception], None] | None = None) -> None:
    """Spin ``executor`` in this thread until ``closed`` is set or ``ctx`` shuts down.

    For an in-process node spun in a thread of its own (the demos' recorder,
    the tests' clients).  rclpy's wait raises when another thread destroys
    an entity it waits on (a publisher's QoS event handler, destroyed with
    it: ``cannot use Destroyable because destruction was requested``);
    ``executor.spin()`` then ends for good, and nothing more is received
    (a demo's recorder missed the controller's vent that way in 5 of 18
    short runs beside two CPU-bound processes).  Here the error goes to
    ``on_error`` and the next wait is built without the entity.
    """
    while ctx.ok() and not closed.is_set():
        try:
            executor.spin_once(timeout_sec=0.1)
        except (ShutdownException, ExternalShutdownException):
            return
        except Exception as exc:  # noqa: BLE001 - see the docstring
            if closed.is_set():
                return
            if on_error is not None:
                on_error(exc)
            time.sleep(0.001)   # (never a busy loop)


def control_now(node) -> float:
    """The node's control time [s]: what its timers, time windows and filters run on.

    Under ``use_sim_time`` (the ROS clock follows ``/clock``) it is the
    simulation time, which stops when the simulation pauses; otherwise
    ``time.monotonic()``, which never jumps (as ros2_control's steady clock).
    What must stay on the wall clock whatever the clock (solve budgets, the
    exit deadline, the vent's acknowledgement) reads ``time.monotonic()``
    itself.
    """
    clock = node.get_clock()
    if getattr(clock, 'ros_time_is_active', False):
        return clock.now().nanoseconds * 1e-9
    return time.monotonic()


#: Most back-to-back reads of the two clocks when a stamp is mapped (``ControlClock.time_of``).
TIME_OF_READS = 4
#: A read of the two clocks that took at most this long is taken at once [ns].
TIME_OF_SPAN_NS = 200_000


class ControlClock:
    """A node's control time (:func:`control_now`) that never runs backwards.

    The ROS clock goes back when a simulation is reset or a recorded bag
    starts over.  This time then stands still across the jump and runs on
    from there (``jumps_back`` counts them): every window measured on it (a
    timeout, a keepalive's spacing, a path's clock, the creep's lead) counts
    nothing for the jump instead of going negative or waiting for the clock
    to come back.  Message stamps map onto it by their age (:meth:`time_of`,
    as a message's age on the ROS clock).  Off simulation time it is
    ``time.monotonic()`` itself, as it is for a stand-in node without a clock.
    Under ``use_sim_time`` the ROS clock reads 0 until the first ``/clock``:
    0 is a time like any other here (never "no time yet"), and the first
    ``/clock`` is a jump forwards.  Thread-safe; :func:`control_clock` gives
    a node's own.
    """

    def __init__(self, node) -> None:
        self.node = node
        self._lock = threading.Lock()
        self._offset = 0.0              # the jumps back so far [s]
        self._last = -float('inf')      # the newest time given
        self.jumps_back = 0

    @property
    def simulated(self) -> bool:
        """True while the node's ROS clock follows ``/clock`` (``use_sim_time``)."""
        get_clock = getattr(self.node, 'get_clock', None)
        return get_clock is not None and bool(getattr(get_clock(), 'ros_time_is_active', False))

    def now(self) -> float:
        """The control time now [s]: :func:`control_now` without its jumps back."""
        with self._lock:   # (read and compared at once: two threads see one order)
            raw = control_now(self.node) if hasattr(self.node, 'get_clock') else time.monotonic()
            t = raw + self._offset
            if t < self._last:
                self._offset += self._last - t
                self.jumps_back += 1
                t = self._last
            self._last = t
            return t

    def time_of(self, stamp, future: bool = False) -> float:
        """A message stamp as this clock's time, by its age on the node's ROS clock.

        A zero stamp (or none) is now; a stamp in the future is now unless
        ``future`` (a target wanted later, e.g. a previewed trajectory).
        The two clocks are read back to back, the ROS clock on both sides
        of this one, up to :data:`TIME_OF_READS` times, and the tightest
        read is used: a thread kept off the CPU between two single reads
        would date the stamp as early as it waited, and a target sent after
        another could come out wanted before it (the target stream then
        starts again).  Measured beside one CPU-bound process per core, the
        first read took at most 0.28 ms in some 32,000.
        """
        if stamp is None or (stamp.sec == 0 and stamp.nanosec == 0) or not hasattr(
                self.node, 'get_clock'):
            return self.now()
        ros = self.node.get_clock()
        best = None   # (the read's span, now, ROS time at it) of the tightest read
        for _ in range(TIME_OF_READS):
            r0 = ros.now().nanoseconds
            now = self.now()
            span = ros.now().nanoseconds - r0
            if best is None or span < best[0]:
                best = (span, now, r0 + span // 2)
            if span <= TIME_OF_SPAN_NS:
                break
        _, now, ros_ns = best
        age = 1e-9 * (ros_ns - (stamp.sec * 1_000_000_000 + stamp.nanosec))
        return now - age if (age >= 0.0 or future) else now


_CLOCKS_LOCK = threading.Lock()


def control_clock(node) -> ControlClock:
    """``node``'s :class:`ControlClock` (made at the first call; one per node).

    ``None`` or a node that takes no attribute gets a clock of its own each call.
    """
    clock = getattr(node, '_bellow_control_clock', None)
    if clock is None:
        with _CLOCKS_LOCK:
            clock = getattr(node, '_bellow_control_clock', None)
            if clock is None:
                clock = ControlClock(node)
                try:
                    node._bellow_control_clock = clock
                except AttributeError:   # None, or slots
                    pass
    return clock


class Param(NamedTuple):
    """One parameter of a node: the table entry both its declaration and its ``--help`` use."""

    name: str
    default: Any
    descriptor: ParameterDescriptor


class Topic(NamedTuple):
    """One topic or service of a node, for its ``--help`` (``direction``: publishes, ...)."""

    direction: str
    name: str
    type: str
    note: str = ''


def declare_all(node, params: Sequence[Param]) -> dict:
    """Declare every :class:`Param` of ``params`` with :func:`declare`; name -> value."""
    return {p.name: declare(node, p.name, p.default, p.descriptor) for p in params}


def _help_value(value: Any) -> str:
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(_help_value(v) for v in value) + ']'
    return f'{value!r}'


def node_help(executable: str, doc: str, topics: Sequence[Topic],
              params: Sequence[Param]) -> str:
    """The ``--help`` text of a node executable: what it does, its topics, its parameters.

    ``doc``: the node module's docstring (its first paragraph is used);
    ``params``: the table the node declares from, so that the defaults and
    ranges printed are the ones declared.
    """
    first = ' '.join((doc or '').strip().split('\n\n')[0].split()).replace('``', '')
    lines = [f'usage: ros2 run bellow_ancf_ros {executable} [--ros-args -p name:=value ...]',
             '', *textwrap.wrap(first, 99), '']
    for direction in dict.fromkeys(t.direction for t in topics):
        lines.append(f'{direction}:')
        for t in topics:
            if t.direction == direction:
                note = f': {t.note}' if t.note else ''
                lines += textwrap.wrap(f'{t.name} ({t.type}){note}', 99, initial_indent='  ',
                                       subsequent_indent=' ' * 6)
    lines += ['', 'parameters (name: default; allowed; description):']
    for p in params:
        d = p.descriptor
        when = '; read-only (start-up only)' if d.read_only else ''
        lines.append(f'  {p.name}: {_help_value(p.default)}; {allowed_values(d)}{when}')
        lines += textwrap.wrap(d.description, 99, initial_indent=' ' * 6,
                               subsequent_indent=' ' * 6)
    lines += ['', 'Start-up values: --ros-args -p name:=value or --params-file FILE. '
              'This help starts no ROS node and publishes nothing.']
    return '\n'.join(lines)


def asks_for_help(args: Sequence[str]) -> bool:
    """True when ``-h``/``--help`` is among the non-ROS arguments (``args`` without argv[0])."""
    in_ros = False
    for a in args:
        if a == '--ros-args':
            in_ros = True
        elif a == '--' and in_ros:
            in_ros = False
        elif not in_ros and a in ('-h', '--help'):
            return True
    return False


def _descriptor_of(node, name: str) -> ParameterDescriptor | None:
    try:
        return node.describe_parameter(name)
    except Exception:  # noqa: BLE001 - not declared
        return None


def guard_parameters(node, names: Sequence[str],
                     extra_check: Callable[[Any], str] | None = None) -> None:
    """Check the start-up values of ``names``; refuse bad run-time changes of any parameter.

    Uses :func:`contract.parameter_problem`.  A bad start-up value raises
    :class:`StartupParameterError`; a refused ``ros2 param set`` fails with
    the reason (and a warning in the log) and the old value stays.
    ``extra_check(parameter)`` may refuse further changes (returns the reason,
    or '' to accept), e.g. parameters that cannot change in the current
    lifecycle state.
    """
    for name in names:
        value = node.get_parameter(name).value
        reason = contract.parameter_problem(name, value)
        if reason:
            d = _descriptor_of(node, name)
            raise StartupParameterError(name, value, allowed_values(d) if d else '', reason)

    def on_set(params) -> SetParametersResult:
        for p in params:
            reason = contract.parameter_problem(p.name, p.value)
            if not reason and extra_check is not None:
                reason = extra_check(p)
            if reason:
                node.get_logger().warning(f'refused parameter change: {reason}')
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)


# ------------------------------------------------------------- messages
def pose_message(position: Any, quaternion: Any, frame_id: str, stamp) -> PoseStamped:
    """Build a PoseStamped from a position (3,) and a quaternion ``(x, y, z, w)``."""
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    p = np.asarray(position, dtype=float)
    q = np.asarray(quaternion, dtype=float)
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in p)
    (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z,
     msg.pose.orientation.w) = (float(v) for v in q)
    return msg


def pressure_message(pressures_pa: Any, unit: str) -> Float64MultiArray:
    """Float64MultiArray of pressures (given in Pa) in ``unit`` with a labelled layout."""
    values = contract.to_unit(pressures_pa, unit)
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=contract.pressure_label(unit), size=len(values),
                                          stride=len(values))]
    msg.layout.data_offset = 0
    msg.data = [float(v) for v in values]
    return msg


def publish_and_wait_acked(node, pub, msg, what: str,
                           timeout_s: float = VENT_ACK_TIMEOUT_S) -> bool:
    """Publish ``msg`` on a reliable publisher and wait until every matched subscriber acked.

    Waits at most ``timeout_s`` (rclpy ``Publisher.wait_for_all_acked``), for
    a message that must arrive before the process exits.  Logs a warning
    naming ``what`` when a subscriber did not acknowledge in time; returns
    whether all did (True without subscribers).
    """
    pub.publish(msg)
    n = pub.get_subscription_count()
    if n == 0:
        node.get_logger().info(f'{what} published (no subscriber matched)')
        return True
    t0 = time.monotonic()
    try:
        ok = bool(pub.wait_for_all_acked(Duration(seconds=timeout_s)))
    except Exception as exc:  # noqa: BLE001 - e.g. the context is going down
        node.get_logger().warning(f'{what}: could not wait for acknowledgement: {exc}')
        return False
    dt = time.monotonic() - t0
    if ok:
        node.get_logger().info(f'{what} acknowledged by all {n} matched subscriber(s) '
                               f'in {dt * 1e3:.1f} ms')
    else:
        node.get_logger().warning(f'{what} NOT acknowledged by all {n} matched subscriber(s) '
                                  f'within {timeout_s:g} s: a subscriber may have missed it')
    return ok


# --------------------------------------------------------- run / signals
class _ShuttingDown:
    """SIGINT/SIGTERM handler during shutdown: a repeated signal must not cut the vent short."""

    def __init__(self) -> None:
        self.count = 0

    def __call__(self, signum, frame) -> None:  # pragma: no cover - signal path
        self.count += 1


def _ignore_further_signals() -> _ShuttingDown:
    handler = _ShuttingDown()
    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return handler


#: Set by the first SIGINT/SIGTERM once the node exists: the spin loop ends and the node vents.
_STOP = threading.Event()
#: Set as soon as the node is constructed (a signal from then on stops it cleanly).
_SPINNING = threading.Event()
#: Set once the spin loop has ended and ``before_destroy`` (the vent) has returned.
_VENTED = threading.Event()
#: After the first SIGINT/SIGTERM (or the end of the spin loop) the process exits within this
#: time [s], whatever hangs: the vent and its acknowledgement wait (VENT_ACK_TIMEOUT_S) have
#: their time, then the teardown of the node and the middleware.  Two guards: a Python timer
#: at CLEAN_EXIT_S (a line on stderr, status 0 after the vent, else 1), and faulthandler's
#: watchdog at WATCHDOG_EXIT_S, a C thread that needs no GIL: it ends a process whose main
#: thread holds the interpreter inside a C call (Fast DDS ``destroy_participant`` spinning in
#: ``rcl_node_fini`` was seen), printing every thread's stack, status 1.
STOP_DEADLINE_S = 2.0 * VENT_ACK_TIMEOUT_S
#: The C watchdog's exit: before the deadline, leaving time for the stacks and the exit itself.
WATCHDOG_EXIT_S = STOP_DEADLINE_S - 0.5
#: The Python guard's exit: before the watchdog, so that a free interpreter ends with its line.
CLEAN_EXIT_S = STOP_DEADLINE_S - 1.0
_NODE_LABEL = ['node']
_DEADLINE_ARMED = threading.Event()


def _exit_if_still_running() -> None:  # pragma: no cover - only when a teardown hangs
    code = 0 if _VENTED.is_set() else 1
    print(f'[{_NODE_LABEL[0]}] shutdown did not finish within {CLEAN_EXIT_S:g} s of the '
          f'signal ({"after" if code == 0 else "before"} the vent step): exiting now',
          file=sys.stderr, flush=True)
    os._exit(code)


def _arm_stop_deadline() -> None:
    """Start both exit guards once (see :data:`STOP_DEADLINE_S`)."""
    if _DEADLINE_ARMED.is_set():
        return
    _DEADLINE_ARMED.set()
    stream = sys.__stderr__
    try:   # the C watchdog: runs and exits while a C call holds the GIL
        faulthandler.dump_traceback_later(WATCHDOG_EXIT_S, exit=True, file=stream)
    except (AttributeError, OSError, ValueError, RuntimeError):  # no usable stderr descriptor
        pass
    timer = threading.Timer(CLEAN_EXIT_S, _exit_if_still_running)
    timer.daemon = True
    timer.start()


#: How often a node checks that the process that started it is still there [s].
PARENT_CHECK_S = 0.2


def _parent_gone(parent: int, label: str) -> None:
    """Stop this node as SIGTERM does, once: its parent ``parent`` has exited."""
    try:   # the parent held our stderr (launch pipes it): it may be gone with it
        print(f'[{label}] the process that started it (pid {parent}) has exited: '
              'stopping as on SIGTERM (vent, then exit)', file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass
    os.kill(os.getpid(), signal.SIGTERM)   # the handler runs in the main thread: _first_signal


def watch_parent(parent: int, label: str, period_s: float = PARENT_CHECK_S):
    """Send this process SIGTERM once its parent ``parent`` has exited; the watching thread.

    ``ros2 launch`` sends its nodes SIGINT on Ctrl-C, but when it is itself
    killed (SIGKILL) or sent SIGTERM (it exits without signalling them) its
    nodes get no signal at all and would keep commanding.  An orphan is re-parented (to init or a
    subreaper), so ``os.getppid()`` changes: a daemon thread checks it every
    ``period_s`` and then raises SIGTERM in this process, which takes the
    same path as a SIGTERM from outside (:func:`_first_signal`: the vent,
    then the exit).  Not ``prctl(PR_SET_PDEATHSIG)``: the kernel sends that
    when the *thread* that started the child ends, which would stop a node
    whose launcher is alive and miss that launcher's real exit later.
    ``parent``: the parent's pid taken as early as possible (a parent that
    had already exited by then is not noticed); ``parent <= 1`` (started by
    init, or already an orphan): nothing to watch, returns None.
    """
    if parent <= 1:
        return None

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(period_s)
        _parent_gone(parent, label)

    thread = threading.Thread(target=watch, name='parent-watch', daemon=True)
    thread.start()
    return thread


def _first_signal(signum, frame):  # pragma: no cover - signal path
    """First SIGINT/SIGTERM: stop spinning; later ones are only counted.

    Once the node exists, the loop is stopped by a flag rather than by
    raising: KeyboardInterrupt raised while the executor is inside rclpy's
    C++ code (taking a message) becomes a RuntimeError there, and the
    process would exit with an error; a signal between the constructor and
    the first spin (the executor being built) also just stops it.  Before
    (in a constructor), it raises KeyboardInterrupt.
    """
    _ignore_further_signals()
    _arm_stop_deadline()
    if _SPINNING.is_set():
        _STOP.set()
    else:
        raise KeyboardInterrupt


#: Environment variable choosing the nodes' executor: ``events`` (default) or ``single_threaded``.
EXECUTOR_ENV = 'BELLOW_ANCF_EXECUTOR'
EXECUTORS = ('events', 'single_threaded')


def executor_choice() -> str:
    """The executor ``BELLOW_ANCF_EXECUTOR`` names (default ``events``); a bad name raises."""
    choice = os.environ.get(EXECUTOR_ENV, '').strip().lower() or 'events'
    if choice not in EXECUTORS:
        raise StartupEnvironmentError(EXECUTOR_ENV, choice, ', '.join(EXECUTORS))
    return choice


def make_executor():
    """The executor a node spins in: rclpy's EventsExecutor where rclpy has one.

    rclpy's SingleThreadedExecutor rebuilds its wait set in Python on every
    wake-up: for a lifecycle node (its services, parameter services, QoS
    event handlers) about 0.7 ms of CPU per incoming target, holding the GIL
    that the solver thread needs (bench/ros_latency.py measures the end-to-end
    latency).  The EventsExecutor (``rclpy.experimental``, C++ event queue)
    does not.  ``BELLOW_ANCF_EXECUTOR=single_threaded`` selects the
    SingleThreadedExecutor, which is also used when rclpy has no
    EventsExecutor (older Jazzy releases).
    """
    if executor_choice() == 'events':
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:
            pass
        else:
            return EventsExecutor()
    return SingleThreadedExecutor()


#: Exit status of the process once :func:`run_node` has returned (:func:`request_stop`).
_EXIT_STATUS = [0]


def request_stop(exit_status: int = 0) -> None:
    """End :func:`run_node`'s spin loop as a first SIGINT would (a node that is done).

    ``exit_status``: the status the executable then exits with (e.g. 1 for a
    node that gave up).
    """
    _EXIT_STATUS[0] = exit_status
    _STOP.set()


#: What :func:`run_node` leaves alive until the process's ``os._exit``: the executor
#: (see ``keep_until_exit``).
_KEPT_UNTIL_EXIT: list = []


def _release_node(executor) -> None:
    """Let ``executor`` drop the node just removed from it, so that its entities can go.

    The EventsExecutor lets go of a removed node's publishers and
    subscriptions only when it next runs; until then ``destroy_node`` leaves
    them alive.  Kept until ``os._exit`` (``keep_until_exit``), it never ran
    again, and the node's publishers stayed in the ROS graph until the
    middleware's lease ran out, 20 s after the process had gone.  Measured
    on the forward node's console script (SIGINT, another process counting
    its publishers): with this release the publisher goes when the process
    exits (after a 2 s pause before ``os._exit``, 2.1 s after the signal in
    4 of 4 trials), not when the node is destroyed; without it, 20 s after.
    Beside two CPU-bound processes it still stayed 20 s in some trials: 4
    of 12 with this release alone, 2 of 18 with :func:`_leave_the_domain`
    too.  A small node leaves at ``destroy_node`` already (its test).
    """
    try:
        executor.spin_once(timeout_sec=0.0)
    except Exception:   # noqa: BLE001 - a context already shut down: nothing to release
        pass


def _leave_the_domain(context) -> None:
    """Destroy ``context`` for a process about to ``os._exit`` (after :func:`_release_node`).

    Alone it changes nothing the others see (the forward node's publisher
    stayed 20 s in 3 of 3 trials without the release); after the release,
    beside two CPU-bound processes, the publisher stayed 20 s in 2 of 18
    trials with it and 4 of 12 without it: kept for that, the cause of the
    remaining cases not known.
    """
    try:
        context.destroy()
    except Exception:   # noqa: BLE001 - nothing more to tidy before the exit
        pass


def run_node(node, before_destroy=None, keep_until_exit: bool = False) -> None:
    """Spin ``node`` until Ctrl-C/SIGTERM or context shutdown, then clean up.

    ``before_destroy(node)`` runs while the context is still valid (vent).
    ``keep_until_exit``: the caller ends the process with ``os._exit`` next,
    so the executor is kept referenced rather than freed as this function
    returns: freeing the EventsExecutor runs rclpy's QoS event handlers'
    ``__exit__``, which hung a simulated robot's process after its vent,
    holding the GIL, until the exit deadline killed it (exit status 1, one
    main-job test in four fresh-clone runs).
    From the first signal on, further SIGINT/SIGTERM are counted, not raised:
    ``ros2 launch`` and a terminal may both deliver SIGINT, and a second one
    must not interrupt the vent or its acknowledgement wait (which is bounded).
    The first signal (or the end of the loop) also starts the exit deadline
    (:data:`STOP_DEADLINE_S`): should anything hang after it, the process
    still exits, with a line on stderr (status 0 once the vent step returned,
    else 1) or, when a C call holds the interpreter, with every thread's
    stack printed by faulthandler's watchdog (status 1).
    """
    _SPINNING.set()
    executor = make_executor()
    executor.add_node(node)
    try:
        while rclpy.ok() and not _STOP.is_set():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        _ignore_further_signals()
        _arm_stop_deadline()   # also when the node ended itself (request_stop)
        try:
            if before_destroy is not None and rclpy.ok():
                before_destroy(node)
        finally:
            _VENTED.set()
            context = node.context
            executor.remove_node(node)
            if keep_until_exit:
                _release_node(executor)
            node.destroy_node()
            rclpy.try_shutdown()
            if keep_until_exit:
                _KEPT_UNTIL_EXIT.append(executor)
                _leave_the_domain(context)
            # the vent is out and the process exits: a late signal must not kill it now.
            # Python resets its own handlers (_ShuttingDown) to the default at exit, and a
            # SIGINT arriving then ended the process with -2 after a clean vent (seen in
            # test_double_sigint_still_vents); an ignored signal stays ignored.
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)


class _ParamsFileError(Exception):
    """A ``--params-file`` rclpy cannot read (one line: the file and what is wrong)."""


def _params_files(args: Sequence[str]) -> list[str]:
    """The files given with ``--params-file`` among the ROS arguments."""
    return [b for a, b in zip(args, args[1:]) if a == '--params-file']


def _params_file_problem(args: Sequence[str]) -> str:
    """What is wrong with a ``--params-file`` of ``args`` that rcl would refuse, or ''.

    Checked before rcl sees them (a missing file, YAML that does not parse, a
    file that is not a mapping); what rcl refuses beyond that comes from
    :func:`init_rclpy`.
    """
    for f in _params_files(args):
        if not os.path.isfile(f):
            return f'--params-file {f}: no such file'
        try:
            with open(f) as fh:
                data = yaml.safe_load(fh)
        except (OSError, UnicodeDecodeError) as err:
            return f'--params-file {f}: cannot be read ({err})'
        except yaml.YAMLError as err:
            where = getattr(err, 'problem_mark', None)
            line = f', line {where.line + 1}' if where is not None else ''
            return (f'--params-file {f}: not valid YAML{line} '
                    f'({getattr(err, "problem", None) or type(err).__name__})')
        if not isinstance(data, dict):
            return (f'--params-file {f}: not a ROS 2 parameters file (allowed: a mapping '
                    '"<node name or /**>: {ros__parameters: {name: value}}")')
    return ''


def init_rclpy(args=None) -> None:
    """Initialise rclpy without its signal handlers; SIGINT/SIGTERM stop the node.

    The first signal ends the spin loop (see :func:`_first_signal`) and makes
    every later one a no-op, so that a second Ctrl-C (terminal and ``ros2 launch`` both send
    one) cannot interrupt the vent on the way out.  ROS arguments rcl would
    refuse (a ``--params-file`` that does not exist, is not YAML or not a
    parameters file) raise :class:`_ParamsFileError` with one line naming the
    file and what is wrong, and rcl's own log lines about it are held back.
    """
    argv = sys.argv if args is None else list(args)
    problem = _params_file_problem(argv)
    if problem:
        raise _ParamsFileError(problem)
    limit_blas_threads()  # small dense matrices: 1 BLAS thread is faster (core.solver)
    try:
        with _StderrHeld() as held:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # noqa: BLE001 - rclpy's RCLError (no public class in Jazzy)
        if type(exc).__name__ != 'RCLError':
            raise
        text = ' '.join(str(exc).split()).split(', at /')[0]
        files = ' '.join(_params_files(argv)) or 'the ROS arguments'
        raise _ParamsFileError(f'{files}: refused by rcl ({text})') from None
    if held.text:   # rcl's output of a successful init goes out as it came
        sys.stderr.write(held.text)
    signal.signal(signal.SIGINT, _first_signal)
    signal.signal(signal.SIGTERM, _first_signal)


class _StderrHeld:
    """Hold what C code writes on file descriptor 2 meanwhile (``.text`` afterwards)."""

    def __enter__(self):
        self.text = ''
        self._file = tempfile.TemporaryFile(mode='w+b')
        try:
            sys.stderr.flush()
            self._saved = os.dup(2)
            os.dup2(self._file.fileno(), 2)
        except OSError:   # no descriptor 2: nothing to hold
            self._saved = None
        return self

    def __exit__(self, *exc):
        if self._saved is not None:
            os.dup2(self._saved, 2)
            os.close(self._saved)
            self._file.seek(0)
            self.text = self._file.read().decode(errors='replace')
        self._file.close()
        return False


#: How long a thread may hold the interpreter while another waits for it [s] (Python: 5 ms).
#: A node's threads that wake for a deadline (the inverse node's paced commands, the
#: simulator's physics) then wait at most about this long for the executor's callbacks
#: (measured beside a modal analysis: 2.8 ms largest delay at 5 ms, 1.9 ms at 1 ms).
SWITCH_INTERVAL_S = 0.001


def main_for(node_class, before_destroy=None, node_name: str | None = None, factory=None):
    """Build ``main(args=None)`` of a node executable: init, construct, spin, clean up.

    ``node_class`` has ``NODE_NAME``, ``TOPICS`` (:class:`Topic`) and
    ``PARAMETERS`` (:class:`Param`, the table it declares from);
    ``factory()`` builds the node (default ``node_class()``).  ``-h`` /
    ``--help`` prints what the node does, its topics and its parameters
    (:func:`node_help`) and exits 0 before rclpy is initialised: no node, no
    message.  A start-up parameter the node cannot run with
    (:class:`StartupParameterError`, a robot file that does not load, a
    ``--params-file`` rcl refuses) ends the process with one line on stderr,
    prefixed with the node's name, and exit status :data:`STARTUP_ERROR_EXIT`,
    no traceback.  Once rclpy is initialised the process watches its parent
    (:func:`watch_parent`): when the process that started it (``ros2 launch``,
    ``ros2 run``, a script) exits, by any signal, the node stops as on
    SIGTERM: vent, then exit.
    """
    name = node_name or getattr(node_class, 'NODE_NAME', node_class.__name__)
    make = factory or node_class

    def main(args=None) -> None:
        parent = os.getppid()   # before anything slow: a parent gone since is still seen
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        argv = sys.argv if args is None else list(args)
        if asks_for_help(argv[1:]):
            doc = sys.modules[node_class.__module__].__doc__
            print(node_help(name, doc, getattr(node_class, 'TOPICS', ()),
                            getattr(node_class, 'PARAMETERS', ())), flush=True)
            sys.exit(0)
        _NODE_LABEL[0] = name
        try:
            init_rclpy(argv)
        except _ParamsFileError as exc:
            print(f'[{name}] cannot start: {exc}', file=sys.stderr, flush=True)
            sys.exit(STARTUP_ERROR_EXIT)
        watch_parent(parent, name)   # with the signal handlers in place (init_rclpy)
        try:
            executor_choice()
            if not numba_cache.is_compiled():   # say at once what the blank terminal is
                # the duration as README.md and docs/cli.md give it (52-66 s measured)
                print(f'[{name}] compiling the numerical kernels once after installation '
                      '(about a minute on a 2-core machine; `ros2 run bellow_ancf_ros '
                      'bellow-ancf warm-up` does it ahead of time)', file=sys.stderr, flush=True)
            node = make()
            use_realtime(node)   # (its threads, and those it starts later, on SCHED_FIFO)
            # what start-up built (modules, the model, compiled kernels: some 150 000 objects)
            # is left out of the garbage collector's full passes, which otherwise stopped
            # every thread of the process for 90 ms every few seconds (a command late by as
            # much, a simulated robot's physics stalled); a lifecycle node's configure freezes
            # what it loads too (worker.ready_model)
            gc.freeze()
            _SPINNING.set()  # from here a signal stops the node cleanly (run_node)
        except (StartupParameterError, ConfigError) as exc:
            rclpy.try_shutdown()
            print(f'[{name}] cannot start: {exc}', file=sys.stderr, flush=True)
            sys.exit(STARTUP_ERROR_EXIT)
        except KeyboardInterrupt:
            rclpy.try_shutdown()
            return
        except Exception:
            rclpy.try_shutdown()
            raise
        program = args is None and _is_the_console_script(name)
        run_node(node, before_destroy=before_destroy, keep_until_exit=program)
        if program:
            # the node's own executable: everything is done (vented, destroyed, shut down),
            # so end the process without the interpreter's finalisation, where the garbage
            # collection of rclpy's event handlers hung 2 of 21 node processes of a main-job
            # run, holding the GIL, until the exit deadline (exit status 1)
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(_EXIT_STATUS[0])
        if _EXIT_STATUS[0]:
            sys.exit(_EXIT_STATUS[0])
    return main


def _is_the_console_script(name: str) -> bool:
    """True when this process runs the node's console script (``ros2 run``, ``ros2 launch``).

    Such a process ends with ``os._exit`` once the node is done (:func:`main_for`).
    Started as ``python -m bellow_ancf_ros.nodes.<node>`` (the tests, the demos)
    it ends through the interpreter: the node's class is then ``__main__``'s,
    which an earlier check of the module's name never matched.  Ending those
    with ``os._exit`` too made two ROS tests fail in 2 of 2 runs of the suite
    (a lost prediction; a status that never came).
    """
    return os.path.basename(sys.argv[0] if sys.argv else '') == name
