"""KKT solves (core.linsolve): envelope LDL^T or banded LU against SuperLU; one BLAS thread."""

import os
import sys

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from bellow_ancf_ros.core import RobotModel, load_robot
from bellow_ancf_ros.core.linalg import _ldlt as ldlt
from bellow_ancf_ros.core.linalg import _kkt as linsolve

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "../..", "data"))
from make_solver_baseline import eval_state  # noqa: E402  (the baseline's perturbed states)


@pytest.mark.parametrize(
    "name,n", [("one_segment", 6), ("one_segment", 4), ("two_segment", 3), ("two_segment", 6)]
)
def test_banded_solve_equals_sparse_lu(name, n):
    model = RobotModel(load_robot(name), n)
    x, lam = eval_state(model, n)
    ev = model.evaluate(x, lam, 1.0, 0.05, jacobian=True, lam_derivative=True)
    B = np.column_stack([ev.residual, ev.dres_dlam])
    ref = spla.splu(ev.jacobian, permc_spec="COLAMD").solve(B)
    new = ev.solve(B)
    np.testing.assert_allclose(new, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    np.testing.assert_allclose(ev.solve(B[:, 0]), ref[:, 0], rtol=0, atol=1e-9 * np.abs(ref).max())


def test_dropped_pattern_entries_are_exactly_zero():
    model = RobotModel(load_robot("two_segment"))
    keep = model.structural_nonzeros()
    assert not keep.all()  # plates sit on nodes: the far node of each attachment is dropped
    for seed in range(3):
        x, lam = eval_state(model, 10 + seed)
        J = model.evaluate(x, lam, 1.0, 0.1).jacobian
        assert not np.any(J.data[~keep])


def test_bandwidth_is_independent_of_elements_and_segments():
    two = load_robot("two_segment")
    three = two.replace(segments=tuple([two.segments[0]] + [two.segments[1]] * 2))
    kl = {
        (cfg.n_segments, n): linsolve.BandedKKT(RobotModel(cfg, n)).kl
        for cfg in (two, three)
        for n in (6, 12, 24)
    }
    assert len(set(kl.values())) == 1, kl


def test_singular_matrix_raises():
    model = RobotModel(load_robot("one_segment"))
    x, lam = eval_state(model, 0)
    ev = model.evaluate(x, lam)
    ev.jacobian = ev.jacobian.copy()
    ev.jacobian.data[:] = 0.0
    with pytest.raises(np.linalg.LinAlgError):
        ev.solve(ev.residual)


def test_factorisation_runs_with_one_blas_thread(monkeypatch):
    """The banded LU (the LDL^T of core.ldlt uses no BLAS; here it is refused) on one thread."""
    threadpoolctl = pytest.importorskip('threadpoolctl')
    threadpool_info = threadpoolctl.threadpool_info
    threadpool_limits = threadpoolctl.threadpool_limits

    seen = []
    real = linsolve.lapack.dgbtrf

    def spy(*args, **kw):
        seen.append(max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"))
        return real(*args, **kw)

    monkeypatch.setattr(linsolve.lapack, "dgbtrf", spy)
    monkeypatch.setattr(ldlt, "MAX_GROWTH", -1.0)  # every LDL^T refused: the banded LU
    model = RobotModel(load_robot("one_segment"))
    x, lam = eval_state(model, 1)
    ev = model.evaluate(x, lam)
    seen.clear()  # building the model warms the solver up
    with threadpool_limits(limits=2, user_api="blas"):  # a caller that allows two threads
        ev.solve(ev.residual)
        outside = max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")
    assert seen == [1]
    assert outside == 2  # the caller's setting is restored


def test_matrix_outside_the_band_falls_back_to_sparse_lu():
    model = RobotModel(load_robot("two_segment"))
    x, lam = eval_state(model, 3)
    ev = model.evaluate(x, lam)
    J = ev.jacobian.copy()
    dropped = np.flatnonzero(~model.structural_nonzeros())
    J.data[dropped] = 1e-3  # entries the band leaves out
    ref = spla.splu(J, permc_spec="COLAMD").solve(ev.residual)
    new = linsolve.kkt_solver(model).solve(J, ev.residual)
    np.testing.assert_allclose(new, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
