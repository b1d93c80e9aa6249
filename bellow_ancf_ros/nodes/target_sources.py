"""Targets from one publisher at a time: two publishers sending on ``target_pose`` hold them.

A planner and a teleoperator (or a forgotten ``ros2 topic pub``) publishing
on the same ``target_pose`` made the inverse node take their targets in
turn: measured on the one-segment simulated robot, two publishers at 50 Hz
each, 10 and 14 mm apart, made consecutive commands differ by up to 100 kPa
and swung the robot by 20 mm, with no log line (a jump's smooth move
converges on the newest target, which flipped at every message).

A message does not say which publisher sent it (rclpy's ``MessageInfo``
carries each publisher's sequence numbers, but the EventsExecutor the nodes
spin in does not deliver it), so :class:`TargetSources` reads the stream
itself: a target that jumps away from the one before (more than
:data:`JUMP_M`) and back near the one before that is two streams taking
turns, when the ROS graph shows more than one publisher on the topic.  That
first turn back is taken (the jump away was the other stream's first
target: the move towards it has barely begun), and the targets after it
are held (the node keeps the last one taken and says so: a throttled WARN
and a WARN diagnostic naming the publishers) until no turn has come for
:data:`HOLD_S`.  One publisher (the graph's count) is never
held, whatever it sends; two whose targets do not take turns (a lead-in
publisher handing over to a path that starts where it held, a planner idle
beside a teleoperator) are not either.
"""

from __future__ import annotations

from collections import deque
import math

from ..core.control import JUMP_M   # (a target this far from the one before is a jump [m])

__all__ = ['HOLD_S', 'TargetSources', 'publisher_names']

#: Targets are held until no turn of two streams has come for this long [s].
HOLD_S = 0.5


def publisher_names(node, topic: str) -> list:
    """The nodes publishing ``topic`` as the ROS graph knows them (``/namespace/name``)."""
    return [f'{i.node_namespace.rstrip("/")}/{i.node_name}'
            for i in node.get_publishers_info_by_topic(topic)]


class TargetSources:
    """Whether a target may be taken, from the targets received before it (module docstring).

    ``count()``: publishers on the topic (None: not asked, taken as more
    than one); ``names()``: their names (:func:`publisher_names`), asked once
    when an episode begins.
    """

    def __init__(self, count=None, names=None, hold_s: float = HOLD_S) -> None:
        """No target seen yet."""
        self.count, self.names = count, names
        self.hold_s = float(hold_s)
        self.turns = 0                # targets that jumped back to the one before the last
        self.publishers = ''          # the publishers named when the last episode began
        self._recent: deque = deque(maxlen=2)
        self._until = -math.inf

    def holds(self, position, now: float) -> str | None:
        """None: take this target; else why it is held (one line, the same through an episode).

        ``position``: the target's position [m] in the base frame; ``now``: a
        monotonic time [s].
        """
        p = tuple(float(v) for v in position)
        turn = False
        if len(self._recent) == 2:
            older, last = self._recent
            jump = math.dist(p, last)
            turn = (jump > JUMP_M and math.dist(older, last) > JUMP_M
                    and math.dist(p, older) < 0.5 * jump)
        self._recent.append(p)
        if turn and (self.count is None or self.count() > 1):
            self.turns += 1
            new = now >= self._until
            self._until = now + self.hold_s
            if new:   # an episode begins: the turn back is taken, who is there is asked
                if self.names is not None:
                    self.publishers = ', '.join(self.names())
                return None
        if now >= self._until:
            return None
        who = f' ({self.publishers})' if self.publishers else ''
        return (f'more than one publisher sends target_pose{who}, their targets take turns: '
                f'targets held at the last one taken until they stop for {self.hold_s:g} s')
