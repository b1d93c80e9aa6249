"""The robot family: reproducible draws inside the documented ranges, at the drawn mode."""

import pytest

from bellow_ancf_ros.core import load_robot
from bellow_ancf_ros.core.sim import FAMILY_RANGES, draw_robot, first_mode


@pytest.mark.parametrize('robot', ['one_segment', 'two_segment'])
def test_draws_are_reproducible_and_inside_the_ranges(robot):
    a, b, c = draw_robot(robot, 3), draw_robot(robot, 3), draw_robot(robot, 4)
    assert a.values == b.values and a.config == b.config and a.effects == b.effects
    assert a.values != c.values
    for d in (a, c):
        for name, (lo, hi) in FAMILY_RANGES.items():
            assert lo <= d.values[name] <= hi, name
        e = d.effects
        assert e.regulator_time_constant_s == d.values['regulator_time_constant_s']
        assert e.mocap_rate_hz == d.values['mocap_rate_hz']
        assert e.position_noise_m == d.values['position_noise_m']


@pytest.mark.parametrize('robot', ['one_segment', 'two_segment'])
def test_a_draw_has_its_drawn_mode_and_damping(robot):
    """The masses put the first mode at the drawn multiple of the model's, the damping at zeta."""
    base = load_robot(robot)
    f_model = first_mode(base).frequency_hz
    for seed in (0, 1):
        d = draw_robot(robot, seed)
        mode = first_mode(d.config)
        assert d.model_mode_hz == pytest.approx(f_model)
        assert mode.frequency_hz == pytest.approx(d.values['mode_scale'] * f_model, rel=0.03)
        assert mode.damping_ratio == pytest.approx(d.values['damping_ratio'], rel=0.02)
        # stiffness and geometry scaled as drawn, the element count doubled
        cfg = d.config
        assert cfg.stiffness_coeffs[0] == pytest.approx(
            base.stiffness_coeffs[0] * d.values['stiffness_scale'])
        assert cfg.d_a == pytest.approx(base.d_a * d.values['d_a_scale'])
        assert cfg.segments[0].pitch_radius == pytest.approx(
            base.segments[0].pitch_radius * d.values['pitch_radius_scale'])
        assert cfg.n_elements == 2 * base.n_elements
        # a lighter robot rings faster: the mass scale follows the drawn mode
        heavier = d.values['mode_scale'] < 1.0
        assert (cfg.rho0 > base.rho0) == heavier or abs(d.values['mode_scale'] - 1) < 0.05


def test_a_draw_builds_its_simulated_robot():
    d = draw_robot('one_segment', 2)
    robot = d.robot()
    assert robot.cfg == d.config and robot.effects == d.effects
    assert robot.first_mode_hz == pytest.approx(d.first_mode_hz, rel=1e-6)
