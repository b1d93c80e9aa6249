"""Stability test (core.stability): penalised banded Cholesky against the dense reduced Hessian."""

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward
from bellow_ancf_ros.core import solver, stability


def _dense(fw):
    m = fw.model
    return solver.ReducedHessian(fw.jacobian, m.nq, m.dof_scale)


def test_banded_cholesky_matches_numpy_and_detects_indefinite():
    rng = np.random.default_rng(0)
    n, kd = 40, 5
    A = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - kd), i + 1):
            A[i, j] = A[j, i] = rng.standard_normal()
    A += 2 * kd * np.eye(n)  # diagonally dominant: positive definite
    ab = np.zeros((n, kd + 1))
    for j in range(n):
        for k in range(min(kd, n - 1 - j) + 1):
            ab[j, k] = A[j + k, j]
    assert stability.banded_cholesky(ab)
    L = np.zeros((n, n))
    for j in range(n):
        for k in range(min(kd, n - 1 - j) + 1):
            L[j + k, j] = ab[j, k]
    np.testing.assert_allclose(L, np.linalg.cholesky(A), atol=1e-12)
    A[7, 7] = -1.0
    ab2 = np.zeros((n, kd + 1))
    for j in range(n):
        for k in range(min(kd, n - 1 - j) + 1):
            ab2[j, k] = A[j + k, j]
    assert not stability.banded_cholesky(ab2)


CASES = [
    ("one_segment", 6, 0.0),
    ("one_segment", 4, 0.3),
    ("one_segment", 12, 0.1),
    ("two_segment", 6, 0.0),
    ("two_segment", 3, 0.12),
    ("two_segment", 6, 0.15),
    ("two_segment", 6, 0.25),
    ("two_segment", 3, 0.4),
]


@pytest.mark.parametrize("name,n,payload", CASES)
def test_penalised_test_agrees_with_dense_reduced_hessian(name, n, payload):
    model = RobotModel(load_robot(name), n)
    rng = np.random.default_rng(n)
    pressures = [np.zeros(model.A), rng.uniform(model.cfg.p_min, model.cfg.p_max, model.A)]
    checked = 0
    for p in pressures:
        fw = solve_forward(model, p, payload, check_stability=False)
        if not fw.converged:  # a heavy payload can collapse the robot: nothing to check
            continue
        checked += 1
        dense = _dense(fw).is_positive_definite(1e-10)
        chk = stability.StabilityCheck(fw.jacobian, model)
        assert chk.is_positive_definite(1e-10) == dense
        if chk.proved_by is not None:
            assert dense  # a banded proof is never given for an unstable equilibrium
        assert chk.min_eigenvalue == pytest.approx(_dense(fw).min_eigenvalue, rel=1e-9)
    assert checked


def test_stable_default_answers_are_proved_by_the_banded_test(one, two):
    for model in (one, two):
        p = np.full(model.A, model.cfg.p_min)
        p[0] = model.cfg.p_max
        fw = solve_forward(model, p)
        assert fw.stable and fw._reduced_hessian.proved_by is not None


def test_banded_pattern_bandwidth_does_not_grow_with_elements():
    kd = [
        stability.BandedPattern(RobotModel(load_robot("two_segment"), n)).kd for n in (6, 12, 24)
    ]
    assert kd[0] == kd[1] == kd[2], kd
