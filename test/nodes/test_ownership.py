"""TopicOwner's log after a yield, on a fake clock and a fake ROS graph (no rclpy needed).

The rule (docs/ros.md "One owner of pressure_command", nodes/ownership.py):
one ERROR that names the other node once the graph knows its name (it waits
up to ``NAME_WAIT_S`` = 2 s, then gives the count; never rclpy's placeholder
``_NODE_NAME_UNKNOWN_``), a WARN reminder every ``REMINDER_S`` = 10 s while
the other node stays, one INFO when it has left.  The node calls
``report()`` at its timer rate; here it is called every 0.125 s of a fake
monotonic clock while the fake graph changes at chosen instants.
"""

from types import SimpleNamespace

import pytest

from bellow_ancf_ros.nodes import ownership
from bellow_ancf_ros.nodes.ownership import NAME_WAIT_S, REMINDER_S, TopicOwner

UNKNOWN_NAME, UNKNOWN_NS = '_NODE_NAME_UNKNOWN_', '_NODE_NAMESPACE_UNKNOWN_'
RESUME = 'ros2 lifecycle set /inverse_kinetostatic_node activate'
TICK = 0.125   # [s] about the nodes' 10 Hz, and exact in binary: no rounding at 10 s


class FakeClock:
    """time.monotonic of ownership.py, advanced by the test."""

    def __init__(self):
        self.t = 1000.0

    def __call__(self):
        return self.t


class FakeNode:
    """What TopicOwner uses of an rclpy node: its name, the graph, a parameter, a logger."""

    def __init__(self, name='inverse_kinetostatic_node', namespace='/'):
        self.name, self.namespace = name, namespace
        self.publishers = [(name, namespace)]   # (node name, namespace) per publisher
        self.allow = False
        self.logged = []                         # (clock time, level, text)
        self.clock = None
        self.queried = []

    def get_name(self):
        return self.name

    def get_namespace(self):
        return self.namespace

    def resolve_topic_name(self, topic):
        return '/' + topic

    def get_publishers_info_by_topic(self, topic):
        self.queried.append(topic)
        return [SimpleNamespace(node_name=n, node_namespace=ns) for n, ns in self.publishers]

    def get_parameter(self, name):
        assert name == 'allow_other_publishers'
        return SimpleNamespace(value=self.allow)

    def get_logger(self):
        def log(level):
            return lambda text: self.logged.append((self.clock(), level, text))
        return SimpleNamespace(error=log('error'), warning=log('warn'), info=log('info'))


@pytest.fixture
def clock(monkeypatch):
    c = FakeClock()
    monkeypatch.setattr(ownership, 'time', SimpleNamespace(monotonic=c))
    return c


@pytest.fixture
def node(clock):
    n = FakeNode()
    n.clock = clock
    return n


def run(owner, node, clock, seconds, events=()):
    """Call ``owner.report()`` every TICK for ``seconds``; ``events``: {time: graph change}."""
    events = dict(events)
    t0 = clock.t
    for i in range(round(seconds / TICK) + 1):
        clock.t = t0 + i * TICK
        for when in [when for when in events if when <= i * TICK]:
            events.pop(when)(node)
        owner.report()
    return t0


def at(level, node, t0):
    """Times (relative to t0) of the log lines of ``level``."""
    return [round(t - t0, 6) for t, lev, _ in node.logged if lev == level]


def texts(level, node):
    return [text for _, lev, text in node.logged if lev == level]


def test_the_error_waits_for_the_name_then_names_the_node_once(node, clock):
    owner = TopicOwner(node, 'pressure_command', RESUME)
    node.publishers.append((UNKNOWN_NAME, UNKNOWN_NS))   # discovery: a publisher, no name yet
    assert not owner.may_publish()
    assert owner.others == ['1 publisher(s) not named yet']
    owner.start_yield()
    assert owner.yielded
    name_at = 1.25   # the graph names it 1.25 s after the yield (< NAME_WAIT_S)
    t0 = run(owner, node, clock, 45.0, {name_at: lambda n: n.publishers.__setitem__(
        1, ('excitation_publisher', '/'))})

    assert at('error', node, t0) == [name_at]   # not before the name, and only once
    (error,) = texts('error', node)
    assert error.startswith('/pressure_command: /excitation_publisher publishes it too: '
                            'vented once and stopped commanding'), error
    assert 'no automatic resume' in error and f'to resume: {RESUME}' in error, error
    assert 'allow_other_publishers:=true' in error, error
    assert all('UNKNOWN' not in text for _, _, text in node.logged), node.logged
    assert owner.yielded_to == '/excitation_publisher'
    # a reminder every REMINDER_S after the ERROR while the other node stays
    assert at('warn', node, t0) == [name_at + k * REMINDER_S for k in (1, 2, 3, 4)]
    for k, warn in enumerate(texts('warn', node), start=1):
        assert warn == (f'still not commanding /pressure_command ({name_at + k * REMINDER_S:.0f}'
                        f' s; /excitation_publisher publishes it); to resume: stop it, then '
                        f'{RESUME}'), warn
    assert at('info', node, t0) == []
    assert 'yielded /pressure_command to /excitation_publisher' in owner.status()


def test_one_info_when_the_other_node_leaves_and_no_more_reminders(node, clock):
    owner = TopicOwner(node, 'pressure_command', RESUME)
    node.publishers.append(('excitation_publisher', '/exc'))
    assert not owner.may_publish() and owner.others == ['/exc/excitation_publisher']
    owner.start_yield()
    t0 = run(owner, node, clock, 60.0, {25.1: lambda n: n.publishers.pop()})

    assert at('error', node, t0) == [0.0]   # named at once: no wait
    assert at('warn', node, t0) == [10.0, 20.0]   # not at 30, 40, 50
    assert at('info', node, t0) == [25.125]   # the first report after it left, once
    (info,) = texts('info', node)
    assert info == (f'/exc/excitation_publisher no longer publishes /pressure_command; not '
                    f'resuming by itself: {RESUME}')
    # the owner stays yielded (no resume by itself) and may publish only after clear()
    assert owner.yielded and owner.may_publish()
    owner.clear()
    assert not owner.yielded and owner.status() == ''


def test_an_unnamed_publisher_gets_the_error_with_its_count_after_the_wait(node, clock):
    owner = TopicOwner(node, 'pressure_command', RESUME)
    node.publishers.append((UNKNOWN_NAME, UNKNOWN_NS))
    owner.start_yield(vented=False)
    t0 = run(owner, node, clock, 15.0)

    assert at('error', node, t0) == [NAME_WAIT_S]
    (error,) = texts('error', node)
    assert '1 publisher(s) not named yet publishes it too' in error, error
    assert 'stopped before commanding (no vent: it never did)' in error, error
    assert at('warn', node, t0) == [NAME_WAIT_S + REMINDER_S]
    assert all('UNKNOWN' not in text for _, _, text in node.logged), node.logged


def test_nothing_is_logged_without_a_yield_and_the_rule_can_be_lifted(node, clock):
    owner = TopicOwner(node, 'pressure_command', RESUME)
    node.publishers.append(('node_b', '/'))   # its own publisher above is not "another"
    node.publishers.append(('inverse_kinetostatic_node', '/other_ns'))
    assert owner.other_publishers() == ['/node_b', '/other_ns/inverse_kinetostatic_node']
    assert not owner.may_publish()
    node.allow = True
    assert owner.may_publish() and owner.others == []
    run(owner, node, clock, 30.0)
    assert node.logged == [] and owner.status() == ''
    assert set(node.queried) == {'/pressure_command'}


def test_a_second_yield_after_clear_reports_again(node, clock):
    owner = TopicOwner(node, 'pressure_command', RESUME)
    node.publishers.append(('excitation_publisher', '/'))
    owner.start_yield()
    owner.start_yield()   # a second call while yielded changes nothing
    t0 = run(owner, node, clock, 1.0)
    assert at('error', node, t0) == [0.0]
    owner.clear()
    owner.start_yield()
    t1 = run(owner, node, clock, 1.0)
    assert at('error', node, t0) == [0.0, t1 - t0]   # one more ERROR, at the second yield
