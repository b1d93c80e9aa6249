"""Self-checks of the cantilever reference solutions in reference_beams.py."""

import numpy as np
import pytest

import reference_beams as rb  # test/support (conftest.py)

CASE = rb.project_case_parameters()
L, KT, KB, W = CASE["L"], CASE["kt"], CASE["kb"], CASE["w"]


# (a) tiny loads: both large-deflection solvers -> linear Euler-Bernoulli
@pytest.mark.parametrize("w, P", [(W * 1e-4, 0.0), (0.0, 1e-5), (W * 1e-4, 1e-5)])
def test_tiny_load_matches_small_deflection(w, P):
    lin = rb.small_deflection_tip_drop(L, KB, w, P)
    x_e, d_e = rb.elastica_tip(L, KB, w, P)
    assert d_e == pytest.approx(lin, rel=1e-3)
    assert x_e == pytest.approx(L, rel=1e-6)
    for method in ("cartesian", "polar"):
        x_s, d_s = rb.spec_continuum_tip(L, KT, KB, w, P, method=method)
        assert d_s == pytest.approx(lin, rel=1e-3)
        assert x_s == pytest.approx(L, rel=1e-6)


def test_elastica_classical_tip_load_table():
    # tip-loaded cantilever elastica, alpha = P L^2/EI: (v/L, u/L), classical
    # tabulated values (Bisshopp & Drucker 1945; Mattiasson 1981)
    table = {1: (0.30172, 0.05643), 2: (0.49346, 0.16064), 5: (0.71379, 0.38763),
             10: (0.81061, 0.55500)}
    for alpha, (v, u) in table.items():
        x_tip, drop = rb.elastica_tip(1.0, 1.0, 0.0, float(alpha))
        assert drop == pytest.approx(v, abs=6e-6)
        assert 1.0 - x_tip == pytest.approx(u, abs=6e-6)


# (b) finite kt: spec continuum slightly softer; -> elastica as kt -> inf
def test_spec_softer_and_converges_to_elastica():
    P = 0.1
    _, d_e = rb.elastica_tip(L, KB, W, P)
    rel = []
    for fac in (1.0, 1e1, 1e2, 1e3, 1e4):
        _, d_s = rb.spec_continuum_tip(L, KT * fac, KB, W, P)
        rel.append(d_s / d_e - 1.0)
    rel = np.array(rel)
    assert np.all(rel > 0.0), rel                      # softer
    assert 1e-3 < rel[0] < 1e-2, rel                  # "slightly"
    assert np.all(np.diff(rel) < 0.0), rel            # monotone in kt
    # difference ~ 1/kt
    np.testing.assert_allclose(rel[1:] / rel[:-1], 0.1, rtol=0.1)
    assert rel[-1] < 1e-6


def test_cartesian_and_polar_forms_agree():
    P = 0.2297
    x_c, d_c = rb.spec_continuum_tip(L, KT, KB, W, P, method="cartesian")
    x_p, d_p = rb.spec_continuum_tip(L, KT, KB, W, P, method="polar")
    assert d_c == pytest.approx(d_p, rel=1e-9)
    assert x_c == pytest.approx(x_p, rel=1e-9)


def test_spec_bvp_satisfies_boundary_conditions():
    P = 0.2297
    sol = rb.spec_continuum_solution(L, KT, KB, W, P, method="cartesian")
    ya, yb = sol.y[:, 0], sol.y[:, -1]
    beta, b = KT * L**2 / KB, P * L**2 / KB
    eps_b = 0.5 * (yb[2] ** 2 + yb[3] ** 2 - 1.0)
    assert np.allclose([ya[0], ya[1], ya[3], ya[4]], 0.0, atol=1e-10)
    assert np.allclose([yb[4], yb[5]], 0.0, atol=1e-10)
    assert beta * eps_b * yb[2] - yb[6] == pytest.approx(0.0, abs=1e-9)
    assert beta * eps_b * yb[3] - yb[7] == pytest.approx(-b, abs=1e-9)
    # tangent length at the clamp is free: the clamp stretch is non-zero
    assert abs(ya[2] - 1.0) > 1e-6


def _hermite_fe_tip(ne, L, kt, kb, w, P, ngauss=6):
    """Independent check: exact-quadrature cubic-Hermite discretisation.

    Cubic Hermite (gradient-deficient ANCF) elements on the spec energy,
    Newton with FD Hessian.
    """
    from scipy.optimize import minimize

    gx, gw = np.polynomial.legendre.leggauss(ngauss)
    le = L / ne
    s = (gx + 1.0) / 2.0
    wq = gw / 2.0 * le
    H = np.array([2 * s**3 - 3 * s**2 + 1, le * (s**3 - 2 * s**2 + s),
                  -2 * s**3 + 3 * s**2, le * (s**3 - s**2)])
    dH = np.array([6 * s**2 - 6 * s, le * (3 * s**2 - 4 * s + 1),
                   -6 * s**2 + 6 * s, le * (3 * s**2 - 2 * s)]) / le
    ddH = np.array([12 * s - 6, le * (6 * s - 4), -12 * s + 6, le * (6 * s - 2)]) / le**2
    fvec = np.array([0.0, w])

    def full(q):  # node 0: r = 0, r'_z = 0, r'_x = q[0] free
        d = np.zeros((ne + 1, 4))
        d[0, 2] = q[0]
        d[1:] = q[1:].reshape(ne, 4)
        return d

    def energy_grad(q):
        d = full(q)
        E, G = P * d[-1, 1], np.zeros_like(d)
        G[-1, 1] += P
        for e in range(ne):
            A = np.array([d[e, 0:2], d[e, 2:4], d[e + 1, 0:2], d[e + 1, 2:4]])
            r, r1, r2 = H.T @ A, dH.T @ A, ddH.T @ A
            eps = 0.5 * ((r1**2).sum(1) - 1.0)
            E += np.sum(wq * (0.5 * kt * eps**2 + 0.5 * kb * (r2**2).sum(1) + w * r[:, 1]))
            gA = (dH @ (wq[:, None] * kt * eps[:, None] * r1) + ddH @ (wq[:, None] * kb * r2)
                  + H @ (wq[:, None] * fvec[None, :]))
            G[e, 0:2] += gA[0]
            G[e, 2:4] += gA[1]
            G[e + 1, 0:2] += gA[2]
            G[e + 1, 2:4] += gA[3]
        return E, np.concatenate(([G[0, 2]], G[1:].ravel()))

    d0 = np.zeros((ne + 1, 4))
    d0[:, 0] = np.linspace(0.0, L, ne + 1)
    d0[:, 2] = 1.0
    q = np.concatenate(([1.0], d0[1:].ravel()))
    q = minimize(energy_grad, q, jac=True, method="BFGS",
                 options={"gtol": 1e-12, "maxiter": 20000}).x
    n, h = q.size, 1e-7
    for _ in range(10):
        g = energy_grad(q)[1]
        K = np.empty((n, n))
        for i in range(n):
            dq = np.zeros(n)
            dq[i] = h
            K[:, i] = (energy_grad(q + dq)[1] - energy_grad(q - dq)[1]) / (2 * h)
        step = np.linalg.solve(0.5 * (K + K.T), g)
        q -= step
        if np.max(np.abs(step)) < 1e-15:
            break
    d = full(q)
    return d[-1, 0], -d[-1, 1]


def test_spec_continuum_is_limit_of_hermite_fe():
    P = 0.2297
    _, d_ref = rb.spec_continuum_tip(L, KT, KB, W, P)
    errs = []
    for ne in (3, 6, 12):
        _, d_fe = _hermite_fe_tip(ne, L, KT, KB, W, P)
        errs.append(abs(d_fe / d_ref - 1.0))
    assert errs[-1] < 5e-6, errs
    # roughly 4th-order convergence (h^4 -> factor 16 per halving)
    assert errs[0] / errs[1] > 8 and errs[1] / errs[2] > 8, errs


# (c) the project test case: tip mass for an elastica drop of 35 % L
def test_project_case_35_percent_drop():
    m = rb.tip_mass_for_drop_fraction(L, KB, W, 0.35)
    P = m * rb.G_STD
    x_e, d_e = rb.elastica_tip(L, KB, W, P)
    x_s, d_s = rb.spec_continuum_tip(L, KT, KB, W, P)
    pct = 100.0 * (d_s / d_e - 1.0)
    print("\ntip mass %.10g kg (P=%.10g N): elastica drop %.10g m, spec drop %.10g m, "
          "spec softer by %.4f %%; x_tip %.10g vs %.10g m" % (m, P, d_e, d_s, pct, x_e, x_s))
    assert d_e == pytest.approx(0.35 * L, rel=1e-9)
    assert 0.02 < m < 0.03
    assert 0.2 < pct < 0.6
