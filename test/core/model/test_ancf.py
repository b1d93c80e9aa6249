"""ANCF element math (eqs. 5-8, 11, 17, 18): derivatives against finite differences."""

import numpy as np
import pytest

from bellow_ancf_ros.core.model import _ancf as ancf


def _random_elements(rng, E=5):
    """Bent, stretched elements: nodes near a curve with gradients of length ~1."""
    le = rng.uniform(0.005, 0.03, E)
    qe = np.zeros((E, 4, 3))
    qe[:, 0] = rng.normal(0, 0.01, (E, 3))
    qe[:, 1] = np.array([0, 0, 1.0]) + rng.normal(0, 0.2, (E, 3))
    qe[:, 2] = qe[:, 0] + le[:, None] * (np.array([0, 0, 1.0]) + rng.normal(0, 0.2, (E, 3)))
    qe[:, 3] = np.array([0, 0, 1.0]) + rng.normal(0, 0.2, (E, 3))
    kt = rng.uniform(30, 80, E)
    kb = rng.uniform(1e-3, 5e-3, E)
    return qe, le, kt, kb


def test_hermite_interpolates_nodes():
    h0, h1 = ancf.hermite(np.array([0.0, 1.0])), ancf.hermite(np.array([0.0, 1.0]), 1)
    np.testing.assert_allclose(h0, [[1, 0, 0, 0], [0, 0, 1, 0]], atol=0)
    np.testing.assert_allclose(h1, [[0, 1, 0, 0], [0, 0, 0, 1]], atol=0)


def test_shape_functions_reproduce_a_cubic_exactly():
    # r(x) = a + b x + c x^2 + d x^3 is represented exactly by its nodal values (eq. 7)
    le = 0.037
    a, b, c, d = np.random.default_rng(0).normal(size=(4, 3))

    def r(x):
        x = np.asarray(x, float)[..., None]
        return a + b * x + c * x**2 + d * x**3

    def rx(x):
        x = np.asarray(x, float)[..., None]
        return b + 2 * c * x + 3 * d * x**2

    qe = np.stack([r(0.0), rx(0.0), r(le), rx(le)])
    xi = np.linspace(0, 1, 7)
    for k, exact in enumerate([r(xi * le), rx(xi * le), 2 * c + 6 * d * (xi * le)[:, None]]):
        w, _ = ancf.shape_weights(xi, le, k)
        np.testing.assert_allclose(w @ qe, exact, rtol=1e-12, atol=1e-14)


def test_straight_unit_gradient_element_is_stress_free():
    le = 0.02
    qe = np.array([[[0, 0, 0], [0, 0, 1], [0, 0, le], [0, 0, 1]]], float)
    f = ancf.element_forces(qe, np.array([le]), np.array([50.0]), np.array([2e-3]))
    # per unit stiffness the force scale is 1/le; round-off only
    assert np.abs(f["ft"]).max() < 1e-13 / le and np.abs(f["fb"]).max() < 1e-13 / le
    energy = ancf.element_energy(qe, np.array([le]), np.array([50.0]), np.array([2e-3]))
    assert energy[0] == pytest.approx(0, abs=1e-20)


def test_quadrature_is_exact_against_a_fine_rule():
    rng = np.random.default_rng(1)
    qe, le, kt, kb = _random_elements(rng)
    W5 = ancf.element_energy(qe, le, kt, kb)
    # brute force: 40-point Gauss rule on the same integrand
    x, w = np.polynomial.legendre.leggauss(40)
    xi, w = 0.5 * (x + 1), 0.5 * w
    W = np.zeros(len(le))
    for e in range(len(le)):
        rx = ancf.shape_weights(xi, le[e], 1)[0] @ qe[e]
        rxx = ancf.shape_weights(xi, le[e], 2)[0] @ qe[e]
        eps = 0.5 * ((rx * rx).sum(1) - 1)
        W[e] = 0.5 * le[e] * np.sum(w * (kt[e] * eps**2 + kb[e] * (rxx * rxx).sum(1)))
    np.testing.assert_allclose(W5, W, rtol=1e-13)


def test_forces_are_the_energy_gradient():
    rng = np.random.default_rng(2)
    qe, le, kt, kb = _random_elements(rng)
    f = ancf.element_forces(qe, le, kt, kb)
    Q = kt[:, None, None] * f["ft"] + kb[:, None, None] * f["fb"]
    h = 1e-7
    for a in range(4):
        for i in range(3):
            dq = np.zeros_like(qe)
            dq[:, a, i] = h
            fd = (ancf.element_energy(qe + dq, le, kt, kb)
                  - ancf.element_energy(qe - dq, le, kt, kb)) / (2 * h)
            np.testing.assert_allclose(Q[:, a, i], fd, rtol=1e-6, atol=1e-9 * np.abs(Q).max())


def test_tangent_stiffness_matches_finite_differences():
    rng = np.random.default_rng(3)
    qe, le, kt, kb = _random_elements(rng)
    K = ancf.element_forces(qe, le, kt, kb)["K"]
    h = 1e-7

    def Q(q):
        f = ancf.element_forces(q, le, kt, kb, stiffness=False)
        return (kt[:, None, None] * f["ft"] + kb[:, None, None] * f["fb"]).reshape(len(le), 12)

    for c in range(12):
        dq = np.zeros((len(le), 12))
        dq[:, c] = h
        fd = (Q(qe + dq.reshape(qe.shape)) - Q(qe - dq.reshape(qe.shape))) / (2 * h)
        np.testing.assert_allclose(K[:, :, c], fd, rtol=1e-6, atol=1e-7 * np.abs(K).max())
    np.testing.assert_allclose(K, np.swapaxes(K, 1, 2), rtol=1e-12, atol=1e-12 * np.abs(K).max())


def test_length_derivative_matches_finite_differences():
    rng = np.random.default_rng(4)
    qe, le, kt, kb = _random_elements(rng)
    f = ancf.element_forces(qe, le, kt, kb, stiffness=False, length_derivative=True)
    h = 1e-8
    fp = ancf.element_forces(qe, le + h, kt, kb, stiffness=False)
    fm = ancf.element_forces(qe, le - h, kt, kb, stiffness=False)
    for k in ("ft", "fb"):
        fd = (fp[k] - fm[k]) / (2 * h)
        np.testing.assert_allclose(f["d" + k], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def test_gravity_weights_integrate_shape_functions():
    le = np.array([0.01, 0.05])
    w, dw = ancf.gravity_weights(le)
    x, gw = np.polynomial.legendre.leggauss(4)
    for e in range(2):
        S = ancf.shape_weights(0.5 * (x + 1), le[e])[0]
        np.testing.assert_allclose(w[e], le[e] * (0.5 * gw) @ S, rtol=1e-14)
    h = 1e-7
    fd = (ancf.gravity_weights(le + h)[0] - ancf.gravity_weights(le - h)[0]) / (2 * h)
    np.testing.assert_allclose(dw, fd, rtol=1e-6)
