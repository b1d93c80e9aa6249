"""The integral loop checked against the robot's own first mode at the held equilibrium.

The loop's margins (module ``_loop_margins``) depend on where the robot is
held: a payload, a tip force or a bent pose move the first lateral mode
(the two-segment robot: 2.4 Hz vented and unloaded, 1.45 Hz with 50 g).
:class:`ModeCheck` computes the first mode of the controller's model at the
equilibrium of its newest solve (:func:`~bellow_ancf_ros.core.dynamics.natural_modes`,
tens to hundreds of milliseconds: never in the control path), the margins of
the configured gain with it, and the largest gain that keeps the documented
margins (:func:`~._loop_margins.safe_gain`).  It recomputes when the
payload or the tip force changed, or every ``period_s`` while the robot
moves, and says whether the first mode moved by more than
``retune_fraction`` since the last answer (what a gain that follows the
mode needs).

With ``gain_per_s='auto'`` (:data:`AUTO_GAIN`) the gain *is* the safe gain
at the held equilibrium: every answer whose mode moved by more than
``retune_fraction`` carries a new gain to integrate with (the margins are
then the documented ones by construction, and within about twice that
fraction of them in between); the watchdog's cuts still apply on top of it
(``IntegralFeedback.set_gain``).

Only the first mode enters the loop (a unit-gain second-order factor): it
carries most of the lateral compliance (the second pair lies 4-5 times
higher and is twice as damped), and a product of several factors would add
the phase of modes that act in parallel, not in series.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from ..dynamics import ModalError, natural_modes
from ._loop_margins import (MIN_GAIN_MARGIN, MIN_PHASE_MARGIN_DEG, LoopMargins, loop_margins,
                            safe_gain)

__all__ = ['AUTO_GAIN', 'GAIN_RANGE_PER_S', 'ModeCheck', 'ModeCheckResult', 'RETUNE_FRACTION',
           'gain_setting']

#: The first mode moved by more than this fraction: a new answer (and a new automatic gain).
RETUNE_FRACTION = 0.05
#: The gain setting that follows the robot's first mode.
AUTO_GAIN = 'auto'
#: The integral gains allowed [1/s], fixed or automatic (an automatic gain is clipped to it).
GAIN_RANGE_PER_S = (0.01, 50.0)


def gain_setting(value) -> float | str:
    """A gain setting: :data:`AUTO_GAIN`, or a fixed gain in :data:`GAIN_RANGE_PER_S` [1/s].

    Raises ValueError naming the value and what is allowed.
    """
    lo, hi = GAIN_RANGE_PER_S
    if isinstance(value, str) and value.strip().lower() == AUTO_GAIN:
        return AUTO_GAIN
    if isinstance(value, str):   # (a dynamically typed parameter set to '1.5': a number)
        try:
            value = float(value)
        except ValueError:
            pass
    if not isinstance(value, bool) and isinstance(value, (int, float)) and (
            math.isfinite(value) and lo <= value <= hi):
        return float(value)
    raise ValueError(f'{value!r} is not allowed; allowed: {AUTO_GAIN!r} or a number from '
                     f'{lo:g} to {hi:g} [1/s]')


@dataclass(frozen=True)
class ModeCheckResult:
    """The first mode at the held equilibrium and the loop's margins with it."""

    frequency_hz: float
    damping_ratio: float
    gain_per_s: float
    margins: LoopMargins
    safe_gain_per_s: float
    payload_kg: float
    moved: bool            #: the mode moved by more than the retune fraction since the last
    computed_s: float      #: how long the modal analysis and the margins took [s]
    auto: bool = False     #: the gain is the safe gain (``gain_per_s='auto'``)

    @property
    def ok(self) -> bool:
        """Both margins at least the documented ones (an automatic gain: within 2 retunes).

        An automatic gain is set to the safe gain whenever the mode moves by
        more than :data:`RETUNE_FRACTION`; in between, its margins may be
        thinner by about that fraction squared or less.
        """
        gm, pm = self.required
        return self.margins.gain_margin >= gm and self.margins.phase_margin_deg >= pm

    @property
    def required(self) -> tuple[float, float]:
        """``(gain margin, phase margin [deg])`` that :attr:`ok` asks for (the one rule).

        The documented margins; an automatic gain's thinned by
        ``(1 - RETUNE_FRACTION)^2`` (it is re-tuned when the mode moves by more
        than :data:`RETUNE_FRACTION`).
        """
        slack = (1.0 - RETUNE_FRACTION) ** 2 if self.auto else 1.0
        return MIN_GAIN_MARGIN * slack, MIN_PHASE_MARGIN_DEG * slack

    @property
    def message(self) -> str:
        """One line: the gain, its margins with the mode, the safe gain."""
        m = self.margins
        auto = ' (auto)' if self.auto else ''
        head = (f'feedback gain {self.gain_per_s:.3g} /s{auto} with the robot\'s first mode '
                f'({self.frequency_hz:.3g} Hz, damping ratio {self.damping_ratio:.3f}, payload '
                f'{self.payload_kg:g} kg): gain margin {m.gain_margin:.2f}, phase margin '
                f'{m.phase_margin_deg:.0f} deg')
        if self.ok:
            return head
        risk = ('unstable: it rings itself up near' if m.gain_margin < 1
                else 'too thin: it may ring near')
        return (f'{head}; {risk} {m.limit_hz:.2f} Hz; safe gain {self.safe_gain_per_s:.3g} /s '
                f'(gain margin {MIN_GAIN_MARGIN:g}, phase margin {MIN_PHASE_MARGIN_DEG:g} deg)')

    def values(self) -> dict:
        """Diagnostics values."""
        m = self.margins
        return {'loop_first_mode_hz': f'{self.frequency_hz:.4g}',
                'loop_first_mode_damping_ratio': f'{self.damping_ratio:.4f}',
                'loop_gain_margin': f'{m.gain_margin:.3g}',
                'loop_phase_margin_deg': f'{m.phase_margin_deg:.1f}',
                'loop_safe_gain_per_s': f'{self.safe_gain_per_s:.4g}',
                'loop_margins_ok': str(self.ok).lower(),
                'loop_margins_required': (f'gain margin {self.required[0]:.3g}, phase margin '
                                          f'{self.required[1]:.3g} deg'
                                          + (' (automatic gain: the documented 3 and 45 deg '
                                             'within two re-tunes)' if self.auto else ''))}


class ModeCheck:
    """Margins of an integral gain with the first mode of the newest equilibrium (module doc).

    Parameters
    ----------
    gain_per_s : the integral gain to check, or :data:`AUTO_GAIN`: the safe
        gain at each answer's equilibrium (``result.gain_per_s``).
    lag_s, delay_s : the regulators' time constant and the loop's delay
        (:func:`~._loop_margins.loop_delay_s`).
    period_s : recompute at most this often while the equilibrium moves.
    retune_fraction : a move of the first mode by more than this is reported
        as ``moved``.
    """

    def __init__(self, gain_per_s: float, lag_s: float, delay_s: float, period_s: float = 2.0,
                 retune_fraction: float = RETUNE_FRACTION) -> None:
        self.auto = gain_setting(gain_per_s) == AUTO_GAIN
        self.gain_per_s = GAIN_RANGE_PER_S[0] if self.auto else float(gain_per_s)
        loop_margins(self.gain_per_s, lag_s, delay_s)   # checks the numbers (ValueError)
        self.lag_s, self.delay_s = float(lag_s), float(delay_s)
        self.period_s = float(period_s)
        self.retune_fraction = float(retune_fraction)
        self.last: ModeCheckResult | None = None
        self._last_t = -math.inf
        self._last_load = None
        self._last_x = None

    def due(self, fw, now_s: float) -> bool:
        """Whether ``fw`` (a usable equilibrium) asks for a new answer now."""
        if fw is None or not fw.converged:
            return False
        if self.last is None or fw.load != self._last_load:
            return True
        return (now_s - self._last_t >= self.period_s and self._last_x is not None
                and fw.x is not self._last_x)

    def update(self, fw, now_s: float) -> ModeCheckResult | None:
        """The first mode at ``fw`` and the margins with it (None: no mode at ``fw``)."""
        t0 = time.perf_counter()
        self._last_t, self._last_load, self._last_x = now_s, fw.load, fw.x
        try:
            mode = natural_modes(fw, 1).first
        except ModalError:
            return None
        modes = [(mode.frequency_hz, mode.damping_ratio)]
        safe = safe_gain(self.lag_s, self.delay_s, modes)
        prev = self.last
        moved = prev is None or abs(mode.frequency_hz - prev.frequency_hz) > (
            self.retune_fraction * prev.frequency_hz)
        gain = self.gain_per_s
        if self.auto:   # a new gain when the mode moved, not for every small move (no
            lo, hi = GAIN_RANGE_PER_S   # dither): the margins stay within the retune fraction
            gain = min(max(safe, lo), hi)
            if not moved and prev is not None:
                gain = prev.gain_per_s
        margins = loop_margins(gain, self.lag_s, self.delay_s, modes)
        self.last = ModeCheckResult(mode.frequency_hz, mode.damping_ratio, gain, margins, safe,
                                    float(fw.load.payload_kg), moved,
                                    time.perf_counter() - t0, self.auto)
        return self.last
