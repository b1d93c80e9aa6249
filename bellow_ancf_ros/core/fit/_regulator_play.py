"""The pressure regulators' play (hysteresis band) from a recorded staircase of set-points.

A proportional regulator's valve moves only when its set-point leaves a band
of width ``h`` around where the valve stands (a play operator; the simulated
robot's :class:`~bellow_ancf_ros.core.sim.PressureRegulators`, the inverse
node's ``regulator_play_kpa`` compensates it).  After a set-point step
upwards the pressure settles ``h/2`` below the set-point, after a step
downwards ``h/2`` above it, whatever the regulator's lag and dead time.
:func:`fit_play` reads that from a recording of the set-points and the
regulator's own pressure sensor (the ``measured_pressure`` a regulator
driver publishes):

* the recording is cut into holds (the set-point constant); a hold's settled
  pressure is the median of its samples from ``settle_s`` after its start
  (the lag and the dead time are over by then) to its end;
* only holds reached by a step in the same direction as the step before
  count: after a reversal smaller than the band the valve does not move, so
  the offset there says nothing about ``h``; a vent (a set-point of exactly
  0 Pa, which opens the exhaust past the play) and the hold after it do
  not count either;
* ``h = median(set-point - pressure | up) - median(set-point - pressure |
  down)``: a constant offset of the sensor cancels; the standard error
  comes from the spread of the offsets (1.4826 times their median absolute
  deviation).

:func:`play_staircase` makes such a recording's set-points and
:func:`staircase_recording` plays them to simulated regulators.  Every
failure is a ``ValueError`` with a one-line reason.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ['PlayFit', 'fit_play', 'play_staircase', 'staircase_recording']

#: Default time after a set-point step before its pressure counts as settled [s]: five
#: time constants of the slowest regulators the project knows (0.12 s) and their dead time.
SETTLE_S = 0.6


@dataclass(frozen=True)
class PlayFit:
    """What :func:`fit_play` found: the band's width and how well it is known."""

    width_pa: float       #: the play band's full width [Pa] (0 when the fit read less)
    std_error_pa: float   #: its standard error [Pa]
    holds_up: int         #: holds that counted, reached by steps upwards
    holds_down: int       #: and downwards


def play_staircase(low_pa: float, high_pa: float, steps: int = 5, cycles: int = 2,
                   hold_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Set-points that climb from ``low_pa`` to ``high_pa`` in ``steps`` and come back down.

    ``cycles`` times, each level held ``hold_s``.  Returns ``(start times [s],
    set-points [Pa])`` of the holds.  The steps must be wider than the play
    that is to be measured.
    """
    if not (np.isfinite(low_pa) and np.isfinite(high_pa) and low_pa < high_pa):
        raise ValueError(f'a staircase needs low_pa < high_pa, got {low_pa} and {high_pa}')
    if steps < 2 or cycles < 1 or not hold_s > 0:
        raise ValueError(f'a staircase needs steps >= 2, cycles >= 1 and hold_s > 0, got '
                         f'{steps}, {cycles} and {hold_s}')
    up = np.linspace(low_pa, high_pa, steps + 1)
    levels = np.concatenate([up] + [np.concatenate((up[-2::-1], up[1:]))] * cycles)
    return np.arange(len(levels)) * float(hold_s), levels


def staircase_recording(regulators, starts_s, levels_pa, dt_s: float = 0.01):
    """The staircase ``(starts_s, levels_pa)`` sent to ``regulators``, their sensors sampled.

    ``regulators``: anything with ``n``, ``set_command(p)`` and ``step(dt) ->
    pressures`` (:class:`~bellow_ancf_ros.core.sim.PressureRegulators`); every
    set-point gets each level, held until the next start (the last one as
    long as the one before it).  Returns ``(times (m,),
    set-point in effect (m,), measured (m, n))``, one row every ``dt_s``.
    """
    starts = np.asarray(starts_s, dtype=float)
    hold = starts[-1] - starts[-2] if len(starts) > 1 else 1.0
    t, k = 0.0, 0
    times, sent, measured = [], [], []
    while t < starts[-1] + hold - 1e-9:
        if k < len(starts) and t >= starts[k] - 1e-9:
            regulators.set_command(np.full(regulators.n, levels_pa[k]))
            k += 1
        measured.append(regulators.step(dt_s))
        t += dt_s
        times.append(t)
        sent.append(levels_pa[k - 1])
    return np.array(times), np.array(sent), np.array(measured)


def fit_play(times_s, command_pa, measured_pa, settle_s: float = SETTLE_S) -> PlayFit:
    """The play band's width from set-points and measured pressures sampled together.

    ``times_s`` (n,) increasing; ``command_pa`` (n,) the set-point in effect
    at each sample (as sent); ``measured_pa`` (n,) the regulator's pressure
    then.  See the module docstring for the method.
    """
    t = np.asarray(times_s, dtype=float).ravel()
    c = np.asarray(command_pa, dtype=float).ravel()
    m = np.asarray(measured_pa, dtype=float).ravel()
    if not (len(t) == len(c) == len(m)) or len(t) < 3:
        raise ValueError(f'fit_play needs at least 3 samples of times, set-points and pressures '
                         f'of one length, got {len(t)}, {len(c)} and {len(m)}')
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(c)) and np.all(np.isfinite(m))):
        raise ValueError('fit_play: times, set-points and pressures must be finite')
    if np.any(np.diff(t) <= 0):
        raise ValueError('fit_play: times must increase')
    edges = np.flatnonzero(np.diff(c) != 0.0) + 1
    starts = np.concatenate(([0], edges))
    ends = np.concatenate((edges, [len(t)]))
    offsets = {1.0: [], -1.0: []}
    before, direction = None, 0.0
    for a, b in zip(starts, ends):
        level = c[a]
        if before is None or level == 0.0 or before == 0.0:   # the start, a vent, after it
            before, direction = level, 0.0
            continue
        d = float(np.sign(level - before))
        settled = (t[a:b] >= t[a] + settle_s)
        if d == direction and np.any(settled):
            offsets[d].append(level - float(np.median(m[a:b][settled])))
        before, direction = level, d
    up, down = np.array(offsets[1.0]), np.array(offsets[-1.0])
    if len(up) == 0 or len(down) == 0:
        raise ValueError(f'fit_play needs settled holds after two steps in the same direction '
                         f'both upwards and downwards (holds of more than settle_s = '
                         f'{settle_s:g} s), found {len(up)} up and {len(down)} down')
    width = float(np.median(up) - np.median(down))

    def spread(x):
        return 1.4826 * float(np.median(np.abs(x - np.median(x)))) if len(x) > 1 else 0.0
    err = float(np.hypot(spread(up) / np.sqrt(len(up)), spread(down) / np.sqrt(len(down))))
    return PlayFit(max(width, 0.0), err, len(up), len(down))
