"""Setup script of the ``bellow_ancf_ros`` ament_python package.

Works both for ``colcon build`` on a ROS 2 Jazzy machine and for a plain
``pip install`` / ``pip install -e .`` in a virtual environment.  The ROS 2
client libraries are deliberately *not* listed in ``install_requires``: on a
ROS machine they come from ``/opt/ros/jazzy``, in a venv from
``requirements.txt``.
"""

from glob import glob
import os

from setuptools import find_packages, setup

PACKAGE_NAME = 'bellow_ancf_ros'
HERE = os.path.dirname(os.path.abspath(__file__))


def _files(pattern):
    """Repository-relative files matching ``pattern`` (sorted, may be empty)."""
    return sorted(os.path.relpath(p, HERE) for p in glob(os.path.join(HERE, pattern)))


data_files = [
    ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
    ('share/' + PACKAGE_NAME, ['package.xml']),
    ('share/' + PACKAGE_NAME + '/config', _files('config/*.yaml')),
    ('share/' + PACKAGE_NAME + '/data', _files('data/*.csv')),
    # the example recording (rosbag2 directory) that README's `calibrate --bag` line reads
    ('share/' + PACKAGE_NAME + '/data/one_segment_bag', _files('data/one_segment_bag/*')),
    ('share/' + PACKAGE_NAME + '/rviz', _files('rviz/*.rviz')),
]
_launch_files = _files('launch/*.launch.py')
if _launch_files:
    data_files.append(('share/' + PACKAGE_NAME + '/launch', _launch_files))

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=data_files,
    install_requires=[
        'numpy',
        'scipy',
        'PyYAML',
        'matplotlib',
        'rosbags',
        'numba',  # compiled kernels (core/model/_kernels.py, linalg/_ldlt.py, solve/_chord.py)
    ],
    extras_require={'test': ['pytest', 'hypothesis']},
    python_requires='>=3.10',
    zip_safe=True,
    maintainer='bellow_ancf_ros maintainers',
    maintainer_email='maintainer@example.com',
    description='Kinetostatic ANCF model of bellow-shaped pneumatic soft '
                'continuum robots, with ROS 2 nodes.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'bellow-ancf = bellow_ancf_ros.cli:main',
            'inverse_kinetostatic_node = bellow_ancf_ros.nodes.inverse_kinetostatic_node:main',
            'forward_kinetostatic_node = bellow_ancf_ros.nodes.forward_kinetostatic_node:main',
            'trajectory_publisher = bellow_ancf_ros.nodes.trajectory_publisher:main',
            'excitation_publisher = bellow_ancf_ros.nodes.excitation_publisher:main',
            'simulated_robot_node = bellow_ancf_ros.nodes.simulated_robot_node:main',
            'mocap_relay = bellow_ancf_ros.nodes.mocap_relay:main',
            'regulator_driver = bellow_ancf_ros.nodes.regulator_driver:main',
            'wrench_estimator_node = bellow_ancf_ros.nodes.wrench_estimator_node:main',
        ],
    },
)
