"""The oscillation watchdog (core/control/_watchdog.py) and the loop's reaction to a trip."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core.control import FeedbackSettings, IntegralFeedback
from bellow_ancf_ros.core.control._feedback import OSCILLATING
from bellow_ancf_ros.core.control._watchdog import OscillationWatchdog

F = 1.45   # the two-segment robot's first mode with 50 g [Hz]
RATE = 120.0


def _run(wd, signal, seconds, seed=0):
    rng = np.random.default_rng(seed)
    for i in range(int(seconds * RATE)):
        t = i / RATE
        e = signal(t) + 0.15e-3 * rng.standard_normal(3)
        trip = wd.feed(t, e)
        if trip is not None:
            return trip
    return None


def test_a_growing_swing_trips_within_a_few_periods():
    wd = OscillationWatchdog(F)
    f_cycle = 1.6   # where the loop rings, near the mode

    def grow(t):
        x = math.sin(2 * math.pi * f_cycle * t)
        return 0.2e-3 * math.exp(0.5 * t) * np.array([x, 0.0, 0.0])
    trip = _run(wd, grow, 30.0)
    assert trip is not None and trip.time_s < 6 / F * 2   # within six windows
    assert trip.frequency_hz == pytest.approx(f_cycle, rel=0.06)
    assert 'Hz' in trip.message and wd.trips == 1


def test_a_sustained_limit_cycle_trips():
    wd = OscillationWatchdog(F)
    trip = _run(wd, lambda t: np.array([0.0, 2e-3 * math.sin(2 * math.pi * 1.6 * t), 0.0]),
                20.0)
    assert trip is not None and 'above 1 mm' in trip.reason
    assert trip.time_s < 4 * wd.window_s + 0.1


@pytest.mark.parametrize('period', [2.0, 5.0, 20.0])
def test_tracking_errors_and_noise_do_not_trip(period):
    """A 2 mm error at a circle's own frequency (10x, 4x and 1x the paper's speed)."""
    wd = OscillationWatchdog(F)

    def circle(t):
        w = 2 * math.pi / period
        return 2e-3 * np.array([math.cos(w * t), math.sin(w * t), 0.0])
    assert _run(wd, circle, 40.0) is None
    assert _run(OscillationWatchdog(F), lambda t: np.zeros(3), 40.0, seed=3) is None


@pytest.mark.parametrize('f_mode', [2.2, 2.9, 3.5])
def test_a_circles_error_growing_as_it_spins_up_does_not_trip(f_mode):
    """A 10x circle's error (2 s) grows as its spin-up ends: slow, however it grows.

    Over a window of a two-segment robot (two periods of its mode) the
    circle turns by a third of its period; the error's growth over the
    spin-up (0.1 mm held, then up to 3 mm in 1 s) is no swing at the mode.
    """
    def circle(t):
        w = 2 * math.pi / 2.0
        amp = 0.1e-3 + 2.9e-3 * min(max(t - 3.0, 0.0), 1.0) ** 2
        return amp * np.array([math.cos(w * t), math.sin(w * t), 0.0])
    for seed in range(3):
        assert _run(OscillationWatchdog(f_mode), circle, 12.0, seed=seed) is None


@pytest.mark.parametrize('slow_m', [0.0, 3e-3, 10e-3])
def test_a_swing_growing_under_a_circles_error_trips_as_without_it(slow_m):
    """A ring-up at 1.1 times the mode (1.5x per window) beside a 10x circle's error of 0-10 mm."""
    f_mode = 2.9
    window = 2.0 / f_mode

    def signal(t):
        w = 2 * math.pi / 2.0
        swing = 0.1e-3 * 1.5 ** (t / window) * math.sin(2 * math.pi * 1.1 * f_mode * t)
        return slow_m * np.array([math.cos(w * t), math.sin(w * t), 0.0]) + [swing, 0.0, 0.0]
    trip = _run(OscillationWatchdog(f_mode), signal, 20.0)
    assert trip is not None and trip.time_s < 8.5 * window   # (5.53 s for each)
    assert trip.frequency_hz == pytest.approx(1.1 * f_mode, rel=0.1)


def test_a_swing_peaks_in_the_band_a_slow_errors_leak_does_not():
    """The window's fit: a swing near the mode is a peak; a slow error rises below the band."""
    wd = OscillationWatchdog(2.9)
    t = np.arange(0.0, wd.window_s, 1 / RATE)
    swing = 0.5e-3 * np.sin(2 * math.pi * 1.1 * 2.9 * t)
    amp, freq, peak = wd._fit(t, np.column_stack([swing, 0 * t, 0 * t]))
    assert peak == amp == pytest.approx(0.5e-3, rel=0.05) and freq == pytest.approx(3.19)
    slow = 3e-3 * np.column_stack([np.cos(math.pi * (t + 0.3)), np.sin(math.pi * (t + 0.3)),
                                   0 * t])   # a circle of 2 s, a third of it in the window
    amp, freq, peak = wd._fit(t, slow)
    assert freq == pytest.approx(0.75 * 2.9) and amp > 1e-5 and peak < 0.5 * amp   # 0.48


def test_the_loop_cuts_its_gain_and_holds_on_a_trip():
    fb = IntegralFeedback(FeedbackSettings(gain_per_s=2.5, correction_frame='base'))
    fb.watch(F)
    target = np.array([0.0, 0.0, 0.1])
    for i in range(int(20 * RATE)):
        t = i / RATE
        swing = 2e-3 * math.sin(2 * math.pi * 1.6 * t)
        fb.measurement(t, target + np.array([swing, 0.0, 0.0]))
        fb.corrected_target(t, target)
        if fb.watchdog.trips:
            break
    assert fb.watchdog.trips == 1 and fb.gain_per_s == pytest.approx(1.25)
    assert fb.state == OSCILLATING
    c = fb.correction_m.copy()
    t0 = t
    while t < t0 + 0.5 * fb.watchdog.window_s:   # held for a window
        t += 1 / RATE
        fb.measurement(t, target + np.array([1e-3, 0.0, 0.0]))
        fb.corrected_target(t, target)
    np.testing.assert_array_equal(fb.correction_m, c)
    status = fb.status(t)
    assert status['oscillation_trips'] == 1 and 'Hz' in status['oscillation_seen']
    assert status['feedback_gain_per_s'] == '1.25'


def test_bunched_or_sparse_samples_invent_no_swing():
    """Samples bunched at the end of a window (a late burst), or a dropout inside it."""
    wd = OscillationWatchdog(10.4)
    rng = np.random.default_rng(1)
    t, trips = 0.0, []
    for k in range(200):   # windows of 0.19 s; every other one has its samples in a 20 ms burst
        w0 = k * wd.window_s
        times = (w0 + np.linspace(0, wd.window_s, 23) if k % 2 else
                 w0 + wd.window_s - 0.02 + np.linspace(0, 0.02, 10))
        for t in times:
            trip = wd.feed(t, 0.15e-3 * rng.standard_normal(3))
            if trip is not None:
                trips.append(trip)
    assert not trips
    assert all(a < 1e-3 for _, a in wd.amplitudes)


def test_a_small_move_of_the_mode_keeps_the_windows():
    """The mode recomputed every 2 s drifts a little: the windows must still add up to a trip."""
    wd = OscillationWatchdog(1.45)
    trip, t = None, 0.0
    while trip is None and t < 10.0:
        if int(t / 2.0) != int((t - 1 / 120) / 2.0):   # a new answer every 2 s, 1 % off
            wd.set_mode(1.45 * (1.01 if int(t / 2.0) % 2 else 0.99))
        trip = wd.feed(t, [3e-3 * math.sin(2 * math.pi * 1.5 * t), 0.0, 0.0])
        t += 1 / 120
    assert trip is not None and t < 6.0   # three windows of 1.4 s, and a little
    wd.set_mode(2.0)                      # a real move: the windows start again
    assert not wd.amplitudes


def test_a_free_swing_dying_out_is_no_trip_a_limit_cycle_is():
    """After a step the two-segment robot rings (damping ratio 0.04) for seconds: no trip."""
    f, zeta = 1.6, 0.04
    for decay, tripped in ((zeta * 2 * math.pi * f, False), (0.0, True)):
        wd = OscillationWatchdog(1.45)
        trips = []
        for k in range(int(10 * 120)):
            t = k / 120
            e = 0.02 * math.exp(-decay * t) * math.sin(2 * math.pi * f * t)
            trips.append(wd.feed(t, [e, 0.0, 0.0]))
        assert any(trips) == tripped


def _growing_during(fb, t_end, hold_until=None):
    """A swing near the mode growing 1.5x per window until ``t_end``; the trips counted."""
    target = np.array([0.0, 0.0, 0.1])
    window = 2.0 / F
    for i in range(int(t_end * RATE)):
        t = i / RATE
        swing = 0.05e-3 * 1.5 ** (t / window) * math.sin(2 * math.pi * 1.6 * t)
        fb.measurement(t, target + np.array([swing, 0.0, 0.0]))
        fb.corrected_target(t, target, hold_until=hold_until)
    return fb.watchdog.trips


def test_a_move_of_its_own_is_not_watched_a_ringing_loop_after_it_is():
    """A move holds the correction: the loop is open, its transient grows and is no trip."""
    settings = FeedbackSettings(gain_per_s=2.5, correction_frame='base')
    unheld = IntegralFeedback(settings)
    unheld.watch(F)
    assert _growing_during(unheld, 12 / F) == 1   # the same swing without the move trips
    held = IntegralFeedback(settings)
    held.watch(F)
    assert _growing_during(held, 12 / F, hold_until=12 / F) == 0
    assert not held.watchdog.amplitudes   # its windows start again after the move
    # after the move, a loop that rings up is caught within a few periods
    t0 = 12 / F
    target = np.array([0.0, 0.0, 0.1])
    for i in range(int(12 / F * RATE)):
        t = t0 + i / RATE
        swing = 0.2e-3 * math.exp(0.5 * (t - t0)) * math.sin(2 * math.pi * 1.6 * t)
        held.measurement(t, target + np.array([swing, 0.0, 0.0]))
        held.corrected_target(t, target)
        if held.watchdog.trips:
            break
    assert held.watchdog.trips == 1 and t - t0 < 6 * held.watchdog.window_s


def test_a_cut_gain_comes_back_after_a_quiet_time_unless_the_loop_rings_again():
    """A swing from outside halves the gain; 20 s without one doubles it back, once per 20 s.

    A lab-style trial's robot was rung by its target stream, the watchdog
    cut the gain, and the cut stayed for the rest of the run (2-3 mm off a
    held target afterwards).  A trip within 20 s of a restore is the loop's
    own: the cut then stays.
    """
    from bellow_ancf_ros.core.control._feedback import RESTORE_S
    fb = IntegralFeedback(FeedbackSettings(gain_per_s=2.5, correction_frame='base'))
    fb.watch(F)
    target = np.array([0.0, 0.0, 0.1])

    def run(t0, seconds, swing_m, until=lambda: False):
        for i in range(int(seconds * RATE)):
            t = t0 + i / RATE
            swing = swing_m * math.sin(2 * math.pi * 1.6 * t)
            fb.measurement(t, target + np.array([swing, 0.0, 0.0]))
            fb.corrected_target(t, target)
            if until():
                break
        return t

    t = run(0.0, 20.0, 2e-3, until=lambda: fb.watchdog.trips)   # a knock: a sustained swing
    assert fb.watchdog.trips == 1 and fb.gain_scale == 0.5
    t = run(t, RESTORE_S - 1.0, 0.0)             # quiet, but not long enough
    assert fb.gain_scale == 0.5 and fb.restores == 0
    t = run(t, 2.0, 0.0)
    assert fb.gain_scale == 1.0 and fb.restores == 1 and fb.restorable
    assert fb.status(t)['oscillation_gain_restores'] == 1
    t = run(t, 15.0, 2e-3, until=lambda: fb.watchdog.trips > 1)   # rings again: the loop's own
    assert fb.watchdog.trips == 2 and not fb.restorable and fb.gain_scale == 0.5
    run(t, 3 * RESTORE_S, 0.0)
    assert fb.gain_scale == 0.5 and fb.restores == 1   # the cut stays
