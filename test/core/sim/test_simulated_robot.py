"""Tests of the simulated robot (core/control): regulators, creep, physics, motion capture."""

import math
from pathlib import Path

import numpy as np

from bellow_ancf_ros.core.geometry import rotation_from_vector
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward
from bellow_ancf_ros.core.sim import (EFFECTS, MotionCapture, PlantEffects, SimulatedRobot,
                                      simulated_robot_file)

IDEAL = PlantEffects.ideal()


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
    return SimulatedRobot('one_segment_mismatched', seed=3, effects=IDEAL)


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
    robot = SimulatedRobot('one_segment_mismatched', seed=0, effects=IDEAL)
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
    b = SimulatedRobot('one_segment_mismatched', seed=42)   # the realistic defaults' noise
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
    exact = SimulatedRobot('one_segment_mismatched',
                           effects=IDEAL.replace(position_noise_m=0.0, angle_noise_rad=0.0))
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


# ------------------------------------------------------------------ hardware effects
def test_realistic_robot_answers_later_and_creeps():
    """Dead time and creep: nothing in the first 15 ms, most at once, the rest over seconds."""
    real = SimulatedRobot('one_segment_mismatched', seed=0,
                          effects=PlantEffects(regulator_hysteresis_pa=0.0))
    z0 = real.true_pose()[0][2]
    real.command([100e3, 100e3, 100e3])
    real.step(0.01)
    assert real.true_pose()[0][2] == pytest.approx(z0, abs=1e-12)   # within the dead time
    for _ in range(50):                                      # 0.5 s: regulators settled
        real.step(0.01)
    z_fast = real.true_pose()[0][2]
    for _ in range(300):                                     # 30 s more: creep settled
        real.step(0.1)
    z_end = real.true_pose()[0][2]
    rise = (z_fast - z0) / (z_end - z0)
    assert 0.85 < rise < 0.91      # 85 % at once, plus the creep over 0.5 s of its 2 s
    ideal = SimulatedRobot('one_segment_mismatched', seed=0, effects=IDEAL)
    ideal.command([100e3, 100e3, 100e3])
    for _ in range(150):
        ideal.step(0.01)
    assert z_end == pytest.approx(ideal.true_pose()[0][2], abs=1e-6)   # same equilibrium


def test_the_realistic_robot_vents_to_zero_despite_the_play():
    """Issue 28: the vent left 0.5 kPa (half the 1 kPa hysteresis) on measured_pressure."""
    real = SimulatedRobot('one_segment_mismatched', seed=0, effects=PlantEffects())
    assert real.effects.regulator_hysteresis_pa == 1e3
    real.command([100e3, 40e3, -30e3])
    for _ in range(50):
        real.step(0.02)
    real.command([0.0, 0.0, 0.0])   # the vent command (contract.vent_pressures)
    for _ in range(50):
        real.step(0.02)
    np.testing.assert_allclose(real.pressures_pa, 0.0, atol=0.01)   # Pa


def test_capture_sees_the_pose_one_latency_ago():
    e = PlantEffects.ideal(position_noise_m=0.0, angle_noise_rad=0.0, mocap_latency_s=0.008,
                           regulator_time_constant_s=0.05)
    robot = SimulatedRobot('one_segment_mismatched', effects=e)
    robot.command([120e3, 0.0, 0.0])
    poses = {}
    for i in range(1, 41):
        robot.step(0.005)
        poses[i] = robot.true_pose()[0]
    s = robot.capture()
    assert s.captured_s == pytest.approx(robot.time_s - 0.008)
    # 8 ms before step 40 lies between steps 38 (190 ms) and 39 (195 ms): interpolated
    a = (0.192 - 0.190) / 0.005
    np.testing.assert_allclose(s.position, poses[38] + a * (poses[39] - poses[38]), atol=1e-12)
    assert not np.allclose(s.position, poses[40])
    np.testing.assert_allclose(s.rotation.T @ s.rotation, np.eye(3), atol=1e-12)


def test_every_effect_has_a_preset_row():
    assert set(EFFECTS) == {'regulator lag 60 ms', 'regulator dead time', 'regulator hysteresis',
                            'bellows creep', 'mocap 120 Hz, latency', 'mocap outliers',
                            'mocap dropouts', 'robot dynamics'}
    for name in EFFECTS:
        PlantEffects().only(name)   # each switches on alone
    assert MotionCapture(PlantEffects.ideal(), 0).in_dropout(1.0) is False
    assert PlantEffects().dynamics and not PlantEffects.ideal().dynamics
    assert PlantEffects().only('robot dynamics').dynamics
    with pytest.raises(ValueError, match='plant setting dynamics'):
        PlantEffects(dynamics=1.0)


def test_dynamic_robot_rings_at_its_first_mode_and_settles_on_its_equilibrium():
    """A pressure step sets the robot swinging at its own first mode.

    It comes to rest at its own static equilibrium.  A physics rate too
    coarse for the mode is refused.
    """
    from bellow_ancf_ros.core.fit import fit_free_vibration

    e = PlantEffects.ideal(dynamics=True, regulator_time_constant_s=0.005)
    robot = SimulatedRobot('one_segment_mismatched', seed=0, effects=e)
    assert 8.0 < robot.first_mode_hz < 9.5
    with pytest.raises(ValueError, match=r'physics_rate_hz = 100 is too coarse .* at least 17'):
        robot.check_physics_rate(100.0)
    robot.check_physics_rate(200.0)
    p = np.array([100e3, 0.0, 0.0])
    robot.command(p)
    t, x = [], []
    for _ in range(200):
        robot.step(0.004)
        t.append(robot.time_s)
        x.append(robot.true_pose()[0])
    fit = fit_free_vibration(t, x, 0.1, 0.8)
    mode = robot.first_mode_hz
    own = solve_forward(robot.model, p)
    assert fit.frequency_hz == pytest.approx(mode, rel=0.1)   # the bent robot's mode is near
    for _ in range(500):
        robot.step(0.004)
    np.testing.assert_allclose(robot.true_pose()[0], own.position, atol=1e-6)
    assert robot.failures == 0
    quasi = SimulatedRobot('one_segment_mismatched', seed=0, effects=PlantEffects.ideal())
    quasi.check_physics_rate(1.0)   # no mode to resolve without dynamics


def test_the_simulated_robot_file_of_a_robot_without_a_mismatched_one(tmp_path):
    """``<robot>_mismatched``: the shipped one where there is one, else the robot itself."""
    from bellow_ancf_ros.core import ConfigError
    cfg, note = simulated_robot_file('two_segment_mismatched')
    assert cfg.name == 'two_segment_mismatched' and note is None
    cfg, note = simulated_robot_file('three_segment_mismatched')
    assert cfg.name == 'three_segment' and "simulating 'three_segment' itself" in note
    own = tmp_path / 'arm.yaml'
    own.write_text((Path(load_robot('one_segment').source)).read_text())
    cfg, note = simulated_robot_file(f'{own}_mismatched')
    assert cfg.name == 'arm' and str(own) in note
    with pytest.raises(ConfigError, match='unknown robot name'):
        simulated_robot_file('no_such_robot_mismatched')
    bad = tmp_path / 'bad.yaml_mismatched'
    bad.write_text('name: [')
    with pytest.raises(ConfigError, match='YAML syntax error'):   # a file that is there: its error
        simulated_robot_file(str(bad))
