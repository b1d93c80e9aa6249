"""sample_motion, sampling_step and piecewise_linear (issue 26: the CLI's simulation helpers)."""

import numpy as np
import pytest

from bellow_ancf_ros.core import DynamicsStatus, solve_forward
from bellow_ancf_ros.core.dynamics import (GeneralizedAlpha, piecewise_linear, sample_motion,
                                           sampling_step)


def test_sampling_step_puts_the_samples_on_steps():
    assert sampling_step(0.004, None) == 0.004
    assert sampling_step(0.004, 0.01) == pytest.approx(0.01 / 3)
    assert sampling_step(0.005, 0.01) == pytest.approx(0.005)     # already a multiple
    assert sampling_step(0.004, 0.001) == pytest.approx(0.001)    # a sample every step
    with pytest.raises(ValueError, match="sample_s = 0 is not allowed"):
        sampling_step(0.004, 0)


def test_piecewise_linear_interpolates_and_holds():
    f = piecewise_linear([0.0, 1.0, 2.0], [[0.0, 10.0], [10.0, 10.0], [10.0, 0.0]])
    np.testing.assert_allclose(f(0.5), [5.0, 10.0])
    np.testing.assert_allclose(f(1.5), [10.0, 5.0])
    np.testing.assert_allclose(f(-1.0), [0.0, 10.0])
    np.testing.assert_allclose(f(9.0), [10.0, 0.0])
    with pytest.raises(ValueError, match="increase"):
        piecewise_linear([0.0, 0.0], [[1.0], [2.0]])


def test_samples_are_the_integrators_states_at_the_sample_times(one):
    p = np.array([40e3, 0.0, 0.0])
    fw = solve_forward(one, p, tip_force_n=[0.1, 0.0, 0.0])
    ig = GeneralizedAlpha(one, step_s=0.002)
    ig.start_released(fw)
    run = sample_motion(ig, 0.05, sample_s=0.01, pressures_pa=p)
    assert run.success and run.step_s == pytest.approx(0.002)
    np.testing.assert_allclose(run.times_s, np.arange(6) * 0.01, atol=1e-12)
    assert run.report.steps == 25 and len(run.step_wall_s) == 25
    # the same run step by step
    ref = GeneralizedAlpha(one, step_s=0.002)
    ref.start_released(fw)
    pos = [ref.end_effector()[0]]
    for k in range(1, 6):
        assert ref.advance(0.01 * k, pressures_pa=p).success
        pos.append(ref.end_effector()[0])
    np.testing.assert_allclose(run.positions_m, pos, rtol=0, atol=1e-15)
    np.testing.assert_allclose(run.z_axes[0], fw.z_axis, atol=1e-12)
    np.testing.assert_allclose(run.pressures_pa, np.tile(p, (6, 1)))
    assert run.constraint_violation < 1e-9 and run.real_time_factor > 0
    s = run.samples()
    assert set(s[0]) == {"t_s", "position_m", "z_axis"} and len(s) == 6


def test_energy_and_constraints_are_checked_at_their_own_interval(one):
    """``check_s``: checks at the first and last sample and every ``check_s``; NaN between."""
    fw = solve_forward(one, np.zeros(3), tip_force_n=[0.05, 0.0, 0.0])
    every = GeneralizedAlpha(one, step_s=0.002, rho_inf=1.0, damping_time_s=0.0)
    every.start_released(fw)
    ref = sample_motion(every, 0.1, pressures_pa=np.zeros(3))
    ig = GeneralizedAlpha(one, step_s=0.002, rho_inf=1.0, damping_time_s=0.0)
    ig.start_released(fw)
    run = sample_motion(ig, 0.1, pressures_pa=np.zeros(3), check_s=0.03)
    np.testing.assert_array_equal(run.positions_m, ref.positions_m)
    checked = np.flatnonzero(np.isfinite(run.energy_j))
    np.testing.assert_allclose(run.times_s[checked],
                               [0.0, 0.03, 0.06, 0.09, 0.1], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(run.energy_j[checked], ref.energy_j[checked])
    assert np.all(np.isfinite(ref.energy_j))
    assert run.constraint_violation <= ref.constraint_violation < 1e-9
    # undamped: the checked energies stay those of the release
    drift = np.abs(run.energy_j[checked] - run.energy_j[0]).max()
    vibration = ref.energy_j[0] - float(one.potential(solve_forward(one, np.zeros(3)).q,
                                                      fw.stretch))
    assert 0 < drift < 1e-3 * vibration
    with pytest.raises(ValueError, match="check_s = 0 is not allowed"):
        sample_motion(ig, 0.2, check_s=0)


def test_a_failed_run_keeps_what_was_computed(one):
    fw = solve_forward(one, np.zeros(3))
    ig = GeneralizedAlpha(one, step_s=0.002, tol=0.0, max_iter=2, max_halvings=1)
    ig.start(fw)
    run = sample_motion(ig, 0.01, pressures_pa=[100e3, 0.0, 0.0])
    assert not run.success and run.report.status == DynamicsStatus.STEP_TOO_SMALL
    assert len(run.times_s) == 1 and "at t = 0 s" in run.report.message
    np.testing.assert_allclose(run.positions_m[0], fw.position, atol=1e-12)
