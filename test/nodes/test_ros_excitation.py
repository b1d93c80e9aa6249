"""The excitation publisher with real rclpy: the whole sequence, in order and limits, then vent."""

import random
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from bellow_ancf_ros.core import load_robot  # noqa: E402
from bellow_ancf_ros.core.fit._excitation import excitation_sequence  # noqa: E402
from bellow_ancf_ros.nodes.excitation_publisher import ExcitationPublisher  # noqa: E402
from bellow_ancf_ros.nodes.ros_util import command_qos  # noqa: E402
from ros_processes import wait_for  # noqa: E402


@pytest.mark.parametrize('unit', ['Pa', 'kPa'])
def test_steps_through_the_sequence_then_vents(ros_context, unit, capfd):
    ns = f'/exc{random.randint(0, 99999)}'
    client = rclpy.create_node('rec', namespace=ns, context=ros_context)
    got, lock = [], threading.Lock()

    def cb(msg):
        with lock:
            got.append(msg)
    client.create_subscription(Float64MultiArray, 'pressure_command', cb, command_qos())
    params = [Parameter('robot_config', value='two_segment'), Parameter('dwell_s', value=0.1),
              Parameter('rate_hz', value=50.0), Parameter('points_per_scheme', value=2),
              Parameter('n_random', value=3), Parameter('seed', value=7),
              Parameter('pressure_unit', value=unit), Parameter('start_delay_s', value=0.0),
              Parameter('wait_for_subscribers', value=1)]
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(client)
    thread = threading.Thread(target=ex.spin, daemon=True)
    thread.start()
    try:
        node = ExcitationPublisher(namespace=ns, context=ros_context, parameter_overrides=params)
        ex.add_node(node)
        wait_for(lambda: node.finished, 20.0, 'the end of the excitation')
        wait_for(lambda: len(got) and np.all(np.asarray(got[-1].data) == 0.0), 20.0, 'the vent')
    finally:
        ex.shutdown()
        thread.join(timeout=5)
    cfg = load_robot('two_segment')
    factor = 1e3 if unit == 'kPa' else 1.0
    with lock:
        msgs = list(got)
    assert all(m.layout.dim[0].label == f'actuator_pressure_gauge_{unit.lower()}' for m in msgs)
    values = np.array([m.data for m in msgs]) * factor
    assert values.shape[1] == 6
    assert np.all((values >= cfg.p_min) & (values <= cfg.p_max))
    steps = [values[0]] + [v for a, v in zip(values, values[1:]) if np.any(v != a)]
    expected = list(excitation_sequence(cfg, 2, 3, 7)) + [np.zeros(6)]
    # it starts once the recorder is matched: every step arrives, in order
    np.testing.assert_allclose(steps, expected, rtol=1e-12, atol=1e-9)
    assert node.vented and node.published >= len(expected)
    assert f'excitation finished: vent command (0 {unit} gauge) published' in (
        capfd.readouterr().err)
    node.destroy_node()
    client.destroy_node()


def test_a_stall_skips_no_step_and_keeps_each_dwell(ros_context):
    """A tick late by several dwells (a busy CPU) sends the next step, held for its dwell."""
    ns = f'/exc{random.randint(0, 99999)}'
    params = [Parameter('robot_config', value='two_segment'), Parameter('dwell_s', value=0.05),
              Parameter('rate_hz', value=0.1), Parameter('points_per_scheme', value=2),
              Parameter('n_random', value=3), Parameter('seed', value=7),
              Parameter('start_delay_s', value=0.0)]
    node = ExcitationPublisher(namespace=ns, context=ros_context, parameter_overrides=params)
    sent = []
    node._publish = lambda p, vent=False: sent.append(np.array(p, dtype=float))
    try:
        node._tick()                   # the first step goes out
        assert node.step == 0
        time.sleep(0.2)                # four dwells without a tick
        node._tick()
        assert node.step == 1          # the next step, not the fourth
        node._tick()
        assert node.step == 1          # held for its dwell from when it went out
        time.sleep(0.06)
        node._tick()
        assert node.step == 2
        expected = excitation_sequence(load_robot('two_segment'), 2, 3, 7)
        np.testing.assert_allclose(sent[1], expected[1])
    finally:
        node.destroy_node()
