"""Stability of an equilibrium in linear time: penalised banded Cholesky, exact dense fallback.

An equilibrium is stable when the Hessian of the Lagrangian ``H`` is
positive definite on the tangent space of the constraints ``C_q z = 0``
(docs/model.md, stability).  :class:`solver.ReducedHessian` tests this with a
dense null-space basis ``Z`` (cost ~ N^3).  Here the same test, to the same
threshold, costs ~ N:

In scaled coordinates ``H_s = D H D``, ``C_s = C_q D`` the dense test asks
whether ``Z^T (H_s - s I) Z`` is positive definite, ``s = rtol * max|H_s|``.
For any ``rho >= 0`` and any positive row weights ``W``::

    z^T (H_s - s I + rho C_s^T W C_s) z = z^T (H_s - s I) z   for C_s z = 0,

so a successful Cholesky factorisation of the penalised matrix
``A(rho) = H_s - s I + rho C_s^T W C_s`` proves the equilibrium stable, and
by Finsler's lemma some finite ``rho`` succeeds whenever it is.  ``A`` is
sparse with the coupling of the robot's chain;
in the level order of :mod:`core.linsolve` (unknowns by height along the
robot) it is banded with a bandwidth independent of the element and segment counts,
and its Cholesky factorisation (LAPACK's banded ``dpbtrf``, BLAS on one
thread) is linear in the size.  Two penalties are tried (``rho = 10`` and ``1e4`` times
``max|H_s|``, rows of ``C_s`` normalised); if both fail, the exact dense test
decides (unstable equilibria, or a margin within ~1e-8 of buckling), so
every answer is the dense test's answer or a proof of it.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg.lapack as lapack
import scipy.sparse as sp
from numba import njit

from . import solver
from .blas import one_thread
from .linsolve import level_order

__all__ = ["StabilityCheck", "BandedPattern", "banded_cholesky"]

PENALTIES = (10.0, 1e4)


class BandedPattern:
    """Level order (core.linsolve) and bandwidth of ``H + C_q^T C_q`` (built once per model)."""

    def __init__(self, model):
        nq, N = model.nq, model.N
        keep = model.structural_nonzeros().astype(float)  # always-zero entries do not count
        J = sp.csc_matrix(
            (keep, model._csc_indices.copy(), model._csc_indptr.copy()), shape=(N, N)
        )
        J.eliminate_zeros()
        H = J[:nq, :nq]
        C = J[nq:, :nq]
        A = (abs(H) + abs(C.T) @ abs(C) + sp.eye(nq)).tocoo()
        order = level_order(model)
        perm = order[order < nq].astype(np.int64)
        iperm = np.empty(nq, dtype=np.int64)
        iperm[perm] = np.arange(nq)
        self.kd = int(np.max(np.abs(iperm[A.row] - iperm[A.col])))
        self.iperm = iperm
        self.nq = nq
        self.csc = (model._csc_indptr, model._csc_indices)  # the model's pattern, and in int64:
        self.csc64 = (model._csc_indptr.astype(np.int64), model._csc_indices.astype(np.int64))


def _pattern(model):
    pat = getattr(model, "_banded_pattern", None)
    if pat is None:
        pat = model._banded_pattern = BandedPattern(model)
    return pat


def banded_cholesky(ab):
    """In-place Cholesky ``A = L L^T`` of a banded SPD matrix; ``ab[j, k] = A[j + k, j]``.

    LAPACK's ``dpbtrf`` (``ab.T`` is its lower band storage), BLAS on one
    thread.  Returns False when ``A`` is not positive definite (a pivot is
    not positive); ``ab`` then holds a partial factor.
    """
    ab = np.asarray(ab)
    if not (ab.flags.c_contiguous and ab.dtype == np.float64):
        raise ValueError("banded_cholesky: a C-contiguous float64 array (factorised in place)")
    with one_thread():
        _, info = lapack.dpbtrf(ab.T, lower=1, overwrite_ab=1)
    return info == 0


@njit(cache=True, nogil=True)
def _assemble(data, indptr, indices, nq, D, iperm, kd):
    """Banded ``H_s``, penalty ``C_s^T W C_s`` (rows of ``C_s`` normalised) and ``max|H_s|``."""
    bh = np.zeros((nq, kd + 1))
    bp = np.zeros((nq, kd + 1))
    ref = 0.0
    for j in range(nq):
        pj = iperm[j]
        for k in range(indptr[j], indptr[j + 1]):
            i = indices[k]
            if i < nq:
                v = D[i] * data[k] * D[j]
                if abs(v) > ref:
                    ref = abs(v)
                pi = iperm[i]
                if pi >= pj and pi - pj <= kd:  # outside: entries that are always zero
                    bh[pj, pi - pj] += v
    N = indptr.shape[0] - 1
    for c in range(nq, N):
        a, b = indptr[c], indptr[c + 1]
        s = 0.0
        for k in range(a, b):
            i = indices[k]
            if i < nq:
                s += (data[k] * D[i]) ** 2
        if s == 0.0:
            continue
        w = 1.0 / s
        for k in range(a, b):
            i = indices[k]
            if i >= nq:
                continue
            vi = data[k] * D[i]
            pi = iperm[i]
            for kk in range(a, b):
                jj = indices[kk]
                if jj >= nq:
                    continue
                pl = iperm[jj]
                if pl <= pi and pi - pl <= kd:
                    bp[pl, pi - pl] += w * vi * data[kk] * D[jj]
    return bh, bp, ref


def _penalised_test(bh, bp, ref, rtol, penalties):
    """Index of the first penalty whose ``A(rho)`` factorises, or -1."""
    shift = rtol * ref
    for t, pen in enumerate(penalties):
        ab = bh + (pen * ref) * bp
        ab[:, 0] -= shift
        if banded_cholesky(ab):
            return t
    return -1


class StabilityCheck:
    """Stability of the equilibrium with KKT matrix ``jacobian`` (eq. 27) of ``model``.

    Same interface as :class:`solver.ReducedHessian`: ``is_positive_definite(rtol)``
    and ``min_eigenvalue`` (the dense generalised eigenproblem, on demand).
    ``proved_by`` tells which penalty proved stability (None: dense test).
    """

    def __init__(self, jacobian, model):
        self.jacobian = jacobian
        self.model = model
        self.proved_by = None
        self._dense = None

    @property
    def dense(self):
        """The exact dense reduced Hessian (built on first use, one BLAS thread)."""
        if self._dense is None:
            with one_thread():
                self._dense = solver.ReducedHessian(
                    self.jacobian, self.model.nq, self.model.dof_scale
                )
        return self._dense

    def is_positive_definite(self, rtol=1e-10):
        """Smallest reduced eigenvalue above ``rtol * max|H_s|``? (banded proof, else dense)."""
        m = self.model
        J = self.jacobian
        pat = _pattern(m)
        if (J.indices.shape == pat.csc[1].shape and np.array_equal(J.indptr, pat.csc[0])
                and np.array_equal(J.indices, pat.csc[1])):
            indptr, indices = pat.csc64
        else:
            indptr, indices = J.indptr.astype(np.int64), J.indices.astype(np.int64)
        bh, bp, ref = _assemble(
            J.data,
            indptr,
            indices,
            m.nq,
            m.dof_scale,
            pat.iperm,
            pat.kd,
        )
        t = _penalised_test(bh, bp, ref, float(rtol), PENALTIES)
        if t >= 0:
            self.proved_by = PENALTIES[t]
            return True
        with one_thread():
            return self.dense.is_positive_definite(rtol)

    @property
    def min_eigenvalue(self):
        """Smallest eigenvalue of the reduced Hessian pencil (scaled coordinates)."""
        with one_thread():
            return self.dense.min_eigenvalue
