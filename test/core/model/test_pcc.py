"""The piecewise-constant-curvature baseline (core/pcc.py) against the ANCF model."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward
from bellow_ancf_ros.core.model._pcc import PccModel, arc_parameters, arc_state, arc_transform

NO_GRAVITY = (0.0, 0.0, 0.0)


@pytest.mark.parametrize('s, beta, phi', [(0.1, 0.0, 0.0), (0.1, 0.3, 0.0), (0.09, 0.5, 2.0),
                                          (0.11, 1e-7, -1.0), (0.1, 0.2, -2.5)])
def test_arc_parameters_invert_the_arc(s, beta, phi):
    angles = 2 * np.pi * np.arange(3) / 3 + 0.2
    R = 0.02
    lengths = s - R * beta * np.cos(angles - phi)
    s2, b2, p2 = arc_parameters(lengths, angles, R)
    assert s2 == pytest.approx(s, rel=1e-12)
    assert b2 == pytest.approx(beta, rel=1e-9, abs=1e-13)  # cancellation: eps * s / R
    if beta > 1e-6:
        assert math.remainder(p2 - phi, 2 * np.pi) == pytest.approx(0.0, abs=1e-9)


def test_arc_end_is_on_a_circle_tangent_to_the_base_axis():
    s, beta, phi = 0.1, 0.6, 0.7
    p, R = arc_transform(s, beta, phi)
    kappa = beta / s
    centre = np.array([np.cos(phi), np.sin(phi), 0.0]) / kappa
    assert np.linalg.norm(p - centre) == pytest.approx(1.0 / kappa, rel=1e-12)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-14)
    assert R[:, 2] @ np.array([0, 0, 1.0]) == pytest.approx(np.cos(beta))
    # the end tangent is perpendicular to the radius through the end
    assert abs(R[:, 2] @ (p - centre)) < 1e-14
    # small-angle branch is continuous with the exact one
    p0, _ = arc_transform(s, 1e-5, phi)
    p1, _ = arc_transform(s, 1.0001e-4, phi)
    assert np.linalg.norm(p0 - np.array([0, 0, s])) < 1e-6 and np.isfinite(p1).all()


@pytest.mark.parametrize('name', ['one_segment', 'two_segment'])
def test_pure_elongation_without_gravity_agrees_with_ancf(name):
    cfg = load_robot(name).replace(gravity=NO_GRAVITY)
    model, pcc = RobotModel(cfg), PccModel(cfg)
    for p in (cfg.p_min, 0.0, 0.5 * cfg.p_max, cfg.p_max):
        P = np.full(model.A, p)
        fw = solve_forward(model, P)
        pc = pcc.forward(P)
        assert fw.converged
        assert np.linalg.norm(fw.position - pc.position) < 1e-9
        assert np.allclose(fw.rotation, pc.rotation, atol=1e-9)


def test_rotation_convention_matches_ancf_with_tool_and_theta0(two_cfg):
    seg2 = two_cfg.segments[1].__class__(**{**two_cfg.segments[1].__dict__,
                                            'theta0': math.radians(40.0)})
    cfg = two_cfg.replace(gravity=NO_GRAVITY, tool_length=0.012,
                          segments=(two_cfg.segments[0], seg2))
    P = np.full(6, 60e3)
    fw = solve_forward(RobotModel(cfg), P)
    pc = PccModel(cfg).forward(P)
    assert np.linalg.norm(fw.position - pc.position) < 1e-9
    assert np.allclose(fw.rotation, pc.rotation, atol=1e-9)
    t0 = math.radians(40)
    assert pc.rotation[:, 0] == pytest.approx([math.cos(t0), math.sin(t0), 0.0])


def test_bending_goes_the_same_way_as_ancf_and_is_of_similar_size(one_cfg):
    cfg = one_cfg.replace(gravity=NO_GRAVITY)
    for P in ([150e3, -50e3, -50e3], [0.0, 100e3, 0.0], [100e3, 100e3, -50e3]):
        fw = solve_forward(RobotModel(cfg), P)
        pc = PccModel(cfg).forward(P)
        a, b = fw.position[:2], pc.position[:2]
        cos = a @ b / (np.linalg.norm(a) * np.linalg.norm(b))
        assert cos > 0.9999  # same bending plane
        # PCC ignores the actuators' axial stiffness in stage 2: it bends more, but not wildly
        assert 1.0 < np.linalg.norm(b) / np.linalg.norm(a) < 1.35


def test_pcc_disagrees_with_ancf_under_payload(one_cfg, two_cfg):
    for cfg, P in ((one_cfg, np.full(3, 50e3)), (two_cfg, np.r_[120e3, 0, 0, 120e3, 0, 0])):
        model, pcc = RobotModel(cfg), PccModel(cfg)
        pc = pcc.forward(P)
        d = [np.linalg.norm(solve_forward(model, P, payload_kg=m).position - pc.position)
             for m in (0.0, 0.05, 0.1)]
        print(cfg.name, 'ANCF - PCC [mm]:', np.round(np.array(d) * 1e3, 3))
        assert d[0] < d[1] < d[2]
        assert d[2] > 0.5e-3
    # the two-segment robot bent under 100 g: centimetres
    assert d[2] > 20e-3


def test_one_segment_inverse_is_the_exact_inverse(one_cfg):
    pcc = PccModel(one_cfg)
    for P in ([150e3, -50e3, -50e3], [10e3, 80e3, 33e3], [0.0, 0.0, 0.0]):
        pose = pcc.forward(P)
        p, ok, pose2 = pcc.inverse(pose.position)
        assert ok
        assert np.allclose(p, P, atol=1e-6)
        assert np.linalg.norm(pose2.position - pose.position) < 1e-12


def test_two_segment_inverse_meets_position_and_axis(two_cfg):
    pcc = PccModel(two_cfg)
    P = np.array([110e3, -20e3, 30e3, 0.0, 90e3, 10e3])
    pose = pcc.forward(P)
    p, ok, pose2 = pcc.inverse(pose.position, pose.z_axis)
    assert ok
    assert np.linalg.norm(pose2.position - pose.position) < 1e-9
    assert np.all((p >= two_cfg.p_min - 1e-6) & (p <= two_cfg.p_max + 1e-6))


def test_unreachable_target_stays_within_the_limits(one_cfg):
    pcc = PccModel(one_cfg)
    p, ok, _ = pcc.inverse([0.08, 0.0, 0.08])
    assert not ok
    assert np.all((p >= one_cfg.p_min) & (p <= one_cfg.p_max))
    with pytest.raises(ValueError):
        pcc.inverse([0.0, 0.0, -0.05])


@pytest.mark.parametrize('name', ['one_segment', 'two_segment'])
def test_arc_state_meets_every_constraint_and_starts_near_the_equilibrium(name):
    """The cold start: constraints exact, the straight robot at lam = 1, the PCC pose."""
    model = RobotModel(load_robot(name))
    nq = model.nq
    np.testing.assert_allclose(arc_state(model, np.ones(model.A)),
                               model.straight_state(np.ones(model.A)), rtol=0, atol=1e-14)
    rng = np.random.default_rng(4)
    st = model.stage1
    for _ in range(3):
        lam = rng.uniform(st.lam_min, st.lam_max, model.A)
        x = arc_state(model, lam)
        r = model.evaluate(x, lam, 0.0, 0.0, jacobian=False).residual * model.residual_scale
        assert np.max(np.abs(r[nq:])) < 1e-12  # attachments, parallelism, orthonormality
        # the end plate is where the PCC model puts it
        pcc = PccModel(model.cfg).forward_stretch(lam)
        p, D = model.end_effector(x[:nq])
        np.testing.assert_allclose(p, pcc.position, atol=1e-12)
        np.testing.assert_allclose(D, pcc.rotation, atol=1e-12)
        # much nearer the equilibrium than the straight robot (load included)
        fw = solve_forward(model, st.pressure(lam))
        assert fw.converged
        d_arc = np.max(np.abs(fw.x[:nq] - x[:nq]))
        d_straight = np.max(np.abs(fw.x[:nq] - model.straight_state(lam)[:nq]))
        assert d_arc < 0.5 * d_straight, (d_arc, d_straight)
