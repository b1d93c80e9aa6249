"""Test-session settings and fixtures shared by all test modules."""

import pytest

from bellow_ancf_ros.core import RobotModel, load_robot

from bellow_ancf_ros.core.solver import limit_blas_threads

# Small dense matrices: single-threaded BLAS is faster, and much faster on a loaded 2-core machine.
limit_blas_threads()


@pytest.fixture(scope="session")
def one():
    """The default one-segment robot model."""
    return RobotModel(load_robot("one_segment"))


@pytest.fixture(scope="session")
def two():
    """The default two-segment robot model."""
    return RobotModel(load_robot("two_segment"))


@pytest.fixture(scope="session")
def one_cfg():
    """The default one-segment robot description."""
    return load_robot("one_segment")


@pytest.fixture(scope="session")
def two_cfg():
    """The default two-segment robot description."""
    return load_robot("two_segment")
