"""Tests of the simulated motion capture (core/sim/_motion_capture.py)."""

import numpy as np
import pytest

from bellow_ancf_ros.core.sim import MotionCapture, PlantEffects

POS = np.array([0.01, -0.02, 0.15])
ROT = np.eye(3)


def _samples(effects, seed, n, t0=0.0):
    mocap = MotionCapture(effects, seed)
    return mocap, [mocap.observe(t0 + i * mocap.period_s, POS, ROT) for i in range(n)]


def test_outliers_have_their_rate_and_size_and_are_flagged():
    e = PlantEffects(position_noise_m=0.0, angle_noise_rad=0.0, dropout_every_s=0.0,
                     dropout_duration_s=0.0, outlier_probability=0.02)
    mocap, samples = _samples(e, 3, 20000)
    flagged = [s for s in samples if s.outlier]
    assert mocap.outliers == len(flagged)
    assert abs(len(flagged) / 20000 - 0.02) < 4 * np.sqrt(0.02 * 0.98 / 20000)
    size = np.array([np.linalg.norm(s.position - POS) for s in flagged])
    assert size.min() >= 0.010 and size.max() <= 0.030 and size.max() > 0.028
    clean = [s for s in samples if not s.outlier]
    assert all(np.array_equal(s.position, POS) for s in clean)   # no noise asked for


def test_dropouts_are_periodic_with_a_seeded_phase():
    e = PlantEffects(outlier_probability=0.0)           # 0.5 s every 15 s
    mocap, samples = _samples(e, 5, 120 * 45)           # 45 s at 120 Hz
    lost = np.array([s is None for s in samples])
    assert lost.sum() == pytest.approx(3 * 0.5 * 120, abs=3)
    t = np.arange(len(samples)) * mocap.period_s
    starts = t[1:][lost[1:] & ~lost[:-1]]
    np.testing.assert_allclose(np.diff(starts), 15.0, atol=mocap.period_s)
    assert starts[0] == pytest.approx(mocap.dropout_phase_s, abs=mocap.period_s)
    other = MotionCapture(e, 6)
    assert other.dropout_phase_s != mocap.dropout_phase_s
    again, same = _samples(e, 5, 500)
    assert all((a is None and b is None) or np.array_equal(a.position, b.position)
               for a, b in zip(samples[:500], same))       # same seed, same samples


def test_noise_statistics_and_capture_time():
    e = PlantEffects.ideal()
    mocap, samples = _samples(e, 9, 4000, t0=2.0)
    err = np.array([s.position for s in samples]) - POS
    np.testing.assert_allclose(err.std(axis=0), 0.15e-3, rtol=0.08)
    assert samples[0].captured_s == 2.0 and not any(s.outlier for s in samples)
    assert mocap.period_s == pytest.approx(0.01)


def test_plant_effects_presets_and_checks():
    real, ideal = PlantEffects(), PlantEffects.ideal()
    assert (real.regulator_time_constant_s, real.regulator_dead_time_s,
            real.regulator_hysteresis_pa, real.creep_fraction, real.mocap_rate_hz,
            real.mocap_latency_s, real.outlier_probability, real.dropout_duration_s) == (
        0.06, 0.015, 1e3, 0.15, 120.0, 0.008, 0.005, 0.5)
    assert (ideal.regulator_time_constant_s, ideal.regulator_dead_time_s, ideal.creep_fraction,
            ideal.outlier_probability, ideal.dropout_every_s) == (0.1, 0.0, 0.0, 0.0, 0.0)
    assert real.preview_s(50.0) == pytest.approx(0.015 + 0.06 + 0.01)
    assert ideal.preview_s(10.0) == pytest.approx(0.1 + 0.05)
    only = real.only('bellows creep')
    assert only.creep_fraction == 0.15 and only.regulator_dead_time_s == 0.0
    with pytest.raises(ValueError, match="effect 'wind'"):
        real.only('wind')
    with pytest.raises(ValueError, match='creep_fraction: 1.0 must be in'):
        real.replace(creep_fraction=1.0)
    with pytest.raises(ValueError, match='mocap_latency_s: -0.001 must be >= 0'):
        real.replace(mocap_latency_s=-0.001)
    with pytest.raises(ValueError, match='dropout_duration_s'):
        real.replace(dropout_duration_s=20.0)
    with pytest.raises(ValueError, match='outlier_max_m'):
        real.replace(outlier_max_m=0.001)
