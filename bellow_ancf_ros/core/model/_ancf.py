"""Gradient-deficient ANCF beam element (paper section III.B-C).

One element has two nodes with nodal coordinates ``[r, r_x]`` (eq. 5), twelve
coordinates in the order ``[r_1, r_x1, r_2, r_x2]``.  The position field is
``r(x) = S(x) q_e`` (eq. 6) with the cubic Hermite shape functions of eq. (7)::

    S = [h1 I, le*h2 I, h3 I, le*h4 I],  xi = x / le

so that every quantity is a sum over four 3-vectors ``q_e[a]`` weighted by a
scalar shape function.  This module keeps those scalar weights and works on
element coordinates of shape ``(E, 4, 3)``: all element math is vectorised over
elements and Gauss points.

Elastic energy (eqs. 11, 17)::

    W = 1/2 int_0^le (k_t eps^2 + k_b r_xx.r_xx) dx,   eps = (r_x.r_x - 1)/2

``r_x`` is quadratic in ``xi``, so ``eps^2`` has degree 8 and five Gauss-
Legendre points integrate the energy, the forces (eq. 18) and the tangent
stiffness exactly.

Each function also returns the derivative with respect to the element length
``le``; the stretch of stage 1 enters stage 2 only through ``le``, ``k_t`` and
``k_b``, which is what the inverse problem's Jacobian (eq. 30) needs.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "GAUSS_XI",
    "GAUSS_W",
    "hermite",
    "shape_weights",
    "element_energy",
    "element_forces",
    "gravity_weights",
]

# Five-point Gauss-Legendre rule on [0, 1] (exact to degree 9).
_gx, _gw = np.polynomial.legendre.leggauss(5)
GAUSS_XI = 0.5 * (_gx + 1.0)
GAUSS_W = 0.5 * _gw


def hermite(xi, derivative=0):
    """Cubic Hermite polynomials h1..h4 of eq. (7) (without the ``le`` factors).

    Returns an array of shape ``xi.shape + (4,)`` holding ``d^k h_a / dxi^k``.
    """
    xi = np.asarray(xi, dtype=float)
    if derivative == 0:
        h = [1 - 3 * xi**2 + 2 * xi**3, xi - 2 * xi**2 + xi**3,
             3 * xi**2 - 2 * xi**3, -(xi**2) + xi**3]
    elif derivative == 1:
        h = [-6 * xi + 6 * xi**2, 1 - 4 * xi + 3 * xi**2, 6 * xi - 6 * xi**2, -2 * xi + 3 * xi**2]
    elif derivative == 2:
        h = [-6 + 12 * xi, -4 + 6 * xi, 6 - 12 * xi, -2 + 6 * xi]
    else:
        raise ValueError("derivative must be 0, 1 or 2")
    return np.stack(np.broadcast_arrays(*h), axis=-1)


def _le_powers(le, derivative):
    """Factors that turn h_a^(k) into d^k S_a / dx^k, and their le-derivative.

    ``S_a = h_a * [1, le, 1, le]``; each x-derivative divides by ``le``.
    Returns ``(f, df_dle)`` of shape ``le.shape + (4,)``.
    """
    le = np.asarray(le, dtype=float)[..., None]
    one = np.ones_like(le)
    # exponent of le for a = 0..3: [0, 1, 0, 1] - derivative
    e = np.array([0, 1, 0, 1]) - derivative
    f = le**e * one
    df = e * le ** (e - 1) * one
    return f, df


def shape_weights(xi, le, derivative=0):
    """Scalar weights ``d^k S_a/dx^k (xi; le)`` and their derivative w.r.t. ``le``.

    ``xi`` and ``le`` broadcast; result shape ``broadcast(xi, le).shape + (4,)``.
    ``r^(k)(x) = sum_a w[a] * q_e[a]`` (eqs. 6, 7).
    """
    h = hermite(xi, derivative)
    f, df = _le_powers(le, derivative)
    return h * f, h * df


def gravity_weights(le):
    """``int_0^le S_a dx`` for the four blocks (eqs. 15, 16): ``le*[1/2, le/12, 1/2, -le/12]``.

    Returns ``(w, dw_dle)`` of shape ``le.shape + (4,)``.
    """
    le = np.asarray(le, dtype=float)
    w = np.stack([le / 2, le**2 / 12, le / 2, -(le**2) / 12], axis=-1)
    dw = np.stack([0.5 + 0 * le, le / 6, 0.5 + 0 * le, -le / 6], axis=-1)
    return w, dw


_H1 = hermite(GAUSS_XI, 1)  # (G, 4)
_H2 = hermite(GAUSS_XI, 2)  # (G, 4)


def _kinematics(qe, le):
    """Gauss-point kinematics of all elements (vectorised, batched matrix products)."""
    f1, df1 = _le_powers(le, 1)  # (E, 4)
    f2, df2 = _le_powers(le, 2)
    Nx = _H1[None, :, :] * f1[:, None, :]  # (E, G, 4)
    Nxx = _H2[None, :, :] * f2[:, None, :]
    dNx = _H1[None, :, :] * df1[:, None, :]
    dNxx = _H2[None, :, :] * df2[:, None, :]
    rx = Nx @ qe  # (E, G, 3)
    rxx = Nxx @ qe
    eps = 0.5 * ((rx * rx).sum(-1) - 1.0)
    return Nx, Nxx, dNx, dNxx, rx, rxx, eps


def _wsum(N, w, r):
    """``sum_g w[e,g] N[e,g,a] r[e,g,i]`` -> (E, 4, 3)."""
    return (N * w[:, :, None]).transpose(0, 2, 1) @ r


def element_energy(qe, le, kt, kb):
    """Elastic energy of every element, eq. (17), shape ``(E,)``."""
    qe = np.asarray(qe, dtype=float)
    _, _, _, _, rx, rxx, eps = _kinematics(qe, le)
    dens = kt[:, None] * eps**2 + kb[:, None] * (rxx * rxx).sum(-1)
    return 0.5 * le * (dens @ GAUSS_W)


def element_forces(qe, le, kt, kb, stiffness=True, length_derivative=False):
    """Generalised elastic forces (eq. 18), tangent stiffness and le-derivatives.

    Parameters
    ----------
    qe : (E, 4, 3) element coordinates ``[r_1, r_x1, r_2, r_x2]``.
    le, kt, kb : (E,) element length, tensile stiffness ``k_t`` (eq. 2) and
        bending stiffness ``k_b`` (eq. 4).

    Returns a dict with
    ``ft, fb`` : (E, 4, 3) tensile and bending parts of ``Q_e`` per unit
        stiffness (``Q_e = kt*ft + kb*fb``), so that derivatives with respect
        to ``k_t`` and ``k_b`` are free;
    ``K`` : (E, 12, 12) tangent stiffness ``dQ_e/dq_e`` (if ``stiffness``);
    ``dft, dfb`` : (E, 4, 3) derivatives of ``ft, fb`` w.r.t. ``le`` (if
        ``length_derivative``).
    """
    qe = np.asarray(qe, dtype=float)
    le = np.asarray(le, dtype=float)
    Nx, Nxx, dNx, dNxx, rx, rxx, eps = _kinematics(qe, le)
    wle = GAUSS_W[None, :] * le[:, None]  # (E, G) quadrature weight * jacobian
    out = {"ft": _wsum(Nx, wle * eps, rx), "fb": _wsum(Nxx, wle, rxx)}
    if stiffness:
        E = qe.shape[0]
        # tensile: kt * sum_g w le Nx_a Nx_b (rx_i rx_j + eps delta_ij);
        # bending: kb Nxx_a Nxx_b delta_ij
        M = (Nx[:, :, :, None] * rx[:, :, None, :]).reshape(E, -1, 12)
        K = (M * (wle * kt[:, None])[:, :, None]).transpose(0, 2, 1) @ M
        S = (Nx * (wle * eps * kt[:, None])[:, :, None]).transpose(0, 2, 1) @ Nx
        S += (Nxx * (wle * kb[:, None])[:, :, None]).transpose(0, 2, 1) @ Nxx
        K = K.reshape(E, 4, 3, 4, 3)
        for i in range(3):
            K[:, :, i, :, i] += S
        out["K"] = K.reshape(E, 12, 12)
    if length_derivative:
        drx = dNx @ qe
        drxx = dNxx @ qe
        deps = (rx * drx).sum(-1)
        w = np.broadcast_to(GAUSS_W[None, :], wle.shape)
        out["dft"] = (_wsum(Nx, w * eps + wle * deps, rx) + _wsum(dNx, wle * eps, rx)
                      + _wsum(Nx, wle * eps, drx))
        out["dfb"] = _wsum(Nxx, w, rxx) + _wsum(dNxx, wle, rxx) + _wsum(Nxx, wle, drxx)
    return out
