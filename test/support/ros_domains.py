"""ROS_DOMAIN_IDs for the tests: none used twice in a session until all 102 were.

A test picks a domain of its own so that two tests never see each other's
nodes.  Drawn at random with repeats, a test could land on a domain a
recent test used; a participant killed with SIGKILL stays in discovery
until its lease runs out, and such a test saw a stranger's
``inverse_kinetostatic_node``.  This hands the domains out in a shuffled
order instead, so a domain comes back only after every other one was used.
Under pytest-xdist each worker has its own share of the domains (worker
``i`` of ``n``: the domains ``d`` with ``d % n == i``), so that tests
running at the same time on two workers never meet either.
"""

import os
import random
import threading

__all__ = ['fresh_domain', 'own_domains']

_lock = threading.Lock()
_left: list = []


def own_domains() -> list:
    """The ROS_DOMAIN_IDs (0-101) this test process may use (its xdist worker's share)."""
    worker = os.environ.get('PYTEST_XDIST_WORKER', '')
    count = int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1') or 1)
    index = int(worker[2:]) if worker.startswith('gw') and worker[2:].isdigit() else 0
    return [d for d in range(102) if d % count == index % count]


def fresh_domain() -> int:
    """A ROS_DOMAIN_ID of :func:`own_domains` not handed out since all the others were."""
    with _lock:
        if not _left:
            mine = own_domains()
            _left.extend(random.sample(mine, len(mine)))
        return _left.pop()
