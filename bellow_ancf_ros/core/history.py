"""Time-stamped histories: the entries around a time (targets wanted, poses reached)."""

from __future__ import annotations

from typing import Iterable

__all__ = ['bracket']


def bracket(entries: Iterable[tuple], t: float) -> tuple:
    """``(before, after)``: the last entry at or before ``t`` and the first after it.

    ``entries`` are tuples whose first item is a time, in non-decreasing
    order; either side is None when there is none.
    """
    before = None
    for entry in entries:
        if entry[0] > t:
            return before, entry
        before = entry
    return before, None
