"""The motion capture's noise read from its samples, and the gain it allows (core, no ROS)."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core.control._feedback import FeedbackSettings, IntegralFeedback
from bellow_ancf_ros.core.control._mocap_noise import (GATE_NOISE_FACTOR, NOISE_BUDGET_M,
                                                       NOISE_GAIN_FLOOR_PER_S, NOISE_GATE_S,
                                                       MocapNoise)


def _circle(t, radius=0.010, period=2.0):
    """The paper's circle at ten times its speed (the fastest smooth motion of the goals)."""
    w = 2.0 * math.pi / period
    return np.stack([radius * np.cos(w * t), radius * np.sin(w * t), 0.09 + 0.0 * t], axis=1)


@pytest.mark.parametrize('rate_hz', [60.0, 240.0])
@pytest.mark.parametrize('sigma', [0.05e-3, 0.2e-3])
def test_the_noise_of_a_moving_robot_is_read_from_its_samples(rate_hz, sigma):
    """The second difference cancels the circle: the noise is read within 15 %."""
    rng = np.random.default_rng(3)
    t = np.arange(400) / rate_hz
    p = _circle(t) + rng.normal(0.0, sigma, (t.size, 3))
    est = MocapNoise()
    for ti, pi in zip(t, p):
        est.add(ti, pi)
    assert est.sigma_m == pytest.approx(sigma, rel=0.15)
    assert est.rate_hz == pytest.approx(rate_hz, rel=1e-6)


def test_outliers_a_dropout_and_a_step_barely_move_the_estimate():
    rng = np.random.default_rng(4)
    t = np.arange(300) / 100.0
    t[150:] += 0.3                       # a 0.3 s dropout
    p = 0.2e-3 * rng.normal(size=(t.size, 3))
    p[200:, 1] += 0.010                  # a 10 mm step target reached at once
    p[[40, 90, 260], 0] += 0.020         # three swapped markers
    est = MocapNoise()
    for ti, pi in zip(t, p):
        est.add(ti, pi)
    assert est.sigma_m == pytest.approx(0.2e-3, rel=0.2)


def test_the_cap_is_the_gain_whose_noise_meets_the_budget():
    est = MocapNoise()
    assert est.gain_cap() == math.inf and est.sigma_m is None   # nothing known yet
    est.sigma_m, est.rate_hz = 0.27e-3, 66.0
    assert est.gain_cap() == pytest.approx(2 * 66.0 * NOISE_BUDGET_M ** 2 / (3 * 0.27e-3 ** 2))
    assert est.gain_cap() == pytest.approx(1.509, abs=1e-3)
    est.sigma_m, est.rate_hz = 0.05e-3, 120.0      # a quiet motion capture: far above the margins'
    assert est.gain_cap() == pytest.approx(80.0)
    est.sigma_m, est.rate_hz = 1e-3, 30.0          # too noisy for the budget: the floor
    assert est.gain_cap() == NOISE_GAIN_FLOOR_PER_S


def test_an_integral_loop_at_the_cap_moves_the_robot_by_the_budget():
    """The formula's physics: a robot that follows the correction at once, 66 Hz, 50 Hz control.

    The correction integrates the mean error of the samples of each control
    step; at the cap its RMS (3-D) is the budget, within 15 %.
    """
    rng = np.random.default_rng(5)
    sigma, f_m, dt = 0.27e-3, 66.0, 0.02
    est = MocapNoise()
    est.sigma_m, est.rate_hz = sigma, f_m
    k = est.gain_cap()
    c, seen, t_next, out = np.zeros(3), [], 0.0, []
    for i in range(int(400.0 * f_m)):
        t = i / f_m
        while t_next <= t:           # control steps due before this sample
            if seen:
                c = c + k * dt * np.mean(seen, axis=0)
                seen = []
            out.append(np.linalg.norm(c))
            t_next += dt
        seen.append(-c + rng.normal(0.0, sigma, 3))   # target 0: the error is minus the robot
    rms = math.sqrt(np.mean(np.square(out[500:])))
    assert rms == pytest.approx(NOISE_BUDGET_M, rel=0.15)


def test_the_noise_caps_the_automatic_gain_and_not_a_gain_set_by_hand():
    rng = np.random.default_rng(6)
    fixed = IntegralFeedback(FeedbackSettings(gain_per_s=6.0))
    auto = IntegralFeedback(FeedbackSettings())
    auto.set_gain(6.4)
    for i in range(200):
        p = np.array([0.0, 0.0, 0.09]) + rng.normal(0.0, 0.27e-3, 3)
        for fb in (fixed, auto):
            fb.measurement(i / 66.0, p)
    assert fixed.gain_per_s == 6.0
    assert auto.noise.sigma_m == pytest.approx(0.27e-3, rel=0.2)
    assert auto.gain_per_s == pytest.approx(auto.noise.gain_cap()) and auto.gain_per_s < 2.5
    auto.gain_scale = 0.5                                     # the watchdog's cut still applies
    assert auto.gain_per_s == pytest.approx(0.5 * auto.noise.gain_cap())
    st = auto.status(200 / 66.0)
    assert float(st['mocap_noise_mm']) == pytest.approx(auto.noise.sigma_m * 1e3, abs=1e-3)
    assert float(st['noise_gain_cap_per_s']) == pytest.approx(auto.noise.gain_cap(), rel=1e-2)


def _noisy(sigma=0.27e-3, rate_hz=66.0):
    est = MocapNoise()
    est.sigma_m, est.rate_hz = sigma, rate_hz
    return est


def test_the_mean_errors_noise_is_what_an_exponential_mean_of_white_noise_gives():
    rng = np.random.default_rng(3)
    est, dt = _noisy(), 1.0 / 66.0
    a = 1.0 - math.exp(-dt / NOISE_GATE_S)
    m, norms = np.zeros(3), []
    for i in range(40000):
        m = m + a * (rng.normal(0.0, est.sigma_m, 3) - m)
        if i > 500:
            norms.append(np.linalg.norm(m))
    assert math.sqrt(np.mean(np.square(norms))) == pytest.approx(est.mean_error_noise_m(),
                                                                 rel=0.1)


def test_the_cap_holds_an_error_that_is_noise_and_not_one_the_robot_has():
    est = _noisy()
    cap, s = est.gain_cap(), est.mean_error_noise_m()
    assert est.allowed_gain(6.4, None) == cap                      # nothing known: the cap
    assert est.allowed_gain(6.4, 0.0) == cap
    assert est.allowed_gain(6.4, GATE_NOISE_FACTOR * s) == pytest.approx(cap)
    assert est.allowed_gain(6.4, 1.5 * GATE_NOISE_FACTOR * s) == pytest.approx(0.5 * (cap + 6.4))
    assert est.allowed_gain(6.4, 2.0 * GATE_NOISE_FACTOR * s) == pytest.approx(6.4)
    assert est.allowed_gain(6.4, 1e-3) == 6.4
    assert est.allowed_gain(0.8 * cap, 0.0) == 0.8 * cap           # below the cap: as it is
    assert MocapNoise().allowed_gain(6.4, 0.0) == 6.4               # noise unknown: no cap


def _held(offset_m, seconds=6.0, seed=8):
    """An integral loop on a robot off by ``offset_m`` (x), noisy 66 Hz mocap, 100 Hz steps.

    The robot is where the corrected target says plus the offset (a model
    mismatch).  Returns (times [s], error norms [m], gains [1/s]) per step.
    """
    rng = np.random.default_rng(seed)
    fb = IntegralFeedback(FeedbackSettings())
    fb.set_gain(6.4)
    target = np.array([0.0, 0.0, 0.09])
    command = target.copy()
    ts, errs, gains = [], [], []
    n_meas = 0
    for i in range(int(seconds * 100)):
        t = i / 100.0
        while n_meas / 66.0 <= t:
            robot = command + np.array([offset_m if n_meas / 66.0 >= 2.0 else 0.0, 0.0, 0.0])
            fb.measurement(n_meas / 66.0, robot + rng.normal(0.0, 0.27e-3, 3))
            n_meas += 1
        command, _ = fb.corrected_target(t, target)
        fb.report(True, False)
        ts.append(t)
        errs.append(np.linalg.norm(command + [offset_m if t >= 2.0 else 0.0, 0, 0] - target))
        gains.append(fb.gain_per_s)
    return np.array(ts), np.array(errs), np.array(gains)


def test_a_real_error_is_corrected_at_the_full_gain_and_noise_held_at_the_cap():
    """A 1 mm mismatch from 2 s on: corrected at about the full gain, then held at the cap.

    The cap alone (1.5 /s) would take 1.5 s to bring 1 mm to 0.1 mm; the
    full gain (6.4 /s) 0.36 s.
    """
    t, err, gain = _held(1e-3)
    cap = 2 * 66.0 * NOISE_BUDGET_M ** 2 / (3 * 0.27e-3 ** 2)
    assert np.all(gain[(t > 1.5) & (t < 2.0)] < 1.3 * cap)          # noise only: about the cap
    assert gain[(t > 2.0) & (t < 2.2)].max() == pytest.approx(6.4)  # the mismatch: all of it
    within = t[(t > 2.0) & (err < 0.1e-3)][0] - 2.0
    assert within < 1.0   # (the cap alone: 1.53 s)
    assert np.median(gain[t > 4.0]) < 1.3 * cap                     # corrected: the cap again
    held = np.sqrt(np.mean(np.square(err[t > 4.0])))
    assert held < 2 * NOISE_BUDGET_M
