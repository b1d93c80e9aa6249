"""history.bracket: the entries around a time, as the definition says."""

from collections import deque

from hypothesis import given, strategies as st

from bellow_ancf_ros.core.history import bracket


@given(st.lists(st.integers(0, 20), max_size=30), st.integers(-2, 22))
def test_bracket_is_the_last_entry_at_or_before_and_the_first_after(times, t):
    entries = deque((float(x), i) for i, x in enumerate(sorted(times)))
    before = [e for e in entries if e[0] <= t]
    after = [e for e in entries if e[0] > t]
    assert bracket(entries, t) == (before[-1] if before else None, after[0] if after else None)
    assert bracket(list(entries), t) == bracket(entries, t)
