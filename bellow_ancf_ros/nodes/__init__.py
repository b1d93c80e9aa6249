"""ROS 2 nodes around the pure-Python core.

* :mod:`.inverse_kinetostatic_node` -- managed (lifecycle) feedforward
  controller: ``target_pose`` -> ``pressure_command``.
* :mod:`.forward_kinetostatic_node` -- pressures -> ``predicted_pose`` and
  ``predicted_shape`` (RViz markers).
* :mod:`.trajectory_publisher` -- the paper's trajectories on ``target_pose``.
* :mod:`.contract` -- the message contract and the pressure safety gate (no rclpy import);
* :mod:`.worker` -- the latest-only solve worker, budget slices, solve statistics and
  the model ready for a control loop (no rclpy import).
* :mod:`.ros_util` -- rclpy helpers: QoS, checked parameter declaration,
  one-line start-up errors, the acknowledged vent, the executor and the
  main / spin / signal idiom.
* :mod:`.diagnostics` -- ``/diagnostics``: the 1 Hz status heartbeat,
  per-event statuses, rate limits for refusals and per-solve statuses.

Every node module has a ``main(args=None)`` and runs with
``python -m bellow_ancf_ros.nodes.<module> --ros-args ...``.

A node process stopped by Ctrl-C or SIGTERM while it is still loading (its
imports take seconds, before rclpy starts and anything is commanded) exits
at once with status 0 and one line, not a ``KeyboardInterrupt`` traceback
(:func:`_node_program`); from rclpy's start on, the node's own handlers
(:mod:`.ros_util`) stop it, with the vent.

``kill -USR1 <pid>`` makes a node process print every thread's Python stack
on its stderr and go on (:mod:`faulthandler`, registered when this package is
imported, before rclpy and the kernels load): the way to see where a node
that does not answer is, even inside a C call that holds it.
"""

import faulthandler as _faulthandler
import os as _os
import signal as _signal
import sys as _sys

#: The node executables (``setup.py``'s console scripts; also the modules' names).
NODE_PROGRAMS = ('inverse_kinetostatic_node', 'forward_kinetostatic_node',
                 'trajectory_publisher', 'excitation_publisher', 'simulated_robot_node',
                 'mocap_relay', 'regulator_driver', 'wrench_estimator_node')


def _node_program(orig_argv, argv) -> str:
    """The node this process runs as its program (being loaded now), or ''.

    ``python -m bellow_ancf_ros.nodes.<node>`` (this package is imported
    while ``-m`` locates the module: ``argv[0]`` is ``'-m'`` then) or a
    node's console script (``ros2 run``, ``ros2 launch``).
    """
    if argv and argv[0] == '-m':
        for flag, module in zip(orig_argv, orig_argv[1:]):
            if flag == '-m' and module.startswith(__name__ + '.'):
                node = module[len(__name__) + 1:]
                return node if node in NODE_PROGRAMS else ''
        return ''
    base = _os.path.basename(argv[0]) if argv else ''
    return base if base in NODE_PROGRAMS else ''


def _stopped_while_loading(signum, frame) -> None:  # pragma: no cover - signal path
    _os.write(2, f'[{_PROGRAM}] stopped by {_signal.Signals(signum).name} while loading, '
              'before anything was commanded\n'.encode())
    _os._exit(0)


_PROGRAM = _node_program(getattr(_sys, 'orig_argv', []), _sys.argv)
if _PROGRAM:   # (ros_util.init_rclpy puts the node's own handlers in place)
    _signal.signal(_signal.SIGINT, _stopped_while_loading)
    _signal.signal(_signal.SIGTERM, _stopped_while_loading)

if hasattr(_signal, 'SIGUSR1') and _sys.__stderr__ is not None:
    try:
        _faulthandler.register(_signal.SIGUSR1, file=_sys.__stderr__, all_threads=True)
    except (AttributeError, OSError, ValueError):  # no usable stderr descriptor
        pass
