"""Margins of the integral loop with the robot's modes (core/control/_loop_margins.py)."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core import solve_forward
from bellow_ancf_ros.core.control import (MIN_GAIN_MARGIN, MIN_PHASE_MARGIN_DEG, loop_delay_s,
                                          loop_margins, safe_gain)
from bellow_ancf_ros.core.dynamics import natural_modes

TAU, T = 0.06, 0.05


def _simulate(k, mode_hz, zeta, seconds=16.0, dt=2e-4):
    """Integrator -> delay -> lag -> second-order mode, explicit in time: the error after 4 s."""
    wn = 2 * math.pi * mode_hz
    n_delay = int(round(T / dt))
    c = np.zeros(int(seconds / dt) + n_delay + 1)
    x = y = yd = 0.0
    late = []
    for i in range(n_delay, len(c) - 1):
        x += dt * (c[i - n_delay] - x) / TAU
        ydd = wn * wn * (x - y) - 2 * zeta * wn * yd
        yd += dt * ydd
        y += dt * yd
        c[i + 1] = c[i] + dt * k * (1.0 - y)
        if i * dt > 4.0:
            late.append(1.0 - y)
    return np.asarray(late)


def test_a_far_mode_changes_nothing_and_closed_forms_hold():
    plain = loop_margins(2.5, TAU, T)
    far = loop_margins(2.5, TAU, T, [(1e5, 0.3)])
    assert far.gain_margin == pytest.approx(plain.gain_margin, rel=1e-4)
    assert far.phase_margin_deg == pytest.approx(plain.phase_margin_deg, abs=0.01)
    assert far.limit_hz == pytest.approx(plain.limit_hz, rel=1e-4)
    assert loop_delay_s(0.015, 0.008, 50.0, 120.0) == pytest.approx(0.015 + 0.008 + 0.01
                                                                    + 0.5 / 120)


@pytest.mark.parametrize('mode_hz, zeta', [(1.7, 0.04), (2.4, 0.05), (10.6, 0.17)])
@pytest.mark.parametrize('factor, grows', [(0.85, False), (1.15, True)])
def test_the_predicted_limit_holds_in_time(mode_hz, zeta, factor, grows):
    """Below the predicted largest gain the loop settles; above it the error grows.

    It grows at the predicted frequency.
    """
    m1 = loop_margins(1.0, TAU, T, [(mode_hz, zeta)])
    err = _simulate(factor * m1.max_gain_per_s, mode_hz, zeta)
    third = len(err) // 3
    early, late = np.abs(err[:third]).max(), np.abs(err[-third:]).max()
    assert (late > early) == grows, (early, late)
    late = err[-third:]
    if grows:   # the oscillation is at the limit's frequency
        spec = np.abs(np.fft.rfft(late - late.mean()))
        f = np.fft.rfftfreq(len(late), 2e-4)[np.argmax(spec)]
        assert f == pytest.approx(m1.limit_hz, rel=0.15)


def test_a_light_mode_near_the_crossover_takes_the_margin():
    """Two segments carrying 50 g (1.7 Hz, zeta 0.04) ring up at the default 2.5 /s.

    As measured: a limit cycle near 1.6 Hz.
    """
    m = loop_margins(2.5, TAU, T, [(1.7, 0.04)])
    assert m.gain_margin < 1.0 and 1.3 < m.limit_hz < 1.7
    assert loop_margins(2.5, TAU, T).gain_margin > 8


@pytest.mark.parametrize('modes', [[], [(10.6, 0.17)], [(2.4, 0.05)], [(1.45, 0.04), (12.5, 0.2)]])
def test_safe_gain_keeps_both_margins(modes):
    k = safe_gain(TAU, T, modes)
    m = loop_margins(k, TAU, T, modes)
    assert m.gain_margin >= MIN_GAIN_MARGIN * (1 - 1e-6)
    assert m.phase_margin_deg >= MIN_PHASE_MARGIN_DEG - 1e-6
    above = loop_margins(1.02 * k, TAU, T, modes)
    assert (above.gain_margin < MIN_GAIN_MARGIN
            or above.phase_margin_deg < MIN_PHASE_MARGIN_DEG)


def test_the_default_robots_safe_gains(one, two):
    """With their own first modes (vented): one segment keeps 2.5 /s, two segments do not."""
    delay = loop_delay_s(0.015, 0.008, 50.0, 120.0)
    out = {}
    for name, model in (('one', one), ('two', two)):
        for payload in (0.0, 0.05):
            mode = natural_modes(solve_forward(model, np.zeros(model.A), payload_kg=payload),
                                 1).first
            out[name, payload] = safe_gain(TAU, delay, [(mode.frequency_hz,
                                                        mode.damping_ratio)])
    assert out['one', 0.0] > 2.5 and out['one', 0.05] > 2.5
    assert out['two', 0.0] < 2.5 and out['two', 0.05] < out['two', 0.0]


def test_bad_inputs_named():
    with pytest.raises(ValueError, match='gain_per_s must be > 0'):
        loop_margins(0.0, TAU, T, [(1.0, 0.1)])
    with pytest.raises(ValueError, match='a mode needs a frequency > 0'):
        loop_margins(1.0, TAU, T, [(0.0, 0.1)])


def test_mode_check_follows_the_payload(two):
    from bellow_ancf_ros.core.control import ModeCheck
    chk = ModeCheck(2.5, TAU, T, period_s=1.0)
    fw0 = solve_forward(two, np.zeros(two.A))
    assert chk.due(fw0, 0.0)
    r0 = chk.update(fw0, 0.0)
    assert round(r0.frequency_hz, 3) == 2.399 and r0.moved
    assert not r0.ok and 'safe gain 1.6' in r0.message and r0.margins.gain_margin < 3
    assert not chk.due(fw0, 0.5)
    fw1 = solve_forward(two, np.zeros(two.A), payload_kg=0.05)
    assert chk.due(fw1, 0.6)   # a new payload: at once
    r1 = chk.update(fw1, 0.6)
    assert round(r1.frequency_hz, 3) == 1.454 and r1.moved
    assert r1.margins.gain_margin < 1 and 'unstable' in r1.message
    assert set(r1.values()) >= {'loop_first_mode_hz', 'loop_gain_margin', 'loop_safe_gain_per_s'}
    fine = ModeCheck(r1.safe_gain_per_s, TAU, T).update(fw1, 0.0)
    assert fine.ok and 'safe gain' not in fine.message


def test_automatic_gain_is_the_safe_gain_and_follows_the_mode(two):
    """``'auto'``: the safe gain at each equilibrium; kept for small moves, never thin."""
    from bellow_ancf_ros.core.control import (AUTO_GAIN, MIN_GAIN_MARGIN, MIN_PHASE_MARGIN_DEG,
                                              ModeCheck, gain_setting)
    chk = ModeCheck(AUTO_GAIN, TAU, T, period_s=0.0)
    fw0 = solve_forward(two, np.zeros(two.A))
    r0 = chk.update(fw0, 0.0)
    assert r0.auto and r0.ok and r0.gain_per_s == pytest.approx(r0.safe_gain_per_s)
    assert 1.5 < r0.gain_per_s < 1.7 and '(auto)' in r0.message
    # margins at the documented ones: one of them is met with equality, none is thinner
    m = r0.margins
    assert m.gain_margin >= MIN_GAIN_MARGIN - 1e-6
    assert m.phase_margin_deg >= MIN_PHASE_MARGIN_DEG - 1e-6
    assert min(m.gain_margin / MIN_GAIN_MARGIN, m.phase_margin_deg / MIN_PHASE_MARGIN_DEG) \
        == pytest.approx(1.0, abs=1e-3)
    r1 = chk.update(solve_forward(two, np.zeros(two.A), payload_kg=0.05), 1.0)
    assert r1.moved and 0.35 < r1.gain_per_s < 0.45 and r1.ok   # 50 g: a quarter of it
    # a small move of the mode, either way, keeps the gain (no dither, no log line)...
    for t, kg in ((2.0, 0.048), (3.0, 0.052)):
        r = chk.update(solve_forward(two, np.zeros(two.A), payload_kg=kg), t)
        assert not r.moved and r.gain_per_s == r1.gain_per_s and r.ok
        assert r.margins.gain_margin > 0.95 * MIN_GAIN_MARGIN   # within the retune fraction
    # ...a large one retunes
    r4 = chk.update(solve_forward(two, np.zeros(two.A), payload_kg=0.1), 4.0)
    assert r4.moved and r4.gain_per_s == pytest.approx(r4.safe_gain_per_s)
    assert r4.gain_per_s < r1.gain_per_s
    assert gain_setting('auto') == gain_setting(' Auto ') == AUTO_GAIN
    assert gain_setting(2) == 2.0
    assert gain_setting(' 1.5 ') == 1.5   # a string a dynamically typed parameter was set to
    for bad in ('fast', 0.0, 51.0, float('nan'), True, '0', '51', 'nan'):
        with pytest.raises(ValueError, match="allowed: 'auto' or a number from 0.01 to 50"):
            gain_setting(bad)


def test_mode_check_result_shows_the_rule_it_applies():
    """One rule: ``ok`` and the diagnostics' required margins agree (2.99 is ok only on auto)."""
    from bellow_ancf_ros.core.control import LoopMargins, ModeCheckResult
    m = LoopMargins(phase_margin_deg=60.0, gain_margin=2.99, crossover_rad_s=1.0,
                    max_gain_per_s=2.99, delay_margin_s=1.0)
    kw = dict(frequency_hz=2.4, damping_ratio=0.05, gain_per_s=1.0, margins=m,
              safe_gain_per_s=1.0, payload_kg=0.0, moved=False, computed_s=0.01)
    fixed, auto = ModeCheckResult(**kw), ModeCheckResult(**kw, auto=True)
    assert not fixed.ok and auto.ok
    assert fixed.required == (MIN_GAIN_MARGIN, MIN_PHASE_MARGIN_DEG)
    gm, pm = auto.required
    assert 2.99 > gm > 0.85 * MIN_GAIN_MARGIN and pm < MIN_PHASE_MARGIN_DEG
    v = auto.values()
    assert v['loop_margins_ok'] == 'true' and f'gain margin {gm:.3g}' in v['loop_margins_required']
    assert fixed.values()['loop_margins_required'].startswith('gain margin 3,')
