"""Stability test (core.stability): penalised envelope factorisation against dense tests."""

import os
import sys

import numpy as np

from bellow_ancf_ros.core.linalg import coordinates_envelope
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward
from bellow_ancf_ros.core.linalg import _ldlt as ldlt
from bellow_ancf_ros.core.solve import _newton as solver
from bellow_ancf_ros.core.solve import _stability as stability


def _dense(fw):
    m = fw.model
    return solver.ReducedHessian(fw.jacobian, m.nq, m.dof_scale)


def _penalised_dense(model, J, pen, rtol):
    """``H_s - s I + rho C_s^T W C_s`` as a dense matrix (rows of ``C_s`` normalised)."""
    nq, D = model.nq, model.dof_scale
    Jd = J.toarray()
    Hs = D[:, None] * Jd[:nq, :nq] * D[None, :]
    Cs = Jd[nq:, :nq] * D[None, :]
    ref = np.abs(Hs).max()
    w = 1.0 / np.sum(Cs ** 2, axis=1)
    return Hs - rtol * ref * np.eye(nq) + pen * ref * (Cs.T * w) @ Cs


@pytest.mark.parametrize("name,n", [("one_segment", 6), ("one_segment", 4), ("two_segment", 3)])
def test_envelope_test_is_numpys_positive_definiteness(name, n):
    """The envelope factorisation's verdict is the sign of the penalised matrix's eigenvalues."""
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "../..", "data"))
    from make_solver_baseline import eval_state

    model = RobotModel(load_robot(name), n)
    pat = coordinates_envelope(model)
    rng = np.random.default_rng(n)
    # perturbed states with random multipliers (indefinite), and equilibria (stable)
    jacobians = [model.evaluate(*eval_state(model, seed), 1.0, 0.1).jacobian for seed in range(3)]
    for _ in range(2):
        p = rng.uniform(model.cfg.p_min, model.cfg.p_max, model.A)
        jacobians.append(solve_forward(model, p, check_stability=False).jacobian)
    verdicts = set()
    for J in jacobians:
        for pen in stability.PENALTIES:
            lmin = np.linalg.eigvalsh(_penalised_dense(model, J, pen, 1e-10)).min()
            ref = np.abs(_penalised_dense(model, J, 0.0, 0.0)).max()
            if abs(lmin) < 1e-8 * ref * pen:
                continue  # too close to call in floating point
            got = pat.positive_definite(J, model.dof_scale, pen, 1e-10)
            assert got == (lmin > 0), (pen, lmin)
            verdicts.add(got)
    assert verdicts == {True, False}


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


def test_stable_default_answers_are_proved_by_the_linear_time_test(one, two):
    for model in (one, two):
        p = np.full(model.A, model.cfg.p_min)
        p[0] = model.cfg.p_max
        fw = solve_forward(model, p)
        assert fw.stable and fw._reduced_hessian.proved_by is not None


def test_envelope_height_does_not_grow_with_elements():
    heights = []
    for n in (6, 12, 24):
        pat = coordinates_envelope(RobotModel(load_robot("two_segment"), n))
        last = pat.ints[pat.ints[ldlt._LAST]:pat.ints[ldlt._LAST + 1]]
        heights.append(int(np.max(last - np.arange(len(last)))))
    assert heights[0] == heights[1] == heights[2], heights
