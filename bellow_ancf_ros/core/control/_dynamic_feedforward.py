"""Dynamic feedforward: the target shifted by its first mode's inertia and damping.

The quasi-static inverse (eq. 28) gives the pressures that hold the robot
at the target at rest.  Moving, the robot lags its quasi-static pose through
its first lateral mode (docs/dynamics.md): near that mode the end effector
answers its quasi-static pose ``y_s`` like

    y'' / w^2 + 2 zeta y' / w + y = y_s,

with ``w = 2 pi f`` the undamped first mode and ``zeta`` its damping ratio
at the held equilibrium (:func:`~bellow_ancf_ros.core.dynamics.natural_modes`).
Inverting it, the robot follows a planned path ``x(t)`` when the static
inverse is asked for

    x_ff = x + (2 zeta / w) x' + x'' / w^2,

the target plus the generalized inertial and damping loads of the motion
expressed as the static offset they cause through the mode (first-order
inverse dynamics, in task space).  The same holds for the end effector's
z-axis (two or more segments: the first mode moves the tip's position and
its axis together).  This is exact for a robot whose motion along the path
is carried by its first mode, and it leaves the higher modes (four to five
times higher, twice as damped) alone; it costs one static solve per target,
as the quasi-static feedforward does.

:func:`dynamic_path` shifts a known path (a function of time: the
derivatives by central differences).  :class:`StreamFeedforward` shifts a
stream of stamped targets (a planner's stream, a trajectory publisher's
preview): the derivatives at the newest target by polynomials fitted to the
targets before it; a jump (a step target) is passed unshifted, since its
derivatives are not a motion the robot can follow (input shaping is the
remedy for steps).  Every shift is clipped to ``max_shift_m`` (and
``max_shift_rad``).

A stream's stamps need not be its poses' times: a planner that stamps a
pose when it sends it, 0.2 ms after it computed it for its own clock (a
lab-style trial's planner, 50 Hz, quiet computer; 2.8 ms at the 99th
percentile with two CPU-bound processes beside it), puts each target off
its path by the speed times that difference.  The second and third
derivatives of a cubic over 0.1 s (five targets, :data:`FITS`) multiply
that into the shift: on the two-segment bending circle at 10x, 0.2 ms RMS
of stamp jitter moved the shift by 3.9 mm from one target to the next (99th
percentile), 1 ms by 15 mm, and the commands by 10-60 kPa.  A stream whose
targets lie more than :data:`NOISE_M` off that cubic is therefore read with
longer fits (:data:`NOISY_FITS`, for :data:`NOISY_HOLD_S` after the last
such target): the same jitter then moves the shift by 0.4 and 0.8 mm (the
circle alone turns it by 0.4 mm per target), at a cost of 0.27 mm of the
shift on that circle and up to 1 mm while a path speeds up
(``test_stream_shift_survives_jittered_stamps``).  A stream whose stamps
are its poses' times keeps the short fit (0.05 mm on that circle): the
long one, on every stream, made two-segment robots of the family ring at
the end of the circle's spin-up (watchdog trips in 3 of 40 more).
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from typing import Callable

import numpy as np

from ._stream_heading import STALL_S, off_cubic, stream_jumps, stream_times

__all__ = ['DynamicFeedforward', 'StreamFeedforward', 'dynamic_path']

#: Largest shift of the target [m] and of its z-axis [rad] the feedforward applies.
MAX_SHIFT_M = 0.01
MAX_SHIFT_RAD = math.radians(10.0)
#: A stopped stream slower than this over its brake time is not braked [m], [rad].
_STILL_M, _STILL_RAD = 1.0e-5, 1.0e-4
#: The most a target is carried on to the time it is commanded at [s] (a pose that old is a
#: stall, and the stream brakes after its stale time).
MAX_LEAD_S = 0.1
#: Intakes whose age (taken in after the pose's own time) give the usual one (their median).
AGES_KEPT = 25
#: ``(window [s], polynomial degree)`` of the fits that give the velocity, the acceleration
#: and the jerk at the newest target (module docstring); fewer targets than ``degree + 2`` in
#: a window: the degree they allow, at least 2 (three targets).  ``FITS``: a stream whose
#: targets lie on a smooth path by their stamps; ``NOISY_FITS``: one whose do not.
FITS = ((0.1, 3),) * 3
NOISY_FITS = ((0.3, 3), (0.4, 3), (0.6, 4))
#: A stream whose targets leave more than this [m] RMS off the cubic of its last
#: ``FITS`` window is read with ``NOISY_FITS`` for :data:`NOISY_HOLD_S` [s] from then on.
NOISE_M = 2.0e-6
NOISY_HOLD_S = 2.0
#: A target this close to the newest one [m], [rad] repeats it: the stream stands still.
_REPEAT_M, _REPEAT_RAD = 1.0e-9, 1.0e-9


class DynamicFeedforward:
    """The shift ``c1 v + c2 a + c3 j`` of a target moving at ``v, a, j`` (module docstring).

    ``lag_s``: the regulators' time constant ``tau``; with it the shift
    inverts ``(1 + tau s)(1 + 2 zeta s / w + s^2 / w^2)``:
    ``c1 = tau + 2 zeta / w``, ``c2 = 2 zeta tau / w + 1 / w^2``,
    ``c3 = tau / w^2``; the dead time stays with the preview.
    """

    def __init__(self, frequency_hz: float, damping_ratio: float, lag_s: float = 0.0,
                 max_shift_m: float = MAX_SHIFT_M, max_shift_rad: float = MAX_SHIFT_RAD) -> None:
        self.max_shift_m, self.max_shift_rad = float(max_shift_m), float(max_shift_rad)
        if not (math.isfinite(lag_s) and lag_s >= 0):
            raise ValueError(f'lag_s = {lag_s!r} is not allowed; allowed: a time >= 0 [s]')
        self.lag_s = float(lag_s)
        self.set_mode(frequency_hz, damping_ratio)

    def set_mode(self, frequency_hz: float, damping_ratio: float) -> None:
        """Shift for this mode from now on (a payload moves it)."""
        f, z = float(frequency_hz), float(damping_ratio)
        if not (math.isfinite(f) and f > 0 and math.isfinite(z) and z >= 0):
            raise ValueError(f'a mode needs a frequency > 0 and a damping ratio >= 0, '
                             f'got ({f}, {z})')
        w = 2 * math.pi * f
        tau = self.lag_s
        self.frequency_hz, self.damping_ratio = f, z
        self.c1 = tau + 2 * z / w
        self.c2 = 2 * z * tau / w + 1 / (w * w)
        self.c3 = tau / (w * w)

    def shift(self, velocity, acceleration, jerk=None, max_shift: float | None = None
              ) -> np.ndarray:
        """``c1 v + c2 a + c3 j``, clipped in length to ``max_shift`` (default ``max_shift_m``)."""
        s = self.c1 * np.asarray(velocity, float) + self.c2 * np.asarray(acceleration, float)
        if jerk is not None:
            s = s + self.c3 * np.asarray(jerk, float)
        cap = self.max_shift_m if max_shift is None else max_shift
        n = float(np.linalg.norm(s))
        return s * (cap / n) if n > cap else s

    def shifted(self, position, derivatives, z_axis=None, z_derivatives=None):
        """The shifted target ``(position, z_axis or None)``.

        ``derivatives``: ``(velocity, acceleration[, jerk])`` of the position,
        ``z_derivatives`` those of the z-axis.
        """
        p = np.asarray(position, float) + self.shift(*derivatives)
        if z_axis is None:
            return p, None
        z = np.asarray(z_axis, float)
        dz = self.shift(*z_derivatives, max_shift=self.max_shift_rad)
        dz = dz - (dz @ z) * z     # a turn of the axis (by atan|dz| <= the clip), no stretch
        zn = z + dz
        return p, zn / np.linalg.norm(zn)


def dynamic_path(path: Callable[[float], tuple], frequency_hz: float, damping_ratio: float,
                 step_s: float = 0.005, **kw) -> Callable[[float], tuple]:
    """A path ``t -> (position, z_axis or None)`` shifted for its first mode.

    Derivatives by central differences with ``step_s`` (the path must be
    smooth on that scale); ``kw``: :class:`DynamicFeedforward` clips.
    """
    ff = DynamicFeedforward(frequency_hz, damping_ratio, **kw)
    h = float(step_s)

    def derivatives(x):   # central differences on five points: v, a, j
        return ((x[3] - x[1]) / (2 * h), (x[3] - 2 * x[2] + x[1]) / (h * h),
                (x[4] - 2 * x[3] + 2 * x[1] - x[0]) / (2 * h ** 3))

    def f(t):
        vals = [path(t + k * h) for k in (-2, -1, 0, 1, 2)]
        ps = np.array([np.asarray(v[0], float) for v in vals])
        if vals[2][1] is None:
            return ff.shifted(ps[2], derivatives(ps))
        zs = np.array([np.asarray(v[1], float) for v in vals])
        return ff.shifted(ps[2], derivatives(ps), zs[2], derivatives(zs))
    f.feedforward = ff
    return f


def _brake_bases() -> np.ndarray:
    """Quintic bases of a stop: ``g_k^(m)(0) = delta_km`` (k, m = 1, 2), all else zero at 0 and 1.

    Rows: coefficients (lowest power first) of ``g_1, g_2``: the path
    ``v T g_1 + a T^2 g_2`` leaves with the stream's velocity and
    acceleration and is back at rest at its start after ``T``.  (Matching
    the jerk too, a septic, rang more on the robot family.)
    """
    rows = []
    for k in (1, 2):
        A, b = np.zeros((6, 6)), np.zeros(6)
        for m in range(3):
            for n in range(6):      # d^m/dtau^m of tau^n at 0 and at 1
                A[m, n] = math.factorial(n) if n == m else 0.0
                A[3 + m, n] = (math.factorial(n) / math.factorial(n - m)) if n >= m else 0.0
        b[k] = 1.0
        rows.append(np.linalg.solve(A, b))
    return np.array(rows)


_BRAKE = [np.array([np.polynomial.polynomial.polyder(c, m) if m else c for c in _brake_bases()])
          for m in range(4)]


def _brake(tau: float) -> np.ndarray:
    """``(2 bases, value and 3 derivatives in tau)`` of the stop at ``tau`` (zero from 1 on)."""
    t = max(float(tau), 0.0)
    if t >= 1.0:
        return np.zeros((2, 4))
    return np.array([[np.polynomial.polynomial.polyval(t, c) for c in d] for d in _BRAKE]).T


def _ahead(x, d, lead: float):
    """``x`` and its derivative rows ``d`` (v, a[, j]) ``lead`` seconds on (Taylor series)."""
    if lead <= 0.0:
        return x, d
    x = x + sum(row * lead ** (n + 1) / math.factorial(n + 1) for n, row in enumerate(d))
    d = np.array([sum(d[m] * lead ** (m - n) / math.factorial(m - n) for m in range(n, len(d)))
                  for n in range(len(d))])
    return x, d


class StreamFeedforward:
    """:class:`DynamicFeedforward` on a stream of stamped targets.

    :meth:`push` each target with the time it is wanted at; :meth:`target`
    gives the newest one shifted by the derivatives of polynomials fitted to
    the targets before it (:data:`FITS`; at least three targets), and
    carried on by them to the time it is commanded at, less the usual age
    of the stream's targets when taken in (the median of the last
    :data:`AGES_KEPT`; at most :data:`MAX_LEAD_S`): a pose solved later
    than usual (a node kept waiting by a busy computer, a planner's late
    send) would leave the command behind the path by the extra age times
    its speed, a jitter that rings the robot's mode.  A constant age (a
    planner whose clock is behind the node's, the usual transport and
    queue) is not carried: it costs little, and a clock's offset is no age.  A target
    farther than ``jump_m`` from where the stream was heading (a step), a
    stop (:meth:`_jump`), or too few samples: the newest target unshifted.

    **A stream that stops** while it was moving, either by no target for
    ``stale_periods`` of its own intervals (at least ``min_stale_s``) or by
    repeating its newest target (a planner that holds the path's last pose
    and keeps publishing it): the robot, led by the shift, is moving at the
    stream's speed.  Holding the shifted target would drive it on by the
    shift and leave its mode ringing; dropping the shift, a velocity step,
    rings it too; and fitting the repeated targets reads the stop as an
    acceleration of metres per second squared (a lab-style trial: the shift
    flipped between +10 and -10 mm from one 20 ms target to the next, the
    commands by 40-90 kPa).  Instead the wanted pose (the *reference*,
    :meth:`reference`) continues from the last moving target along a
    quintic that starts with the stream's velocity and acceleration and
    comes back to rest at that target after one brake time
    (``brake_periods`` of the mode, at least ``4 lag_s``), shifted as any
    path: the robot follows it and comes to rest at the last target, no
    shift left in the command (:meth:`busy` while braking; the closed loop
    holds its integral then).  Repeated targets are not fitted: when the
    stream moves again, its fit starts at the pose it stood at.  An abrupt
    stop at speed still swings the robot at its mode.
    """

    def __init__(self, frequency_hz: float, damping_ratio: float, min_stale_s: float = 0.025,
                 jump_m: float = 0.005, stale_periods: float = 2.5, brake_periods: float = 1.0,
                 **kw) -> None:
        self.ff = DynamicFeedforward(frequency_hz, damping_ratio, **kw)
        self.min_stale_s, self.jump_m = float(min_stale_s), float(jump_m)
        self.stale_periods, self.brake_periods = float(stale_periods), float(brake_periods)
        self._keep_s = max(w for w, _ in FITS + NOISY_FITS)
        self._hist: deque = deque()
        self._brake = None   # the stop of the stream, once seen: (t1, T, p1, dp, z1, dz)
        self._held_to = None   # the hold's end of a brake the stream cut short by moving on
        self._anchor = 0.0     # the newest target's stamp, or when it was pushed if later
        self._t_pose = 0.0     # the newest pose's own time (its tick, read by the grid)
        self._ages: deque = deque(maxlen=AGES_KEPT)   # intake times after the poses' own
        self._repeated = False   # the newest targets repeat the one before them
        self._repeat_t = 0.0     # the newest repeat's time
        self._noisy_until = -math.inf   # read with NOISY_FITS until then
        self._on_grid = False    # the fits read the targets' times from their stamps' grid
        self._times = self._positions = np.zeros(0)   # the fits' (:meth:`_read_times`)
        self._trusted = np.zeros(0, dtype=bool)
        self._read = None   # (newest sample, times, trusted) by stream_times, as last read
        self._late_s = 0.0  # the latest send after its tick in the stream's window [s]

    def set_mode(self, frequency_hz: float, damping_ratio: float) -> None:
        """Shift for this mode from now on."""
        self.ff.set_mode(frequency_hz, damping_ratio)

    def reset(self) -> None:
        """Forget the stream (the next target starts unshifted)."""
        self._hist.clear()
        self._brake = None
        self._held_to = None
        self._ages.clear()
        self._repeated = False
        self._noisy_until = -math.inf
        self._on_grid = False
        self._read = None
        self._late_s = 0.0

    def push(self, t: float, position, z_axis=None, at: float | None = None) -> None:
        """A target wanted at time ``t`` (a time that goes back starts the stream again).

        ``at``: when it was taken in, on the same clock (default ``t``): a
        stream counts as stopped :meth:`stale_s` after the later of the two,
        so a node that solves a target late (a busy computer) does not brake
        a stream that goes on.
        """
        p = np.asarray(position, float).reshape(3)
        z = None if z_axis is None else np.asarray(z_axis, float).reshape(3)
        h = self._hist
        if h and t > h[-1][0] and float(np.linalg.norm(p - h[-1][1])) <= _REPEAT_M and (
                z is None or h[-1][2] is None
                or float(np.linalg.norm(z - h[-1][2])) <= _REPEAT_RAD):
            self._repeated, self._repeat_t = True, float(t)   # standing still: not fitted
            return
        if self._repeated:   # moving again: from the pose it stood at, when it last said so
            stood = (self._repeat_t, h[-1][1], h[-1][2])
            h.clear()
            h.append(stood)
        if h and (t <= h[-1][0] or self._jump(t, p)):
            h.clear()
        h.append((float(t), p, z))
        while len(h) > 3 and h[0][0] < t - self._keep_s:
            h.popleft()
        anchor = float(t) if at is None else max(float(t), float(at))
        if self._brake is not None:   # the stream moves on: the hold ends as long after it
            t1, T = self._brake[0], self._brake[1]   # as the brake had run (the robot's answer)
            self._held_to = min(t1 + T, 2.0 * anchor - self._anchor - self.stale_s())
        self._anchor = anchor
        self._brake = None
        self._repeated = False
        self._read_times(t)
        if at is not None:
            self._ages.append(float(at) - self._t_pose)

    def _jump(self, t: float, p) -> bool:
        """Whether a target starts the stream again: a jump (a step), a stop, a late start.

        A jump: farther than ``jump_m`` from where the stream was heading
        (:func:`~._stream_heading.stream_jumps`, which allows for the
        stream's acceleration over a stall); a stop: no target for
        :data:`~._stream_heading.STALL_S`.
        """
        h = self._hist
        if t - h[-1][0] > STALL_S:
            return True
        read = self._read if self._read is not None and self._read[0] is h[-1] else None
        return stream_jumps(list(h), t, p, jump_m=self.jump_m,
                            read=None if read is None else read[1:])

    def _read_times(self, t: float) -> None:
        """Read the stream by its stamps or by their grid (:func:`~._stream_heading.stream_times`).

        Called with each new target (at ``t``): the grid is the fits' time
        from now on if the targets lie within :data:`NOISE_M` of a cubic by
        it and closer than by their stamps; else the stamps, and a stream off
        its cubic by more than :data:`NOISE_M` by them is read with
        :data:`NOISY_FITS` (for :data:`NOISY_HOLD_S`).
        """
        h = self._hist
        self._positions = np.array([s[1] for s in h])
        stamps = np.array([s[0] for s in h])
        times, trusted, on_grid, off = stream_times(stamps, self._positions)
        self._read = (h[-1], times, trusted)   # (the next target's jump test reads it so)
        self._on_grid = on_grid and off <= NOISE_M
        if on_grid and not self._on_grid:   # (a grid, but not a smooth path by it either)
            times, off = stamps, off_cubic(stamps, self._positions)
            trusted = np.ones(len(stamps), dtype=bool)
        self._t_pose = float(times[-1])
        self._times = times - times[-1]   # (about the newest target's time: its shift's)
        # how late its sends have come after their ticks (by the grid; exact stamps: none)
        self._late_s = max(float(np.max(stamps - times)), 0.0) if self._on_grid else 0.0
        self._trusted = trusted           # (the fits': by the grid, a late send's tick is a guess)
        if not self._on_grid and off > NOISE_M:
            self._noisy_until = float(t) + NOISY_HOLD_S

    @property
    def brake_s(self) -> float:
        """How long a stopped stream's brake takes [s]."""
        return max(self.brake_periods / self.ff.frequency_hz, 4.0 * self.ff.lag_s)

    def stale_s(self) -> float:
        """How long after its newest target the stream counts as stopped [s].

        ``stale_periods`` of its median interval (at least ``min_stale_s``),
        plus the latest a send of the stream read by its timer's grid came
        after its tick in the fits' window (a late send is no stop: braking
        for it, the command left the path and the closed loop held its
        correction for the brake's time), plus how much later than usual
        the node took its targets in lately (:meth:`_held_up_s`).
        """
        gap = self._interval()
        if gap is None:   # (no speed yet: nothing to brake)
            return self.min_stale_s
        return max(self.stale_periods * gap, self.min_stale_s) + self._late_s + self._held_up_s()

    def _held_up_s(self) -> float:
        """How much later than usual the stream's targets were taken in, lately [s].

        The largest age at intake of the last :data:`AGES_KEPT` over their
        median, at most :data:`MAX_LEAD_S`: a computer that kept the node
        from its targets that long lately will again, and a target sent on
        time that the node has not taken in yet is no stop (braked, the
        command left the path and came back to it when the target was
        taken: a kick to the robot's mode, up to four of them in one
        circle on a busy computer).
        """
        ages = self._ages
        if len(ages) < 2:
            return 0.0
        return min(max(ages) - statistics.median(ages), MAX_LEAD_S)

    def _interval(self) -> float | None:
        """The median interval of the targets kept [s] (None: fewer than two)."""
        t = [s[0] for s in self._hist]
        if len(t) < 2:
            return None
        return statistics.median(b - a for a, b in zip(t, t[1:]))   # (numpy's: 10x the time)

    def _fit(self):
        """The derivatives at the newest target, ``(dp, dz or None)``: rows v, a[, j].

        Each from its own polynomial fit (:data:`FITS`, or :data:`NOISY_FITS`
        for a noisy stream); the jerk only with the regulators' lag
        (``c3 > 0``) and enough targets for a cubic.
        """
        h = self._hist
        if len(h) < 3:
            return None
        fits = NOISY_FITS if h[-1][0] <= self._noisy_until and not self._on_grid else FITS
        ok = self._trusted
        t, P = self._times[ok], self._positions[ok]
        if len(t) < 3:
            return None
        Z = None if h[-1][2] is None else np.array([s[2] for s in h])[ok]
        PZ = P if Z is None else np.hstack([P, Z])   # (one fit for both)
        rows_p, rows_z = [], []
        solved: dict = {}   # (first sample, degree) -> coefficients (FITS: one fit for all)
        for order, (window, degree) in enumerate(fits, start=1):
            sel = t >= min(-window, t[-3])   # (at least the last three)
            deg = min(degree, int(sel.sum()) - 2) if sel.sum() > 3 else 2
            if order > deg or (order == 3 and self.ff.c3 <= 0):
                break
            key = (int(np.argmax(sel)), deg)
            if key not in solved:
                tt = t[sel]
                V = np.column_stack([tt ** n / math.factorial(n) for n in range(deg + 1)])
                solved[key] = np.linalg.lstsq(V, PZ[sel], rcond=None)[0]
            rows_p.append(solved[key][order, :3])
            if Z is not None:
                rows_z.append(solved[key][order, 3:])
        return np.array(rows_p), (None if Z is None else np.array(rows_z))

    def _braking(self, now: float | None):
        """The brake of a stream stopped by ``now`` (None: not stopped, or not moving).

        Stopped: repeating its newest target, or none for :meth:`stale_s`.
        """
        h = self._hist
        if not h or (not self._repeated
                     and (now is None or now <= self._anchor + self.stale_s())):
            return None
        if self._brake is None:
            fit = self._fit()
            if fit is None:
                return None
            t1, p1, z1 = h[-1]
            dp, dz = fit
            T = self.brake_s

            def reach(d):
                return 0.0 if d is None else float(np.linalg.norm(d[0]) * T
                                                   + np.linalg.norm(d[1]) * T * T)
            if reach(dp) < _STILL_M and reach(dz) < _STILL_RAD:
                return None   # a held target repeated, then not: nothing to brake
            self._brake = (t1, T, p1, dp, z1, dz)
        return self._brake

    def _along(self, brake, now: float):
        """Pose and derivative rows ``(v, a, j)`` on the brake at ``now``."""
        t1, T, p1, dp, z1, dz = brake
        k, m = np.arange(1, 3)[:, None], np.arange(4)[None, :]
        W = _brake((now - t1) / T) * T ** (k - m)   # d^m/dt^m of T^k g_k(tau) [k rows]

        def on(x, d):   # d: rows v, a[, j] at the stream's end
            moved = W.T @ d[:2]                      # rows: offset, v, a, j
            return x + moved[0], moved[1:]
        p, vp = on(p1, dp)
        if z1 is None:
            return p, vp, None, None
        z, vz = on(z1, dz)
        return p, vp, z / np.linalg.norm(z), vz

    def reference(self, now: float | None = None):
        """The pose wanted at ``now``: the newest target, or the brake of a stopped stream."""
        h = self._hist
        if not h:
            raise ValueError('no target pushed yet')
        if now is None and self._repeated:   # (the stream says it stands still then)
            now = self._repeat_t
        brake = self._braking(now)
        if brake is None:
            return h[-1][1], h[-1][2]
        p, _, z, _ = self._along(brake, now)
        return p, z

    def busy(self, now: float) -> bool:
        """True while a stopped stream brakes (until one target after its end was given out)."""
        brake = self._braking(now)
        return brake is not None and now <= brake[0] + 1.5 * brake[1]

    def hold_until(self):
        """The end of a brake under way (the closed loop holds its integral until then).

        A brake the stream cut short by a target that moves on (a late send
        or a stall, not a stop) ends the hold as long after that target as
        the brake had run (the robot's answer to the commands that left the
        path), or at the brake's end if sooner.  Held for the whole brake
        time (a mode's period: 0.42 s on the two-segment robot), a lab's
        planner late by 3-40 ms once in 33 sends held the correction for
        0-39 % of the 10x circle's solves and tracked it to 0.88-1.53 mm
        RMSE (simulated, with the node's re-solves while braking); now
        0-7 % and 0.72-1.33 mm.  Stalls of 60-200 ms: as before.
        """
        if self._brake is not None:
            return self._brake[0] + self._brake[1]
        return self._held_to

    def stream_tick(self) -> tuple | None:
        """The newest target's pose time and the stream's median interval [s], or None.

        The pose's time is its tick on the stream's grid (else its stamp):
        what a :class:`~._pacing.CommandPacer` times the command by.  None
        while the stream stands still or brakes, or before its second target.
        """
        gap = self._interval()
        if self._repeated or self._brake is not None or gap is None:
            return None
        return self._t_pose, gap

    def target(self, now: float | None = None):
        """The wanted pose shifted for the mode: ``(position, z_axis or None)``.

        ``now``: the time it is commanded at (None: the newest target's).
        """
        h = self._hist
        if not h:
            raise ValueError('no target pushed yet')
        if now is None and self._repeated:
            now = self._repeat_t
        brake = self._braking(now)
        if brake is not None:   # (no jerk term: the quintic's own jerk at its start, 36 v / T^2,
            p, vp, z, vz = self._along(brake, now)   # would step the command by c3 times it)
            return self.ff.shifted(p, vp[:2], z, None if vz is None else vz[:2])
        t1, p1, z1 = h[-1]
        fit = self._fit()
        if fit is None:
            return p1, z1
        dp, dz = fit
        usual = statistics.median(self._ages) if self._ages else 0.0
        lead = 0.0 if now is None else min(max(float(now) - self._t_pose - usual, 0.0),
                                           MAX_LEAD_S)
        p1, dp = _ahead(p1, dp, lead)
        if z1 is None:
            return self.ff.shifted(p1, dp)
        z1, dz = _ahead(z1, dz, lead)
        return self.ff.shifted(p1, dp, z1 / np.linalg.norm(z1), dz)
