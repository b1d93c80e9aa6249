"""The inverse node's force input: a known or estimated force at the end effector.

``external_force`` (geometry_msgs/WrenchStamped in ``base_frame``, the force
part; from a force sensor, a known tool load, or another estimator) and,
with ``use_estimated_force``, ``estimated_wrench`` of the
``wrench_estimator_node``: the newest valid force goes into the feedforward
(:func:`~bellow_ancf_ros.core.solve_inverse` with ``tip_force_n``), so that
the pressures reach the target under it.  A force older than
``external_force_timeout_s`` is no longer applied (said once, WARN in the
status): a dead sensor must not hold the robot against a push that ended.
Bad messages are refused by :func:`.contract.validate_force`.
"""

from __future__ import annotations

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import WrenchStamped

from . import contract
from .ros_util import command_qos, control_clock

__all__ = ['ExternalForce']

#: A force that changed by more than this [N] re-solves the held target.
RESOLVE_CHANGE_N = 1e-3


class ExternalForce:
    """Subscriptions, validation and staleness of the force the inverse node compensates."""

    def __init__(self, node, base_frame: str, timeout_s: float, use_estimate: bool,
                 refuse, on_change) -> None:
        """Subscribe ``external_force`` (and ``estimated_wrench`` with ``use_estimate``).

        ``refuse(reason)`` reports a bad message; ``on_change()`` is called
        when the force in effect changed by more than :data:`RESOLVE_CHANGE_N`.
        """
        self.node, self.base_frame, self.timeout_s = node, base_frame, float(timeout_s)
        self._refuse, self._on_change = refuse, on_change
        self._clock = control_clock(node)   # the timeout: control time (use_sim_time)
        self._force, self._t, self._source = None, -np.inf, ''
        self._applied = np.zeros(3)
        self._said_stale = False
        self.received = self.refused = 0
        topics = ['external_force'] + (['estimated_wrench'] if use_estimate else [])
        self.subs = [node.create_subscription(WrenchStamped, t,
                                              lambda m, t=t: self._on_force(m, t), command_qos())
                     for t in topics]

    def _on_force(self, msg: WrenchStamped, topic: str) -> None:
        self.received += 1
        f = msg.wrench.force
        try:
            force = contract.validate_force((f.x, f.y, f.z), msg.header.frame_id,
                                            self.base_frame)
        except contract.InputError as exc:
            self.refused += 1
            self._refuse(f'{topic}: {exc}')
            return
        self._force, self._t, self._source = force, self._clock.now(), topic
        self._said_stale = False
        if np.max(np.abs(force - self._applied)) > RESOLVE_CHANGE_N:
            self._on_change()

    def current(self):
        """The force in effect [N] (a tuple), or None: none yet, or older than the timeout."""
        if self._force is None:
            return None
        if self._clock.now() - self._t > self.timeout_s:
            if not self._said_stale:
                self._said_stale = True
                self.node.get_logger().warning(
                    f'{self._source}: no force for {self.timeout_s:g} s: no longer compensated')
            self._applied = np.zeros(3)
            return None
        self._applied = self._force
        return tuple(float(v) for v in self._force)

    def status(self) -> tuple:
        """``(level, message, values)`` for the heartbeat."""
        f = self.current()
        values = {'tip_force_n': 'none' if f is None else ' '.join(f'{v:.4g}' for v in f),
                  'forces_received': self.received, 'forces_refused': self.refused}
        if self._force is not None and f is None:
            return DiagnosticStatus.WARN, f'{self._source} stale: not compensated', values
        return DiagnosticStatus.OK, '', values

    def destroy(self) -> None:
        """Drop the subscriptions (cleanup)."""
        for s in self.subs:
            self.node.destroy_subscription(s)
        self.subs = []
