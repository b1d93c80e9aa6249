"""rclpy helpers shared by the nodes: QoS profiles, parameter descriptors,
message builders, and the start-up / spin / shutdown idiom.

The pure (rclpy-free) helpers live in :mod:`bellow_ancf_ros.nodes.common`.
"""

from __future__ import annotations

import signal
import threading
import time
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import (
    FloatingPointRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from ..core.solver import limit_blas_threads
from . import common

__all__ = [
    'QOS_DEPTH', 'REFUSAL_DIAG_INTERVAL_S', 'WARN_THROTTLE_S', 'Refusals', 'command_qos', 'descriptor',
    'publish_diagnostic',
    'diagnostic_status', 'diagnostics_qos', 'guard_parameters', 'init_rclpy', 'main_for', 'pose_message',
    'pressure_message', 'run_node',
]

QOS_DEPTH = 5
WARN_THROTTLE_S = 2.0
#: Minimum interval between two WARN diagnostics of the same refusal reason [s].
REFUSAL_DIAG_INTERVAL_S = 0.1


def command_qos() -> QoSProfile:
    """Reliable, keep-last, depth :data:`QOS_DEPTH` (targets, pressures, poses)."""
    return QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                      depth=QOS_DEPTH)


def diagnostics_qos() -> QoSProfile:
    return QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                      depth=10)


def descriptor(description: str, ptype: int, *, lo: float | None = None,
               hi: float | None = None, read_only: bool = False,
               constraints: str = '') -> ParameterDescriptor:
    """A ParameterDescriptor with description, optional range and constraints text."""
    d = ParameterDescriptor(description=description, type=ptype, read_only=read_only,
                            additional_constraints=constraints)
    if lo is not None and hi is not None:
        d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi),
                                                     step=0.0)]
    return d


def pose_message(position: Any, quaternion: Any, frame_id: str, stamp) -> PoseStamped:
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
    values = common.to_unit(pressures_pa, unit)
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=common.pressure_label(unit), size=len(values),
                                          stride=len(values))]
    msg.layout.data_offset = 0
    msg.data = [float(v) for v in values]
    return msg


def diagnostic_status(name: str, hardware_id: str, level: bytes, message: str,
                      values: dict) -> DiagnosticStatus:
    st = DiagnosticStatus()
    st.name = name
    st.hardware_id = hardware_id
    st.level = level
    st.message = message
    st.values = [KeyValue(key=str(k), value=str(v)) for k, v in values.items()]
    return st


#: Set by SIGINT/SIGTERM once spinning: the spin loop ends and the node vents.
_STOP = threading.Event()
_SPINNING = threading.Event()


def _on_stop_signal(signum, frame):  # pragma: no cover - signal path
    """SIGINT/SIGTERM: while spinning, ask the spin loop to stop; before that, interrupt.

    Raising KeyboardInterrupt while the executor is inside rclpy's C++ code (taking a
    message) turns into a RuntimeError there and the vent would be skipped, so the spin
    loop is stopped by a flag instead.
    """
    if _SPINNING.is_set():
        _STOP.set()
    else:
        raise KeyboardInterrupt


def run_node(node, before_destroy=None) -> None:
    """Spin ``node`` until Ctrl-C/SIGTERM or context shutdown, then clean up.

    ``before_destroy(node)`` runs while the context is still valid (vent).
    """
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    _SPINNING.set()
    try:
        while rclpy.ok() and not _STOP.is_set():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        try:
            if before_destroy is not None and rclpy.ok():
                before_destroy(node)
        finally:
            executor.remove_node(node)
            node.destroy_node()
            rclpy.try_shutdown()


def init_rclpy(args=None) -> None:
    """rclpy.init without rclpy's signal handlers; SIGINT/SIGTERM stop the spin loop cleanly."""
    limit_blas_threads()  # small dense matrices: 1 BLAS thread is faster (core.solver)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, _on_stop_signal)
    signal.signal(signal.SIGTERM, _on_stop_signal)


def guard_parameters(node, names) -> None:
    """Check the start-up values of ``names`` and refuse bad run-time changes of any parameter.

    Uses :func:`common.parameter_problem`; a refused ``ros2 param set`` fails with the
    reason (and a warning in the log) and the old value stays.
    """
    for name in names:
        reason = common.parameter_problem(name, node.get_parameter(name).value)
        if reason:
            raise ValueError(f'parameter {name}: {reason}')

    def on_set(params) -> SetParametersResult:
        for p in params:
            reason = common.parameter_problem(p.name, p.value)
            if reason:
                node.get_logger().warning(f'refused parameter change: {reason}')
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)


def main_for(node_class, before_destroy=None):
    """``main(args=None)`` of a node executable: init, construct, spin, clean up."""
    def main(args=None) -> None:
        init_rclpy(args)
        try:
            node = node_class()
        except Exception:
            rclpy.try_shutdown()
            raise
        run_node(node, before_destroy=before_destroy)
    return main


def publish_diagnostic(node, pub, name: str, hardware_id: str, level: bytes, message: str,
                       values: dict) -> None:
    """Publish one DiagnosticStatus on ``pub`` (no-op without a publisher or once it is destroyed)."""
    if pub is None:
        return
    arr = DiagnosticArray()
    arr.header.stamp = node.get_clock().now().to_msg()
    arr.status = [diagnostic_status(name, hardware_id, level, message, values)]
    try:
        pub.publish(arr)
    except Exception:  # noqa: BLE001 - publisher destroyed meanwhile
        pass


class Refusals:
    """Reporting of refused inputs: a throttled warning always, a WARN diagnostic at most
    every :data:`REFUSAL_DIAG_INTERVAL_S` per reason (a flood of bad input cannot flood
    ``/diagnostics``).  ``what`` names the input (``targets``, ``pressures``)."""

    def __init__(self, node, what: str, publish_diag) -> None:
        self.node, self.what, self.publish_diag = node, what, publish_diag
        self._last = ('', 0.0)

    def report(self, reason: str, total: int) -> None:
        self.node.get_logger().warning(f'{self.what} refused: {reason}', throttle_duration_sec=WARN_THROTTLE_S)
        now = time.monotonic()
        if reason != self._last[0] or now - self._last[1] >= REFUSAL_DIAG_INTERVAL_S:
            self._last = (reason, now)
            self.publish_diag(DiagnosticStatus.WARN, f'{self.what} refused: {reason}',
                              {f'refused_{self.what}': total})
