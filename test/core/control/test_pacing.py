"""CommandPacer: a stream's commands on its grid ring a lightly damped mode less."""

import numpy as np
import pytest
from scipy import signal

from bellow_ancf_ros.core.control import CommandPacer, StreamFeedforward
from bellow_ancf_ros.core.control._pacing import MAX_MARGIN_S, MIN_SAMPLES

PERIOD = 0.02          # a 50 Hz stream
MODE_HZ, ZETA = 2.4, 0.03   # the two-segment robot's first mode, lightly damped


def _path(t):
    """A command that moves as the 10x circle's pressures do (one unit, 2 s period)."""
    return np.sin(2 * np.pi * np.asarray(t) / 2.0)


def _times(seed, n=500, solve_s=0.006, jitter_s=0.003):
    """Ticks, intakes (1 ms + exp 0.5 ms late) and solve ends (6 ms + exp 3 ms after)."""
    rng = np.random.default_rng(seed)
    ticks = np.arange(n) * PERIOD
    intake = ticks + 0.001 + rng.exponential(0.0005, n)
    return ticks, intake, intake + solve_s + rng.exponential(jitter_s, n)


def _ringing(out_t, values):
    """RMS swing of the mode driven by the staircase ``values`` from ``out_t`` on.

    Measured against the same mode driven by the command path itself, delayed
    by the staircase's mean lag (what a perfectly regular staircase follows).
    """
    t = np.arange(out_t[0], out_t[-1], 0.00025)
    stair = values[np.searchsorted(out_t, t, side='right') - 1]
    w = 2 * np.pi * MODE_HZ
    mode = signal.lti([w * w], [1.0, 2 * ZETA * w, w * w])
    _, x, _ = signal.lsim(mode, stair, t)
    lag = float(np.mean(np.diff(out_t))) / 2.0
    _, ideal, _ = signal.lsim(mode, _path(t - lag), t)
    keep = t > t[0] + 2.0
    return float(np.sqrt(np.mean((x - ideal)[keep] ** 2)))


def _run(seed, paced):
    """Publication times and values of a stream's commands, each right for when it goes out."""
    ticks, intake, ready = _times(seed)
    pacer = CommandPacer()
    out = []
    for k in range(len(ticks)):
        regular, due = pacer.due(ticks[k], intake[k], PERIOD)
        wait = pacer.ready(regular, ready[k], due if paced else None)
        out.append(ready[k] + wait)
    out = np.array(out)
    return out, _path(out), pacer


def test_paced_commands_ring_the_mode_less():
    """Six draws of the timing: the mode rings less in each, by half or more on average."""
    free, paced = [], []
    for seed in range(6):
        t_free, v_free, _ = _run(seed, paced=False)
        t_paced, v_paced, pacer = _run(seed, paced=True)
        free.append(_ringing(t_free, v_free))
        paced.append(_ringing(t_paced, v_paced))
        # the commands' intervals: regular but for the late ones (about 1 in 20)
        assert pacer.late <= 0.1 * pacer.paced
        assert np.percentile(np.abs(np.diff(t_paced) - PERIOD), 80) < 5e-4   # (the margin moves)
        assert np.percentile(np.abs(np.diff(t_free) - PERIOD), 80) > 1e-3
    assert all(p < f for p, f in zip(paced, free)), (paced, free)
    assert np.mean(paced) < 0.5 * np.mean(free), (paced, free)


def test_margin_is_the_readiness_quantile_capped_and_never_its_own_wait():
    pacer = CommandPacer(window=50, quantile=0.9)
    for k in range(MIN_SAMPLES - 1):
        regular, due = pacer.due(k * PERIOD, k * PERIOD + 0.001, PERIOD)
        assert regular == pytest.approx(k * PERIOD + 0.001) and due is None   # (too few: at once)
        assert pacer.ready(regular, regular + 0.005, due) == 0.0
    delays = np.linspace(0.001, 0.011, 50)
    for k, d in enumerate(delays):
        regular, due = pacer.due(k * PERIOD, k * PERIOD + 0.001, PERIOD)
        wait = pacer.ready(regular, regular + d, due)
        assert wait >= 0.0
        if due is not None:   # (the wait ends at the due time, or there is none)
            assert wait == pytest.approx(max(due - (regular + d), 0.0))
    assert pacer.margin_s == pytest.approx(np.quantile(delays, 0.9))
    # a load that makes every command later than the cap: capped, and they go out when ready
    for k in range(50):
        regular, due = pacer.due(k * PERIOD, k * PERIOD + 0.001, PERIOD)
        pacer.ready(regular, regular + 0.2, due)
    assert pacer.margin_s == MAX_MARGIN_S
    regular, due = pacer.due(0.0, 0.001, PERIOD)
    assert due == pytest.approx(regular + PERIOD)        # (at most one interval of the stream)
    assert pacer.ready(regular, regular + 0.2, due) == 0.0
    pacer.reset()
    assert pacer.margin_s is None


def test_a_commands_wait_does_not_time_the_next():
    """A margin of more than an interval delays the next solve, not the next command's time.

    The regular intake comes from the arrivals, not from when the solves start:
    else the waits fed back and the margin grew by itself.
    """
    pacer = CommandPacer(max_margin_s=0.05)
    rng = np.random.default_rng(0)
    free_at, out = 0.0, []
    for k in range(400):
        tick = k * PERIOD
        arrived = tick + 0.001
        start = max(arrived, free_at)            # the solve waits for the previous wait
        regular, due = pacer.due(tick, arrived, PERIOD)
        # a busy computer (95th percentile of the solve 24 ms), then a quiet one (6 ms)
        ready = start + (0.012 + rng.exponential(0.004) if k < 200 else 0.006)
        free_at = ready + pacer.ready(regular, ready, due)
        out.append(free_at - tick)
    assert max(out[:200]) < 0.1                  # (no backlog that grows)
    assert pacer.margin_s < 0.01                 # back to the quiet computer's readiness
    assert np.ptp(out[-50:]) < 1e-3              # on the grid again


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match='quantile'):
        CommandPacer(quantile=0.0)
    with pytest.raises(ValueError, match='window'):
        CommandPacer(window=0)


def test_stream_tick_is_the_grid_tick_and_the_interval():
    sf = StreamFeedforward(2.4, 0.05)
    rng = np.random.default_rng(3)
    for k in range(60):
        tick = k * PERIOD
        sent = tick + rng.exponential(0.0005)          # stamped when sent
        p = np.array([0.01 * np.sin(np.pi * tick), 0.0, 0.2])
        sf.push(sent, p, at=sent + 0.004)
        if k >= 40:   # by the grid, its tick; by the stamps (close enough to the cubic), its stamp
            t, interval = sf.stream_tick()
            assert abs(t - tick) < 5e-4 or t == sent   # (the grid: a fitted line; or the stamp)
            assert interval == pytest.approx(PERIOD, 0.1)
    sf.push(60 * PERIOD, p, at=60 * PERIOD + 0.004)       # the same pose again: standing still
    assert sf.stream_tick() is None
    one = StreamFeedforward(2.4, 0.05)
    one.push(0.0, p)
    assert one.stream_tick() is None                       # one target: no stream yet
