"""Message-free helpers of the nodes (bellow_ancf_ros.nodes.common): no ROS needed."""

import math
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bellow_ancf_ros.nodes import common
from bellow_ancf_ros.nodes.common import InputError, UnsafePressureError

P_MIN, P_MAX = -50e3, 150e3


def test_common_does_not_import_rclpy():
    import subprocess
    code = ('import sys; import bellow_ancf_ros.nodes.common; '
            'print(any(m == "rclpy" or m.startswith("rclpy.") for m in sys.modules))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[1])
    assert out.stdout.strip() == 'False'


# ------------------------------------------------------------------ units
def test_units_and_labels():
    assert common.pressure_label() == 'actuator_pressure_gauge_pa'
    assert common.pressure_label('kPa') == 'actuator_pressure_gauge_kpa'
    assert common.unit_from_label('actuator_pressure_gauge_kpa') == 'kPa'
    assert common.unit_from_label('actuator_pressure_gauge_pa') == 'Pa'
    assert common.unit_from_label('pressures') is None
    assert common.unit_from_label('') is None
    np.testing.assert_allclose(common.to_unit([150e3, -50e3], 'kPa'), [150.0, -50.0])
    np.testing.assert_allclose(common.from_unit([150.0, -50.0], 'kPa'), [150e3, -50e3])
    np.testing.assert_allclose(common.to_unit([1.5], 'Pa'), [1.5])
    for bad in ('bar', 'pa', 'psi', ''):
        with pytest.raises(ValueError, match='pressure unit'):
            common.check_unit(bad)
        with pytest.raises(ValueError):
            common.pressure_label(bad)


# ------------------------------------------------------------------ safety gate
def test_safe_pressures_accepts_and_returns_floats():
    p = common.safe_pressures([0, 150e3, -50e3], P_MIN, P_MAX, 3)
    assert p.dtype == float and p.tolist() == [0.0, 150e3, -50e3]


@pytest.mark.parametrize('values,match', [
    ([math.nan, 0, 0], 'not a finite'),
    ([0, math.inf, 0], 'not a finite'),
    ([0, 0, -math.inf], 'not a finite'),
    ([150.001e3, 0, 0], 'outside the limits'),
    ([0, -50.001e3, 0], 'outside the limits'),
    ([1e12, 0, 0], 'outside the limits'),
    ([0, 0], 'expected 3'),
    ([0, 0, 0, 0], 'expected 3'),
    ([], 'empty'),
    (['a', 0, 0], 'not numbers'),
])
def test_safe_pressures_refuses(values, match):
    with pytest.raises(UnsafePressureError, match=match):
        common.safe_pressures(values, P_MIN, P_MAX, 3)


def test_safe_pressures_round_off_is_clipped_exactly():
    p = common.safe_pressures([150e3 * (1 + 1e-13), -50e3 * (1 + 1e-13), 0.0], P_MIN, P_MAX)
    assert p[0] == P_MAX and p[1] == P_MIN
    with pytest.raises(UnsafePressureError):
        common.safe_pressures([0.0], math.nan, P_MAX)
    with pytest.raises(UnsafePressureError):
        common.safe_pressures([0.0], P_MAX, P_MIN)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=8))
def test_safe_pressures_never_lets_anything_unsafe_through(values):
    try:
        p = common.safe_pressures(values, P_MIN, P_MAX, 6)
    except UnsafePressureError:
        return
    assert p.shape == (6,)
    assert np.all(np.isfinite(p)) and np.all(p >= P_MIN) and np.all(p <= P_MAX)


def test_vent_pressures():
    assert common.vent_pressures(6, -50e3, 120e3).tolist() == [0.0] * 6
    # a robot whose limits exclude 0 Pa vents to the nearest limit
    assert common.vent_pressures(3, 10e3, 120e3).tolist() == [10e3] * 3


def test_validate_pressure_input():
    p = common.validate_pressure_input([150.0, -50.0, 0.0], 'kPa', 3, P_MIN, P_MAX,
                                       'actuator_pressure_gauge_kpa')
    np.testing.assert_allclose(p, [150e3, -50e3, 0.0])
    p = common.validate_pressure_input([1.0, 2.0, 3.0], 'Pa', 3, P_MIN, P_MAX, None)
    np.testing.assert_allclose(p, [1.0, 2.0, 3.0])
    with pytest.raises(InputError, match='labelled'):
        common.validate_pressure_input([150.0, 0, 0], 'Pa', 3, P_MIN, P_MAX,
                                       'actuator_pressure_gauge_kpa')
    with pytest.raises(InputError, match='labelled'):
        common.validate_pressure_input([150e3, 0, 0], 'kPa', 3, P_MIN, P_MAX,
                                       'actuator_pressure_gauge_pa')
    with pytest.raises(InputError, match='outside'):
        common.validate_pressure_input([150e3, 0, 0], 'kPa', 3, P_MIN, P_MAX)   # 150 MPa
    with pytest.raises(InputError, match='expected 3'):
        common.validate_pressure_input([0, 0], 'Pa', 3, P_MIN, P_MAX)
    with pytest.raises(InputError, match='finite'):
        common.validate_pressure_input([0, math.nan, 0], 'Pa', 3, P_MIN, P_MAX)


def test_validate_payload():
    assert common.validate_payload(0.0) == 0.0
    assert common.validate_payload(0.1) == 0.1
    assert common.validate_payload(1) == 1.0
    for bad, match in ((-0.001, 'negative'), (1.5, 'maximum'), (math.nan, 'finite'),
                       (math.inf, 'finite'), (True, 'number'), ('0.1', 'number')):
        with pytest.raises(ValueError, match=match):
            common.validate_payload(bad)


# ------------------------------------------------------------------ quaternions
def _rot(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def test_z_axis_from_quaternion_known_values():
    np.testing.assert_allclose(common.z_axis_from_quaternion([0, 0, 0, 1]), [0, 0, 1])
    s = math.sqrt(0.5)
    # +90 deg about x: z -> -y ; +90 deg about y: z -> +x
    np.testing.assert_allclose(common.z_axis_from_quaternion([s, 0, 0, s]), [0, -1, 0], atol=1e-15)
    np.testing.assert_allclose(common.z_axis_from_quaternion([0, s, 0, s]), [1, 0, 0], atol=1e-15)
    # rotation about z does not move the z-axis; scaling is normalised away
    np.testing.assert_allclose(common.z_axis_from_quaternion([0, 0, 5 * s, 5 * s]), [0, 0, 1],
                               atol=1e-15)


@pytest.mark.parametrize('q,match', [
    ([0, 0, 0, 0], 'normalised'),
    ([1e-9, 0, 0, 0], 'normalised'),
    ([math.nan, 0, 0, 1], 'NaN or inf'),
    ([0, math.inf, 0, 1], 'NaN or inf'),
    ([0, 0, 1], '4 components'),
])
def test_bad_quaternions_refused(q, match):
    with pytest.raises(InputError, match=match):
        common.z_axis_from_quaternion(q)
    with pytest.raises(InputError):
        common.quaternion_to_rotation(q)


def test_quaternion_rotation_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(200):
        R = _rot(rng.normal(size=3), rng.uniform(-math.pi, math.pi))
        q = common.quaternion_from_rotation(R)
        assert q[3] >= 0 and abs(np.linalg.norm(q) - 1) < 1e-12
        np.testing.assert_allclose(common.quaternion_to_rotation(q), R, atol=1e-12)
        np.testing.assert_allclose(common.z_axis_from_quaternion(q), R[:, 2], atol=1e-12)
    # the near-half-turn branches
    for axis in ([1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]):
        R = _rot(axis, math.pi)
        back = common.quaternion_to_rotation(common.quaternion_from_rotation(R))
        np.testing.assert_allclose(back, R, atol=1e-12)


def test_quaternion_from_z_axis():
    rng = np.random.default_rng(1)
    for z in list(rng.normal(size=(100, 3))) + [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, 0, 1e-3]]:
        z = np.asarray(z, float)
        q = common.quaternion_from_z_axis(z)
        np.testing.assert_allclose(common.z_axis_from_quaternion(q), z / np.linalg.norm(z),
                                   atol=1e-12)
    # smallest rotation: no twist about z, i.e. the rotation axis is horizontal
    q = common.quaternion_from_z_axis([math.sin(0.3), 0, math.cos(0.3)])
    assert q[2] == 0.0
    assert common.angle_between(common.quaternion_to_rotation(q)[:, 1], [0, 1, 0]) < 1e-12
    with pytest.raises(ValueError):
        common.quaternion_from_z_axis([0, 0, 0])


def test_angle_between():
    assert common.angle_between([0, 0, 1], [0, 0, 2]) == 0.0
    assert common.angle_between([0, 0, 1], [0, 1, 0]) == pytest.approx(math.pi / 2)
    assert common.angle_between([0, 0, 1], [0, 0, -1]) == pytest.approx(math.pi)
    assert common.angle_between([1, 0, 0], [1, 1e-9, 0]) == pytest.approx(1e-9, rel=1e-6)


# ------------------------------------------------------------------ targets
def test_validate_target():
    pos, z = common.validate_target([0.01, 0, 0.1], [0, 0, 0, 2], 'base', 'base', True)
    np.testing.assert_allclose(pos, [0.01, 0, 0.1])
    np.testing.assert_allclose(z, [0, 0, 1])
    pos, z = common.validate_target([0.01, 0, 0.1], [0, 0, 0, 0], 'base', 'base', False)
    assert z is None        # orientation not used: not checked
    with pytest.raises(InputError, match="frame 'world'"):
        common.validate_target([0, 0, 0.1], [0, 0, 0, 1], 'world', 'base', False)
    with pytest.raises(InputError, match='frame'):
        common.validate_target([0, 0, 0.1], [0, 0, 0, 1], '', 'base', False)
    with pytest.raises(InputError, match='finite'):
        common.validate_target([0, math.nan, 0.1], [0, 0, 0, 1], 'base', 'base', False)
    with pytest.raises(InputError, match='finite'):
        common.validate_target([0, 0, math.inf], [0, 0, 0, 1], 'base', 'base', False)
    with pytest.raises(InputError, match='normalised'):
        common.validate_target([0, 0, 0.1], [0, 0, 0, 0], 'base', 'base', True)


# ------------------------------------------------------------------ latest-only worker
def _wait(pred, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.002)
    return False


def test_latest_worker_processes_only_the_newest():
    gate = threading.Event()
    seen = []

    def process(item):
        seen.append(item)
        if item == 0:
            gate.wait(5.0)      # block on the first item while more arrive

    w = common.LatestWorker(process)
    try:
        w.submit(0)
        assert _wait(lambda: seen == [0])
        for i in range(1, 1001):
            w.submit(i)
        assert w.pending
        gate.set()
        assert _wait(lambda: w.idle())
        assert seen == [0, 1000]
        assert w.submitted == 1001 and w.processed == 2 and w.dropped == 999
    finally:
        w.stop()


def test_latest_worker_bounds_the_rate():
    starts = []
    w = common.LatestWorker(lambda item: starts.append(time.monotonic()), min_period=lambda: 0.05)
    try:
        for i in range(5):
            w.submit(i)
            assert _wait(lambda: w.idle())
        assert len(starts) == 5
        assert np.min(np.diff(starts)) >= 0.05 - 1e-3
    finally:
        w.stop()


def test_latest_worker_survives_exceptions_and_stops():
    errors, seen = [], []

    def process(item):
        if item == 'boom':
            raise RecursionError('deep')
        seen.append(item)

    w = common.LatestWorker(process, on_error=errors.append)
    w.submit('boom')
    assert _wait(lambda: w.idle() and errors)
    assert isinstance(errors[0], RecursionError)
    w.submit('ok')
    assert _wait(lambda: seen == ['ok'])
    assert w.wait_idle(1.0)
    w.stop()
    assert not w._thread.is_alive()
    w.submit('after stop')        # harmless, never processed
    time.sleep(0.05)
    assert seen == ['ok']


# ------------------------------------------------------------ solve statistics
def test_solve_stats_summary_window_and_age():
    now = [100.0]
    stats = common.SolveStats(window=4, clock=lambda: now[0])
    s = stats.summary()
    assert s['count'] == 0 and s['last_solve_age_s'] is None and s['median_s'] is None
    for dt in (0.001, 0.002, 0.003, 0.004, 0.010):
        now[0] += 1.0
        stats.record(dt, ok=dt < 0.01)
    now[0] += 0.25
    s = stats.summary()
    assert s['count'] == 5 and s['failures'] == 1 and s['window'] == 4   # oldest dropped
    assert s['last_s'] == 0.010 and s['max_s'] == 0.010 and s['last_ok'] is False
    assert s['median_s'] == pytest.approx(0.0035)
    assert s['p95_s'] == pytest.approx(np.percentile([0.002, 0.003, 0.004, 0.010], 95))
    assert s['last_solve_age_s'] == pytest.approx(0.25)
    assert stats.times() == [0.002, 0.003, 0.004, 0.010]


def test_recovery_texts_name_the_node_and_every_step():
    text = common.configure_time_refusal('robot_config', '/ns/inv', 'active', 'one_segment')
    steps = ['ros2 lifecycle set /ns/inv deactivate', 'ros2 lifecycle set /ns/inv cleanup',
             'ros2 param set /ns/inv robot_config', 'ros2 lifecycle set /ns/inv configure',
             'ros2 lifecycle set /ns/inv activate']
    positions = [text.index(step) for step in steps]
    assert positions == sorted(positions)           # in the order they must be done
    assert "'one_segment'" in text
    assert 'deactivate' not in common.configure_time_refusal('robot_config', '/inv', 'inactive',
                                                             'x')
    hint = common.configure_failed_hint('/inv')
    assert 'stays unconfigured' in hint and 'ros2 lifecycle set /inv configure' in hint
