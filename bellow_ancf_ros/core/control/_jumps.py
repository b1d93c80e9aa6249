"""A target jump becomes a move the robot can follow without ringing: the minimum-jerk transition.

A step target (a planner's new goal, a teleoperator's click, the first
target after start: :meth:`JumpTransition.reset` with the pose the robot is
at) asks the pressures to jump; the robot answers through
its first mode and rings, and a closed loop that measures the error meanwhile
winds the transient into its correction (measured on the robot family: 3-9
mm of overshoot on a 10 mm step).  :class:`JumpTransition` replaces each jump
of the target stream by a minimum-jerk move (``s = 10 f^3 - 15 f^4 + 6 f^5``
of ``f = (t - t_jump) / T``) from where the output was to the new target,
over ``T = CYCLES / (MODE_SPREAD f_1)``: two periods of the slowest first
mode the robot may have (0.7 times the model's ``f_1``).  The residual swing
a minimum-jerk move of duration ``T`` leaves on an undamped mode of
frequency ``f`` is at most 4.1 % of the move for every ``f T >= 1.7`` (the
largest at ``f T = 2.22``; 12 % at 1.5, 46 % at 1), so the move leaves the
whole family (0.7-1.4x the model's mode: ``f T`` from 2 to 4) nearly at
rest, with no assumption on the damping (which only lowers it); unlike a
ZV/ZVD shaper, it does not need the mode within +-20 %.

A robot whose first mode was measured (``dynamics.first_mode_error`` of its
file: the model's mode over the measured one, minus one, within
:data:`KNOWN_MODE_ERROR`) gets a shorter move that leaves that mode at rest
whatever its damping: a minimum-jerk ramp of :data:`KNOWN_RAMP_CYCLES`
periods of the robot's mode ``f_r`` (the model's corrected by that error),
shaped by a ZV shaper at ``f_r`` and the model's damping ratio (two ramps,
the second half a damped period later: 1.5 periods in all).  Its residual
swing is zero at the mode and at most 3.9 % of the move for a mode 5 % off
(2.1 % at a damping ratio of 0.15); a plain minimum-jerk move leaves none
only on an undamped mode, at ``f T = 1.8346``, and 2-3.5 % on one damped at
0.05-0.25.  For the slowest robots of the family (first mode 1.5 Hz, two
periods of 0.7 times it: a 1.9 s move) it is what brings a 10 mm step
within 0.2 mm 1.5 s after it (measured on the family's two-segment robots:
1.85 -> 0.07 mm on the slowest; 0.212 -> 0.119 mm at the 95th percentile,
the overshoot 0.139 -> 0.094 mm).

A jump: a target more than :data:`JUMP_M` (or :data:`JUMP_RAD` of its
z-axis) from where the stream was heading, plus what the stream's own
acceleration allows over the time since its last target
(:func:`~._stream_heading.stream_heading`: the previous target plus the
previous step scaled to the time since it, by the targets' times; the
previous target itself after a jump or a stop): a stream that moves
smoothly passes unchanged and undelayed at any rate, with any jitter of its
times and through a busy computer's stall (a circle at 10x: 0.02 mm from
the extrapolation between 50 Hz targets, 0.5 mm between 10 Hz ones; a
target 25 ms later than the one before, on the two-segment circle at 10x,
is 2.1 mm from an extrapolation by one step); a stream that starts moving
at full speed gets a smooth start.  While a move runs, new
targets move its end (the move converges on the newest).  The closed loop
holds its correction until :meth:`JumpTransition.hold_until` (the move's end
plus :data:`SETTLE_S` for the regulators' lag and the motion capture's
latency): the move is the controller's own, not a mismatch to learn.
"""

from __future__ import annotations

import math

import numpy as np

from ._shaping import shaper_impulses
from ._stream_heading import STALL_S, stream_jumps

__all__ = ['CYCLES', 'JUMP_M', 'JUMP_RAD', 'JumpTransition', 'KNOWN_MODE_ERROR',
           'KNOWN_RAMP_CYCLES', 'MODE_SPREAD', 'SETTLE_S']

#: A target this far from where the stream was heading [m] is a jump.
JUMP_M = 0.002
#: The same for the z-axis [rad] (the chord between unit vectors).
JUMP_RAD = math.radians(2.0)
#: The stream's targets kept to read it by [s] (at least three; its timer's grid: six or more).
STREAM_KEEP_S = 0.6
#: The slowest first mode the robot may have, as a fraction of the model's.
MODE_SPREAD = 0.7
#: The move lasts this many periods of that slowest mode.
CYCLES = 2.0
#: A measured first mode (``dynamics.first_mode_error`` at most this far from 0) is known.
KNOWN_MODE_ERROR = 0.05
#: A known mode's move: a minimum-jerk ramp of this many of its periods, ZV-shaped at it.
KNOWN_RAMP_CYCLES = 1.0
#: The closed loop holds its correction this long after a move ends [s]: the family's slowest
#: regulators (lag 0.12 s, dead time 0.04 s) and motion capture (latency 0.02 s) catch up;
#: measured on robots of the family, 0.5 s overshot less than 0.2 s and recovered as fast.
SETTLE_S = 0.5


def _min_jerk(f: float) -> float:
    f = min(max(f, 0.0), 1.0)
    return f * f * f * (10.0 - 15.0 * f + 6.0 * f * f)


class JumpTransition:
    """Jumps of a target stream replaced by minimum-jerk moves (module docstring).

    :meth:`push` each target with the time it is wanted at; :meth:`at` gives
    the target to command at any time.  Until :meth:`set_mode` gives the first
    mode, targets pass unchanged.
    """

    def __init__(self, frequency_hz: float | None = None,
                 mode_error: float | None = None) -> None:
        self.duration_s = 0.0
        self.frequency_hz: float | None = None
        #: the model's first mode over the robot's measured one, minus one (None: unknown)
        self.mode_error = mode_error
        #: a move: a minimum-jerk ramp of ``_ramp_s`` at each impulse ``(time [s], amplitude)``
        self._ramp_s = 0.0
        self._impulses: tuple = ((0.0, 1.0),)
        if frequency_hz is not None:
            self.set_mode(frequency_hz)
        self.moves = 0
        self.reset()

    def set_mode(self, frequency_hz: float, damping_ratio: float = 0.0) -> None:
        """Moves for this first mode of the model (and its damping ratio) from now on.

        CYCLES periods of MODE_SPREAD times it; when :attr:`mode_error` says
        the robot's mode was measured, KNOWN_RAMP_CYCLES periods of the
        robot's mode shaped by a ZV shaper at it (module docstring).
        """
        f = float(frequency_hz)
        if not (math.isfinite(f) and f > 0):
            raise ValueError(f'a jump transition needs a frequency > 0, got {frequency_hz!r}')
        self.frequency_hz = f
        err = self.mode_error
        if err is not None and abs(err) <= KNOWN_MODE_ERROR:
            f_robot = f / (1.0 + err)
            zeta = float(damping_ratio)
            zeta = min(max(zeta, 0.0), 0.9) if math.isfinite(zeta) else 0.0   # (0.9: < 1)
            times, amps = shaper_impulses('zv', f_robot, zeta)
            self._ramp_s = KNOWN_RAMP_CYCLES / f_robot
            self._impulses = tuple(zip(times.tolist(), amps.tolist()))
        else:
            self._ramp_s = CYCLES / (MODE_SPREAD * f)
            self._impulses = ((0.0, 1.0),)
        self.duration_s = self._ramp_s + self._impulses[-1][0]

    def reset(self, start=None) -> None:
        """Forget the stream.

        ``start``: ``(position, z_axis or None)``, where the robot is (the
        pose of its current command, e.g. vented): the next target is a jump
        from it when far enough; None: the next target is taken as it is.
        """
        self._newest: tuple | None = None   # (t, position, z-axis)
        if start is not None:
            z0 = None if start[1] is None else np.asarray(start[1], dtype=float).reshape(3)
            self._newest = (-math.inf, np.asarray(start[0], dtype=float).reshape(3), z0)
        self._stream: list = []   # its newest targets since a jump (stream_heading's)
        self._move: tuple | None = None     # (t0, duration, start position, start z-axis)

    def push(self, t: float, position, z_axis=None) -> None:
        """A new target wanted from time ``t`` on (times must not decrease)."""
        p = np.asarray(position, dtype=float).reshape(3)
        z = None if z_axis is None else np.asarray(z_axis, dtype=float).reshape(3)
        old = self._newest
        if old is not None:
            # where the stream was heading (its last step scaled to the time since the last
            # target: a late target of a smooth stream, a busy computer's stall, is no jump)
            jump = stream_jumps(self._stream or [old], float(t), p, z, JUMP_M, JUMP_RAD)
            if jump and self.duration_s > 0:
                start_p, start_z = self.at(float(t))
                self._move = (float(t), self.duration_s, start_p, start_z, self._ramp_s,
                              self._impulses)
                self.moves += 1
            # the stream's steps (none across a jump, a stop or from the start: not its speed)
            if jump or not float(t) - old[0] <= STALL_S:
                self._stream = []
        self._stream.append((float(t), p, z))
        while len(self._stream) > 3 and self._stream[0][0] < float(t) - STREAM_KEEP_S:
            self._stream.pop(0)
        self._newest = (float(t), p, z)

    @property
    def move(self):
        """The newest move: ``(start time, start position, goal position, goal z-axis or None)``.

        None before the first jump.  The goal is the newest target (a move's
        end follows the targets that come during it).
        """
        if self._move is None:
            return None
        return self._move[0], self._move[2], self._newest[1], self._newest[2]

    def busy(self, t: float) -> bool:
        """True while a move runs at time ``t``."""
        return self._move is not None and t < self._move[0] + self._move[1]

    @property
    def hold_until(self) -> float:
        """Until when a closed loop should hold its correction [s] (-inf: no move yet)."""
        if self._move is None:
            return -math.inf
        return self._move[0] + self._move[1] + SETTLE_S

    def at(self, t: float):
        """The target to command at time ``t``: ``(position, z_axis or None)``."""
        if self._newest is None:
            raise ValueError('no target pushed yet')
        _, p, z = self._newest
        if self._move is None or t >= self._move[0] + self._move[1]:   # (the target exactly)
            return p.copy(), None if z is None else z.copy()
        t0, _, p0, z0, ramp, impulses = self._move
        s = sum(a * _min_jerk((t - t0 - ti) / ramp) for ti, a in impulses)
        out_p = p0 + s * (p - p0)
        if z is None or z0 is None:
            return out_p, None if z is None else z.copy()
        zz = z0 + s * (z - z0)
        return out_p, zz / np.linalg.norm(zz)
