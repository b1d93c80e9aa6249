"""ModeWatch's thread (no ROS): an answer that comes after stop reaches nobody."""

import threading
import types

from bellow_ancf_ros.nodes.mode_watch import ModeWatch


class _Logger:
    def __init__(self):
        self.lines = []

    def error(self, msg, **_):
        self.lines.append(msg)


class _Node:
    def __init__(self):
        self.logger = _Logger()

    def get_logger(self):
        return self.logger


class _SlowCheck:
    """A modal analysis that runs until released (then answers, or raises)."""

    def __init__(self, fail=False):
        self.entered, self.release, self.fail = threading.Event(), threading.Event(), fail

    def due(self, fw, now):
        return True

    def update(self, fw, now):
        self.entered.set()
        self.release.wait(10.0)
        if self.fail:
            raise RuntimeError('analysis failed')
        return types.SimpleNamespace(frequency_hz=10.0)


def _running(fail):
    node, check = _Node(), _SlowCheck(fail)
    watch, heard = ModeWatch(node, check), []
    watch.listen(lambda before, res: heard.append(res))
    watch.start()
    watch.offer(types.SimpleNamespace(success=True, converged=True, load=None))
    assert check.entered.wait(5.0)
    return node, check, watch, heard


def test_an_answer_after_stop_reaches_no_listener():
    node, check, watch, heard = _running(fail=False)
    thread = watch._thread
    assert watch.stop(timeout=0.05) is False      # the analysis still runs
    check.release.set()
    thread.join(5.0)
    assert not thread.is_alive()
    assert heard == [] and watch.result is None


def test_a_failure_after_stop_logs_nothing():
    node, check, watch, heard = _running(fail=True)
    thread = watch._thread
    assert watch.stop(timeout=0.05) is False
    check.release.set()
    thread.join(5.0)
    assert node.logger.lines == [] and heard == []


def test_an_answer_before_stop_is_heard_and_stop_joins():
    node, check, watch, heard = _running(fail=False)
    check.release.set()
    for _ in range(100):
        if heard:
            break
        threading.Event().wait(0.02)
    assert len(heard) == 1 and heard[0].frequency_hz == 10.0
    assert watch.stop() is True


def test_a_watch_started_again_after_stop_answers_its_start_pose():
    node, check = _Node(), _SlowCheck()
    check.release.set()
    watch, heard = ModeWatch(node, check), []
    watch.listen(lambda before, res: heard.append(res))
    fw = types.SimpleNamespace(success=True, converged=True, load=None)
    watch.start(fw)
    assert len(heard) == 1 and watch.stop() is True
    watch.start(fw)   # answered at once, before the thread: not refused as stopped
    assert len(heard) == 2
    assert watch.stop() is True
