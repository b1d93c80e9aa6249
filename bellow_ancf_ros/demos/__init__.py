"""Runnable jobs that show the package at work (through the public API and the nodes).

Each runs as ``python -m bellow_ancf_ros.demos.<module>``:

* :mod:`.closed_loop` -- ``make demo``, the main job (about 14 min on a quiet
  2-core machine, longer on a busy one): the nodes
  as separate processes against a mismatched simulated robot, feedforward
  then integral feedback, one and two segments, next to the paper's
  figures; a plot.
* :mod:`.forces` -- the main job's loads phase (``make demo`` runs it after
  :mod:`.closed_loop`, about 40 s): an unannounced payload and a push on the
  simulated robot, the force estimator's reading against the truth, and
  tracking with integral feedback alone and with force compensation.
* :mod:`.calibration` -- ``make demo-calibrate`` (about 3 min): excitation
  -> simulated robot seen by an offset motion capture -> rosbag2 ->
  ``bellow-ancf calibrate`` -> tracking with the nominal and the
  calibrated robot files.
* :mod:`.offline` -- ``make demo-offline`` (about 2 s): the core alone, forward
  and inverse problems printed, no ROS.
* :mod:`.wiring_check` -- run shortened by ``test/nodes/test_ros_e2e.py``
  (about 40 s in full): every topic of the launch file wired as documented.

Helpers: :mod:`.pipeline` (node processes, recorders, waiting with a
deadline) and :mod:`.closed_loop_plot` (the main job's figure).
"""
