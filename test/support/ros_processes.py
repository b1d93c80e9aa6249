"""Shared by the tests that run nodes as processes: their environment and a spun client.

Imports rclpy: only for tests that already skipped without it.
"""

import os
from pathlib import Path
from ros_domains import fresh_domain  # noqa: E402
import signal
import subprocess
import threading
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor

from bellow_ancf_ros.nodes.ros_util import spin_until_closed

REPO = Path(__file__).resolve().parents[2]


def node_process_env() -> dict:
    """The environment of a node process: an isolated domain, this checkout, unbuffered."""
    e = dict(os.environ)
    e['ROS_DOMAIN_ID'] = str(fresh_domain())
    e['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    e['PYTHONPATH'] = str(REPO) + os.pathsep + e.get('PYTHONPATH', '')
    e['PYTHONUNBUFFERED'] = '1'
    return e


def interrupt(proc, wait_s: float):
    """Ctrl-C to a node process's group (started with ``start_new_session``); SIGKILL late.

    Waits up to ``wait_s`` for it to exit, then SIGKILLs its group.  Returns
    what it wrote to a ``stdout=PIPE`` (None without one); its exit status
    is then ``proc.returncode``.
    """
    return interrupt_all([proc], wait_s)[0]


def interrupt_all(procs, wait_s: float) -> list:
    """:func:`interrupt` for several node processes: Ctrl-C to all first, then each waited for.

    Returns their outputs, in order (see :func:`interrupt`).
    """
    for proc in procs:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
    outputs = []
    for proc in procs:
        try:   # (communicate: a full pipe would block the process on its way out)
            outputs.append(proc.communicate(timeout=wait_s)[0])
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            outputs.append(proc.communicate(timeout=5.0)[0])
    return outputs


def wait_for(pred, timeout=15.0, what='condition', every=None, action=None):
    """Poll ``pred`` until true, else AssertionError naming ``what``.

    ``action``: called first and then every ``every`` seconds while waiting
    (e.g. a target published again until a node answers).
    """
    deadline = time.monotonic() + timeout
    next_action = time.monotonic()
    while time.monotonic() < deadline:
        if action is not None and time.monotonic() >= next_action:
            action()
            next_action = time.monotonic() + every
        if pred():
            return
        time.sleep(0.005)
    raise AssertionError(f'timed out after {timeout} s waiting for {what}')


class SpunClient:
    """An rclpy node in this process on ``domain``, spun in a daemon thread until ``close``.

    A subclass creates its subscriptions and publishers in ``setup(node)``,
    which runs before the spinning starts.
    """

    def __init__(self, domain: int, name: str):
        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=domain)
        self.node = rclpy.create_node(name, context=self.ctx)
        self.lock = threading.Lock()
        self.setup(self.node)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.closed = threading.Event()
        self.thread = threading.Thread(target=spin_until_closed,
                                       args=(self.executor, self.ctx, self.closed), daemon=True)
        self.thread.start()

    def setup(self, node) -> None:
        """Create the subscriptions and publishers (nothing here)."""

    def close(self):
        self.closed.set()
        self.executor.shutdown(timeout_sec=2.0)
        self.thread.join(5.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)
