"""The generalized-alpha integrator (docs/dynamics.md): rest, free vibration, energy, order."""

import numpy as np
import pytest

from bellow_ancf_ros.core import DynamicsStatus, TipLoad, solve_forward
from bellow_ancf_ros.core.dynamics import GeneralizedAlpha, default_step, natural_modes
from bellow_ancf_ros.core.fit import fit_free_vibration


@pytest.mark.parametrize("robot,p1,p2", [
    ("one", [0.0, 0.0, 0.0], [120e3, -30e3, 10e3]),
    ("two", [0.0] * 6, [60e3, 0.0, -20e3, 0.0, 40e3, 0.0]),
    ("three", [0.0] * 9, [30e3, 0.0, 0.0, 0.0, 30e3, 0.0, 0.0, 0.0, 30e3]),
])
def test_rest_state_is_the_static_solution(robot, p1, p2, request):
    """At constant pressures the state stays at the static solution.

    After a pressure and a payload step it comes to rest at the new static
    solution (to 1e-9 m).
    """
    model = request.getfixturevalue(robot)
    fw1 = solve_forward(model, p1)
    fw2 = solve_forward(model, p2, payload_kg=0.01)
    # air damping near critical for the first mode at the end: a short settling
    w1 = 2 * np.pi * natural_modes(fw2, 1).first.frequency_hz
    ig = GeneralizedAlpha(model, step_s=0.005, mass_damping_per_s=1.6 * w1)
    ig.start(fw1)
    rep = ig.advance(0.3)
    assert rep.success
    np.testing.assert_allclose(ig.end_effector()[0], fw1.position, rtol=0, atol=1e-12)
    assert ig.constraint_violation() < 1e-12
    rep = ig.advance(0.3 + 40.0 / w1, pressures_pa=np.asarray(p2), load=0.01)
    assert rep.success, rep.message
    pos, rot = ig.end_effector()
    np.testing.assert_allclose(pos, fw2.position, rtol=0, atol=1e-9)
    np.testing.assert_allclose(rot, fw2.rotation, rtol=0, atol=1e-8)
    np.testing.assert_allclose(ig.static_coordinates(), fw2.q, rtol=0, atol=1e-8)
    assert np.abs(ig.state.v).max() < 1e-6


@pytest.mark.parametrize("robot,force,window", [("one", 0.01, (0.05, 0.45)),
                                                ("two", 0.002, (0.3, 4.0))])
def test_free_vibration_has_the_modal_frequency_and_damping(robot, force, window, request):
    model = request.getfixturevalue(robot)
    p = np.zeros(model.A)
    mode = natural_modes(solve_forward(model, p), 1).first
    fw = solve_forward(model, p, tip_force_n=[force, 0, 0])
    ig = GeneralizedAlpha(model)
    ig.start_released(fw)
    assert ig.step_s == pytest.approx(default_step(mode.frequency_hz), rel=1e-3)
    t, x = [], []
    while ig.state.t < window[1]:
        assert ig.advance(ig.state.t + ig.step_s).success
        t.append(ig.state.t)
        x.append(ig.end_effector()[0])
    fit = fit_free_vibration(t, x, *window)
    assert fit.frequency_hz == pytest.approx(mode.frequency_hz, rel=0.005)
    assert fit.damping_ratio == pytest.approx(mode.damping_ratio, rel=0.10)
    np.testing.assert_allclose(fit.direction, [1, 0, 0], atol=1e-3)


def test_undamped_energy_is_conserved_and_constraints_hold(one):
    p = np.array([40e3, 0.0, 0.0])
    rest = solve_forward(one, p)
    fw = solve_forward(one, p, tip_force_n=[0.01, 0.005, 0])
    f1 = natural_modes(rest, 1).first.frequency_hz
    ig = GeneralizedAlpha(one, rho_inf=1.0, damping_time_s=0.0, mass_damping_per_s=0.0)
    ig.start_released(fw)
    e_rest = ig.energy(ig.state)["total_j"] - ig.energy(ig.state)["kinetic_j"]
    e_rest = float(one.potential(rest.q, rest.stretch, 1.0, 0.0))
    e0 = ig.energy()["total_j"] - e_rest  # the vibration's energy
    assert e0 > 0
    worst_e, worst_c = 0.0, 0.0
    while ig.state.t < 20 / f1:
        assert ig.advance(ig.state.t + 10 * ig.step_s).success
        worst_e = max(worst_e, abs(ig.energy()["total_j"] - e_rest - e0))
        worst_c = max(worst_c, ig.constraint_violation())
    assert worst_e < 1e-3 * e0
    assert worst_c < 1e-9


@pytest.mark.parametrize("robot", ["one", "two"])
def test_compiled_checks_are_the_models_energy_and_constraints(robot, request):
    """``checks`` (one compiled call) equals the numpy read-outs at a moving, loaded state."""
    model = request.getfixturevalue(robot)
    p = np.zeros(model.A)
    p[0] = 40e3
    fw = solve_forward(model, p, payload_kg=0.02, tip_force_n=[0.05, -0.03, 0.0])
    ig = GeneralizedAlpha(model, mass_damping_per_s=0.5)
    ig.start_released(fw, load_after=TipLoad(0.02, (0.0, 0.01, 0.0)))
    p2 = p.copy()
    p2[-1] = 25e3
    assert ig.advance(0.03, pressures_pa=p2).success
    st = ig.state
    energy, violation = ig.checks()
    qs = ig.static_coordinates()
    kinetic = ig.inertia.kinetic_energy(st.v, st.load)
    potential = float(model.potential(qs, st.stretch, 1.0, st.load))
    assert kinetic > 1e-6
    assert energy["kinetic_j"] == pytest.approx(kinetic, rel=1e-12)
    assert energy["potential_j"] == pytest.approx(potential, rel=1e-12, abs=1e-15)
    assert energy["total_j"] == pytest.approx(kinetic + potential, rel=1e-12)
    assert ig.energy() == energy
    res = model.evaluate(np.concatenate([qs, st.mu]), st.stretch, 1.0, st.load,
                         jacobian=False).residual
    assert violation == ig.constraint_violation() == pytest.approx(
        np.abs(res[model.nq:]).max(), rel=1e-9, abs=1e-17)
    # a state off the constraints shows its violation
    off = st.copy()
    off.q = off.q + 1e-4
    res = model.evaluate(np.concatenate([ig.static_coordinates(off), off.mu]), off.stretch,
                         1.0, off.load, jacobian=False).residual
    assert ig.constraint_violation(off) == pytest.approx(np.abs(res[model.nq:]).max(),
                                                         rel=1e-12)
    # the end effector read straight from the material coordinates
    pos, rot = ig.end_effector()
    ref_pos, ref_rot = model.end_effector(qs)
    np.testing.assert_array_equal(pos, ref_pos)
    np.testing.assert_array_equal(rot, ref_rot)


def test_constant_pressures_are_mapped_once_and_follow_a_change(one):
    """Constant pressures give the same steps as the same pressures as a function of time."""
    fw = solve_forward(one, np.zeros(3), tip_force_n=[0.05, 0.0, 0.0])
    a = GeneralizedAlpha(one, step_s=0.002)
    b = GeneralizedAlpha(one, step_s=0.002)
    a.start_released(fw)
    b.start_released(fw)
    p1, p2 = np.array([30e3, 0.0, 0.0]), np.array([0.0, 20e3, 0.0])
    for k in range(1, 6):
        assert a.advance(0.004 * k, pressures_pa=p1).success
    p1[0] = 99e3   # the caller's array changes: the next call maps it afresh
    for k in range(6, 9):
        assert a.advance(0.004 * k, pressures_pa=p1).success
    for k in range(9, 12):
        assert a.advance(0.004 * k, pressures_pa=p2).success
    for k in range(1, 12):
        q = [30e3, 0.0, 0.0] if k < 6 else [99e3, 0.0, 0.0] if k < 9 else [0.0, 20e3, 0.0]
        assert b.advance(0.004 * k, pressures_pa=lambda t, q=q: q).success
    np.testing.assert_array_equal(a.state.q, b.state.q)
    np.testing.assert_array_equal(a.state.stretch, one.stage1.stretch(p2))


def test_second_order_by_step_halving(one):
    fw = solve_forward(one, [50e3, 0.0, 0.0], tip_force_n=[0.0, 0.01, 0.0])

    def tip(h):
        ig = GeneralizedAlpha(one, step_s=h)
        ig.start_released(fw)
        assert ig.advance(0.12, pressures_pa=lambda t: [50e3 + 2e5 * t, 0.0, 0.0]).success
        return ig.end_effector()[0]

    h = 0.004
    ref = tip(h / 32)
    e = [np.linalg.norm(tip(h / k) - ref) for k in (1, 2, 4)]
    assert 3.0 < e[0] / e[1] < 5.5 and 3.0 < e[1] / e[2] < 5.5, e


def test_a_step_that_cannot_converge_is_reported_not_taken(one):
    fw = solve_forward(one, np.zeros(3))
    ig = GeneralizedAlpha(one, step_s=0.002, tol=0.0, max_iter=2, max_halvings=1)
    ig.start(fw)
    rep = ig.advance(0.01, pressures_pa=[100e3, 0.0, 0.0])
    assert not rep.success and rep.status == DynamicsStatus.STEP_TOO_SMALL
    assert ig.state.t == 0.0 and "at t = 0 s" in rep.message
    np.testing.assert_array_equal(ig.static_coordinates(), fw.q)


def test_bad_settings_named(one):
    with pytest.raises(ValueError, match="rho_inf = 2 is not allowed"):
        GeneralizedAlpha(one, rho_inf=2)
    with pytest.raises(ValueError, match="step_s = -1.0 is not allowed"):
        GeneralizedAlpha(one, step_s=-1.0)
