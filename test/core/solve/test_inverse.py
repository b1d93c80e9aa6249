"""Inverse kinetostatic problem: round trips, limits, uniqueness and smoothness."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from bellow_ancf_ros.core import InverseStatus, solve_forward, solve_inverse


def _angle(a, b):
    return np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b)


def test_round_trip_one_segment(one):
    rng = np.random.default_rng(11)
    prev = None
    for k in range(8):
        p = rng.uniform(one.cfg.p_min, one.cfg.p_max, 3)
        payload = [0.0, 0.05, 0.1][k % 3]
        fw = solve_forward(one, p, payload)
        inv = solve_inverse(one, fw.position, payload_kg=payload, warm_start=prev)
        assert inv.success and inv.reachable, inv.message
        assert np.linalg.norm(inv.forward.position - fw.position) < 1e-6
        assert inv.position_error_m < 1e-6 and inv.angle_error_rad is None
        # one segment: three equations, three stretches -> the pressures themselves come back
        np.testing.assert_allclose(inv.pressures_pa, p, atol=1.0)  # Pa
        assert not inv.active_limits.any()
        prev = inv


@settings(max_examples=10, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.floats(0.0, 1.0), min_size=6, max_size=6), st.sampled_from([0.0, 0.05]))
def test_round_trip_two_segments(two, u, payload):
    lo, hi = two.cfg.p_min, two.cfg.p_max
    p = lo + np.array(u) * (hi - lo)
    fw = solve_forward(two, p, payload)
    if not fw.success:  # only usable (stable) configurations are targets
        return
    inv = solve_inverse(two, fw.position, fw.z_axis, payload)
    assert inv.reachable and inv.success, inv.message
    assert np.linalg.norm(inv.forward.position - fw.position) < 1e-6
    assert _angle(inv.forward.z_axis, fw.z_axis) < 1e-4
    assert np.all(inv.pressures_pa >= lo) and np.all(inv.pressures_pa <= hi)


def test_unreachable_targets_give_best_in_limit_pressures(one, two):
    cases = [(one, [0.0, 0.0, 0.2], None), (one, [0.08, 0.0, 0.05], None),
             (two, [0.0, 0.0, 0.3], [0, 0, 1.0]), (two, [0.15, 0.0, 0.1], [1.0, 0, 0])]
    for model, pos, z in cases:
        inv = solve_inverse(model, pos, z)
        assert not inv.reachable and not inv.success and inv.status == 1, inv.message
        p = inv.pressures_pa
        assert np.all(np.isfinite(p))
        assert np.all(p >= model.cfg.p_min) and np.all(p <= model.cfg.p_max)
        assert inv.active_limits.any()
        assert inv.position_error_m > 1e-3
        assert "unreachable" in inv.message
    # straight up and too high: everything at p_max
    inv = solve_inverse(one, [0.0, 0.0, 0.2])
    np.testing.assert_array_equal(inv.active_limits, [1, 1, 1])
    np.testing.assert_allclose(inv.pressures_pa, one.cfg.p_max)
    # the answer is the best reachable: it beats the corners and the middle of the pressure box
    target = np.array([0.08, 0.0, 0.05])
    best = solve_inverse(one, target).position_error_m
    for p in ([150e3, -50e3, -50e3], [-50e3, 150e3, 150e3], [50e3] * 3):
        assert best <= np.linalg.norm(solve_forward(one, p).position - target) + 1e-9


def test_redundant_solution_is_unique_and_smooth_along_a_path(two):
    """Two segments: the same target gives the same pressures whatever the warm start.

    A smooth path of targets gives a smooth path of pressures.
    """
    fw = solve_forward(two, [90e3, -20e3, 10e3, -30e3, 60e3, 0.0])
    p0, z0 = fw.position, fw.z_axis
    # a short arc of targets: rotate the pose about the base z axis in 1-degree steps
    pressures, prev = [], None
    for k in range(7):
        a = np.radians(k)
        Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        inv = solve_inverse(two, Rz @ p0, Rz @ z0, warm_start=prev)
        assert inv.success, inv.message
        pressures.append(inv.pressures_pa)
        prev = inv
    P = np.array(pressures)
    # smooth: second differences much smaller than first differences
    d1 = np.abs(np.diff(P, axis=0)).max()
    d2 = np.abs(np.diff(P, 2, axis=0)).max()
    assert d2 < 0.1 * d1, (d1, d2)
    # unique: a cold solve of the last target gives the same pressures as the warm path
    cold = solve_inverse(two, prev.target_position, prev.target_z_axis)
    np.testing.assert_allclose(cold.pressures_pa, prev.pressures_pa, atol=1.0)  # Pa


def test_warm_start_is_used(one, monkeypatch):
    calls = []
    original = one.evaluate
    monkeypatch.setattr(one, "evaluate", lambda *a, **k: calls.append(1) or original(*a, **k))
    fw = solve_forward(one, [60e3, 0.0, -20e3])
    target = fw.position + [1e-3, 0, 0]
    calls.clear()
    cold = solve_inverse(one, target)
    n_cold = len(calls)
    calls.clear()
    warm = solve_inverse(one, target, warm_start=fw)
    n_warm = len(calls)
    calls.clear()
    # the warm start carries its sensitivities
    warmer = solve_inverse(one, target + [0, 1e-3, 0], warm_start=warm)
    n_warmer = len(calls)
    assert warm.success and cold.success and warmer.success
    assert n_warmer <= n_warm < n_cold / 3, (n_cold, n_warm, n_warmer)
    np.testing.assert_allclose(warm.pressures_pa, cold.pressures_pa, atol=1e-3)


def test_bad_targets_are_refused(one, two):
    with pytest.raises(ValueError, match="finite"):
        solve_inverse(one, [np.nan, 0, 0.1])
    with pytest.raises(ValueError, match="z-axis"):
        solve_inverse(two, [0, 0, 0.2])
    with pytest.raises(ValueError, match="z-axis"):
        solve_inverse(two, [0, 0, 0.2], [0, 0, 0])
    with pytest.raises(ValueError, match="payload"):
        solve_inverse(one, [0, 0, 0.1], payload_kg=np.inf)


# ---------------------------------------------------------------- issue 7 edges
def _objective(model, fw, position, z_axis):
    return float(np.sum(((fw.position - position) / model.length_scale) ** 2)
                 + np.sum((fw.z_axis - z_axis) ** 2))


def test_orientation_rows_tell_z_from_minus_z(two):
    """An axis outside the reachable cone gets the best answer by eq. 28, not one pointing away."""
    fw = solve_forward(two, [100e3, -50e3, -50e3, 100e3, -50e3, -50e3])
    down = np.array([0.0, 0.0, -1.0])
    inv = solve_inverse(two, fw.position, z_axis=down)
    assert not inv.reachable and inv.status == 1
    # the pressures that made fw (0 mm, 133.7 deg) are a better answer than 32.6 mm and 174 deg
    best = _objective(two, inv.forward, fw.position, down)
    assert best <= _objective(two, fw, fw.position, down)
    assert np.degrees(inv.angle_error_rad) < 134.0


def test_unreachable_target_behind_the_base_beats_the_corners(one):
    target = np.array([-0.04310101421361593, 0.012098869629431373, -0.4406812508414606])
    inv = solve_inverse(one, target, payload_kg=0.1)
    corner = solve_forward(one, [150e3, -50e3, -50e3], payload_kg=0.1)
    assert inv.position_error_m <= np.linalg.norm(corner.position - target) + 1e-12
    assert inv.position_error_m < 0.5336


def test_redundant_answer_does_not_depend_on_the_start(two):
    target = [0.005244173407707042, 0.07737872091473293, 0.19320070275506848]
    z = [0.20615067168408105, 0.5452194118729704, 0.8125501175195871]
    payload = 0.04828658286999078
    cold = solve_inverse(two, target, z_axis=z, payload_kg=payload)
    prev = solve_inverse(two, [-0.024948670783080787, 0.029605165168264412, 0.20741416386600506],
                         z_axis=[-0.09425973946896296, 0.24620901060928507, 0.9646223222656441],
                         payload_kg=0.0010826836126505257)
    warm = solve_inverse(two, target, z_axis=z, payload_kg=payload, warm_start=prev)
    assert cold.success and warm.success
    np.testing.assert_allclose(cold.pressures_pa, warm.pressures_pa, rtol=0, atol=1.0)  # Pa
    # the documented rule: the exact solution closest to mid-range stretches (here an interior one)
    assert not cold.active_limits.any()
    lam_ref = two.stage1.stretch(0.5 * (two.cfg.p_min + two.cfg.p_max))
    assert np.linalg.norm(cold.stretch - lam_ref) < 0.1145


def test_huge_targets_are_refused_with_the_reason(one):
    with pytest.raises(ValueError, match="robot lengths"):
        solve_inverse(one, [2.9986933304112912e+221, -2.918861344136323e+220,
                            -4.013089389107437e+221])
    inv = solve_inverse(one, [50.0, 0.0, 0.0])  # far, but not absurd: a finite, true error
    assert not inv.reachable and np.isfinite(inv.position_error_m)
    true_error = np.linalg.norm(inv.forward.position - [50.0, 0, 0])
    assert inv.position_error_m == pytest.approx(true_error, rel=1e-12)


@pytest.mark.parametrize("scale", [1e-13, 1e-300, 1e200])
def test_any_finite_nonzero_z_axis_is_a_direction(two, scale):
    fw = solve_forward(two, [40e3, 60e3, 0.0, 0.0, 20e3, 20e3])
    inv = solve_inverse(two, fw.position, fw.z_axis * scale)
    assert inv.success and inv.reachable
    np.testing.assert_allclose(inv.target_z_axis, fw.z_axis, atol=1e-15)


def test_budgets_end_the_solve_with_a_clear_status(two):
    fw = solve_forward(two, [100e3, -50e3, -50e3, 100e3, -50e3, -50e3])
    target = (fw.position, [0.0, 0.0, -1.0])  # unreachable: the expensive path
    for kwargs, status in (({"max_forward_solves": 3}, InverseStatus.ITERATION_BUDGET),
                           ({"time_budget_s": 1e-3}, InverseStatus.TIME_BUDGET)):
        inv = solve_inverse(two, *target, **kwargs)
        assert inv.status == status and not inv.success and not inv.reachable, inv.message
        assert "budget" in inv.message
        p = inv.pressures_pa
        assert np.all(np.isfinite(p)) and np.all(p >= two.cfg.p_min) and np.all(p <= two.cfg.p_max)
    inv = solve_inverse(two, *target, max_forward_solves=20)
    assert inv.forward is not None and inv.forward.converged  # the best answer so far, honestly
    true_error = np.linalg.norm(inv.forward.position - fw.position)
    assert inv.position_error_m == pytest.approx(true_error)
    with pytest.raises(ValueError, match="time_budget_s"):
        solve_inverse(two, *target, time_budget_s=0.0)


def test_corners_are_computed_once_and_progress_survives_a_budget(one):
    from bellow_ancf_ros.core.solve._inverse import precompute_corners
    payload = 0.0123
    assert not precompute_corners(one, payload, time_budget_s=1e-9)  # nothing done yet
    assert precompute_corners(one, payload)
    inv = solve_inverse(one, [0.0, 0.0, -0.3], payload_kg=payload, max_forward_solves=60)
    assert inv.status == 1 and inv.forward.converged  # the corners cost no forward solve now
