"""Compiled kernels: residual (eq. 25), its Jacobian (eq. 27) and dR/dlam (eq. 30).

The same mathematics as :mod:`bellow_ancf_ros.core.model._ancf` (element forces,
eqs. 17, 18, five Gauss points) and the constraint rows of
:mod:`bellow_ancf_ros.core.model._assembly` (attachments, parallel gradients,
orthonormal plate axes), written as loops compiled by numba.  The Jacobian
values are summed straight into the CSC storage of the KKT pattern that the
model builds once (``RobotModel._build_pattern``): its COO order is the order
in which the values are produced here.  Nothing here calls BLAS, so the
kernels run on one thread however they are called.

Compilation is cached on disk (``cache=True``) and triggered by
:func:`warm_up` when a model is built, never inside a control loop.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["evaluate_kernel", "element_parameters", "horner"]

_PAIRS = np.array([[0, 0], [1, 1], [2, 2], [0, 1], [0, 2], [1, 2]], dtype=np.int64)


@njit(cache=True, nogil=True)
def _element_part(
    q,
    lam,
    le_a,
    kt_a,
    kb_a,
    dle_a,
    dkt_a,
    dkb_a,
    rho0,
    g,
    elem_dofs,
    elem_act,
    H1,
    H2,
    GW,
    res,
    data,
    d,
    want_jac,
    want_lam,
):
    """Elastic forces (eq. 18), tangent stiffness, gravity (eq. 16) and their lam-derivatives."""
    E = elem_dofs.shape[0]
    qe = np.empty((4, 3))
    ft = np.empty((4, 3))
    fb = np.empty((4, 3))
    dft = np.empty((4, 3))
    dfb = np.empty((4, 3))
    K = np.empty((12, 12))
    Nx = np.empty(4)
    Nxx = np.empty(4)
    dNx = np.empty(4)
    dNxx = np.empty(4)
    rx = np.empty(3)
    rxx = np.empty(3)
    drx = np.empty(3)
    drxx = np.empty(3)
    M = np.empty(12)
    for e in range(E):
        a = elem_act[e]
        le, kt, kb = le_a[a], kt_a[a], kb_a[a]
        il = 1.0 / le
        f1 = (il, 1.0, il, 1.0)
        f2 = (il * il, il, il * il, il)
        df1 = (-il * il, 0.0, -il * il, 0.0)
        df2 = (-2.0 * il * il * il, -il * il, -2.0 * il * il * il, -il * il)
        for b in range(4):
            for i in range(3):
                qe[b, i] = q[elem_dofs[e, 3 * b + i]]
        ft[:] = 0.0
        fb[:] = 0.0
        dft[:] = 0.0
        dfb[:] = 0.0
        K[:] = 0.0
        for gp in range(GW.shape[0]):
            for b in range(4):
                Nx[b] = H1[gp, b] * f1[b]
                Nxx[b] = H2[gp, b] * f2[b]
                dNx[b] = H1[gp, b] * df1[b]
                dNxx[b] = H2[gp, b] * df2[b]
            for i in range(3):
                s1 = 0.0
                s2 = 0.0
                for b in range(4):
                    s1 += Nx[b] * qe[b, i]
                    s2 += Nxx[b] * qe[b, i]
                rx[i] = s1
                rxx[i] = s2
            eps = 0.5 * (rx[0] * rx[0] + rx[1] * rx[1] + rx[2] * rx[2] - 1.0)
            w = GW[gp]
            wle = w * le
            for b in range(4):
                for i in range(3):
                    ft[b, i] += wle * eps * Nx[b] * rx[i]
                    fb[b, i] += wle * Nxx[b] * rxx[i]
            if want_jac:
                for b in range(4):
                    for i in range(3):
                        M[3 * b + i] = Nx[b] * rx[i]
                ck = wle * kt
                for r in range(12):
                    for c in range(12):
                        K[r, c] += ck * M[r] * M[c]
                for b in range(4):
                    for c in range(4):
                        s = ck * eps * Nx[b] * Nx[c] + wle * kb * Nxx[b] * Nxx[c]
                        for i in range(3):
                            K[3 * b + i, 3 * c + i] += s
            if want_lam:
                for i in range(3):
                    s1 = 0.0
                    s2 = 0.0
                    for b in range(4):
                        s1 += dNx[b] * qe[b, i]
                        s2 += dNxx[b] * qe[b, i]
                    drx[i] = s1
                    drxx[i] = s2
                deps = rx[0] * drx[0] + rx[1] * drx[1] + rx[2] * drx[2]
                for b in range(4):
                    for i in range(3):
                        dft[b, i] += (
                            Nx[b] * (w * eps + wle * deps) * rx[i]
                            + dNx[b] * wle * eps * rx[i]
                            + Nx[b] * wle * eps * drx[i]
                        )
                        dfb[b, i] += (
                            Nxx[b] * w * rxx[i] + dNxx[b] * wle * rxx[i] + Nxx[b] * wle * drxx[i]
                        )
        # gravity of the element (eqs. 15, 16), density rho0 / lam
        rho = rho0 / lam[a]
        wg = (le / 2.0, le * le / 12.0, le / 2.0, -le * le / 12.0)
        dwg = (0.5, le / 6.0, 0.5, -le / 6.0)
        for b in range(4):
            dwl = (-rho / lam[a]) * wg[b] + rho * dle_a[a] * dwg[b]
            for i in range(3):
                k = elem_dofs[e, 3 * b + i]
                res[k] += kt * ft[b, i] + kb * fb[b, i] - rho * wg[b] * g[i]
                if want_lam:
                    d[k, a] += (
                        dkt_a[a] * ft[b, i]
                        + dkb_a[a] * fb[b, i]
                        + dle_a[a] * (kt * dft[b, i] + kb * dfb[b, i])
                        - dwl * g[i]
                    )
        if want_jac:
            base = e * 144
            for r in range(12):
                for c in range(12):
                    data[base + 12 * r + c] = K[r, c]


@njit(cache=True, nogil=True)
def _constraint_part(
    q,
    alpha,
    le_a,
    dle_a,
    aed,
    pdofs,
    att_act,
    att_free,
    att_c,
    att_h,
    h_att,
    h1_att,
    plate_dofs,
    c_rows,
    c_cols,
    nq,
    ne_vals,
    res,
    data,
    d,
    want_jac,
    want_lam,
):
    """Constraint values, their Jacobian (as C_q and C_q^T), the Hessian of alpha.C, lam terms."""
    G = aed.shape[0]
    P = plate_dofs.shape[0]
    nf = 0
    for gi in range(G):
        if att_free[gi]:
            nf += 1
    nc_vals = G * 12 + nf * 12 + G * 24 + nf * 6 + P * 36
    cv = np.empty(nc_vals)
    nh = nf * 24
    hv = np.empty(nh)
    qe = np.empty((4, 3))
    d12 = np.empty((2, 3))
    X = np.empty(3)
    r = np.empty(3)
    rx = np.empty(3)
    N = np.empty(4)
    Nx = np.empty(4)
    o_a = 0
    o_b = G * 12
    o_c = o_b + nf * 12
    o_d = o_c + G * 24
    o_e = o_d + nf * 6
    fi = 0
    for gi in range(G):
        act = att_act[gi]
        le = le_a[act]
        f0 = (1.0, le, 1.0, le)
        f1 = (1.0 / le, 1.0, 1.0 / le, 1.0)
        for b in range(4):
            N[b] = h_att[gi, b] * f0[b]
            Nx[b] = h1_att[gi, b] * f1[b]
            for i in range(3):
                qe[b, i] = q[aed[gi, b, i]]
        for i in range(3):
            s0 = 0.0
            s1 = 0.0
            for b in range(4):
                s0 += N[b] * qe[b, i]
                s1 += Nx[b] * qe[b, i]
            r[i] = s0
            rx[i] = s1
        free = att_free[gi]
        if free:
            for k in range(2):
                for i in range(3):
                    d12[k, i] = q[pdofs[gi, 1 + k, i]]
            for i in range(3):
                X[i] = (
                    q[pdofs[gi, 0, i]]
                    + att_c[gi, 0] * q[pdofs[gi, 1, i]]
                    + att_c[gi, 1] * q[pdofs[gi, 2, i]]
                    + att_h[gi] * q[pdofs[gi, 3, i]]
                )
        else:
            d12[:] = 0.0
            d12[0, 0] = 1.0
            d12[1, 1] = 1.0
            for i in range(3):
                X[i] = att_c[gi, i]
        row = nq + 5 * gi
        for i in range(3):
            res[row + i] = r[i] - X[i]
        for k in range(2):
            res[row + 3 + k] = d12[k, 0] * rx[0] + d12[k, 1] * rx[1] + d12[k, 2] * rx[2]
        for b in range(4):
            for i in range(3):
                cv[o_a + 12 * gi + 3 * b + i] = N[b]
                for k in range(2):
                    cv[o_c + 24 * gi + 12 * k + 3 * b + i] = Nx[b] * d12[k, i]
        if free:
            coef = (1.0, att_c[gi, 0], att_c[gi, 1], att_h[gi])
            for b in range(4):
                for i in range(3):
                    cv[o_b + 12 * fi + 3 * b + i] = -coef[b]
            for k in range(2):
                for i in range(3):
                    cv[o_d + 6 * fi + 3 * k + i] = rx[i]
                ak = alpha[5 * gi + 3 + k]
                for b in range(4):
                    for i in range(3):
                        hv[24 * fi + 12 * k + 3 * b + i] = ak * Nx[b]
        if want_lam:
            dl = dle_a[act]
            # dN = h * [0, 1, 0, 1], dNx = h1 * [-1/le^2, 0, -1/le^2, 0]
            dN = (0.0, h_att[gi, 1], 0.0, h_att[gi, 3])
            il2 = 1.0 / (le * le)
            dNx = (-h1_att[gi, 0] * il2, 0.0, -h1_att[gi, 2] * il2, 0.0)
            drx = np.zeros(3)
            for i in range(3):
                s0 = 0.0
                s1 = 0.0
                for b in range(4):
                    s0 += dN[b] * qe[b, i]
                    s1 += dNx[b] * qe[b, i]
                d[row + i, act] = s0 * dl
                drx[i] = s1 * dl
            for k in range(2):
                d[row + 3 + k, act] = d12[k, 0] * drx[0] + d12[k, 1] * drx[1] + d12[k, 2] * drx[2]
            for b in range(4):
                for i in range(3):
                    t = dN[b] * alpha[5 * gi + i] * dl
                    t += (
                        dNx[b]
                        * (alpha[5 * gi + 3] * d12[0, i] + alpha[5 * gi + 4] * d12[1, i])
                        * dl
                    )
                    d[aed[gi, b, i], act] += t
            if free:
                for k in range(2):
                    for i in range(3):
                        d[pdofs[gi, 1 + k, i], act] += alpha[5 * gi + 3 + k] * drx[i]
        if free:
            fi += 1
    # orthonormality of the plate axes d_i.d_j = delta_ij
    for p in range(P):
        for m in range(6):
            i0 = _PAIRS[m, 0]
            j0 = _PAIRS[m, 1]
            s = 0.0
            for i in range(3):
                di = q[plate_dofs[p, 3 + 3 * i0 + i]]
                dj = q[plate_dofs[p, 3 + 3 * j0 + i]]
                s += di * dj
                cv[o_e + 36 * p + 6 * m + i] = dj
                cv[o_e + 36 * p + 6 * m + 3 + i] = di
            res[nq + 5 * G + 6 * p + m] = s - (1.0 if i0 == j0 else 0.0)
    # constraint forces C_q^T alpha in the force rows
    for k in range(nc_vals):
        res[c_cols[k]] += cv[k] * alpha[c_rows[k]]
    if want_jac:
        o = ne_vals
        for k in range(nc_vals):
            data[o + k] = cv[k]
            data[o + nc_vals + k] = cv[k]
        o += 2 * nc_vals
        for k in range(nh):
            data[o + k] = hv[k]
            data[o + nh + k] = hv[k]
        o += 2 * nh
        no = P * 18
        for p in range(P):
            for m in range(6):
                a_pm = alpha[5 * G + 6 * p + m]
                for i in range(3):
                    data[o + 18 * p + 3 * m + i] = a_pm
                    data[o + no + 18 * p + 3 * m + i] = a_pm
    return nc_vals


@njit(cache=True, nogil=True)
def horner(a, c):
    """``sum_i c[i] a**i`` for the array ``a`` (ascending coefficients ``c``), as ``polyval``."""
    out = np.full(a.shape[0], c[c.shape[0] - 1])
    for k in range(c.shape[0] - 2, -1, -1):
        out = out * a + c[k]
    return out


@njit(cache=True, nogil=True)
def element_parameters(lam, kcoef, dkcoef, l0, n_el, d_a):
    """Per-actuator ``le, k_t, k_b`` and their derivatives w.r.t. ``lam`` (eqs. 2, 4).

    ``kcoef``, ``dkcoef``: stage 1's ``k(lam)`` and ``dk/dlam`` (ascending
    coefficients); ``le = lam l0 / n``, ``k_t = k l0``, ``k_b = D_a^2 l0 lam k / 8``.
    """
    k = horner(lam, kcoef)
    dk = horner(lam, dkcoef)
    le = lam * l0 / n_el
    kt = k * l0
    kb = d_a * d_a * l0 * lam * k / 8.0
    dle = np.full(lam.shape[0], l0 / n_el)
    dkt = dk * l0
    dkb = d_a * d_a * l0 * (k + lam * dk) / 8.0
    return le, kt, kb, dle, dkt, dkb


@njit(cache=True, nogil=True)
def _scatter(coo_map, coo_vals, nnz):
    """Sum COO values into the CSC data array of the fixed pattern."""
    out = np.zeros(nnz)
    for k in range(coo_map.shape[0]):
        out[coo_map[k]] += coo_vals[k]
    return out


@njit(cache=True, nogil=True)
def evaluate_kernel(
    q,
    alpha,
    lam,
    le_a,
    kt_a,
    kb_a,
    dle_a,
    dkt_a,
    dkb_a,
    rho0,
    g,
    Qpoint,
    elem_dofs,
    elem_act,
    H1,
    H2,
    GW,
    aed,
    pdofs,
    att_act,
    att_free,
    att_c,
    att_h,
    h_att,
    h1_att,
    plate_dofs,
    c_rows,
    c_cols,
    coo_map,
    nnz,
    want_jac,
    want_lam,
):
    """Residual (eq. 25), CSC values of the KKT Jacobian (eq. 27) and dR/dlam (eq. 30).

    ``Qpoint`` holds the point forces (eq. 14) already scaled; ``g`` the
    scaled gravity.  Returns ``(residual, csc_data or empty, dres_dlam or empty)``.
    """
    nq = q.shape[0]
    nc = alpha.shape[0]
    A = lam.shape[0]
    res = np.zeros(nq + nc)
    for k in range(nq):
        res[k] = -Qpoint[k]
    ne_vals = elem_dofs.shape[0] * 144
    n_coo = coo_map.shape[0]
    vals = np.zeros(n_coo if want_jac else 0)
    d = np.zeros((nq + nc, A) if want_lam else (0, A))
    _element_part(
        q,
        lam,
        le_a,
        kt_a,
        kb_a,
        dle_a,
        dkt_a,
        dkb_a,
        rho0,
        g,
        elem_dofs,
        elem_act,
        H1,
        H2,
        GW,
        res,
        vals,
        d,
        want_jac,
        want_lam,
    )
    _constraint_part(
        q,
        alpha,
        le_a,
        dle_a,
        aed,
        pdofs,
        att_act,
        att_free,
        att_c,
        att_h,
        h_att,
        h1_att,
        plate_dofs,
        c_rows,
        c_cols,
        nq,
        ne_vals,
        res,
        vals,
        d,
        want_jac,
        want_lam,
    )
    data = _scatter(coo_map, vals, nnz) if want_jac else np.zeros(0)
    return res, data, d
