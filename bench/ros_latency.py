"""End-to-end latency across processes: ``target_pose`` publish -> ``pressure_command`` receipt.

Starts ``inverse_kinetostatic_node`` as its own process (isolated
``ROS_DOMAIN_ID``, localhost discovery), then sends targets one at a time
(1 mm apart on a circle; for two segments with the end-effector z-axis
tilted 10 degrees and turning with it) and times each answer.  Prints the
median and p99 (targets: median 2 ms one segment, 4 ms two).

Receipt is the subscriber's reception time stamped by the middleware
(``MessageInfo['received_timestamp']``, system clock, against the system
time just before the target is published): the latency of the node and the
transport.  This client's own executor then takes a further 0.2 to 0.7 ms
before its callback runs (rclpy's SingleThreadedExecutor rebuilding its
wait set); that figure is returned too (``callback_median_s``).
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time

import numpy as np


def _tilt(angle, azimuth):
    """Rotation whose z-axis is tilted by ``angle`` towards the azimuth ``azimuth``."""
    axis = np.array([-np.sin(azimuth), np.cos(azimuth), 0.0])
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def main(n_targets=150, robot="one_segment", quiet=False, pythonpath=None):
    """Measure; print (unless ``quiet``) and return median, p99 and counts.

    ``pythonpath``: run the node from another checkout (the benchmark's baseline).
    """
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 101)))
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from std_msgs.msg import Float64MultiArray

    from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward
    from bellow_ancf_ros.core.geometry import quaternion_from_rotation
    from bellow_ancf_ros.nodes.ros_util import command_qos

    env, cwd = dict(os.environ), None
    if pythonpath:  # the other checkout first on the path (python -m puts the cwd first)
        env["PYTHONPATH"] = cwd = os.path.abspath(pythonpath)
    node_proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "bellow_ancf_ros.nodes.inverse_kinetostatic_node",
            "--ros-args",
            "-p",
            f"robot_config:={robot}",
            "-p",
            "max_rate_hz:=1000.0",
        ],
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
        cwd=cwd,
    )
    rclpy.init()
    node = rclpy.create_node("latency_bench")
    got = []

    def on_command(msg, info):
        now = time.time_ns()
        got.append((info.get("received_timestamp") or now, now))  # (no stamp: the callback)

    node.create_subscription(Float64MultiArray, "pressure_command", on_command, command_qos())
    pub = node.create_publisher(PoseStamped, "target_pose", command_qos())
    try:
        deadline = time.monotonic() + 30
        while pub.get_subscription_count() == 0 or node.count_publishers("pressure_command") == 0:
            rclpy.spin_once(node, timeout_sec=0.05)
            if time.monotonic() > deadline or node_proc.poll() is not None:
                raise RuntimeError("inverse_kinetostatic_node did not come up")
        model = RobotModel(load_robot(robot))
        multi = model.cfg.n_segments > 1
        centre = solve_forward(model, np.full(model.A, 30e3 if multi else 40e3)).position
        radius = 0.02 if multi else 0.01
        lat = []
        for k in range(n_targets + 10):
            phi = k * 1e-3 / radius
            msg = PoseStamped()
            msg.header.frame_id = "base"
            msg.pose.position.x = float(centre[0] + radius * np.cos(phi))
            msg.pose.position.y = float(centre[1] + radius * np.sin(phi))
            msg.pose.position.z = float(centre[2])
            q = quaternion_from_rotation(_tilt(np.radians(10.0), phi) if multi else np.eye(3))
            (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z,
             msg.pose.orientation.w) = (float(v) for v in q)
            got.clear()
            t0 = time.time_ns()
            pub.publish(msg)
            deadline = time.monotonic() + 5
            while not got and time.monotonic() < deadline:
                rclpy.spin_once(node, timeout_sec=0.001)
            if got and k >= 10:  # the first answers include discovery and warm-up
                lat.append(((got[0][0] - t0) * 1e-9, (got[0][1] - t0) * 1e-9))
        lat = np.array(lat).reshape(-1, 2)
        out = {
            "median_s": float(np.median(lat[:, 0])),
            "p99_s": float(np.percentile(lat[:, 0], 99)),
            "callback_median_s": float(np.median(lat[:, 1])),
            "answered": len(lat),
            "sent": n_targets,
        }
        if not quiet:
            print(
                f"{'end-to-end target_pose -> pressure_command (' + robot + ', processes)':<78} "
                f"{out['median_s'] * 1e3:7.2f}ms {out['p99_s'] * 1e3:7.2f}ms"
            )
            print(f"   ({len(lat)} of {n_targets} targets answered; at this client's callback: "
                  f"median {out['callback_median_s'] * 1e3:.2f} ms)")
    finally:
        close(node, node_proc)
    return out


def close(node, proc):
    """Destroy the client ``node``, shut rclpy down, stop the node process (SIGINT, SIGKILL)."""
    import rclpy

    node.destroy_node()
    rclpy.try_shutdown()
    try:
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=10)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        os.killpg(proc.pid, signal.SIGKILL)


if __name__ == "__main__":
    main(robot=sys.argv[1] if len(sys.argv) > 1 else "one_segment")
    sys.exit(0)
