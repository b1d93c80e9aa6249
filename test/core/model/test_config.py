"""Tests of the robot description loader (bellow_ancf_ros/core/config.py)."""

import copy
import dataclasses
import math
from pathlib import Path

import numpy as np
from numpy.polynomial import Polynomial
import pytest
import yaml

from bellow_ancf_ros.core import geometry
from bellow_ancf_ros.core.model import _config as config_mod
from bellow_ancf_ros.core.model import (ConfigError, RobotConfig, SegmentConfig, config_dirs,
                                        find_shipped, load_robot, robot_from_dict,
                                        shipped_robot_names)

REPO_CONFIG = Path(__file__).resolve().parents[3] / 'config'


@pytest.fixture
def one():
    """The shipped one-segment description as a plain dict."""
    return yaml.safe_load((REPO_CONFIG / 'one_segment.yaml').read_text())


@pytest.fixture
def two():
    return yaml.safe_load((REPO_CONFIG / 'two_segment.yaml').read_text())


def refused(d, *keys):
    """Assert ``d`` is refused and every key is named in the message; return it."""
    with pytest.raises(ConfigError) as info:
        robot_from_dict(d)
    message = str(info.value)
    for key in keys:
        assert key in message, message
    return info.value


# -------------------------------------------------------------- shipped files
def check_default_actuator(cfg):
    """docs/model.md section 5, in SI."""
    assert cfg.l0 == pytest.approx(0.0963)
    assert cfg.stiffness_coeffs == (28.9, 576.94)
    assert cfg.d_eff == pytest.approx(8.087e-3, rel=1e-15)
    assert cfg.d_a == pytest.approx(17.90e-3, rel=1e-15)
    assert cfg.rho0 == pytest.approx(0.20)
    assert cfg.n_elements == 6
    assert cfg.gravity == (0.0, 0.0, -9.81)
    assert cfg.tool_length == 0.0
    assert cfg.payload == 0.0
    seg = cfg.segments[0]
    assert seg.n_actuators == 3
    assert seg.pitch_radius == pytest.approx(0.020, rel=1e-15)
    assert seg.theta0 == 0.0
    assert seg.plate_fractions == pytest.approx((1 / 3, 2 / 3), rel=1e-15)
    assert seg.constraint_plate_mass == pytest.approx(0.004)
    assert seg.top_plate_mass == pytest.approx(0.010)
    assert seg.connector_height == 0.0 and seg.connector_mass == 0.0


def test_one_segment_matches_spec():
    cfg = load_robot('one_segment')
    check_default_actuator(cfg)
    assert cfg.name == 'one_segment'
    assert cfg.n_segments == 1
    assert cfg.n_actuators_total == 3
    assert cfg.actuator_slices == [slice(0, 3)]
    assert (cfg.p_min, cfg.p_max) == (-50e3, 150e3)
    assert Path(cfg.source).name == 'one_segment.yaml'


def test_two_segment_matches_spec():
    cfg = load_robot('two_segment')
    check_default_actuator(cfg)
    assert cfg.name == 'two_segment'
    assert cfg.n_segments == 2
    assert cfg.n_actuators_total == 6
    assert cfg.actuator_slices == [slice(0, 3), slice(3, 6)]
    assert (cfg.p_min, cfg.p_max) == (-50e3, 120e3)
    seg2 = cfg.segments[1]
    assert seg2.connector_height == pytest.approx(0.015, rel=1e-15)
    assert seg2.connector_mass == pytest.approx(0.020)
    assert seg2.theta0 == 0.0
    assert seg2.n_actuators == 3 and seg2.pitch_radius == pytest.approx(0.020)
    np.testing.assert_allclose(seg2.actuator_angles, [0.0, 2 * math.pi / 3, 4 * math.pi / 3])


def test_load_by_path_and_name_agree(tmp_path):
    by_name = load_robot('two_segment')
    by_path = load_robot(REPO_CONFIG / 'two_segment.yaml')
    by_str = load_robot(str(REPO_CONFIG / 'two_segment.yaml'))
    assert by_name == by_path == by_str
    copy_path = tmp_path / 'robot.yml'
    copy_path.write_text((REPO_CONFIG / 'two_segment.yaml').read_text())
    copied = load_robot(copy_path)
    assert copied.source == str(copy_path)
    # the same robot, named by its file (test_a_robot_loaded_from_a_path_is_named_by_its_file)
    assert copied.name == 'robot' and copied == dataclasses.replace(by_name, name='robot')


def test_shipped_names_and_search_order():
    assert {'one_segment', 'two_segment'} <= set(shipped_robot_names())
    assert REPO_CONFIG in config_dirs()
    shipped = find_shipped('one_segment').read_text()
    assert shipped == (REPO_CONFIG / 'one_segment.yaml').read_text()


def test_shipped_search_falls_back_to_sys_prefix(tmp_path, monkeypatch):
    share = tmp_path / 'share' / 'bellow_ancf_ros' / 'config'
    share.mkdir(parents=True)
    (share / 'only_here.yaml').write_text((REPO_CONFIG / 'one_segment.yaml').read_text())
    monkeypatch.setattr(config_mod.sys, 'prefix', str(tmp_path))
    assert find_shipped('only_here') == share / 'only_here.yaml'
    assert load_robot('only_here').name == 'one_segment'


def test_a_robot_loaded_from_a_path_is_named_by_its_file(tmp_path, monkeypatch):
    """A copied shipped file keeps 'name: one_segment' inside: logs would say one_segment."""
    path = tmp_path / 'lab_robot_3.yaml'
    path.write_text((REPO_CONFIG / 'one_segment.yaml').read_text())
    cfg = load_robot(path)
    assert cfg.name == 'lab_robot_3' and cfg.source == str(path)
    assert cfg == dataclasses.replace(load_robot('one_segment'), name='lab_robot_3')
    assert cfg.to_dict()['name'] == 'lab_robot_3'   # written back under its own name
    monkeypatch.chdir(tmp_path)
    assert load_robot('./lab_robot_3.yaml').name == 'lab_robot_3'
    assert load_robot(str(REPO_CONFIG / 'two_segment.yaml')).name == 'two_segment'
    assert load_robot('two_segment').name == 'two_segment'   # a shipped name: unchanged


def test_dataclasses_are_frozen_and_replace_works():
    cfg = load_robot('one_segment')
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.payload = 1.0
    heavier = cfg.replace(payload=0.1, stiffness_coeffs=[1.0, 2.0])
    assert heavier.payload == 0.1 and cfg.payload == 0.0
    assert heavier.stiffness_coeffs == (1.0, 2.0)
    assert isinstance(cfg.segments[0], SegmentConfig)
    assert isinstance(cfg, RobotConfig)
    hash(cfg)


def test_to_dict_round_trip():
    for name in ('one_segment', 'two_segment'):
        cfg = load_robot(name)
        again = robot_from_dict(cfg.to_dict())
        assert again.source == '<dict>' and again.name == cfg.name
        for f in dataclasses.fields(RobotConfig):
            if f.name not in ('source', 'segments', 'name', 'mocap_frame', 'first_mode_error'):
                assert getattr(again, f.name) == pytest.approx(getattr(cfg, f.name), rel=1e-15)
        assert again.mocap_frame is None and cfg.mocap_frame is None
        assert again.first_mode_error is None and cfg.first_mode_error is None
        for s_a, s_b in zip(again.segments, cfg.segments):
            for f in dataclasses.fields(SegmentConfig):
                if getattr(s_b, f.name) is None:
                    assert getattr(s_a, f.name) is None
                else:
                    assert getattr(s_a, f.name) == pytest.approx(getattr(s_b, f.name),
                                                                 rel=1e-15)


def test_dynamics_keys_defaults_round_trip_and_refusals():
    """damping_time_s, mass_damping_per_s (section dynamics) and plate_radius_mm (per segment)."""
    d = load_robot('one_segment').to_dict()
    del d['dynamics']
    cfg = robot_from_dict(d)
    assert cfg.damping_time == 0.005 and cfg.mass_damping == 0.0
    # default disc radius: the actuators' outer edge, R + D_a/2
    assert cfg.plate_radius_of(0) == pytest.approx(0.020 + 0.0179 / 2, rel=1e-12)
    d['dynamics'] = {'damping_time_s': 0.01, 'mass_damping_per_s': 0.5}
    d['segments'][0]['plate_radius_mm'] = 35.0
    cfg = robot_from_dict(d)
    assert (cfg.damping_time, cfg.mass_damping) == (0.01, 0.5)
    assert cfg.plate_radius_of(0) == pytest.approx(0.035)
    again = robot_from_dict(cfg.to_dict())
    assert again.segments[0].plate_radius == pytest.approx(0.035)
    assert (again.damping_time, again.mass_damping) == (0.01, 0.5)
    assert again.first_mode_error is None and 'first_mode_error' not in again.to_dict()['dynamics']
    d['dynamics']['first_mode_error'] = -0.021   # measured (identify damping)
    assert robot_from_dict(robot_from_dict(d).to_dict()).first_mode_error == -0.021
    for key, value, words in (('damping_time_s', -1.0, 'dynamics.damping_time_s'),
                              ('first_mode_error', 1.5, 'dynamics.first_mode_error: 1.5 is '
                               'not from -0.5 to 1'),
                              ('first_mode_error', 'x', 'dynamics.first_mode_error'),
                              ('mass_damping_per_s', 'x', 'dynamics.mass_damping_per_s'),
                              ('damping_s', 0.1, "did you mean 'damping_time_s'")):
        bad = load_robot('one_segment').to_dict()
        bad['dynamics'] = {key: value}
        with pytest.raises(ConfigError, match=words.replace('.', r'\.').replace("'", "'")):
            robot_from_dict(bad)
    bad = load_robot('one_segment').to_dict()
    bad['segments'][0]['plate_radius_mm'] = 0.0
    with pytest.raises(ConfigError, match=r'segments\[0\]\.plate_radius_mm'):
        robot_from_dict(bad)


def test_mocap_frame_entry_validated_and_round_tripped(one):
    """Optional ``mocap_frame``: the base's pose in the mocap frame; its quaternion normalised."""
    one['mocap_frame'] = {'frame_id': 'world', 'position_m': [0.1, -0.2, 0.3],
                          'quaternion_xyzw': [0.0, 0.0, 2.0, 2.0]}
    cfg = robot_from_dict(one)
    mf = cfg.mocap_frame
    assert mf.frame_id == 'world' and mf.position == (0.1, -0.2, 0.3)
    np.testing.assert_allclose(mf.quaternion_xyzw, [0, 0, np.sqrt(0.5), np.sqrt(0.5)])
    assert robot_from_dict(cfg.to_dict()) == cfg
    # a point 0.1 m above the base origin, seen in the mocap frame, back in the base frame
    p, q = mf.to_base(np.array([0.1, -0.2, 0.4]), mf.quaternion_xyzw)
    np.testing.assert_allclose(p, [0, 0, 0.1], atol=1e-15)
    np.testing.assert_allclose(np.abs(q), [0, 0, 0, 1], atol=1e-12)
    # from_base is its inverse (what a mocap in that frame sees of a base-frame pose)
    R_pose = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    p_m, R_m = mf.from_base([0.01, 0.02, 0.1], R_pose)
    p_b, q_b = mf.to_base(p_m, geometry.quaternion_from_rotation(R_m))
    np.testing.assert_allclose(p_b, [0.01, 0.02, 0.1], atol=1e-15)
    np.testing.assert_allclose(geometry.quaternion_to_rotation(q_b), R_pose, atol=1e-12)
    one['mocap_frame'] = {'frame_id': '', 'position_m': [0, 0],
                          'quaternion_xyzw': [0, 0, 0, 0], 'frame': 'x'}
    with pytest.raises(ConfigError) as e:
        robot_from_dict(one)
    text = str(e.value)
    for key in ('mocap_frame.frame_id', 'mocap_frame.position_m',
                'mocap_frame.quaternion_xyzw', "mocap_frame.frame: unknown key; did you mean"):
        assert key in text, text


def test_ints_are_accepted_for_floats(one):
    one['segments'][0]['pitch_radius_mm'] = 20
    one['payload_kg'] = 0
    one['pressure_limits'] = {'p_min_kpa': -50, 'p_max_kpa': 150}
    cfg = robot_from_dict(one)
    assert cfg.segments[0].pitch_radius == pytest.approx(0.02)
    assert isinstance(cfg.payload, float)


def test_unit_conversion(one):
    one['segments'][0]['theta0_deg'] = 90.0
    one['model']['tool_length_mm'] = 25.0
    one['payload_kg'] = 0.05
    cfg = robot_from_dict(one)
    assert cfg.segments[0].theta0 == pytest.approx(math.pi / 2)
    assert cfg.tool_length == pytest.approx(0.025)
    assert cfg.payload == 0.05


def test_third_order_stiffness_accepted(one):
    one['actuator']['stiffness_coeffs_n_per_m'] = [28.9, 576.94, 120.0, 900.0]
    cfg = robot_from_dict(one)
    assert cfg.stiffness_coeffs == (28.9, 576.94, 120.0, 900.0)


def test_no_plates_accepted(one):
    one['segments'][0]['constraint_plate_fractions'] = []
    assert robot_from_dict(one).segments[0].plate_fractions == ()


# --------------------------------------------------------------------- errors
@pytest.mark.parametrize('path, key', [
    (('name',), 'name'),
    (('actuator', 'd_eff_mm'), 'actuator.d_eff_mm'),
    (('segments', 0, 'pitch_radius_mm'), 'segments[0].pitch_radius_mm'),
    (('pressure_limits', 'p_max_kpa'), 'pressure_limits.p_max_kpa'),
    (('model', 'gravity_m_per_s2'), 'model.gravity_m_per_s2'),
    (('payload_kg',), 'payload_kg'),
    (('actuator',), 'actuator'),
])
def test_missing_key(one, path, key):
    parent = one
    for p in path[:-1]:
        parent = parent[p]
    del parent[path[-1]]
    err = refused(one, key, 'missing')
    assert err.key == key


@pytest.mark.parametrize('path, value, key', [
    (('payload_kg',), True, 'payload_kg'),
    (('actuator', 'l0_m'), 'long', 'actuator.l0_m'),
    (('actuator', 'd_a_mm'), None, 'actuator.d_a_mm'),
    (('segments', 0, 'n_actuators'), 3.0, 'segments[0].n_actuators'),
    (('segments', 0, 'n_actuators'), True, 'segments[0].n_actuators'),
    (('model', 'n_elements'), 6.5, 'model.n_elements'),
    (('model', 'gravity_m_per_s2'), [0.0, 0.0], 'model.gravity_m_per_s2'),
    (('model', 'gravity_m_per_s2'), [0.0, False, -9.81], 'model.gravity_m_per_s2[1]'),
    (('actuator', 'stiffness_coeffs_n_per_m'), 576.94, 'actuator.stiffness_coeffs_n_per_m'),
    (('actuator', 'stiffness_coeffs_n_per_m'), [28.9, '576.94'],
     'actuator.stiffness_coeffs_n_per_m[1]'),
    (('segments', 0, 'constraint_plate_fractions'), '1/3',
     'segments[0].constraint_plate_fractions'),
    (('name',), 42, 'name'),
    (('pressure_limits',), [-50, 150], 'pressure_limits'),
    (('actuator', 'd_eff_mm'), float('nan'), 'actuator.d_eff_mm'),
    (('segments', 0, 'theta0_deg'), float('inf'), 'segments[0].theta0_deg'),
])
def test_wrong_type_or_not_finite(one, path, value, key):
    parent = one
    for p in path[:-1]:
        parent = parent[p]
    parent[path[-1]] = value
    err = refused(one, key)
    assert err.key == key


@pytest.mark.parametrize('path, value, key', [
    (('actuator', 'l0_m'), 0.0, 'actuator.l0_m'),
    (('actuator', 'l0_m'), -0.1, 'actuator.l0_m'),
    (('actuator', 'd_eff_mm'), 0, 'actuator.d_eff_mm'),
    (('actuator', 'd_a_mm'), -17.9, 'actuator.d_a_mm'),
    (('segments', 0, 'pitch_radius_mm'), 0.0, 'segments[0].pitch_radius_mm'),
    (('actuator', 'linear_density_kg_per_m'), -0.2, 'actuator.linear_density_kg_per_m'),
    (('segments', 0, 'constraint_plate_mass_kg'), -0.004, 'segments[0].constraint_plate_mass_kg'),
    (('segments', 0, 'top_plate_mass_kg'), -1e-9, 'segments[0].top_plate_mass_kg'),
    (('payload_kg',), -0.05, 'payload_kg'),
    (('model', 'tool_length_mm'), -1.0, 'model.tool_length_mm'),
    (('segments', 0, 'n_actuators'), 2, 'segments[0].n_actuators'),
    (('model', 'n_elements'), 0, 'model.n_elements'),
])
def test_out_of_range_values(one, path, value, key):
    parent = one
    for p in path[:-1]:
        parent = parent[p]
    parent[path[-1]] = value
    err = refused(one, key)
    assert err.key == key


def test_zero_masses_and_density_are_allowed(one):
    one['actuator']['linear_density_kg_per_m'] = 0.0
    one['segments'][0]['top_plate_mass_kg'] = 0
    assert robot_from_dict(one).rho0 == 0.0


@pytest.mark.parametrize('p_min, p_max', [(150.0, 150.0), (200.0, 150.0)])
def test_pressure_limits_order(one, p_min, p_max):
    one['pressure_limits'] = {'p_min_kpa': p_min, 'p_max_kpa': p_max}
    err = refused(one, 'pressure_limits.p_min_kpa', 'pressure_limits.p_max_kpa')
    assert err.key == 'pressure_limits.p_min_kpa'


@pytest.mark.parametrize('where, bad, good', [
    ((), 'payload', 'payload_kg'),
    (('actuator',), 'd_eff', 'd_eff_mm'),
    (('segments', 0), 'pitch_radius_m', 'pitch_radius_mm'),
    (('pressure_limits',), 'p_max_kPa', 'p_max_kpa'),
    (('model',), 'n_element', 'n_elements'),
])
def test_unknown_key_with_suggestion(one, where, bad, good):
    parent = one
    for p in where:
        parent = parent[p]
    parent[bad] = 1.0
    prefix = ''.join(f'[{p}]' if isinstance(p, int) else f'.{p}' for p in where).lstrip('.')
    full = f'{prefix}.{bad}' if prefix else bad
    err = refused(one, full, 'unknown key', repr(good))
    assert err.key == full


def test_unknown_key_without_close_match_lists_allowed(one):
    one['model']['zzz'] = 1
    refused(one, 'model.zzz', 'allowed keys', 'n_elements')


@pytest.mark.parametrize('fractions', [
    [0.6666, 0.3333], [0.5, 0.5], [0.0, 0.5], [0.5, 1.0], [-0.1], [1.2], [0.2, 0.5, 0.4],
])
def test_plate_fractions(one, fractions):
    one['segments'][0]['constraint_plate_fractions'] = fractions
    refused(one, 'segments[0].constraint_plate_fractions')


def test_empty_stiffness_polynomial(one):
    one['actuator']['stiffness_coeffs_n_per_m'] = []
    refused(one, 'actuator.stiffness_coeffs_n_per_m', 'empty')


def test_non_monotonic_stiffness_refused(one):
    # dP/dlam < 0 for lam in (1.04, 1.06), inside [p_min, p_max]
    x = Polynomial(np.array([0.0024, -0.05, 1.0 / 3.0]) * 250000.0)
    one['actuator']['stiffness_coeffs_n_per_m'] = [float(c) for c in x(Polynomial([-1, 1])).coef]
    err = refused(one, 'actuator.stiffness_coeffs_n_per_m', 'monotonic')
    assert err.key == 'actuator.stiffness_coeffs_n_per_m'


def test_saturating_stiffness_refused(one):
    # k = 600 - 8000 (lam-1)^2: P(lam) peaks at ~118.6 kPa < p_max = 150 kPa
    k = Polynomial([600.0, 0.0, -8000.0])(Polynomial([-1, 1]))
    one['actuator']['stiffness_coeffs_n_per_m'] = [float(c) for c in k.coef]
    refused(one, 'actuator.stiffness_coeffs_n_per_m', 'monotonic')
    one['pressure_limits']['p_max_kpa'] = 100.0           # below the peak: fine
    robot_from_dict(one)


def test_negative_stiffness_refused(one):
    one['actuator']['stiffness_coeffs_n_per_m'] = [-700.0, 100.0]
    refused(one, 'actuator.stiffness_coeffs_n_per_m')


def test_connector_keys_forbidden_on_first_segment(one):
    one['segments'][0]['connector_height_mm'] = 15.0
    err = refused(one, 'segments[0].connector_height_mm', 'first segment')
    assert err.key == 'segments[0].connector_height_mm'


def test_connector_keys_required_on_later_segments(two):
    del two['segments'][1]['connector_height_mm']
    del two['segments'][1]['connector_mass_kg']
    err = refused(two, 'segments[1].connector_height_mm', 'segments[1].connector_mass_kg')
    assert len(err.issues) == 2


@pytest.mark.parametrize('key, value', [
    ('connector_height_mm', 0.0), ('connector_height_mm', -15.0), ('connector_mass_kg', -0.02),
    ('connector_height_mm', 'high'),
])
def test_connector_values(two, key, value):
    two['segments'][1][key] = value
    refused(two, f'segments[1].{key}')


@pytest.mark.parametrize('segments, key', [
    ([], 'segments'), ('seg', 'segments'), ({'n_actuators': 3}, 'segments'), ([7], 'segments[0]'),
])
def test_segment_list_shape(one, segments, key):
    one['segments'] = segments
    err = refused(one, key)
    assert err.key == key


def test_top_level_not_a_mapping():
    for value in (None, [], 'robot', 3):
        refused(value, 'expected a mapping')


def test_all_problems_reported_together(two):
    two['actuator']['l0_m'] = -1
    two['segments'][1]['n_actuators'] = 1
    two['model']['n_elements'] = 'six'
    two['extra'] = 1
    err = refused(two, 'actuator.l0_m', 'segments[1].n_actuators', 'model.n_elements', 'extra')
    assert len(err.issues) == 4
    assert isinstance(err, ValueError)
    # one line, as every error of the package ("<dict>: 4 problems: a; b; ...")
    message = str(err)
    assert '\n' not in message and ':;' not in message, message
    assert message.startswith('<dict>: 4 problems: '), message
    assert all(f'{key}: {reason}' in message for key, reason in err.issues), message


# ------------------------------------------------------------------ file level
def test_unknown_shipped_name():
    with pytest.raises(ConfigError) as info:
        load_robot('five_segment')
    message = str(info.value)
    assert 'five_segment' in message
    assert 'one_segment' in message and 'two_segment' in message


def test_missing_file(tmp_path):
    path = tmp_path / 'nope.yaml'
    with pytest.raises(ConfigError) as info:
        load_robot(path)
    assert str(path) in str(info.value)
    assert 'one_segment' in str(info.value)


def test_yaml_syntax_error(tmp_path):
    path = tmp_path / 'broken.yaml'
    path.write_text('name: broken\nactuator: {l0_m: 0.0963,\n')
    with pytest.raises(ConfigError) as info:
        load_robot(path)
    assert 'broken.yaml' in str(info.value)
    assert 'YAML' in str(info.value)


def test_duplicate_yaml_key(tmp_path):
    text = (REPO_CONFIG / 'one_segment.yaml').read_text() + 'payload_kg: 0.1\n'
    path = tmp_path / 'dup.yaml'
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_robot(path)
    assert 'duplicate' in str(info.value) and 'dup.yaml' in str(info.value)


def test_file_errors_name_the_key_and_file(tmp_path, one):
    bad = copy.deepcopy(one)
    bad['segments'][0]['pitch_radius_mm'] = -20.0
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(bad))
    with pytest.raises(ConfigError) as info:
        load_robot(path)
    assert str(path) in str(info.value)
    assert 'segments[0].pitch_radius_mm' in str(info.value)
    assert info.value.source == str(path)


# ------------------------------------------------ element counts and plates
TENTHS = [round(0.1 * k, 10) for k in range(1, 10)]


def test_element_counts_that_cannot_carry_the_plates_are_refused(one):
    one['model']['n_elements'] = 2
    err = refused(one, 'model.n_elements', 'smallest count that works is 3')
    assert err.key == 'model.n_elements'
    one['model']['n_elements'] = 1
    refused(one, 'model.n_elements', 'smallest count that works is 3')
    one['model']['n_elements'] = 6
    one['segments'][0]['constraint_plate_fractions'] = TENTHS
    refused(one, 'model.n_elements', 'smallest count that works is 10')
    one['model']['n_elements'] = 10
    assert robot_from_dict(one).n_elements == 10


def test_robot_model_refuses_the_same_counts(one_cfg, two_cfg):
    from bellow_ancf_ros.core import RobotModel
    for cfg in (one_cfg, two_cfg):
        for n in (1, 2):
            with pytest.raises(ConfigError, match='smallest count that works is 3') as info:
                RobotModel(cfg, n)
            assert info.value.key == 'model.n_elements'
        assert RobotModel(cfg, 3).n == 3


def test_plates_too_close_for_any_count_name_the_fractions(one):
    one['segments'][0]['constraint_plate_fractions'] = [0.5, 0.5 + 1e-6, 0.5 + 2e-6]
    refused(one, 'segments[0].constraint_plate_fractions', 'too close')


@pytest.mark.parametrize('fractions, accepted', [
    ([1 / 3, 2 / 3], [3, 4, 5, 6, 7, 8]),
    (TENTHS, [10, 11, 12]),
    ([0.5], [2, 3, 4, 5, 6]),
    ([0.25, 0.5, 0.75], [4, 5, 6, 7, 8]),
    ([0.3, 0.7], [3, 4, 5, 6]),
    ([0.45, 0.55], [3, 4, 5, 6]),
    ([0.2], [2, 3, 4, 5, 6]),
    ([], [1, 2, 3]),
])
def test_every_accepted_count_matches_a_fine_reference(one_cfg, fractions, accepted):
    """Accepted counts are accurate (< 0.5 mm at the extremes); the smaller ones are refused."""
    from bellow_ancf_ros.core import RobotModel, solve_forward
    seg = dataclasses.replace(one_cfg.segments[0], plate_fractions=tuple(fractions))
    cfg = one_cfg.replace(segments=(seg,))
    for n in range(1, accepted[0]):
        assert config_mod.plate_support_problem(fractions, n) is not None, n
    assert [n for n in range(1, accepted[-1] + 1)
            if config_mod.plate_support_problem(fractions, n) is None] == accepted
    cases = [([150e3, -50e3, -50e3], 0.1), ([-50e3, 150e3, 40e3], 0.0)]
    fine = RobotModel(cfg, 60)
    refs = [solve_forward(fine, p, m).position for p, m in cases]
    for n in accepted:
        model = RobotModel(cfg, n)
        for (p, m), ref in zip(cases, refs):
            fw = solve_forward(model, p, m)
            assert fw.converged and fw.stable, (n, fw.message)
            assert np.linalg.norm(fw.position - ref) < 0.5e-3, (n, p, fw.position - ref)


def test_every_accepted_count_matches_a_fine_reference_two_segments(two_cfg):
    from bellow_ancf_ros.core import RobotModel, solve_forward
    p = [120e3, -50e3, -50e3, 120e3, -50e3, -50e3]
    ref = solve_forward(RobotModel(two_cfg, 36), p).position
    for n in range(3, 9):
        fw = solve_forward(RobotModel(two_cfg, n), p)
        assert fw.converged and fw.stable, (n, fw.message)
        assert np.linalg.norm(fw.position - ref) < 0.01 * 0.2076, n  # 1 % of the robot length


# ------------------------------------------ robustness: only ConfigError (issue 36)
def test_issue36_file_loads(tmp_path, one):
    """Stage 1's Newton swung forever between two iterates at p_min of this valid file."""
    one['actuator']['stiffness_coeffs_n_per_m'] = [28.9, 576.94, -260.83722699795754,
                                                   298.82506635307084]
    one['pressure_limits'] = {'p_min_kpa': -268.35083388056347, 'p_max_kpa': 23.49094129759813}
    path = tmp_path / 'issue36.yaml'
    path.write_text(yaml.safe_dump(one))
    cfg = load_robot(path)
    from bellow_ancf_ros.core import Stage1
    s = Stage1.from_config(cfg)
    assert s.lam_min == pytest.approx(0.5423, abs=1e-4)
    assert s.lam_max == pytest.approx(1.0189, abs=1e-4)
    assert s.pressure(s.lam_min) == pytest.approx(cfg.p_min, rel=1e-12)


@pytest.mark.parametrize('where, value, key', [
    (('model', 'n_elements'), 10 ** 12, 'model.n_elements'),          # was: memory exhausted
    (('pressure_limits', 'p_max_kpa'), 1e306, 'pressure_limits.p_max_kpa'),   # inf in Pa
    (('actuator', 'd_eff_mm'), 1.7e308, 'actuator.d_eff_mm'),         # was: OverflowError
    (('actuator', 'd_eff_mm'), 1e-320, 'actuator.d_eff_mm'),          # was: ZeroDivisionError
    (('actuator', 'stiffness_coeffs_n_per_m'), [28.9, 576.94, 1e308],
     'actuator.stiffness_coeffs_n_per_m'),                            # k(1 + x) overflows
])
def test_values_that_leave_the_float_range_name_their_key(one, where, value, key):
    one[where[0]][where[1]] = value
    assert refused(one, key).key == key


def test_a_stiffness_whose_square_overflows_loads_rigid(one):
    """k(1)**2 overflows (was: OverflowError): the actuator does not stretch at any pressure."""
    from bellow_ancf_ros.core import Stage1
    one['actuator']['stiffness_coeffs_n_per_m'] = [1e232]
    s = Stage1.from_config(robot_from_dict(one))
    assert s.lam_min == s.lam_max == 1.0


def _random_value(rng):
    """A value of any YAML type, plausible or hostile."""
    pool = [0.0, -0.0, 5e-324, 1e-320, 1.7e308, -1.7e308, math.nan, math.inf, -math.inf,
            0, 1, -1, 3, 10 ** 30, 2 ** 63, True, False, None, '', 'abc', '1.0', [], [1.0, 2.0],
            {'x': 1.0}, float(rng.normal() * 10.0 ** rng.uniform(-300, 300)),
            float(rng.normal() * 10.0 ** rng.uniform(-3, 3)), int(rng.integers(-5, 2000))]
    return pool[rng.integers(len(pool))]


def _random_coeffs(rng):
    """k(lam) of the issue-36 family, of random sizes, or monotone by construction."""
    kind, degree = rng.integers(4), int(rng.integers(0, 7))
    if kind == 0:
        return [28.9, 576.94] + rng.uniform(-600.0, 600.0, rng.integers(0, 4)).tolist()
    if kind in (1, 2):
        spread = 6.0 if kind == 1 else 300.0
        return (rng.normal(size=degree + 1)
                * 10.0 ** rng.uniform(-spread / 2, spread, degree + 1)).tolist()
    dh = Polynomial([10.0 ** rng.uniform(0.0, 4.0)])       # h' > 0 everywhere
    for _ in range(rng.integers(1, 4)):
        r, s = rng.uniform(-1.0, 2.0), abs(rng.normal()) * 10.0 ** rng.uniform(-4.0, 0.0)
        dh = dh * Polynomial([r * r + s * s, -2.0 * r, 1.0])
    h = dh.integ()
    return Polynomial(h.coef[1:])(Polynomial([-1.0, 1.0])).coef.tolist()


def _paths(d, prefix=()):
    """Every key path of a nested description."""
    items = d.items() if isinstance(d, dict) else enumerate(d) if isinstance(d, list) else ()
    for k, v in items:
        yield prefix + (k,)
        yield from _paths(v, prefix + (k,))


def _random_robot(rng, bases):
    d = copy.deepcopy(bases[rng.integers(len(bases))])
    if rng.random() < 0.7:
        d['actuator']['stiffness_coeffs_n_per_m'] = _random_coeffs(rng)
    if rng.random() < 0.6:
        d['pressure_limits'] = {'p_min_kpa': -10.0 ** rng.uniform(-3.0, 3.5),
                                'p_max_kpa': 10.0 ** rng.uniform(-3.0, 3.5)}
    for _ in range(rng.integers(0, 4)):
        paths = list(_paths(d))
        path = paths[rng.integers(len(paths))]
        parent = d
        for k in path[:-1]:
            parent = parent[k]
        if isinstance(parent, dict) and rng.random() < 0.15:
            del parent[path[-1]]
        else:
            parent[path[-1]] = _random_value(rng)
    return d


@pytest.mark.parametrize('seed', [36, 3600, 36000])
def test_random_robot_files_load_or_raise_config_error(tmp_path, seed):
    """Seeded fuzz of robot files: every outcome is a RobotConfig or a one-line ConfigError.

    Random stiffness polynomials (any order and size, mixed signs), pressure
    limits, and hostile values, deleted keys and wrong types anywhere; every
    tenth file goes through YAML and ``load_robot``.
    """
    from bellow_ancf_ros.core import Stage1
    rng = np.random.default_rng(seed)
    bases = [yaml.safe_load((REPO_CONFIG / f'{n}.yaml').read_text())
             for n in ('one_segment', 'two_segment', 'three_segment')]
    outcomes = {'ok': 0, 'refused': 0}
    for i in range(120):
        d = _random_robot(rng, bases)
        try:
            if i % 10 == 0:
                path = tmp_path / f'fuzz{i}.yaml'
                path.write_text(yaml.safe_dump(d))
                cfg = load_robot(path)
            else:
                cfg = robot_from_dict(d)
        except ConfigError as exc:
            outcomes['refused'] += 1
            assert '\n' not in str(exc) and exc.key, str(exc)
            continue
        outcomes['ok'] += 1
        s = Stage1.from_config(cfg)
        assert s.lam_min <= s.lam_max
    assert outcomes['ok'] > 10 and outcomes['refused'] > 10, outcomes
