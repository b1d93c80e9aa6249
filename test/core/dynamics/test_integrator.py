"""The generalized-alpha integrator (docs/dynamics.md): rest, free vibration, energy, order."""

import json
from pathlib import Path
import sys

import numpy as np
import pytest

from bellow_ancf_ros.core import DynamicsStatus, TipLoad, solve_forward
from bellow_ancf_ros.core.dynamics import GeneralizedAlpha, PressureRamp, default_step


ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "bench"))
import integrator_checks  # noqa: E402

ROBOTS = {1: "one", 2: "two", 3: "three"}


@pytest.fixture(scope="module")
def recorded():
    """docs/dynamics.md's table is the committed run file's."""
    with open(integrator_checks.OUT) as f:
        return json.load(f)


def test_the_docs_show_the_integrator_table_of_the_run_file(recorded):
    assert integrator_checks.doc_block() == integrator_checks.markdown(recorded)


@pytest.mark.parametrize("m", [1, 2, 3])
def test_rest_state_is_the_static_solution(m, recorded, request):
    """At constant pressures the state stays at the static solution.

    After a pressure and a payload step it comes to rest at the new static
    solution (to 1e-9 m); the committed figures are below the same bounds.
    """
    model = request.getfixturevalue(ROBOTS[m])
    for r in (integrator_checks.rest_state(model, *integrator_checks.REST_PRESSURES[m]),
              recorded["rest"][str(m)]):
        assert r["success"], r["message"]
        assert r["held_m"] < 1e-12 and r["held_violation_m"] < 1e-12
        assert r["position_m"] < 1e-9
        assert r["rotation"] < 1e-8 and r["coordinates"] < 1e-8
        assert r["speed"] < 1e-6


@pytest.mark.parametrize("m", [1, 2])
def test_free_vibration_has_the_modal_frequency_and_damping(m, recorded, request):
    model = request.getfixturevalue(ROBOTS[m])
    r = integrator_checks.free_vibration(model, *integrator_checks.RELEASES[m])
    assert r["success"]
    mode = r["modal_frequency_hz"]
    assert r["step_s"] == pytest.approx(default_step(mode), rel=1e-3)
    assert r["frequency_hz"] == pytest.approx(mode, rel=0.005)
    assert r["damping_ratio"] == pytest.approx(r["modal_damping_ratio"], rel=0.10)
    np.testing.assert_allclose(r["direction"], [1, 0, 0], atol=1e-3)
    # the integrator is deterministic: the committed run's figures are these
    rec = recorded["release"][str(m)]
    for key in ("step_s", "frequency_hz", "modal_frequency_hz", "damping_ratio",
                "modal_damping_ratio"):
        assert r[key] == pytest.approx(rec[key], rel=1e-6), key


def test_undamped_energy_is_conserved_and_constraints_hold(one, recorded):
    r = integrator_checks.undamped(one)
    assert r["success"] and r["vibration_energy_j"] > 0
    assert r["energy_drift"] < 1e-3
    assert r["violation_m"] < 1e-9
    rec = recorded["undamped"]
    assert r["vibration_energy_j"] == pytest.approx(rec["vibration_energy_j"], rel=1e-6)
    assert r["energy_drift"] == pytest.approx(rec["energy_drift"], rel=1e-3)
    assert rec["violation_m"] < 1e-9


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


@pytest.mark.parametrize("settings", [{}, {"tol": 1e-12, "max_iter": 3}])
def test_a_pressure_ramp_is_the_same_function_of_time(one, settings):
    """A PressureRamp (its table: one call per run) gives the steps its values as a function do.

    ``tol 1e-12, max_iter 3``: steps that fail and are halved (the ramp asked between steps).
    """
    fw = solve_forward(one, np.zeros(3), tip_force_n=[0.1, 0.0, 0.0])
    a = GeneralizedAlpha(one, step_s=0.002, **settings)
    b = GeneralizedAlpha(one, step_s=0.002, **settings)
    a.start_released(fw)
    b.start_released(fw)
    p0 = np.zeros(3)
    halved = 0
    for k, t1 in enumerate([0.0045, 0.009, 0.0101, 0.02, 0.02, 0.031]):
        p1 = np.array([20e3 * (1.0 - np.cos(40.0 * t1)), 3e3 * k, 0.0])
        t0 = a.state.t
        ramp = PressureRamp(t0, t1, p0, p1)
        span = max(t1 - t0, 1e-12)
        ra = a.advance(t1, pressures_pa=ramp)
        rb = b.advance(t1, pressures_pa=lambda t: p0 + (min(t, t1) - t0) / span * (p1 - p0))
        assert ra.success and rb.success and (ra.steps, ra.halvings) == (rb.steps, rb.halvings)
        halved += ra.halvings
        for name in ("q", "v", "acc", "aux", "mu", "stretch"):
            np.testing.assert_array_equal(getattr(a.state, name), getattr(b.state, name))
        assert a.state.t == b.state.t
        times = np.array([t0, 0.5 * (t0 + t1), t1, t1 + 1.0])
        np.testing.assert_array_equal(ramp.table(times), np.array([ramp(t) for t in times]))
        p0 = p1
    assert a.counters == b.counters and (halved > 0) == bool(settings)
    _, run = a.advance_through([0.035, 0.04], pressures_pa=PressureRamp(0.031, 0.04, p0, 2 * p0))
    np.testing.assert_array_equal(run.pressures_pa[1], 2 * p0)


@pytest.mark.parametrize("settings", [{}, {"tol": 1e-12, "max_iter": 3}])
def test_a_run_through_many_ends_is_advancing_to_each_in_turn(one, settings):
    """advance_through: one compiled run, the same states as advance end by end.

    ``tol 1e-12, max_iter 3``: steps that fail and are halved (Python's path).
    """
    fw = solve_forward(one, np.zeros(3), tip_force_n=[0.1, 0.0, 0.0])

    def p(t):
        return np.array([20e3 * (1.0 - np.cos(40.0 * t)), 0.0, 5e3 * t])
    ends = [0.003, 0.0071, 0.0071, 0.02, 0.05]
    check = [False, True, True, False, True]   # (0.0071 twice: no step between, one record)
    a = GeneralizedAlpha(one, step_s=0.002, **settings)
    b = GeneralizedAlpha(one, step_s=0.002, **settings)
    a.start_released(fw)
    b.start_released(fw)
    rep, run = a.advance_through(ends, pressures_pa=p, check=check)
    assert rep.success and rep.steps > 0
    if settings:
        assert rep.halvings > 0
    for j, t in enumerate(ends):
        r = b.advance(t, pressures_pa=p)
        assert r.success
        assert run.times_s[j] == b.state.t
        pos, rot = b.end_effector()
        x, r_ = one.end_effectors(run.plate[j])
        np.testing.assert_array_equal(x[0], pos)
        np.testing.assert_array_equal(r_[0], rot)
        np.testing.assert_array_equal(run.pressures_pa[j], p(b.state.t))
        e, worst = b.checks()
        if check[j]:
            assert run.checks[j].tolist() == [e["kinetic_j"], e["potential_j"], worst]
        else:
            assert np.all(np.isnan(run.checks[j]))
    np.testing.assert_array_equal(a.state.q, b.state.q)
    np.testing.assert_array_equal(a.state.mu, b.state.mu)
    assert a.counters == b.counters


def test_a_time_budget_stops_between_steps(one):
    fw = solve_forward(one, np.zeros(3), tip_force_n=[0.1, 0.0, 0.0])
    ig = GeneralizedAlpha(one, step_s=0.002)
    ig.start_released(fw)
    rep = ig.advance(0.1, time_budget_s=0.0)
    assert rep.status == DynamicsStatus.TIME_BUDGET and rep.steps == 0 and ig.state.t == 0.0
    rep = ig.advance(10.0, time_budget_s=0.05)
    assert rep.status == DynamicsStatus.TIME_BUDGET and 0 < rep.steps < 5000
    assert ig.state.t == pytest.approx(0.002 * rep.steps) and "at t = " in rep.message
    assert ig.advance(ig.state.t + 0.01).success   # and it goes on from there


def test_second_order_by_step_halving(one, recorded):
    r = integrator_checks.step_halving(one)
    e = r["errors_m"]
    assert 3.0 < e[0] / e[1] < 5.5 and 3.0 < e[1] / e[2] < 5.5, e
    np.testing.assert_allclose(e, recorded["halving"]["errors_m"], rtol=1e-4)


def test_a_chord_matrix_gone_stale_is_made_afresh_when_its_extra_iterations_add_up(one):
    """A large fast motion (12 mm of swing at 2 Hz) at the simulated robot's tolerance.

    The chord matrix made at rest converges slower and slower as the robot
    moves away from where it was made (at rates below the refactorisation's
    threshold): kept for the whole run, the steps took 4.2 iterations each
    and ended 1.9e-8 m from a run at tol 1e-13.  Made afresh once the
    steps' extra iterations add up to about a factorisation, they take 3.0,
    and end closer to that run.
    """
    def pressures(t):
        w = 2 * np.pi * 2.0 * t
        return np.array([60e3 * (1 - np.cos(w)), 30e3 * (1 - np.cos(w + 1)), 0.0])

    runs = []
    for tol in (1e-7, 1e-13):
        ig = GeneralizedAlpha(one, tol=tol)
        ig.start(solve_forward(one, np.zeros(3)))
        pos = []
        for k in range(1, 51):
            assert ig.advance(0.01 * k, pressures_pa=pressures).success
            pos.append(ig.end_effector()[0])
        runs.append((np.array(pos), dict(ig.counters)))
    (pos, c), (ref, _) = runs
    assert np.ptp(ref[:, 0]) > 0.01
    assert c["iterations"] < 3.5 * c["steps"] and c["factorizations"] > 1
    assert np.abs(pos - ref).max() < 2e-9


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
