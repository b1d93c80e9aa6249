"""Stability of an equilibrium in linear time: penalised envelope factorisation, dense fallback.

An equilibrium is stable when the Hessian of the Lagrangian ``H`` is
positive definite on the tangent space of the constraints ``C_q z = 0``
(docs/model.md, stability).  :class:`ReducedHessian` tests this with a
dense null-space basis ``Z`` (cost ~ N^3).  Here the same test, to the same
threshold, costs ~ N:

In scaled coordinates ``H_s = D H D``, ``C_s = C_q D`` the dense test asks
whether ``Z^T (H_s - s I) Z`` is positive definite, ``s = rtol * max|H_s|``.
For any ``rho >= 0`` and any positive row weights ``W``::

    z^T (H_s - s I + rho C_s^T W C_s) z = z^T (H_s - s I) z   for C_s z = 0,

so a successful Cholesky factorisation of the penalised matrix
``A(rho) = H_s - s I + rho C_s^T W C_s`` proves the equilibrium stable, and
by Finsler's lemma some finite ``rho`` succeeds whenever it is.  ``A`` is
sparse with the coupling of the robot's chain; in the level order of
:mod:`core.linalg._kkt` (unknowns by height along the robot) its fill stays in
an envelope that does not grow with the element and segment counts, and its
factorisation (:meth:`core.linalg._ldlt.EnvelopeKKT.positive_definite`: an LDL^T
whose pivots must all be positive, the operations of a Cholesky
factorisation without the square roots) is linear in the size.  Two
penalties are tried (``rho = 10`` and ``1e4`` times ``max|H_s|``, rows of
``C_s`` normalised); if both fail, the exact dense test decides (unstable
equilibria, or a margin within ~1e-8 of buckling), so every answer is the
dense test's answer or a proof of it.
"""

from __future__ import annotations

import numpy as np

from ..linalg import coordinates_envelope, one_thread
from ._newton import ReducedHessian

__all__ = ["StabilityCheck", "PENALTIES"]

PENALTIES = (10.0, 1e4)


class StabilityCheck:
    """Stability of the equilibrium with KKT matrix ``jacobian`` (eq. 27) of ``model``.

    Same interface as :class:`ReducedHessian`: ``is_positive_definite(rtol)``
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
                self._dense = ReducedHessian(
                    self.jacobian, self.model.nq, self.model.dof_scale
                )
        return self._dense

    def is_positive_definite(self, rtol=1e-10):
        """Smallest reduced eigenvalue above ``rtol * max|H_s|``? (banded proof, else dense)."""
        m = self.model
        J = self.jacobian
        same = (J.indices is m.csc_indices and J.indptr is m.csc_indptr) or (
            J.indices.shape == m.csc_indices.shape and np.array_equal(J.indptr, m.csc_indptr)
            and np.array_equal(J.indices, m.csc_indices))
        if same:  # (else: not the model's pattern, never seen: the dense test)
            pat = coordinates_envelope(m)
            D = np.ascontiguousarray(m.dof_scale, dtype=float)
            for pen in PENALTIES:
                try:
                    proved = pat.positive_definite(J, D, pen, rtol)
                except ValueError:  # non-zeros outside the pattern
                    break
                if proved:
                    self.proved_by = pen
                    return True
        with one_thread():
            return self.dense.is_positive_definite(rtol)

    @property
    def min_eigenvalue(self):
        """Smallest eigenvalue of the reduced Hessian pencil (scaled coordinates)."""
        with one_thread():
            return self.dense.min_eigenvalue
