"""Launch the bellow_ancf_ros pipeline on a ROS 2 Jazzy install.

    ros2 launch bellow_ancf_ros bellow_ancf.launch.py
    ros2 launch bellow_ancf_ros bellow_ancf.launch.py robot_config:=two_segment \
        trajectory:=bending_circle bending_angle_deg:=10.0
    ros2 launch bellow_ancf_ros bellow_ancf.launch.py with_trajectory:=false \
        pressure_topic:=measured_pressure

Starts ``inverse_kinetostatic_node`` (managed node, autostarted),
``forward_kinetostatic_node`` (its input remapped to ``pressure_topic``) and,
unless ``with_trajectory:=false``, ``trajectory_publisher``.  Node parameters
come from ``params_file`` (default: the installed ``config/nodes.yaml``);
the launch arguments below override it.

``launch`` and ``launch_ros`` are not on PyPI: without a ROS install, start
the nodes with ``python -m bellow_ancf_ros.nodes.<module> --ros-args ...``
instead (see the README).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from launch import LaunchDescription

PACKAGE = 'bellow_ancf_ros'


def generate_launch_description():
    share = get_package_share_directory(PACKAGE)
    default_params = os.path.join(share, 'config', 'nodes.yaml')

    args = [
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='ROS parameters file of the nodes'),
        DeclareLaunchArgument('robot_config', default_value='one_segment',
                              description='robot: shipped name (one_segment, two_segment) or YAML path'),
        DeclareLaunchArgument('base_frame', default_value='base',
                              description='frame of targets and outputs'),
        DeclareLaunchArgument('pressure_unit', default_value='Pa',
                              description='unit of the pressure topics: Pa or kPa (gauge)'),
        DeclareLaunchArgument('pressure_topic', default_value='pressure_command',
                              description='pressures the forward node predicts from '
                                          '(e.g. a measured-pressure topic)'),
        DeclareLaunchArgument('with_trajectory', default_value='true',
                              description='start the trajectory publisher'),
        DeclareLaunchArgument('trajectory', default_value='planar_circle',
                              description='space_spiral, space_rose, planar_circle, planar_spiral, '
                                          'planar_rose, bending_circle (two or more segments)'),
        DeclareLaunchArgument('bending_angle_deg', default_value='0.0',
                              description='bending angle of bending_circle [deg]'),
        DeclareLaunchArgument('period_s', default_value='0.0',
                              description='trajectory period [s]; 0 = default'),
    ]

    params_file = LaunchConfiguration('params_file')
    common = {
        'robot_config': LaunchConfiguration('robot_config'),
        'base_frame': LaunchConfiguration('base_frame'),
    }
    unit = {'pressure_unit': LaunchConfiguration('pressure_unit')}

    inverse = Node(
        package=PACKAGE, executable='inverse_kinetostatic_node', name='inverse_kinetostatic_node',
        output='screen', parameters=[params_file, common, unit],
    )
    forward = Node(
        package=PACKAGE, executable='forward_kinetostatic_node', name='forward_kinetostatic_node',
        output='screen', parameters=[params_file, common, unit],
        remappings=[('pressure_command', LaunchConfiguration('pressure_topic'))],
    )
    trajectory = Node(
        package=PACKAGE, executable='trajectory_publisher', name='trajectory_publisher',
        output='screen',
        parameters=[params_file, common, {
            'trajectory': LaunchConfiguration('trajectory'),
            'bending_angle_deg': ParameterValue(LaunchConfiguration('bending_angle_deg'),
                                                value_type=float),
            'period_s': ParameterValue(LaunchConfiguration('period_s'), value_type=float),
        }],
        condition=IfCondition(LaunchConfiguration('with_trajectory')),
    )
    return LaunchDescription(args + [inverse, forward, trajectory])
