"""A control node's threads on the real-time scheduler (``nodes/realtime.py``), without ROS.

The node is a stand-in with the parameters and logger ``use_realtime``
reads; the scheduler calls are recorded, never made (the test process stays
on the normal scheduler).  The real node's threads are checked by
``test_ros_busy_loop.py``, which runs it beside CPU-bound processes.
"""

import os
import threading

import pytest

from bellow_ancf_ros.nodes import realtime


class _Value:
    def __init__(self, value):
        self.value = value


class _Log:
    def __init__(self):
        self.lines = []

    def info(self, text):
        self.lines.append(('info', text))

    def warning(self, text):
        self.lines.append(('warning', text))


class _Node:
    def __init__(self, **params):
        self.params, self.log = params, _Log()

    def has_parameter(self, name):
        return name in self.params

    def get_parameter(self, name):
        return _Value(self.params[name])

    def get_logger(self):
        return self.log


@pytest.fixture
def calls(monkeypatch):
    """The scheduler calls ``use_realtime`` makes, on three made-up threads (none made)."""
    made = []
    monkeypatch.setattr(realtime, '_threads', lambda: [11, 12, 13])
    monkeypatch.setattr(realtime.os, 'sched_setscheduler',
                        lambda tid, policy, param: made.append((tid, policy,
                                                                param.sched_priority)),
                        raising=False)
    return made


def test_every_thread_at_the_priority_asked_for(calls):
    node = _Node(realtime_priority=10, use_sim_time=False)
    text = realtime.use_realtime(node)
    assert calls == [(tid, os.SCHED_FIFO, 10) for tid in (11, 12, 13)]
    assert node.log.lines == [('info', text)] and 'SCHED_FIFO priority 10' in text
    assert 'its 3 threads' in text


@pytest.mark.parametrize('params', [dict(realtime_priority=0, use_sim_time=False),
                                    dict(realtime_priority=10, use_sim_time=True),
                                    dict(use_sim_time=False)])
def test_normal_scheduler_at_zero_under_sim_time_or_without_the_parameter(calls, params):
    node = _Node(**params)
    realtime.use_realtime(node)
    assert calls == [] and node.log.lines == []


def test_not_permitted_warns_once_and_leaves_no_thread_on_fifo(monkeypatch):
    made = []

    def setscheduler(tid, policy, param):
        if policy == os.SCHED_FIFO and tid == 12:
            raise PermissionError(1, 'Operation not permitted')
        made.append((tid, policy))
    monkeypatch.setattr(realtime, '_threads', lambda: [11, 12, 13])
    monkeypatch.setattr(realtime.os, 'sched_setscheduler', setscheduler, raising=False)
    node = _Node(realtime_priority=10, use_sim_time=False)
    text = realtime.use_realtime(node)
    # the one thread raised before the refusal is back on the normal scheduler, as all are
    assert made == [(11, os.SCHED_FIFO)] + [(t, os.SCHED_OTHER) for t in (11, 12, 13)]
    assert node.log.lines == [('warning', text)]
    assert text.startswith('realtime_priority 10: not permitted (Operation not permitted)')
    assert 'realtime_priority 0' in text   # (how to silence it)


def test_the_threads_are_this_processs():
    assert os.getpid() in realtime._threads()   # (the main thread's id is the process id)


def test_background_work_stays_on_the_normal_scheduler():
    """A thread that says it does background work is left out of the threads raised."""
    seen = {}

    def work():
        realtime.background()
        seen['tid'] = threading.get_native_id()
        seen['policy'] = os.sched_getscheduler(0)
    t = threading.Thread(target=work)
    t.start()
    t.join()
    assert seen['policy'] == os.SCHED_OTHER
    assert seen['tid'] in realtime._BACKGROUND
    realtime._BACKGROUND.discard(seen['tid'])
