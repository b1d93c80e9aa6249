"""Test-session settings and fixtures shared by all test modules."""

import os
from pathlib import Path
import random
import sys

import pytest

from bellow_ancf_ros.core import RobotModel, limit_blas_threads, load_robot

TEST_DIR = Path(__file__).resolve().parent
# shared test helpers (reference_beams, calibration_data) import by name from any folder
sys.path.insert(0, str(TEST_DIR / 'support'))

# Small dense matrices: single-threaded BLAS is faster, and much faster on a loaded 2-core machine.
limit_blas_threads()


#: Test modules that start ROS 2 nodes, node processes or launch files (marker ``ros``).
ROS_MODULES = ('test_launch.py', 'test_readme_examples.py')


def pytest_collection_modifyitems(config, items):
    """Mark ROS tests ``ros``: ``test_ros_*.py``, :data:`ROS_MODULES`, users of ``ros_context``."""
    for item in items:
        name = item.path.name
        if (name.startswith('test_ros_') or name in ROS_MODULES
                or 'ros_context' in getattr(item, 'fixturenames', ())):
            item.add_marker(pytest.mark.ros)


@pytest.fixture(scope="session")
def one():
    """The default one-segment robot model."""
    return RobotModel(load_robot("one_segment"))


@pytest.fixture(scope="session")
def two():
    """The default two-segment robot model."""
    return RobotModel(load_robot("two_segment"))


@pytest.fixture(scope="session")
def three():
    """The shipped three-segment robot model (config/three_segment.yaml)."""
    return RobotModel(load_robot("three_segment"))


@pytest.fixture(scope="session")
def one_cfg():
    """The default one-segment robot description."""
    return load_robot("one_segment")


@pytest.fixture(scope="session")
def two_cfg():
    """The default two-segment robot description."""
    return load_robot("two_segment")


@pytest.fixture
def factorisations(monkeypatch):
    """A list that grows by one for each KKT factorisation made (LDL^T, or the banded LU)."""
    from bellow_ancf_ros.core.linalg import BandedKKT, EnvelopeKKT

    made = []
    orig_ldl, orig_lu = EnvelopeKKT.factor, BandedKKT.factor

    def ldl(self, J, D):
        f = orig_ldl(self, J, D)
        if f is not None:  # refused: the banded LU follows, and counts
            made.append(1)
        return f

    def lu(self, J):
        made.append(1)
        return orig_lu(self, J)

    monkeypatch.setattr(EnvelopeKKT, "factor", ldl)
    monkeypatch.setattr(BandedKKT, "factor", lu)
    return made


@pytest.fixture(scope='module')
def ros_context():
    """Isolated ROS 2 context: random domain id, localhost discovery, set before init."""
    rclpy = pytest.importorskip('rclpy')
    from rclpy.context import Context

    domain = random.randint(0, 101)
    saved = {k: os.environ.get(k) for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')}
    os.environ['ROS_DOMAIN_ID'] = str(domain)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    yield ctx
    rclpy.try_shutdown(context=ctx)
    for k, v in saved.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v
