"""The tests' ROS_DOMAIN_IDs (test/support/ros_domains.py): a worker's own, none reused early."""

import importlib

import ros_domains


def _fresh(monkeypatch, worker, count):
    if worker is None:
        monkeypatch.delenv('PYTEST_XDIST_WORKER', raising=False)
        monkeypatch.delenv('PYTEST_XDIST_WORKER_COUNT', raising=False)
    else:
        monkeypatch.setenv('PYTEST_XDIST_WORKER', worker)
        monkeypatch.setenv('PYTEST_XDIST_WORKER_COUNT', str(count))
    return importlib.reload(ros_domains)   # (a fresh pool of domains)


def test_two_workers_share_the_domains_without_meeting(monkeypatch):
    first = _fresh(monkeypatch, 'gw0', 2).own_domains()
    second = _fresh(monkeypatch, 'gw1', 2).own_domains()
    assert not set(first) & set(second)
    assert sorted(first + second) == list(range(102))


def test_a_domain_comes_back_only_after_all_the_others(monkeypatch):
    mod = _fresh(monkeypatch, 'gw1', 2)
    mine = mod.own_domains()
    drawn = [mod.fresh_domain() for _ in range(2 * len(mine))]
    assert sorted(drawn[:len(mine)]) == mine and sorted(drawn[len(mine):]) == mine
    alone = _fresh(monkeypatch, None, 1)
    assert alone.own_domains() == list(range(102))
    importlib.reload(ros_domains)
