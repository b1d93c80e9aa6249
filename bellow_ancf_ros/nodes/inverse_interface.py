"""The inverse node's interface: its parameters and topics (what it declares, ``--help`` prints).

The closed loop's parameters are :data:`~.measured_feedback.FEEDBACK_PARAMETER_TABLE`,
the targets' :data:`~.target_link.TARGET_PARAMETER_TABLE`; the node declares
all three (:class:`~.inverse_kinetostatic_node.InverseKinetostaticNode`).
"""

from __future__ import annotations

from rcl_interfaces.msg import ParameterType

from . import contract
from .measured_feedback import FEEDBACK_PARAMETERS
from .realtime import REALTIME_PARAMETER, REALTIME_PRIORITY
from .ros_util import Param, Topic, descriptor
from .target_link import TARGET_PARAMETER_TABLE

__all__ = ['CONFIGURE_PARAMETERS', 'PARAMETERS', 'TOPICS']

#: Parameters read on configure, or that change what a command means: a change needs
#: cleanup + configure (refused while configured, with the way out)
CONFIGURE_PARAMETERS = (('robot_config', 'pressure_unit', 'base_frame') + FEEDBACK_PARAMETERS
                        + tuple(p.name for p in TARGET_PARAMETER_TABLE))
D, S, B, INT = (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_STRING,
                ParameterType.PARAMETER_BOOL, ParameterType.PARAMETER_INTEGER)
#: The node's parameters: what it declares and what ``--help`` prints.
PARAMETERS = (
    Param('robot_config', 'one_segment', descriptor(
        'Robot description: a shipped robot name (one_segment, two_segment, three_segment, '
        '...: the files in '
        'share/bellow_ancf_ros/config) or a path to a robot YAML file. Read on configure: '
        'change it in the unconfigured state (deactivate, cleanup, set, configure).', S,
        constraints='a shipped robot name or a robot YAML path')),
    Param('payload_kg', 0.0, descriptor(
        'Payload mass at the end effector [kg]; may be changed at run time and takes effect '
        'on the next solve. Negative or larger values than the range are refused.', D,
        lo=0.0, hi=contract.PAYLOAD_MAX_KG)),
    Param('base_frame', 'base', descriptor(
        'Frame of targets and outputs (robot base). Targets in any other frame are refused '
        '(no tf2 transform).', S, constraints='a non-empty frame name')),
    Param('pressure_unit', 'Pa', descriptor(
        'Unit of pressure_command: Pa (default, REP-103) or kPa. Pressures are gauge '
        '(relative to atmosphere); the layout label says the unit.', S,
        constraints="one of: 'Pa', 'kPa'")),
    Param('max_rate_hz', 100.0, descriptor(
        'Maximum solve (and command) rate [Hz]; only the newest target is solved.', D,
        lo=0.1, hi=1000.0)),
    Param('command_rate_hz', 20.0, descriptor(
        'Rate at which the current command is republished while active and no new one went '
        'out [Hz]; 0 = off. A regulator driver tells a live controller from a dead one by '
        'it (command_timeout_s).', D, lo=0.0, hi=1000.0, read_only=True)),
    Param('regulator_play_kpa', 0.0, descriptor(
        "The regulators' hysteresis (play) band [kPa], from their data sheet or bellow-ancf "
        'identify play: each command '
        'is sent at the edge of the band that puts the valve exactly at the pressure wanted '
        '(a change of direction no longer vanishes in the play; a shaped step then leaves no '
        'swing); 0 = off. Read on configure.', D, lo=0.0, hi=50.0)),
    Param('creep_fraction', 0.0, descriptor(
        "Part of the bellows' elongation that creeps after a pressure change (bellow-ancf "
        'identify creep): each command leads the creep by its inverse, so that the robot '
        'arrives at once instead of creeping the rest; 0 = off. Read on configure.', D,
        lo=0.0, hi=0.9)),
    Param('creep_time_constant_s', 2.0, descriptor(
        "Time constant of the bellows' creep [s] (bellow-ancf identify creep). Read on "
        'configure.', D, lo=0.05, hi=600.0)),
    Param('allow_other_publishers', False, descriptor(
        'Publish pressure_command even while another node publishes it (default false: '
        'vent once, deactivate and wait for activate; see ownership in docs/ros.md).', B)),
    Param('use_estimated_force', False, descriptor(
        'Compensate the force of estimated_wrench (wrench_estimator_node) in the '
        'feedforward, as external_force is; read at start-up.', B, read_only=True)),
    Param('external_force_timeout_s', 1.0, descriptor(
        'A force (external_force, estimated_wrench) older than this is no longer '
        'compensated [s].', D, lo=0.01, hi=3600.0, read_only=True)),
    Param('autostart', True, descriptor(
        'Configure and activate at start-up (so that a plain ros2 run works).', B,
        read_only=True)),
    Param(REALTIME_PARAMETER, REALTIME_PRIORITY, descriptor(
        "SCHED_FIFO priority of the node's threads on the wall clock (1-98; 0: the normal "
        'scheduler): its commands keep their period while other processes load the CPU. '
        'Needs the privilege (root, CAP_SYS_NICE or an rtprio limit, as for ros2_control); '
        'without it, one warning and the normal scheduler. Not under use_sim_time. Read at '
        'start-up.', INT, lo=0, hi=98, read_only=True)),
)


TOPICS = (
    Topic('subscribes', 'target_pose', 'geometry_msgs/PoseStamped', 'in base_frame'),
    Topic('subscribes', 'measured_pose', 'geometry_msgs/PoseStamped',
          "with feedback 'integral' (best effort)"),
    Topic('subscribes', 'external_force', 'geometry_msgs/WrenchStamped',
          'a force at the end effector, compensated'),
    Topic('subscribes', 'estimated_wrench', 'geometry_msgs/WrenchStamped',
          'with use_estimated_force'),
    Topic('publishes', 'pressure_command', 'std_msgs/Float64MultiArray',
          'gauge pressures in pressure_unit, only while active; the vent on deactivate, '
          'shutdown, or when it yields to another publisher'),
    Topic('publishes', 'commanded_pose', 'geometry_msgs/PoseStamped',
          "the model's pose for the command"),
    Topic('publishes', '/diagnostics', 'diagnostic_msgs/DiagnosticArray',
          'per-solve status and 1 Hz heartbeat'),
    Topic('publishes', 'lockstep_clock', 'std_msgs/Header',
          'use_sim_time: the simulation time its work is done until (a lockstep)'),
    Topic('services', '~/change_state, ~/get_state, ...', 'lifecycle_msgs',
          'the standard lifecycle services (autostart: configure + activate at start-up)'),
)
