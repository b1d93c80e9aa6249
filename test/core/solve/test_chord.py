"""core.chord: compiled chord steps against LAPACK and against the same steps in Python."""

import numpy as np
import pytest
import scipy.linalg.lapack as lapack

from bellow_ancf_ros.core import RobotModel, load_robot, solve_inverse
from bellow_ancf_ros.core.solve import _chord as chord
from bellow_ancf_ros.core.linalg import _ldlt as ldlt
from bellow_ancf_ros.core.linalg import _kkt as linsolve
from bellow_ancf_ros.core.solve._inverse_newton import Target
from bellow_ancf_ros.core.solve._inverse_warm import _StretchStep


@pytest.mark.parametrize("n, kl, ku", [(1, 0, 0), (7, 2, 1), (60, 5, 9), (240, 43, 43)])
def test_banded_solve_is_dgbtrs(n, kl, ku):
    rng = np.random.default_rng(n + kl)
    A = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - kl), min(n, i + ku + 1)):
            A[i, j] = rng.standard_normal()
    A[np.arange(n), np.arange(n)] *= 0.1  # small diagonal: partial pivoting swaps rows
    ab = np.zeros((2 * kl + ku + 1, n))
    for j in range(n):
        for i in range(max(0, j - ku), min(n, j + kl + 1)):
            ab[kl + ku + i - j, j] = A[i, j]
    lub, piv, info = lapack.dgbtrf(ab, kl, ku)
    assert info == 0
    if n > 1:
        assert np.any(piv != np.arange(n))  # the test exercises row interchanges
    b = rng.standard_normal(n)
    ref, info = lapack.dgbtrs(lub, kl, ku, b, piv)
    got = chord.banded_solve(lub, piv, kl, ku, b)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref)))
    np.testing.assert_allclose(A @ got, b, atol=1e-9 * np.max(np.abs(b)) * np.linalg.cond(A))


def _path_start(name):
    """A warm answer, the next target 1 mm away, and the state after the predictor."""
    model = RobotModel(load_robot(name))
    multi = model.cfg.n_segments > 1
    p0 = np.full(model.A, 30e3)
    from bellow_ancf_ros.core import solve_forward

    fw0 = solve_forward(model, p0)
    z0 = fw0.z_axis if multi else None
    a = solve_inverse(model, fw0.position, z0)
    b = solve_inverse(model, fw0.position + [1e-3, 0, 0], z0, warm_start=a)
    target_pos = fw0.position + [1e-3, 1e-3, 0]
    return model, multi, b, Target(model, target_pos, z0)


@pytest.mark.parametrize("kind", ["ldlt", "banded_lu"])
@pytest.mark.parametrize("name,null_space", [("one_segment", True), ("two_segment", True),
                                             ("two_segment", False)])
def test_compiled_chord_steps_are_the_python_steps(name, null_space, kind):
    model, multi, warm, target = _path_start(name)
    fw = warm.forward
    st = model.stage1
    lo, hi = np.full(model.A, st.lam_min), np.full(model.A, st.lam_max)
    lam_ref = np.full(model.A, float(st.stretch(0.5 * (model.cfg.p_min + model.cfg.p_max))))
    factorised, WF = fw._warm.chord
    assert isinstance(factorised.lu, ldlt.EnvelopeLDL)  # what the solver made
    if kind == "banded_lu":  # the fallback for a refused LDL^T, on the same matrix
        factorised = linsolve.kkt_solver(model).pattern.factor(factorised.J)
    step = _StretchStep(target, multi, WF, lam_ref, lo, hi)
    x, lam = fw.x.copy(), fw.stretch.copy()
    d = step(target, x, lam, np.zeros(model.N))  # the predictor of full_space_newton
    x, lam = x - WF @ d, lam + d
    if not null_space:  # minimum-norm steps (the chord phase of redundant robots)
        step.proj = None
    # the same steps in Python: evaluate, banded solve, Schur-complement stretch step
    xp, lp, hist = x.copy(), lam.copy(), []
    for _ in range(4):
        r = model.evaluate(xp, lp, 1.0, 0.0, jacobian=False).residual
        hist.append(np.max(np.abs(r * model.residual_scale)))
        w0 = factorised.solve(r)
        d = step(target, xp, lp, w0)
        xp, lp = xp - (w0 + WF @ d), lp + d
    lu = factorised if kind == "banded_lu" else factorised.lu
    xc, lc, status, steps, h, rn = chord.chord_steps(
        model, 0.0, target, lu, WF, step, x, lam, tol=0.0, rate=10.0, max_steps=4,
        null_space=null_space)
    assert status == chord.MAX_STEPS and steps == 4
    np.testing.assert_allclose(h[:4], hist, rtol=1e-6, atol=1e-10 * hist[0])  # round-off
    np.testing.assert_allclose(xc, xp, rtol=0, atol=1e-12)
    np.testing.assert_allclose(lc, lp, rtol=0, atol=1e-14)
    # linear convergence: each step cuts the residual
    assert all(h[k + 1] < 0.2 * h[k] for k in range(4))


def test_chord_loop_stops_when_a_step_does_not_cut_the_residual_enough():
    model, multi, warm, target = _path_start("one_segment")
    fw = warm.forward
    st = model.stage1
    lo, hi = np.full(model.A, st.lam_min), np.full(model.A, st.lam_max)
    factorised, WF = fw._warm.chord
    step = _StretchStep(target, multi, WF, np.ones(model.A), lo, hi)
    *_, status, steps, h, rn = chord.chord_steps(
        model, 0.0, target, factorised.lu, WF, step, fw.x, fw.stretch, tol=0.0, rate=1e-9,
        max_steps=10)
    assert status == chord.STALLED and steps == 1 and rn == h[-1] > 1e-9 * h[0]


def _numpy_stretch_step(target, x, w0, lam, inv, proj, lam_ref, lo, hi):
    """The stretch step written with numpy: ``-J_O^{-1}(O(x) - T w0)`` plus the null-space term."""
    d = -inv @ (target(x) - target.linear(w0))
    null = np.zeros_like(lam) if proj is None else proj @ (lam_ref - lam)
    d = d + null
    ok = bool(np.all(np.abs(d) <= 0.05) and np.all(lo < lam + d) and np.all(lam + d < hi))
    return d, float(np.max(np.abs(null))), ok


@pytest.mark.parametrize("multi", [False, True])
def test_compiled_stretch_step_is_the_numpy_formula(multi):
    model = RobotModel(load_robot("two_segment" if multi else "one_segment"))
    rng = np.random.default_rng(11)
    x = model.straight_state(np.ones(model.A)) + 1e-3 * rng.standard_normal(model.N)
    w0 = 1e-4 * rng.standard_normal(model.N)
    target = Target(model, np.array([0.01, -0.02, 0.2]),
                    np.array([0.1, 0.0, 0.99]) / np.linalg.norm([0.1, 0.0, 0.99]) if multi
                    else None)
    k = 6 if multi else 3
    inv = 1e-3 * rng.standard_normal((model.A, k))
    proj = None
    if multi:
        q, _ = np.linalg.qr(rng.standard_normal((model.A, 1)))
        proj = q @ q.T  # a rank-1 null-space projector
    lam_ref, lam = np.ones(model.A), 1.0 + 0.01 * rng.standard_normal(model.A)
    lo, hi = np.full(model.A, 0.5), np.full(model.A, 1.5)
    args = (target.pd, target.tool, target.L, target.axis, target.offset, inv,
            proj if multi else np.zeros((model.A, model.A)), multi, lam_ref, lo, hi)
    d, null, ok = chord.stretch_step(x, w0, lam, *args)
    d_ref, null_ref, ok_ref = _numpy_stretch_step(target, x, w0, lam, inv, proj, lam_ref, lo, hi)
    np.testing.assert_allclose(d, d_ref, rtol=1e-12, atol=1e-15)
    assert null == pytest.approx(null_ref, rel=1e-12, abs=1e-300) and ok == ok_ref
    assert ok and (null > 0) == multi  # a step inside the region, with a null-space term
    # outside the trust region (0.05 per stretch), outside the box, non-finite: refused
    _, _, ok_big = chord.stretch_step(x, w0, lam, *args[:5], 1e4 * inv, *args[6:])
    assert not ok_big
    _, _, ok_box = chord.stretch_step(x, w0, np.full(model.A, 1.5 - 1e-12), *args)
    assert not ok_box
    x_nan = x.copy()
    x_nan[target.pd[0]] = np.nan
    _, _, ok_nan = chord.stretch_step(x_nan, w0, lam, *args)
    assert not ok_nan
