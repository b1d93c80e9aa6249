"""A target stream made for a robot with a mode: input shaping and dynamic feedforward together.

What the inverse node does to each target before its (optional) closed-loop
correction and the static inverse (eq. 28):

* ``shaping``: ``smooth`` (the inverse node's default,
  :class:`~._jumps.JumpTransition`): a jump of the target stream becomes a
  minimum-jerk move over two periods of the slowest mode the robot may have,
  a smooth stream passes unchanged; ``zv``, ``zvd``
  (:class:`~._shaping.TargetShaper`): a step target is replaced by the
  shaper's staircase, so that it leaves no residual swing at the first mode
  (known to +-20 %), and a stream is delayed by the shaper; ``none``.  The
  output moves for a while after a new target, so the caller re-solves
  while :meth:`TargetFilter.busy`, and a closed loop holds its correction
  until :attr:`TargetFilter.hold_until`;
* ``dynamic_feedforward`` (:class:`~._dynamic_feedforward.StreamFeedforward`):
  a moving target is shifted by the inertial and damping loads of its motion
  through the first mode, and by the regulators' lag (``lag_s``); a step is
  passed as it is.

Both follow :meth:`TargetFilter.set_mode` (the first mode at the held
equilibrium; until the first mode is known the targets pass unchanged).
Targets carry the time they are wanted at; the output is for time
``max(now, newest wanted time)``: a previewed stream is shaped at its newest
target's time, a held target as time goes on.
"""

from __future__ import annotations

import numpy as np

from ._dynamic_feedforward import StreamFeedforward
from ._jumps import JumpTransition
from ._shaping import SHAPERS, TargetShaper

__all__ = ['TARGET_SHAPINGS', 'TargetFilter']

#: Values of the inverse node's ``target_shaping``.
TARGET_SHAPINGS = ('smooth',) + SHAPERS


class TargetFilter:
    """Input shaping and dynamic feedforward of one target stream (module docstring)."""

    def __init__(self, shaping: str = 'none', dynamic_feedforward: bool = False,
                 lag_s: float = 0.0, mode_error: float | None = None) -> None:
        """``mode_error``: the robot file's ``dynamics.first_mode_error`` (the jumps' moves)."""
        if shaping not in TARGET_SHAPINGS:
            raise ValueError(f'target_shaping = {shaping!r} is not allowed; allowed: '
                             f'{list(TARGET_SHAPINGS)}')
        self.shaping = shaping
        self.shaper = None if shaping in ('none', 'smooth') else TargetShaper(shaping)
        self.jumps = JumpTransition(mode_error=mode_error) if shaping == 'smooth' else None
        self.feedforward = (StreamFeedforward(1.0, 0.0, lag_s=lag_s)
                            if dynamic_feedforward else None)
        self.mode: tuple[float, float] | None = None
        self._newest: tuple | None = None
        self._arrived = True   # the shaped target reached the newest target (was solved for)

    @classmethod
    def of(cls, jumps: JumpTransition | None = None,
           feedforward: StreamFeedforward | None = None) -> 'TargetFilter':
        """A filter made of these parts (``smooth`` when given ``jumps``, else ``none``).

        Its mode is theirs (the feedforward's, else the jumps' if they have
        one) until :meth:`set_mode`.
        """
        filt = cls('smooth' if jumps is not None else 'none')
        filt.jumps, filt.feedforward = jumps, feedforward
        if feedforward is not None:
            filt.mode = (feedforward.ff.frequency_hz, feedforward.ff.damping_ratio)
        elif jumps is not None and jumps.frequency_hz is not None:
            filt.mode = (jumps.frequency_hz, 0.0)
        return filt

    @property
    def enabled(self) -> bool:
        """True when shaping (smooth jumps included) or dynamic feedforward is on."""
        return (self.shaper is not None or self.jumps is not None
                or self.feedforward is not None)

    def set_mode(self, frequency_hz: float, damping_ratio: float) -> None:
        """Shape and shift for this first mode from now on."""
        if self.shaper is not None:
            self.shaper.set_mode(frequency_hz, damping_ratio)
        if self.jumps is not None:
            self.jumps.set_mode(frequency_hz, damping_ratio)
        if self.feedforward is not None:
            self.feedforward.set_mode(frequency_hz, damping_ratio)
        self.mode = (float(frequency_hz), float(damping_ratio))

    @property
    def delay_s(self) -> float:
        """The shaper's added delay (the centroid of its impulses) [s]; 0 without one."""
        return 0.0 if self.shaper is None or self.mode is None else self.shaper.delay_s

    @property
    def hold_until(self) -> float | None:
        """Until when a closed loop holds its correction (a jump's move, a stopped stream's brake).

        In seconds; None: never.
        """
        ends = [h for h in (None if self.jumps is None else self.jumps.hold_until,
                            None if self.feedforward is None else self.feedforward.hold_until())
                if h is not None]
        return max(ends) if ends else None

    @property
    def move(self):
        """The newest jump's move, as :attr:`JumpTransition.move` gives it (or None)."""
        return None if self.jumps is None else self.jumps.move

    def reset(self, start=None) -> None:
        """Forget the stream (the next target is taken as it is).

        ``start``: ``(position, z_axis or None)``, the pose the robot is at
        (``smooth``: the next target is a jump from it when far enough).
        """
        if self.shaper is not None:
            self.shaper.reset()
        if self.jumps is not None:
            self.jumps.reset(start)
        if self.feedforward is not None:
            self.feedforward.reset()
        self._newest = None

    def push(self, t: float, position, z_axis=None, at: float | None = None) -> None:
        """A new target, wanted at time ``t`` (an earlier time starts the stream again).

        ``at``: when it was taken in (a node's solve of it; default ``t``):
        the feedforward's stream stops only its stale time after the later.
        """
        p = np.asarray(position, float).reshape(3)
        z = None if z_axis is None else np.asarray(z_axis, float).reshape(3)
        if self._newest is not None and t < self._newest[0]:
            # a stream that goes back in time starts again, from where it stands: a
            # jump from there is still a move (never a step of the commands)
            start = self._standing()
            self.reset(start)
            if self.shaper is not None:
                self.shaper.push(t, *start)
        if self.shaper is not None:   # (the first target is taken as it is: a stream's start)
            self.shaper.push(t, p, z)
        if self.jumps is not None:
            self.jumps.push(t, p, z)
        if self.feedforward is not None:
            self.feedforward.push(t, p, z, at=at)
        self._newest = (float(t), p, z)
        self._arrived = False

    def _standing(self):
        """Where the shaped target stands at the newest target's time: ``(position, z_axis)``."""
        t_new, p, z = self._newest
        if self.shaper is not None:
            return self.shaper.at(t_new)
        if self.jumps is not None:
            return self.jumps.at(t_new)
        return p, z

    def stream_tick(self) -> tuple | None:
        """The feedforward's :meth:`StreamFeedforward.stream_tick` (None without it)."""
        return None if self.feedforward is None else self.feedforward.stream_tick()

    def busy(self, now: float) -> bool:
        """True until the output stops moving: past the shaper's last impulse, a move's end.

        Or a stopped stream's brake (the feedforward's).
        """
        if self.mode is None:
            return False
        if self.feedforward is not None and self.feedforward.busy(now):
            return True
        if self.jumps is not None:   # (until a target at the move's end was given out)
            return not self._arrived
        return self.shaper is not None and not self._arrived

    def target(self, now: float):
        """The target to command now: ``(position, z_axis or None)`` (shaped and shifted)."""
        return self.targets(now)[0]

    def targets(self, now: float):
        """``(command, reference)``: the target to command now, and the pose wanted now.

        The reference is the shaped target without the feedforward's shift: a
        closed loop compares the measured pose with it and corrects the command.
        """
        if self._newest is None:
            raise ValueError('no target pushed yet')
        t_new, p, z = self._newest
        if self.mode is None:
            return (p, z), (p, z)
        ref_p, ref_z = p, z
        if self.shaper is not None:
            t = max(now, t_new)
            ref_p, ref_z = self.shaper.at(t)
            self._arrived = t >= t_new + self.shaper.duration_s
        elif self.jumps is not None:
            t = max(now, t_new)
            ref_p, ref_z = self.jumps.at(t)
            self._arrived = not self.jumps.busy(t)
        out_p, out_z = ref_p, ref_z
        if self.feedforward is not None:   # (a stopped stream brakes: the pose wanted moves)
            bp, bz = self.feedforward.reference(now)
            fp, fz = self.feedforward.target(now)
            ref_p, ref_z = ref_p + (bp - p), _turned(ref_z, bz, z)
            out_p, out_z = ref_p + (fp - bp), _turned(ref_z, fz, bz)
        return (out_p, out_z), (ref_p, ref_z)


def _turned(z, to, frm):
    """``z`` turned as ``frm`` turned to ``to`` (to first order; unit; None stays None)."""
    if z is None or to is None or frm is None:
        return z
    zz = z + (to - frm)
    return zz / np.linalg.norm(zz)
