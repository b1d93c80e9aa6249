"""Robot assembly (eqs. 19-25, 27, 30): analytic Jacobians against finite differences."""

import os
import sys

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "../..", "data"))
from make_solver_baseline import eval_state, model_for  # noqa: E402  (the baseline's cases)


# plates on nodes (n = 6), plates inside elements (n = 4), two segments with a tool
CASES = [("one_segment", 6, 0.0), ("one_segment", 4, 0.0), ("two_segment", 4, 0.02)]


@pytest.mark.parametrize("name,n,tool", CASES)
def test_kkt_jacobian_eq27_matches_finite_differences(name, n, tool):
    model = model_for(name, n, tool)
    x, lam = eval_state(model, 0)
    J = model.evaluate(x, lam, 1.0, 0.07).jacobian.toarray()
    h = 1e-7
    Jfd = np.empty_like(J)
    for i in range(model.N):
        e = np.zeros(model.N)
        e[i] = h
        Jfd[:, i] = (model.evaluate(x + e, lam, 1.0, 0.07, jacobian=False).residual
                     - model.evaluate(x - e, lam, 1.0, 0.07, jacobian=False).residual) / (2 * h)
    err = np.abs(J - Jfd).max() / np.abs(J).max()
    assert err < 1e-7, err
    # symmetric saddle-point matrix
    np.testing.assert_allclose(J, J.T, atol=1e-12 * np.abs(J).max())


@pytest.mark.parametrize("name,n,tool", CASES)
def test_stretch_derivative_eq30_matches_finite_differences(name, n, tool):
    model = model_for(name, n, tool)
    x, lam = eval_state(model, 1)
    D = model.evaluate(x, lam, 1.0, 0.07, jacobian=False, lam_derivative=True).dres_dlam
    h = 1e-7
    for a in range(model.A):
        dl = np.zeros(model.A)
        dl[a] = h
        fd = (model.evaluate(x, lam + dl, 1.0, 0.07, jacobian=False).residual
              - model.evaluate(x, lam - dl, 1.0, 0.07, jacobian=False).residual) / (2 * h)
        assert np.abs(D[:, a] - fd).max() < 1e-6 * np.abs(D).max()


@pytest.mark.parametrize("name,n,tool", CASES)
def test_force_residual_is_potential_gradient_plus_constraint_forces(name, n, tool):
    model = model_for(name, n, tool)
    x, lam = eval_state(model, 2)
    q, alpha = x[: model.nq], x[model.nq:]
    res = model.evaluate(x, lam, 1.0, 0.07).residual
    J = model.evaluate(x, lam, 1.0, 0.07).jacobian
    Cq = J[model.nq:, : model.nq].toarray()
    grad = np.empty(model.nq)
    h = 1e-7
    for i in range(model.nq):
        e = np.zeros(model.nq)
        e[i] = h
        grad[i] = (model.potential(q + e, lam, 1.0, 0.07)
                   - model.potential(q - e, lam, 1.0, 0.07)) / (2 * h)
    np.testing.assert_allclose(res[:model.nq], grad + Cq.T @ alpha,
                               atol=1e-6 * np.abs(grad).max())


@pytest.mark.parametrize("name", ["one_segment", "two_segment"])
def test_straight_state_satisfies_constraints_and_counts(name):
    model = model_for(name, 6)
    cfg = model.cfg
    x = model.straight_state(np.ones(model.A))
    r = model.evaluate(x, np.ones(model.A), 0.0, 0.0).residual
    assert np.abs(r).max() < 1e-12  # unloaded straight robot at lam = 1 is an exact equilibrium
    n_plates = sum(len(s.plate_fractions) + 1 for s in cfg.segments)  # moving plates
    assert model.P == n_plates
    attachments = sum(s.n_actuators * (len(s.plate_fractions) + 2) for s in cfg.segments)
    assert model.nc == 5 * attachments + 6 * n_plates


@pytest.mark.parametrize("name", ["one_segment", "two_segment"])
def test_constraint_jacobian_has_full_row_rank_at_a_bent_solution(name):
    model = model_for(name, 4)
    p = np.full(model.A, model.cfg.p_min)
    p[0] = model.cfg.p_max
    fw = solve_forward(model, p, 0.05)
    Cq = fw.jacobian[model.nq:, : model.nq].toarray()
    s = np.linalg.svd(Cq, compute_uv=False)
    assert s.min() > 1e-6 * s.max()
    assert np.linalg.matrix_rank(Cq) == model.nc


def test_a_model_and_what_solvers_cached_with_it_are_freed_together():
    """One per-model cache (RobotModel.cached): corners, cold solves, patterns go with the model.

    Regression: module-level WeakKeyDictionaries whose values (ForwardResults)
    held their model kept every model alive (a leak per node configure).
    """
    import gc
    import weakref

    from bellow_ancf_ros.core import precompute_corners, solve_inverse

    model = RobotModel(load_robot("one_segment"))
    assert precompute_corners(model, 0.0)
    fw = solve_forward(model, [50e3, 0.0, 0.0])
    inv = solve_inverse(model, fw.position + [0.0, 0.0, 0.5])  # unreachable: the corners
    assert not inv.reachable
    assert model.cached("corner_solutions", lambda m: None)  # filled
    ref = weakref.ref(model)
    del model, fw, inv
    gc.collect()
    assert ref() is None
