"""Linear algebra of the KKT matrix (eq. 27): patterns and factorisations, not physics.

* :func:`level_order`: the banded order of the unknowns by height along the robot;
* :class:`EnvelopeKKT` / :class:`EnvelopeLDL`: the symmetric envelope LDL^T
  without pivoting (compiled), its growth measured, its pivots the inertia;
* :class:`BandedKKT` / :class:`BandedLU`: LAPACK's pivoted banded LU, where the
  LDL^T is refused;
* :func:`kkt_solver`: the choice between them, one solver per model;
* :func:`limit_blas_threads`, :func:`one_thread`, :func:`one_thread_call`: BLAS
  on one thread inside the core's solves.

Every module here takes a model only for its pattern (sizes, the CSC index
arrays, the plates' levels); none imports the model or the solvers.
"""

from ._blas import limit_blas_threads, one_thread, one_thread_call
from ._kkt import BandedKKT, BandedLU, KKTSolver, coordinates_envelope, kkt_solver
from ._ldlt import MAX_GROWTH, PENALTY, EnvelopeKKT, EnvelopeLDL, ldl_solve_vector
from ._ordering import level_order

__all__ = [
    "BandedKKT", "BandedLU", "EnvelopeKKT", "EnvelopeLDL", "KKTSolver", "MAX_GROWTH", "PENALTY",
    "coordinates_envelope", "kkt_solver", "ldl_solve_vector", "level_order", "limit_blas_threads",
    "one_thread", "one_thread_call",
]
