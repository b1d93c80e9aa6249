"""The closed loop without ROS: the controller and a simulated robot closed around each other.

* :class:`LoopSimulation`, :class:`LoopRecord`: the inverse node's closed
  loop (targets, feedback, the command output) around a
  :class:`~bellow_ancf_ros.core.sim.SimulatedRobot`, in simulated time
  (tests, benchmarks);
* :func:`held_case`, :func:`circle_case`, :func:`step_case`: the closed
  loop's goals measured on it, at the inverse node's defaults
  (:func:`default_loop`; :func:`paper_circle`, :data:`STEP_M`).
"""

from ._loop_simulation import LoopRecord, LoopSimulation
from ._loop_cases import STEP_M, circle_case, default_loop, held_case, paper_circle, step_case

__all__ = ["LoopRecord", "LoopSimulation", "STEP_M", "circle_case", "default_loop", "held_case",
           "paper_circle", "step_case"]
