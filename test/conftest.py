"""Test-session settings shared by all test modules."""

from bellow_ancf_ros.core.solver import limit_blas_threads

# Small dense matrices: single-threaded BLAS is faster, and much faster on a loaded 2-core machine.
limit_blas_threads()
