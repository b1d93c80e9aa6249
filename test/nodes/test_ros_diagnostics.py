"""nodes.diagnostics: per-solve statuses throttled to 10 Hz, news at once, the newest flushed."""

import threading
import time

import pytest

rclpy = pytest.importorskip('rclpy')

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.lifecycle import Node as LifecycleNode  # noqa: E402

from bellow_ancf_ros.nodes.diagnostics import STATUS_PERIOD_S, ThrottledStatus  # noqa: E402
from bellow_ancf_ros.nodes.diagnostics import (  # noqa: E402
    lifecycle_level, lifecycle_state, solve_outcome)
from bellow_ancf_ros.nodes.ros_util import diagnostics_qos  # noqa: E402
from bellow_ancf_ros.demos.pipeline import wait_until  # noqa: E402


@pytest.fixture
def spun(ros_context):
    """A node publishing statuses and a recorder of /diagnostics, spun in a thread."""
    node = rclpy.create_node('status_source', namespace='/throttle', context=ros_context)
    pub = node.create_publisher(DiagnosticArray, '/diagnostics', diagnostics_qos())
    got, lock = [], threading.Lock()

    def record(arr):
        with lock:
            got.extend(s for s in arr.status if s.name == 'solver')
    node.create_subscription(DiagnosticArray, '/diagnostics', record, diagnostics_qos())
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    thread = threading.Thread(target=ex.spin, daemon=True)
    thread.start()
    assert wait_until(lambda: pub.get_subscription_count() >= 1, 10.0)

    def statuses():
        with lock:
            return list(got)
    yield node, pub, statuses
    ex.shutdown(timeout_sec=2.0)
    thread.join(5.0)
    node.destroy_node()


def _values(s):
    return {v.key: v.value for v in s.values}


def test_repeats_are_throttled_news_go_at_once_and_the_newest_arrives(spun):
    node, pub, statuses = spun
    st = ThrottledStatus(node, pub, 'solver')
    OK, WARN = DiagnosticStatus.OK, DiagnosticStatus.WARN
    t0 = time.monotonic()
    for i in range(200):  # a burst far faster than 10 Hz, all "target reached"
        st.submit('robot', OK, 'target reached', {'i': str(i)})
    burst_s = time.monotonic() - t0
    assert wait_until(lambda: any(_values(s)['i'] == '199' for s in statuses()), 10.0)
    ok = statuses()
    assert _values(ok[0])['i'] == '0'  # the first at once
    assert _values(ok[-1])['i'] == '199'  # the newest flushed by the timer
    # at most one per period while the burst lasted, plus the flush
    assert len(ok) <= 2 + burst_s / STATUS_PERIOD_S, [_values(s)['i'] for s in ok]
    assert st.deferred >= 200 - len(ok)
    # a new level goes out at once (published inside submit), a repeat right after it waits
    n, published = len(statuses()), st.published
    st.submit('robot', WARN, 'target unreachable', {'i': 'w'})
    assert st.published == published + 1
    st.submit('robot', WARN, 'target unreachable', {'i': 'w2'})
    assert st.published == published + 1
    assert wait_until(lambda: len(statuses()) >= n + 2, 10.0)
    assert [(s.level, _values(s)['i']) for s in statuses()[n:]] == [(WARN, 'w'), (WARN, 'w2')]
    # and statuses slower than the period are each published
    for i in range(3):
        time.sleep(STATUS_PERIOD_S * 1.2)
        st.submit('robot', WARN, 'target unreachable', {'i': f's{i}'})
    assert wait_until(
        lambda: [_values(s)['i'] for s in statuses()][-3:] == ['s0', 's1', 's2'], 10.0)


class _Inv:
    def __init__(self, reachable=True, message='m'):
        self.reachable, self.message = reachable, message


@pytest.mark.parametrize('args, level, counter, logged, words', [
    ((False, True, True), DiagnosticStatus.WARN, None, True, 'no usable answer'),
    ((False, True, False), DiagnosticStatus.ERROR, 'failed', True, 'no usable answer'),
    ((False, False, False), DiagnosticStatus.ERROR, 'failed', True, 'solve failed'),
    ((True, False, False, 'limit'), DiagnosticStatus.ERROR, 'failed', True, 'safety gate (limit)'),
    ((True, True, True), DiagnosticStatus.WARN, 'over_budget', True, 'so far sent, continuing'),
    ((True, False, False, None, 'stale'), DiagnosticStatus.WARN, None, False, 'feedback stale'),
    ((True, False, False), DiagnosticStatus.OK, None, False, 'target reached'),
])
def test_each_solve_outcome_has_its_level_counter_and_words(args, level, counter, logged, words):
    got = solve_outcome(_Inv(), *args)
    assert got[0] == level and got[2] == counter and got[3] == logged and words in got[1]


def test_an_unreachable_target_is_a_counted_warning_naming_the_best_fit():
    level, msg, counter, logged = solve_outcome(_Inv(False, 'best 3 mm'), True, False, False)
    assert (level, counter, logged) == (DiagnosticStatus.WARN, 'unreachable', True)
    assert msg.endswith('best 3 mm')


@pytest.mark.parametrize('args, level, words', [
    (('inactive', 'yielded to /exc'), DiagnosticStatus.ERROR, 'inactive: yielded to /exc'),
    (('active', '', True), DiagnosticStatus.OK, 'pressure commands enabled'),
    (('active', '', False), DiagnosticStatus.WARN, 'the last solve failed'),
    (('active', '', True, '', '', 0), DiagnosticStatus.WARN, 'nothing subscribes to its'),
    (('active', '', True, '', '', 2), DiagnosticStatus.OK, 'pressure commands enabled'),
    (('inactive', '', None, '', '', 0), DiagnosticStatus.OK, 'pressure commands disabled'),
    (('inactive',), DiagnosticStatus.OK, 'pressure commands disabled'),
    (('unconfigured', '', None, 'no robot', 'configure again'), DiagnosticStatus.ERROR,
     'configure failed (no robot); configure again'),
    (('unconfigured',), DiagnosticStatus.WARN, 'unconfigured: no pressure commands'),
])
def test_the_heartbeat_says_the_lifecycle_state_and_why(args, level, words):
    got = lifecycle_level(*args)
    assert got[0] == level and words in got[1]


def test_the_lifecycle_state_is_rclpys_and_the_flags_without_it(ros_context):
    node = LifecycleNode('lifecycle_label', context=ros_context)
    try:
        # the state machine's word, whatever the flags say
        assert lifecycle_state(node, active=True, configured=True) == 'unconfigured'
        node.trigger_configure()
        assert lifecycle_state(node, active=False, configured=False) == 'inactive'
        node.trigger_activate()
        assert lifecycle_state(node, active=False, configured=False) == 'active'
    finally:
        node.destroy_node()
    no_machine = object()
    assert lifecycle_state(no_machine, active=True, configured=True) == 'active'
    assert lifecycle_state(no_machine, active=False, configured=True) == 'inactive'
    assert lifecycle_state(no_machine, active=False, configured=False) == 'unconfigured'
