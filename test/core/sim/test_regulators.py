"""Tests of the simulated robot's actuation (core/sim/_regulators.py).

Regulators: first-order lag (exact), slew and hardware limits, dead time,
play hysteresis; bellows: creep of a part of the stage-1 elongation.
"""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot
from bellow_ancf_ros.core.sim import BellowCreep, PressureRegulators


def test_regulator_first_order_step_response_and_exact_discretisation():
    reg = PressureRegulators(3, -50e3, 150e3, time_constant_s=0.1, slew_rate_pa_per_s=1e9)
    reg.set_command([100e3, -40e3, 0.0])
    p = reg.step(0.1)   # one time constant: 1 - 1/e of the step
    np.testing.assert_allclose(p, np.array([100e3, -40e3, 0.0]) * (1 - math.exp(-1)), rtol=1e-12)
    # the discrete step is exact: ten steps of tau/10 = one step of tau
    reg2 = PressureRegulators(3, -50e3, 150e3, time_constant_s=0.1, slew_rate_pa_per_s=1e9)
    reg2.set_command([100e3, -40e3, 0.0])
    for _ in range(10):
        q = reg2.step(0.01)
    np.testing.assert_allclose(q, p, rtol=1e-12)
    # settles on the set-point
    for _ in range(100):
        p = reg.step(0.02)
    np.testing.assert_allclose(p, [100e3, -40e3, 0.0], atol=1e-3)


def test_regulator_slew_limit_and_hardware_limits():
    reg = PressureRegulators(2, -50e3, 150e3, time_constant_s=0.1, slew_rate_pa_per_s=1e6)
    reg.set_command([500e3, -500e3])            # beyond the hardware: clipped
    np.testing.assert_array_equal(reg.command_pa, [150e3, -50e3])
    p = reg.step(0.01)
    # actuator 1: the lag asks for 14.3 kPa, the slew limit allows 1e6 Pa/s * 0.01 s
    # actuator 2: the lag's 4.76 kPa is within the slew limit
    np.testing.assert_allclose(p, [10e3, -50e3 * (1 - math.exp(-0.1))])
    for _ in range(200):
        p = reg.step(0.01)
        assert np.all(p >= -50e3) and np.all(p <= 150e3)
    np.testing.assert_allclose(p, [150e3, -50e3], atol=1e-6)


def test_regulator_refuses_bad_input():
    reg = PressureRegulators(3, -50e3, 150e3)
    with pytest.raises(ValueError, match='finite'):
        reg.set_command([np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match='expected 3'):
        reg.set_command([0.0, 0.0])
    with pytest.raises(ValueError, match='dt'):
        reg.step(-1.0)
    with pytest.raises(ValueError, match='time_constant_s'):
        PressureRegulators(3, -50e3, 150e3, time_constant_s=-0.1)
    np.testing.assert_array_equal(reg.command_pa, [0.0, 0.0, 0.0])   # old command kept


def test_dead_time_delays_a_set_point_exactly():
    reg = PressureRegulators(1, -50e3, 150e3, time_constant_s=0.06, slew_rate_pa_per_s=1e9,
                             dead_time_s=0.015)
    reg.set_command([100e3])
    assert reg.step(0.010)[0] == 0.0          # nothing within the dead time
    p = reg.step(0.010)[0]                     # 5 ms of response after it
    assert p == pytest.approx(100e3 * (1 - math.exp(-0.005 / 0.06)), rel=1e-12)
    # the same answer in one step: piecewise exact at the moment it takes effect
    one = PressureRegulators(1, -50e3, 150e3, time_constant_s=0.06, slew_rate_pa_per_s=1e9,
                             dead_time_s=0.015)
    one.set_command([100e3])
    assert one.step(0.020)[0] == pytest.approx(p, rel=1e-12)


def test_dead_time_keeps_the_order_of_set_points():
    reg = PressureRegulators(1, -50e3, 150e3, time_constant_s=0.0, dead_time_s=0.02,
                             slew_rate_pa_per_s=1e9)
    reg.set_command([10e3])
    reg.step(0.01)
    reg.set_command([20e3])
    assert reg.step(0.015)[0] == 10e3          # the first arrived at 20 ms, the second not yet
    assert reg.step(0.01)[0] == 20e3           # the second at 30 ms


def test_hysteresis_is_a_play_of_its_width():
    """Approached from below and from above, one set-point gives pressures h apart."""
    h = 1e3
    reg = PressureRegulators(1, -50e3, 150e3, time_constant_s=0.0, hysteresis_pa=h,
                             slew_rate_pa_per_s=1e9)
    reg.set_command([60e3])
    up = reg.step(0.01)[0]
    assert up == pytest.approx(60e3 - h / 2)
    reg.set_command([80e3])
    reg.step(0.01)
    reg.set_command([60e3])
    down = reg.step(0.01)[0]
    assert down == pytest.approx(60e3 + h / 2)
    assert down - up == pytest.approx(h)
    # a change smaller than the band moves nothing
    reg.set_command([60e3 + 0.4 * h])
    assert reg.step(0.01)[0] == pytest.approx(down)
    with pytest.raises(ValueError, match='hysteresis_pa'):
        PressureRegulators(1, -50e3, 150e3, hysteresis_pa=-1.0)
    with pytest.raises(ValueError, match='dead_time_s'):
        PressureRegulators(1, -50e3, 150e3, dead_time_s=float('nan'))


def test_the_vent_exhausts_to_atmosphere_past_the_play():
    """A 0 Pa gauge set-point opens the exhaust: 0, not the band's edge (0.5 kPa), either side.

    Dead time and lag stay; other set-points keep their play.
    """
    h, tau, dead = 1e3, 0.06, 0.015
    for start in (60e3, -40e3):   # from pressure and from vacuum
        reg = PressureRegulators(3, -50e3, 150e3, time_constant_s=tau, hysteresis_pa=h,
                                 dead_time_s=dead, slew_rate_pa_per_s=1e6)
        reg.set_command([start, start, 0.5 * start])
        reg.step(1.0)
        held = reg.pressures_pa.copy()
        reg.set_command([0.0, 0.0, 0.0])
        np.testing.assert_allclose(reg.step(0.5 * dead), held)       # the dead time
        p = reg.step(0.5 * dead + tau)[0]                            # one time constant
        assert p == pytest.approx(held[0] * math.exp(-1.0), rel=1e-6)   # the lag to 0
        np.testing.assert_allclose(reg.step(1.0), 0.0, atol=0.01)    # 0 Pa, not +-500 Pa
        # a set-point near 0 but not the vent keeps the play
        reg.set_command([2e3, 2e3, 2e3])
        reg.step(1.0)
        reg.set_command([1e-3, 1e-3, 1e-3])
        assert reg.step(1.0)[0] == pytest.approx(1e-3 + h / 2, abs=1e-3)


@pytest.fixture(scope='module')
def stage1():
    return RobotModel(load_robot('one_segment_mismatched')).stage1


def test_creep_a_fraction_follows_a_step_with_its_time_constant(stage1):
    creep = BellowCreep(stage1, 0.15, 2.0, np.zeros(3))
    p = np.array([100e3, 50e3, -30e3])
    x_final = stage1.stretch(p) - 1.0
    x_now = stage1.stretch(creep.step(p, 1e-9)) - 1.0
    np.testing.assert_allclose(x_now, 0.85 * x_final, rtol=1e-6)   # 85 % at once
    x_tau = stage1.stretch(creep.step(p, 2.0)) - 1.0
    np.testing.assert_allclose(x_tau, x_final * (1 - 0.15 * math.exp(-1.0)), rtol=1e-6)
    for _ in range(40):
        eff = creep.step(p, 1.0)
    np.testing.assert_allclose(eff, p, rtol=1e-8)                 # settled: no lasting change


def test_creep_off_and_bad_settings(stage1):
    p = np.array([10e3, 20e3, 30e3])
    np.testing.assert_array_equal(BellowCreep(stage1, 0.0, 2.0, p).step(p * 2, 0.1), p * 2)
    with pytest.raises(ValueError, match='fraction'):
        BellowCreep(stage1, 1.0, 2.0, p)
    with pytest.raises(ValueError, match='time constant'):
        BellowCreep(stage1, 0.1, 0.0, p)
