"""A horizontally cantilevered actuator against beam theory (own weight + tip load).

Three references (test/reference_beams.py): the small-deflection formula, the
classical inextensible elastica, and the exact continuum limit of the spec's
own energy (Green strain, ``|r_xx|^2``), each solved as a boundary value
problem.  The spec's energy is a little softer than the elastica (finite
``k_t``): that is the model, not an error.
"""

import numpy as np
import pytest

import reference_beams as rb
from bellow_ancf_ros.core import load_robot
from bellow_ancf_ros.core.fit._cantilever import Cantilever

G = 9.81


@pytest.fixture(scope="module")
def beam():
    """Unactuated default actuator (lam = 1) and the tip mass for a drop of 35 % of its length."""
    cfg = load_robot("one_segment")
    L = cfg.l0
    k1 = float(np.polyval(cfg.stiffness_coeffs[::-1], 1.0))
    kt = k1 * L  # eq. 2
    kb = cfg.d_a**2 * L * k1 / 8  # eq. 4
    w = cfg.rho0 * G
    m = rb.tip_mass_for_drop_fraction(L, kb, w, 0.35, g=G, model="elastica")
    return dict(L=L, kt=kt, kb=kb, rho=cfg.rho0, w=w, m=m)


def _ancf(beam, m, n):
    res = Cantilever(beam["L"], beam["kt"], beam["kb"], beam["rho"], m, n=n, g=G).solve()
    assert res.converged, res.message
    return res


def test_small_loads_match_the_small_deflection_formula(beam):
    # tiny loads: one hundredth of the weight, a 0.1 g tip mass
    b = dict(beam, rho=beam["rho"] * 0.01)
    res = _ancf(b, 1e-4, 8)
    lin = rb.small_deflection_tip_drop(b["L"], b["kb"], b["rho"] * G, 1e-4 * G)
    assert res.tip_drop == pytest.approx(lin, rel=2e-3)


def test_large_deflection_matches_the_classical_elastica_within_1_percent(beam):
    x_tip, drop = rb.elastica_tip(beam["L"], beam["kb"], beam["w"], beam["m"] * G)
    res = _ancf(beam, beam["m"], 6)
    assert drop / beam["L"] == pytest.approx(0.35, rel=1e-6)
    rel = (res.tip_drop - drop) / drop
    print(f"tip drop: ANCF n=6 {res.tip_drop * 1e3:.4f} mm, elastica {drop * 1e3:.4f} mm "
          f"({100 * rel:+.3f} %)")
    assert abs(rel) < 0.01
    assert res.tip[0] == pytest.approx(x_tip, rel=0.01)
    # the model is slightly softer than the inextensible elastica
    assert 0.002 < rel < 0.006


def test_converges_to_the_continuum_limit_of_its_own_energy_at_least_like_h3(beam):
    _, drop = rb.spec_continuum_tip(beam["L"], beam["kt"], beam["kb"], beam["w"], beam["m"] * G)
    ns = [2, 4, 8, 16]
    errs = [abs(_ancf(beam, beam["m"], n).tip_drop - drop) for n in ns]
    print("continuum drop %.6f mm; errors:" % (drop * 1e3), ["%.2e" % e for e in errs])
    assert errs[-1] < 1e-5 * drop
    for (n0, e0), (n1, e1) in zip(zip(ns, errs), zip(ns[1:], errs[1:])):
        order = np.log(e0 / e1) / np.log(n1 / n0)
        assert order > 3.0, (ns, errs)
