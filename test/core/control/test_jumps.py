"""JumpTransition: a jump of the targets becomes a minimum-jerk move leaving the family at rest."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core import load_robot
from bellow_ancf_ros.core.control import FeedbackSettings, IntegralFeedback, JumpTransition
from bellow_ancf_ros.core.loop import paper_circle
from bellow_ancf_ros.core.control._jumps import (CYCLES, KNOWN_MODE_ERROR, KNOWN_RAMP_CYCLES,
                                                 MODE_SPREAD, SETTLE_S)
from bellow_ancf_ros.core.control._stream_heading import STALL_S
from bellow_ancf_ros.core.control._feedback import TRACKING

F = 2.4    # the two-segment model's first mode [Hz]
DT = 0.02  # a 50 Hz stream


def _stream(jt, ts, path):
    out = []
    for t in ts:
        p, z = path(t)
        jt.push(t, p, z)
        out.append(jt.at(t))
    return out


def test_a_held_or_smooth_stream_passes_unchanged():
    jt = JumpTransition(F)
    ts = np.arange(0.0, 4.0, DT)

    def circle(t):   # 10 mm radius at 2 s period: 0.63 mm between targets
        return np.array([0.01 * math.cos(math.pi * t), 0.01 * math.sin(math.pi * t), 0.2]), None
    for t, (p, _) in zip(ts, _stream(jt, ts, circle)):
        np.testing.assert_array_equal(p, circle(t)[0])
    assert jt.moves == 0 and jt.hold_until == -math.inf


def test_a_step_becomes_a_minimum_jerk_move_of_two_slowest_periods():
    jt = JumpTransition(F)
    dur = CYCLES / (MODE_SPREAD * F)
    assert jt.duration_s == pytest.approx(dur)
    a, b = np.array([0.0, 0.0, 0.2]), np.array([0.0, 0.01, 0.2])
    jt.push(0.0, a)
    jt.push(1.0, b)
    assert jt.moves == 1 and jt.hold_until == pytest.approx(1.0 + dur + SETTLE_S)
    np.testing.assert_allclose(jt.at(1.0)[0], a, atol=1e-15)
    np.testing.assert_allclose(jt.at(1.0 + dur / 2)[0], (a + b) / 2, atol=1e-12)
    np.testing.assert_allclose(jt.at(1.0 + dur)[0], b, atol=1e-15)
    ys = np.array([jt.at(t)[0][1] for t in np.linspace(1.0, 1.0 + dur, 200)])
    assert np.all(np.diff(ys) >= 0) and ys.min() >= 0 and ys.max() <= 0.01   # never past it
    assert jt.busy(1.0 + 0.9 * dur) and not jt.busy(1.0 + dur)


def test_the_first_target_after_start_is_a_move_from_where_the_robot_is():
    """reset(start): a first target far from the start pose is a jump; a near one passes."""
    jt = JumpTransition(F)
    start, far = np.array([0.0, 0.0, 0.2]), np.array([0.015, 0.0, 0.19])
    jt.reset((start, None))
    jt.push(3.0, far)
    assert jt.moves == 1 and jt.busy(3.0)
    np.testing.assert_allclose(jt.at(3.0)[0], start, atol=1e-15)
    np.testing.assert_allclose(jt.at(3.0 + jt.duration_s)[0], far, atol=1e-15)
    near = start + np.array([0.001, 0.0, 0.0])
    jt.reset((start, None))
    jt.push(3.0, near)
    assert jt.moves == 1 and not jt.busy(3.0)
    np.testing.assert_array_equal(jt.at(3.0)[0], near)
    jt.reset()   # no start: the first target is taken as it is
    jt.push(5.0, far)
    assert jt.moves == 1 and not jt.busy(5.0)


def _residual(jt, f, zeta=0.0):
    """The swing a mode at ``f`` (damping ratio ``zeta``) keeps after ``jt``'s move of 1."""
    jt.push(0.0, np.zeros(3))
    jt.push(0.0 + 1e-9, np.array([1.0, 0.0, 0.0]))
    dt = 1e-4
    ts = np.arange(0.0, jt.duration_s + 1e-12, dt)
    u = np.array([jt.at(t)[0][0] for t in ts])
    w = 2 * math.pi * f
    # response of x'' = w^2 (u - x) - 2 zeta w x' to the piecewise-linear input, finely
    x, v = 0.0, 0.0
    for k in range(len(ts) - 1):
        a = w * w * (0.5 * (u[k] + u[k + 1]) - x) - 2.0 * zeta * w * v
        v += a * dt
        x += v * dt
    wd = w * math.sqrt(1.0 - zeta * zeta)
    return math.hypot(x - 1.0, (v + zeta * w * (x - 1.0)) / wd)


def test_the_move_leaves_every_mode_of_the_family_nearly_at_rest():
    """An undamped mode at 0.7-1.4x the model's, driven by the move: residual at most 4.1 %."""
    for scale in np.linspace(MODE_SPREAD, 1.4, 15):   # (f T from 2 to 4)
        residual = _residual(JumpTransition(F), F * scale)
        assert residual < 0.042, (scale, residual)


def test_a_measured_mode_gets_a_shorter_move_that_leaves_it_at_rest():
    """dynamics.first_mode_error within 5 %: a ramp of one period, ZV-shaped at the robot's mode.

    The model's mode 2.4 Hz, measured 2 % above the robot's (1/1.02 of it):
    two minimum-jerk ramps of one period of the robot's mode, the second
    half a damped period later (0.62 s in all instead of 1.19 s).  No swing
    is left on the mode, undamped or damped at 0.15 (where a plain
    minimum-jerk move of any such length leaves 2-3 %); a mode 5 % off keeps
    at most 3.9 %.  An error beyond 5 % is not used (the unmeasured move).
    """
    f_robot = F / 1.02

    def known(zeta):
        jt = JumpTransition(mode_error=0.02)
        jt.set_mode(F, zeta)
        return jt
    for zeta in (0.0, 0.15):
        td = 1.0 / (f_robot * math.sqrt(1.0 - zeta * zeta))
        assert known(zeta).duration_s == pytest.approx(KNOWN_RAMP_CYCLES / f_robot + td / 2)
        assert _residual(known(zeta), f_robot, zeta) < 0.002
        for off in (0.95, 1.05):
            assert _residual(known(zeta), f_robot * off, zeta) < 0.040
    assert known(0.15).duration_s < 0.55 * CYCLES / (MODE_SPREAD * F)
    jt = known(0.15)   # the output: from the start, through the two ramps, to the goal
    jt.push(0.0, np.zeros(3))
    jt.push(1e-9, np.array([1.0, 0.0, 0.0]))
    xs = [jt.at(t)[0][0] for t in np.linspace(0.0, jt.duration_s, 300)]
    assert xs[0] == pytest.approx(0.0, abs=1e-9) and xs[-1] == pytest.approx(1.0)
    assert np.all(np.diff(xs) >= -1e-12)
    odd = JumpTransition(mode_error=0.02)   # a damping ratio a mode check could not give
    odd.set_mode(F, math.nan)
    assert odd.duration_s == known(0.0).duration_s
    far = JumpTransition(F, mode_error=KNOWN_MODE_ERROR + 0.01)
    assert far.duration_s == pytest.approx(CYCLES / (MODE_SPREAD * F))


def test_a_new_jump_during_a_move_starts_where_the_output_is():
    jt = JumpTransition(F)
    jt.push(0.0, np.zeros(3))
    jt.push(0.1, np.array([0.01, 0.0, 0.0]))
    mid = jt.at(0.3)[0]
    jt.push(0.3, np.array([0.0, 0.01, 0.0]))
    np.testing.assert_allclose(jt.at(0.3)[0], mid, atol=1e-15)   # continuous
    assert jt.moves == 2
    np.testing.assert_allclose(jt.at(0.3 + jt.duration_s)[0], [0.0, 0.01, 0.0], atol=1e-15)


def test_no_move_before_the_mode_is_known_and_a_z_axis_jump_is_one():
    jt = JumpTransition()
    jt.push(0.0, np.zeros(3))
    jt.push(0.02, np.array([0.01, 0.0, 0.0]))
    np.testing.assert_array_equal(jt.at(0.02)[0], [0.01, 0.0, 0.0])
    jt.set_mode(F)
    z0, z1 = np.array([0.0, 0.0, 1.0]), np.array([math.sin(0.1), 0.0, math.cos(0.1)])
    jt.push(0.04, np.array([0.01, 0.0, 0.0]), z0)
    jt.push(0.06, np.array([0.01, 0.0, 0.0]), z1)   # 5.7 deg: a jump of the z-axis
    _, z = jt.at(0.06 + jt.duration_s / 2)
    assert jt.moves == 1 and z == pytest.approx(((z0 + z1) / np.linalg.norm(z0 + z1)))
    with pytest.raises(ValueError, match='frequency > 0'):
        jt.set_mode(0.0)


def test_the_feedback_holds_its_correction_through_a_move():
    fb = IntegralFeedback(FeedbackSettings(gain_per_s=5.0))
    target = np.array([0.0, 0.0, 0.2])
    for k in range(10):   # a constant 1 mm error is integrated
        t = 0.02 * k
        fb.measurement(t, target + [0.001, 0.0, 0.0])
        fb.corrected_target(t, target)
    c = fb.correction_m.copy()
    assert np.linalg.norm(c) > 0
    for k in range(10, 20):   # the same error during a move: held, state MOVING
        t = 0.02 * k
        fb.measurement(t, target + [0.005, 0.0, 0.0])
        fb.corrected_target(t, target, hold_until=0.5)
        assert fb.state.startswith('holding the correction: a move of its own') and fb.frozen
    np.testing.assert_array_equal(fb.correction_m, c)
    for k in range(26, 30):   # captured after it: integrated again
        t = 0.02 * k
        fb.measurement(t, target + [0.001, 0.0, 0.0])
        fb.corrected_target(t, target, hold_until=0.5)
    assert np.linalg.norm(fb.correction_m) > np.linalg.norm(c)


def test_a_hold_the_caller_cuts_short_ends_then():
    """A stopped stream's brake holds the correction; a target after a late send ends the hold.

    The caller's ``hold_until`` is taken as it is each time, also when it is
    earlier than before (a brake cut short by a target that moves on).
    """
    fb = IntegralFeedback(FeedbackSettings(gain_per_s=5.0))
    target = np.array([0.0, 0.0, 0.2])
    for k in range(10):
        fb.measurement(0.02 * k, target + [0.001, 0.0, 0.0])
        fb.corrected_target(0.02 * k, target)
    c = fb.correction_m.copy()
    fb.measurement(0.2, target + [0.001, 0.0, 0.0])
    fb.corrected_target(0.2, target, hold_until=0.6)      # a brake to 0.6 s
    assert fb.state.startswith('holding the correction: a move of its own')
    np.testing.assert_array_equal(fb.correction_m, c)
    fb.measurement(0.24, target + [0.001, 0.0, 0.0])
    fb.corrected_target(0.24, target, hold_until=0.22)    # the stream came back at 0.22 s
    assert fb.state == TRACKING and np.linalg.norm(fb.correction_m) > np.linalg.norm(c)


def test_a_late_target_of_a_smooth_stream_is_no_jump():
    """One 50 Hz target 25 ms late on the two-segment circle at 10x: 2.1 mm past one step.

    (A busy computer: the step is scaled to the targets' times.)
    """
    path = paper_circle(load_robot('two_segment'), 2.0)
    jt = JumpTransition(2.4)
    for t in list(np.arange(0.0, 1.0, 0.02)) + list(np.arange(1.025, 2.0, 0.02)):
        jt.push(t, *path(t))
    assert jt.moves == 0
    jt.push(2.02, path(2.0)[0] + [0.0, 0.005, 0.0], path(2.0)[1])   # a real jump still is one
    assert jt.moves == 1


@pytest.mark.parametrize('stall_s', [0.1, 0.2, 0.3])
def test_a_stalled_stream_is_no_jump_and_a_step_after_it_is_one(stall_s):
    """A busy computer's stall of the planner (the busy bench saw 104 ms) is not a step.

    On the two-segment circle at 10x, the target after a 0.1 s stall (0.12 s
    after the one before) lies 2.2 mm off the linear heading, more than
    JUMP_M: read as a jump, the next 1.2 s of the circle became a move that
    lagged it by up to 32 mm.  The stream's acceleration allows for it; a
    real step after the stall is still a jump, and a stream silent for
    longer than a stall (it stopped) starts from its last target.
    """
    path = paper_circle(load_robot('two_segment'), 2.0)
    jt = JumpTransition(2.4)
    ts = list(np.arange(0.0, 1.0, 0.02)) + list(np.arange(1.0 + stall_s, 2.0, 0.02))
    for t in ts:
        jt.push(t, *path(t))
    assert jt.moves == 0
    if stall_s == 0.1:   # what the linear heading alone missed by
        p0, p1, p2 = (path(t)[0] for t in (0.96, 0.98, 1.1))
        assert np.linalg.norm(p2 - (p1 + 6.0 * (p1 - p0))) == pytest.approx(2.2e-3, abs=1e-4)
    t = ts[-1] + 0.02
    jt.push(t, path(t)[0] + [0.0, 0.005, 0.0], path(t)[1])   # a real jump still is one
    assert jt.moves == 1
    t_back = t + STALL_S + 0.1      # stopped, then the path again: 50 mm on, a new start
    jt.push(t_back, *path(t_back))
    assert jt.moves == 2


def _lab_sends(seed, late_p=0.03, late_max=0.04, n=150):
    """A lab's planner on a busy computer: ``(stamp, tick time)`` of each target sent.

    Ticks at 50 Hz, each pose the path at its tick, stamped when sent:
    0.5 ms late on average, one in ``1 / late_p`` 3 ms to ``late_max`` late;
    a tick whose time passed before the send before it is skipped (a ROS
    timer).  (The busy bench measured 0.4 ms median, 5.8-8.1 ms p99 and up to
    187 ms.)
    """
    rng = np.random.default_rng(seed)
    late = rng.exponential(5e-4, n)
    tail = rng.random(n) < late_p
    late[tail] = rng.uniform(3e-3, late_max, tail.sum())
    sends, k = [], 0
    while k < n:
        stamp = k * DT + late[k]
        sends.append((stamp, k * DT))
        k = max(k + 1, math.ceil(stamp / DT))
    return sends


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_targets_stamped_late_when_sent_are_no_jump(seed):
    """A planner's poses on its timer, stamped when sent, some sends up to 40 ms late.

    A late send's stamp puts the stream's last step off its time: the target
    after it (on time, some ticks on) lay 2.7-3.4 mm off the heading by the
    stamps, and 6-14 such false jumps in 7 s turned the two-segment circle at
    10x into moves (simulated closed loop: 6.7-24 mm RMSE; 0.75 mm without
    late sends).  By the stamps' grid, and the heading of the targets before
    a late one, none is a jump; a real step among them still is one.
    """
    path = paper_circle(load_robot('two_segment'), 2.0)
    jt = JumpTransition(2.4)
    sends = _lab_sends(seed)
    assert max(s - t for s, t in sends) > 0.02       # (some sends later than a whole tick)
    for stamp, t in sends:
        jt.push(stamp, *path(t))
    assert jt.moves == 0
    stamp, t = sends[-1]
    jt.push(stamp + 0.02, path(t + 0.02)[0] + [0.0, 0.0, 0.005], path(t + 0.02)[1])
    assert jt.moves == 1
