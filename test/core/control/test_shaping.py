"""Input shaping of the target stream (core/control/_shaping.py): ZV/ZVD after Singer & Seering."""

import os
import sys

import numpy as np
import pytest

from bellow_ancf_ros.core.control import TargetShaper, shaper_impulses

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..', '..', '..', 'bench'))
import remedies_bench  # noqa: E402  (the bench's runs: one measurement, asserted here)


@pytest.mark.parametrize('kind', ['zv', 'zvd'])
@pytest.mark.parametrize('zeta', [0.0, 0.05, 0.2])
def test_impulses_cancel_the_mode_and_sum_to_one(kind, zeta):
    f = 2.4
    t, a = shaper_impulses(kind, f, zeta)
    assert a.sum() == pytest.approx(1.0) and np.all(a > 0) and t[0] == 0.0
    wd = 2 * np.pi * f * np.sqrt(1 - zeta**2)
    # the impulses' vibrations, A_i exp(-zeta w (t - t_i)) sin(wd (t - t_i)), cancel
    s = zeta * 2 * np.pi * f - 1j * wd
    assert abs(np.sum(a * np.exp(s * t))) < 1e-12
    if kind == 'zvd':   # and its derivative with respect to the frequency
        assert abs(np.sum(a * t * np.exp(s * t))) < 1e-12
    assert t[-1] == pytest.approx((0.5 if kind == 'zv' else 1.0) / (f * np.sqrt(1 - zeta**2)))


def test_stream_shaper_follows_the_mode_and_reports_its_delay():
    sh = TargetShaper('zvd', 2.0, 0.0)
    assert sh.duration_s == pytest.approx(0.5) and sh.delay_s == pytest.approx(0.25)
    sh.push(0.0, [0.0, 0.0, 0.1], [0, 0, 1])
    sh.push(1.0, [0.01, 0.0, 0.1], [0, 0, 1])
    np.testing.assert_allclose(sh.at(0.9)[0], [0.0, 0.0, 0.1])
    np.testing.assert_allclose(sh.at(1.1)[0], [0.0025, 0.0, 0.1])   # 1/4 at once
    np.testing.assert_allclose(sh.at(1.3)[0], [0.0075, 0.0, 0.1])   # 3/4 after half a period
    np.testing.assert_allclose(sh.at(1.6)[0], [0.01, 0.0, 0.1])     # all after a period
    sh.set_mode(1.0, 0.0)                                           # a payload: slower mode
    assert sh.duration_s == pytest.approx(1.0)
    np.testing.assert_allclose(sh.at(1.6)[0], [0.0075, 0.0, 0.1])
    with pytest.raises(ValueError, match="target_shaping = 'zz' is not allowed"):
        TargetShaper('zz')


def test_a_shaped_step_leaves_no_residual_swing():
    """Two segments (the model's own file as the robot: only dynamics), a 10 mm step.

    Unshaped the robot rings (2.4 Hz, zeta 0.05); ZVD at the model's mode
    leaves less than 0.1 mm one second after the step (the runs of
    ``make bench``, bench/remedies_bench.py; 8 s before the step let the
    start's swing die out).
    """
    out = {kind: remedies_bench.step_residual(kind)[0] for kind in ('none', 'zvd')}
    assert out['none'] > 2e-3, out
    assert out['zvd'] < 0.1e-3, out


def test_a_shaped_step_on_the_realistic_mismatched_robot_with_its_play_compensated():
    """The robot's mode 7 % above the model's, 1 kPa of play, creep: ZVD at the model's mode.

    Without the play compensated, the play takes up the first part of each
    actuator's move (an unshaped step of up to 1 kPa inside the shaped one);
    compensated (``regulator_play_kpa``), the swing 1-2 s after the step
    is within 0.1 mm (the runs of ``make bench``).
    """
    name = 'two_segment_mismatched'
    unshaped = remedies_bench.step_residual('none', name)[0]
    compensated = remedies_bench.step_residual('zvd', name, 1e3)[0]
    assert unshaped > 1e-3 and compensated < 0.1e-3, (unshaped, compensated)
