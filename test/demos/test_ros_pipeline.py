"""The demos' in-process rclpy node (pipeline.SpunNode/Recorder) with real rclpy and topics."""

from contextlib import contextmanager
import time

import pytest

pytest.importorskip('rclpy')

from rclpy.context import Context  # noqa: E402
import rclpy  # noqa: E402
from std_msgs.msg import Float64MultiArray, Header  # noqa: E402

from bellow_ancf_ros.demos.pipeline import Recorder, record_qos, wait_until  # noqa: E402
from ros_domains import fresh_domain  # noqa: E402


@contextmanager
def _commander(rec, domain):
    """A ``pressure_command`` publisher in a context of its own, matched with ``rec`` both ways.

    Yields the publisher; on the way out the commander goes and ``rec`` is closed.
    """
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node('commander', context=ctx)
    pub = node.create_publisher(Float64MultiArray, 'pressure_command', record_qos())
    try:
        assert wait_until(lambda: rec.publishers('pressure_command') == 1
                          and pub.get_subscription_count() == 1, 10.0)
        yield pub
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        rec.close()


def test_a_recorder_records_on_after_its_node_destroyed_a_publisher_while_it_spun():
    """An entity destroyed by another thread made rclpy's wait raise; the spin goes on.

    With ``executor.spin()`` the recorder's thread ended there (238 publishers
    into the loop below in one trial; a closed-loop run of ``make demo``
    destroys one as it ends) and nothing more was recorded: a vent the
    middleware had acknowledged never reached the recording.
    """
    domain = fresh_domain()
    rec = Recorder(domain, {'pressure_command': Float64MultiArray})
    with _commander(rec, domain) as pub:
        for _ in range(400):   # a publisher (its QoS events are waitables) made and destroyed
            p = rec.node.create_publisher(Header, 'leave', 10)
            time.sleep(0.001)
            rec.node.destroy_publisher(p)
        assert rec.thread.is_alive()
        pub.publish(Float64MultiArray(data=[0.0, 0.0, 0.0]))
        assert pub.wait_for_all_acked(rclpy.duration.Duration(seconds=4.0))
        assert rec.wait_for_vent(timeout=5.0)    # acknowledged, and recorded
        assert rec.count('pressure_command') == 1
    assert not rec.thread.is_alive()   # close() ends the spin


def test_a_wait_that_raises_does_not_end_the_recorders_spin():
    """The race above made deterministic: the recorder's wait raises once, as rclpy's did.

    ``rclpy._rclpy_pybind11.InvalidHandle`` (``cannot use Destroyable because
    destruction was requested``, from a publisher's event handler) ended
    ``executor.spin()`` in 5 of 18 busy short demo runs; the spin goes on,
    counts it, and records what comes after.
    """
    domain = fresh_domain()
    rec = Recorder(domain, {'pressure_command': Float64MultiArray})
    real = rec.executor.wait_for_ready_callbacks   # (where rclpy raised: its wait set)
    raised = []

    def wait_for_ready_callbacks(*args, **kwargs):
        if not raised:
            raised.append(1)
            raise RuntimeError('cannot use Destroyable because destruction was requested')
        return real(*args, **kwargs)
    rec.executor.wait_for_ready_callbacks = wait_for_ready_callbacks
    with _commander(rec, domain) as pub:
        pub.publish(Float64MultiArray(data=[1.0, 1.0, 1.0]))   # (wakes a blocking spin too)
        assert wait_until(lambda: raised, 5.0)
        time.sleep(0.3)
        assert rec.thread.is_alive() and rec.spin_errors == 1
        pub.publish(Float64MultiArray(data=[0.0, 0.0, 0.0]))
        assert rec.wait_for_vent(timeout=5.0)
