"""TargetFilter: shaping and dynamic feedforward of a target stream, as the inverse node does."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core.control import (StreamFeedforward, TargetFilter, TargetShaper,
                                          shaper_impulses)

F, ZETA = 2.4, 0.05


def test_a_step_is_shaped_after_the_mode_is_known_and_busy_meanwhile():
    tf = TargetFilter('zvd')
    a, b = np.array([0.0, 0.0, 0.2]), np.array([0.01, 0.0, 0.2])
    tf.push(0.0, a)
    tf.push(1.0, b)
    np.testing.assert_array_equal(tf.target(1.0)[0], b)   # no mode yet: as it is
    assert tf.delay_s == 0.0 and not tf.busy(1.0)
    tf.set_mode(F, ZETA)
    times, amps = shaper_impulses('zvd', F, ZETA)
    assert tf.delay_s == pytest.approx(float(amps @ times))
    for k, tk in enumerate(times):   # the staircase: the impulses that have arrived
        assert tf.busy(1.0 + tk - 1e-6)
        got = tf.target(1.0 + tk + 1e-6)[0]
        np.testing.assert_allclose(got, a + amps[:k + 1].sum() * (b - a), atol=1e-12)
    assert not tf.busy(1.0 + times[-1] + 1e-6)   # the last level was solved for
    np.testing.assert_allclose(tf.target(5.0)[0], b)


def test_a_previewed_stream_is_shaped_at_its_newest_time():
    """A target wanted in the future is shaped for that time, not for now."""
    tf = TargetFilter('zv')
    tf.set_mode(F, ZETA)
    ref = TargetShaper('zv', F, ZETA)
    for k in range(50):
        t, p = 0.02 * k, np.array([0.001 * k, 0.0, 0.2])
        tf.push(t + 0.09, p)
        ref.push(t + 0.09, p)
        np.testing.assert_allclose(tf.target(t)[0], ref.at(t + 0.09)[0])


def test_dynamic_feedforward_adds_the_streams_shift_and_keeps_the_axis_a_unit_vector():
    tf = TargetFilter('none', dynamic_feedforward=True, lag_s=0.06)
    ff = StreamFeedforward(F, ZETA, lag_s=0.06)
    tf.set_mode(F, ZETA)
    w = 2 * math.pi / 2.0
    for k in range(60):
        t = 0.02 * k
        p = np.array([0.01 * math.sin(w * t), 0.0, 0.2])
        z = np.array([0.2 * math.sin(w * t), 0.0, 1.0])
        z /= np.linalg.norm(z)
        tf.push(t, p, z)
        ff.push(t, p, z)
        got_p, got_z = tf.target(t)
        np.testing.assert_allclose(got_p, ff.target()[0], atol=1e-15)
        assert np.linalg.norm(got_z) == pytest.approx(1.0)
    assert np.linalg.norm(got_p - p) > 1e-4   # moving: shifted
    assert not tf.busy(t)                      # no shaper: nothing to re-solve


def test_bad_shaping_and_a_stream_going_back():
    with pytest.raises(ValueError, match="target_shaping = 'zvdd' is not allowed"):
        TargetFilter('zvdd')
    a, b = np.array([0.0, 0.0, 0.2]), np.array([0.01, 0.0, 0.2])
    tf = TargetFilter('zv')
    tf.set_mode(F, ZETA)
    tf.push(5.0, a)
    tf.push(1.0, b)   # time went back (a new stream): shaped from where it stood
    times, amps = shaper_impulses('zv', F, ZETA)
    np.testing.assert_allclose(tf.target(1.0 + 1e-6)[0], a + amps[0] * (b - a), atol=1e-15)
    np.testing.assert_allclose(tf.target(1.0 + times[-1] + 1e-6)[0], b, atol=1e-15)
    assert not TargetFilter().enabled and TargetFilter('zv').enabled


@pytest.mark.parametrize('feedforward', [False, True])
def test_a_step_dated_before_the_held_target_is_still_a_move(feedforward):
    """A held target, then a 10 mm step whose time came out 30 ms before the last held one.

    (A node kept off the CPU between reading its clocks dated a target
    early.)  The commands must not step: the stream starts again from
    where it stands, and the step is the smooth move it is otherwise.
    """
    a, b = np.array([0.0, 0.0, 0.2]), np.array([0.01, 0.0, 0.2])
    tf = TargetFilter('smooth', dynamic_feedforward=feedforward, lag_s=0.05)
    tf.set_mode(F, ZETA)
    for k in range(100):
        tf.push(0.02 * k, a)
        tf.target(0.02 * k)
    t_step = 0.02 * 99 - 0.03
    tf.push(t_step, b)
    first = tf.target(0.02 * 99 + 0.01)[0]
    assert np.linalg.norm(first - a) < 0.05 * np.linalg.norm(b - a)   # barely moved
    assert tf.busy(0.02 * 99 + 0.01)
    end = t_step + tf.jumps.duration_s
    np.testing.assert_allclose(tf.target(end + 0.01)[0], b, atol=1e-12)


def test_the_reference_is_shaped_not_shifted():
    tf = TargetFilter('zv', dynamic_feedforward=True, lag_s=0.06)
    tf.set_mode(F, ZETA)
    w = 2 * math.pi / 2.0
    for k in range(30):
        t = 0.02 * k
        tf.push(t, np.array([0.01 * math.sin(w * t), 0.0, 0.2]))
    (cmd, _), (ref, _) = tf.targets(t)
    np.testing.assert_allclose(ref, tf.shaper.at(t)[0])
    assert np.linalg.norm(cmd - ref) > 1e-4   # the shift is on the command only


def test_smooth_stays_busy_until_the_moves_end_was_given_out():
    """A caller that re-solves while busy gets the target itself last, not a point short of it."""
    tf = TargetFilter('smooth')
    a, b = np.array([0.0, 0.0, 0.2]), np.array([0.0, 0.01, 0.2])
    tf.push(0.0, a)
    assert not tf.busy(0.0)                 # no mode yet: targets as they come
    tf.set_mode(10.0, 0.05)
    tf.push(1.0, b)
    dur = tf.jumps.duration_s
    assert tf.busy(1.0) and tf.target(1.0 + dur / 2)[0][1] < 0.01
    assert tf.busy(1.0 + 2 * dur)           # time alone does not end it ...
    np.testing.assert_array_equal(tf.target(1.0 + dur)[0], b)
    assert not tf.busy(1.0 + dur)           # ... the target at the end given out does
    assert tf.hold_until == pytest.approx(1.0 + dur + 0.5)


def test_a_jumps_move_is_not_shifted_by_the_feedforward():
    """The move is the controller's own: the feedforward shifts the stream, not the move.

    (As the node composes them; LoopSimulation builds the same with TargetFilter.of. Shifting
    the move inverted the model's mode on it: one-segment steps overshot 1.2-1.7 mm instead of
    0.26-0.58 mm on three robots of the family.)
    """
    from bellow_ancf_ros.core.control import JumpTransition, StreamFeedforward
    tf = TargetFilter.of(JumpTransition(2.4), StreamFeedforward(2.4, 0.05, lag_s=0.06))
    assert tf.mode == (2.4, 0.05)
    a, b = np.array([0.0, 0.0, 0.2]), np.array([0.0, 0.01, 0.2])
    for k in range(10):
        tf.push(0.02 * k, a)
        tf.targets(0.02 * k)
    t = 0.2
    tf.push(t, b)
    for k in range(1, 40):
        cmd, ref = tf.targets(t + 0.02 * k)
        tf.push(t + 0.02 * k, b)
        np.testing.assert_allclose(cmd[0], ref[0], atol=1e-12)
    assert tf.jumps.moves == 1


def test_smooth_jumps_take_the_robot_files_measured_mode():
    """``mode_error`` (``dynamics.first_mode_error``) reaches the jumps with the mode's damping."""
    from bellow_ancf_ros.core.control._jumps import CYCLES, KNOWN_RAMP_CYCLES, MODE_SPREAD
    tf = TargetFilter('smooth', mode_error=-0.03)
    tf.set_mode(F, ZETA)
    f_robot = F / 0.97
    td = 1.0 / (f_robot * math.sqrt(1.0 - ZETA ** 2))
    assert tf.jumps.duration_s == pytest.approx(KNOWN_RAMP_CYCLES / f_robot + td / 2)
    unknown = TargetFilter('smooth')
    unknown.set_mode(F, ZETA)
    assert unknown.jumps.duration_s == pytest.approx(CYCLES / (MODE_SPREAD * F))
