#!/usr/bin/env python3
"""Generate ``data/one_segment_bag``: a small calibration recording of the simulated robot.

The recording ``bellow-ancf calibrate --bag`` reads, made without ROS and
repeatable (seeded): the simulated robot of ``make demo`` and ``make
demo-calibrate`` (:class:`bellow_ancf_ros.core.sim.SimulatedRobot`, the robot
file ``config/one_segment_mismatched.yaml``, whose pitch radius, ``D_a``,
stiffness and masses differ from ``config/one_segment.yaml``; the ideal
hardware of ``PlantEffects.ideal``: 0.1 s regulators, motion capture with
0.15 mm and 0.1 deg noise) is stepped through the excitation sequence of
``excitation_publisher`` (``excitation_sequence``: the workspace schemes with
two points each, then random vectors), each step held ``DWELL_S``.  The
rosbag2 directory (sqlite3, written with ``rosbags``) holds what a lab
recording holds:

* ``/pressure_command`` (std_msgs/Float64MultiArray, Pa, the nodes' layout
  label), each step republished at ``COMMAND_RATE_HZ``;
* ``/measured_pose`` (geometry_msgs/PoseStamped of the end effector) at
  ``MOCAP_RATE_HZ`` in a motion-capture frame ``world`` in which the base
  frame sits at ``MOCAP_T`` with rotation vector ``MOCAP_ROTVEC_DEG``
  (unknown to the calibration, which finds it).

Usage: ``python3 data/make_recording.py [OUTDIR]`` (default: this directory;
the bag is ``OUTDIR/one_segment_bag``, replaced if it exists).  Needs the
package and its dependencies (numpy, scipy, rosbags), not ROS.
"""

import shutil
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from bellow_ancf_ros.core import load_robot
from bellow_ancf_ros.core.sim import PlantEffects, SimulatedRobot
from bellow_ancf_ros.core.fit import excitation_sequence, write_bag

BAG_NAME = 'one_segment_bag'
ROBOT = 'one_segment_mismatched'      # the simulated robot ("the real one")
NOMINAL = 'one_segment'               # the robot file the excitation is planned for
SEED = 7
POINTS_PER_SCHEME = 2
N_RANDOM = 24
DWELL_S = 1.5                         # each step held [s]
PHYSICS_DT_S = 0.01
COMMAND_RATE_HZ = 10.0
MOCAP_RATE_HZ = 20.0
START_S = 1767225600.0                # receive times from 2026-01-01 00:00 UTC [s]
MOCAP_T = np.array([0.042, -0.027, 0.061])       # base frame origin in the mocap frame [m]
MOCAP_ROTVEC_DEG = np.array([4.0, -3.0, 6.0])    # base frame rotation in the mocap frame [deg]


def simulate():
    """``(commands, poses)`` of the recording: ``(t_s, Pa)`` and ``(t_s, position, xyzw)``."""
    steps = excitation_sequence(load_robot(NOMINAL), POINTS_PER_SCHEME, N_RANDOM, seed=SEED)
    robot = SimulatedRobot(ROBOT, effects=PlantEffects.ideal(mocap_rate_hz=MOCAP_RATE_HZ),
                           seed=SEED)
    frame = Rotation.from_rotvec(np.radians(MOCAP_ROTVEC_DEG))
    commands, poses = [], []
    per_step = int(round(DWELL_S / PHYSICS_DT_S))
    command_every = int(round(1.0 / (COMMAND_RATE_HZ * PHYSICS_DT_S)))
    mocap_every = int(round(1.0 / (MOCAP_RATE_HZ * PHYSICS_DT_S)))
    tick = 0
    for p in list(steps) + [np.zeros(steps.shape[1])]:      # then the vent, as the node does
        robot.command(p)
        for k in range(per_step):
            t = START_S + tick * PHYSICS_DT_S
            if k % command_every == 0:
                commands.append((t, p))
            robot.step(PHYSICS_DT_S)
            if tick % mocap_every == 0:
                sample = robot.capture()
                if sample is not None:
                    position = frame.apply(sample.position) + MOCAP_T
                    quat = (frame * Rotation.from_matrix(sample.rotation)).as_quat()
                    poses.append((t + PHYSICS_DT_S, position, quat))
            tick += 1
    if robot.failures:
        raise RuntimeError(f'simulated robot: {robot.failures} failed solves: '
                           f'{robot.last_failure}')
    return commands, poses


def main(argv):
    out = Path(argv[1] if len(argv) > 1 else Path(__file__).resolve().parent) / BAG_NAME
    commands, poses = simulate()
    shutil.rmtree(out, ignore_errors=True)
    write_bag(out, commands, poses, storage='sqlite3', frame_id='world')
    size = sum(f.stat().st_size for f in out.iterdir())
    print(f'{out}: {len(commands)} pressure commands, {len(poses)} poses, '
          f'{size / 1e3:.0f} kB')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
