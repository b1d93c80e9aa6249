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
naming the frames that are accepted.
"""

from __future__ import annotations

import numpy as np

from ..core import geometry
from . import contract

__all__ = ['PoseFrames']


class PoseFrames:
    """Express incoming poses in ``base_frame`` (see the module docstring)."""

    def __init__(self, node, base_frame: str, mocap_frame=None, use_tf2: bool = True) -> None:
        """``mocap_frame``: the robot file's :class:`MocapFrame` or None; tf2 if importable."""
        self.base_frame = base_frame
        self.mocap = mocap_frame
        self._tf = None
        if use_tf2:
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
            names.append('any frame tf2 can transform into it')
        return ', '.join(names)

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
        raise contract.InputError(f'frame {frame_id!r} is neither of the accepted frames: '
                                  f'{self.accepted}')

    def _via_tf2(self, frame_id, p, quaternion, stamp):
        from rclpy.time import Time

        when = Time() if stamp is None or (stamp.sec == 0 and stamp.nanosec == 0) \
            else Time.from_msg(stamp)
        try:
            t = self._tf.lookup_transform(self.base_frame, frame_id, when)
        except Exception as exc:  # noqa: BLE001 - tf2's lookup, connectivity, extrapolation
            raise contract.InputError(f'no tf2 transform from {frame_id!r} to '
                                      f'{self.base_frame!r}: {exc}') from None
        tr, rot = t.transform.translation, t.transform.rotation
        R = geometry.quaternion_to_rotation((rot.x, rot.y, rot.z, rot.w))
        p_base = R @ p + np.array([tr.x, tr.y, tr.z])
        if quaternion is None:
            return p_base, None
        return p_base, geometry.quaternion_from_rotation(
            R @ geometry.quaternion_to_rotation(quaternion))
