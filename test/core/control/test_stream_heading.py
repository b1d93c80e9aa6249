"""stream_heading: where a target stream was heading, and what its acceleration allows."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core.control._stream_heading import STALL_S, stream_heading


def _parabola(t):
    return (np.array([0.01, -0.02, 0.2]) + np.array([0.08, 0.03, 0.0]) * t
            + 0.5 * np.array([-0.3, 0.2, 0.05]) * t * t)


@pytest.mark.parametrize('gap', [0.0, 0.02, 0.12, 0.3, STALL_S])
def test_a_constant_acceleration_misses_the_heading_by_exactly_the_allowance(gap):
    """The last step's chord is the velocity half a step back: the miss is a g (g + h) / 2."""
    h = 0.02
    hist = [(t, _parabola(t), None) for t in (0.96, 0.98, 1.0)]
    head, z, allow, allow_rad = stream_heading(hist, 1.0 + gap)
    a = np.linalg.norm([-0.3, 0.2, 0.05])
    miss = np.linalg.norm(_parabola(1.0 + gap) - head)
    assert z is None and allow_rad == 0.0
    assert allow == pytest.approx(0.5 * a * gap * (gap + h), rel=1e-9, abs=1e-15)
    assert miss == pytest.approx(allow, rel=1e-9, abs=1e-15)


def test_a_stream_silent_longer_than_a_stall_heads_for_its_last_target():
    hist = [(t, _parabola(t), np.array([0.0, 0.0, 1.0])) for t in (0.96, 0.98, 1.0)]
    head, z, allow, allow_rad = stream_heading(hist, 1.0 + STALL_S + 0.01)
    np.testing.assert_array_equal(head, _parabola(1.0))
    np.testing.assert_array_equal(z, [0.0, 0.0, 1.0])
    assert allow == allow_rad == 0.0


def test_one_or_two_targets_give_no_allowance_and_the_z_axis_extrapolates():
    z0, z1 = np.array([0.0, 0.0, 1.0]), np.array([math.sin(0.01), 0.0, math.cos(0.01)])
    head, z, allow, _ = stream_heading([(0.0, np.zeros(3), z0)], 0.1)
    np.testing.assert_array_equal(head, np.zeros(3))
    np.testing.assert_array_equal(z, z0)
    head, z, allow, allow_rad = stream_heading(
        [(0.0, np.zeros(3), z0), (0.02, np.array([1e-3, 0.0, 0.0]), z1)], 0.06)
    np.testing.assert_allclose(head, [3e-3, 0.0, 0.0])
    np.testing.assert_allclose(z, z1 + 2 * (z1 - z0))
    assert allow == allow_rad == 0.0
