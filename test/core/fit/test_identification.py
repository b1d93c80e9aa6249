"""Parameter identification (paper section V): stiffness, D_eff and D_a.

The fits run on the shipped synthetic data (data/, generated from the paper's
fitted curves plus stated noise by data/make_synthetic.py) and must recover
the paper's values within that noise.
"""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from bellow_ancf_ros.core import Stage1, load_robot
from bellow_ancf_ros.core import identification as ident

REPO = Path(__file__).resolve().parents[3]
DATA = REPO / 'data'
TENSILE = DATA / 'tensile_test_segment.csv'
PRESSURE = DATA / 'pressure_force.csv'
K_PAPER = np.array([28.9, 576.94])
D_EFF_PAPER = 8.087e-3


@pytest.fixture(scope='module')
def cfg():
    return load_robot('one_segment')


# ------------------------------------------------------------ polynomials
def test_paper_fits_imply_l0_and_k():
    l0 = ident.l0_from_paper_fits()
    assert l0 == pytest.approx(576.94 / 5990.4)
    assert l0 == pytest.approx(0.0963, abs=2e-5)
    k = ident.stiffness_from_force_poly(ident.PAPER_F_COEFFS, l0)
    # slope exactly 576.94; the constant is 605.9 - 576.94 = 28.96 (the paper prints 28.9)
    assert k[1] == pytest.approx(576.94, rel=1e-12)
    assert k[0] == pytest.approx(28.96, rel=1e-12)


@pytest.mark.parametrize('coeffs', [(605.9,), (605.9, 5990.4), (609.6, 5523.4, 11986.9),
                                    (100.0, -2000.0, 3e4, 5e5)])
def test_force_and_stiffness_polynomials_are_inverse(coeffs):
    l0 = 0.0963
    k = ident.stiffness_from_force_poly(coeffs, l0)
    assert np.allclose(ident.force_poly_from_stiffness(k, l0), coeffs, rtol=1e-10, atol=1e-8)
    # F(dl) = k(lam) * dl at arbitrary points
    dl = np.linspace(-0.01, 0.03, 7)
    lam = 1.0 + dl / l0
    F = dl * np.polynomial.polynomial.polyval(dl, coeffs)
    assert np.allclose(np.polynomial.polynomial.polyval(lam, k) * dl, F, rtol=1e-10, atol=1e-12)


def test_noise_free_fit_of_any_order_is_exact():
    l0 = 0.08
    a = (300.0, 4000.0, -2.0e4)
    dl = np.linspace(-0.008, 0.025, 30)
    F = dl * np.polynomial.polynomial.polyval(dl, a)
    fit = ident.fit_stiffness(dl, F, order=3, l0=l0, force_per='actuator')
    assert np.allclose(fit.f_coeffs, a, rtol=1e-9)
    assert np.allclose(fit.k_coeffs, ident.stiffness_from_force_poly(a, l0), rtol=1e-9)
    assert fit.r2 == pytest.approx(1.0, abs=1e-12)
    assert fit.rms_n < 1e-10


# ------------------------------------------------------ shipped data
def test_shipped_data_is_marked_synthetic_and_documented():
    for path in (TENSILE, PRESSURE):
        lines = path.read_text().splitlines()
        assert lines[0].startswith('# synthetic:'), path
        assert any(line.startswith('# columns:') for line in lines), path


def test_shipped_data_is_what_the_generator_makes(tmp_path):
    spec = importlib.util.spec_from_file_location('make_synthetic', DATA / 'make_synthetic.py')
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    for path in mod.write(str(tmp_path)):
        assert Path(path).read_text() == (DATA / Path(path).name).read_text()


def test_stiffness_fit_recovers_the_paper_k_within_the_noise(cfg):
    data = ident.read_table(str(TENSILE))
    fg = ident.default_gravity_share(cfg, 'segment')
    assert fg == pytest.approx(9.81 * 0.010 / 3)
    fit = ident.fit_stiffness(data['dl_mm'] * 1e-3, data['force_n'], order=2, l0=cfg.l0,
                              force_per='segment', n_actuators=3, gravity_share_n=fg)
    print('k =', fit.k_coeffs, '+-', fit.k_coeffs_stderr, 'R2', fit.r2, 'RMS', fit.rms_n)
    k, se = np.array(fit.k_coeffs), np.array(fit.k_coeffs_stderr)
    assert np.all(np.abs(k - K_PAPER) < 3.0 * se)
    assert k[1] == pytest.approx(576.94, rel=0.01)
    assert k[0] == pytest.approx(28.9, abs=3.0)
    # stated noise: 0.20 N on the segment force -> 0.067 N per actuator
    assert fit.rms_n == pytest.approx(0.20 / 3, rel=0.3)
    assert fit.r2 > 0.9999
    # the derived k is usable by stage 1 of the robot
    Stage1(fit.k_coeffs, cfg.l0, cfg.d_eff, cfg.p_min, cfg.p_max)


def test_segment_and_actuator_modes_agree():
    dl = np.linspace(-0.004, 0.02, 25)
    fe = 605.84 * dl + 5991.0 * dl ** 2
    a = ident.fit_stiffness(dl, 3 * (fe + 0.05), force_per='segment', n_actuators=3,
                            gravity_share_n=0.05)
    b = ident.fit_stiffness(dl, fe, force_per='actuator')
    assert np.allclose(a.k_coeffs, b.k_coeffs, rtol=1e-9)


def test_deff_fit_recovers_the_paper_value_with_a_confidence_interval():
    data = ident.read_table(str(PRESSURE))
    fit = ident.fit_deff(data['pressure_kpa'] * 1e3, data['force_n'])
    lo, hi = fit.d_eff_ci_m
    print(f'D_eff = {fit.d_eff_m * 1e3:.4f} mm [{lo * 1e3:.4f}, {hi * 1e3:.4f}]')
    assert lo < D_EFF_PAPER < hi
    assert fit.d_eff_m == pytest.approx(D_EFF_PAPER, rel=0.005)
    assert hi - lo < 0.1e-3
    assert fit.rms_n == pytest.approx(0.05, rel=0.3)
    # a wider confidence level gives a wider interval
    wide = ident.fit_deff(data['pressure_kpa'] * 1e3, data['force_n'], confidence=0.99)
    assert wide.d_eff_ci_m[0] < lo and wide.d_eff_ci_m[1] > hi


def test_deff_from_measured_lengths(cfg):
    st = Stage1.from_config(cfg)
    p = np.linspace(-30e3, 150e3, 10)
    length = np.asarray(st.stretch(p)) * cfg.l0
    f = ident.actuation_force_from_length(length, cfg.stiffness_coeffs, cfg.l0)
    fit = ident.fit_deff(p, f)
    assert fit.d_eff_m == pytest.approx(cfg.d_eff, rel=1e-9)


def test_bad_input_is_refused():
    with pytest.raises(ValueError):
        ident.fit_stiffness([0.001, 0.002], [1.0, 2.0], order=3)
    with pytest.raises(ValueError):
        ident.fit_stiffness([0.001, 0.002, np.nan], [1.0, 2.0, 3.0])
    with pytest.raises(ValueError):
        ident.fit_deff([1.0, 2.0, 3.0], [3.0, 2.0, 1.0])  # force falls with pressure
    with pytest.raises(ValueError):
        ident.fit_deff([1.0, 1.0, 1.0], [1.0, 2.0, 3.0])


def test_read_table_reports_the_bad_line(tmp_path):
    f = tmp_path / 'x.csv'
    f.write_text('# comment\na,b\n1,2\n3,oops\n')
    with pytest.raises(ValueError, match='line 4'):
        ident.read_table(str(f))
    f.write_text('# only comments\n')
    with pytest.raises(ValueError, match='no header'):
        ident.read_table(str(f))
    f.write_text('A, B \n1,2\n\n3,4\n')
    data = ident.read_table(str(f))
    assert list(data) == ['a', 'b'] and data['b'].tolist() == [2.0, 4.0]


# ------------------------------------------------------------------ D_a
def test_da_from_the_paper_drop_is_17_90_mm(cfg):
    res = ident.identify_da(cfg, 34.35e-3, ident.PAPER_END_MASS_KG)
    print(f'D_a = {res.D_a_m * 1e3:.5f} mm, {res.iterations} iterations, '
          f'{res.function_calls} solves')
    assert res.converged
    assert res.D_a_m * 1e3 == pytest.approx(17.90, abs=0.005)
    assert res.model_drop_m == pytest.approx(34.35e-3, abs=1e-8)
    assert res.n_elements == 20
    assert res.bracket_m[0] <= res.D_a_m <= res.bracket_m[1]
    # eq. 2 and eq. 4 at lam = 1
    k1 = 28.9 + 576.94
    assert res.kt_n == pytest.approx(k1 * cfg.l0)
    assert res.kb_n_m2 == pytest.approx(res.D_a_m ** 2 * cfg.l0 * k1 / 8)


def test_the_end_mass_that_maps_34_35_mm_onto_17_90_mm(cfg):
    m = ident.tip_mass_for_da(cfg, 17.90e-3, 34.35e-3)
    print(f'end mass {m * 1e3:.4f} g')
    assert m == pytest.approx(ident.PAPER_END_MASS_KG, abs=1e-5)
    assert 0.023 < m < 0.025  # "near 24 g"


def test_da_drop_is_monotone_and_bad_drops_are_refused(cfg):
    soft = ident.identify_da(cfg, 40e-3, ident.PAPER_END_MASS_KG)
    assert soft.D_a_m < 17.90e-3
    with pytest.raises(ValueError):
        ident.identify_da(cfg, 0.0, 0.02)
    with pytest.raises(ValueError):
        ident.identify_da(cfg, 0.95 * cfg.l0, 0.02)
