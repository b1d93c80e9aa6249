"""The motion capture's noise read from its samples, and the gain it allows (core, no ROS)."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core.control._feedback import FeedbackSettings, IntegralFeedback
from bellow_ancf_ros.core.control._mocap_noise import (NOISE_BUDGET_M, NOISE_GAIN_FLOOR_PER_S,
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
