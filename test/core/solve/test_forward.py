"""Forward kinetostatic problem: physics, convergence, robustness, stability."""

import numpy as np
import pytest

from bellow_ancf_ros.core import (ForwardStatus, RobotModel, load_robot, solve_forward,
                                  solve_inverse)
from bellow_ancf_ros.core.solve import _newton as solver


def _extreme(model):
    p = np.full(model.A, model.cfg.p_min)
    p[0] = model.cfg.p_max
    return p


def test_newton_converges_quadratically(one, two, monkeypatch):
    monkeypatch.setattr(solver, "CHORD_BELOW", 0.0)  # Newton steps only
    for model in (one, two):
        fw = solve_forward(model, _extreme(model) * 0.3)
        h = np.array(fw.history)
        print(f"{model.cfg.name}: scaled residual per Newton iteration:",
              " ".join(f"{v:.1e}" for v in h))
        assert fw.converged and h[-1] < 1e-10
        # in the final phase each residual is at most ~C * previous^2
        tail = h[np.argmax(h < 1e-2):]
        assert len(tail) >= 3, h
        for a, b in zip(tail[:-1], tail[1:]):
            assert b <= 100.0 * a**2 or b < 1e-12, h
        # the order estimate log(r_k+1)/log(r_k) approaches 2
        orders = np.log(tail[1:]) / np.log(tail[:-1])
        assert orders.max() > 1.8, (h, orders)


def test_chord_steps_near_the_solution_cut_the_residual_and_change_nothing(one, two,
                                                                           monkeypatch,
                                                                           factorisations):
    for model in (one, two):
        p = _extreme(model)
        factorisations.clear()
        fw = solve_forward(model, p)
        n_fast = len(factorisations)
        h = np.array(fw.history)
        assert fw.converged and fw.stable and h[-1] < 1e-10
        # every step below CHORD_BELOW cuts the residual by CHORD_CUT at least (chord or Newton)
        tail = h[np.argmax(h <= solver.CHORD_BELOW):]
        assert all(b <= solver.CHORD_CUT * a or b < 1e-10 for a, b in zip(tail[:-1], tail[1:]))
        factorisations.clear()
        with monkeypatch.context() as mp:
            mp.setattr(solver, "CHORD_BELOW", 0.0)
            ref = solve_forward(model, p)
        assert n_fast < len(factorisations)  # chord steps saved factorisations
        assert np.linalg.norm(fw.position - ref.position) < 1e-9
        # the Jacobian returned is the one at the solution (stability, sensitivities)
        ev = model.evaluate(fw.x, fw.stretch, 1.0, 0.0, jacobian=True)
        assert abs(fw.jacobian - ev.jacobian).max() == 0.0


@pytest.mark.parametrize("p_kpa", [-50.0, 0.0, 80.0, 150.0])
def test_equal_pressures_give_pure_elongation_and_exact_length_without_gravity(p_kpa):
    cfg = load_robot("one_segment").replace(gravity=(0.0, 0.0, 0.0))
    model = RobotModel(cfg)
    fw = solve_forward(model, np.full(3, p_kpa * 1e3))
    lam = model.stage1.stretch(p_kpa * 1e3)
    assert np.hypot(*fw.position[:2]) < 1e-12
    assert fw.position[2] == pytest.approx(lam * cfg.l0, rel=1e-12)
    np.testing.assert_allclose(fw.z_axis, [0, 0, 1], atol=1e-12)


def test_two_segments_without_gravity_stack_lengths_exactly():
    cfg = load_robot("two_segment").replace(gravity=(0.0, 0.0, 0.0))
    model = RobotModel(cfg)
    p = np.array([100e3] * 3 + [-40e3] * 3)
    fw = solve_forward(model, p)
    lam = model.stage1.stretch(p)
    expected = (lam[0] + lam[3]) * cfg.l0 + cfg.segments[1].connector_height
    assert fw.position[2] == pytest.approx(expected, rel=1e-12)
    assert np.hypot(*fw.position[:2]) < 1e-12


def test_equal_pressures_with_gravity_stay_on_axis_and_sag(one):
    fw = solve_forward(one, np.full(3, 60e3), payload_kg=0.08)
    assert np.hypot(*fw.position[:2]) < 1e-12
    assert fw.position[2] < one.stage1.stretch(60e3) * one.cfg.l0


@pytest.mark.parametrize("name", ["one_segment", "two_segment"])
def test_rotating_the_pressure_pattern_rotates_the_tip_by_120_degrees(name):
    model = RobotModel(load_robot(name))
    rng = np.random.default_rng(7)
    p = rng.uniform(model.cfg.p_min, model.cfg.p_max, model.A)
    fw0 = solve_forward(model, p, payload_kg=0.03)
    # actuator i takes the pressure of actuator i-1 -> pattern turned by +120 deg
    p_rot = np.concatenate([np.roll(p[s], 1) for s in model.cfg.actuator_slices])
    fw1 = solve_forward(model, p_rot, payload_kg=0.03)
    c, s = np.cos(2 * np.pi / 3), np.sin(2 * np.pi / 3)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    np.testing.assert_allclose(fw1.position, Rz @ fw0.position, atol=1e-10)
    np.testing.assert_allclose(fw1.z_axis, Rz @ fw0.z_axis, atol=1e-9)


def test_inflating_one_actuator_bends_the_robot_away_from_it(one):
    for i in range(3):
        p = np.zeros(3)
        p[i] = 120e3
        fw = solve_forward(one, p)
        direction = one.act_offset[i, :2] / np.linalg.norm(one.act_offset[i, :2])
        assert fw.position[:2] @ direction < -5e-3  # at least 5 mm away from actuator i
        assert fw.z_axis[:2] @ direction < -0.1


def test_more_payload_lowers_the_tip(one, two):
    for model in (one, two):
        p = _extreme(model) * 0.5
        z = [solve_forward(model, p, payload_kg=m).position[2] for m in (0.0, 0.05, 0.1)]
        assert z[0] > z[1] > z[2]


def test_results_report_poses_backbones_and_plates(two):
    fw = solve_forward(two, _extreme(two))
    R = fw.rotation
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-10)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-10)
    bb = fw.backbones(11)
    assert bb.shape == (6, 11, 3)
    # base attachment is clamped
    np.testing.assert_allclose(bb[0, 0], two.act_offset[0], atol=1e-12)
    poses = fw.plate_poses()
    assert len(poses) == 8  # base + 2 constraint plates + top, per segment
    # every actuator end sits on its top plate at pitch radius
    top = [p for p in poses if p[0] == 1 and p[1] == 1.0][0]
    for a in range(3, 6):
        np.testing.assert_allclose(np.linalg.norm(bb[a, -1] - top[2]), 0.02, atol=1e-10)
    np.testing.assert_allclose(top[2], fw.position, atol=1e-12)
    d = fw.to_dict()
    for key in ("position_m", "rotation", "z_axis", "stretch", "pressures_pa", "converged",
                "stable", "status", "message", "iterations", "residual_norm"):
        assert key in d


def test_element_count_convergence_fig4d():
    """Tip error for n = 3..12 against n = 48 at the extreme actuation (paper Fig. 4(d)).

    n = 1 and n = 2 cannot carry the plates at 1/3 and 2/3 and are refused (test_config.py).
    """
    cfg = load_robot("one_segment")
    p = [150e3, -50e3, -50e3]
    ref = solve_forward(RobotModel(cfg, 48), p, payload_kg=0.1).position
    L = cfg.l0
    err = {}
    for n in range(3, 13):
        fw = solve_forward(RobotModel(cfg, n), p, payload_kg=0.1, check_stability=False)
        err[n] = np.linalg.norm(fw.position - ref) if fw.converged else np.inf
    assert err[4] < 0.01 * L
    assert err[12] < err[4]
    # nodes on the plates (multiples of 3) are markedly more accurate than their neighbours
    for n in (3, 6, 9, 12):
        neighbours = [err[k] for k in (n - 1, n + 1) if 3 <= k <= 12]
        assert err[n] < 0.2 * min(neighbours), err
    # the spec's figures: n = 4 ~ 0.16 mm, n = 3 ~ 0.01 mm, n = 6 ~ 0.001 mm
    assert 0.1e-3 < err[4] < 0.25e-3 and err[3] < 0.02e-3 and err[6] < 0.002e-3


def _actuation_grid(model, levels):
    grid = np.array(np.meshgrid(*[levels] * model.A, indexing="ij")).reshape(model.A, -1).T
    return grid


def test_cold_starts_converge_over_the_admissible_actuations_one_segment(one):
    levels = np.linspace(one.cfg.p_min, one.cfg.p_max, 5)
    for payload in (0.0, 0.1):
        for p in _actuation_grid(one, levels):
            fw = solve_forward(one, p, payload_kg=payload)
            assert fw.converged and fw.stable, (p, payload, fw.message)


def test_cold_starts_converge_two_segments_extreme_actuations(two):
    lo, hi = two.cfg.p_min, two.cfg.p_max
    rng = np.random.default_rng(3)
    cases = ([rng.choice([lo, hi], 6) for _ in range(10)]
             + [rng.uniform(lo, hi, 6) for _ in range(5)])
    for p in cases:
        for payload in (0.0, 0.1):
            fw = solve_forward(two, p, payload_kg=payload)
            assert fw.converged, (p, payload, fw.message)


def test_warm_start_is_used(two):
    p = _extreme(two) * 0.5
    cold = solve_forward(two, p)
    warm = solve_forward(two, p * 1.01, warm_start=cold)
    again = solve_forward(two, p * 1.01)
    assert warm.iterations < again.iterations
    np.testing.assert_allclose(warm.position, again.position, atol=1e-9)


def test_a_warm_start_of_another_element_count_is_refused_not_read_past(one):
    """A solution of the same robot with 12 elements per actuator cannot start a 6-element solve.

    (Passed on, the compiled kernels read and wrote past its end: heap corruption.)
    """
    fine = RobotModel(load_robot('one_segment'), n_elements=12)
    other = solve_forward(fine, [20e3, 0, 0])
    assert other.converged and one.n != fine.n
    with pytest.raises(ValueError, match='warm_start has .* coordinates'):
        solve_forward(one, [20e3, 0, 0], warm_start=other)
    with pytest.raises(ValueError, match='warm_start has .* coordinates'):
        solve_inverse(one, other.position, warm_start=other)
    same = solve_forward(one, [20e3, 0, 0], warm_start=solve_forward(one, [10e3, 0, 0]))
    assert same.converged


def test_two_segment_payload_buckling_is_reported():
    model = RobotModel(load_robot("two_segment"))
    light = solve_forward(model, np.zeros(6), payload_kg=0.15)
    heavy = solve_forward(model, np.zeros(6), payload_kg=0.25)
    assert light.converged and light.stable and light.success and light.min_eigenvalue > 0
    assert heavy.converged and not heavy.stable and not heavy.success
    assert heavy.status == ForwardStatus.UNSTABLE and "unstable" in heavy.message
    # the critical payload lies in 0.18-0.2 kg
    lo, hi = 0.15, 0.25
    fw = light
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        fw = solve_forward(model, np.zeros(6), payload_kg=mid, warm_start=fw)
        lo, hi = (mid, hi) if fw.stable else (lo, mid)
    assert 0.18 <= lo <= 0.2


def test_non_convergence_is_reported_not_hidden(one):
    fw = solve_forward(one, _extreme(one), max_iter=1)
    assert not fw.converged and not fw.success
    assert fw.status != 0 and fw.message != "converged"


@pytest.mark.parametrize("bad,match", [
    ([0.0, 0.0], "expected 3 pressures"),
    ([0.0, np.nan, 0.0], "finite"),
    ([0.0, 0.0, 200e3], "outside the limits"),
])
def test_bad_pressures_are_refused(one, bad, match):
    with pytest.raises(ValueError, match=match):
        solve_forward(one, bad)


def test_bad_payload_is_refused(one):
    with pytest.raises(ValueError, match="payload"):
        solve_forward(one, np.zeros(3), payload_kg=-0.1)


def test_iteration_and_time_budgets_are_reported(two):
    p = _extreme(two)
    fw = solve_forward(two, p, payload_kg=0.1, max_iter=2, iteration_budget=5)
    assert not fw.converged and fw.status == ForwardStatus.ITERATION_BUDGET and fw.iterations <= 5
    assert "iteration budget" in fw.message
    fw = solve_forward(two, p, payload_kg=0.1, time_budget_s=1e-6)
    assert not fw.converged and fw.status == ForwardStatus.TIME_BUDGET
    assert "wall-clock" in fw.message
    full = solve_forward(two, p, payload_kg=0.1, time_budget_s=60.0)
    assert full.success and full.iterations < 500  # the default budget leaves room
    with pytest.raises(ValueError, match="time_budget_s"):
        solve_forward(two, p, time_budget_s=-1.0)
