"""Targets from one publisher at a time (nodes/target_sources.py), without ROS."""

import numpy as np

from bellow_ancf_ros.nodes.target_sources import HOLD_S, TargetSources

A = np.array([0.0, 0.0, 0.1])
B = A + np.array([0.0, 0.01, 0.0])


def test_two_publishers_taking_turns_are_held_until_one_stops():
    asked = []
    src = TargetSources(lambda: 2, lambda: asked.append(1) or ['/planner', '/teleop'])
    t, held = 0.0, []
    for _ in range(50):   # both at 50 Hz, 10 mm apart, interleaved
        for p in (A, B):
            t += 0.01
            held.append(src.holds(p, t))
    # the second target jumps away (taken: the move towards it begins), the third turns back
    # (taken: to the first stream's target), every one after is held
    assert held[0] is None and held[1] is None and held[2] is None
    assert all(h is not None for h in held[3:])
    assert len(set(held[3:])) == 1   # one line through the episode (rate-limited WARN)
    assert '/planner, /teleop' in held[3] and 'more than one publisher' in held[3]
    assert len(asked) == 1 and src.turns == 98
    t0 = t + 0.02   # the teleoperator stops: the planner's next target is the last turn,
    while t < t0 + 1.0:   # then its targets are taken after HOLD_S
        t += 0.02
        assert (src.holds(A, t) is None) == (t >= t0 + HOLD_S - 1e-9)


def test_one_publisher_is_never_held_and_streams_that_do_not_take_turns_neither():
    src = TargetSources(lambda: 1)
    t = 0.0
    for _ in range(20):   # one publisher stepping back and forth (a test rig): taken
        for p in (A, B):
            t += 0.02
            assert src.holds(p, t) is None
    two = TargetSources(lambda: 2)   # a lead-in held, then a path starting there: no turns
    path = [A + np.array([0.001 * np.sin(0.1 * k), 0.0, 0.0]) for k in range(100)]
    assert all(two.holds(p, 0.02 * k) is None for k, p in enumerate([A] * 20 + path))
    assert two.holds(B, 3.0) is None and two.holds(B, 3.02) is None   # a step: taken
    assert two.turns == 0
