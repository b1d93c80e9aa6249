"""PoseFrames with tf2: refusals name the frame given and the frames accepted.

tf2_ros is not installable from PyPI, so a stand-in buffer plays tf2: it
raises exceptions of tf2's names and texts (tf2_py's LookupException,
ConnectivityException, ExtrapolationException, all TransformException) and
answers ``all_frames_as_yaml`` in tf2's BufferCore format.  No ROS graph
is needed (no rclpy node).
"""

from types import SimpleNamespace

from builtin_interfaces.msg import Time
import numpy as np
import pytest

from bellow_ancf_ros.core.model import MocapFrame
from bellow_ancf_ros.nodes.contract import InputError
from bellow_ancf_ros.nodes.diagnostics import Refusals
from bellow_ancf_ros.nodes.frames import MAX_FRAMES_LISTED, PoseFrames, tf2_frame_names


class TransformException(Exception):
    """tf2.TransformException."""


class LookupException(TransformException):
    """tf2.LookupException."""


class ConnectivityException(TransformException):
    """tf2.ConnectivityException."""


class ExtrapolationException(TransformException):
    """tf2.ExtrapolationException."""


class FakeBuffer:
    """A tf2 buffer holding static transforms ``{child: (parent, translation)}`` (no rotation).

    ``latest_s``: the newest transform's time; a lookup at a later stamp
    raises tf2's extrapolation error, whose text carries both times.
    """

    def __init__(self, edges, latest_s=None):
        self.edges, self.latest_s = dict(edges), latest_s

    def frames(self):
        return set(self.edges) | {parent for parent, _ in self.edges.values()}

    def all_frames_as_yaml(self):
        if not self.edges:
            return '[]'
        out = []
        for child, (parent, _) in self.edges.items():
            out += [f'{child}: ', f"  parent: '{parent}'", "  broadcaster: 'default_authority'",
                    '  rate: 10000.000', '  most_recent_transform: 0.000000',
                    '  oldest_transform: 0.000000', '  buffer_length: 0.000']
        return '\n'.join(out) + '\n'

    def _to_root(self, frame):
        chain, p = [frame], np.zeros(3)
        while frame in self.edges:
            frame, t = self.edges[frame]
            p = p + np.asarray(t, dtype=float)
            chain.append(frame)
        return chain, p

    def lookup_transform(self, target_frame, source_frame, time):
        for arg, frame in (('target_frame', target_frame), ('source_frame', source_frame)):
            if frame not in self.frames():
                raise LookupException(
                    f'"{frame}" passed to lookupTransform argument {arg} does not exist. ')
        (t_chain, t_p), (s_chain, s_p) = self._to_root(target_frame), self._to_root(source_frame)
        if t_chain[-1] != s_chain[-1]:
            raise ConnectivityException(
                f"Could not find a connection between '{target_frame}' and '{source_frame}' "
                'because they are not part of the same tree.Tf has two or more unconnected trees.')
        wanted = time.nanoseconds * 1e-9
        if self.latest_s is not None and wanted > self.latest_s:
            raise ExtrapolationException(
                'Lookup would require extrapolation into the future.  Requested time '
                f'{wanted:.6f} but the latest data is at time {self.latest_s:.6f}, when looking '
                f'up transform from frame [{source_frame}] to frame [{target_frame}]')
        d = s_p - t_p   # source origin in the target frame (translations only)
        return SimpleNamespace(transform=SimpleNamespace(
            translation=SimpleNamespace(x=d[0], y=d[1], z=d[2]),
            rotation=SimpleNamespace(x=0.0, y=0.0, z=0.0, w=1.0)))


def stamp(sec, nanosec=0):
    return Time(sec=sec, nanosec=nanosec)


def refusal(frames, frame_id, when=stamp(0)):
    with pytest.raises(InputError) as info:
        frames.to_base(frame_id, [0.01, 0.0, 0.1], None, when)
    return str(info.value)


def test_frame_names_from_tf2_yaml():
    buf = FakeBuffer({'world': ('map', (0, 0, 0)), 'base': ('world', (0, 0, 1))})
    assert tf2_frame_names(buf) == ['base', 'map', 'world']   # the root 'map' only as a parent
    assert tf2_frame_names(FakeBuffer({})) == []                # tf2's '[]'


def test_transform_through_tf2():
    buf = FakeBuffer({'base': ('world', (0.0, 0.0, 0.5)), 'rig': ('world', (1.0, 0.0, 0.0))})
    frames = PoseFrames(None, 'base', tf_buffer=buf)
    p, q = frames.to_base('rig', [0.01, 0.0, 0.1])
    assert np.allclose(p, [1.01, 0.0, -0.4]) and q is None


def test_base_frame_unknown_to_tf2_is_refused_naming_the_frames():
    """The lab's case: tf2 has the mocap's tree but not the base frame."""
    buf = FakeBuffer({'rigid_body_1': ('world', (0, 0, 0))})
    mocap = MocapFrame('optitrack', [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    msg = refusal(PoseFrames(None, 'base', mocap, tf_buffer=buf), 'world')
    assert 'passed to lookupTransform' not in msg          # not tf2's raw text
    assert "frame 'world'" in msg and "tf2 knows no frame 'base'" in msg
    assert "'base'" in msg and "'optitrack'" in msg      # base and the mocap frame
    assert "tf2 knows 'rigid_body_1', 'world'" in msg     # and tf2's frames


def test_pose_frame_unknown_to_tf2():
    buf = FakeBuffer({'base': ('world', (0, 0, 0))})
    msg = refusal(PoseFrames(None, 'base', tf_buffer=buf), 'elsewhere')
    assert "frame 'elsewhere'" in msg and "tf2 knows no frame 'elsewhere'" in msg
    assert "tf2 knows no frame 'base'" not in msg
    assert "tf2 knows 'base', 'world'" in msg


def test_unconnected_trees():
    buf = FakeBuffer({'base': ('world', (0, 0, 0)), 'camera': ('odom', (0, 0, 0))})
    msg = refusal(PoseFrames(None, 'base', tf_buffer=buf), 'camera')
    assert "frame 'camera'" in msg and 'no chain of transforms' in msg
    assert "tf2 knows 'base', 'camera', 'odom', 'world'" in msg


def test_a_stamp_too_new_gives_the_same_refusal_each_time():
    """tf2's extrapolation text carries the times; the refusal's does not (rate limit)."""
    buf = FakeBuffer({'base': ('world', (0, 0, 0))}, latest_s=100.0)
    frames = PoseFrames(None, 'base', tf_buffer=buf)
    first, second = refusal(frames, 'world', stamp(101)), refusal(frames, 'world', stamp(102, 5))
    assert first == second
    assert "frame 'world'" in first and 'stamp' in first and '101' not in first


def test_long_frame_lists_are_capped():
    edges = {f'marker_{i:02d}': ('world', (0, 0, 0)) for i in range(40)}
    msg = refusal(PoseFrames(None, 'base', tf_buffer=FakeBuffer(edges)), 'marker_03')
    assert f'and {41 - MAX_FRAMES_LISTED} more' in msg
    assert "'marker_00'" in msg and "'marker_39'" not in msg
    assert len(msg) < 600


def test_tf2_without_frames_yet():
    msg = refusal(PoseFrames(None, 'base', tf_buffer=FakeBuffer({})), 'world')
    assert 'tf2 knows no frame yet' in msg


class FakeLogger:
    def __init__(self):
        self.lines = []

    def warning(self, text, throttle_duration_sec=None):
        self.lines.append((text, throttle_duration_sec))


def test_refusal_reaches_log_and_diagnostics_once_per_interval():
    """The log line (throttled) and /diagnostics carry the frames; repeats are rate-limited."""
    buf = FakeBuffer({'rigid_body_1': ('world', (0, 0, 0))}, latest_s=100.0)
    frames = PoseFrames(None, 'base', tf_buffer=buf)
    log, diags = FakeLogger(), []
    node = SimpleNamespace(get_logger=lambda: log)
    refusals = Refusals(node, 'measured poses', lambda *a: diags.append(a))
    for k in range(5):   # a mocap streaming in 'world', each with its own stamp
        with pytest.raises(InputError) as info:
            frames.to_base('world', [0.0, 0.0, 0.1], None, stamp(200 + k))
        refusals.report(str(info.value), k + 1)
    assert len(diags) == 1
    assert "frame 'world'" in diags[0][1] and "tf2 knows 'rigid_body_1', 'world'" in diags[0][1]
    assert len(log.lines) == 1 and "tf2 knows no frame 'base'" in log.lines[0][0]


def test_a_refusal_of_another_kind_is_logged_at_once():
    """A NaN target right after one in a wrong frame: both logged; repeats of each throttled.

    rclpy's throttle is per call site: the first refusal's line hid the
    second's (a lab-style trial: the NaN refusal reached /diagnostics only).
    Numbers in a reason (values, stamps) do not make it another kind.
    """
    log = FakeLogger()
    node = SimpleNamespace(get_logger=lambda: log)
    refusals = Refusals(node, 'targets', lambda *a: None)
    for k in range(3):
        refusals.report(f"target frame 'world' is not the base frame 'base' (stamp {k}.5)", k)
        refusals.report(f'target position must be 3 finite numbers, got [{k}.0, nan, inf]', k)
    assert [line for line, _ in log.lines] == [
        "targets refused: target frame 'world' is not the base frame 'base' (stamp 0.5)",
        'targets refused: target position must be 3 finite numbers, got [0.0, nan, inf]']
