"""package.xml: every dependency is a resolvable rosdep key and matches what the code imports.

``rosdep`` and its database are not installable offline, so the keys are
checked against a list verified by hand (December 2026):

* ROS packages released for Jazzy: the PyPI ``ros-jazzy-<name>`` wheels
  (rclpy, ament_index_python, *_msgs, rcl_interfaces, ament_flake8,
  ament_pep257; std_srvs: the ``ros-std-srvs`` wheel that
  ``ros-jazzy-common-interfaces`` installs, ros2/common_interfaces;
  rosgraph_msgs: the ``ros-rosgraph-msgs`` wheel that rclpy itself
  installs, ros2/rcl_interfaces, the /clock message) and
  the Jazzy API docs on docs.ros.org (launch, launch_ros, tf2_ros: released
  from ros2/geometry2 for Jazzy; not on PyPI, so the nodes import it only
  where it is installed);
* system keys: entries of ``rosdep/python.yaml`` in ros/rosdistro with an
  ``ubuntu`` rule (python3-numpy, python3-scipy, python3-yaml,
  python3-matplotlib, python3-pytest, python3-hypothesis; python3-numba,
  added by ros/rosdistro PR #32274, ubuntu rule for every release since PR
  #36477);
* pip keys of ``rosdep/python.yaml``: python3-rosbags-pip (ros/rosdistro PR
  #37795, PyPI ``rosbags``);
* python3-joblib: an entry of ``rosdep/python.yaml`` with an ``ubuntu`` rule
  (``python3-joblib``; read December 2026), used by the robot family's
  benchmark and its test.

``threadpoolctl`` is optional (the core limits BLAS threads with it when it is
installed) and is not a rosdep dependency.  ``pytest-xdist`` (and its
``execnet``) is used only by ``make test`` in the venv, to run the tests
without ROS on two workers; nothing imports it and rosdep has no key for it
(``rosdep/python.yaml`` lists python3-pytest-asyncio, -benchmark, -cov, -mock
and -timeout, not -xdist: read December 2026), so it is not in package.xml.

A new dependency must be added here with how it was verified.
"""

import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

ROS_PACKAGES = {'rclpy', 'rcl_interfaces', 'ament_index_python', 'geometry_msgs', 'std_msgs',
                'visualization_msgs', 'diagnostic_msgs', 'lifecycle_msgs', 'launch',
                'launch_ros', 'ament_flake8', 'ament_pep257', 'builtin_interfaces', 'tf2_ros',
                'std_srvs', 'rosgraph_msgs'}
SYSTEM_KEYS = {'python3-numpy', 'python3-scipy', 'python3-yaml', 'python3-matplotlib',
               'python3-pytest', 'python3-hypothesis', 'python3-numba', 'python3-rosbags-pip',
               'python3-joblib'}
VERIFIED_KEYS = ROS_PACKAGES | SYSTEM_KEYS

#: top-level Python module -> rosdep key
MODULE_KEYS = {'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'yaml': 'python3-yaml',
               'matplotlib': 'python3-matplotlib', 'pytest': 'python3-pytest',
               'hypothesis': 'python3-hypothesis', 'numba': 'python3-numba',
               'rosbags': 'python3-rosbags-pip', 'joblib': 'python3-joblib'}
STDLIB_OR_OWN = {'bellow_ancf_ros'}
#: the test suite's own helper modules (test/, test/data/, bench/)
LOCAL_TEST_HELPERS = {'conftest', 'reference_beams', 'calibration_data', 'make_solver_baseline',
                      'update_readme', 'remedies_bench', 'family_bench', 'busy_bench',
                      'demo_table', 'demo_results', 'effects_bench', 'ros_processes',
                      'redundant_bench', 'stream_latency', 'ros_domains', 'integrator_checks',
                      'dynamics_bench', 'hung_test_guard'}


def dependencies():
    root = ET.parse(REPO / 'package.xml').getroot()
    deps = {}
    for tag in ('depend', 'build_depend', 'exec_depend', 'test_depend', 'buildtool_depend'):
        for e in root.findall(tag):
            deps.setdefault(e.text.strip(), set()).add(tag)
    return deps


def required_imports(paths):
    """Top-level modules imported by ``paths`` (not those guarded by ``except ImportError``)."""
    guards = ('ImportError', 'ModuleNotFoundError')
    found = set()
    for path in paths:
        tree = ast.parse(path.read_text(), str(path))
        optional = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Try) and any(
                    isinstance(h.type, ast.Name) and h.type.id in guards for h in node.handlers):
                optional |= {id(n) for b in node.body for n in ast.walk(b)}
        for node in ast.walk(tree):
            if id(node) in optional:
                continue
            if isinstance(node, ast.Import):
                found |= {a.name.split('.')[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split('.')[0])
    return found - set(sys.stdlib_module_names) - STDLIB_OR_OWN


def key_of(module):
    if module in MODULE_KEYS:
        return MODULE_KEYS[module]
    return module        # ROS Python packages are imported under their package name


def test_every_rosdep_key_is_verified():
    unknown = sorted(set(dependencies()) - VERIFIED_KEYS)
    assert not unknown, f'rosdep keys not in the verified list: {unknown}'


def test_code_imports_are_exec_dependencies():
    deps = dependencies()
    code = list((REPO / 'bellow_ancf_ros').rglob('*.py')) + list((REPO / 'launch').glob('*.py'))
    missing = sorted(key_of(m) for m in required_imports(code)
                     if 'exec_depend' not in deps.get(key_of(m), set())
                     and 'depend' not in deps.get(key_of(m), set()))
    assert not missing, f'imported but not an exec_depend of package.xml: {missing}'


def test_test_imports_are_test_dependencies():
    deps = dependencies()
    tests = list((REPO / 'test').glob('*.py'))
    missing = []
    for m in required_imports(tests):
        if m in LOCAL_TEST_HELPERS or m.startswith('test_'):
            continue
        tags = deps.get(key_of(m), set())
        if not tags & {'test_depend', 'exec_depend', 'depend'}:
            missing.append(key_of(m))
    # colcon builds the package in a test; its PyPI packages are test tools of the venv only
    missing = sorted(set(missing) - {'colcon_core'})
    assert not missing, f'imported by tests but not a test_depend: {missing}'


def test_linter_tests_of_the_template_are_declared():
    deps = dependencies()
    for key, test in (('ament_flake8', 'test_flake8.py'), ('ament_pep257', 'test_pep257.py'),
                      ('python3-pytest', 'conftest.py')):
        assert 'test_depend' in deps[key], key
        assert (REPO / 'test' / test).is_file(), test
