"""Launch the bellow_ancf_ros pipeline on a ROS 2 Jazzy install.

    ros2 launch bellow_ancf_ros bellow_ancf.launch.py
    ros2 launch bellow_ancf_ros bellow_ancf.launch.py robot_config:=two_segment \
        trajectory:=bending_circle bending_angle_deg:=10.0 period_s:=20.0 pressure_unit:=kPa
    ros2 launch bellow_ancf_ros bellow_ancf.launch.py with_trajectory:=false \
        pressure_topic:=measured_pressure
    ros2 launch bellow_ancf_ros bellow_ancf.launch.py rviz:=true
    ros2 launch bellow_ancf_ros bellow_ancf.launch.py sim:=true feedback:=integral payload_kg:=0.02

Starts ``inverse_kinetostatic_node`` (managed node, autostarted),
``forward_kinetostatic_node`` (its input remapped to ``pressure_topic``),
unless ``with_trajectory:=false`` ``trajectory_publisher``, and with
``rviz:=true`` rviz2 with the installed ``rviz/bellow_ancf.rviz`` (where
rviz2 is installed; otherwise a log line says it is not), and with
``sim:=true`` ``simulated_robot_node`` (``sim_robot_config``, default the
shipped mismatched robot of ``robot_config``, ``sim_plant`` realistic or ideal hardware; it
vents after ``command_timeout_s`` 0.5 s without a command, as a regulator
driver does).  ``use_sim_time`` (default: as ``sim``) puts every node on
``/clock``; with ``sim:=true`` the simulated robot publishes it, paced by
``sim_real_time_factor`` (1.0) and in lockstep with the controller's commands
(``sim_lockstep``, default true), as Gazebo and Chrono::ROS are the clock of
their simulations.  ``feedback`` and
``payload_kg`` go to the controller (and the payload to the forward node and
the trajectory publisher, whose lead-in starts at the robot at rest).  The
trajectory publisher sends its first target once the controller is active
(``controller_node``, default ``inverse_kinetostatic_node``), so that the
lead-in (``ramp_in_s``) is not lost while a two-segment controller warms up.

One outcome: a node that ends (a robot file that does not load ends the
forward node and the trajectory publisher at start-up) ends the whole
launch, so no half of the pipeline keeps running.  The controller gets
``sigterm_timeout`` 10 s: its vent and the wait for the acknowledgement
(at most 4 s) are not cut short by SIGKILL.

Node parameters come from ``params_file`` (default: the installed
``config/nodes.yaml``); the launch arguments below override it.  launch_ros
passes them as ``/**:`` (wildcard) parameter files after ``params_file``; a
node-specific entry of any params file would win over them, so the shipped
``config/nodes.yaml`` keeps every parameter that is a launch argument under
``/**:`` only.  A custom ``params_file`` must do the same for the launch
arguments to apply.

``launch`` and ``launch_ros`` are not on PyPI: without a ROS install, start
the nodes with ``python -m bellow_ancf_ros.nodes.<module> --ros-args ...``
instead (see the README).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, LogInfo, Shutdown
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from launch import LaunchDescription

PACKAGE = 'bellow_ancf_ros'
RVIZ_PACKAGE = 'rviz2'


def _installed(package):
    """Whether ``package`` is in the ament index (e.g. rviz2 on a desktop install)."""
    try:
        get_package_share_directory(package)
    except Exception:  # noqa: BLE001 - PackageNotFoundError, or no ament index at all
        return False
    return True


def _typed(name, value_type):
    """Launch argument ``name`` as a parameter value of ``value_type``."""
    return ParameterValue(LaunchConfiguration(name), value_type=value_type)


def generate_launch_description():
    """Declare the launch arguments and the nodes."""
    share = get_package_share_directory(PACKAGE)
    default_params = os.path.join(share, 'config', 'nodes.yaml')
    default_rviz = os.path.join(share, 'rviz', 'bellow_ancf.rviz')

    args = [
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='ROS parameters file of the nodes'),
        DeclareLaunchArgument('robot_config', default_value='one_segment',
                              description='robot: shipped name (one_segment, two_segment) '
                                          'or YAML path'),
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
                              description='space_spiral, space_rose, planar_circle, '
                                          'planar_spiral, planar_rose, bending_circle '
                                          '(two or more segments)'),
        DeclareLaunchArgument('bending_angle_deg', default_value='0.0',
                              description='bending angle of bending_circle [deg]'),
        DeclareLaunchArgument('period_s', default_value='0.0',
                              description='trajectory period [s]; 0 = default'),
        DeclareLaunchArgument('feedback', default_value='none',
                              description="controller: 'none' (feedforward) or 'integral' "
                                          '(closed loop on measured_pose)'),
        DeclareLaunchArgument('payload_kg', default_value='0.0',
                              description='payload at the end effector [kg], known to the model'),
        DeclareLaunchArgument('sim', default_value='false',
                              description='start simulated_robot_node in place of the robot'),
        DeclareLaunchArgument('sim_robot_config',
                              default_value=[LaunchConfiguration('robot_config'), '_mismatched'],
                              description="the simulated robot's own file; default "
                                          '<robot_config>_mismatched, the shipped robot that is '
                                          'not the model (one_segment_mismatched, '
                                          'two_segment_mismatched), or robot_config itself '
                                          'where none is shipped'),
        DeclareLaunchArgument('sim_plant', default_value='realistic',
                              description="the simulated robot's hardware: realistic (lag, "
                                          'dead time, hysteresis, creep, mocap latency, '
                                          'outliers, dropouts) or ideal'),
        # after 'sim': its default is sim's value
        DeclareLaunchArgument('use_sim_time', default_value=LaunchConfiguration('sim'),
                              description='every node on /clock (simulation time); default: '
                                          'as sim (the simulated robot is the clock)'),
        DeclareLaunchArgument('sim_real_time_factor', default_value='1.0',
                              description='simulated seconds per wall second (0: as fast as '
                                          'the computer allows); with use_sim_time'),
        DeclareLaunchArgument('sim_lockstep', default_value='true',
                              description='the simulation waits for the controller\'s commands '
                                          '(a busy computer slows it, not its result); with '
                                          'use_sim_time'),
        DeclareLaunchArgument('rviz', default_value='false',
                              description='start rviz2 with the package RViz config'),
        DeclareLaunchArgument('rviz_config', default_value=default_rviz,
                              description='RViz config file'),
    ]

    params_file = LaunchConfiguration('params_file')
    robot = {
        'robot_config': _typed('robot_config', str),
        'base_frame': _typed('base_frame', str),
    }
    unit = {'pressure_unit': _typed('pressure_unit', str)}

    payload = {'payload_kg': _typed('payload_kg', float)}
    sim_time = {'use_sim_time': _typed('use_sim_time', bool)}
    ends_all = Shutdown(reason='a node of the pipeline ended')

    inverse = Node(
        package=PACKAGE, executable='inverse_kinetostatic_node',
        name='inverse_kinetostatic_node', output='screen',
        parameters=[params_file, robot, unit, payload, sim_time,
                    {'feedback': _typed('feedback', str)}],
        sigterm_timeout='10', on_exit=ends_all,
    )
    forward = Node(
        package=PACKAGE, executable='forward_kinetostatic_node',
        name='forward_kinetostatic_node', output='screen',
        parameters=[params_file, robot, unit, payload, sim_time],
        remappings=[('pressure_command', LaunchConfiguration('pressure_topic'))],
        on_exit=ends_all,
    )
    sim = Node(
        package=PACKAGE, executable='simulated_robot_node', name='simulated_robot_node',
        output='screen',
        parameters=[params_file, {'robot_config': _typed('sim_robot_config', str),
                                  'base_frame': _typed('base_frame', str),
                                  'plant': _typed('sim_plant', str),
                                  'command_timeout_s': 0.5,
                                  'publish_clock': _typed('use_sim_time', bool),
                                  'real_time_factor': _typed('sim_real_time_factor', float),
                                  'lockstep': _typed('sim_lockstep', bool)}, unit, sim_time],
        condition=IfCondition(LaunchConfiguration('sim')), on_exit=ends_all,
    )
    trajectory = Node(
        package=PACKAGE, executable='trajectory_publisher', name='trajectory_publisher',
        output='screen',
        parameters=[params_file, robot, payload, sim_time, {
            'trajectory': _typed('trajectory', str),
            'bending_angle_deg': _typed('bending_angle_deg', float),
            'period_s': _typed('period_s', float),
        }],
        condition=IfCondition(LaunchConfiguration('with_trajectory')),
    )
    if _installed(RVIZ_PACKAGE):
        rviz = Node(
            package=RVIZ_PACKAGE, executable='rviz2', name='rviz2', output='screen',
            arguments=['-d', LaunchConfiguration('rviz_config')], parameters=[sim_time],
            condition=IfCondition(LaunchConfiguration('rviz')),
        )
    else:
        rviz = LogInfo(
            msg='rviz:=true but rviz2 is not installed (apt install ros-jazzy-rviz2); '
                'starting without RViz',
            condition=IfCondition(LaunchConfiguration('rviz')),
        )
    return LaunchDescription(args + [inverse, forward, sim, trajectory, rviz])
