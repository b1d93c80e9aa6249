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

``kill -USR1 <pid>`` makes a node process print every thread's Python stack
on its stderr and go on (:mod:`faulthandler`, registered when this package is
imported, before rclpy and the kernels load): the way to see where a node
that does not answer is, even inside a C call that holds it.
"""

import faulthandler as _faulthandler
import signal as _signal
import sys as _sys

if hasattr(_signal, 'SIGUSR1') and _sys.__stderr__ is not None:
    try:
        _faulthandler.register(_signal.SIGUSR1, file=_sys.__stderr__, all_threads=True)
    except (AttributeError, OSError, ValueError):  # no usable stderr descriptor
        pass
