"""Targets from one publisher at a time: two publishers sending on ``target_pose`` hold them.

A planner and a teleoperator (or a forgotten ``ros2 topic pub``) publishing
on the same ``target_pose`` make the inverse node take their targets in
turn: measured on the one-segment simulated robot, two publishers at 50 Hz
each, 10 and 14 mm apart, made consecutive commands differ by up to 100 kPa
and swung the robot by 20 mm, with no log line.  A message does not say
which publisher sent it in every middleware, but its *publication sequence
number* (``MessageInfo['publication_sequence_number']``: each publisher
counts its own messages from 1) does: one publisher's numbers grow by one
(a few more where a message was lost), two publishers' interleave, so the
numbers go back, or leap ahead, at least every other message (a publisher
that sends rarely with higher numbers than the other leaps ahead, and is
refused too).  :class:`TargetSources` holds the targets while that happens (the
node keeps its last target and says so: a throttled WARN and a WARN
diagnostic naming the publishers) and takes them again once the numbers
have only grown for :data:`HOLD_S`: the other publisher stopped, or a
publisher took over from one that stopped (a handover costs that pause).  A
middleware that gives no sequence number leaves every target taken, as
before.
"""

from __future__ import annotations

__all__ = ['HOLD_S', 'TargetSources', 'publisher_names']

#: Targets are held until the sequence numbers have only grown for this long [s].
HOLD_S = 0.5
#: A number this far ahead of the last one is another publisher's (messages lost in between
#: are at most a few; a target stream at 100 Hz sends this many in a second).
MAX_LEAP = 100


def publisher_names(node, topic: str) -> list:
    """The nodes publishing ``topic`` as the ROS graph knows them (``/namespace/name``)."""
    return [f'{i.node_namespace.rstrip("/")}/{i.node_name}'
            for i in node.get_publishers_info_by_topic(topic)]


class TargetSources:
    """Whether a target may be taken, from its publication sequence number (module docstring).

    ``names()``: the topic's publishers (:func:`publisher_names`), asked once
    when an episode of interleaving begins.
    """

    def __init__(self, names=None, hold_s: float = HOLD_S) -> None:
        """No target seen yet."""
        self.names = names
        self.hold_s = float(hold_s)
        self.interleavings = 0        # messages whose sequence number went back
        self.publishers = ''          # the publishers named when the last episode began
        self._last: int | None = None
        self._until = -float('inf')

    def holds(self, info, now: float) -> str | None:
        """None: take this target; else why it is held (one line, the same through an episode).

        ``info``: the message's ``MessageInfo`` (a dict; None, or no
        ``publication_sequence_number`` in it, or 0: unknown); ``now``: a
        monotonic time [s].
        """
        sequence = None if info is None else info.get('publication_sequence_number')
        if not isinstance(sequence, int) or sequence <= 0:
            return None
        if self._last is not None and not self._last < sequence <= self._last + MAX_LEAP:
            self.interleavings += 1
            if now >= self._until and self.names is not None:   # a new episode: who is there
                self.publishers = ', '.join(self.names())
            self._until = now + self.hold_s
        self._last = sequence
        if now >= self._until:
            return None
        who = f' ({self.publishers})' if self.publishers else ''
        return (f'more than one publisher sends target_pose{who}: targets held at the last one '
                f'taken until one publisher has sent alone for {self.hold_s:g} s')
