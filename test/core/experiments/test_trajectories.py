"""Reference trajectories: shapes, parameters, and reachability of the defaults.

Uses the session fixtures ``one`` / ``two`` (default robot models) of conftest.py.
"""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core import solve_inverse
from bellow_ancf_ros.core.experiments.trajectories import (
    MULTI_SEGMENT_TRAJECTORIES,
    ONE_SEGMENT_TRAJECTORIES,
    PAPER_BENDING_ANGLES_DEG,
    QUASI_STATIC_SPEED,
    TRAJECTORY_NAMES,
    default_parameters,
    trajectory,
    trajectory_parameters,
    workspace_estimate,
)


def test_names():
    assert set(ONE_SEGMENT_TRAJECTORIES) == {'space_spiral', 'space_rose', 'planar_circle',
                                             'planar_spiral', 'planar_rose'}
    assert set(MULTI_SEGMENT_TRAJECTORIES) == set(ONE_SEGMENT_TRAJECTORIES) | {'bending_circle'}
    assert TRAJECTORY_NAMES == MULTI_SEGMENT_TRAJECTORIES
    assert PAPER_BENDING_ANGLES_DEG == (0.0, 10.0, 20.0)


@pytest.mark.parametrize('name', ONE_SEGMENT_TRAJECTORIES)
def test_one_segment_shapes_closed_and_periodic(name, one):
    cfg = one.cfg
    p = default_parameters(name, cfg)
    T = p['period']
    t = np.linspace(0.0, T, 401)
    pos, z = trajectory(name, t, cfg)
    assert z is None
    assert pos.shape == (401, 3) and np.all(np.isfinite(pos))
    np.testing.assert_allclose(pos[0], pos[-1], atol=1e-12)           # closed
    pos2, _ = trajectory(name, t + 3 * T, cfg)                         # periodic
    np.testing.assert_allclose(pos, pos2, atol=1e-12)
    # continuous: no jump larger than the quasi-static speed allows (with slack)
    step = np.linalg.norm(np.diff(pos, axis=0), axis=1).max()
    assert step <= 4 * QUASI_STATIC_SPEED * (t[1] - t[0])
    c = np.asarray(p['center'])
    rho = np.linalg.norm(pos[:, :2] - c[:2], axis=1)
    assert rho.max() == pytest.approx(p['radius'], rel=1e-3)
    if name.startswith('planar'):
        np.testing.assert_allclose(pos[:, 2], c[2], atol=1e-15)
    else:
        # dome: centre height on the rim, up to height_amplitude above at the middle
        assert pos[:, 2].min() == pytest.approx(c[2], abs=1e-6)
        assert pos[:, 2].max() == pytest.approx(c[2] + p['height_amplitude'], rel=1e-3)
    if name == 'planar_circle':
        np.testing.assert_allclose(rho, p['radius'], rtol=1e-12)
    if 'spiral' in name or 'rose' in name:
        assert rho.min() < 1e-3 * p['radius']   # passes the centre


def test_shape_formulas_exact(one):
    cfg = one.cfg
    R, T = 0.01, 10.0
    c = (0.001, -0.002, 0.1)
    pos, _ = trajectory('planar_rose', [0.0, 1.25, 2.5], cfg, radius=R, period=T, center=c,
                        petals=2)
    # rho = R cos(2 phi): phi = 0 -> (R, 0); phi = pi/4 -> centre;
    # phi = pi/2 -> rho = -R at angle pi/2
    np.testing.assert_allclose(pos[0], [c[0] + R, c[1], c[2]], atol=1e-15)
    np.testing.assert_allclose(pos[1], c, atol=1e-15)
    np.testing.assert_allclose(pos[2], [c[0], c[1] - R, c[2]], atol=1e-15)
    pos, _ = trajectory('planar_spiral', [0.0, 5.0], cfg, radius=R, period=T, center=c, turns=3)
    np.testing.assert_allclose(pos[0], c, atol=1e-15)                       # starts at the centre
    # rim at half period, 1.5 turns
    np.testing.assert_allclose(pos[1], [c[0] - R, c[1], c[2]], atol=1e-15)
    pos, _ = trajectory('space_spiral', [0.0], cfg, radius=R, period=T, center=c,
                        height_amplitude=0.003)
    np.testing.assert_allclose(pos[0], [c[0], c[1], c[2] + 0.003], atol=1e-15)
    pos, _ = trajectory('planar_circle', 2.5, cfg, radius=R, period=T, height=0.095)
    np.testing.assert_allclose(pos[0], [0.0, R, 0.095], atol=1e-15)


@pytest.mark.parametrize('beta', PAPER_BENDING_ANGLES_DEG)
def test_bending_circle_angle_and_outward_tilt(beta, two):
    cfg = two.cfg
    t = np.linspace(0.0, 80.0, 97)
    pos, z = trajectory('bending_circle', t, cfg, bending_angle_deg=beta, period=80.0)
    assert z.shape == pos.shape == (97, 3)
    np.testing.assert_allclose(np.linalg.norm(z, axis=1), 1.0, rtol=1e-12)
    ang = np.degrees(np.arccos(np.clip(z[:, 2], -1, 1)))
    np.testing.assert_allclose(ang, beta, atol=1e-9)
    if beta > 0:
        # tilted radially outward: horizontal part of z parallel to the radius vector
        c = np.asarray(default_parameters('bending_circle', cfg, beta)['center'])
        radial = pos[:, :2] - c[:2]
        radial /= np.linalg.norm(radial, axis=1)[:, None]
        horiz = z[:, :2] / np.linalg.norm(z[:, :2], axis=1)[:, None]
        np.testing.assert_allclose(np.sum(radial * horiz, axis=1), 1.0, atol=1e-12)


def test_multi_segment_other_curves_have_vertical_axis(two):
    cfg = two.cfg
    for name in ONE_SEGMENT_TRAJECTORIES:
        _, z = trajectory(name, np.linspace(0, 50, 11), cfg)
        np.testing.assert_allclose(z, np.tile([0.0, 0.0, 1.0], (11, 1)), atol=1e-15)


def test_parameter_errors(one, two):
    cfg1 = one.cfg
    cfg2 = two.cfg
    with pytest.raises(ValueError, match='unknown trajectory'):
        trajectory('figure_eight', 0.0, cfg1)
    with pytest.raises(ValueError, match='two or more segments'):
        trajectory('bending_circle', 0.0, cfg1)
    with pytest.raises(ValueError, match='two or more segments'):
        trajectory('planar_circle', 0.0, cfg1, bending_angle_deg=10.0)
    with pytest.raises(ValueError, match='unknown trajectory parameter'):
        trajectory('planar_circle', 0.0, cfg1, radious=0.01)
    with pytest.raises(ValueError, match='radius'):
        trajectory('planar_circle', 0.0, cfg1, radius=-0.01)
    with pytest.raises(ValueError, match='period'):
        trajectory('planar_circle', 0.0, cfg1, period=0.0)
    with pytest.raises(ValueError, match='turns'):
        trajectory('planar_spiral', 0.0, cfg1, turns=1.5)
    with pytest.raises(ValueError, match='finite'):
        trajectory('planar_circle', [0.0, float('nan')], cfg1)
    with pytest.raises(ValueError, match='bending_angle_deg'):
        trajectory('bending_circle', 0.0, cfg2, bending_angle_deg=95.0)
    for name in ONE_SEGMENT_TRAJECTORIES:
        with pytest.raises(ValueError, match='bending_circle'):
            trajectory(name, 0.0, cfg2, bending_angle_deg=10.0)
    # names and paths work as config
    a, _ = trajectory('planar_circle', 1.0, 'one_segment')
    b, _ = trajectory('planar_circle', 1.0, cfg1.source)
    np.testing.assert_allclose(a, b)


def test_defaults_derived_from_config(one):
    cfg = one.cfg
    ws = workspace_estimate(cfg)
    # straight robot from stage 1: l0 * lam at the limits
    assert 0.0915 < ws['z_lo'] < 0.0925 and 0.107 < ws['z_hi'] < 0.1085
    p = default_parameters('planar_circle', cfg)
    # a longer robot gets a higher and wider default trajectory
    longer = cfg.replace(l0=cfg.l0 * 1.5)
    q = default_parameters('planar_circle', longer)
    assert q['center'][2] > 1.4 * p['center'][2]
    assert q['radius'] > 1.4 * p['radius']
    # period: quasi-static speed
    assert 2 * math.pi * p['radius'] / p['period'] <= QUASI_STATIC_SPEED


def _track(model, pos, z):
    """Inverse along samples (warm-started).

    Returns the worst position and angle errors, the smallest distance of a
    pressure to its limits [Pa] and the list of failed samples.
    """
    cfg = model.cfg
    warm, worst_p, worst_a, margin, bad = None, 0.0, 0.0, np.inf, []
    for i in range(len(pos)):
        inv = solve_inverse(model, pos[i], None if z is None else z[i], warm_start=warm)
        if not (inv.success and inv.reachable):
            bad.append((i, pos[i].tolist(), inv.message))
            warm = None
            continue
        assert np.all(np.isfinite(inv.pressures_pa))
        assert np.all(inv.pressures_pa >= cfg.p_min) and np.all(inv.pressures_pa <= cfg.p_max)
        worst_p = max(worst_p, inv.position_error_m)
        worst_a = max(worst_a, inv.angle_error_rad or 0.0)
        margin = min(margin, inv.pressures_pa.min() - cfg.p_min,
                     cfg.p_max - inv.pressures_pa.max())
        warm = inv
    return worst_p, worst_a, margin, bad


def _samples(name, cfg, n, **kw):
    period = default_parameters(name, cfg, kw.get('bending_angle_deg'))['period']
    return trajectory(name, np.arange(n) * period / n, cfg, **kw)


#: The defaults keep every pressure at least this far inside its limits [Pa]
#: (the larger copies only need to be reachable).
PRESSURE_MARGIN = 15e3


@pytest.mark.parametrize('name', ONE_SEGMENT_TRAJECTORIES)
@pytest.mark.parametrize('scale', [1.0, 1.15])
def test_one_segment_defaults_reachable_with_margin(name, scale, one):
    """Every default trajectory, and a copy 15 % larger, is reachable.

    Larger means radius and height amplitude scaled by 1.15.
    """
    model = one
    cfg = model.cfg
    p = default_parameters(name, cfg)
    pos, z = _samples(name, cfg, 24, radius=scale * p['radius'],
                      height_amplitude=scale * p['height_amplitude'])
    worst_p, _, margin, bad = _track(model, pos, z)
    assert not bad, bad
    assert worst_p < 1e-6
    if scale == 1.0:
        assert margin >= PRESSURE_MARGIN


@pytest.mark.parametrize('name,beta', [(n, 0.0) for n in ONE_SEGMENT_TRAJECTORIES]
                         + [('bending_circle', b) for b in PAPER_BENDING_ANGLES_DEG])
@pytest.mark.parametrize('scale', [1.0, 1.15])
def test_two_segment_defaults_reachable_with_margin(name, beta, scale, two):
    model = two
    cfg = model.cfg
    p = default_parameters(name, cfg, beta)
    pos, z = _samples(name, cfg, 16, radius=scale * p['radius'],
                      height_amplitude=scale * p['height_amplitude'], bending_angle_deg=beta)
    worst_p, worst_a, margin, bad = _track(model, pos, z)
    assert not bad, bad
    assert worst_p < 1e-6 and worst_a < 1e-6
    if scale == 1.0:
        assert margin >= PRESSURE_MARGIN


def test_trajectory_parameters_are_the_ones_used(two):
    cfg = two.cfg
    p = trajectory_parameters('bending_circle', cfg, bending_angle_deg=20.0, height=0.21)
    assert p['bending_angle_deg'] == 20.0
    assert p['center'] == (0.0, 0.0, 0.21)
    assert p['radius'] == default_parameters('bending_circle', cfg, 20.0)['radius']
    assert p['period'] == default_parameters('bending_circle', cfg, 20.0)['period']
    assert p['period'] != default_parameters('bending_circle', cfg)['period']   # 10 deg default
    # one period of samples closes the curve
    pos, _ = trajectory('bending_circle', [0.0, p['period']], cfg, bending_angle_deg=20.0)
    np.testing.assert_allclose(pos[0], pos[1], atol=1e-15)
    with pytest.raises(ValueError, match='unknown trajectory parameter'):
        trajectory_parameters('planar_circle', cfg, radios=1.0)


def test_lead_in_goes_from_the_held_pose_to_the_path_smoothly():
    from bellow_ancf_ros.core.experiments import lead_in
    from bellow_ancf_ros.core.geometry import angle_between
    p0, p1 = np.array([0.0, 0.0, 0.1]), np.array([0.013, 0.0, 0.098])
    z0, z1 = np.array([0.0, 0.0, 1.0]), np.array([np.sin(0.2), 0.0, np.cos(0.2)])
    f = np.linspace(0.0, 1.0, 201)
    poses = [lead_in(p0, z0, p1, z1, v) for v in f]
    pos = np.array([p for p, _ in poses])
    np.testing.assert_allclose(pos[0], p0, atol=1e-15)
    np.testing.assert_allclose(pos[-1], p1, atol=1e-15)
    np.testing.assert_allclose(poses[-1][1], z1, atol=1e-12)
    step = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    assert np.all(np.diff(np.linalg.norm(pos - p0, axis=1)) >= -1e-15)   # monotone
    assert step[0] < 0.01 * step.max() and step[-1] < 0.01 * step.max()  # rests at both ends
    assert step.max() <= 1.9 * np.linalg.norm(p1 - p0) / 200             # min-jerk peak 1.875
    ang = [angle_between(z, z1) for _, z in poses]
    assert np.all(np.diff(ang) <= 1e-12)
    assert lead_in(p0, None, p1, None, 0.5)[1] is None


def test_spin_up_starts_at_rest_and_joins_the_path_at_full_speed():
    from bellow_ancf_ros.core.experiments import spin_up
    d, h = 2.0, 1e-4
    assert spin_up(0.0, d) == 0.0 and spin_up(-1.0, d) == -1.0
    speed = lambda t: (spin_up(t + h, d) - spin_up(t - h, d)) / (2 * h)  # noqa: E731
    assert abs(speed(h)) < 1e-6 and speed(d) == pytest.approx(1.0, abs=1e-6)
    assert spin_up(d, d) == pytest.approx(d / 2) and spin_up(5.0, d) == pytest.approx(4.0)
    acc = [(speed(t + h) - speed(t - h)) / (2 * h) for t in (2 * h, d - 2 * h)]
    assert max(abs(a) for a in acc) < 1e-2            # no jump of acceleration at either end
    ts = np.linspace(0, d, 201)
    assert np.all(np.diff([spin_up(t, d) for t in ts]) >= 0)   # never backwards
    assert spin_up(3.0, 0.0) == 3.0
    with pytest.raises(ValueError, match='spin_up_s'):
        spin_up(1.0, -1.0)


def test_spin_down_mirrors_the_spin_up():
    from bellow_ancf_ros.core.experiments import spin_down, spin_up
    d, h = 2.0, 1e-4
    speed = lambda s: (spin_down(s + h, d) - spin_down(s - h, d)) / (2 * h)  # noqa: E731
    assert spin_down(0.0, d) == 0.0 and spin_down(d, d) == pytest.approx(d / 2)
    assert speed(2 * h) == pytest.approx(1.0, abs=1e-3) and abs(speed(d - 2 * h)) < 1e-3
    assert spin_down(9.0, d) == pytest.approx(d / 2)      # at rest after it
    for s in np.linspace(0, d, 11):   # the spin-up run backwards
        assert spin_down(s, d) == pytest.approx(d / 2 - spin_up(d - s, d))


@pytest.mark.parametrize("name,config,params", [
    ("planar_circle", "one_segment", {"period": 2.0}),
    ("bending_circle", "two_segment", {"period": 4.0, "bending_angle_deg": 10.0}),
    ("space_rose", "two_segment", {"height": 0.2}),
])
def test_trajectory_target_is_the_trajectory_with_its_parameters_merged_once(
        monkeypatch, name, config, params):
    """``trajectory_target(t)`` gives :func:`trajectory`'s pose at t without re-merging.

    The defaults cost a stage-1 set-up (about 1 ms, 40 % of a closed-loop
    simulation's CPU when it was done at every control step): the target
    function merges the parameters once, when it is made.
    """
    from bellow_ancf_ros.core.experiments import trajectories as tr
    times = [0.0, 0.37, 1.9, 7.25]
    expected = [trajectory(name, t, config, **params) for t in times]
    target = tr.trajectory_target(name, config, **params)

    def merged_again(*args, **kwargs):
        raise AssertionError("parameters merged again")
    monkeypatch.setattr(tr, "_merge", merged_again)
    for t, (pos, z) in zip(times, expected):
        got_p, got_z = target(t)
        np.testing.assert_array_equal(got_p, pos[0])
        if z is None:
            assert got_z is None
        else:
            np.testing.assert_array_equal(got_z, z[0])
