"""Test-session settings and fixtures shared by all test modules."""

import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

from bellow_ancf_ros.core import RobotModel, limit_blas_threads, load_robot

TEST_DIR = Path(__file__).resolve().parent
REPO = TEST_DIR.parent
PKG = 'bellow_ancf_ros'
# shared test helpers (reference_beams, calibration_data) import by name from any folder
sys.path.insert(0, str(TEST_DIR / 'support'))
from ros_domains import fresh_domain  # noqa: E402
# a test that hangs ends its process with every thread's stack (see hung_test_guard)
from hung_test_guard import (pytest_configure, pytest_runtest_protocol,  # noqa: E402,F401
                             pytest_unconfigure)

# Small dense matrices: single-threaded BLAS is faster, and much faster on a loaded 2-core machine.
limit_blas_threads()


#: Test modules that start ROS 2 nodes, node processes or launch files, or use the colcon
#: install (marker ``ros``: ``make test`` runs them after the others, on two workers).
ROS_MODULES = ('test_launch.py', 'test_readme_examples.py', 'test_package_layout.py')
#: ROS test modules that run alone (marker ``serial``): ``make demo``'s runs (eight node
#: processes on the cores, on domains the demo draws itself), the CPU-bound burners, and the
#: simulation-clock tests whose fake ``/clock`` or pacing runs on the wall clock (beside another
#: worker the keepalive measured 7.1 instead of 20 per simulated second after a jump back).
SERIAL_MODULES = ('test_ros_demo.py', 'test_ros_busy_loop.py', 'test_ros_sim_time.py',
                  'test_ros_sim_clock.py')


def pytest_collection_modifyitems(config, items):
    """Mark ROS tests ``ros``: ``test_ros_*.py``, :data:`ROS_MODULES`, users of ``ros_context``.

    And those of :data:`SERIAL_MODULES` ``serial``.
    """
    for item in items:
        name = item.path.name
        if (name.startswith('test_ros_') or name in ROS_MODULES
                or 'ros_context' in getattr(item, 'fixturenames', ())):
            item.add_marker(pytest.mark.ros)
        if name in SERIAL_MODULES:
            item.add_marker(pytest.mark.serial)


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

    domain = fresh_domain()
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


# ------------------------------------------------------------------ colcon install
#: what a copy of the checkout for colcon leaves out (a venv or build tree is never crawled)
_NOT_SOURCE = shutil.ignore_patterns('.git', '.venv', 'venv', 'build', 'install', 'log',
                                     '__pycache__', '.pytest_cache', '.hypothesis',
                                     '.ruff_cache', '*.egg-info', '*.png')


class ColconInstall:
    """A workspace built by ``colcon build`` from a copy of this checkout (see the fixture)."""

    def __init__(self, root: Path):
        self.root = root
        self.install = root / 'install'
        self.prefix = self.install / PKG        # colcon's default isolated layout
        self.share = self.prefix / 'share' / PKG
        self.bin = root / 'bin'                 # the test's ``ros2`` command (ros2_shim.py)
        self.outside = root / 'elsewhere'       # a working directory outside any source tree

    def site_packages(self) -> Path:
        found = list(self.prefix.glob('lib/python3*/site-packages'))
        assert found, 'no site-packages in the install prefix'
        return found[0]

    def shell(self, line: str, cwd: Path, timeout: float = 300.0, env=None):
        """Run ``line`` in bash as a user does after ``source install/setup.sh``, in ``cwd``.

        ``PATH`` starts with the ``ros2`` shim (``ros2 run``, ``ros2 pkg prefix``);
        the environment is otherwise the test's (its venv's Python runs the
        installed executables, as the build's interpreter).
        """
        env = dict(os.environ if env is None else env)
        env['PATH'] = str(self.bin) + os.pathsep + env.get('PATH', '')
        env.pop('AMENT_PREFIX_PATH', None)
        env.pop('PYTHONPATH', None)
        script = f'. {self.install / "setup.sh"} && cd {cwd} && {line}'
        return subprocess.run(['bash', '-c', script], env=env, capture_output=True, text=True,
                              timeout=timeout, stdin=subprocess.DEVNULL)


def _seed_kernel_cache(installed_core: Path) -> None:
    """Copy the checkout's compiled kernels into the install's cache (a test-time shortcut).

    The first ``warm-up`` of a fresh install compiles for about a minute of
    CPU; the checkout's venv has compiled the same sources (``make venv``).
    numba keys its cache by the source directory (``<dir name>_<sha1 of its
    path>``, ``numba.core.caching``) and checks each source file's mtime and
    size, which the copy and colcon keep: the renamed copies load.  Should
    numba not take them, the install compiles as a user's would: slower, not wrong.
    """
    import hashlib

    from bellow_ancf_ros.core import numba_cache

    ours = numba_cache.cache_dir()
    if not ours.is_dir() or not str(ours).startswith(str(REPO)):
        return
    target = installed_core / '__pycache__' / ours.name
    for sub in ours.iterdir():
        name = sub.name.rsplit('_', 1)[0]               # linalg, model, solve
        installed_dir = installed_core / name
        if not installed_dir.is_dir():
            continue
        digest = hashlib.sha1(str(installed_dir).encode()).hexdigest()
        shutil.copytree(sub, target / f'{name}_{digest}', dirs_exist_ok=True)


@pytest.fixture(scope='session')
def colcon_install(tmp_path_factory):
    """One ``colcon build`` of a copy of the checkout per test session, and a ``ros2`` shim.

    colcon-core, colcon-ros and colcon-python-setup-py are on PyPI (requirements.txt).
    The build goes to ``<tmp>/install`` (isolated layout); ``<tmp>/bin/ros2``
    runs ``test/support/ros2_shim.py``.
    """
    try:
        import colcon_core  # noqa: F401
    except ImportError:
        pytest.fail('colcon is not installed: pip install -r requirements.txt '
                    '(colcon-core, colcon-ros, colcon-python-setup-py)')
    root = tmp_path_factory.mktemp('colcon')
    shutil.copytree(REPO, root / 'src' / PKG, ignore=_NOT_SOURCE)
    cmd = [sys.executable, '-m', 'colcon', '--log-base', str(root / 'log'), 'build',
           '--base-paths', str(root / 'src'), '--build-base', str(root / 'build'),
           '--install-base', str(root / 'install'), '--event-handlers', 'console_direct-']
    res = subprocess.run(cmd, cwd=root, capture_output=True, text=True, timeout=300,
                         stdin=subprocess.DEVNULL)
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-4000:]
    inst = ColconInstall(root)
    assert inst.prefix.is_dir(), list(inst.install.iterdir())
    _seed_kernel_cache(inst.site_packages() / PKG / 'core')
    inst.bin.mkdir()
    shim = inst.bin / 'ros2'
    shim.write_text(f'#!/bin/sh\nexec {sys.executable} {TEST_DIR / "support" / "ros2_shim.py"} '
                    '"$@"\n')
    shim.chmod(0o755)
    inst.outside.mkdir()
    return inst
