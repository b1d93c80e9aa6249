"""The notch at the first mode (core/control/_notch.py) and the loop margins with it."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core.control import (FeedbackSettings, IntegralFeedback, loop_margins,
                                          safe_gain)
from bellow_ancf_ros.core.control._loop_margins import robust_margins
from bellow_ancf_ros.core.control._notch import NOTCH_POLE_DAMPING, ModeNotch

F, ZETA = 1.405, 0.04     # two segments carrying 50 g: the first mode


def _response(n, f_in, dt=0.002, periods=40):
    """Steady amplitude of the notch's output for a unit sine at ``f_in`` (sampled at dt)."""
    ts = np.arange(0.0, periods / max(f_in, 0.05), dt)
    ys = np.array([n.filter(t, [math.sin(2 * math.pi * f_in * t)])[0] for t in ts])
    return np.abs(ys[len(ys) // 2:]).max()


def _exact(f_in, f=F, z=ZETA, zp=NOTCH_POLE_DAMPING):
    w, s = 2 * math.pi * f, 2j * math.pi * f_in
    return abs((s * s + 2 * z * w * s + w * w) / (s * s + 2 * zp * w * s + w * w))


@pytest.mark.parametrize('f_in', [0.2, 0.7, F, 3.0])
def test_frequency_response_is_the_notchs(f_in):
    got = _response(ModeNotch(F, ZETA, size=1), f_in)
    assert got == pytest.approx(_exact(f_in), abs=0.02)


def test_static_gain_one_and_no_transient_from_a_held_input():
    n = ModeNotch(F, ZETA, size=3)
    u = np.array([1e-3, -2e-3, 0.5e-3])
    for t in np.arange(0.0, 3.0, 0.02):
        np.testing.assert_allclose(n.filter(t, u), u, atol=1e-15)


def test_zero_order_hold_is_exact_whatever_the_step():
    """Steps of 20 ms or twice 10 ms with the same held inputs end in the same state."""
    a, b = ModeNotch(F, ZETA, size=1), ModeNotch(F, ZETA, size=1)
    a.filter(0.0, [0.0])
    b.filter(0.0, [0.0])
    for k in range(1, 50):
        u = [1.0 if k > 3 else 0.0]
        ya = a.filter(0.02 * k, u)
        b.filter(0.02 * k - 0.01, [1.0 if k - 1 > 3 else 0.0])   # the input held before
        yb = b.filter(0.02 * k, u)
        np.testing.assert_allclose(ya, yb, atol=1e-12)


def test_a_new_mode_continues_the_output():
    n = ModeNotch(F, ZETA, size=1)
    n.filter(0.0, [0.0])
    y = n.filter(0.3, [1.0])            # in the transient of a step
    y = n.filter(0.32, [1.0])
    n.set_mode(1.1 * F, ZETA)
    assert n.filter(0.32, [1.0]) == pytest.approx(y, abs=1e-12)


@pytest.mark.parametrize('bad', [(0.0, 0.04), (1.0, -0.1), (1.0, 0.8), (math.nan, 0.04)])
def test_bad_modes_are_refused(bad):
    with pytest.raises(ValueError, match='notch'):
        ModeNotch(*bad)


def test_notch_that_cancels_the_mode_has_the_margins_of_a_damped_mode():
    """Exact cancellation: the robot seen through the notch is the mode damped to zeta_p."""
    a = loop_margins(1.5, 0.06, 0.05, [(F, ZETA)], notch=(F, ZETA))
    b = loop_margins(1.5, 0.06, 0.05, [(F, NOTCH_POLE_DAMPING)])
    assert a.gain_margin == pytest.approx(b.gain_margin, rel=1e-9)
    assert a.phase_margin_deg == pytest.approx(b.phase_margin_deg, abs=1e-6)


def test_a_notch_without_depth_changes_nothing():
    a = loop_margins(0.3, 0.06, 0.05, [(F, ZETA)], notch=(F, 0.5, 0.5))
    b = loop_margins(0.3, 0.06, 0.05, [(F, ZETA)])
    assert a.max_gain_per_s == pytest.approx(b.max_gain_per_s, rel=1e-9)
    assert a.phase_margin_deg == pytest.approx(b.phase_margin_deg, abs=1e-6)


def test_safe_gain_with_the_notch_and_a_mismatched_robot():
    plain = safe_gain(0.06, 0.05, [(F, ZETA)])
    exact = safe_gain(0.06, 0.05, [(F, ZETA)], notch=(F, ZETA))
    robust = safe_gain(0.06, 0.05, [(F, ZETA)], notch=(F, ZETA), mismatch=0.1)
    assert plain == pytest.approx(0.378, abs=0.01)
    assert plain * 4 < robust < exact     # the notch buys a gain; the mismatch costs some
    m = robust_margins(robust, 0.06, 0.05, [(F, ZETA)], notch=(F, ZETA), mismatch=0.1)
    assert m.gain_margin >= 3.0 * (1 - 1e-6) and m.phase_margin_deg >= 45.0 - 1e-3
    # the robot whose mode is 10 % off is the thin one
    worst = min((loop_margins(robust, 0.06, 0.05, [(F * s, ZETA)], notch=(F, ZETA))
                 for s in (0.9, 1.1)), key=lambda m: m.gain_margin)
    assert worst.gain_margin == pytest.approx(m.gain_margin, rel=1e-9)


def test_feedback_applies_the_notched_correction():
    fb = IntegralFeedback(FeedbackSettings(gain_per_s=1.0, notch=True))
    fb.watch(F, ZETA)
    assert fb.notch is not None and fb.status(0.0)['feedback_notch_hz'] == f'{F:.4g}'
    fb2 = IntegralFeedback(FeedbackSettings(gain_per_s=1.0))
    fb2.watch(F, ZETA)
    assert fb2.notch is None and fb2.status(0.0)['feedback_notch_hz'] == 'off'
    with pytest.raises(ValueError, match='notch'):
        FeedbackSettings(notch='yes')
