"""Targets from one publisher at a time (nodes/target_sources.py), without ROS."""

from bellow_ancf_ros.nodes.target_sources import HOLD_S, TargetSources


def _info(seq):
    return {'source_timestamp': 0, 'received_timestamp': 0, 'publication_sequence_number': seq,
            'reception_sequence_number': None}


def test_one_publisher_is_always_taken_and_unknown_sequences_too():
    src = TargetSources()
    assert all(src.holds(_info(k), 0.02 * k) is None for k in range(1, 200))
    assert all(src.holds(_info(k), 0.02 * k) is None for k in range(230, 400, 7))   # lost ones
    for info in (None, {}, _info(None), _info(0)):   # a middleware that does not number them
        assert TargetSources().holds(info, 0.0) is None
    assert src.interleavings == 0


def test_two_publishers_hold_the_targets_until_one_sends_alone():
    asked = []
    src = TargetSources(lambda: asked.append(1) or ['/planner', '/teleop'])
    t, a, b, held = 0.0, 500, 0, []
    for _ in range(50):   # both at 50 Hz, interleaved
        a, b, t = a + 1, b + 1, t + 0.01
        held.append(src.holds(_info(a), t))
        t += 0.01
        held.append(src.holds(_info(b), t))
    assert held[0] is None   # the first publisher's target, before the other was seen
    assert all(h is not None for h in held[1:])
    assert len({h for h in held[1:]}) == 1   # one line through the episode (rate-limited WARN)
    assert '/planner, /teleop' in held[1] and 'more than one publisher' in held[1]
    assert len(asked) == 1 and src.interleavings == 99   # each one back, or far ahead
    # the second publisher stops: the first one's targets are taken after HOLD_S alone
    # (from its first message after the other's last: far ahead of it)
    a, t = a + 1, t + 0.02
    assert src.holds(_info(a), t) is not None
    t0 = t
    while t < t0 + 1.0:
        a, t = a + 1, t + 0.02
        taken = src.holds(_info(a), t) is None
        assert taken == (t >= t0 + HOLD_S - 1e-9)


def test_a_handover_costs_a_pause():
    src = TargetSources()
    for k in range(1, 100):   # the planner, then it stops
        assert src.holds(_info(k), 0.02 * k) is None
    t = 3.0   # a teleoperator starts: its numbering starts at 1
    assert src.holds(_info(1), t) is not None
    assert src.holds(_info(2), t + HOLD_S / 2) is not None
    assert src.holds(_info(3), t + HOLD_S + 0.01) is None


def test_a_rare_publisher_with_higher_numbers_is_refused_too():
    """A teleoperator that has sent for an hour at 1 Hz beside a planner that just started."""
    src = TargetSources()
    taken, t, planner, teleop = [], 0.0, 0, 3600
    for k in range(300):   # the planner at 50 Hz, the teleoperator every second
        t += 0.02
        planner += 1
        taken.append(('planner', src.holds(_info(planner), t) is None))
        if k % 50 == 25:
            teleop += 1
            taken.append(('teleop', src.holds(_info(teleop), t) is None))
    assert not any(ok for who, ok in taken if who == 'teleop')
    assert any(ok for who, ok in taken if who == 'planner')
