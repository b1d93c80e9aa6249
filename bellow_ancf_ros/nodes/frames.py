"""Measured poses from any frame the node knows, expressed in the base frame.

A motion-capture system publishes in its own frame (``world``, ``mocap``).
:class:`PoseFrames` accepts, for a node whose outputs are in ``base_frame``:

* poses in ``base_frame``, as they are;
* poses in the robot file's mocap frame (``mocap_frame.frame_id``): the
  calibrated pose of the base in that frame (:class:`~bellow_ancf_ros.core.model.MocapFrame`,
  written by ``bellow-ancf calibrate``) expresses them in the base frame;
* where tf2 is importable (a ROS install), any frame tf2 can transform into
  ``base_frame`` at the pose's stamp (or the newest transform for a zero stamp).

Anything else is refused with a :class:`~bellow_ancf_ros.nodes.contract.InputError`
naming the frame given and the frames that are accepted: with tf2, the frames
its buffer knows (at most :data:`MAX_FRAMES_LISTED`) and why tf2 could not
transform (a frame it does not know, no chain between the two, no transform
at the stamp), in words that stay the same from one refused pose to the next
(tf2's own text carries times: it would defeat the refusals' rate limit).
"""

from __future__ import annotations

import re
import time

import numpy as np

from ..core import geometry
from . import contract

__all__ = ['MAX_FRAMES_LISTED', 'PoseFrames', 'tf2_frame_names']

#: At most this many of tf2's frames are named in a refusal (then "and N more").
MAX_FRAMES_LISTED = 12
#: tf2's frame list is read again after this long [s] (refusals can come at mocap rate).
_FRAMES_MAX_AGE_S = 1.0
#: tf2's ``all_frames_as_yaml``: a frame's line (``name: ``), its parent's (``  parent: 'x'``).
_YAML_FRAME = re.compile(r"^(\S.*?):\s*$")
_YAML_PARENT = re.compile(r"^\s+parent:\s*'(.*)'\s*$")


def tf2_frame_names(buffer) -> list[str]:
    """The frames a tf2 buffer knows, sorted (the children and parents of its transforms).

    Read from ``buffer.all_frames_as_yaml()`` (tf2_ros.Buffer, through
    tf2_py's BufferCore): one block per frame that has a transform, its
    parent on the next line; the root frames appear only as parents.  An
    empty list when the buffer knows nothing or cannot tell.
    """
    try:
        text = buffer.all_frames_as_yaml()
    except Exception:  # noqa: BLE001 - a message helper never raises
        return []
    names = set()
    for line in str(text).splitlines():
        m = _YAML_FRAME.match(line) or _YAML_PARENT.match(line)
        if m and m.group(1):
            names.add(m.group(1))
    return sorted(names)


def _exception_kinds(exc) -> set:
    return {c.__name__ for c in type(exc).__mro__}


class PoseFrames:
    """Express incoming poses in ``base_frame`` (see the module docstring)."""

    def __init__(self, node, base_frame: str, mocap_frame=None, use_tf2: bool = True,
                 tf_buffer=None) -> None:
        """``mocap_frame``: the robot file's :class:`MocapFrame` or None; tf2 if importable.

        ``tf_buffer``: a tf2 buffer to use instead of one of its own (kept up
        to date by its owner).
        """
        self.base_frame = base_frame
        self.mocap = mocap_frame
        self._tf = tf_buffer
        self._known = (-float('inf'), [])   # (when read, tf2's frames)
        self._clock = None   # its age: the node's control time (ros_util.ControlClock)
        if hasattr(node, 'get_clock'):   # (else, e.g. no node: time.monotonic())
            from .ros_util import control_clock   # (lazily: this module needs no rclpy)
            self._clock = control_clock(node)
        if use_tf2 and tf_buffer is None:
            try:   # a ROS install has tf2_ros; the PyPI wheels of this venv do not
                from tf2_ros import Buffer, TransformListener
            except ImportError:
                pass
            else:
                self._tf = Buffer()
                self._listener = TransformListener(self._tf, node)

    @property
    def accepted(self) -> str:
        """The frames accepted, for messages."""
        names = [repr(self.base_frame)]
        if self.mocap is not None:
            names.append(f'{self.mocap.frame_id!r} (the robot file\'s mocap_frame)')
        if self._tf is not None:
            names.append(f'any frame tf2 can transform into it ({self._tf2_listing()})')
        return ', '.join(names)

    def tf2_frames(self) -> list[str]:
        """The frames tf2 knows (read at most once a second); empty without tf2."""
        if self._tf is None:
            return []
        now = time.monotonic() if self._clock is None else self._clock.now()
        if now - self._known[0] >= _FRAMES_MAX_AGE_S:
            self._known = (now, tf2_frame_names(self._tf))
        return self._known[1]

    def _tf2_listing(self) -> str:
        known = self.tf2_frames()
        if not known:
            return 'tf2 knows no frame yet'
        shown = ', '.join(repr(f) for f in known[:MAX_FRAMES_LISTED])
        more = len(known) - MAX_FRAMES_LISTED
        return f'tf2 knows {shown}' + (f' and {more} more' if more > 0 else '')

    def pose_in_base(self, msg, orientation: bool = True):
        """A PoseStamped's ``(position, quaternion or None)`` in the base frame.

        InputError for a non-finite position or a frame it cannot transform;
        a quaternion that cannot be normalised raises ValueError later, where
        it is used.  ``orientation`` False: the position only.
        """
        p, o = msg.pose.position, msg.pose.orientation
        pos = np.array([p.x, p.y, p.z], dtype=float)
        if not np.all(np.isfinite(pos)):
            raise contract.InputError(f'measured position is not finite: {pos.tolist()}')
        quat = (o.x, o.y, o.z, o.w) if orientation else None
        return self.to_base(msg.header.frame_id, pos, quat, msg.header.stamp)

    def to_base(self, frame_id: str, position, quaternion=None, stamp=None):
        """``(position, quaternion or None)`` in the base frame; InputError when not possible."""
        p = np.asarray(position, dtype=float).reshape(3)
        if frame_id == self.base_frame:
            return p, None if quaternion is None else np.asarray(quaternion, dtype=float)
        if self.mocap is not None and frame_id == self.mocap.frame_id:
            return self.mocap.to_base(p, quaternion)
        if self._tf is not None and frame_id:
            return self._via_tf2(frame_id, p, quaternion, stamp)
        raise contract.InputError(f'frame {frame_id!r} is not one of the accepted frames: '
                                  f'{self.accepted}')

    def _via_tf2(self, frame_id, p, quaternion, stamp):
        from rclpy.time import Time

        when = Time() if stamp is None or (stamp.sec == 0 and stamp.nanosec == 0) \
            else Time.from_msg(stamp)
        try:
            t = self._tf.lookup_transform(self.base_frame, frame_id, when)
        except Exception as exc:  # noqa: BLE001 - tf2's lookup, connectivity, extrapolation
            raise contract.InputError(
                f'frame {frame_id!r} cannot be transformed into {self.base_frame!r}: '
                f'{self._tf2_reason(frame_id, exc)}; accepted frames: {self.accepted}') from None
        tr, rot = t.transform.translation, t.transform.rotation
        R = geometry.quaternion_to_rotation((rot.x, rot.y, rot.z, rot.w))
        p_base = R @ p + np.array([tr.x, tr.y, tr.z])
        if quaternion is None:
            return p_base, None
        return p_base, geometry.quaternion_from_rotation(
            R @ geometry.quaternion_to_rotation(quaternion))

    def _tf2_reason(self, frame_id: str, exc: Exception) -> str:
        """Why tf2 refused, in words that do not change with the pose's stamp."""
        kinds = _exception_kinds(exc)
        known = self.tf2_frames()
        unknown = [f for f in (frame_id, self.base_frame) if f not in known]
        if 'LookupException' in kinds and unknown:
            return 'tf2 knows no frame ' + ' and no frame '.join(repr(f) for f in unknown)
        if 'ConnectivityException' in kinds:
            return 'tf2 has no chain of transforms between the two frames'
        if 'ExtrapolationException' in kinds:
            return ("tf2 has no transform between the two frames at the pose's stamp (before "
                    'its buffer or after its newest transform: clocks or stamps?)')
        text = str(exc).strip().splitlines()
        return f'tf2: {text[0][:200] if text else type(exc).__name__}'
