"""ROS 2 nodes around the pure-Python core.

* :mod:`.inverse_kinetostatic_node` -- managed (lifecycle) feedforward
  controller: ``target_pose`` -> ``pressure_command``.
* :mod:`.forward_kinetostatic_node` -- pressures -> ``predicted_pose`` and
  ``predicted_shape`` (RViz markers).
* :mod:`.trajectory_publisher` -- the paper's trajectories on ``target_pose``.
* :mod:`.contract` -- the message contract and the pressure safety gate (no rclpy import);
* :mod:`.worker` -- the latest-only solve worker and solve statistics (no rclpy import).
* :mod:`.ros_util` -- rclpy helpers: QoS, checked parameter declaration,
  one-line start-up errors, the acknowledged vent, the executor and the
  main / spin / signal idiom.
* :mod:`.diagnostics` -- ``/diagnostics``: the 1 Hz status heartbeat,
  per-event statuses, rate limits for refusals and per-solve statuses.

Every node module has a ``main(args=None)`` and runs with
``python -m bellow_ancf_ros.nodes.<module> --ros-args ...``.
"""
