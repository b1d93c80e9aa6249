"""A notch at the robot's first mode in the integral loop: a useful gain with a payload.

A lightly damped first mode (the two-segment robot carrying 50 g: 1.45 Hz,
damping ratio 0.04) puts a peak of about ``1 / (2 zeta)`` (12) into the
integral loop where its phase is already past -180 deg
(:mod:`~bellow_ancf_ros.core.control._loop_margins`): the safe gain falls to
0.43 /s, a time constant of 2.3 s, far too slow to learn a 2 s circle.  The
correction is therefore passed through

    N(s) = (s^2 + 2 zeta_z w s + w^2) / (s^2 + 2 zeta_p w s + w^2)

before it is applied, with ``w`` the model's first mode at the held
equilibrium, ``zeta_z`` its damping ratio (the zeros cancel the mode's poles:
seen through the notch, the robot's mode is as damped as ``zeta_p``) and
``zeta_p`` = :data:`NOTCH_POLE_DAMPING`.  ``N`` has unit static gain, so the
correction it holds is unchanged; it costs phase below the mode (26 deg at
a third of it), which the margins include.  The robot's mode is not the
model's exactly: the margins of a notched loop are taken as the worst over
a robot mode within :data:`NOTCH_MISMATCH` of the model's
(:func:`~._loop_margins.loop_margins` ``notch=``), so the notch does not buy
a gain that a slightly different robot would ring with.

:class:`ModeNotch` filters a vector signal sampled at irregular times: the
exact zero-order-hold discretisation of ``N`` in state space for each
step's length, so a late control step does not detune it.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

__all__ = ['NOTCH_MISMATCH', 'NOTCH_POLE_DAMPING', 'ModeNotch']

#: Damping ratio the notch gives the mode it cancels (its poles).
NOTCH_POLE_DAMPING = 0.7
#: The robot's first mode is taken to lie within this fraction of the model's (margins).
NOTCH_MISMATCH = 0.10


class ModeNotch:
    """``N(s)`` above, on a signal of ``size`` components (module docstring).

    State space: ``x' = A x + B u``, ``y = u + C x`` with
    ``A = [[0, 1], [-w^2, -2 zeta_p w]]``, ``B = [0, 1]``,
    ``C = [0, 2 (zeta_z - zeta_p) w]``.
    """

    def __init__(self, frequency_hz: float, damping_ratio: float, size: int = 6,
                 pole_damping: float = NOTCH_POLE_DAMPING) -> None:
        self.size = int(size)
        self.pole_damping = float(pole_damping)
        if not (math.isfinite(self.pole_damping) and self.pole_damping > 0):
            raise ValueError(f'pole_damping = {pole_damping!r} is not allowed; allowed: > 0')
        self._x = None          # (2, size) state; None: start at the steady state of the input
        self._t = None
        self._u = None
        self.set_mode(frequency_hz, damping_ratio)

    def set_mode(self, frequency_hz: float, damping_ratio: float) -> None:
        """Notch this mode from now on, the output continuing where it was (no jump)."""
        f, z = float(frequency_hz), float(damping_ratio)
        if not (math.isfinite(f) and f > 0 and math.isfinite(z) and 0 <= z < self.pole_damping):
            raise ValueError(f'a notch needs a frequency > 0 and a damping ratio in '
                             f'[0, {self.pole_damping:g}), got ({f}, {z})')
        w = 2 * math.pi * f
        C = np.array([0.0, 2 * (z - self.pole_damping) * w])
        if self._x is not None:   # the same output and the same departure from steady
            self._x = np.vstack([self._x[0] * (self._w2 / (w * w)),
                                 self._x[1] * (self._C[1] / C[1])])
        self.frequency_hz, self.damping_ratio = f, z
        self._A = np.array([[0.0, 1.0], [-w * w, -2 * self.pole_damping * w]])
        self._C = C
        self._w2 = w * w
        self._dt = None

    def _steady(self, u: np.ndarray) -> np.ndarray:
        return np.vstack([u / self._w2, np.zeros(self.size)])

    def reset(self) -> None:
        """Forget the signal: the next input is taken as steady."""
        self._x = self._t = self._u = None

    def filter(self, t: float, u) -> np.ndarray:
        """The output at time ``t`` for the input ``u`` (held since the previous call)."""
        u = np.asarray(u, dtype=float).reshape(self.size)
        if self._x is None or self._t is None or t <= self._t:
            if self._x is None:
                self._x = self._steady(u)
            self._t, self._u = float(t), u
            return u + self._C @ self._x
        dt = float(t) - self._t
        if dt != self._dt:   # exact zero-order hold over this step
            M = np.zeros((3, 3))
            M[:2, :2], M[1, 2] = self._A * dt, dt
            E = expm(M)
            self._Ad, self._Bd, self._dt = E[:2, :2], E[:2, 2], dt
        # the input held over the step is the previous one
        self._x = self._Ad @ self._x + np.outer(self._Bd, self._u)
        self._t, self._u = float(t), u
        return u + self._C @ self._x
