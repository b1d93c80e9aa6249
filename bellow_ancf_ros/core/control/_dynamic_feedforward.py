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
stream of stamped targets (a trajectory publisher's preview): the
derivatives of the newest samples by a local quadratic fit; a jump (a step
target) is passed unshifted, since its derivatives are not a motion the
robot can follow (input shaping is the remedy for steps).  Every shift is
clipped to ``max_shift_m`` (and ``max_shift_rad``).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Callable

import numpy as np

__all__ = ['DynamicFeedforward', 'StreamFeedforward', 'dynamic_path']

#: Largest shift of the target [m] and of its z-axis [rad] the feedforward applies.
MAX_SHIFT_M = 0.01
MAX_SHIFT_RAD = math.radians(10.0)


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


class StreamFeedforward:
    """:class:`DynamicFeedforward` on a stream of stamped targets.

    :meth:`push` each target with the time it is wanted at; :meth:`target`
    gives the newest one shifted by the derivatives of a quadratic fitted to
    the targets of the last ``window_s`` (at least three).  A target farther
    than ``jump_m`` from the one before (a step), a gap longer than
    ``window_s``, or too few samples: the newest target unshifted.
    """

    def __init__(self, frequency_hz: float, damping_ratio: float, window_s: float = 0.08,
                 jump_m: float = 0.005, **kw) -> None:
        self.ff = DynamicFeedforward(frequency_hz, damping_ratio, **kw)
        self.window_s, self.jump_m = float(window_s), float(jump_m)
        self._hist: deque = deque()

    def set_mode(self, frequency_hz: float, damping_ratio: float) -> None:
        """Shift for this mode from now on."""
        self.ff.set_mode(frequency_hz, damping_ratio)

    def reset(self) -> None:
        """Forget the stream (the next target starts unshifted)."""
        self._hist.clear()

    def push(self, t: float, position, z_axis=None) -> None:
        """A target wanted at time ``t`` (a time that goes back starts the stream again)."""
        p = np.asarray(position, float).reshape(3)
        z = None if z_axis is None else np.asarray(z_axis, float).reshape(3)
        h = self._hist
        if h and (t <= h[-1][0] or t - h[-1][0] > self.window_s
                  or np.linalg.norm(p - h[-1][1]) > self.jump_m):
            h.clear()
        h.append((float(t), p, z))
        while len(h) > 3 and h[0][0] < t - self.window_s:
            h.popleft()

    def target(self):
        """The newest target shifted for the mode: ``(position, z_axis or None)``."""
        h = self._hist
        if not h:
            raise ValueError('no target pushed yet')
        t1, p1, z1 = h[-1]
        if len(h) < 3:
            return p1, z1
        t = np.array([s[0] for s in h]) - t1
        cols = [np.ones_like(t), t, 0.5 * t * t]   # value, slope, curvature (and jerk)
        if len(h) >= 5 and self.ff.c3 > 0:
            cols.append(t ** 3 / 6)
        V = np.column_stack(cols)
        coef = np.linalg.lstsq(V, np.array([s[1] for s in h]), rcond=None)[0]
        if z1 is None:
            return self.ff.shifted(p1, coef[1:])
        cz = np.linalg.lstsq(V, np.array([s[2] for s in h]), rcond=None)[0]
        return self.ff.shifted(p1, coef[1:], z1, cz[1:])
