"""ros_util without a ROS context: what rclpy's own parameter checks refuse, in words."""

import math

from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter

from bellow_ancf_ros.nodes.ros_util import _descriptor_refusal, allowed_values, descriptor


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
