"""nodes.worker: the model, the latest-only worker, budget slices, solve statistics (no ROS)."""

import threading
import time

import numpy as np
import pytest

from bellow_ancf_ros.core import ConfigError
from bellow_ancf_ros.nodes import worker


# ------------------------------------------------------------------ the model
def test_ready_model_starts_vented_and_carries_the_payload():
    cfg, model, vented, start = worker.ready_model('one_segment')
    assert cfg.name == 'one_segment' and model.A == cfg.n_actuators_total
    assert vented.success and start is vented          # no payload: one equilibrium
    assert vented.position[2] > 0.0                    # the straight robot, pointing up
    _, _, vented2, loaded = worker.ready_model('one_segment', payload_kg=0.05)
    assert loaded.success and loaded is not vented2
    assert loaded.position[2] < vented2.position[2]    # the payload shortens the robot
    assert np.allclose(vented2.position, vented.position)   # the warm start: no payload


def test_ready_model_leaves_what_it_built_out_of_the_collectors_full_passes():
    """gc.freeze: a full pass of the collector then skips the model and the modules (90 ms)."""
    import gc
    gc.unfreeze()
    try:
        worker.ready_model('one_segment')
        assert gc.get_freeze_count() > 10_000      # (modules, the model, compiled kernels)
        t0 = time.process_time()
        gc.collect()
        assert time.process_time() - t0 < 0.5 * _full_pass_unfrozen()
    finally:
        gc.unfreeze()


def _full_pass_unfrozen() -> float:
    import gc
    gc.unfreeze()
    t0 = time.process_time()
    gc.collect()
    return time.process_time() - t0


def test_ready_model_refuses_an_unknown_robot():
    with pytest.raises(ConfigError):
        worker.ready_model('no_such_robot')


# ------------------------------------------------------------------ latest-only worker
def _wait(pred, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.002)
    return False


def test_latest_worker_processes_only_the_newest():
    gate = threading.Event()
    seen = []

    def process(item):
        seen.append(item)
        if item == 0:
            gate.wait(5.0)      # block on the first item while more arrive

    w = worker.LatestWorker(process)
    try:
        w.submit(0)
        assert _wait(lambda: seen == [0])
        for i in range(1, 1001):
            w.submit(i)
        assert w.pending
        gate.set()
        assert _wait(lambda: w.idle())
        assert seen == [0, 1000]
        assert w.submitted == 1001 and w.processed == 2 and w.dropped == 999
    finally:
        w.stop()


def test_a_re_solve_never_displaces_a_new_item():
    """``resubmit`` (a re-solve tick's) queues only when nothing newer waits."""
    gate = threading.Event()
    seen = []

    def process(item):
        seen.append(item)
        if item == 'old':
            gate.wait(5.0)

    w = worker.LatestWorker(process)
    try:
        assert w.resubmit('old') and _wait(lambda: seen == ['old'])
        w.submit('new')
        assert not w.resubmit('old')   # (the new target waits: it is solved, not this)
        gate.set()
        assert _wait(lambda: w.idle())
        assert seen == ['old', 'new'] and w.resubmitted == 1 and w.dropped == 0
    finally:
        w.stop()


def test_latest_worker_bounds_the_rate():
    """Token bucket: at most BURST starts back to back, then one per period."""
    starts = []
    w = worker.LatestWorker(lambda item: starts.append(time.monotonic()), min_period=lambda: 0.05)
    try:
        for i in range(8):
            w.submit(i)
            assert _wait(lambda: w.idle())
        assert len(starts) == 8
        span = starts[-1] - starts[0]
        # 8 starts: the first BURST free, the other 6 at least one period apart on average
        assert span >= (8 - worker.BURST) * 0.05 - 5e-3
        gaps = np.diff(starts)
        assert np.all(gaps[worker.BURST - 1:] >= 0.05 - 5e-3)
    finally:
        w.stop()


def test_latest_worker_answers_after_idle_at_once():
    starts, sent = [], []
    w = worker.LatestWorker(lambda item: starts.append(time.monotonic()), min_period=lambda: 0.05)
    try:
        for _ in range(3):
            time.sleep(0.12)          # idle for more than two periods: credit is back
            sent.append(time.monotonic())
            w.submit(0)
            assert _wait(lambda: w.idle())
        lags = np.array(starts) - np.array(sent)
        assert np.all(lags < 0.02), lags
    finally:
        w.stop()


def test_latest_worker_keeps_up_with_a_jittery_stream_at_the_limit_rate():
    """A stream at exactly the limit rate, with jitter: no lag builds up, nothing dropped.

    A fixed spacing of one period after the previous start (the old rule)
    made this a queue at full load: each late arrival's lag carried over.
    """
    period = 0.02
    starts, sent = {}, {}
    w = worker.LatestWorker(lambda item: starts.setdefault(item, time.monotonic()),
                            min_period=lambda: period)
    rng = np.random.default_rng(3)
    try:
        t0 = time.monotonic()
        for k in range(60):
            due = t0 + k * period + rng.uniform(-0.4, 0.4) * period
            time.sleep(max(0.0, due - time.monotonic()))
            sent[k] = time.monotonic()
            w.submit(k)
        assert _wait(lambda: w.idle())
        answered = [k for k in sent if k in starts]
        assert len(answered) >= 57, len(answered)      # (the old rule dropped more)
        lags = np.array([starts[k] - sent[k] for k in answered])
        assert np.median(lags) < 0.25 * period, np.median(lags)
    finally:
        w.stop()


def test_latest_worker_survives_exceptions_and_stops():
    errors, seen = [], []

    def process(item):
        if item == 'boom':
            raise RecursionError('deep')
        seen.append(item)

    w = worker.LatestWorker(process, on_error=errors.append)
    w.submit('boom')
    assert _wait(lambda: w.idle() and errors)
    assert isinstance(errors[0], RecursionError)
    w.submit('ok')
    assert _wait(lambda: seen == ['ok'])
    assert w.wait_idle(1.0)
    w.stop()
    assert not w._thread.is_alive()
    w.submit('after stop')        # harmless, never processed
    time.sleep(0.05)
    assert seen == ['ok']


# ------------------------------------------------------------ solve statistics
def test_solve_stats_summary_window_and_age():
    now = [100.0]
    stats = worker.SolveStats(window=4, clock=lambda: now[0])
    s = stats.summary()
    assert s['count'] == 0 and s['last_solve_age_s'] is None and s['median_s'] is None
    for dt in (0.001, 0.002, 0.003, 0.004, 0.010):
        now[0] += 1.0
        stats.record(dt, ok=dt < 0.01)
    now[0] += 0.25
    s = stats.summary()
    assert s['count'] == 5 and s['failures'] == 1 and s['window'] == 4   # oldest dropped
    assert s['last_s'] == 0.010 and s['max_s'] == 0.010 and s['last_ok'] is False
    assert s['median_s'] == pytest.approx(0.0035)
    assert s['p95_s'] == pytest.approx(np.percentile([0.002, 0.003, 0.004, 0.010], 95))
    assert s['last_solve_age_s'] == pytest.approx(0.25)
    assert stats.times() == [0.002, 0.003, 0.004, 0.010]


# ------------------------------------------------------------ budget slices
def test_budget_slices_stop_after_max_slices_of_one_item_in_a_row():
    slices, queued = worker.BudgetSlices(3), []

    def queue(item):
        queued.append(item)
        return True
    a, b = object(), object()
    assert slices.next(a, queue) and slices.next(a, queue)   # slices 1 and 2 of a: queued
    assert not slices.next(a, queue)                         # the third: no more
    assert queued == [a, a]
    assert slices.next(b, queue)                             # a new item counts from 1
    assert queued == [a, a, b]


def test_budget_slices_say_when_the_queue_refuses():
    slices = worker.BudgetSlices(40)
    assert not slices.next('item', lambda item: False)


def test_an_unusable_answer_is_the_next_slice_warm_start_once_and_for_its_item_only():
    slices = worker.BudgetSlices(40)
    a, b = object(), object()
    assert slices.warm_start(a, 'warm') == 'warm'            # nothing handed on yet
    assert slices.next(a, lambda item: True, unusable='a, slice 1')
    assert slices.warm_start(a, 'warm') == 'a, slice 1'      # goes on from it
    assert slices.warm_start(a, 'warm') == 'warm'            # taken once
    assert slices.next(a, lambda item: True, unusable='a, slice 2')
    assert slices.warm_start(b, 'warm') == 'warm'            # a newer item: the last good one
    assert slices.warm_start(a, 'warm') == 'warm'            # (and the old answer is gone)
    assert slices.next(a, lambda item: True)                 # usable: nothing handed on
    assert slices.warm_start(a, 'warm') == 'warm'
    assert not slices.next(a, lambda item: False, unusable='not queued')
    assert slices.warm_start(a, 'warm') == 'warm'            # no next slice: nothing kept
