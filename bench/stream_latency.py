"""Latency of the inverse node under a target *stream* at its rate limit, against one solve.

Starts ``inverse_kinetostatic_node`` as its own process (isolated
``ROS_DOMAIN_ID``, localhost discovery) at its default ``max_rate_hz``
(100 Hz) and streams targets at that same rate along the paper's planar
circle (one segment) or bending circle (two segments, 10 deg), each stamped
with its publish time.  Every ``commanded_pose`` carries the stamp of the
target it answers: latency = its reception (middleware stamp) minus that
stamp.  Printed: median and p99 latency, the share of targets never
answered, and the ratio of the median to the latency of one target on its
own (the same node answering the same trajectory's targets sent one at a
time, with idle time between them).

Target (issue: "the rate limit adds latency it does not need"): median
within 1.5x of the single-solve time.

    .venv/bin/python bench/stream_latency.py [one_segment|two_segment] [--seconds 20]
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys
import time

import numpy as np

from ros_latency import close   # same folder


def _start_node(robot, rate_hz):
    return subprocess.Popen(
        [sys.executable, "-m", "bellow_ancf_ros.nodes.inverse_kinetostatic_node", "--ros-args",
         "-p", f"robot_config:={robot}", "-p", f"max_rate_hz:={rate_hz}"],
        start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _targets(robot, n, rate_hz):
    """``n`` poses of the paper's trajectory at ``rate_hz`` (positions, quaternions)."""
    from bellow_ancf_ros.core import load_robot
    from bellow_ancf_ros.core.experiments import trajectory
    from bellow_ancf_ros.core.geometry import quaternion_from_z_axis

    cfg = load_robot(robot)
    t = np.arange(n) / rate_hz
    if cfg.n_segments > 1:
        pos, z = trajectory("bending_circle", t, cfg, bending_angle_deg=10.0)
    else:
        pos, z = trajectory("planar_circle", t, cfg)
    quats = [quaternion_from_z_axis(v) if v is not None else np.array([0, 0, 0, 1.0])
             for v in (z if z is not None else [None] * n)]
    return np.asarray(pos), np.asarray(quats)


def main(robot="one_segment", seconds=20.0, rate_hz=100.0, quiet=False):
    """Measure; print (unless ``quiet``) and return the figures."""
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 101)))
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    import rclpy
    from geometry_msgs.msg import PoseStamped

    from bellow_ancf_ros.nodes.ros_util import command_qos

    proc = _start_node(robot, rate_hz)
    rclpy.init()
    node = rclpy.create_node("stream_latency_bench")
    answers = {}   # target stamp (ns) -> reception (ns)

    def on_pose(msg, info):
        now = time.time_ns()
        key = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        answers.setdefault(key, info.get("received_timestamp") or now)

    node.create_subscription(PoseStamped, "commanded_pose", on_pose, command_qos())
    pub = node.create_publisher(PoseStamped, "target_pose", command_qos())

    def send(p, q, stamp_ns):
        msg = PoseStamped()
        msg.header.frame_id = "base"
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        (msg.pose.position.x, msg.pose.position.y, msg.pose.position.z) = (float(v) for v in p)
        (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z,
         msg.pose.orientation.w) = (float(v) for v in q)
        pub.publish(msg)

    try:
        deadline = time.monotonic() + 60
        while pub.get_subscription_count() == 0 or node.count_publishers("commanded_pose") == 0:
            rclpy.spin_once(node, timeout_sec=0.05)
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError("inverse_kinetostatic_node did not come up")
        n = int(seconds * rate_hz)
        pos, quat = _targets(robot, n + 200, rate_hz)
        # 1) one target at a time (the single-solve figure): the stream's first 100 poses
        single = []
        for k in range(100):
            t0 = time.time_ns()
            send(pos[k], quat[k], t0)
            wait = time.monotonic() + 5
            while t0 not in answers and time.monotonic() < wait:
                rclpy.spin_once(node, timeout_sec=0.001)
            if t0 in answers and k >= 10:
                single.append((answers[t0] - t0) * 1e-9)
            time.sleep(1.0 / rate_hz)   # idle between targets
        # 2) the stream at the rate limit, from where the single targets ended
        sent = []
        start = time.monotonic()
        for k in range(n):
            due = start + k / rate_hz
            while True:
                left = due - time.monotonic()
                if left <= 0:
                    break
                rclpy.spin_once(node, timeout_sec=min(left, 0.002))
            stamp = time.time_ns()
            send(pos[100 + k], quat[100 + k], stamp)
            sent.append(stamp)
        drain = time.monotonic() + 1.0
        while time.monotonic() < drain:
            rclpy.spin_once(node, timeout_sec=0.01)
        sent = sent[int(rate_hz):]   # the first second: the node meets the stream
        lat = np.array([(answers[s] - s) * 1e-9 for s in sent if s in answers])
        single_med = float(np.median(single))
        out = {
            "robot": robot, "rate_hz": rate_hz, "sent": len(sent), "answered": int(lat.size),
            "unanswered_fraction": 1.0 - lat.size / len(sent),
            "median_s": float(np.median(lat)), "p99_s": float(np.percentile(lat, 99)),
            "single_median_s": single_med,
            "ratio": float(np.median(lat)) / single_med,
        }
        if not quiet:
            print(f"{robot}: {rate_hz:g} Hz target stream at max_rate_hz {rate_hz:g}: latency "
                  f"median {out['median_s'] * 1e3:.2f} ms, p99 {out['p99_s'] * 1e3:.2f} ms, "
                  f"{out['unanswered_fraction'] * 100:.2f} % of {len(sent)} targets unanswered; "
                  f"one target at a time: median {single_med * 1e3:.2f} ms; "
                  f"ratio {out['ratio']:.2f} (target <= 1.5)")
    finally:
        close(node, proc)
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("robot", nargs="?", default="one_segment")
    ap.add_argument("--seconds", type=float, default=20.0)
    args = ap.parse_args()
    main(args.robot, args.seconds)
