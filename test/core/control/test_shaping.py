"""Input shaping of the target stream (core/control/_shaping.py): ZV/ZVD after Singer & Seering."""

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward, solve_inverse
from bellow_ancf_ros.core.control import (LoopSimulation, PlantEffects, SimulatedRobot,
                                          TargetShaper, shaped, shaper_impulses)
from bellow_ancf_ros.core.dynamics import natural_modes


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
    leaves less than 0.1 mm one second after the step.
    """
    model = RobotModel(load_robot('two_segment'))
    fw0 = solve_forward(model, [30e3, 0, 0, 0, 0, 0])
    goal = fw0.position + np.array([0.0, 0.010, 0.0])
    mode = natural_modes(solve_inverse(model, goal, fw0.z_axis, warm_start=fw0).forward,
                         1).first

    def step(t):
        return (fw0.position if t < 8.0 else goal), fw0.z_axis

    out = {}
    for kind in ('none', 'zvd'):
        e = PlantEffects.ideal(dynamics=True, regulator_time_constant_s=0.06,
                               regulator_dead_time_s=0.015, position_noise_m=0.0,
                               angle_noise_rad=0.0)
        robot = SimulatedRobot('two_segment', seed=0, effects=e)
        sim = LoopSimulation(model, robot, None, physics_rate_hz=robot.auto_physics_rate_hz)
        tgt = step if kind == 'none' else shaped(step, kind, mode.frequency_hz,
                                                 mode.damping_ratio)
        rec = sim.run(11.0, tgt)   # 8 s: the swing of the start dies out
        a = rec.arrays()
        final = a['true_p'][a['t'] > 10.5].mean(axis=0)
        w = (a['t'] >= 9.0) & (a['t'] <= 10.0)
        out[kind] = np.linalg.norm(a['true_p'][w] - final, axis=1).max()
    assert out['none'] > 2e-3, out
    assert out['zvd'] < 0.1e-3, out
