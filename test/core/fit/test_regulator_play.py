"""fit_play: the regulators' play band read from a staircase of set-points."""

import numpy as np
import pytest

from bellow_ancf_ros.core.fit import fit_play, play_staircase, staircase_recording
from bellow_ancf_ros.core.sim import PressureRegulators


def _record(width_pa, tau=0.08, dead=0.03, noise_pa=0.0, offset_pa=0.0, hold_s=1.0, seed=0):
    """The staircase sent to a simulated regulator, its sensor sampled at 100 Hz."""
    reg = PressureRegulators(3, -50e3, 150e3, tau, dead_time_s=dead, hysteresis_pa=width_pa)
    times, sent, measured = staircase_recording(
        reg, *play_staircase(10e3, 40e3, steps=5, cycles=2, hold_s=hold_s))
    noise = np.random.default_rng(seed).normal(0.0, noise_pa, size=len(times))
    return times, sent, measured[:, 0] + offset_pa + noise


@pytest.mark.parametrize("width_pa", [0.0, 500.0, 1574.0, 2000.0])
def test_the_play_of_a_simulated_regulator_is_found(width_pa):
    fit = fit_play(*_record(width_pa))
    assert fit.width_pa == pytest.approx(width_pa, abs=5.0)
    # the climb and two cycles: 4 + 4 + 4 continuing steps upwards, 4 + 4 downwards
    assert (fit.holds_up, fit.holds_down) == (12, 8)


def test_sensor_noise_and_offset_leave_the_width():
    fit = fit_play(*_record(1500.0, noise_pa=100.0, offset_pa=700.0, seed=3))
    assert fit.width_pa == pytest.approx(1500.0, abs=4 * fit.std_error_pa + 20.0)
    assert 0.0 < fit.std_error_pa < 60.0


def test_holds_too_short_to_settle_are_refused():
    t, c, m = _record(1000.0, hold_s=0.5)
    with pytest.raises(ValueError, match='settle_s = 0.6'):
        fit_play(t, c, m)


def test_a_vent_resets_the_direction():
    """The hold after a vent (exhaust past the play) does not count."""
    t = np.arange(6) * 1.0 + 0.0
    c = np.array([10e3, 20e3, 0.0, 10e3, 20e3, 30e3])
    times = np.repeat(t, 2) + np.tile([0.0, 0.9], 6)
    cmd = np.repeat(c, 2)
    meas = cmd - 500.0
    fit_kwargs = dict(settle_s=0.5)
    with pytest.raises(ValueError, match='found 1 up and 0 down'):
        fit_play(times, cmd, meas, **fit_kwargs)


@pytest.mark.parametrize("bad,match", [
    (dict(times_s=[0.0, 1.0]), 'at least 3 samples'),
    (dict(measured_pa=[0.0, np.nan, 1.0]), 'finite'),
    (dict(times_s=[0.0, 2.0, 1.0]), 'must increase'),
])
def test_bad_recordings_are_refused_with_the_reason(bad, match):
    args = dict(times_s=[0.0, 1.0, 2.0], command_pa=[0.0, 1.0, 2.0], measured_pa=[0.0, 1.0, 2.0])
    args.update(bad)
    with pytest.raises(ValueError, match=match):
        fit_play(**args)


def test_staircase_levels():
    starts, levels = play_staircase(0.0, 10.0, steps=2, cycles=1, hold_s=0.5)
    assert levels.tolist() == [0.0, 5.0, 10.0, 5.0, 0.0, 5.0, 10.0]
    assert starts.tolist() == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0]
    with pytest.raises(ValueError, match='low_pa < high_pa'):
        play_staircase(1.0, 1.0)
