"""Tests of the motion-capture outlier gate (core/control/_median_gate.py)."""

import numpy as np

from hypothesis import given, settings, strategies as st

from bellow_ancf_ros.core.control._median_gate import MedianGate, _median


def test_a_spike_is_refused_a_lasting_change_accepted_after_three():
    gate = MedianGate(0.005)
    p = np.array([0.01, 0.0, 0.1])
    assert not any(gate.refuses(p + [0.0, 0.0, 1e-4 * i]) for i in range(5))
    assert gate.refuses(p + [0.02, 0.0, 0.0])          # a swapped marker
    assert not gate.refuses(p)                          # the next sample is fine
    moved = p + [0.0, 0.02, 0.0]                        # the robot really moved
    assert [gate.refuses(moved) for _ in range(4)] == [True, True, True, False]


def test_nothing_is_refused_before_three_samples_and_distance_is_pluggable():
    gate = MedianGate(0.1, distance=lambda x, m: abs(float(x[0] - m[0])))
    assert not gate.refuses(np.array([0.0]))
    assert not gate.refuses(np.array([5.0]))           # only one sample before it
    assert not gate.refuses(np.array([0.05]))          # median of (0, 5) is 2.5: two samples
    assert gate.refuses(np.array([5.0]))               # median of (0, 5, 0.05) is 0.05


@settings(max_examples=200, deadline=None)
@given(st.lists(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3), min_size=1,
                max_size=12), st.integers(1, 7))
def test_the_gate_decides_as_numpys_median_of_the_window(samples, window):
    """The plain-float median is ``np.median``'s, bit for bit, whatever the window holds."""
    gate = MedianGate(0.3, window=window)
    recent = []
    for s in samples:
        x = np.array(s)
        want = (len(recent[-window:]) >= 3 and float(np.linalg.norm(
            x - np.median(np.array(recent[-window:]), axis=0))) > 0.3)
        assert gate.refuses(x) == want
        recent.append(x)
    for n in range(1, 8):
        v = samples[0] * n
        assert _median(v[:n]) == np.median(v[:n])
