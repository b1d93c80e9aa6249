"""Tests of the simulated robot (core/simulated_robot.py): regulators, physics, mocap noise."""

import math

import numpy as np

from bellow_ancf_ros.core.geometry import rotation_from_vector
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward
from bellow_ancf_ros.core.control._simulated_robot import (
    PressureRegulators,
    SimulatedRobot,
)


# ------------------------------------------------------------------ regulators
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


# ------------------------------------------------------------------ robot files
@pytest.mark.parametrize('name', ['one_segment', 'two_segment'])
def test_mismatched_files_differ_exactly_as_documented(name):
    base = load_robot(name).to_dict()
    mis = load_robot(name + '_mismatched').to_dict()
    seg_keys = {'pitch_radius_mm', 'constraint_plate_mass_kg', 'top_plate_mass_kg',
                'connector_mass_kg'}
    changed = set()
    for key in ('l0_m', 'stiffness_coeffs_n_per_m', 'd_eff_mm', 'd_a_mm',
                'linear_density_kg_per_m'):
        if base['actuator'][key] != mis['actuator'][key]:
            changed.add(key)
    for sb, sm in zip(base['segments'], mis['segments']):
        for key in sb:
            if sb[key] != sm[key]:
                assert key in seg_keys, key
                ratio = sm[key] / sb[key]
                assert 0.85 < ratio < 1.15 and abs(ratio - 1) > 0.03, (key, ratio)
    assert changed == {'stiffness_coeffs_n_per_m', 'd_a_mm', 'linear_density_kg_per_m'}
    for key in changed:
        ratio = np.asarray(mis['actuator'][key]) / np.asarray(base['actuator'][key])
        assert np.all((0.85 < ratio) & (ratio < 1.15)) and np.all(abs(ratio - 1) > 0.03)
    assert base['pressure_limits'] == mis['pressure_limits']
    assert mis['model']['n_elements'] > base['model']['n_elements']
    assert mis['model']['n_elements'] % 3 == 0   # nodes on the plates at 1/3 and 2/3


# ------------------------------------------------------------------ robot
@pytest.fixture(scope='module')
def robot1():
    return SimulatedRobot('one_segment_mismatched', seed=3)


def test_robot_settles_on_its_own_equilibrium_not_the_models(robot1, one):
    p = np.array([80e3, 10e3, -20e3])
    robot1.command(p)
    for _ in range(100):
        robot1.step(0.02)
    np.testing.assert_allclose(robot1.pressures_pa, p, atol=1e-3)
    # the state is re-solved whenever the regulated pressures moved by 1 Pa or more
    np.testing.assert_allclose(robot1.state.pressures_pa, p, atol=1.0)
    own = solve_forward(robot1.model, robot1.state.pressures_pa)
    pos, R = robot1.true_pose()
    np.testing.assert_allclose(pos, own.position, atol=1e-9)
    model = solve_forward(one, p)
    assert np.linalg.norm(pos - model.position) > 1e-3   # the robot is not the model
    assert robot1.failures == 0
    # a held command does not re-solve
    n = robot1.solves
    robot1.step(0.02)
    assert robot1.solves == n


def test_robot_lags_behind_a_step_command():
    robot = SimulatedRobot('one_segment_mismatched', seed=0)
    z0 = robot.true_pose()[0][2]
    robot.command([150e3, 150e3, 150e3])
    robot.step(0.05)
    z_half = robot.true_pose()[0][2]
    for _ in range(50):
        robot.step(0.02)
    z_end = robot.true_pose()[0][2]
    assert z0 < z_half < z_end
    assert (z_half - z0) < 0.6 * (z_end - z0)   # regulators still on the way (tau 0.1 s)


def test_payload_change_lowers_the_robot():
    robot = SimulatedRobot('one_segment_mismatched', seed=0)
    robot.command([50e3, 50e3, 50e3])
    for _ in range(40):
        robot.step(0.02)
    z0 = robot.true_pose()[0][2]
    robot.set_payload(0.05)
    robot.step(0.02)
    assert robot.true_pose()[0][2] < z0 - 1e-4
    with pytest.raises(ValueError, match='payload'):
        robot.set_payload(-1.0)


def test_mocap_noise_statistics_and_seed():
    a = SimulatedRobot('one_segment_mismatched', seed=42)
    b = SimulatedRobot('one_segment_mismatched', seed=42)
    true_p, true_R = a.true_pose()
    samples = np.array([a.measure()[0] for _ in range(3000)])
    err = samples - true_p
    np.testing.assert_allclose(err.std(axis=0), 0.15e-3, rtol=0.08)
    assert np.all(np.abs(err.mean(axis=0)) < 0.15e-3 * 4 / math.sqrt(3000))
    b_samples = np.array([b.measure()[0] for _ in range(3000)])
    np.testing.assert_array_equal(samples, b_samples)   # same seed, same noise
    R = a.measure()[1]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert 0 < math.degrees(math.acos(min(1.0, R[:, 2] @ true_R[:, 2]))) < 1.0
    exact = SimulatedRobot('one_segment_mismatched', position_noise_m=0.0, angle_noise_rad=0.0)
    np.testing.assert_array_equal(exact.measure()[0], exact.true_pose()[0])


def test_rotation_from_vector_is_a_rotation_about_the_vector():
    v = np.array([0.1, -0.2, 0.3])
    R = rotation_from_vector(v)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(R @ v, v, atol=1e-15)
    assert math.isclose(math.acos((np.trace(R) - 1) / 2), np.linalg.norm(v), rel_tol=1e-12)


def test_default_robot_file_and_finer_elements():
    robot = SimulatedRobot()
    assert robot.cfg.name == 'one_segment_mismatched'
    assert isinstance(robot.model, RobotModel) and robot.model.cfg.n_elements == 12
