"""TargetLink's wall-clock deadlines (no ROS): one thread, in order, cancellable, never early."""

import threading
import time

from bellow_ancf_ros.nodes.target_link import _WallTimers


def _threads() -> int:
    return sum(1 for t in threading.enumerate() if t.name == 'target-timers')


def test_calls_come_in_deadline_order_never_before_their_deadline_from_one_thread():
    errors, fired, done = [], [], threading.Event()
    before = _threads()
    timers = _WallTimers(errors.append)
    t0 = time.monotonic()
    delays = [0.06, 0.02, 0.04, 0.0, 0.05, 0.01, 0.03]
    for d in delays:   # (asked out of order)
        timers.call_in(d, lambda d=d: fired.append((d, time.monotonic() - t0)))
    timers.call_in(0.08, done.set)
    assert done.wait(10.0)
    assert [d for d, _ in fired] == sorted(delays)
    assert all(at >= d for d, at in fired), fired
    assert _threads() == before + 1 and not errors
    for _ in range(100):   # a stream's targets: one deadline each, each cancelled by the next
        timers.call_in(0.5, lambda: fired.append('late')).cancel()
    assert _threads() == before + 1


def test_a_cancelled_call_never_comes_and_is_alive_says_so():
    fired, done = [], threading.Event()
    timers = _WallTimers(lambda exc: None)
    dropped = timers.call_in(0.01, lambda: fired.append('dropped'))
    kept = timers.call_in(0.02, lambda: fired.append('kept'))
    assert dropped.is_alive() and kept.is_alive()
    dropped.cancel()
    assert not dropped.is_alive()
    timers.call_in(0.05, done.set)
    assert done.wait(10.0)
    assert fired == ['kept'] and not kept.is_alive()
    kept.cancel()   # (after it fired: nothing)
    assert fired == ['kept']


def test_a_call_that_raises_is_reported_and_the_next_ones_still_come():
    errors, fired, done = [], [], threading.Event()
    timers = _WallTimers(errors.append)

    def bad():
        raise RuntimeError('solver gone')
    timers.call_in(0.0, bad)
    timers.call_in(0.01, lambda: fired.append(1))
    timers.call_in(0.02, done.set)
    assert done.wait(10.0)
    assert fired == [1] and [str(e) for e in errors] == ['solver gone']


def test_a_call_may_ask_for_the_next_one_as_the_late_target_re_solves_do():
    fired, done = [], threading.Event()
    timers = _WallTimers(lambda exc: None)

    def again(left):
        fired.append(left)
        if left:
            timers.call_in(0.005, lambda: again(left - 1))
        else:
            done.set()
    timers.call_in(0.0, lambda: again(3))
    assert done.wait(10.0)
    assert fired == [3, 2, 1, 0]


def test_an_earlier_deadline_asked_while_the_thread_waits_for_a_later_one_comes_first():
    fired, done = [], threading.Event()
    timers = _WallTimers(lambda exc: None)
    timers.call_in(0.3, lambda: (fired.append('later'), done.set()))
    time.sleep(0.05)   # (the thread now waits for the later one)
    timers.call_in(0.0, lambda: fired.append('sooner'))
    assert done.wait(10.0)
    assert fired == ['sooner', 'later']
