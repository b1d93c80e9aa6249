"""Tip compliance and stiffness (issue 20, item 2): exact, symmetric, the finite differences'."""

import numpy as np
import pytest

from bellow_ancf_ros.core import solve_forward, solve_inverse, tip_compliance


def _finite_differences(model, p, payload, force, h=1e-3):
    """Central differences of whole forward solves: d position / dF and d z-axis / dF."""
    dp, dz = np.empty((3, 3)), np.empty((3, 3))
    base = solve_forward(model, p, payload_kg=payload, tip_force_n=force)
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        a = solve_forward(model, p, payload_kg=payload, tip_force_n=np.add(force, e),
                          warm_start=base, tol=1e-13)
        b = solve_forward(model, p, payload_kg=payload, tip_force_n=np.subtract(force, e),
                          warm_start=base, tol=1e-13)
        dp[:, j] = (a.position - b.position) / (2 * h)
        dz[:, j] = (a.z_axis - b.z_axis) / (2 * h)
    return dp, dz


@pytest.mark.parametrize('name, p, payload, force', [
    ('one_segment', [0.0, 0.0, 0.0], 0.0, [0.0, 0.0, 0.0]),
    ('one_segment', [80e3, 10e3, -20e3], 0.05, [0.1, -0.05, 0.0]),
    ('two_segment', [30e3, 0.0, 10e3, 5e3, 40e3, 0.0], 0.02, [0.0, 0.02, -0.05]),
])
def test_compliance_is_the_finite_differences_of_forward_solves_and_symmetric(
        name, p, payload, force, one, two):
    model = one if name == 'one_segment' else two
    fw = solve_forward(model, p, payload_kg=payload, tip_force_n=force, tol=1e-13)
    assert fw.success
    c = tip_compliance(fw)
    dp, dz = _finite_differences(model, p, payload, force)
    scale = np.max(np.abs(dp))
    np.testing.assert_allclose(c.translational_m_per_n, dp, rtol=0, atol=1e-6 * scale)
    np.testing.assert_allclose(c.axis_per_n, dz, rtol=0, atol=1e-6 * np.max(np.abs(dz)))
    C = c.translational_m_per_n
    np.testing.assert_allclose(C, C.T, rtol=0, atol=1e-9 * scale)   # Maxwell-Betti
    assert np.all(np.linalg.eigvalsh(0.5 * (C + C.T)) > 0)           # stable: positive definite
    np.testing.assert_allclose(c.stiffness_n_per_m @ C, np.eye(3), atol=1e-9)
    # the z-axis stays a unit vector to first order: its change is normal to it
    assert np.max(np.abs(fw.z_axis @ c.axis_per_n)) < 1e-8 * np.max(np.abs(c.axis_per_n))
    d = c.to_dict()
    assert set(d) == {'translational_compliance_m_per_n', 'axis_compliance_per_n',
                      'stiffness_n_per_m'}
    assert np.array(d['stiffness_n_per_m']).shape == (3, 3)


def test_compliance_of_an_inverse_answer_and_of_a_failed_solve(two):
    fw0 = solve_forward(two, [30e3, 20e3, 10e3, 40e3, 0.0, 5e3])
    inv = solve_inverse(two, fw0.position + [1e-3, 0.0, 0.0], fw0.z_axis)
    again = solve_forward(two, inv.pressures_pa)
    np.testing.assert_allclose(tip_compliance(inv.forward).translational_m_per_n,
                               tip_compliance(again).translational_m_per_n, rtol=1e-7, atol=0)
    failed = solve_forward(two, np.zeros(6), iteration_budget=1)
    assert not failed.converged
    with pytest.raises(ValueError, match='no compliance without a converged equilibrium'):
        tip_compliance(failed)


def test_vented_vertical_stiffness_is_the_actuators_spring_rates(one):
    """Vented and straight, a vertical force stretches the three actuators in parallel.

    Their spring rate at ``lam = 1`` is ``k(1)`` (the paper's fit ``k = 576.94 lam + 28.9``
    N/m): ``3 k(1)`` = 1817.5 N/m, less a little bending under gravity.
    """
    c = tip_compliance(solve_forward(one, np.zeros(3)))
    k1 = sum(one.cfg.stiffness_coeffs)
    assert c.vertical_stiffness_n_per_m == pytest.approx(3 * k1, rel=0.01)
    assert c.vertical_stiffness_n_per_m < 3 * k1
