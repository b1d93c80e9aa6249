"""Tests of the integral feedback law (core/feedback.py), closed around the simulated robot.

The loop of the ROS pipeline without ROS: a control step every 50 ms (inverse
kinetostatics on the default model, warm-started), physics every 20 ms
(regulators, equilibrium of the mismatched robot), motion capture every
10 ms (0.15 mm noise unless a test says otherwise), in simulated time.
"""

import math

import numpy as np

from bellow_ancf_ros.core.geometry import rotation_between, rotation_from_vector
import pytest

from bellow_ancf_ros.core import solve_forward, solve_inverse
from bellow_ancf_ros.core.sim import PlantEffects
from bellow_ancf_ros.core.control._feedback import (
    NO_TARGET,
    OUTLIER,
    SATURATED,
    STALE,
    TRACKING,
    WAITING,
    FeedbackSettings,
    IntegralFeedback,
)
from bellow_ancf_ros.core.control import MismatchTransfer, loop_margins
from bellow_ancf_ros.core.sim._simulated_robot import SimulatedRobot

CTRL_S, PHYS_S, MOCAP_S = 0.05, 0.02, 0.01
IDEAL = PlantEffects.ideal()           # the clean robot: the law's basics
EXACT = PlantEffects.ideal(position_noise_m=0.0, angle_noise_rad=0.0)


class Loop:
    """Controller (model + optional feedback) closed around a simulated robot."""

    def __init__(self, model, robot, feedback=None):
        self.model, self.robot, self.fb = model, robot, feedback
        self.t = 0.0
        self.inv = None
        self.measuring = True
        self.corrupt = None          # callable(position) -> position, for one sample
        self.handed = None           # last target handed to the inverse
        self.pressures = []

    def control(self, pos, z):
        if self.fb is not None:
            pc, zc = self.fb.corrected_target(self.t, pos, z)
        else:
            pc, zc = pos, z
        self.handed = (pc, zc)
        self.inv = solve_inverse(self.model, pc, zc, warm_start=self.inv)
        fw = self.inv.forward
        assert fw is not None and fw.converged
        if self.fb is not None:
            self.fb.report(self.inv.reachable, bool(np.any(self.inv.active_limits)),
                           fw.position, fw.z_axis)
        p = self.inv.pressures_pa
        assert np.all(np.isfinite(p))
        assert np.all(p >= self.model.cfg.p_min) and np.all(p <= self.model.cfg.p_max)
        self.pressures.append(p)
        self.robot.command(p)

    def run(self, duration, pos, z=None):
        """Hold target ``(pos, z)`` for ``duration`` s; returns the measured samples."""
        samples = []
        n = int(round(duration / MOCAP_S))
        for i in range(n):
            if i % int(round(CTRL_S / MOCAP_S)) == 0:
                self.control(pos, z)
            if i % int(round(PHYS_S / MOCAP_S)) == 0:
                self.robot.step(PHYS_S)
            self.t += MOCAP_S
            if self.measuring:
                mp, mR = self.robot.measure()
                if self.corrupt is not None:
                    mp, self.corrupt = self.corrupt(mp), None
                samples.append((mp, mR[:, 2]))
                if self.fb is not None:
                    self.fb.measurement(self.t, mp, mR[:, 2])
        return samples

    def true_error(self, pos, z=None):
        p, R = self.robot.true_pose()
        ang = None if z is None else math.degrees(np.linalg.norm(rotation_between(R[:, 2], z)))
        return np.linalg.norm(p - pos), ang


def reachable_target(model, pressures):
    fw = solve_forward(model, pressures)
    return fw.position, fw.z_axis


@pytest.fixture
def loop1(one):
    def make(feedback=True, noise=True, payload=None, settings=None):
        robot = SimulatedRobot('one_segment_mismatched', seed=7, payload_kg=payload,
                               effects=IDEAL if noise else EXACT)
        fb = IntegralFeedback(settings, use_orientation=False) if feedback else None
        return Loop(one, robot, fb)
    return make


# ------------------------------------------------------------------ held targets
def test_feedforward_misses_and_integral_converges_one_segment(loop1, one):
    target, _ = reachable_target(one, [70e3, 10e3, -30e3])
    ff = loop1(feedback=False)
    ff.run(1.5, target)
    ff_err, _ = ff.true_error(target)
    assert ff_err > 1.0e-3, 'the mismatched robot must miss under feedforward'
    cl = loop1(feedback=True)
    samples = cl.run(3.0, target)
    err, _ = cl.true_error(target)
    assert err < 0.2e-3, f'true steady-state error {err * 1e3:.3f} mm'
    # what the motion capture sees: mean over the last second within 0.3 mm
    mean_meas = np.mean([s[0] for s in samples[-100:]], axis=0)
    assert np.linalg.norm(mean_meas - target) <= 0.3e-3
    assert cl.fb.state == TRACKING
    # the correction is the mismatch the integrator learned, bounded by the clamp
    assert 0.5 * ff_err < np.linalg.norm(cl.fb.correction_m) <= cl.fb.settings.max_correction_m


def test_integral_converges_two_segments_position_and_axis(two):
    robot = SimulatedRobot('two_segment_mismatched', seed=11, effects=IDEAL)
    fb = IntegralFeedback(use_orientation=True)
    loop = Loop(two, robot, fb)
    target, z = reachable_target(two, [60e3, 20e3, 0.0, 10e3, 40e3, 20e3])
    samples = loop.run(3.0, target, z)
    err, ang = loop.true_error(target, z)
    assert err <= 0.5e-3 and ang <= 0.5, (err * 1e3, ang)
    mean_p = np.mean([s[0] for s in samples[-100:]], axis=0)
    mean_z = np.mean([s[1] for s in samples[-100:]], axis=0)
    assert np.linalg.norm(mean_p - target) <= 0.5e-3
    assert math.degrees(np.linalg.norm(rotation_between(mean_z, z))) <= 0.5
    ff = Loop(two, SimulatedRobot('two_segment_mismatched', seed=11, effects=IDEAL))
    ff.run(1.0, target, z)
    ff_err, ff_ang = ff.true_error(target, z)
    assert ff_err > 2e-3 and ff_ang > 0.5   # feedforward alone is far off


def test_noise_does_not_destabilise_and_averages_out(loop1, one):
    target, _ = reachable_target(one, [40e3, 60e3, 0.0])
    cl = loop1(feedback=True, noise=True)
    cl.run(2.5, target)
    corrections = []
    for _ in range(10):
        cl.run(0.1, target)
        corrections.append(cl.fb.correction_m.copy())
    # jitter of the learned correction over 1 s: far below the noise of one sample
    assert np.max(np.std(corrections, axis=0)) < 0.05e-3
    assert cl.true_error(target)[0] < 0.15e-3


# ------------------------------------------------------------------ outage and jumps
def test_measurement_outage_holds_the_correction_and_resumes_without_a_jump(loop1, one):
    target, _ = reachable_target(one, [70e3, 10e3, -30e3])
    cl = loop1(feedback=True)
    cl.run(2.5, target)
    normal = np.abs(np.diff(np.array(cl.pressures[-20:]), axis=0)).max()   # noise moves these
    cl.measuring = False
    cl.run(0.06, target)   # the next control step integrates the last sample, once
    c_held = cl.fb.correction_m.copy()
    cl.run(cl.fb.settings.measured_pose_timeout_s + 0.2, target)
    assert cl.fb.state == STALE and not cl.fb.fallback and cl.fb.frozen
    np.testing.assert_array_equal(cl.fb.correction_m, c_held)      # integrator frozen
    np.testing.assert_allclose(cl.handed[0], target + c_held)      # and still applied
    assert cl.true_error(target)[0] < 0.2e-3                       # the robot stays put
    cl.measuring = True
    n = len(cl.pressures)
    cl.run(2.0, target)
    assert cl.fb.state == TRACKING
    assert cl.true_error(target)[0] < 0.2e-3   # with 0.15 mm measurement noise
    # no catch-up: the commands after the return move no more than before the outage
    steps = np.abs(np.diff(np.array(cl.pressures[n - 1:n + 10]), axis=0)).max()
    assert steps <= 1.5 * normal, f'{steps:.0f} Pa against {normal:.0f} Pa'


def test_an_outlier_is_ignored_and_moves_no_command(loop1, one):
    target, _ = reachable_target(one, [70e3, 10e3, -30e3])
    cl = loop1(feedback=True, noise=False)
    cl.run(2.0, target)
    cl.corrupt = lambda p: p + np.array([0.02, 0.0, 0.0])   # a 20 mm swapped marker
    cl.run(0.01, target)   # a control step, then the outlier arrives
    assert cl.fb.rejected == 1
    c_before = cl.fb.correction_m.copy()
    p_before = cl.pressures[-1].copy()
    cl.run(0.01, target)   # a control step sees it: correction held and applied
    assert cl.fb.state == OUTLIER and cl.fb.frozen
    np.testing.assert_allclose(cl.handed[0], target + c_before)
    np.testing.assert_array_equal(cl.fb.correction_m, c_before)
    assert np.max(np.abs(cl.pressures[-1] - p_before)) < 1.0   # Pa: the command stands
    cl.run(1.0, target)
    assert cl.fb.rejected == 1 and cl.fb.state == TRACKING   # the next sample is accepted
    assert cl.true_error(target)[0] < 0.1e-3


def test_a_lasting_change_of_the_measurements_is_accepted_after_a_few_samples():
    fb = IntegralFeedback()
    p = np.array([0.01, 0.0, 0.1])
    for i in range(5):
        assert fb.measurement(0.01 * i, p)
    shifted = p + np.array([0.0, 0.02, 0.0])   # the robot really is elsewhere now
    accepted = [fb.measurement(0.05 + 0.01 * i, shifted) for i in range(5)]
    assert accepted == [False, False, False, True, True]   # the median moved after three


def test_a_target_jump_keeps_the_correction_turned_to_the_new_azimuth():
    """The correction is the robot's mismatch, valid across the workspace: a jump keeps it."""
    fb = IntegralFeedback(FeedbackSettings(gain_per_s=1.0))
    a, b = np.array([0.02, 0.0, 0.1]), np.array([0.0, 0.03, 0.09])   # b: 90 deg further
    for i in range(21):
        t = 0.05 * i
        fb.measurement(t, a - np.array([0.001, 0.0, 0.0]))
        fb.corrected_target(t, a)
    c = fb.correction_m.copy()
    assert np.linalg.norm(c) > 0.5e-3
    p, _ = fb.corrected_target(1.01, b)   # no new measurement since the last step
    assert p == pytest.approx(b + np.array([-c[1], c[0], c[2]]), abs=1e-12)


def test_the_loop_converges_after_a_large_target_jump(loop1, one):
    a, _ = reachable_target(one, [70e3, 10e3, -30e3])
    b, _ = reachable_target(one, [-20e3, 60e3, 90e3])
    assert np.linalg.norm(a - b) > 0.01
    cl = loop1(feedback=True, noise=False)
    cl.run(2.0, a)
    assert np.linalg.norm(cl.fb.correction_m) > 1e-3
    cl.run(3.05, b)
    assert cl.true_error(b)[0] < 0.1e-3


# ------------------------------------------------------------------ limits
def test_unreachable_target_keeps_correction_bounded_then_converges(loop1, one):
    reach, _ = reachable_target(one, [70e3, 10e3, -30e3])
    cl = loop1(feedback=True)
    cl.run(2.0, reach)
    far = reach + np.array([0.03, 0.0, 0.0])     # 30 mm further out: beyond the workspace
    cl.run(2.0, far)
    assert cl.fb.state == SATURATED and not cl.inv.reachable
    assert np.linalg.norm(cl.fb.correction_m) <= cl.fb.settings.max_correction_m + 1e-12
    cl.run(3.0, reach)
    assert cl.fb.state == TRACKING and cl.inv.reachable
    assert cl.true_error(reach)[0] < 0.2e-3
    # every pressure of the run was finite and in the limits (checked in Loop.control)
    assert len(cl.pressures) > 100


def test_unreachable_by_a_little_winds_nothing_up(loop1, one):
    """A target just outside the workspace: the correction stays bounded, no creeping."""
    edge = solve_forward(one, [150e3, -50e3, -50e3]).position
    target = edge + np.array([0.002, 0.0, 0.0])
    cl = loop1(feedback=True, noise=False)
    cl.run(2.0, target)
    c1 = np.linalg.norm(cl.fb.correction_m)
    cl.run(2.0, target)
    c2 = np.linalg.norm(cl.fb.correction_m)
    assert c2 <= c1 + 1e-6 and c2 <= cl.fb.settings.max_correction_m


# ------------------------------------------------------------------ payload
def test_unknown_payload_is_corrected(loop1, one):
    target, _ = reachable_target(one, [70e3, 10e3, -30e3])
    cl = loop1(feedback=True, noise=False)
    cl.run(2.0, target)
    cl.robot.set_payload(0.05)       # the robot carries 50 g the model does not know
    cl.run(0.3, target)
    assert cl.true_error(target)[0] > 0.2e-3
    cl.run(3.0, target)
    assert cl.true_error(target)[0] < 0.1e-3


# ------------------------------------------------------------------ the law alone
def test_no_command_freezes_the_integrator_until_an_answer_goes_out():
    """A failed solve sends nothing: the error then says nothing about the correction.

    Regression (payload beyond the buckling load): the integrator kept
    integrating while no command went out and wound up to its clamp.
    """
    fb = IntegralFeedback(FeedbackSettings(gain_per_s=2.0))
    target = np.array([0.0, 0.0, 0.1])
    offset = np.array([2e-3, 0.0, 0.0])      # the robot stays 2 mm off: nothing moves it
    t = 0.0
    for _ in range(50):                       # 0.5 s of normal integration
        fb.measurement(t, target + offset)
        t += 0.01
        fb.corrected_target(t, target)
        fb.report(True, False)
    # the first failed solve: its correction was integrated before the failure was known
    fb.measurement(t, target + offset)
    t += 0.01
    fb.corrected_target(t, target)
    fb.no_command()
    held = fb.correction_m.copy()
    assert np.linalg.norm(held) > 0.1e-3
    for _ in range(300):                      # 3 s more of failed solves
        fb.measurement(t, target + offset)
        t += 0.01
        handed, _ = fb.corrected_target(t, target)
        fb.no_command()
        np.testing.assert_allclose(handed, target + held)   # the held correction still applies
    assert fb.state == 'frozen: no command went out for the corrected target'
    np.testing.assert_array_equal(fb.correction_m, held)
    fb.report(True, False)                    # an answer went out again: integration resumes
    fb.measurement(t, target + offset)
    t += 0.01
    fb.corrected_target(t, target)
    assert np.linalg.norm(fb.correction_m) > np.linalg.norm(held)
    # resumes without a catch-up step: one step of dt 0.01 at most
    assert np.linalg.norm(fb.correction_m - held) <= 2.0 * 0.01 * 2e-3 + 1e-12


def test_integral_law_against_a_constant_offset_plant():
    """Plant = target + offset: the correction converges to -offset at rate gain_per_s."""
    s = FeedbackSettings(gain_per_s=2.0)
    fb = IntegralFeedback(s)
    offset = np.array([1e-3, -2e-3, 0.5e-3])
    target = np.array([0.0, 0.0, 0.1])
    t, handed = 0.0, target
    for _ in range(200):             # 2 s in 10 ms steps
        fb.measurement(t, handed + offset)
        t += 0.01
        handed, _ = fb.corrected_target(t, target)
        fb.report(True, False)
    expected = -offset * (1 - (1 - 0.02) ** 199)   # discrete integrator, k dt = 0.02
    np.testing.assert_allclose(fb.correction_m, expected, rtol=1e-2)


def test_settings_are_validated():
    with pytest.raises(ValueError, match='gain_per_s'):
        FeedbackSettings(gain_per_s=-1.0)
    with pytest.raises(ValueError, match='measured_pose_timeout_s'):
        FeedbackSettings(measured_pose_timeout_s=float('nan'))
    with pytest.raises(ValueError, match="correction_frame: 'tool'"):
        FeedbackSettings(correction_frame='tool')


def test_rotation_error_takes_one_axis_to_the_other():
    a = np.array([0.1, 0.2, 1.0])
    b = np.array([-0.2, 0.1, 0.9])
    r = rotation_between(a, b)
    np.testing.assert_allclose(rotation_from_vector(r) @ (a / np.linalg.norm(a)),
                               b / np.linalg.norm(b), atol=1e-12)
    np.testing.assert_array_equal(rotation_between(a, a), np.zeros(3))


def test_delayed_measurements_are_compared_with_the_target_then():
    """A perfect plant seen 0.2 s late on a moving target: no spurious correction.

    Compared with the newest target, the delay would look like an error of
    speed * delay (2 mm here) and the integrator would lead the target by it.
    """
    fb = IntegralFeedback(FeedbackSettings(gain_per_s=3.0))
    speed = np.array([0.01, 0.0, 0.0])          # 10 mm/s
    delay = 0.2
    handed = []
    t = 0.0
    for _ in range(300):                        # 3 s, 10 ms steps
        target = np.array([0.0, 0.0, 0.1]) + speed * t
        p, _ = fb.corrected_target(t, target)
        fb.report(True, False)
        handed.append((t, p))
        past = [h for h in handed if h[0] <= t - delay]
        if past:
            fb.measurement(past[-1][0], past[-1][1])   # taken then, arrives now
        t += 0.01
    assert np.linalg.norm(fb.correction_m) < 1e-9
    assert fb.state == TRACKING


# ------------------------------------------------------------------ stability margins
def test_loop_margins_analytic_cases():
    k, T, tau = 2.5, 0.05, 0.06
    m = loop_margins(k, 0.0, T)                     # pure delay: closed forms
    assert m.phase_margin_deg == pytest.approx(90.0 - math.degrees(k * T))
    assert m.gain_margin == pytest.approx(math.pi / (2 * k * T))
    m = loop_margins(k, tau, 0.0)                   # lag only: never unstable
    assert m.gain_margin == math.inf
    assert m.crossover_rad_s * math.hypot(1.0, m.crossover_rad_s * tau) == pytest.approx(k)
    m = loop_margins(k, tau, T)
    assert 70.0 < m.phase_margin_deg < 80.0 and 8.0 < m.gain_margin < 10.0
    with pytest.raises(ValueError, match='gain_per_s'):
        loop_margins(0.0, tau, T)


@pytest.mark.parametrize('factor, grows', [(0.9, False), (1.1, True)])
def test_loop_margins_predict_the_stability_limit_in_time(factor, grows):
    """Integrator -> delay -> first-order lag, simulated: it oscillates past max_gain."""
    tau, T, dt = 0.06, 0.05, 1e-4
    k = factor * loop_margins(1.0, tau, T).max_gain_per_s
    n_delay = int(round(T / dt))
    c = np.zeros(int(8.0 / dt) + n_delay)
    x = 0.0
    late = []
    for i in range(n_delay, len(c) - 1):
        x += dt * (c[i - n_delay] - x) / tau
        c[i + 1] = c[i] + dt * k * (1.0 - x)
        if i * dt > 6.0:
            late.append(abs(1.0 - x))
    early_amp = 1.0
    assert (max(late) > early_amp) == grows


def test_targets_are_interpolated_at_the_capture_time():
    """Targets every 20 ms on a moving line, a perfect robot sampled between them: no error.

    Compared with the last target before each capture (a step function), the
    robot would look 0.1 mm behind on average (5 mm/s, 10 ms) and the
    integrator would lead the target by that.
    """
    fb = IntegralFeedback(FeedbackSettings(gain_per_s=5.0, correction_frame='base'))
    speed = np.array([0.005, 0.0, 0.0])
    start = np.array([0.01, 0.0, 0.1])
    t = 0.0
    for i in range(200):                       # 4 s of 50 Hz control, mocap at 7 ms offsets
        fb.measurement(t - 0.013, start + speed * (t - 0.013))
        fb.corrected_target(t, start + speed * t)
        fb.report(True, False)
        t += 0.02
    assert np.linalg.norm(fb.correction_m) < 1e-9


def test_a_shifted_command_is_corrected_but_the_pose_wanted_is_measured_against():
    """Dynamic feedforward shifts the command; the loop measures against the pose wanted.

    A robot exactly at the pose wanted leaves no correction (it is not pulled
    onto the shifted command), and the shift is handed on.
    """
    fb = IntegralFeedback(FeedbackSettings(gain_per_s=5.0, correction_frame='base'))
    wanted = np.array([0.01, 0.0, 0.2])
    shift = np.array([0.0, 0.002, 0.0])
    for k in range(50):
        t = 0.02 * k
        fb.measurement(t, wanted)
        p, _ = fb.corrected_target(t, wanted, command=(wanted + shift, None))
    np.testing.assert_allclose(fb.correction_m, 0.0, atol=1e-15)
    np.testing.assert_allclose(p, wanted + shift)
    # measured 1 mm short of the pose wanted: the correction grows towards it, on the command
    for k in range(50, 100):
        t = 0.02 * k
        fb.measurement(t, wanted - np.array([0.001, 0.0, 0.0]))
        p, _ = fb.corrected_target(t, wanted, command=(wanted + shift, None))
    assert fb.correction_m[0] > 0.5e-3 and abs(fb.correction_m[1]) < 1e-12
    np.testing.assert_allclose(p, wanted + shift + fb.correction_m)


def test_a_jump_carries_the_correction_to_its_goal_along_the_move(one):
    """The transfer's correction is reached with the goal, in proportion to the way there.

    Asked once per move, from the answer of the last command that went out
    and the model's answer for the goal with the correction as it was, then
    again (:data:`CARRY_AGAIN` times) with the model's answer for the goal
    with the correction carried; none before a command's answer was reported.
    """
    from bellow_ancf_ros.core.control._feedback import CARRY_AGAIN
    c_old, c_goal = np.array([1e-3, 0.0, 0.0]), np.array([2e-3, 1e-3, 0.0])
    calls, agains = [], []

    class Transfer:
        model = one

        def transfer(self, held, c, r, new):
            calls.append((held, c.copy(), new.position.copy()))
            return c_goal, None

        def again(self, new):
            agains.append(new.position.copy())
            return c_goal, None

    fb = IntegralFeedback(FeedbackSettings(correction_frame='base'), transfer=Transfer())
    a = solve_forward(one, [30e3, 0.0, 0.0]).position
    b = a + np.array([0.0, 0.01, 0.0])
    fb.measurement(0.0, a)
    fb.corrected_target(0.0, a)
    fb.correction_m = c_old
    fb.corrected_target(0.5, a, move=(0.5, a, b, None), hold_until=2.0)
    assert calls == []                       # no command's answer yet: nothing to carry from
    inv = solve_inverse(one, a + c_old)
    fb.report(True, False, inv.forward.position, inv.forward.z_axis, inverse=inv)
    move = (1.0, a, b, None)
    p, _ = fb.corrected_target(1.0, a, move=move, hold_until=3.0)
    assert p == pytest.approx(a + c_old, abs=1e-12)
    assert len(calls) == 1 and calls[0][0] is inv.forward
    assert calls[0][2] == pytest.approx(b + c_old, abs=1e-8)   # the goal, corrected as it was
    assert len(agains) == CARRY_AGAIN    # then the goal, corrected as carried, asked again
    for got in agains:
        assert got == pytest.approx(b + c_goal, abs=1e-8)
    p, _ = fb.corrected_target(1.5, 0.5 * (a + b), move=move, hold_until=3.0)
    assert p == pytest.approx(0.5 * (a + b) + 0.5 * (c_old + c_goal), abs=1e-12)
    p, _ = fb.corrected_target(2.0, b, move=move, hold_until=3.0)
    assert p == pytest.approx(b + c_goal, abs=1e-12)
    fb.corrected_target(2.1, b, move=move, hold_until=3.0)
    assert len(calls) == 1                   # one move, one transfer
    assert fb.status(2.1)['feedback_carries'] == 1 and fb.status(2.1)['feedback_carries_cut'] == 0


def test_a_carry_whose_solve_runs_out_of_its_budget_is_counted(one, monkeypatch):
    """The status counts the carries whose goal solve ran out of its wall-clock budget."""
    import bellow_ancf_ros.core.control._feedback as feedback_module
    monkeypatch.setattr(feedback_module, 'CARRY_BUDGET_S', 1e-9)
    fb = IntegralFeedback(FeedbackSettings(correction_frame='model'),
                          transfer=MismatchTransfer(one))
    a = solve_forward(one, [30e3, 0.0, 0.0]).position
    fb.measurement(0.0, a)
    fb.corrected_target(0.0, a)
    fb.correction_m = np.array([1e-3, 0.0, 0.0])
    inv = solve_inverse(one, a + fb.correction_m)
    fb.report(True, False, inv.forward.position, inv.forward.z_axis, inverse=inv)
    fb.corrected_target(1.0, a, move=(1.0, a, a + [0.0, 0.01, 0.0], None), hold_until=3.0)
    st = fb.status(1.0)
    assert st['feedback_carries'] == 1 and st['feedback_carries_cut'] == 1


def test_a_carried_correction_stays_within_its_share_of_the_move(one):
    """A transfer that asks for much more is held to CARRY_SHARE of the move's length."""
    from bellow_ancf_ros.core.control._feedback import CARRY_SHARE

    class Transfer:
        model = one

        def transfer(self, held, c, r, new):
            return c + np.array([0.0, -0.02, 0.0]), None   # 20 mm: a fit gone wrong

        def again(self, new):
            return self.transfer(None, c_old, None, new)

    fb = IntegralFeedback(FeedbackSettings(correction_frame='base'), transfer=Transfer())
    a = solve_forward(one, [30e3, 0.0, 0.0]).position
    b = a + np.array([0.0, 0.01, 0.0])
    c_old = np.array([1e-3, 0.0, 0.0])
    fb.measurement(0.0, a)
    fb.corrected_target(0.0, a)
    fb.correction_m = c_old
    inv = solve_inverse(one, a + c_old)
    fb.report(True, False, inv.forward.position, inv.forward.z_axis, inverse=inv)
    move = (1.0, a, b, None)
    fb.corrected_target(1.0, a, move=move, hold_until=3.0)
    p, _ = fb.corrected_target(2.0, b, move=move, hold_until=3.0)
    assert p - b == pytest.approx(c_old + [0.0, -CARRY_SHARE * 0.01, 0.0], abs=1e-12)


def test_measured_poses_before_any_target_say_so():
    """Measured poses arrive, no target yet (refused, none sent): not "waiting for measured_pose".

    A lab-style trial's heartbeat said "feedback without measured poses:
    waiting for measured_pose" while 120 poses a second arrived and its
    targets were refused (a frame the node does not take).
    """
    fb = IntegralFeedback()
    assert fb.state == WAITING and fb.blind
    assert fb.measurement(0.0, [0.0, 0.0, 0.2])
    assert fb.state == NO_TARGET and not fb.blind and fb.measurement_age(0.01) == 0.01
    p, _ = fb.corrected_target(0.02, [0.0, 0.0, 0.2])   # the first target: a control step
    assert fb.state == TRACKING and np.allclose(p, [0.0, 0.0, 0.2])
