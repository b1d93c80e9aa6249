"""Compiled parts of a generalized-alpha step (module ``_integrator``).

* :func:`dynamic_rhs` forms
  ``-[(M q'' + alpha M q' + beta T^-1 K_m T^-1 q' + T^-1 R_q) / beta' ; R_c]``
  from the static residual ``R`` of eq. (25) (the compiled kernel of
  ``model/_kernels.py``): the Kelvin-Voigt force of module ``_inertia``
  (the strain rates of eq. 17 at fixed stretch) summed element by element,
  and a CSR product with the mass matrix, without temporary arrays;
* :func:`chord_iterations` runs a step's predictor and chord-Newton
  iterations in one call (residual, right-hand side, :func:`lu_solve`,
  update, convergence and refactorisation tests): at a few hundred
  unknowns the Python around separate calls cost more than the arithmetic;
* :func:`run_steps` runs the steps of a run one after the other (the
  predictor's history, the state, the records of the samples), returning
  to Python only for a factorisation or a step that failed;
* :func:`lu_solve`, :func:`symbolic_factors`, :func:`refactor`: triangular
  solves with LU factors, and their numeric refactorisation along the
  pivots of an earlier SuperLU factorisation;
* :func:`state_checks`: a state's kinetic and potential energy and its
  largest constraint residual in one call (``Inertia.kinetic_energy`` and
  ``RobotModel.potential`` written as loops, the residual from the model's
  kernel: some 17 us for one segment, where the numpy read-outs took 0.3 ms).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..model import element_parameters, evaluate_kernel

__all__ = ["NEED_FACTOR", "chord_iterations", "chord_values", "compact_factors", "dynamic_rhs",
           "lu_solve", "refactor", "run_steps", "split_factors", "state_checks",
           "symbolic_factors"]


@njit(cache=True, nogil=True)
def dynamic_rhs(q, v, acc, s, r, nq, m_indptr, m_indices, m_data, elem_dofs, elem_act, le, kt,
                kb, h1, h2, gw, beta_kv, alpha_air, bp, out):  # pragma: no cover - compiled
    """Fill ``out`` (length N) with the Newton right-hand side; returns nothing."""
    si = np.empty(nq)  # T^-1 and the static coordinates and velocities, once per call
    qs = np.empty(nq)
    us = np.empty(nq)
    for i in range(nq):
        si[i] = 1.0 / s[i]
        qs[i] = q[i] * si[i]
        us[i] = v[i] * si[i]
    for i in range(nq):
        acc_i = 0.0
        vel_i = 0.0
        if alpha_air != 0.0:
            for k in range(m_indptr[i], m_indptr[i + 1]):
                j = m_indices[k]
                acc_i += m_data[k] * acc[j]
                vel_i += m_data[k] * v[j]
        else:   # no air damping (the robot files' default): one product, not two
            for k in range(m_indptr[i], m_indptr[i + 1]):
                acc_i += m_data[k] * acc[m_indices[k]]
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
                    qs0 = qs[d0]
                    qs1 = qs[d0 + 1]
                    qs2 = qs[d0 + 2]
                    us0 = us[d0]
                    us1 = us[d0 + 1]
                    us2 = us[d0 + 2]
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
                    out[d] += beta_kv * fe[a, i] * si[d]
    for i in range(nq):
        out[i] = -out[i] / bp
    for i in range(nq, out.shape[0]):
        out[i] = -r[i]


@njit(cache=True, nogil=True)
def chord_values(jac, map_static, static_rows, static_cols, rs, cs, mass_values, q, ti, le, kt,
                 kb, elem_dofs, elem_act, h1, h2, gw, damping, map_elem,
                 out):  # pragma: no cover - compiled
    """Fill ``out`` with the chord matrix's values (module ``_integrator``, ``_factor``).

    The static KKT Jacobian's CSC values ``jac`` scaled (``rs`` by row, ``cs``
    by column) into the chord pattern at ``map_static``, plus the mass's
    ``mass_values``, plus ``damping`` times the Kelvin-Voigt element blocks
    ``K_m`` (``Inertia.damping_blocks``: axial ``k_t B^T B`` with
    ``B = N_x (x) r_x``, bending ``k_b N_xx^T N_xx`` per coordinate) at the
    static coordinates ``q ti``, seen in material coordinates
    (``ti K_m ti``), at ``map_elem`` (each element's 12 x 12 block, rows
    first).  ``damping``: 0 leaves the blocks out.
    """
    for k in range(out.shape[0]):
        out[k] = mass_values[k]
    for k in range(jac.shape[0]):
        out[map_static[k]] += jac[k] * rs[static_rows[k]] * cs[static_cols[k]]
    if damping == 0.0:
        return
    E = elem_dofs.shape[0]
    G = gw.shape[0]
    K = np.empty((12, 12))
    S = np.empty((4, 4))
    B = np.empty(12)
    nx = np.empty(4)
    nc = np.empty(4)
    for e in range(E):
        a_ = elem_act[e]
        L = le[a_]
        f1 = (1.0 / L, 1.0, 1.0 / L, 1.0)
        f2 = (1.0 / (L * L), 1.0 / L, 1.0 / (L * L), 1.0 / L)
        K[:, :] = 0.0
        S[:, :] = 0.0
        for g in range(G):
            r0 = r1 = r2 = 0.0
            for a in range(4):
                nx[a] = h1[g, a] * f1[a]
                nc[a] = h2[g, a] * f2[a]
                d0 = elem_dofs[e, 3 * a]
                r0 += nx[a] * q[d0] * ti[d0]
                r1 += nx[a] * q[d0 + 1] * ti[d0 + 1]
                r2 += nx[a] * q[d0 + 2] * ti[d0 + 2]
            for a in range(4):
                B[3 * a] = nx[a] * r0
                B[3 * a + 1] = nx[a] * r1
                B[3 * a + 2] = nx[a] * r2
            wt = gw[g] * L * kt[a_]
            wb = gw[g] * L * kb[a_]
            for i in range(12):
                bi = wt * B[i]
                for j in range(12):
                    K[i, j] += bi * B[j]
            for a in range(4):
                for b in range(4):
                    S[a, b] += wb * nc[a] * nc[b]
        base = e * 144
        for i in range(12):
            di = elem_dofs[e, i]
            for j in range(12):
                dj = elem_dofs[e, j]
                v = K[i, j]
                if i % 3 == j % 3:
                    v += S[i // 3, j // 3]
                out[map_elem[base + 12 * i + j]] += damping * v * ti[di] * ti[dj]


@njit(cache=True, nogil=True)
def lu_solve(lu, b, work, out):  # pragma: no cover - compiled
    """Solve ``A out = b`` with SuperLU's factors of ``A``: ``Pr A Pc = L U``.

    ``lu``: ``(l_indptr, l_indices, l_data, l_diag, u_indptr, u_indices,
    u_data, u_diag, perm_r, perm_c)``, the off-diagonal entries of ``L`` and
    ``U`` by columns and their diagonals (:func:`split_factors`).  Two
    triangular sweeps over the stored entries, no allocation: SuperLU's own
    ``solve`` costs several times more at these sizes (a few hundred
    unknowns), most of it call overhead.
    """
    l_indptr, l_indices, l_data, l_diag, u_indptr, u_indices, u_data, u_diag, perm_r, perm_c = lu
    n = b.shape[0]
    for i in range(n):
        work[perm_r[i]] = b[i]
    for j in range(n):
        xj = work[j] / l_diag[j]
        work[j] = xj
        if xj != 0.0:
            for k in range(l_indptr[j], l_indptr[j + 1]):
                work[l_indices[k]] -= l_data[k] * xj
    for j in range(n - 1, -1, -1):
        xj = work[j] / u_diag[j]
        work[j] = xj
        if xj != 0.0:
            for k in range(u_indptr[j], u_indptr[j + 1]):
                work[u_indices[k]] -= u_data[k] * xj
    for i in range(n):
        out[i] = work[perm_c[i]]


def split_factors(superlu):
    """The arrays :func:`lu_solve` takes, from a ``scipy.sparse.linalg.SuperLU`` object."""
    L, U = superlu.L, superlu.U
    return (_split_triangular(L.indptr, L.indices, L.data)
            + _split_triangular(U.indptr, U.indices, U.data)
            + (np.asarray(superlu.perm_r, dtype=np.int64),
               np.asarray(superlu.perm_c, dtype=np.int64)))


@njit(cache=True, nogil=True)
def _split_triangular(indptr, indices, data):  # pragma: no cover - compiled
    """A CSC triangle as (indptr, indices, data) of its off-diagonal entries and its diagonal."""
    n = indptr.shape[0] - 1
    ptr = np.zeros(n + 1, dtype=np.int64)
    idx = np.empty(indices.shape[0], dtype=np.int64)
    val = np.empty(indices.shape[0])
    diag = np.zeros(n)
    k = 0
    for j in range(n):
        for p in range(indptr[j], indptr[j + 1]):
            i = indices[p]
            if i == j:
                diag[j] = data[p]
            else:  # sorted by row within the column (insertion): refactor's order
                m = k
                while m > ptr[j] and idx[m - 1] > i:
                    idx[m] = idx[m - 1]
                    val[m] = val[m - 1]
                    m -= 1
                idx[m] = i
                val[m] = data[p]
                k += 1
        ptr[j + 1] = k
    return ptr, idx[:k].copy(), val[:k].copy(), diag


@njit(cache=True, nogil=True)
def compact_factors(lu):  # pragma: no cover - compiled
    """``lu`` without its off-diagonal entries that are exactly zero (fewer to sweep)."""
    l_indptr, l_indices, l_data, l_diag, u_indptr, u_indices, u_data, u_diag, perm_r, perm_c = lu
    out = []
    for indptr, indices, data in ((l_indptr, l_indices, l_data), (u_indptr, u_indices, u_data)):
        n = indptr.shape[0] - 1
        ptr = np.zeros(n + 1, dtype=np.int64)
        idx = np.empty(indices.shape[0], dtype=np.int64)
        val = np.empty(indices.shape[0])
        k = 0
        for j in range(n):
            for p in range(indptr[j], indptr[j + 1]):
                if data[p] != 0.0:
                    idx[k] = indices[p]
                    val[k] = data[p]
                    k += 1
            ptr[j + 1] = k
        out.append((ptr, idx[:k].copy(), val[:k].copy()))
    return (out[0][0], out[0][1], out[0][2], l_diag, out[1][0], out[1][1], out[1][2], u_diag,
            perm_r, perm_c)


@njit(cache=True, nogil=True)
def symbolic_factors(indptr, indices, perm_r, perm_c):  # pragma: no cover - compiled
    """The pattern of the LU factors of a CSC pattern for fixed row and column permutations.

    Every entry that can be non-zero (no cancellation assumed), as the
    tuple of :func:`lu_solve` with zero values: the pattern :func:`refactor`
    fills.  SuperLU's own factors leave out the entries that happened to be
    zero in the matrix it factorised (a robot's pattern holds exact zeros),
    which a later matrix of the same pattern may need.  ``O(n^2)``, once
    per pivot order.
    """
    n = indptr.shape[0] - 1
    inv_c = np.empty(n, dtype=np.int64)
    for i in range(n):
        inv_c[perm_c[i]] = i
    flag = np.zeros(n, dtype=np.bool_)
    l_ptr = np.zeros(n + 1, dtype=np.int64)
    u_ptr = np.zeros(n + 1, dtype=np.int64)
    l_idx = np.empty(4 * indices.shape[0] + n, dtype=np.int64)
    u_idx = np.empty(4 * indices.shape[0] + n, dtype=np.int64)
    nl = 0
    nu = 0
    for j in range(n):
        c = inv_c[j]
        for p in range(indptr[c], indptr[c + 1]):
            flag[perm_r[indices[p]]] = True
        for k in range(j):  # ascending: the fill of every earlier column reaches the later
            if flag[k]:
                for q in range(l_ptr[k], l_ptr[k + 1]):
                    flag[l_idx[q]] = True
        for k in range(n):
            if flag[k]:
                flag[k] = False
                if k < j:
                    if nu == u_idx.shape[0]:
                        u_idx = np.concatenate((u_idx, np.empty(u_idx.shape[0], np.int64)))
                    u_idx[nu] = k
                    nu += 1
                elif k > j:
                    if nl == l_idx.shape[0]:
                        l_idx = np.concatenate((l_idx, np.empty(l_idx.shape[0], np.int64)))
                    l_idx[nl] = k
                    nl += 1
        l_ptr[j + 1] = nl
        u_ptr[j + 1] = nu
    return (l_ptr, l_idx[:nl].copy(), np.zeros(nl), np.ones(n), u_ptr, u_idx[:nu].copy(),
            np.zeros(nu), np.ones(n), perm_r.astype(np.int64), perm_c.astype(np.int64))


@njit(cache=True, nogil=True)
def refactor(indptr, indices, data, lu, b, work):  # pragma: no cover - compiled
    """LU factors of the CSC matrix ``A`` with the pivots and the pattern of ``lu``.

    The numeric part of a sparse LU (left-looking, Gilbert & Peierls) along
    the row and column permutations an earlier SuperLU factorisation of the
    same pattern chose, as KLU refactors: no ordering, no pivot search, no
    symbolic analysis, so a fraction of a full factorisation.  Returns the
    new factors (the tuple of :func:`lu_solve`) and the backward error of a
    solve with them, ``|A x - b| / (|A| |x| + |b|)`` (maximum norms; infinite
    for a zero pivot): pivots that no longer suit the matrix show there, and
    the caller then factorises afresh.
    """
    l_indptr, l_indices, l_data0, l_diag0, u_indptr, u_indices, u_data0, u_diag0, perm_r, \
        perm_c = lu
    n = indptr.shape[0] - 1
    l_data = np.empty_like(l_data0)
    u_data = np.empty_like(u_data0)
    l_diag = np.ones(n)
    u_diag = np.empty(n)
    inv_c = np.empty(n, dtype=np.int64)
    for i in range(n):
        inv_c[perm_c[i]] = i
    x = work
    x[:] = 0.0
    singular = False
    for j in range(n):
        c = inv_c[j]
        for p in range(indptr[c], indptr[c + 1]):
            x[perm_r[indices[p]]] = data[p]
        for p in range(u_indptr[j], u_indptr[j + 1]):  # rows k < j, ascending
            k = u_indices[p]
            xk = x[k]
            u_data[p] = xk
            x[k] = 0.0
            if xk != 0.0:
                for q in range(l_indptr[k], l_indptr[k + 1]):
                    x[l_indices[q]] -= l_data[q] * xk
        piv = x[j]
        if piv == 0.0 or not np.isfinite(piv):  # these pivots cannot factorise this matrix
            singular = True
            piv = 1.0
        u_diag[j] = piv
        x[j] = 0.0
        for q in range(l_indptr[j], l_indptr[j + 1]):
            i = l_indices[q]
            l_data[q] = x[i] / piv
            x[i] = 0.0
    out = (l_indptr, l_indices, l_data, l_diag, u_indptr, u_indices, u_data, u_diag, perm_r,
           perm_c)
    sol = np.empty(n)
    lu_solve(out, b, x, sol)
    r = -b.copy()
    a_norm = 0.0
    for c in range(n):
        col = 0.0
        for p in range(indptr[c], indptr[c + 1]):
            r[indices[p]] += data[p] * sol[c]
            col += abs(data[p])
        a_norm = max(a_norm, col)   # the 1-norm: a bound of the same size
    err = np.max(np.abs(r)) / (a_norm * np.max(np.abs(sol)) + np.max(np.abs(b)))
    if singular or not np.isfinite(err):
        err = np.inf
    return out, err


#: Contraction rate of the chord iterations above which the matrix is refactorised: a
#: factorisation costs as much as some 50 iterations, so a rate that only ties up a
#: few more iterations per step is kept (the rate of two updates is noisy).
SLOW_RATE = 0.5


@njit(cache=True, nogil=True)
def _iterations_left(left, c, tol):  # pragma: no cover - compiled
    """Iterations still needed at contraction rate ``c`` to bring the error ``left`` to ``tol``."""
    if left <= tol:
        return 0
    if tol <= 0.0 or c <= 0.0:
        return 1 << 30
    return int(np.ceil(np.log(tol / left) / np.log(c)))


@njit(cache=True, nogil=True)
def chord_iterations(st0, prev, weights, predict, st, coef, inputs, kargs, mass, lu, ctl,
                     work):  # pragma: no cover - compiled
    """Chord-Newton iterations of one generalized-alpha step (module ``_integrator``).

    Arguments, grouped in tuples:

    * ``st0 = (q, v, acc, aux, mu)`` at ``t_n``; ``prev = (acc, mu, acc,
      mu)`` at ``t_{n-1}`` and ``t_{n-2}``;
    * ``st = (q, v, acc, aux, mu)``: the step's unknowns, set by the predictor
      when ``predict`` (accelerations and multipliers extrapolated,
      ``w0 x_n + w1 x_{n-1} + w2 x_{n-2}`` with ``weights = (w0, w1, w2)``;
      ``(1, 0, 0)``: constant), then updated in place;
    * ``coef = (h, alpha_m, alpha_f, beta, gamma, beta_kv, alpha_air)``;
    * ``inputs = (lam, slope_act, k_coefficients, dk_coefficients, l0,
      n_elements, d_a, rho0, g, Qpoint)``: the stretches at ``t_{n+1}``
      (``slope_act``: the actuator of each slope coordinate, -1 elsewhere)
      and the loads; ``kargs``: the model's kernel arguments;
    * ``mass``: the CSR mass matrix; ``lu``: the chord matrix (:func:`lu_solve`);
    * ``ctl = (inv_scale, tol, it0, max_iter, last, refreshed)``: iterations
      ``it0`` to ``max_iter``, the last update's size, whether the matrix
      was made in this step; ``work``: four arrays of length N.

    Each iteration: the static residual (the model's ``evaluate_kernel``),
    the dynamic right-hand side (:func:`dynamic_rhs`), the solve with the
    chord matrix, the update.  Converged when the update, or the error it
    leaves (``size c / (1 - c)`` at contraction rate ``c``), is within
    ``tol``.  Returns ``(code, iterations done, last update size)``: ``0``
    converged (``st[3]`` set), ``1`` slow iterations: refactor at the
    current iterate and call again, ``2`` diverging after a refactorisation,
    ``3`` a non-finite right-hand side, ``4`` the budget spent, ``5``
    converged to a non-finite state.
    """
    q0, v0, acc0, aux0, mu0 = st0
    q, v, acc, aux, mu = st
    h, am, af, be, ga, beta_kv, alpha_air = coef
    lam, slope_act, kcoef, dkcoef, l0, n_el, d_a, rho0, g, qpoint = inputs
    m_indptr, m_indices, m_data = mass
    inv_scale, tol, it0, max_iter, last, refreshed = ctl
    xs, rhs, d, s = work
    nq = q.shape[0]
    nc = mu.shape[0]
    for i in range(nq):  # T(lam) (Inertia.scale) and the element parameters (RobotModel's)
        a = slope_act[i]
        s[i] = lam[a] if a >= 0 else 1.0
    le, kt, kb, dle, dkt, dkb = element_parameters(lam, kcoef, dkcoef, l0, n_el, d_a)
    bp = (1.0 - am) / ((1.0 - af) * h * h * be)
    gp = ga / (h * be)
    if predict:
        acc_1, mu_1, acc_2, mu_2 = prev
        w0, w1, w2 = weights
        for i in range(nq):
            a = w0 * acc0[i] + w1 * acc_1[i] + w2 * acc_2[i]
            x = (af * acc0[i] - am * aux0[i] + (1.0 - af) * a) / (1.0 - am)
            acc[i] = a
            v[i] = v0[i] + h * ((1.0 - ga) * aux0[i] + ga * x)
            q[i] = q0[i] + h * v0[i] + h * h * ((0.5 - be) * aux0[i] + be * x)
        for i in range(nc):
            mu[i] = w0 * mu0[i] + w1 * mu_1[i] + w2 * mu_2[i]
    xq = xs[:nq]
    for it in range(it0, max_iter):
        for i in range(nq):
            xq[i] = q[i] / s[i]
        r, _, _ = evaluate_kernel(xq, mu, lam, le, kt, kb, dle, dkt, dkb, rho0, g, qpoint,
                                  *kargs, False, False)
        dynamic_rhs(q, v, acc, s, r, nq, m_indptr, m_indices, m_data, kargs[0], kargs[1], le,
                    kt, kb, kargs[2], kargs[3], kargs[4], beta_kv, alpha_air, bp, rhs)
        total = 0.0
        for i in range(rhs.shape[0]):
            total += rhs[i]
        if not np.isfinite(total):
            return 3, it - it0, last
        lu_solve(lu, rhs, xs, d)
        size = 0.0
        for i in range(nq):
            dq = d[i]
            q[i] += dq
            v[i] += gp * dq
            acc[i] += bp * dq
            a = abs(dq * inv_scale[i])
            if a > size:
                size = a
        for i in range(nc):
            mu[i] += bp * d[nq + i]
        # the error left after this update: about size * c / (1 - c) for a contraction
        # rate c = size / last of the chord iterations (at least size * 1e-3: roundoff)
        left = size
        if it >= 1:
            c = size / last
            left = size * max(c / (1.0 - c), 1e-3) if c < 1.0 else np.inf
        if size <= tol or left <= tol:
            finite = True
            for i in range(nq):
                aux[i] = (af * acc0[i] - am * aux0[i] + (1.0 - af) * acc[i]) / (1.0 - am)
                if not (np.isfinite(q[i]) and np.isfinite(v[i])):
                    finite = False
            return (0 if finite else 5), it + 1 - it0, size
        # slow or diverging chord iterations: refactor at the current iterate, unless the
        # matrix is fresh (then a rate of 0.9 still converges, a rate above 1 fails)
        if it >= 1:
            c = size / last
            if refreshed:
                if c > 1.0:
                    return 2, it + 1 - it0, size
                if c >= 0.9:
                    return 1, it + 1 - it0, size
            elif c > SLOW_RATE or it + 1 + _iterations_left(left, c, tol) > max_iter:
                return 1, it + 1 - it0, size
        last = size
    return 4, max_iter - it0, last


#: :func:`run_steps` asks for the chord matrix at the step's current iterate.
NEED_FACTOR = 1
#: Iterations counted against a chord matrix after which the next step makes it afresh
#: (:func:`run_steps`).  A factorisation costs 13-21 iterations (measured, its values
#: assembled and factorised: one and two segments, the model's elements and twice as many).
#: A step's iteration beyond its matrix's first full step's is not counted: in a smooth run
#: (the bench's sine) a step takes one more as the robot moves on, and a matrix made afresh
#: for it did not pay back (7 % more CPU, counting it); the 10x circle's steps took two to
#: four more.
FACTOR_ITERATIONS = 10


@njit(cache=True, nogil=True)
def _weights(h, cur, hist):  # pragma: no cover - compiled
    """The predictor's earlier values and weights for a step ``h`` (``run_steps``).

    Lagrange extrapolation of the accelerations and multipliers to
    ``t_n + h`` from ``t_n`` and the (up to) two states before: constant
    after a start, linear after one step, quadratic after two.
    """
    acc0, mu0 = cur[2], cur[4]
    ah, mh, hh, count = hist
    if count[0] == 0:
        return (acc0, mu0, acc0, mu0), (1.0, 0.0, 0.0)
    h1 = hh[0]
    if count[0] == 1:
        r = h / h1
        return (ah[0], mh[0], ah[0], mh[0]), (1.0 + r, -r, 0.0)
    h2 = hh[1]
    w0 = (h + h1) * (h + h1 + h2) / (h1 * (h1 + h2))
    w1 = -h * (h + h1 + h2) / (h1 * h2)
    w2 = h * (h + h1) / ((h1 + h2) * h2)
    return (ah[0], mh[0], ah[1], mh[1]), (w0, w1, w2)


@njit(cache=True, nogil=True)
def run_steps(cur, nxt, hist, steps, lams, k0, resume, coef, stage1, qpoint, kargs, mass, lu,
              ctl, work, rec, out):  # pragma: no cover - compiled
    """Steps ``k0, k0 + 1, ...`` of a run in one call: predictor, iterations, history, records.

    * ``cur = (q, v, acc, aux, mu)``: the last converged state, advanced in
      place after every step; ``nxt``: five arrays for the step's unknowns;
    * ``hist = (acc (2, nq), mu (2, nc), steps (2,), count (1,))``: the
      accelerations, multipliers and steps of the two states before ``cur``
      (``count`` of them known), advanced in place;
    * ``steps (n,)``, ``lams (n, A)``: each step's length and its stretches
      at its end; ``resume = (predict, it0, last, refreshed)``: how step
      ``k0`` starts (a fresh step: ``(True, 0, inf, False)``; after a
      factorisation the caller asked for: ``(False, it, last, True)``);
    * ``coef = (alpha_m, alpha_f, beta, gamma, beta_kv, alpha_air)``;
      ``stage1 = (slope_act, k_coefficients, dk_coefficients, l0,
      n_elements, d_a, rho0, g)`` and ``qpoint``: as the ``inputs`` of
      :func:`chord_iterations` without the stretches;
    * ``ctl = (inv_scale, tol, max_iter, lu_step, stale)``: ``lu_step`` the
      step the chord matrix ``lu`` was made for (0: none yet); ``stale``
      (int64, (3,)), kept in place from call to call: the iterations its
      steps took beyond one more than the first full step with it, that
      step's, and whether it is still to be taken.  Once they add up to
      :data:`FACTOR_ITERATIONS` the next step asks for a fresh matrix (rent
      until the rent adds up to the price, then buy).  A matrix made far
      from where the robot now is converges slowly, though at a rate below
      :data:`SLOW_RATE`;
    * ``rec = (row (n,), check (n,), dofs)``: after step ``k``, when
      ``row[k] >= 0``, the coordinates ``dofs`` go to ``out[0][row[k]]`` and,
      when ``check[k]``, :func:`state_checks` (kinetic, potential, largest
      ``|C|``) to ``out[1][row[k]]``.

    Returns ``(code, k, it, last, iterations)``: ``code`` 0 when every step
    is done (``k = n``); :data:`NEED_FACTOR` when step ``k`` needs the chord
    matrix at its current iterate ``nxt`` (then call again from ``k`` with
    ``resume = (False, it, last, True)``); otherwise :func:`chord_iterations`'
    code of the step ``k`` that failed (``cur`` is the state before it).
    ``iterations``: the iterations done in this call.
    """
    am, af, be, ga, beta_kv, alpha_air = coef
    slope_act, kcoef, dkcoef, l0, n_el, d_a, rho0, g = stage1
    inv_scale, tol, max_iter, lu_step, stale = ctl
    row, check, dofs = rec
    out_q, out_checks = out
    ah, mh, hh, count = hist
    predict, it, last, refreshed = resume
    total = 0
    for k in range(k0, steps.shape[0]):
        h = steps[k]
        lam = lams[k]
        inputs = (lam, slope_act, kcoef, dkcoef, l0, n_el, d_a, rho0, g, qpoint)
        step_coef = (h, am, af, be, ga, beta_kv, alpha_air)
        prev, weights = _weights(h, cur, hist)
        if predict and (lu_step <= 0.0 or abs(lu_step - h) > 0.25 * h
                        or stale[0] >= FACTOR_ITERATIONS):
            # the predictor alone: the point to factor the chord matrix at
            chord_iterations(cur, prev, weights, True, nxt, step_coef, inputs, kargs, mass, lu,
                             (inv_scale, tol, 0, 0, np.inf, False), work)
            return NEED_FACTOR, k, 0, np.inf, total
        code, n, last = chord_iterations(cur, prev, weights, predict, nxt, step_coef, inputs,
                                         kargs, mass, lu,
                                         (inv_scale, tol, it, max_iter, last, refreshed), work)
        fresh_from = it   # iterations of this step before its matrix was made (refreshed)
        it += n
        total += n
        if code == 1 and it < max_iter:
            return NEED_FACTOR, k, it, last, total
        if code != 0:
            return (4 if code == 1 else code), k, it, last, total
        # converged: the history moves on, the state becomes the step's
        if refreshed:   # the iterations count against this step's (or the next one's)
            stale[0] = 0
            stale[1] = n
            stale[2] = 1 if fresh_from > 0 else 0
        elif stale[2]:
            stale[1] = n
            stale[2] = 0
        else:
            stale[0] += max(n - stale[1] - 1, 0)
        acc0 = cur[2]
        mu0 = cur[4]
        if count[0] >= 1:
            ah[1, :] = ah[0]
            mh[1, :] = mh[0]
            hh[1] = hh[0]
        ah[0, :] = acc0
        mh[0, :] = mu0
        hh[0] = h
        count[0] = min(count[0] + 1, 2)
        for j in range(5):
            cur[j][:] = nxt[j]
        r = row[k]
        if r >= 0:
            for i in range(dofs.shape[0]):
                out_q[r, i] = cur[0][dofs[i]]
            if check[k]:
                kin, pot, worst = state_checks(cur[0], cur[1], cur[4], inputs, kargs, mass)
                out_checks[r, 0] = kin
                out_checks[r, 1] = pot
                out_checks[r, 2] = worst
        predict, it, last, refreshed = True, 0, np.inf, False
    return 0, steps.shape[0], 0, np.inf, total


@njit(cache=True, nogil=True)
def state_checks(q, v, mu, inputs, kargs, mass):  # pragma: no cover - compiled
    """Kinetic energy, potential energy and largest constraint residual of a state.

    ``q, v, mu``: material coordinates, velocities and multipliers;
    ``inputs``, ``kargs``, ``mass``: as :func:`chord_iterations` takes them
    (the stretches and loads of the state).  The kinetic energy is
    ``1/2 v^T M v``; the potential (eqs. 15-17) the elastic energy of every
    element (five Gauss points, as ``element_energy``) minus the work of
    gravity (``gravity_weights``) and the point forces, at the static
    coordinates ``T(lam)^-1 q``; the constraint residual ``max |C|`` comes
    from the model's kernel.  Returns ``(kinetic, potential, max |C|)``.
    """
    lam, slope_act, kcoef, dkcoef, l0, n_el, d_a, rho0, g, qpoint = inputs
    m_indptr, m_indices, m_data = mass
    elem_dofs, elem_act, h1, h2, gw = kargs[0], kargs[1], kargs[2], kargs[3], kargs[4]
    nq = q.shape[0]
    qs = np.empty(nq)
    for i in range(nq):
        a = slope_act[i]
        qs[i] = q[i] / lam[a] if a >= 0 else q[i]
    kinetic = 0.0
    for i in range(nq):
        mv = 0.0
        for k in range(m_indptr[i], m_indptr[i + 1]):
            mv += m_data[k] * v[m_indices[k]]
        kinetic += 0.5 * v[i] * mv
    le, kt, kb, dle, dkt, dkb = element_parameters(lam, kcoef, dkcoef, l0, n_el, d_a)
    elastic = 0.0
    work = 0.0
    for i in range(nq):
        work += qpoint[i] * qs[i]
    for e in range(elem_dofs.shape[0]):
        a_ = elem_act[e]
        L = le[a_]
        f1 = (1.0 / L, 1.0, 1.0 / L, 1.0)
        f2 = (1.0 / (L * L), 1.0 / L, 1.0 / (L * L), 1.0 / L)
        wg = (0.5 * L, L * L / 12.0, 0.5 * L, -L * L / 12.0)   # gravity_weights
        rho = rho0 / lam[a_]
        dens = 0.0
        for gp in range(gw.shape[0]):
            rx0 = rx1 = rx2 = 0.0
            rc0 = rc1 = rc2 = 0.0
            for a in range(4):
                nx = h1[gp, a] * f1[a]
                nc = h2[gp, a] * f2[a]
                d0 = elem_dofs[e, 3 * a]
                rx0 += nx * qs[d0]
                rx1 += nx * qs[d0 + 1]
                rx2 += nx * qs[d0 + 2]
                rc0 += nc * qs[d0]
                rc1 += nc * qs[d0 + 1]
                rc2 += nc * qs[d0 + 2]
            eps = 0.5 * (rx0 * rx0 + rx1 * rx1 + rx2 * rx2 - 1.0)
            dens += gw[gp] * (kt[a_] * eps * eps + kb[a_] * (rc0 * rc0 + rc1 * rc1 + rc2 * rc2))
        elastic += 0.5 * L * dens
        for a in range(4):
            d0 = elem_dofs[e, 3 * a]
            work += rho * wg[a] * (g[0] * qs[d0] + g[1] * qs[d0 + 1] + g[2] * qs[d0 + 2])
    r, _, _ = evaluate_kernel(qs, mu, lam, le, kt, kb, dle, dkt, dkb, rho0, g, qpoint, *kargs,
                              False, False)
    worst = 0.0
    for i in range(nq, r.shape[0]):
        x = abs(r[i])
        if x > worst or x != x:   # NaN stays (no later x > NaN)
            worst = x
    return kinetic, elastic - work, worst
