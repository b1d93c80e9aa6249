"""ros_util: what rclpy's own parameter checks refuse, in words; a node's way out."""

import math
import time

from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter

from bellow_ancf_ros.nodes.ros_util import (_descriptor_refusal, _release_node, allowed_values,
                                            descriptor)


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


def _publishers_gone(watcher, topic, within_s):
    """Whether ``topic`` has no publisher left within ``within_s`` (the graph ``watcher`` sees)."""
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        if watcher.count_publishers(topic) == 0:
            return True
        time.sleep(0.05)
    return False


def test_a_node_taken_off_its_kept_executor_leaves_the_graph_at_once(ros_context):
    """run_node's end of a console script's node: off the EventsExecutor, kept until the exit.

    The node off its executor, destroyed, its context shut down, the executor
    kept.  Without :func:`_release_node` the node's publisher stayed in the
    graph until the middleware's lease ran out (20 s).
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from std_msgs.msg import Float64MultiArray

    watcher = rclpy.create_node('watcher', context=ros_context)
    own = Context()   # (the leaving node's process: its own context, the same domain)
    rclpy.init(context=own, domain_id=ros_context.get_domain_id())
    node = rclpy.create_node('leaving', context=own)
    publisher = node.create_publisher(Float64MultiArray, 'probe', 10)   # (a node's attribute)
    executor = EventsExecutor(context=own)
    executor.add_node(node)
    deadline = time.monotonic() + 10.0
    while watcher.count_publishers('/probe') == 0 and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    assert watcher.count_publishers('/probe') == 1
    executor.remove_node(node)
    _release_node(executor)
    node.destroy_node()
    own.try_shutdown()
    kept = [executor, publisher]   # (as run_node keeps them: never freed before os._exit)
    assert _publishers_gone(watcher, '/probe', 3.0), 'the publisher stayed in the graph'
    assert kept
    watcher.destroy_node()
