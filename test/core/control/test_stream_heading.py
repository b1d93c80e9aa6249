"""stream_heading: where a target stream was heading, and what its acceleration allows."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core.control._stream_heading import (
    STALL_S, off_cubic, stream_grid, stream_heading, stream_jumps, stream_times)


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


def test_the_grid_of_a_timer_whose_sends_are_late():
    """Ticks at 50 Hz, sends late by 0.5 ms on average, some by 3-19 ms, a tick skipped.

    Each stamp's tick is found (a stamp is never earlier than its pose's
    time); those within a quarter interval after their ticks are on the
    grid's line, the later ones are not trusted.
    """
    rng = np.random.default_rng(3)
    ticks = np.array([k for k in range(31) if k != 12]) * 0.02   # (tick 12 skipped)
    late = rng.exponential(5e-4, len(ticks))
    late[[4, 17, 25]] = [0.003, 0.012, 0.019]
    stamps = 1.0 + ticks + late
    grid, on = stream_grid(stamps)
    np.testing.assert_allclose(grid - 1.0, ticks, atol=1e-3)
    assert list(np.flatnonzero(~on)) == [17, 25]
    assert stream_grid(stamps[:5]) is None                      # too few to tell
    assert stream_grid(np.array([0.0, 0.02, 0.04, 0.041, 0.042, 0.043, 0.06])) is None


def test_the_grid_of_a_timer_sent_3_ms_late_on_average():
    """Sends late by 3 ms on average (exponential, one after the other), 50 Hz, 30 at a time.

    The median interval alone was 0.3-0.6 ms off the timer's (15 ms over the
    window), and a send late by more than half an interval counted as a
    skipped tick: the grid was found in 77 % of the windows, its ticks within
    1 ms of the poses' times in 56 %.  Now in all of them, and 79 %.
    """
    rng = np.random.default_rng(3)
    stamps = np.arange(400) / 50 + rng.exponential(3e-3, 400)
    for i in range(1, 400):
        stamps[i] = max(stamps[i], stamps[i - 1] + 2e-4)   # (a send after the one before)
    found = close = 0
    for end in range(30, 400):
        got = stream_grid(stamps[end - 30:end])
        if got is not None:
            found += 1
            close += np.max(np.abs(got[0] - np.arange(end - 30, end) / 50)) < 1e-3
    assert found == 370 and close >= 0.75 * 370, (found, close)


def test_a_stream_is_read_by_its_grid_only_where_its_poses_are_smoother_by_it():
    """Stamped when sent: by the grid.  Stamped with their own times, however late: the stamps."""
    rng = np.random.default_rng(4)
    ticks = np.arange(30) * 0.02
    late = rng.exponential(1e-3, 30)
    sent = np.array([_parabola(t) for t in ticks])
    times, trusted, on_grid, off = stream_times(ticks + late, sent)
    assert on_grid and off < 1e-9
    np.testing.assert_allclose(times[trusted], ticks[trusted], atol=1e-3)
    own = np.array([_parabola(t) for t in ticks + late])
    times, trusted, on_grid, off = stream_times(ticks + late, own)
    assert not on_grid and trusted.all() and off < 1e-9
    np.testing.assert_array_equal(times, ticks + late)


def test_a_target_after_a_late_send_is_no_jump_but_a_step_is():
    """The newest target sent 37 ms late, the next tick skipped: the target after it.

    Stamped 3 ms after the late one and two ticks on: by the stamps the
    stream's last step took 57 ms, and the target is 3 mm past its heading.
    """
    path = [(k * 0.02 + (0.037 if k == 20 else 0.0), _parabola(k * 0.02), None)
            for k in range(21)]
    t_new, p_new = 22 * 0.02 + 1e-4, _parabola(22 * 0.02)
    head, _, allow, _ = stream_heading(path, t_new)
    assert np.linalg.norm(p_new - head) > 2.5e-3 + allow        # the old reading: a jump
    assert not stream_jumps(path, t_new, p_new, jump_m=2e-3)
    assert stream_jumps(path, t_new, p_new + [0.0, 0.0, 0.005], jump_m=2e-3)


def test_times_on_two_instants_give_a_distance_not_an_error():
    """Stamps on fewer than three instants: the normal equations were singular (LinAlgError)."""
    P = np.random.default_rng(0).normal(size=(8, 3))
    for times in ([0, 0, 0, 0, 0, 0, 1, 1], [5] * 8):
        assert math.isfinite(off_cubic(np.array(times, float), P))
    t = np.arange(8) / 50.0
    assert off_cubic(t, np.c_[t, t ** 2, t ** 3]) < 1e-12   # (a cubic: none)
