"""The integrator's compiled linear algebra: triangular solves, refactorisation, its check."""

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from bellow_ancf_ros.core import solve_forward
from bellow_ancf_ros.core.dynamics import GeneralizedAlpha, Inertia
from bellow_ancf_ros.core.dynamics._integrator import REFACTOR_ERROR
from bellow_ancf_ros.core.dynamics._kernels import (compact_factors, lu_solve, refactor,
                                                    split_factors, symbolic_factors)


def _chord_matrix(model, pressures, step_s):
    """A chord matrix of the integrator (its pattern, with the values of this state)."""
    ig = GeneralizedAlpha(model, step_s=step_s)
    ig.start(solve_forward(model, pressures))
    ig._lu = None
    ig.advance(step_s)
    captured = []
    real = ig._decompose
    ig._decompose = lambda data: captured.append(data.copy()) or real(data)
    ig._factor(ig.state, step_s)
    A = sp.csc_matrix((captured[0], ig._indices, ig._indptr), shape=(model.N, model.N))
    return ig, A


def test_refactor_along_old_pivots_solves_a_changed_matrix(one):
    ig, A0 = _chord_matrix(one, np.zeros(3), 0.002)
    _, A1 = _chord_matrix(one, np.array([80e3, 0.0, -20e3]), 0.003)  # other state and step
    b = np.random.default_rng(3).standard_normal(one.N)
    work, x = np.empty(one.N), np.empty(one.N)
    superlu = spla.splu(A0, permc_spec="COLAMD")
    lu_solve(split_factors(superlu), b, work, x)   # SuperLU's own factors
    np.testing.assert_allclose(x, superlu.solve(b), rtol=1e-10, atol=0)
    sym = symbolic_factors(ig._indptr64, ig._indices64, superlu.perm_r, superlu.perm_c)
    lu, err = refactor(ig._indptr64, ig._indices64, A1.data, sym, ig._check_b, work)
    assert err <= REFACTOR_ERROR
    lu_solve(compact_factors(lu), b, work, x)
    ref = spla.spsolve(A1, b)
    np.testing.assert_allclose(x, ref, rtol=0, atol=1e-10 * np.abs(ref).max())


def test_refactor_reports_pivots_that_no_longer_suit(one):
    ig, A0 = _chord_matrix(one, np.zeros(3), 0.002)
    superlu = spla.splu(A0, permc_spec="COLAMD")
    sym = symbolic_factors(ig._indptr64, ig._indices64, superlu.perm_r, superlu.perm_c)
    # the first pivot made zero: the old pivot order cannot factorise this matrix
    inv_c = np.argsort(superlu.perm_c)
    col = inv_c[0]
    row = np.flatnonzero(superlu.perm_r == 0)[0]
    A = A0.tolil()
    A[row, col] = 0.0
    A = A.tocsc()
    data = np.asarray(A[ig._indices, np.repeat(np.arange(one.N), np.diff(ig._indptr))]).ravel()
    work = np.empty(one.N)
    _, err = refactor(ig._indptr64, ig._indices64, data, sym, ig._check_b, work)
    assert err == np.inf   # the integrator then has SuperLU pivot afresh


def test_integrator_factorises_afresh_when_kept_pivots_fail(one):
    ig, A = _chord_matrix(one, np.zeros(3), 0.002)
    kept = one.cached(("chord pattern", ig._key.tobytes()), lambda _: {})
    good = kept["symbolic"]
    bad = good[:8] + (good[8][::-1].copy(), good[9])   # rows in reverse: zero pivots
    kept["symbolic"] = bad
    lu = ig._decompose(A.data.copy())
    assert kept["symbolic"] is not bad
    b = np.random.default_rng(4).standard_normal(one.N)
    x = np.empty(one.N)
    lu_solve(lu, b, np.empty(one.N), x)
    np.testing.assert_allclose(A @ x, b, rtol=0, atol=1e-9 * np.abs(b).max())


def test_the_chord_matrix_is_mass_damping_and_stiffness_seen_in_material_coordinates(two):
    """The compiled assembly against the sparse matrices of the model and ``Inertia``.

    The dynamic block: ``(T^-1 J T^-1 + b' M + g' D) / b'`` with the static
    Jacobian ``J``, ``T`` the stretch map, ``D`` the Kelvin-Voigt damping
    matrix (``Inertia.damping_matrix``, its own assembly); the constraints'
    rows and columns seen through ``T^-1``, the multipliers scaled by ``b'``.
    """
    h = 0.004
    ig, A = _chord_matrix(two, np.array([30e3, 0.0, 10e3, 0.0, 20e3, 5e3]), h)
    st, m = ig.state, two
    bp = (1 - ig.alpha_m) / ((1 - ig.alpha_f) * h * h * ig.beta)
    gp = ig.gamma / (h * ig.beta)
    ti = 1.0 / ig.inertia.scale(st.stretch)
    ev = m.evaluate(np.concatenate([st.q * ti, st.mu]), st.stretch, 1.0, st.load, jacobian=True)
    J = ev.jacobian.toarray()
    nq = m.nq
    inertia = Inertia(m, ig.inertia.damping_time, 0.0)
    assert inertia.damping_time > 0
    ref = np.zeros((m.N, m.N))
    ref[:nq, :nq] = (ti[:, None] * J[:nq, :nq] * ti[None, :]
                     + bp * inertia.mass_matrix(0.0).toarray()
                     + gp * inertia.damping_matrix(st.q, st.stretch).toarray()) / bp
    ref[:nq, nq:] = ti[:, None] * J[:nq, nq:]
    ref[nq:, :nq] = J[nq:, :nq] * ti[None, :]
    ref[nq:, nq:] = J[nq:, nq:] * bp
    scale = np.abs(ref).max()
    np.testing.assert_allclose(A.toarray(), ref, rtol=0, atol=1e-12 * scale)
