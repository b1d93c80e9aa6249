"""nodes.contract: units, the pressure safety gate, input validation, recovery texts (no ROS)."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bellow_ancf_ros.nodes import contract
from bellow_ancf_ros.nodes.contract import InputError, UnsafePressureError

P_MIN, P_MAX = -50e3, 150e3


def test_helpers_do_not_import_rclpy():
    import subprocess
    code = ('import sys; import bellow_ancf_ros.nodes.contract, bellow_ancf_ros.nodes.worker; '
            'print(any(m == "rclpy" or m.startswith("rclpy.") for m in sys.modules))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[2])
    assert out.stdout.strip() == 'False'


# ------------------------------------------------------------------ units
def test_units_and_labels():
    assert contract.pressure_label() == 'actuator_pressure_gauge_pa'
    assert contract.pressure_label('kPa') == 'actuator_pressure_gauge_kpa'
    assert contract.unit_from_label('actuator_pressure_gauge_kpa') == 'kPa'
    assert contract.unit_from_label('actuator_pressure_gauge_pa') == 'Pa'
    assert contract.unit_from_label('pressures') is None
    assert contract.unit_from_label('') is None
    np.testing.assert_allclose(contract.to_unit([150e3, -50e3], 'kPa'), [150.0, -50.0])
    np.testing.assert_allclose(contract.from_unit([150.0, -50.0], 'kPa'), [150e3, -50e3])
    np.testing.assert_allclose(contract.to_unit([1.5], 'Pa'), [1.5])
    for bad in ('bar', 'pa', 'psi', ''):
        with pytest.raises(ValueError, match='pressure unit'):
            contract.check_unit(bad)
        with pytest.raises(ValueError):
            contract.pressure_label(bad)


def test_a_refused_parameter_names_its_key_its_value_and_what_is_allowed():
    for name, bad, allowed in (('pressure_unit', 'psi', "allowed: 'Pa' or 'kPa'"),
                               ('max_rate_hz', -1.0, 'allowed: a positive number of Hz'),
                               ('base_frame', '', 'allowed: a non-empty frame name'),
                               ('payload_kg', -0.5, 'must not be negative'),
                               ('robot_config', 'no_such_robot', 'no_such_robot')):
        reason = contract.parameter_problem(name, bad)
        assert reason.startswith(f'{name} = {bad!r} is not allowed') and allowed in reason
    for name, good in (('pressure_unit', 'kPa'), ('max_rate_hz', 20.0), ('base_frame', 'base'),
                       ('payload_kg', 0.05), ('robot_config', 'one_segment'), ('other', 1)):
        assert contract.parameter_problem(name, good) == ''


# ------------------------------------------------------------------ safety gate
def test_safe_pressures_accepts_and_returns_floats():
    p = contract.safe_pressures([0, 150e3, -50e3], P_MIN, P_MAX, 3)
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
        contract.safe_pressures(values, P_MIN, P_MAX, 3)


def test_safe_pressures_round_off_is_clipped_exactly():
    p = contract.safe_pressures([150e3 * (1 + 1e-13), -50e3 * (1 + 1e-13), 0.0], P_MIN, P_MAX)
    assert p[0] == P_MAX and p[1] == P_MIN
    with pytest.raises(UnsafePressureError):
        contract.safe_pressures([0.0], math.nan, P_MAX)
    with pytest.raises(UnsafePressureError):
        contract.safe_pressures([0.0], P_MAX, P_MIN)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=8))
def test_safe_pressures_never_lets_anything_unsafe_through(values):
    try:
        p = contract.safe_pressures(values, P_MIN, P_MAX, 6)
    except UnsafePressureError:
        return
    assert p.shape == (6,)
    assert np.all(np.isfinite(p)) and np.all(p >= P_MIN) and np.all(p <= P_MAX)


def test_vent_pressures():
    assert contract.vent_pressures(6, -50e3, 120e3).tolist() == [0.0] * 6
    # a robot whose limits exclude 0 Pa vents to the nearest limit
    assert contract.vent_pressures(3, 10e3, 120e3).tolist() == [10e3] * 3


def test_validate_pressure_input():
    p = contract.validate_pressure_input([150.0, -50.0, 0.0], 'kPa', 3, P_MIN, P_MAX,
                                         'actuator_pressure_gauge_kpa')
    np.testing.assert_allclose(p, [150e3, -50e3, 0.0])
    p = contract.validate_pressure_input([1.0, 2.0, 3.0], 'Pa', 3, P_MIN, P_MAX, None)
    np.testing.assert_allclose(p, [1.0, 2.0, 3.0])
    with pytest.raises(InputError, match='labelled'):
        contract.validate_pressure_input([150.0, 0, 0], 'Pa', 3, P_MIN, P_MAX,
                                         'actuator_pressure_gauge_kpa')
    with pytest.raises(InputError, match='labelled'):
        contract.validate_pressure_input([150e3, 0, 0], 'kPa', 3, P_MIN, P_MAX,
                                         'actuator_pressure_gauge_pa')
    with pytest.raises(InputError, match='outside'):
        contract.validate_pressure_input([150e3, 0, 0], 'kPa', 3, P_MIN, P_MAX)   # 150 MPa
    with pytest.raises(InputError, match='expected 3'):
        contract.validate_pressure_input([0, 0], 'Pa', 3, P_MIN, P_MAX)
    with pytest.raises(InputError, match='finite'):
        contract.validate_pressure_input([0, math.nan, 0], 'Pa', 3, P_MIN, P_MAX)


def test_validate_payload():
    assert contract.validate_payload(0.0) == 0.0
    assert contract.validate_payload(0.1) == 0.1
    assert contract.validate_payload(1) == 1.0
    for bad, match in ((-0.001, 'negative'), (1.5, 'maximum'), (math.nan, 'finite'),
                       (math.inf, 'finite'), (True, 'number'), ('0.1', 'number')):
        with pytest.raises(ValueError, match=match):
            contract.validate_payload(bad)


# ------------------------------------------------------------------ quaternions
def test_validate_target():
    pos, z = contract.validate_target([0.01, 0, 0.1], [0, 0, 0, 2], 'base', 'base', True)
    np.testing.assert_allclose(pos, [0.01, 0, 0.1])
    np.testing.assert_allclose(z, [0, 0, 1])
    pos, z = contract.validate_target([0.01, 0, 0.1], [0, 0, 0, 0], 'base', 'base', False)
    assert z is None        # orientation not used: not checked
    with pytest.raises(InputError, match="frame 'world'"):
        contract.validate_target([0, 0, 0.1], [0, 0, 0, 1], 'world', 'base', False)
    with pytest.raises(InputError, match='frame'):
        contract.validate_target([0, 0, 0.1], [0, 0, 0, 1], '', 'base', False)
    with pytest.raises(InputError, match='finite'):
        contract.validate_target([0, math.nan, 0.1], [0, 0, 0, 1], 'base', 'base', False)
    with pytest.raises(InputError, match='finite'):
        contract.validate_target([0, 0, math.inf], [0, 0, 0, 1], 'base', 'base', False)
    with pytest.raises(InputError, match='normalised'):
        contract.validate_target([0, 0, 0.1], [0, 0, 0, 0], 'base', 'base', True)


def test_recovery_texts_name_the_node_and_every_step():
    text = contract.configure_time_refusal('robot_config', '/ns/inv', 'active', 'one_segment')
    steps = ['ros2 lifecycle set /ns/inv deactivate', 'ros2 lifecycle set /ns/inv cleanup',
             'ros2 param set /ns/inv robot_config', 'ros2 lifecycle set /ns/inv configure',
             'ros2 lifecycle set /ns/inv activate']
    positions = [text.index(step) for step in steps]
    assert positions == sorted(positions)           # in the order they must be done
    assert "'one_segment'" in text
    assert 'deactivate' not in contract.configure_time_refusal('robot_config', '/inv', 'inactive',
                                                               'x')
    hint = contract.configure_failed_hint('/inv')
    assert 'stays unconfigured' in hint and 'ros2 lifecycle set /inv configure' in hint
