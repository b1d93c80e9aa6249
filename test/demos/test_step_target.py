"""The step phase's measure of residual swing (demos/step_target.py), without ROS."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.demos.step_target import residual_swing


def test_the_swing_is_measured_through_a_slow_drift():
    t = np.arange(-3.0, 3.0, 1 / 120)
    drift = 1.5e-3 * (1 - np.exp(-np.clip(t, 0, None) / 2.0))      # creep after the step
    swing = 0.2e-3 * np.sin(2 * math.pi * 2.4 * t)
    pos = np.column_stack([0.02 + 0 * t, drift + swing, 0.2 + 0 * t])
    # the quadratic fit over 2.4 cycles takes a little of the swing
    assert residual_swing(t, pos, 1.0, 2.0) == pytest.approx(0.2e-3, rel=0.15)
    still = np.column_stack([0.02 + 0 * t, drift, 0.2 + 0 * t])
    assert residual_swing(t, still, 1.0, 2.0) < 5e-6


def test_too_few_samples_are_refused():
    t = np.linspace(0, 0.1, 3)
    with pytest.raises(ValueError, match='samples'):
        residual_swing(t, np.zeros((3, 3)), 1.0, 2.0)
