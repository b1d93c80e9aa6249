"""The backlash inverse of the regulators' play (core/control/_play.py)."""

import numpy as np
import pytest

from bellow_ancf_ros.core.sim import PressureRegulators
from bellow_ancf_ros.core.control import PlayCompensation


def _valves(width, commands):
    """Where a play operator of ``width`` leaves the valves after each command (the plant's)."""
    reg = PressureRegulators(len(commands[0]), 0.0, 100e3, time_constant_s=0.0,
                             hysteresis_pa=width)
    out = []
    for c in commands:
        reg.set_command(c)
        reg.step(0.001)
        out.append(reg.setpoint_pa.copy())
    return np.array(out)


def test_the_valves_follow_the_wanted_set_points_exactly():
    rng = np.random.default_rng(3)
    wanted = 30e3 + np.cumsum(rng.normal(0.0, 400.0, size=(200, 3)), axis=0)   # reversals
    comp = PlayCompensation(3, 1e3, 0.0, 100e3)
    sent = [comp.command(w) for w in wanted]
    np.testing.assert_allclose(_valves(1e3, sent), wanted, atol=1e-9)
    plain = _valves(1e3, list(wanted))
    assert np.abs(plain - wanted).max() > 400.0        # without it, the play shows


def test_vent_passes_and_limits_hold():
    comp = PlayCompensation(2, 2e3, 0.0, 50e3)
    np.testing.assert_array_equal(comp.command([49.5e3, 10e3]), [50e3, 11e3])   # cut at p_max
    np.testing.assert_array_equal(comp.command([0.0, 0.0]), [0.0, 0.0])         # the vent
    np.testing.assert_array_equal(comp.command([10e3, 10e3]), [11e3, 11e3])      # from 0: up
    c = comp.command([10e3, 10e3])
    np.testing.assert_array_equal(c, [10e3, 10e3])    # already there: nothing to take up


def test_bad_width_is_refused():
    with pytest.raises(ValueError, match='play'):
        PlayCompensation(3, -1.0, 0.0, 1e5)


def test_regulators_take_a_command_when_it_arrived():
    """A set-point between two steps takes effect after_s + dead time, not at a step's edge."""
    reg = PressureRegulators(1, 0.0, 100e3, time_constant_s=0.0, dead_time_s=0.015)
    reg.step(0.010)
    reg.set_command([20e3], after_s=0.004)      # arrived at 14 ms: in effect at 29 ms
    reg.step(0.0185)                            # to 28.5 ms
    assert reg.setpoint_pa[0] == 0.0
    reg.step(0.001)                             # to 29.5 ms
    assert reg.setpoint_pa[0] == 20e3
