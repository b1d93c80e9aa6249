"""The robot as a force sensor (issue 20, item 3): TipForceEstimator on the simulated robot.

One segment, the simulated robot's own robot file as the estimator's model
(a calibrated model), 0.15 mm motion-capture noise, 4 s of samples at
100 Hz: a tip force comes back within 0.02 N sideways and 0.05 N vertically,
a 30 g payload within 5 g, and the truth lies inside three standard
deviations (the first seeds, not chosen).
"""

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot
from bellow_ancf_ros.core.sim import PlantEffects, SimulatedRobot
from bellow_ancf_ros.core.control import TipForceEstimator

PRESSURES = [30e3, 10e3, 50e3]


def _run(estimator, sim, seconds=4.0, rate=100.0):
    for _ in range(int(seconds * rate)):
        sim.step(1.0 / rate)
        pos, R = sim.measure()
        assert estimator.update(sim.pressures_pa, pos, R[:, 2], time_s=sim.time_s)
    return estimator.estimate()


def _settled_robot(seed, **kw):
    # the clean robot: the estimator is a quasi-static sensor (creep would still be moving it)
    sim = SimulatedRobot('one_segment_mismatched', seed=seed, effects=PlantEffects.ideal(), **kw)
    sim.command(PRESSURES)
    for _ in range(150):
        sim.step(0.01)
    return sim


@pytest.fixture(scope='module')
def calibrated():
    return RobotModel(load_robot('one_segment_mismatched'))


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_tip_force_is_recovered_within_its_standard_deviations(calibrated, seed):
    truth = np.array([0.05, -0.03, -0.1])
    sim = _settled_robot(seed)
    sim.set_tip_force(truth)
    est = _run(TipForceEstimator(calibrated), sim)
    err = est.force_n - truth
    assert np.all(np.abs(err[:2]) < 0.02) and abs(err[2]) < 0.05, err
    assert np.all(np.abs(err) < 3 * est.std_n), (err, est.std_n)
    assert est.samples == 400 and est.refused == 0 and est.blind == []


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_an_unknown_payload_is_weighed(calibrated, seed):
    sim = _settled_robot(seed, payload_kg=0.03)
    est = _run(TipForceEstimator(calibrated, mode='mass'), sim)
    assert abs(est.payload_kg - 0.03) < 0.005
    assert abs(est.payload_kg - 0.03) < 3 * est.payload_std_kg
    np.testing.assert_allclose(est.force_n, est.payload_kg * calibrated.gravity)


def test_one_sample_cannot_see_the_vertical_force_many_can(calibrated):
    sim = _settled_robot(3)
    est = TipForceEstimator(calibrated)
    pos, R = sim.measure()
    est.update(sim.pressures_pa, pos, R[:, 2])
    first = est.estimate()
    # sideways about 0.02 N from one sample; vertically (0.55 mm/N) far more
    assert first.std_n[2] > 0.05 > max(first.std_n[:2])
    assert len(first.blind) == 1 and abs(first.blind[0][2]) > 0.9
    assert _run(est, sim, seconds=2.0).blind == []


def test_tare_zeroes_the_reading_and_a_push_shows_after_it(calibrated):
    sim = _settled_robot(4)
    sim.set_tip_force([0.0, 0.02, 0.0])        # a cable pulling on the tool, say
    est = TipForceEstimator(calibrated, force_rate=0.01)
    _run(est, sim, seconds=2.0)
    est.tare()
    assert np.allclose(est.estimate().force_n, 0.0)
    sim.set_tip_force([0.05, 0.02, 0.0])       # a push of 0.05 N along x on top
    e = _run(est, sim, seconds=2.0)
    assert abs(e.force_n[0] - 0.05) < 0.02 and abs(e.force_n[1]) < 0.02


def test_bad_samples_are_refused_and_counted_bad_settings_named(calibrated):
    est = TipForceEstimator(calibrated)
    assert not est.update(PRESSURES, [np.nan, 0.0, 0.1])
    assert not est.update([1e9, 0.0, 0.0], [0.0, 0.0, 0.1])
    assert not est.update([0.0, 0.0], [0.0, 0.0, 0.1])
    assert est.refused == 3 and est.samples == 0 and 'bad sample' in est.last_reason
    assert np.all(est.estimate().force_n == 0.0)
    with pytest.raises(ValueError, match="mode 'torque' is not allowed; allowed: force, mass"):
        TipForceEstimator(calibrated, mode='torque')
    with pytest.raises(ValueError, match='position_noise_m = -1'):
        TipForceEstimator(calibrated, position_noise_m=-1)


def test_an_outlier_is_refused_and_moves_nothing(calibrated):
    sim = _settled_robot(6)
    est = TipForceEstimator(calibrated)
    for _ in range(20):
        pos, R = sim.measure()
        assert est.update(sim.pressures_pa, pos, R[:, 2])
    before = est.estimate().force_n.copy()
    pos, R = sim.measure()
    assert not est.update(sim.pressures_pa, pos + np.array([0.0, 0.02, 0.0]), R[:, 2])
    assert 'outlier' in est.last_reason and est.refused == 1
    np.testing.assert_array_equal(est.estimate().force_n, before)


def test_an_uncalibrated_model_reads_a_force_that_is_not_there():
    """Why the estimator needs the calibrated robot file.

    The default model on the mismatched robot reads its model error as a force.
    """
    sim = _settled_robot(5)
    est = _run(TipForceEstimator(RobotModel(load_robot('one_segment'))), sim, seconds=1.0)
    assert np.linalg.norm(est.force_n[:2]) > 0.02
