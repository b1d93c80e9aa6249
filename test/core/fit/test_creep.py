"""The bellows' creep from a recorded pressure step (``fit_creep``, ``pressure_step_time``).

Ground truth: the project's simulated robot (its own robot file, regulators,
``BellowCreep``, motion capture with noise, outliers and dropouts), stepped
from vent to 80 kPa on actuator 1 (an 11 mm move) and held for 20 s, the
recording the docs ask for; and analytic curves.
"""

import numpy as np
import pytest

from bellow_ancf_ros.core.sim import PlantEffects, SimulatedRobot
from bellow_ancf_ros.core.fit import CreepFit, fit_creep, pressure_step_time

T_STEP = 1.0
STEP_PA = 80e3


def record_step(c, T, noise_m, dynamics=True, seed=1, after_s=20.0, step_pa=STEP_PA,
                **effects):
    """Mocap samples of the simulated robot, a step of actuator 1 at T_STEP held ``after_s``."""
    e = PlantEffects(creep_fraction=c, creep_time_constant_s=T, position_noise_m=noise_m,
                     dynamics=dynamics, **effects)
    robot = SimulatedRobot(effects=e, seed=seed)
    dt = 1.0 / robot.auto_physics_rate_hz
    period = robot.mocap.period_s
    times, positions = [], []
    t_next = period
    while robot.time_s < T_STEP + after_s:
        if robot.time_s >= T_STEP - 1e-9 and step_pa is not None:
            robot.command([step_pa, 0.0, 0.0])
            step_pa = None
        robot.step(dt)
        while t_next <= robot.time_s + 1e-12:
            sample = robot.capture(t_next)
            if sample is not None:
                times.append(sample.captured_s)
                positions.append(sample.position)
            t_next += period
    return np.array(times), np.array(positions)


def creep_curve(c, T, D=8e-3, delay_s=0.0, rise_s=0.0, rate_hz=120.0, after_s=20.0):
    """A linear plant's step response along (0.6, 0, 0.8): dead time, first-order rise, creep.

    With ``u = 1 - exp(-(t - delay)/rise)`` the regulated input, the slow part
    ``s`` (``T ds/dt = u - s``) is ``1 - (T exp(-(t - delay)/T) - rise
    exp(-(t - delay)/rise)) / (T - rise)`` and the tip stands at ``D ((1 - c)
    u + c s)``.
    """
    t = np.arange(0.0, T_STEP + after_s, 1.0 / rate_hz)
    tau = np.maximum(t - T_STEP - delay_s, 0.0)
    if rise_s > 0:
        u = 1.0 - np.exp(-tau / rise_s)
        s = 1.0 - (T * np.exp(-tau / T) - rise_s * np.exp(-tau / rise_s)) / (T - rise_s)
    else:
        u = (t >= T_STEP + delay_s).astype(float)
        s = u * (1.0 - np.exp(-tau / T))
    y = D * ((1 - c) * u + c * s)
    x = np.array([0.01, -0.02, 0.3]) + np.outer(y, [0.6, 0.0, 0.8])
    return t, x


# ----------------------------------------------------------------- analytic
def test_an_exact_exponential_is_recovered_exactly():
    t, x = creep_curve(0.12, 2.5)
    fit = fit_creep(t, x, T_STEP)
    assert isinstance(fit, CreepFit)
    assert fit.creep_fraction == pytest.approx(0.12, abs=1e-6)
    assert fit.creep_time_constant_s == pytest.approx(2.5, rel=1e-6)
    assert fit.displacement_m == pytest.approx(8e-3, rel=1e-6)
    np.testing.assert_allclose(fit.direction, [0.6, 0.0, 0.8], atol=1e-9)
    assert fit.rms_residual_m < 1e-9 and fit.delay_s == pytest.approx(0.0, abs=1e-6)
    assert fit.t_start_s == pytest.approx(T_STEP + fit.settle_s)
    assert fit.t_end_s == pytest.approx(t[-1]) and fit.n_samples > 2000
    d = fit.to_dict()
    assert d['creep_fraction'] == fit.creep_fraction and len(d['direction']) == 3
    # the fitted curve is the recording's
    y = (x - x[0]) @ np.array(fit.direction)
    sel = t >= fit.t_start_s
    np.testing.assert_allclose(fit.curve(t[sel]), y[sel], atol=1e-9)


def test_the_regulators_delay_is_taken_out_of_the_creep_fraction():
    """A dead time and a first-order rise: c to the first order in rise/T, not c exp(delay/T).

    The late tail is ``D - c D T/(T - rise) exp(-(t - dead)/T)``: with the
    mean delay ``dead + rise`` taken out, ``c T/(T - rise) exp(-rise/T)``,
    1.0003 c here; measured from the command, 1.036 c.
    """
    c, T, dead, rise = 0.15, 2.0, 0.02, 0.05
    t, x = creep_curve(c, T, delay_s=dead, rise_s=rise, rate_hz=500.0)
    fit = fit_creep(t, x, T_STEP)
    expected = c * T / (T - rise) * np.exp(-rise / T)
    assert fit.creep_fraction == pytest.approx(expected, abs=2e-4)
    assert fit.creep_time_constant_s == pytest.approx(T, rel=1e-3)   # the rise's tail
    assert fit.delay_s == pytest.approx(dead + rise, abs=2e-3)


@pytest.mark.parametrize('zeta, c, T', [
    (0.055, 0.17, 1.05), (0.03, 0.08, 2.3), (0.074, 0.15, 1.45)])
def test_a_creep_under_a_first_mode_that_rings_longer_is_fitted_with_the_ringing(zeta, c, T):
    """A lightly damped mode (1.5 Hz, 2 mm ringing) that outlasts the creep.

    Past the ringing nothing of the creep is left (the fit of the creep
    alone failed on such two-segment robots of the family): the ringing is
    fitted with it, from the regulators' rise on.
    """
    w = 2 * np.pi * 1.5
    t, x = creep_curve(c, T, D=20e-3, delay_s=0.02, rise_s=0.05)
    tau = np.maximum(t - T_STEP - 0.02, 0.0)
    ring = -2e-3 * np.exp(-zeta * w * tau) * np.cos(w * np.sqrt(1 - zeta ** 2) * tau)
    x = x + np.outer(ring * (t >= T_STEP + 0.02), [0.6, 0.0, 0.8])
    x = x + np.random.default_rng(5).normal(0.0, 0.15e-3, x.shape)
    fit = fit_creep(t, x, T_STEP)
    assert fit.creep_fraction == pytest.approx(c, rel=0.1)
    assert fit.creep_time_constant_s == pytest.approx(T, rel=0.1)
    assert fit.settle_s == 0.5   # (from the rise on: the ringing is in the curve)
    assert fit.rms_residual_m < 0.2e-3


def test_noise_outliers_and_a_dropout_on_an_exponential():
    t, x = creep_curve(0.1, 2.0)
    rng = np.random.default_rng(7)
    x = x + rng.normal(0.0, 0.1e-3, x.shape)
    spikes = rng.choice(len(t), 30, replace=False)
    x[spikes] += rng.choice([-1.0, 1.0], (30, 3)) * 0.02           # swapped markers
    keep = (t < 4.0) | (t > 4.5)                                   # a dropout
    fit = fit_creep(t[keep], x[keep], T_STEP)
    # the spikes the fit sees: from the pose before the step (0.5 s) on, outside the dropout
    seen = np.count_nonzero(keep[spikes] & (t[spikes] >= T_STEP - 0.5))
    assert fit.outliers == seen > 20
    assert fit.creep_fraction == pytest.approx(0.1, abs=0.01)
    assert fit.creep_time_constant_s == pytest.approx(2.0, rel=0.1)
    assert fit.noise_m == pytest.approx(0.1e-3, rel=0.3)
    assert abs(fit.creep_fraction - 0.1) < 4 * fit.creep_fraction_stderr
    assert abs(fit.creep_time_constant_s - 2.0) < 4 * fit.creep_time_constant_stderr_s


def test_a_ringing_mode_is_fitted_not_skipped():
    """A 3 Hz mode ringing 2 mm (zeta 0.05, 1 s decay): fitted from the rise on, exactly."""
    t, x = creep_curve(0.1, 2.0)
    tau = np.maximum(t - T_STEP, 0.0)
    w = 2 * np.pi * 3.0
    ring = np.where(t >= T_STEP, 2e-3 * np.exp(-0.05 * w * tau) * np.cos(w * tau), 0.0)
    x = x + np.outer(ring, [0.6, 0.0, 0.8])
    fit = fit_creep(t, x, T_STEP)
    assert fit.settle_s == 0.5 and fit.rms_residual_m < 1e-8
    assert fit.creep_fraction == pytest.approx(0.1, abs=1e-3)
    assert fit.creep_time_constant_s == pytest.approx(2.0, rel=1e-3)
    # a fit of the creep alone from where it is asked to start: the ringing pulls it off
    early = fit_creep(t, x, T_STEP, settle_s=0.3)
    assert early.rms_residual_m > 1e4 * fit.rms_residual_m


# ---------------------------------------------------------- simulated robot
#: Over 12 noise seeds the errors' spread matched the reported standard errors: c 0.010 and
#: T 5 % at (0.2, 1 s, 0.3 mm), c 0.004 and T 3 % at (0.2, 5 s, 0.3 mm), c 0.002 and T 8 %
#: at (0.02, 1 s, 0.05 mm), c 0.0005 and T 5 % at (0.02, 5 s, 0.05 mm), c 0.002 and T 3 % at
#: (0.1, 3 s, 0.15 mm); the tolerances are about three of them.
@pytest.mark.parametrize('c, T, noise_m, dynamics, c_tol, T_tol', [
    (0.15, 2.0, 0.0, True, 0.002, 0.01),      # the method's own error: small
    (0.20, 1.0, 0.3e-3, True, 0.03, 0.15),    # the family's extremes: fast, large, noisy
    (0.20, 5.0, 0.3e-3, False, 0.02, 0.15),   # slow, large, noisy
    (0.02, 1.0, 0.05e-3, True, 0.01, 0.25),   # fast, small (0.2 mm of creep), quiet
    (0.02, 5.0, 0.05e-3, False, 0.01, 0.15),  # slow, small, quiet
    (0.10, 3.0, 0.15e-3, True, 0.01, 0.10),   # the default mocap noise
])
def test_the_simulated_robots_creep_is_recovered(c, T, noise_m, dynamics, c_tol, T_tol):
    t, x = record_step(c, T, noise_m, dynamics=dynamics)
    fit = fit_creep(t, x, T_STEP)
    assert fit.creep_fraction == pytest.approx(c, abs=c_tol)
    assert fit.creep_time_constant_s == pytest.approx(T, rel=T_tol)
    # the regulators' dead time (15 ms) and lag (60 ms) are the fast move's delay
    assert 0.05 < fit.delay_s < 0.11
    assert fit.displacement_m == pytest.approx(11.1e-3, rel=0.02)
    assert abs(fit.direction[0]) > 0.5
    if noise_m:
        assert fit.noise_m == pytest.approx(noise_m, rel=0.3)


def test_the_standard_errors_are_honest_where_the_creep_drowns_in_noise():
    """0.2 mm of creep under 0.3 mm noise: T is poorly known, and the fit says so."""
    t, x = record_step(0.02, 5.0, 0.3e-3, dynamics=False, seed=3, dropout_every_s=0.0,
                       dropout_duration_s=0.0)
    fit = fit_creep(t, x, T_STEP)
    assert abs(fit.creep_fraction - 0.02) < 3 * fit.creep_fraction_stderr
    assert abs(fit.creep_time_constant_s - 5.0) < 3 * fit.creep_time_constant_stderr_s
    assert fit.creep_time_constant_stderr_s > 0.1 * fit.creep_time_constant_s


# ------------------------------------------------------------------ refusals
def test_refuses_a_robot_that_does_not_move():
    t, x = record_step(0.1, 2.0, 0.15e-3, dynamics=False, after_s=6.0, step_pa=None)
    with pytest.raises(ValueError, match='the tip does not move'):
        fit_creep(t, x, T_STEP)


def test_a_dropout_during_the_fast_move_is_refused_one_after_it_is_not():
    c, T, rise = 0.15, 2.0, 0.05
    t, x = creep_curve(c, T, delay_s=0.02, rise_s=rise)
    for lost in [(0.03, 0.3), (-0.2, 0.2)]:      # in the rise; across the step
        keep = (t < T_STEP + lost[0]) | (t > T_STEP + lost[1])
        with pytest.raises(ValueError, match='during the fast move after the step'):
            fit_creep(t[keep], x[keep], T_STEP)
    keep = (t < T_STEP + 0.35) | (t > T_STEP + 0.8)    # the fast move was over
    fit = fit_creep(t[keep], x[keep], T_STEP)
    assert fit.creep_fraction == pytest.approx(c * T / (T - rise) * np.exp(-rise / T), abs=5e-4)


def test_refuses_a_recording_too_short_for_the_creep():
    t, x = record_step(0.15, 5.0, 0.05e-3, dynamics=False, after_s=4.0)
    with pytest.raises(ValueError, match='record at least ~4 time constants after the step'):
        fit_creep(t, x, T_STEP)
    with pytest.raises(ValueError, match='record at least ~4 time constants after the step'):
        fit_creep(t, x, T_STEP, t_end_s=T_STEP + 1.0)


def test_refuses_a_robot_without_creep():
    t, x = creep_curve(0.0, 2.0)
    x = x + np.random.default_rng(3).normal(0.0, 0.1e-3, x.shape)
    with pytest.raises(ValueError, match='no (measurable creep|creep resolved)'):
        fit_creep(t, x, T_STEP)


def test_refuses_too_few_poses_and_bad_arguments():
    t, x = creep_curve(0.1, 2.0)
    with pytest.raises(ValueError, match='poses in the 0.5 s before the step'):
        fit_creep(t, x, 0.01)
    with pytest.raises(ValueError, match='only 0 poses from 30 s after the step'):
        fit_creep(t, x, T_STEP, settle_s=30.0)
    with pytest.raises(ValueError, match='settle_s'):
        fit_creep(t, x, T_STEP, settle_s=-1.0)
    with pytest.raises(ValueError, match='t_step_s'):
        fit_creep(t, x, float('nan'))


def test_refuses_a_tip_that_moves_back():
    """An overshoot relaxing back is no creep: c < 0 is refused."""
    t, x = creep_curve(-0.1, 2.0)
    with pytest.raises(ValueError, match=r'outside \[0, 1\)'):
        fit_creep(t, x, T_STEP)


# --------------------------------------------------------------- step time
def test_the_step_is_where_the_command_changes_most():
    t = np.arange(0.0, 5.0, 0.1)
    p = np.zeros((len(t), 3))
    p[t >= 2.0 - 1e-9, 0] = 40e3
    p[t >= 3.0 - 1e-9, 1] = 1e3                       # a smaller change later
    assert pressure_step_time(t, p) == pytest.approx(2.0)
    with pytest.raises(ValueError, match='never change'):
        pressure_step_time(t, np.zeros((len(t), 3)))
    with pytest.raises(ValueError, match='need at least two'):
        pressure_step_time([0.0], [[1.0, 2.0, 3.0]])
