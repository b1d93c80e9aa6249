"""The regulators' play (backlash) inverted: the set-point the valve follows is the one wanted.

A proportional pressure regulator has a hysteresis band: its valve moves
only when the set-point leaves a band of width ``h`` around where it stands
(a play operator, ``w <- clip(w, c - h/2, c + h/2)``; the realistic
simulated robot: 1 kPa, :mod:`~bellow_ancf_ros.core.sim._regulators`).
Any change of direction is therefore taken up by the play first: after a
held target, the first part of a new command (up to ``h``) moves nothing.
That is a small unshaped step inside a shaped one: a ZVD-shaped 10 mm step
on the two-segment robot leaves 0.09-0.27 mm of swing 1 s after it with a
1 kPa play, 0.005 mm without (``LoopSimulation``).

:class:`PlayCompensation` runs the same play operator on the commands it
hands out and commands, for a wanted set-point ``u``, the edge of the band
that puts the valve exactly at ``u``: ``u + h/2`` when ``u`` lies above
where the valve stands, ``u - h/2`` below, ``u`` when it is there (the
classic backlash inverse).  The vent (exactly 0 Pa gauge) passes as it is:
it opens the exhaust, past the play.  Commands stay within
``[p_min, p_max]`` (at a limit the compensation is cut short, never past
it).  With the true width the valve follows the wanted set-points exactly;
a width larger than the true one dithers by the difference, so it is given
from the regulators' data sheet, not guessed high.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ['PlayCompensation']


class PlayCompensation:
    """Backlash inverse of a play of width ``width_pa`` on each of ``n`` set-points."""

    def __init__(self, n: int, width_pa: float, p_min: float, p_max: float) -> None:
        if not (math.isfinite(width_pa) and width_pa >= 0):
            raise ValueError(f'regulator play width {width_pa!r} Pa is not allowed; allowed: '
                             'a width >= 0')
        self.n, self.width_pa = int(n), float(width_pa)
        self.p_min, self.p_max = float(p_min), float(p_max)
        self._valve = np.zeros(self.n)   # where the valves stand (the vent: 0)

    def command(self, wanted_pa) -> np.ndarray:
        """The set-points to send for the wanted ones [Pa] (and where the valves then stand)."""
        u = np.asarray(wanted_pa, dtype=float).reshape(self.n)
        half = 0.5 * self.width_pa
        c = np.where(u > self._valve, u + half, np.where(u < self._valve, u - half, u))
        c = np.where(u == 0.0, 0.0, np.clip(c, self.p_min, self.p_max))
        self._valve = np.where(c == 0.0, 0.0, np.clip(self._valve, c - half, c + half))
        return c

    def vent(self) -> None:
        """The valves were vented (or the regulators restarted): they stand at 0."""
        self._valve = np.zeros(self.n)
