"""One owner of ``pressure_command``: a node that finds another publisher yields, once, for good.

Two controllers on one pressure topic (the inverse node and the excitation
publisher started by mistake) make the regulators flip between their
commands.  Every node that publishes ``pressure_command`` asks the ROS graph,
before every command, which other nodes publish on that topic (a local
query of the middleware's discovery data, about 30 us).  The rule, the same
for every such node:

* **Yield once**: the first time it sees another publisher, the node
  publishes the vent command (0 Pa gauge on every actuator) once and stops
  commanding: the inverse node deactivates itself (lifecycle ``inactive``),
  the excitation publisher aborts its sequence.  With both nodes doing so
  the regulators end vented, whoever saw whom first.
* **Never resume by itself**: when the other node leaves, nothing happens
  but one INFO line; commands resume only on an explicit action
  (``ros2 lifecycle set /inverse_kinetostatic_node activate``, refused while
  another publisher is still there; the excitation publisher is started
  again).  A controller that came back by itself would jump from the vent
  to its last command with nobody at the robot expecting it.
* **One ERROR that names the other node**: discovery may know that there is
  another publisher before it knows its name (rclpy then reports
  ``_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_``); the ERROR waits for the
  name up to :data:`NAME_WAIT_S` and then falls back to the count of
  publishers.  While the other node stays, a WARN reminder every
  :data:`REMINDER_S`.

Parameter ``allow_other_publishers`` (default false) lifts the rule for a
lab that multiplexes on purpose.  Discovery takes up to a few seconds (Fast
DDS announces every 3 s): two nodes started at the same moment may both
publish until they have seen each other.
"""

from __future__ import annotations

import time

__all__ = ['NAME_WAIT_S', 'REMINDER_S', 'TopicOwner']

#: Longest wait for the graph to name another publisher before the ERROR gives its count [s].
NAME_WAIT_S = 2.0
#: Interval of the reminder while the other publisher stays [s].
REMINDER_S = 10.0
_UNKNOWN = '_NODE_NAME_UNKNOWN_'


class TopicOwner:
    """Whether ``node`` is the only publisher of ``topic``, and its yield (module docstring).

    ``resume``: what the operator does to resume after a yield (said in the
    ERROR, the reminder and the INFO line when the other node has left).
    """

    def __init__(self, node, topic: str, resume: str,
                 allow_param: str = 'allow_other_publishers') -> None:
        """``allow_param``: the node's boolean parameter that lifts the rule."""
        self.node = node
        self.topic = node.resolve_topic_name(topic)
        self.resume = resume
        self.allow_param = allow_param
        self.others: list[str] = []
        # the yield's and the reminders' times: the node's control time (simulation time
        # under use_sim_time, ros_util.ControlClock); a stand-in without a clock: monotonic
        self._clock = None
        if hasattr(node, 'get_clock'):
            from .ros_util import control_clock   # (lazily: this module needs no rclpy)
            self._clock = control_clock(node)
        self.yielded_at: float | None = None   # control time of the yield
        self.yielded_to = ''                   # the other node(s), as the ERROR named them
        self._reported = False
        self._reminded_at = -float('inf')
        self._left = False

    def _now(self) -> float:
        return time.monotonic() if self._clock is None else self._clock.now()

    # ------------------------------------------------------------ the graph
    def _publishers(self) -> tuple[list[str], int]:
        """(names of the other publishing nodes, count of other publishers with no name yet)."""
        me = (self.node.get_name(), self.node.get_namespace())
        names, unknown = set(), 0
        for info in self.node.get_publishers_info_by_topic(self.topic):
            if info.node_name == _UNKNOWN:
                unknown += 1
            elif (info.node_name, info.node_namespace) != me:
                names.add(f'{info.node_namespace.rstrip("/")}/{info.node_name}')
        return sorted(names), unknown

    def other_publishers(self) -> list[str]:
        """The other publishers of the topic: node names, or a count not named yet."""
        names, unknown = self._publishers()
        if unknown:
            names.append(f'{unknown} publisher(s) not named yet')
        return names

    def may_publish(self) -> bool:
        """True when no other node publishes the topic, or the rule is lifted."""
        if bool(self.node.get_parameter(self.allow_param).value):
            self.others = []
            return True
        self.others = self.other_publishers()
        return not self.others

    # ------------------------------------------------------------ the yield
    @property
    def yielded(self) -> bool:
        """True from :meth:`start_yield` until :meth:`clear`."""
        return self.yielded_at is not None

    def start_yield(self, vented: bool = True) -> None:
        """The node has stopped (``vented``: and sent the vent): :meth:`report`, no resume."""
        if self.yielded_at is None:
            self.yielded_at = self._now()
            self._reported, self._left, self.yielded_to = False, False, ''
            self._vented = vented

    def clear(self) -> None:
        """The operator resumed (or the node was reset): the yield is over."""
        self.yielded_at = None
        self.yielded_to = ''

    def poll(self, now: float | None = None) -> tuple[str, str] | None:
        """While yielded, what to log now: ``(level, text)`` or None; call it often (10 Hz).

        ``('error', ...)`` once, naming the other node as soon as the graph
        knows it (at most :data:`NAME_WAIT_S` after the yield, then the
        count); ``('warn', ...)`` every :data:`REMINDER_S` while it stays;
        ``('info', ...)`` once when it has left.
        """
        if self.yielded_at is None:
            return None
        now = self._now() if now is None else now
        names, unknown = self._publishers()
        if not self._reported:
            if unknown and not names and now - self.yielded_at < NAME_WAIT_S:
                return None   # the graph has not named it yet
            self._reported, self._reminded_at = True, now
            who = names + ([f'{unknown} publisher(s) not named yet'] if unknown else [])
            self.yielded_to = ', '.join(who) if who else 'another publisher (gone already)'
            done = ('vented once and stopped commanding' if self._vented
                    else 'stopped before commanding (no vent: it never did)')
            return 'error', (
                f'{self.topic}: {self.yielded_to} publishes it too: {done}; no automatic '
                f'resume (one owner per pressure topic); to resume: {self.resume} (or set '
                f'{self.allow_param}:=true to allow two publishers)')
        if names or unknown:
            if now - self._reminded_at >= REMINDER_S:
                self._reminded_at = now
                who = ', '.join(self.other_publishers())
                return 'warn', (f'still not commanding {self.topic} '
                                f'({now - self.yielded_at:.0f} s; {who} publishes it); '
                                f'to resume: stop it, then {self.resume}')
            return None
        if not self._left:
            self._left = True
            return 'info', (f'{self.yielded_to} no longer publishes {self.topic}; not resuming '
                            f'by itself: {self.resume}')
        return None

    def report(self) -> str:
        """Log what :meth:`poll` gives; return the ERROR's text (for diagnostics) or ''."""
        news = self.poll()
        if news is None:
            return ''
        level, text = news
        log = self.node.get_logger()   # (rclpy: one severity per call site)
        if level == 'error':
            log.error(text)
            return text
        if level == 'warn':
            log.warning(text)
        else:
            log.info(text)
        return ''

    def status(self) -> str:
        """One line for diagnostics while yielded ('' otherwise)."""
        if self.yielded_at is None:
            return ''
        who = self.yielded_to or ', '.join(self.other_publishers()) or 'another publisher'
        return (f'yielded {self.topic} to {who} (vented); no automatic resume; to resume: '
                f'{self.resume}')
