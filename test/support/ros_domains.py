"""ROS_DOMAIN_IDs for the tests: none used twice in a session until all 102 were.

A test picks a domain of its own so that two tests never see each other's
nodes.  Drawn at random with repeats, a test could land on a domain a
recent test used; a participant killed with SIGKILL stays in discovery
until its lease runs out, and such a test saw a stranger's
``inverse_kinetostatic_node``.  This hands the domains out in a shuffled
order instead, so a domain comes back only after every other one was used.
"""

import random
import threading

__all__ = ['fresh_domain']

_lock = threading.Lock()
_left: list = []


def fresh_domain() -> int:
    """A ROS_DOMAIN_ID (0-101) not handed out since the last 101 others."""
    with _lock:
        if not _left:
            _left.extend(random.sample(range(102), 102))
        return _left.pop()
