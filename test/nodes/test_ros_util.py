"""ros_util: what rclpy's own parameter checks refuse, in words; a node's way out."""

import math
import os
import signal
import subprocess
import sys

from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter

from bellow_ancf_ros.nodes.ros_util import _descriptor_refusal, allowed_values, descriptor
from ros_processes import node_process_env, wait_for


def test_what_rclpy_refuses_before_any_callback_is_named_type_or_range():
    payload = descriptor('payload', ParameterType.PARAMETER_DOUBLE, lo=0.0, hi=1.0)
    assert _descriptor_refusal(payload, Parameter('payload_kg', value=0.05)) == ''
    assert _descriptor_refusal(payload, Parameter('payload_kg', value=1)) == 'type'
    assert _descriptor_refusal(payload, Parameter('payload_kg', value='heavy')) == 'type'
    for bad in (-0.01, 1.5, math.nan, math.inf):
        assert _descriptor_refusal(payload, Parameter('payload_kg', value=bad)) == 'range'
    steps = descriptor('steps', ParameterType.PARAMETER_INTEGER, lo=1, hi=100)
    assert _descriptor_refusal(steps, Parameter('step_count', value=0)) == 'range'
    assert _descriptor_refusal(steps, Parameter('step_count', value=20)) == ''
    force = descriptor('force', ParameterType.PARAMETER_DOUBLE_ARRAY, lo=-1.0, hi=1.0)
    assert _descriptor_refusal(force, Parameter('tip_force_n', value=[0.0, 5.0, 0.0])) == ''
    gain = descriptor('gain', ParameterType.PARAMETER_DOUBLE, dynamic=True)   # 'auto' or a number
    assert _descriptor_refusal(gain, Parameter('feedback_gain_per_s', value='auto')) == ''
    assert _descriptor_refusal(payload, Parameter('payload_kg', Parameter.Type.NOT_SET)) == ''
    assert allowed_values(payload) == ('a floating-point number (write 1.0, not 1), '
                                       'from 0 to 1')


#: A console script's node at its end: ``run_node(keep_until_exit=True)`` returns on the first
#: line of stdin (as on a first SIGINT) and the process stays up until the second, so that a
#: publisher gone before then left through run_node, not through the process's exit.
_LEAVING = """
import os, sys, threading
import rclpy
from std_msgs.msg import Float64MultiArray
from bellow_ancf_ros.nodes import ros_util
rclpy.init()
node = rclpy.create_node('leaving')
node.create_publisher(Float64MultiArray, 'probe', 10)
def stop():
    sys.stdin.readline()
    ros_util.request_stop()
threading.Thread(target=stop, daemon=True).start()
print('UP', flush=True)
ros_util.run_node(node, keep_until_exit=True)
print('LEFT', flush=True)
sys.stdin.readline()
os._exit(0)
"""


def test_a_console_scripts_node_leaves_the_graph_before_its_process_exits(ros_context):
    """run_node's end of a console script's node: off the EventsExecutor, kept until the exit.

    Without :func:`_release_node` the node's publisher stayed in the graph
    until the middleware's lease ran out (20 s).  In a process of its own:
    freeing an EventsExecutor hung a process, holding the GIL, so this
    test's worker never holds one.
    """
    import rclpy

    env = dict(node_process_env(), ROS_DOMAIN_ID=str(ros_context.get_domain_id()))
    proc = subprocess.Popen([sys.executable, '-c', _LEAVING], env=env, text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, start_new_session=True)
    watcher = rclpy.create_node('watcher', context=ros_context)
    try:
        assert proc.stdout.readline().strip() == 'UP'
        wait_for(lambda: watcher.count_publishers('/probe') == 1, 20.0, 'the publisher')
        proc.stdin.write('stop\n')
        proc.stdin.flush()
        assert proc.stdout.readline().strip() == 'LEFT'
        wait_for(lambda: watcher.count_publishers('/probe') == 0, 3.0,
                 'the publisher to leave the graph')
        assert proc.poll() is None   # (still up: the publisher left before the process did)
        proc.stdin.write('exit\n')
        proc.stdin.flush()
        assert proc.wait(timeout=10.0) == 0, proc.stdout.read()
    finally:
        watcher.destroy_node()
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10.0)
