"""Compiled right-hand side of a generalized-alpha Newton iteration (module ``_integrator``).

One call forms ``-[(M q'' + alpha M q' + beta T^-1 K_m T^-1 q' + T^-1 R_q) / beta' ; R_c]``
from the static residual ``R`` of eq. (25) (the compiled kernel of
``model/_kernels.py``): the Kelvin-Voigt force of module ``_inertia``
(the strain rates of eq. 17 at fixed stretch) summed element by element,
and a CSR product with the mass matrix, without temporary arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["dynamic_rhs"]


@njit(cache=True, nogil=True)
def dynamic_rhs(q, v, acc, s, r, nq, m_indptr, m_indices, m_data, elem_dofs, elem_act, le, kt,
                kb, h1, h2, gw, beta_kv, alpha_air, bp, out):  # pragma: no cover - compiled
    """Fill ``out`` (length N) with the Newton right-hand side; returns nothing."""
    for i in range(nq):
        acc_i = 0.0
        vel_i = 0.0
        for k in range(m_indptr[i], m_indptr[i + 1]):
            j = m_indices[k]
            acc_i += m_data[k] * acc[j]
            vel_i += m_data[k] * v[j]
        out[i] = acc_i + alpha_air * vel_i + r[i] / s[i]
    if beta_kv > 0.0:
        E = elem_dofs.shape[0]
        G = gw.shape[0]
        fe = np.empty((4, 3))
        for e in range(E):
            a_ = elem_act[e]
            L = le[a_]
            f1 = (1.0 / L, 1.0, 1.0 / L, 1.0)
            f2 = (1.0 / (L * L), 1.0 / L, 1.0 / (L * L), 1.0 / L)
            fe[:, :] = 0.0
            for g in range(G):
                rx0 = rx1 = rx2 = 0.0
                ux0 = ux1 = ux2 = 0.0
                uc0 = uc1 = uc2 = 0.0
                for a in range(4):
                    nx = h1[g, a] * f1[a]
                    nc = h2[g, a] * f2[a]
                    d0 = elem_dofs[e, 3 * a]
                    sq0 = 1.0 / s[d0]
                    sq1 = 1.0 / s[d0 + 1]
                    sq2 = 1.0 / s[d0 + 2]
                    qs0 = q[d0] * sq0
                    qs1 = q[d0 + 1] * sq1
                    qs2 = q[d0 + 2] * sq2
                    us0 = v[d0] * sq0
                    us1 = v[d0 + 1] * sq1
                    us2 = v[d0 + 2] * sq2
                    rx0 += nx * qs0
                    rx1 += nx * qs1
                    rx2 += nx * qs2
                    ux0 += nx * us0
                    ux1 += nx * us1
                    ux2 += nx * us2
                    uc0 += nc * us0
                    uc1 += nc * us1
                    uc2 += nc * us2
                w = gw[g] * L
                ct = w * kt[a_] * (rx0 * ux0 + rx1 * ux1 + rx2 * ux2)
                cb = w * kb[a_]
                for a in range(4):
                    nx = h1[g, a] * f1[a]
                    nc = h2[g, a] * f2[a]
                    fe[a, 0] += ct * nx * rx0 + cb * nc * uc0
                    fe[a, 1] += ct * nx * rx1 + cb * nc * uc1
                    fe[a, 2] += ct * nx * rx2 + cb * nc * uc2
            for a in range(4):
                for i in range(3):
                    d = elem_dofs[e, 3 * a + i]
                    out[d] += beta_kv * fe[a, i] / s[d]
    for i in range(nq):
        out[i] = -out[i] / bp
    for i in range(nq, out.shape[0]):
        out[i] = -r[i]
