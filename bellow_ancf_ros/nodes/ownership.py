"""One owner of ``pressure_command``: a node publishes it only while no other node does.

Two controllers on one pressure topic (the inverse node and the excitation
publisher started by mistake) make the regulators flip between their
commands.  Every node that publishes ``pressure_command`` asks the ROS graph,
before every command, which other nodes publish on that topic (a local
query of the middleware's discovery data, about 30 us); while there is one,
it publishes nothing (the vent excepted), logs an error naming the other
node(s) (throttled) and reports ERROR on ``/diagnostics``.  With both nodes
doing so, both fall silent and the regulator driver vents on its command
timeout: the safe outcome.  Parameter ``allow_other_publishers`` (default
false) lifts the rule for a lab that multiplexes on purpose.

Discovery takes up to a few seconds (Fast DDS announces every 3 s): two
nodes started at the same moment may both publish until they have seen
each other.
"""

from __future__ import annotations

__all__ = ['TopicOwner']


class TopicOwner:
    """Whether ``node`` is the only publisher of ``topic`` (see the module docstring)."""

    def __init__(self, node, topic: str, allow_param: str = 'allow_other_publishers') -> None:
        """``allow_param``: the node's boolean parameter that lifts the rule."""
        self.node = node
        self.topic = node.resolve_topic_name(topic)
        self.allow_param = allow_param
        self.others: list[str] = []

    def other_publishers(self) -> list[str]:
        """Fully qualified names of the other nodes publishing the topic (from the graph)."""
        me = (self.node.get_name(), self.node.get_namespace())
        out = []
        for info in self.node.get_publishers_info_by_topic(self.topic):
            if (info.node_name, info.node_namespace) != me:
                ns = info.node_namespace.rstrip('/')
                out.append(f'{ns}/{info.node_name}')
        return sorted(set(out))

    def may_publish(self) -> bool:
        """True when no other node publishes the topic, or the rule is lifted."""
        self.others = self.other_publishers()
        return not self.others or bool(self.node.get_parameter(self.allow_param).value)

    def refusal(self) -> str:
        """The reason given while another node publishes."""
        return (f'not publishing {self.topic}: other publisher(s) {", ".join(self.others)} '
                f'(one owner per pressure topic; stop the other node, or set '
                f'{self.allow_param}:=true to allow it)')
