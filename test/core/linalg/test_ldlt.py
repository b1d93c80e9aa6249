"""Envelope LDL^T of the KKT matrix (core.ldlt): SuperLU's solutions, inertia, refusal."""

import os
import sys

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward
from bellow_ancf_ros.core.linalg import _ldlt as ldlt
from bellow_ancf_ros.core.linalg import _kkt as linsolve
from bellow_ancf_ros.core.solve import _newton as solver

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "../..", "data"))
from make_solver_baseline import eval_state  # noqa: E402  (the baseline's perturbed states)


def _ldl(model, J):
    return linsolve.kkt_solver(model).envelope.factor(J, model.dof_scale)


@pytest.mark.parametrize(
    "name,n", [("one_segment", 6), ("one_segment", 4), ("two_segment", 3), ("two_segment", 6)]
)
def test_solutions_equal_sparse_lu_at_perturbed_states(name, n):
    model = RobotModel(load_robot(name), n)
    for seed in (n, n + 1):
        x, lam = eval_state(model, seed)
        ev = model.evaluate(x, lam, 1.0, 0.05, jacobian=True, lam_derivative=True)
        F = _ldl(model, ev.jacobian)
        assert F is not None and F.growth < 1e3  # no pivoting needed, little growth
        B = np.column_stack([ev.residual, ev.dres_dlam, np.ones(model.N)] * 3)
        ref = spla.splu(ev.jacobian, permc_spec="COLAMD").solve(B)
        tol = 1e-9 * np.abs(ref).max()
        for m in (14, 13, 10, 8, 3, 2):  # blocks of eight, the rest padded or one by one
            np.testing.assert_allclose(F.solve(B[:, :m]), ref[:, :m], rtol=0, atol=tol)
        np.testing.assert_allclose(F.solve(B[:, 0]), ref[:, 0], rtol=0, atol=tol)


@pytest.mark.parametrize("name,n", [("one_segment", 4), ("two_segment", 6)])
def test_every_multiplier_follows_the_coordinates_of_its_constraint(name, n):
    model = RobotModel(load_robot(name), n)
    env = linsolve.kkt_solver(model).envelope
    J = model.evaluate(*eval_state(model, 0)).jacobian.tocoo()
    keep = J.data != 0
    rows, cols = J.row[keep], J.col[keep]
    c = (rows >= model.nq) & (cols < model.nq)
    assert np.all(env.new[rows[c]] > env.new[cols[c]])
    assert sorted(env.order) == list(range(model.N))


@pytest.mark.parametrize("name,n,payload,stable", [
    ("one_segment", 6, 0.0, True), ("two_segment", 6, 0.0, True),
    ("one_segment", 4, 0.3, True), ("two_segment", 3, 0.4, False),
    ("two_segment", 6, 0.25, False), ("one_segment", 6, 1.5, False),
])
def test_inertia_is_the_stability_of_the_equilibrium(name, n, payload, stable):
    """``D`` has nq positive pivots exactly when the reduced Hessian is positive definite."""
    model = RobotModel(load_robot(name), n)
    rng = np.random.default_rng(n)
    seen = set()
    for p in (np.zeros(model.A), rng.uniform(model.cfg.p_min, model.cfg.p_max, model.A)):
        fw = solve_forward(model, p, payload, check_stability=False)
        if not fw.converged:
            continue
        lmin = solver.ReducedHessian(fw.jacobian, model.nq, model.dof_scale).min_eigenvalue
        F = _ldl(model, fw.jacobian)
        if F is None or abs(lmin) < 1e-9:
            continue
        assert F.inertia[0] + F.inertia[1] == model.N
        assert (F.inertia == (model.nq, model.nc)) == (lmin > 0), (F.inertia, lmin)
        seen.add(lmin > 0)
    assert seen == {stable}  # every case has a converged equilibrium, stable or buckled


def test_growth_above_the_limit_is_refused_and_the_banded_lu_solves(monkeypatch):
    model = RobotModel(load_robot("two_segment"))
    ev = model.evaluate(*eval_state(model, 2), jacobian=True)
    ref = spla.splu(ev.jacobian, permc_spec="COLAMD").solve(ev.residual)
    monkeypatch.setattr(ldlt, "MAX_GROWTH", 0.5)  # below any factorisation's (>= 1)
    assert _ldl(model, ev.jacobian) is None
    f = linsolve.kkt_solver(model).bound(ev.jacobian)
    np.testing.assert_allclose(f.solve(ev.residual), ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    assert isinstance(f.lu, linsolve.BandedLU)


def test_a_zero_pivot_is_refused():
    model = RobotModel(load_robot("one_segment"))
    ev = model.evaluate(*eval_state(model, 1), jacobian=True)
    J = ev.jacobian.copy()
    J.data[:] = 0.0
    assert _ldl(model, J) is None


def test_an_equilibrium_is_factorised_by_ldlt_with_its_inertia():
    model = RobotModel(load_robot("one_segment"))
    fw = solve_forward(model, np.array([100e3, 0.0, 20e3]))
    f = fw.lu
    f.solve(np.ones(model.N))
    assert isinstance(f.lu, ldlt.EnvelopeLDL)
    assert f.lu.inertia == (model.nq, model.nc) and fw.stable


@pytest.mark.parametrize("name,n", [("one_segment", 3), ("two_segment", 6), ("three_segment", 6)])
def test_the_penalty_pairs_are_every_ordered_pair_of_each_constraint_rows_entries(name, n):
    """Built vectorised, the pairs are those of the per-row double loop, in its order."""
    model = RobotModel(load_robot(name), n)
    p = linsolve.kkt_solver(model).envelope
    offs = p.ints[:ldlt._NS + 1]

    def sec(i):
        return p.ints[offs[i]:offs[i + 1]]
    new, cq, rptr = sec(ldlt._NEW), sec(ldlt._CQ), sec(ldlt._RPTR)
    pa, pb = [], []
    for r in range(model.nc):
        for i in range(rptr[r], rptr[r + 1]):
            for j in range(rptr[r], rptr[r + 1]):
                if new[cq[i]] >= new[cq[j]]:
                    pa.append(i)
                    pb.append(j)
    assert len(pa) > model.nc
    np.testing.assert_array_equal(sec(ldlt._PA), pa)
    np.testing.assert_array_equal(sec(ldlt._PB), pb)
