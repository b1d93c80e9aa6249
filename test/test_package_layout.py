"""The ament_python package layout after a real ``colcon build``.

colcon (colcon-core, colcon-ros, colcon-python-setup-py; all on PyPI) builds
a copy of the package source in a temporary directory (a copy, so that a
virtual environment or build tree inside the checkout is never crawled; one
build per test session, the ``colcon_install`` fixture of ``test/conftest.py``).
Then the files must be where ``ros2 run`` and ``ros2 launch`` look for them:

* ``share/ament_index/resource_index/packages/bellow_ancf_ros`` (marker),
* ``share/bellow_ancf_ros/package.xml``, ``config/*.yaml``, ``launch/*.launch.py``,
  ``rviz/*.rviz``, ``data/`` (the example files and the recording),
* executables ``lib/bellow_ancf_ros/<node>`` (console scripts),

and an installed executable must start.
"""

import os
import py_compile
from ros_domains import fresh_domain  # noqa: E402
import stat
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PKG = 'bellow_ancf_ros'
NODE_EXECUTABLES = {
    'inverse_kinetostatic_node': 'bellow_ancf_ros.nodes.inverse_kinetostatic_node:main',
    'forward_kinetostatic_node': 'bellow_ancf_ros.nodes.forward_kinetostatic_node:main',
    'trajectory_publisher': 'bellow_ancf_ros.nodes.trajectory_publisher:main',
}
MESSAGE_DEPENDENCIES = ('rclpy', 'geometry_msgs', 'std_msgs', 'visualization_msgs',
                        'diagnostic_msgs', 'lifecycle_msgs')


def test_every_module_of_the_package_imports():
    """Regression: calibration_demo imported names ros_demo no longer had (make demo-calibrate)."""
    import importlib
    import pkgutil

    import bellow_ancf_ros

    names = [m.name for m in pkgutil.walk_packages(bellow_ancf_ros.__path__, 'bellow_ancf_ros.')
             if not m.name.endswith('.__main__')]  # those run their command on import
    assert 'bellow_ancf_ros.demos.calibration' in names
    for name in names:
        importlib.import_module(name)


def test_launch_file_compiles(tmp_path):
    launch = REPO / 'launch' / 'bellow_ancf.launch.py'
    assert launch.is_file()
    py_compile.compile(str(launch), cfile=str(tmp_path / 'launch.pyc'), doraise=True)
    text = launch.read_text()
    assert 'def generate_launch_description' in text
    for exe in NODE_EXECUTABLES:
        assert f"executable='{exe}'" in text


def test_nodes_params_file_is_a_ros_params_file():
    import yaml
    data = yaml.safe_load((REPO / 'config' / 'nodes.yaml').read_text())
    for node in NODE_EXECUTABLES:
        assert 'ros__parameters' in data[node], node
    assert 'ros__parameters' in data['/**']
    assert list(data)[0] == '/**'     # first: later /** entries (launch arguments) override it
    assert data['/**']['ros__parameters']['pressure_unit'] in ('Pa', 'kPa')


def _site_packages(prefix):
    found = list(prefix.glob('lib/python3*/site-packages'))
    assert found, 'no site-packages in the install prefix'
    return found[0]


def test_ament_index_marker_and_package_xml(colcon_install):
    colcon_install = colcon_install.prefix
    marker = colcon_install / 'share' / 'ament_index' / 'resource_index' / 'packages' / PKG
    assert marker.is_file()
    pxml = colcon_install / 'share' / PKG / 'package.xml'
    assert pxml.read_text() == (REPO / 'package.xml').read_text()
    root = ET.parse(pxml).getroot()
    assert root.get('format') == '3'
    assert root.findtext('name') == PKG
    assert root.find('export').findtext('build_type') == 'ament_python'
    deps = {e.text for e in root.findall('exec_depend')}
    core_deps = ('python3-numpy', 'python3-scipy', 'python3-yaml', 'python3-numba')
    for dep in MESSAGE_DEPENDENCIES + core_deps:
        assert dep in deps, dep


#: the checkout's folders installed to ``share/bellow_ancf_ros/`` as they are, except these
#: files (the generators of data/ are tools of the checkout)
SHARED_DIRS = ('config', 'launch', 'rviz', 'data')
NOT_SHARED = ('data/make_synthetic.py', 'data/make_recording.py')


def test_config_launch_rviz_and_data_files_installed(colcon_install):
    """Every file of config/, launch/, rviz/ and data/ (the bag too) is in the share directory."""
    share = colcon_install.share
    files = [p for d in SHARED_DIRS for p in sorted((REPO / d).rglob('*'))
             if p.is_file() and '__pycache__' not in p.parts
             and p.relative_to(REPO).as_posix() not in NOT_SHARED]
    missing = [p.relative_to(REPO).as_posix() for p in files
               if not (share / p.relative_to(REPO)).is_file()]
    assert not missing, f'not installed to share/{PKG}: {missing} (setup.py data_files)'
    for p in files:
        assert (share / p.relative_to(REPO)).read_bytes() == p.read_bytes(), p
    names = {p.relative_to(REPO).as_posix() for p in files}
    assert {'config/nodes.yaml', 'launch/bellow_ancf.launch.py', 'rviz/bellow_ancf.rviz',
            'data/tensile_test_segment.csv', 'data/one_segment_bag/metadata.yaml'} <= names


def test_node_executables_installed(colcon_install):
    colcon_install = colcon_install.prefix
    lib = colcon_install / 'lib' / PKG
    missing = [exe for exe in NODE_EXECUTABLES if not (lib / exe).is_file()]
    have = sorted(p.name for p in lib.iterdir()) if lib.is_dir() else None
    assert not missing, f'console scripts missing from lib/{PKG}: {missing} (have: {have})'
    for exe in NODE_EXECUTABLES:
        mode = (lib / exe).stat().st_mode
        assert mode & stat.S_IXUSR, f'{exe} is not executable'
    # the entry points name the node modules' main functions
    eps = list(_site_packages(colcon_install).glob(f'{PKG}*.egg-info/entry_points.txt'))
    assert eps, 'no entry_points.txt installed'
    text = eps[0].read_text()
    for exe, target in NODE_EXECUTABLES.items():
        assert f'{exe} = {target}' in text.replace('  ', ' '), (exe, text)


def _ros_env(prefix, domain):
    env = dict(os.environ)
    env['AMENT_PREFIX_PATH'] = str(prefix) + os.pathsep + env.get('AMENT_PREFIX_PATH', '')
    env['PYTHONPATH'] = str(_site_packages(prefix)) + os.pathsep + env.get('PYTHONPATH', '')
    env['ROS_DOMAIN_ID'] = str(domain)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    return env


def test_ros2_run_lookup_and_shipped_robots(colcon_install, tmp_path):
    """Do what ``ros2 run`` does, and find the robot files in the installed share directory.

    ``ros2 run`` takes the prefix that holds the marker, then lib/<pkg>/<exe>
    in it.
    """
    colcon_install = colcon_install.prefix
    code = f'''
import os, sys
from ament_index_python.packages import get_package_prefix, get_package_share_directory
prefix = get_package_prefix({PKG!r})
print('PREFIX', prefix)
for exe in {sorted(NODE_EXECUTABLES)!r}:
    path = os.path.join(prefix, 'lib', {PKG!r}, exe)
    print('EXE', exe, os.access(path, os.X_OK))
from bellow_ancf_ros.core import load_robot
import bellow_ancf_ros
print('MODULE', bellow_ancf_ros.__file__)
print('ROBOT', load_robot('two_segment').source)
'''
    res = subprocess.run([sys.executable, '-c', code], env=_ros_env(colcon_install, 0),
                         cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    lines = dict(line.split(' ', 1) for line in res.stdout.splitlines() if ' ' in line)
    assert Path(lines['PREFIX']).resolve() == colcon_install.resolve()
    assert Path(lines['MODULE']).resolve().is_relative_to(colcon_install.resolve())
    assert Path(lines['ROBOT']).resolve() == (colcon_install / 'share' / PKG / 'config'
                                              / 'two_segment.yaml').resolve()
    for exe in NODE_EXECUTABLES:
        assert f'EXE {exe} True' in res.stdout, res.stdout


def test_installed_executable_starts_and_stops_cleanly(colcon_install, tmp_path):
    from ros_processes import interrupt   # (imports rclpy: only where a node runs)

    colcon_install = colcon_install.prefix
    exe = colcon_install / 'lib' / PKG / 'trajectory_publisher'
    if not exe.is_file():
        pytest.fail(f'{exe} not installed (see test_node_executables_installed)')
    log_path = tmp_path / 'node.log'
    with open(log_path, 'w') as log:
        proc = subprocess.Popen(
            [str(exe), '--ros-args', '--params-file',
             str(colcon_install / 'share' / PKG / 'config' / 'nodes.yaml'),
             '-p', 'trajectory_publisher:rate_hz:=20.0'],
            env=_ros_env(colcon_install, fresh_domain()), cwd=tmp_path, stdout=log,
            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and 'publishing' not in log_path.read_text():
            assert proc.poll() is None, log_path.read_text()
            time.sleep(0.05)
        assert "publishing 'planar_circle'" in log_path.read_text()
        assert '20 Hz' in log_path.read_text()      # node-specific -p overrides the file
    finally:
        interrupt(proc, 10.0)
    assert proc.returncode == 0, log_path.read_text()
