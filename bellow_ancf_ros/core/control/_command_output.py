"""What the regulators are sent for the pressures wanted: the bellows' creep and the play inverted.

The static inverse (eq. 28) gives the pressures that hold the robot at the
target once everything has settled.  Two hardware effects stand between
those pressures and the robot's pose, and both have exact inverses when
their parameters are known:

* **Creep of the bellows** (:class:`CreepCompensation`).  A part ``c`` of
  each actuator's stage-1 elongation ``x(p) = lambda(p) - 1`` (eq. 10)
  follows the pressure with a lag ``T``: with its slow part
  ``T ds/dt = x(p) - s`` the bellows stand at ``(1 - c) x(p) + c s``
  (quasi-linear viscoelasticity; the simulated robot's
  :class:`~._regulators.BellowCreep`).  After a step of the wanted pressure
  the robot moves by ``1 - c`` of the way at once and creeps the rest over a
  few ``T``, which an integral loop only chases.  Sending the elongation
  ``x = (x_w - c s) / (1 - c)`` puts the bellows at the wanted ``x_w`` at
  once: the command leads by ``c (x_w - s) / (1 - c)`` and relaxes onto the
  wanted pressure as ``s`` follows.  ``s`` is tracked from the commands
  sent (exact for commands held between updates; the regulators' lag, about
  a tenth of ``T``, is neglected), so the compensation needs updates while
  it relaxes: the inverse node's command republishing (``command_rate_hz``)
  gives them.  ``c`` and ``T`` come from a recorded pressure step
  (``bellow-ancf identify creep``).
* **The regulators' play** (:class:`~._play.PlayCompensation`), applied
  after the creep's inverse: the valve then stands at the creep-compensated
  set-point.

:class:`CommandOutput` chains the two; both pass the vent (exactly 0 Pa
gauge) as it is and keep every command within ``[p_min, p_max]`` (at a
limit the lead is cut short, never past it).
"""

from __future__ import annotations

import math

import numpy as np

from ._play import PlayCompensation

__all__ = ['CommandOutput', 'CreepCompensation']


class CreepCompensation:
    """The inverse of the bellows' creep (``fraction`` of it, over ``time_constant_s``).

    ``stage1``: the model's pressure-stretch map (its ``stretch`` and
    ``pressure``, vectorised over the actuators).
    """

    def __init__(self, stage1, n: int, fraction: float, time_constant_s: float,
                 p_min: float, p_max: float) -> None:
        if not (math.isfinite(fraction) and 0.0 <= fraction < 1.0):
            raise ValueError(f'creep_fraction = {fraction!r} is not allowed; allowed: a '
                             'fraction in [0, 1)')
        if not (math.isfinite(time_constant_s) and time_constant_s > 0):
            raise ValueError(f'creep_time_constant_s = {time_constant_s!r} is not allowed; '
                             'allowed: a time > 0 [s]')
        self.stage1, self.n = stage1, int(n)
        self.fraction, self.time_constant_s = float(fraction), float(time_constant_s)
        self.p_min, self.p_max = float(p_min), float(p_max)
        self._x_lo, self._x_hi = (float(self._x(np.array([p]))[0]) for p in (p_min, p_max))
        self.vent(None)

    def _x(self, p):
        return np.asarray(self.stage1.stretch(np.asarray(p, float)), dtype=float) - 1.0

    def _advance(self, now: float | None) -> None:
        if now is not None and self._t is not None and now > self._t:
            self.slow = self._sent + (self.slow - self._sent) * math.exp(
                -(now - self._t) / self.time_constant_s)
        if now is not None:
            self._t = max(now, self._t) if self._t is not None else now

    def command(self, wanted_pa, now: float) -> np.ndarray:
        """The pressures to send at time ``now`` [s] for the ``wanted_pa`` [Pa] (settled ones)."""
        u = np.asarray(wanted_pa, dtype=float).reshape(self.n)
        self._advance(now)
        c = self.fraction
        x = np.clip((self._x(u) - c * self.slow) / (1.0 - c), self._x_lo, self._x_hi)
        p = np.clip(np.asarray(self.stage1.pressure(1.0 + x), dtype=float),
                    self.p_min, self.p_max)
        p = np.where(u == 0.0, 0.0, p)   # the vent passes as it is
        self._sent = self._x(p)
        return p

    def vent(self, now: float | None) -> None:
        """The regulators were vented at ``now`` (None: at rest there, e.g. at start)."""
        if now is None:
            self._t = None
            self.slow = self._x(np.zeros(self.n))
        else:
            self._advance(now)
        self._sent = self._x(np.zeros(self.n))


class CommandOutput:
    """The command sent for the one wanted: the creep's inverse, then the play's (module doc).

    ``play_pa``: the regulators' play band (0: none); ``creep``:
    ``(fraction, time_constant_s)`` or None.  :attr:`timed`: the output of
    a held wanted command still changes with time (creep compensated):
    :meth:`again` gives it.
    """

    def __init__(self, model, play_pa: float = 0.0, creep=None) -> None:
        cfg = model.cfg
        self.play = (PlayCompensation(model.A, play_pa, cfg.p_min, cfg.p_max)
                     if play_pa > 0 else None)
        self.creep = (CreepCompensation(model.stage1, model.A, creep[0], creep[1], cfg.p_min,
                                        cfg.p_max)
                      if creep is not None and creep[0] > 0 else None)
        self.wanted: np.ndarray | None = None

    @property
    def timed(self) -> bool:
        """True when a held wanted command is sent differently as time goes on."""
        return self.creep is not None

    def command(self, wanted_pa, now: float) -> np.ndarray:
        """The pressures to send now [Pa] for the ``wanted_pa`` (the static inverse's)."""
        self.wanted = np.array(wanted_pa, dtype=float)
        p = self.wanted if self.creep is None else self.creep.command(self.wanted, now)
        return p if self.play is None else self.play.command(p)

    def again(self, now: float) -> np.ndarray | None:
        """The last wanted command as it is to be sent now (None: none yet)."""
        return None if self.wanted is None else self.command(self.wanted, now)

    def vent(self, now: float | None) -> None:
        """The regulators were vented (``now``: when; None: at rest)."""
        self.wanted = None
        if self.play is not None:
            self.play.vent()
        if self.creep is not None:
            self.creep.vent(now)
