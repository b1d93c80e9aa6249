"""Budgets: a solve that runs out comes back with its progress, and budget slices converge.

Repeated warm-started calls with a small budget (iteration budgets for determinism, and one
wall-clock chain with a generous overshoot bound) must reach the answer of one unbudgeted solve.
"""

import time

import numpy as np
import pytest

from bellow_ancf_ros.core import ForwardStatus, InverseStatus, solve_forward, solve_inverse
from bellow_ancf_ros.core.solve import _forward as forward
from bellow_ancf_ros.core.solve._inverse_newton import norm, pose_errors

BUDGET_STATUSES = (ForwardStatus.TIME_BUDGET, ForwardStatus.ITERATION_BUDGET)
ONE_TARGET_KPA = [150.0, -50.0, -50.0]
TWO_TARGET_KPA = [100.0, -50.0, -50.0, 100.0, -50.0, -50.0]


def _target(model, kpa):
    fw = solve_forward(model, np.array(kpa) * 1e3)
    return fw.position, (fw.z_axis if model.cfg.n_segments > 1 else None)


def _straight(model):
    return solve_forward(model, np.zeros(model.A))


def _check_budget_result(model, inv, position, z_axis):
    """Finite, in-limit pressures with a converged, stable forward solution and true errors."""
    cfg = model.cfg
    p = inv.pressures_pa
    assert np.all(np.isfinite(p)) and np.all(p >= cfg.p_min) and np.all(p <= cfg.p_max)
    assert not inv.success and "budget" in inv.message
    fw = inv.forward
    assert fw is not None and fw.converged and fw.stable, inv.message
    np.testing.assert_array_equal(fw.pressures_pa, p)
    # the errors are those of a fresh forward solve of the returned pressures
    fresh = solve_forward(model, p, warm_start=fw)
    pe, ae = pose_errors(fresh, position, z_axis)
    assert inv.position_error_m == pytest.approx(pe, rel=1e-6, abs=1e-12)
    if z_axis is not None:
        assert inv.angle_error_rad == pytest.approx(ae, rel=1e-6, abs=1e-12)


def _slices(model, position, z_axis, warm, max_slices, **budget):
    """Warm-started budgeted calls until one finishes; returns (final result, budget results)."""
    seen = []
    for _ in range(max_slices):
        inv = solve_inverse(model, position, z_axis, warm_start=warm, **budget)
        if inv.status not in BUDGET_STATUSES:
            return inv, seen
        seen.append(inv)
        warm = inv
    pytest.fail(f"no answer after {max_slices} budget slices: {inv.message}")


@pytest.mark.parametrize("robot, kpa, iterations",
                         [("one", ONE_TARGET_KPA, 3), ("two", TWO_TARGET_KPA, 6)])
def test_forward_solve_slices_converge_to_the_unbudgeted_answer(robot, kpa, iterations, request,
                                                                monkeypatch):
    """A cold solve from the straight robot (continuation), cut by iteration budgets."""
    model = request.getfixturevalue(robot)
    # the straight guess instead of the constant-curvature arcs (which need 1-3 iterations):
    # a solve long enough to be sliced
    monkeypatch.setattr(forward, "arc_state", lambda m, lam: m.straight_state(lam))
    p = np.array(kpa) * 1e3
    ref = solve_forward(model, p, payload_kg=0.1)
    assert ref.iterations > iterations
    fw, n = None, 0
    while True:
        fw = solve_forward(model, p, payload_kg=0.1, warm_start=fw, iteration_budget=iterations)
        n += 1
        if fw.converged:
            break
        # cut short: the last equilibrium of the continuation is kept for the next call
        assert fw.status == ForwardStatus.ITERATION_BUDGET, fw.message
        assert fw.resume_state is not None
        assert n < 100
    assert n > 1  # the budget did cut it
    assert fw.stable and norm(fw.position - ref.position) < 1e-9


@pytest.mark.parametrize("robot, kpa", [("one", ONE_TARGET_KPA), ("two", TWO_TARGET_KPA)])
def test_inverse_budget_slices_make_progress_and_converge(robot, kpa, request):
    """Regression: a budget-exhausted call returned its warm start, so slices never moved."""
    model = request.getfixturevalue(robot)
    position, z_axis = _target(model, kpa)
    ref = solve_inverse(model, position, z_axis, warm_start=_straight(model))
    assert ref.success
    final, seen = _slices(model, position, z_axis, _straight(model), 60, max_forward_solves=2)
    assert len(seen) >= 2
    errors = [inv.position_error_m for inv in seen]
    assert errors[-1] < errors[0]  # progress
    assert all(b <= a for a, b in zip(errors, errors[1:]))  # never worse than the last slice
    for inv in seen:
        _check_budget_result(model, inv, position, z_axis)
        assert inv.resume is not None and inv.resume.converged
    assert final.success and final.reachable, final.message
    np.testing.assert_allclose(final.pressures_pa, ref.pressures_pa, atol=1.0)  # Pa


def test_unreachable_target_slices_end_at_the_unbudgeted_answer(one):
    position = np.array([0.06, 0.0, 0.06])  # beyond the bending range
    ref = solve_inverse(one, position, warm_start=_straight(one))
    assert ref.status == 1
    final, seen = _slices(one, position, None, _straight(one), 80, max_forward_solves=3)
    assert seen
    for inv in seen:
        _check_budget_result(one, inv, position, None)
    assert final.status == 1, final.message
    assert final.position_error_m == pytest.approx(ref.position_error_m, abs=1e-9)
    np.testing.assert_allclose(final.pressures_pa, ref.pressures_pa, atol=1.0)


@pytest.mark.parametrize("robot, kpa", [("one", ONE_TARGET_KPA), ("two", TWO_TARGET_KPA)])
def test_time_budget_is_honoured_and_slices_progress(robot, kpa, request):
    model = request.getfixturevalue(robot)
    position, z_axis = _target(model, kpa)
    budget = 0.01
    warm, first = _straight(model), None
    for _ in range(60):
        t0 = time.perf_counter()
        inv = solve_inverse(model, position, z_axis, warm_start=warm, time_budget_s=budget)
        elapsed = time.perf_counter() - t0
        # documented bound: the progress grace (4 budgets) plus one iteration; generous here
        assert elapsed < 10 * budget + 0.05, f"{elapsed * 1e3:.1f} ms for a 10 ms budget"
        if inv.status not in BUDGET_STATUSES:
            break
        _check_budget_result(model, inv, position, z_axis)
        first = inv if first is None else first
        warm = inv
    if first is not None:  # (an unloaded machine may finish in one slice)
        assert inv.position_error_m < first.position_error_m


def test_cold_solve_cut_by_the_budget_is_continued_by_the_next_call(two):
    """A cold solve cut short keeps its continuation: repeated cold calls get there."""
    cold = two.cached("cold_solutions", lambda m: {})  # the model's cache of cold forward solves
    cold.clear()
    payload = 0.0321
    position, z_axis = _target(two, TWO_TARGET_KPA)
    for calls in range(1, 101):
        inv = solve_inverse(two, position, z_axis, payload_kg=payload, time_budget_s=0.002)
        p = inv.pressures_pa
        assert np.all(np.isfinite(p)) and np.all(p >= two.cfg.p_min) and np.all(p <= two.cfg.p_max)
        if inv.forward is not None:
            break
        assert inv.status == InverseStatus.TIME_BUDGET and "no solution yet" in inv.message
    assert inv.forward is not None and inv.forward.converged, f"{calls} calls: {inv.message}"
    # the cold start reached in slices is the one a single cold solve gives
    cached = [fw for fw in cold.values() if fw.converged]
    assert len(cached) == 1
    fresh = solve_forward(two, cached[0].pressures_pa, payload, check_stability=False)
    assert norm(cached[0].position - fresh.position) < 1e-9


def test_slices_under_a_tip_force_end_at_its_unbudgeted_answer(two):
    """The tip load travels with the resume state: slices under a force end where one call does."""
    F = [0.05, -0.03, -0.1]
    aim = solve_forward(two, [60e3, 0.0, 10e3, 5e3, 40e3, 0.0], tip_force_n=F)
    position, z_axis = aim.position, aim.z_axis   # reachable under the force
    straight = solve_forward(two, np.zeros(6), tip_force_n=F)
    ref = solve_inverse(two, position, z_axis, warm_start=straight, tip_force_n=F)
    assert ref.success
    final, seen = _slices(two, position, z_axis, straight, 60, max_forward_solves=2,
                          tip_force_n=F)
    assert seen and all(inv.resume.load.force_n == tuple(F) for inv in seen)
    assert final.success and final.forward.load.force_n == tuple(F)
    np.testing.assert_allclose(final.pressures_pa, ref.pressures_pa, atol=1.0)
    # a forward solve cut short and continued under the force gives the unbudgeted equilibrium
    cut = solve_forward(two, [60e3, 0, 0, 0, 60e3, 0], tip_force_n=F, iteration_budget=3)
    assert cut.status == ForwardStatus.ITERATION_BUDGET and cut.resume_state is not None
    done = solve_forward(two, [60e3, 0, 0, 0, 60e3, 0], tip_force_n=F, warm_start=cut)
    np.testing.assert_allclose(done.x, solve_forward(two, [60e3, 0, 0, 0, 60e3, 0],
                                                     tip_force_n=F).x, atol=1e-9)
