"""Time-stamped histories: the entries around a time (targets wanted, poses reached)."""

from __future__ import annotations

from typing import Reversible

__all__ = ['bracket']


def bracket(entries: Reversible[tuple], t: float) -> tuple:
    """``(before, after)``: the last entry at or before ``t`` and the first after it.

    ``entries`` are tuples whose first item is a time, in non-decreasing
    order (a list or a deque); either side is None when there is none.  The
    search runs from the newest entry back: the times asked for (a motion
    capture's latency ago, a measurement's capture time) lie near the end of
    a history that grows at the other end (a second of physics steps: a scan
    from the oldest cost the simulated robot 5 % of its step).
    """
    after = None
    for entry in reversed(entries):
        if entry[0] <= t:
            return entry, after
        after = entry
    return None, after
