"""The controller's side of a simulation's lockstep: the time up to which it has done its work.

Under ``use_sim_time`` the inverse node publishes ``lockstep_clock``
(rosgraph_msgs/Clock): each ``/clock`` tick it has received, once no solve
is pending or running (at once when idle, else when the solve ends).  A
``simulated_robot_node`` in ``lockstep`` then takes no step beyond that time
(:meth:`~bellow_ancf_ros.core.sim.SimulationClock.done_until`): the
controller's computation takes no simulated time, and a busy computer slows
the simulation instead of delaying the commands in it.  Nothing is published
on the wall clock.
"""

from __future__ import annotations

import threading
from typing import Callable

from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

__all__ = ['TOPIC', 'LockstepReport']

#: The topic (in the node's namespace) a simulated robot's lockstep listens to.
TOPIC = 'lockstep_clock'


class LockstepReport:
    """Publish ``lockstep_clock`` for ``node`` while it runs on simulation time.

    ``idle()``: no work pending or running.  :meth:`work_done` (any thread):
    a piece of work ended; the newest tick held back goes out if now idle.
    """

    def __init__(self, node, idle: Callable[[], bool]) -> None:
        self._node, self._idle = node, idle
        self._lock = threading.Lock()
        self._held: Clock | None = None   # the newest tick received while busy
        self._pub = self._sub = None
        if node.get_parameter('use_sim_time').value:
            self._pub = node.create_publisher(Clock, TOPIC, 10)
            self._sub = node.create_subscription(
                Clock, '/clock', self._on_clock,
                QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                           history=HistoryPolicy.KEEP_LAST))

    def _on_clock(self, msg: Clock) -> None:
        with self._lock:
            self._held = msg
        self.work_done()

    def work_done(self) -> None:
        """Report the newest tick received, unless work is still pending or running."""
        if self._pub is None or not self._idle():
            return
        with self._lock:
            msg, self._held = self._held, None
        if msg is not None:
            try:
                self._pub.publish(msg)
            except Exception:  # noqa: BLE001 - publisher gone at shutdown
                pass

    def destroy(self) -> None:
        """Stop reporting (on cleanup): the publisher and the subscription go."""
        pub, sub, self._pub, self._sub = self._pub, self._sub, None, None
        if sub is not None:
            self._node.destroy_subscription(sub)
        if pub is not None:
            self._node.destroy_publisher(pub)
