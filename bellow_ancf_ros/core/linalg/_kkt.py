"""Linear solves with the KKT matrix (eq. 27): envelope LDL^T, else banded LU in level order.

A factorisation is first the symmetric LDL^T of :mod:`core.linalg._ldlt` (no
pivoting, its growth measured); where that is refused, the banded LU below.

The KKT matrix of a robot is sparse with the coupling of a chain: element
nodes, plates and multipliers at one height only touch their neighbours.
Ordered by height along the robot (``level order``: every unknown at its
material position, segment by segment), it is banded with a bandwidth that
does not grow with the element or segment count (43 for one segment and for
two, of 240 and 480 unknowns with six elements), and LAPACK's banded LU with
partial pivoting (``dgbtrf``, backward stable like a sparse LU) factorises
it in time linear in the size, two to three times faster than SuperLU at
these sizes.  Pattern entries that are always zero (the far node of an
attachment that sits on a node) stay out of the band.

(Reusing one factorisation along a path with iterative refinement was
measured too: at these sizes the extra multi-column solves cost as much as
the factorisations they save, so every matrix is factorised.)

BLAS runs on one thread inside these calls (:mod:`core.linalg._blas`).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg.lapack as lapack

from ._blas import one_thread
from ._ldlt import EnvelopeKKT
from ._ordering import level_order

__all__ = ["BandedKKT", "BandedLU", "KKTSolver", "kkt_solver"]


class BandedKKT:
    """Banded storage of one model's KKT pattern in level order (built once per model)."""

    def __init__(self, model):
        N = model.N
        perm = level_order(model)
        iperm = np.empty(N, dtype=np.int64)
        iperm[perm] = np.arange(N)
        cols = np.repeat(np.arange(N), np.diff(model.csc_indptr))
        keep = model.structural_nonzeros()  # entries that are always zero stay out of the band
        r, c = iperm[model.csc_indices][keep], iperm[cols][keep]
        self.kl = int(np.max(r - c))
        self.ku = int(np.max(c - r))
        self.rows = 2 * self.kl + self.ku + 1
        # LAPACK band storage: A[i, j] -> ab[kl + ku + i - j, j]
        self.flat = (self.kl + self.ku + r - c) * N + c
        self.keep = keep
        self.dropped = np.flatnonzero(~keep)
        self.perm, self.iperm = perm, iperm
        self.N = N
        self.nnz = model.nnz

    def factor(self, J):
        """Banded LU with partial pivoting of ``J`` (CSC, model's pattern); None if singular."""
        if J.nnz != self.nnz:
            raise ValueError("matrix does not have the model's KKT pattern")
        if self.dropped.size and np.any(J.data[self.dropped]):
            raise ValueError("matrix has non-zeros outside the model's band")
        ab = np.zeros((self.rows, self.N))
        ab.ravel()[self.flat] = J.data[self.keep]
        with one_thread():
            lub, piv, info = lapack.dgbtrf(ab, self.kl, self.ku, overwrite_ab=1)
        if info != 0 or not np.all(np.isfinite(lub[self.kl + self.ku])):
            return None
        return BandedLU(self, lub, piv)


class BandedLU:
    """A banded LU factorisation; ``solve`` takes and returns unknowns in the model's order."""

    def __init__(self, pattern, lub, piv):
        self.p, self.lub, self.piv = pattern, lub, piv

    def solve(self, b):
        """Solve ``J x = b`` (``b``: vector or matrix of columns)."""
        p = self.p
        bp = np.asarray(b, dtype=float)[p.perm]
        with one_thread():
            x, info = lapack.dgbtrs(self.lub, p.kl, p.ku, bp, self.piv)
        out = np.empty_like(x)
        out[p.perm] = x
        return out


class KKTSolver:
    """Solves with the KKT matrices of one model (patterns built once).

    A factorisation is the symmetric envelope LDL^T of :mod:`core.linalg._ldlt`
    (two to three times faster than the banded LU) when its growth is
    small, else the banded LU with partial pivoting.
    """

    def __init__(self, model):
        """Build both patterns of ``model``."""
        self.pattern = BandedKKT(model)
        self.envelope = EnvelopeKKT(model)
        self.scale = np.ascontiguousarray(model.dof_scale, dtype=float)

    def solve(self, J, b):
        """Solve ``J x = b`` (``b``: vector or columns) with a new factorisation of ``J``.

        Raises ``numpy.linalg.LinAlgError`` when ``J`` is singular.
        """
        return self.bound(J).solve(b)

    def bound(self, J):
        """Factorisation of ``J`` made on first use: ``.solve(b)`` as many times as needed."""
        return _Factorised(self, J)


class _Factorised:
    def __init__(self, solver, J):
        self.solver, self.J, self.lu = solver, J, None

    def solve(self, b):
        """Solve ``J x = b``; raises ``numpy.linalg.LinAlgError`` when ``J`` is singular."""
        if self.lu is None:
            ks = self.solver
            try:
                self.lu = ks.envelope.factor(self.J, ks.scale)  # None: growth too large
                if self.lu is None:
                    self.lu = ks.pattern.factor(self.J)
            except ValueError:  # not the model's pattern (never seen): general sparse LU
                self.lu = _sparse_lu(self.J)
            if self.lu is None:
                raise np.linalg.LinAlgError("singular KKT matrix")
        x = self.lu.solve(b)
        if not np.all(np.isfinite(x)):
            raise np.linalg.LinAlgError("singular KKT matrix")
        return x


def _sparse_lu(J):
    """Factorise ``J`` with SuperLU (or return None when it is singular)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    try:
        return spla.splu(sp.csc_matrix(J), permc_spec="COLAMD")
    except RuntimeError:
        return None


def kkt_solver(model):
    """The model's KKT solver (one per model, made on first use)."""
    return model.cached("kkt_solver", KKTSolver)


def coordinates_envelope(model):
    """The model's envelope pattern of the penalised coordinates block (the stability test's)."""
    return model.cached("coordinates_envelope",
                        lambda m: EnvelopeKKT(m, coordinates_only=True))
