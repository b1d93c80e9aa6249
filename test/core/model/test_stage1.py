"""Tests of stage 1 (paper eqs. 10 / 24 with F_e = 0): pressure <-> stretch."""

from fractions import Fraction
import math

from hypothesis import assume, example, given, settings, strategies as st
import numpy as np
from numpy.polynomial import Polynomial
import pytest

from bellow_ancf_ros.core.model._stage1 import Stage1

# Default robot, docs/model.md section 5.
C0, C1 = 28.9, 576.94            # k(lam) = C1*lam + C0 [N/m]
L0 = 0.0963                      # [m]
D_EFF = 8.087e-3                 # [m]
P_MIN, P_MAX = -50e3, 150e3      # [Pa]
CUBIC = (28.9, 576.94, 120.0, 900.0)   # a stiffer-at-large-stretch third-order k


@pytest.fixture
def default():
    return Stage1((C0, C1), L0, D_EFF, P_MIN, P_MAX)


@pytest.fixture
def cubic():
    return Stage1(CUBIC, L0, D_EFF, P_MIN, P_MAX)


def k_from_x(coeffs_in_x):
    """Ascending coefficients in lam of a polynomial given in x = lam - 1."""
    return tuple(Polynomial(coeffs_in_x)(Polynomial([-1.0, 1.0])).coef)


# ------------------------------------------------------------------ reference
def test_paper_numbers_by_hand(default):
    """Lambda at 150 kPa from the quadratic formula, written out by hand.

    (pi/4) P D^2 = (C1 lam + C0)(lam - 1) l0
      <=> C1 lam^2 + (C0 - C1) lam - (C0 + F/l0) = 0,   F = (pi/4) P D^2
    """
    force = math.pi / 4.0 * 150e3 * D_EFF ** 2
    a, b, c = C1, C0 - C1, -(C0 + force / L0)
    lam_hand = (-b + math.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)
    assert default.stretch(150e3) == pytest.approx(lam_hand, rel=1e-14)
    assert default.lam_max == pytest.approx(lam_hand, rel=1e-14)
    assert lam_hand == pytest.approx(1.11865, abs=1e-5)    # ~11.9 % elongation
    # and at p_min
    force = math.pi / 4.0 * -50e3 * D_EFF ** 2
    c = -(C0 + force / L0)
    lam_hand = (-b + math.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)
    assert default.lam_min == pytest.approx(lam_hand, rel=1e-14)


def test_pressure_is_eq24(default):
    lam = np.linspace(0.9, 1.2, 31)
    expected = (C1 * lam + C0) * (lam - 1.0) * L0 / (math.pi / 4.0 * D_EFF ** 2)
    np.testing.assert_allclose(default.pressure(lam), expected, rtol=1e-14, atol=1e-9)


def test_zero_pressure_gives_unit_stretch(default, cubic):
    assert default.stretch(0.0) == 1.0
    assert cubic.stretch(0.0) == 1.0
    assert default.pressure(1.0) == 0.0
    assert cubic.pressure(1.0) == 0.0


def test_from_config_matches_constructor():
    class Cfg:
        stiffness_coeffs = CUBIC
        l0, d_eff, p_min, p_max = L0, D_EFF, P_MIN, P_MAX

    s = Stage1.from_config(Cfg)
    assert s.coeffs == CUBIC
    assert s.stretch(1e5) == Stage1(CUBIC, L0, D_EFF, P_MIN, P_MAX).stretch(1e5)


# ------------------------------------------------------------------ round trip
@pytest.mark.parametrize('coeffs', [(C0, C1), CUBIC, (600.0,), (28.9, 576.94, 0.0, 0.0)])
def test_round_trip_over_range(coeffs):
    s = Stage1(coeffs, L0, D_EFF, P_MIN, P_MAX)
    p = np.concatenate([np.linspace(P_MIN, P_MAX, 2001), [-1e-3, 1e-9, 0.0, 5e-300]])
    lam = s.stretch(p)
    np.testing.assert_allclose(s.pressure(lam), p, rtol=1e-12, atol=1e-12 * (P_MAX - P_MIN))
    assert np.all(np.diff(lam[:2001]) > 0.0)          # monotonic
    assert lam[0] == pytest.approx(s.lam_min, rel=1e-15)
    assert lam[2000] == pytest.approx(s.lam_max, rel=1e-15)


@settings(max_examples=200, deadline=None)
@given(p=st.floats(P_MIN, P_MAX, allow_nan=False))
def test_round_trip_property_default(p):
    s = Stage1((C0, C1), L0, D_EFF, P_MIN, P_MAX)
    assert s.pressure(s.stretch(p)) == pytest.approx(p, rel=1e-12, abs=1e-12 * (P_MAX - P_MIN))


@settings(max_examples=200, deadline=None)
@given(
    coeffs=st.lists(st.floats(0.0, 2000.0, allow_nan=False), min_size=1, max_size=5),
    p=st.floats(P_MIN, P_MAX, allow_nan=False),
    q=st.floats(P_MIN, P_MAX, allow_nan=False),
)
def test_round_trip_property_any_order(coeffs, p, q):
    """Random polynomials up to 4th order: round trip and monotonicity."""
    assume(sum(coeffs) > 1.0)                         # k(1) > 0
    try:
        s = Stage1(coeffs, L0, D_EFF, P_MIN, P_MAX)
    except ValueError:
        assume(False)                                 # refused (not monotonic there)
    lam_p, lam_q = s.stretch(p), s.stretch(q)
    span = P_MAX - P_MIN
    assert s.pressure(lam_p) == pytest.approx(p, rel=1e-12, abs=1e-12 * span)
    if p < q:
        assert lam_p <= lam_q
    assert s.lam_min <= lam_p <= s.lam_max
    assert s.dpressure(lam_p) > 0.0


def test_cubic_exactness_eq24_residual(cubic):
    """Eq. (24) holds at machine precision and the exact root is within a few ulps."""
    p = np.linspace(P_MIN, P_MAX, 101)
    lam = cubic.stretch(p)
    force = math.pi / 4.0 * p * D_EFF ** 2
    k = sum(c * lam ** i for i, c in enumerate(CUBIC))
    residual = force - k * (lam - 1.0) * L0
    force_scale = math.pi / 4.0 * P_MAX * D_EFF ** 2
    assert np.max(np.abs(residual)) <= 16 * np.finfo(float).eps * force_scale

    # Exact rational evaluation: the residual changes sign within +-4 ulp of lam.
    area = Fraction(cubic.area)
    coeffs = [Fraction(c) for c in CUBIC]

    def exact_residual(pressure, x):
        x = Fraction(x)
        return Fraction(pressure) * area - sum(c * x ** i for i, c in enumerate(coeffs)) \
            * (x - 1) * Fraction(L0)

    for p_i, li in zip(p[::10], lam[::10]):
        if p_i == 0.0:
            assert li == 1.0
            continue
        below = np.nextafter(li, -np.inf)
        above = np.nextafter(li, np.inf)
        for _ in range(3):
            below = np.nextafter(below, -np.inf)
            above = np.nextafter(above, np.inf)
        assert exact_residual(p_i, below) > 0 > exact_residual(p_i, above)


def test_higher_order_newton_matches_polynomial_roots(cubic):
    p = np.linspace(P_MIN, P_MAX, 9)
    for p_i, li in zip(p, cubic.stretch(p)):
        g = Polynomial(CUBIC) * Polynomial([-1.0, 1.0]) * L0 - math.pi / 4.0 * p_i * D_EFF ** 2
        roots = g.roots()
        real = roots[np.abs(roots.imag) < 1e-9].real
        nearest = real[np.argmin(np.abs(real - li))]
        assert li == pytest.approx(nearest, rel=1e-13)


def test_outside_admissible_range_on_branch(default, cubic):
    for s in (default, cubic):
        lam = s.stretch(400e3)
        assert lam > s.lam_max
        assert s.pressure(lam) == pytest.approx(400e3, rel=1e-12)
        lam = s.stretch(-100e3)
        assert 0.0 < lam < s.lam_min
        assert s.pressure(lam) == pytest.approx(-100e3, rel=1e-12)


# ---------------------------------------------------------------- derivatives
@pytest.mark.parametrize('coeffs', [(C0, C1), CUBIC])
def test_derivatives_against_finite_differences(coeffs):
    s = Stage1(coeffs, L0, D_EFF, P_MIN, P_MAX)
    lam = np.linspace(s.lam_min, s.lam_max, 7)
    h = 1e-6
    np.testing.assert_allclose(s.dk(lam), (s.k(lam + h) - s.k(lam - h)) / (2 * h), rtol=1e-8)
    np.testing.assert_allclose(s.dpressure(lam),
                               (s.pressure(lam + h) - s.pressure(lam - h)) / (2 * h), rtol=1e-8)
    p = np.linspace(P_MIN, P_MAX, 7)
    hp = 1e-2
    np.testing.assert_allclose(s.dstretch(p), (s.stretch(p + hp) - s.stretch(p - hp)) / (2 * hp),
                               rtol=1e-6)


def test_k_polynomial(default, cubic):
    assert default.k(1.1) == pytest.approx(C1 * 1.1 + C0, rel=1e-15)
    assert cubic.k(2.0) == pytest.approx(sum(c * 2.0 ** i for i, c in enumerate(CUBIC)))


# ----------------------------------------------------------------- vectorised
def test_shapes_and_scalar_types(default, cubic):
    for s in (default, cubic):
        assert isinstance(s.stretch(1e4), float)
        assert isinstance(s.pressure(1.05), float)
        assert isinstance(s.k(1.05), float)
        assert isinstance(s.dpressure(1.05), float)
        p = np.linspace(P_MIN, P_MAX, 12).reshape(3, 4)
        lam = s.stretch(p)
        assert lam.shape == (3, 4)
        for f in (s.pressure, s.dpressure, s.k, s.dk):
            assert f(lam).shape == (3, 4)
        assert s.stretch(np.empty(0)).shape == (0,)
        np.testing.assert_array_equal(s.stretch(p.ravel()), lam.ravel())


@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf, [0.0, math.nan]])
def test_nan_and_inf_pressure_raise(default, cubic, bad):
    for s in (default, cubic):
        with pytest.raises(ValueError, match='finite'):
            s.stretch(bad)


# --------------------------------------------------------------- refusals
def test_refuses_dip_in_the_admissible_range():
    """dP/dlam < 0 on lam in (1.04, 1.06) although P_MAX is reached beyond it."""
    coeffs = k_from_x(np.array([0.0024, -0.05, 1.0 / 3.0]) * 250000.0)
    with pytest.raises(ValueError, match='not monotonic') as info:
        Stage1(coeffs, L0, D_EFF, P_MIN, P_MAX)
    assert '1.04' in str(info.value)
    # the same polynomial is fine on a range that stays below the dip
    s = Stage1(coeffs, L0, D_EFF, -5e3, 5e3)
    assert 1.0 < s.lam_max < 1.04


def test_refuses_saturating_polynomial():
    """Refuse k = 600 - 8000 (lam - 1)^2: P peaks at about 118.6 kPa."""
    coeffs = k_from_x([600.0, 0.0, -8000.0])
    with pytest.raises(ValueError, match='not monotonic'):
        Stage1(coeffs, L0, D_EFF, P_MIN, P_MAX)
    s = Stage1(coeffs, L0, D_EFF, -20e3, 20e3)
    assert s.lam_branch[1] == pytest.approx(1.0 + math.sqrt(600.0 / 24000.0), rel=1e-10)
    # beyond p_max but still on the branch
    assert s.pressure(s.stretch(110e3)) == pytest.approx(110e3, rel=1e-12)
    with pytest.raises(ValueError, match='beyond the monotone branch'):
        s.stretch(130e3)


def test_refuses_negative_slope_at_unit_stretch():
    with pytest.raises(ValueError, match='k\\(1\\)'):
        Stage1((600.0, -700.0), L0, D_EFF, P_MIN, P_MAX)
    with pytest.raises(ValueError, match='k\\(1\\)'):
        Stage1((0.0,), L0, D_EFF, P_MIN, P_MAX)


def test_refuses_p_min_needing_nonpositive_stretch():
    with pytest.raises(ValueError, match='lam = 0'):
        Stage1((600.0,), L0, D_EFF, -2000e3, P_MAX)
    with pytest.raises(ValueError, match='p_min'):
        Stage1((C0, C1), L0, D_EFF, -1000e3, P_MAX)     # dP/dlam = 0 at lam ~ 0.475


@pytest.mark.parametrize('args', [
    ((), L0, D_EFF, P_MIN, P_MAX),
    ((C0, math.nan), L0, D_EFF, P_MIN, P_MAX),
    ((C0, C1), 0.0, D_EFF, P_MIN, P_MAX),
    ((C0, C1), L0, -1.0, P_MIN, P_MAX),
    ((C0, C1), L0, D_EFF, P_MAX, P_MIN),
    ((C0, C1), L0, D_EFF, 1e3, 1e3),
])
def test_refuses_bad_arguments(args):
    with pytest.raises(ValueError):
        Stage1(*args)


# ------------------------------------- termination at the rounding level (issue 36)
ISSUE36 = (28.9, 576.94, -260.83722699795754, 298.82506635307084)   # a valid robot file's
ISSUE36_KPA = (-268.35083388056347, 23.49094129759813)             # k and limits [kPa]


def exact_residual(s, p, lam):
    """``k(lam) (lam - 1) l0 - p A`` of eq. (24) in exact rational arithmetic."""
    lam = Fraction(lam)
    k = sum(Fraction(c) * lam ** i for i, c in enumerate(s.coeffs))
    return k * (lam - 1) * Fraction(s.l0) - Fraction(p) * Fraction(s.area)


def assert_root_within_rounding(s, p, lam):
    """The exact root of eq. (24) lies within the rounding uncertainty of ``lam``.

    The computed residual of ``h(x) = k(1 + x) x`` can be wrong by about
    ``(2n + 2) eps (|x| sum (1 + i) |c_i| lam**i + |t|)`` (degree ``n``,
    ``t = p A / l0``); divided by ``dh/dx`` that is how far from the root no
    arithmetic can tell, plus the rounding of ``1 + x`` to ``lam``.
    """
    eps = np.finfo(float).eps
    x, t = lam - 1.0, p * s.area / s.l0
    c = np.abs(np.asarray(s.coeffs))
    size = sum((1 + i) * ci * lam ** i for i, ci in enumerate(c))
    slope = s.dpressure(lam) * s.area / s.l0
    assert slope > 0.0
    delta = 4.0 * np.spacing(lam) + 4.0 * 2 * c.size * eps * (abs(x) * size + abs(t)) / slope
    below, above = lam - delta, lam + delta
    assert exact_residual(s, p, below) < 0 < exact_residual(s, p, above), (p, lam, delta)


def test_issue36_two_iterates_one_rounding_step_apart_terminate():
    """Newton swung between two iterates 18 ulps apart at p_min until its budget raised (issue 36).

    Both residuals are about 6e-14 N/m, at the rounding level of evaluating
    k(lam) (lam - 1) near lam = 0.54: the solve stops there.
    """
    s = Stage1(ISSUE36, L0, 8.087 * 1e-3, ISSUE36_KPA[0] * 1e3, ISSUE36_KPA[1] * 1e3)
    assert s.lam_min == pytest.approx(0.5423, abs=1e-4)
    assert s.lam_max == pytest.approx(1.0189, abs=1e-4)
    for p, lam in ((s.p_min, s.lam_min), (s.p_max, s.lam_max)):
        assert_root_within_rounding(s, p, lam)
    p = np.linspace(s.p_min, s.p_max, 501)
    lam = s.stretch(p)
    assert np.all(np.diff(lam) > 0.0)
    for p_i, lam_i in zip(p[::50], lam[::50]):
        assert_root_within_rounding(s, p_i, lam_i)


def test_spent_budget_is_an_honest_value_error(monkeypatch):
    """A solve that does not finish names the pressure; construction refuses with a ValueError."""
    s = Stage1(CUBIC, L0, D_EFF, P_MIN, P_MAX)
    with pytest.raises(RuntimeError, match='did not converge in 1 iterations'):
        s._solve_newton(np.array([1.0]), max_iter=1)
    monkeypatch.setattr(Stage1, '_MAX_ITER', 1)
    with pytest.raises(ValueError, match='cannot be computed: .* -50000 Pa did not converge'):
        Stage1(CUBIC, L0, D_EFF, P_MIN, P_MAX)


@st.composite
def monotone_k(draw):
    """``k(lam)`` whose ``h(x) = k(1 + x) x`` has ``h' = a prod((x - r)^2 + s^2) > 0``."""
    dh = Polynomial([draw(st.floats(1.0, 1e4))])
    for _ in range(draw(st.integers(1, 3))):
        r = draw(st.floats(-1.0, 2.0))
        s = draw(st.floats(0.02, 2.0))
        dh = dh * Polynomial([r * r + s * s, -2.0 * r, 1.0])
    h = dh.integ()                                   # h(0) = 0
    return k_from_x(h.coef[1:])


@settings(max_examples=1000, deadline=None)
@given(coeffs=monotone_k(), lam_lo=st.floats(0.3, 0.99), lam_hi=st.floats(1.01, 2.0),
       u=st.floats(0.0, 1.0))
def test_every_monotone_polynomial_solves_to_rounding_level(coeffs, lam_lo, lam_hi, u):
    """Monotone k of degree 2..6: always accepted, stretches exact to the rounding level."""
    area = math.pi / 4.0 * D_EFF ** 2

    def pressure(lam):
        return float(Polynomial(coeffs)(lam) * (lam - 1.0) * L0 / area)

    s = Stage1(coeffs, L0, D_EFF, pressure(lam_lo), pressure(lam_hi))
    p = min(s.p_min + u * (s.p_max - s.p_min), s.p_max)
    for p_i, lam_i in zip((s.p_min, s.p_max, p), s.stretch(np.array([s.p_min, s.p_max, p]))):
        assert_root_within_rounding(s, p_i, lam_i)


@settings(max_examples=1000, deadline=None)
@given(high=st.lists(st.floats(-600.0, 600.0), min_size=1, max_size=4),
       p_min=st.floats(-400e3, -1.0), p_max=st.floats(1.0, 400e3))
# a negligible leading term: the companion matrix's roots lost the turn just below p_max
@example(high=[-502.0, 1.0, -2.5924714496828322e-68], p_min=-1.0, p_max=10791.0)
def test_random_higher_order_terms_accepted_or_refused(high, p_min, p_max):
    """The default k plus random terms (issue 36's family): a ValueError or exact stretches."""
    try:
        s = Stage1((C0, C1) + tuple(high), L0, D_EFF, p_min, p_max)
    except ValueError as exc:
        assert 'not monotonic' in str(exc) or 'cannot be reached' in str(exc), str(exc)
        return
    for p_i, lam_i in ((s.p_min, s.lam_min), (s.p_max, s.lam_max)):
        assert_root_within_rounding(s, p_i, lam_i)
