"""Tip forces in the forward and inverse problems (issue 20): eq. (14) at the end effector.

Checked: the generalised force is the virtual work of the force at the end
effector (finite differences of the end-effector position); a force equal to
a payload's weight gives the payload's answer exactly; the equilibrium under
a force has zero residual and the robot yields towards the force, linearly
for small forces and by the same amount in every horizontal direction of a
symmetric robot; the inverse reaches targets under a force and a forward
solve under the same force reproduces them; warm starts made under another
force are re-solved, not trusted; bad forces are refused with the key, the
value and what is allowed; a force beyond the buckling load ends in a status
that names it.
"""

import numpy as np
import pytest

from bellow_ancf_ros.core import (ForwardStatus, InverseStatus, TipLoad, solve_forward,
                                  solve_inverse)
from bellow_ancf_ros.core.model import MAX_TIP_FORCE_N

G = np.array([0.0, 0.0, -9.81])


def test_generalised_force_is_the_virtual_work_at_the_end_effector(two):
    """Q . dq = F . dx_p for any dq (eq. 14 with x_p at the end effector, tool length too)."""
    model = two
    rng = np.random.default_rng(1)
    fw = solve_forward(model, [30e3, 10e3, 0.0, 20e3, 40e3, 5e3])
    F = np.array([0.3, -0.2, 0.7])
    Q = model.point_forces(TipLoad(0.0, tuple(F))) - model.point_forces(0.0)
    for _ in range(5):
        dq = rng.normal(size=model.nq) * 1e-7
        dx = model.end_effector(fw.q + dq)[0] - model.end_effector(fw.q)[0]
        assert Q @ dq == pytest.approx(F @ dx, rel=1e-6, abs=1e-15)


def test_a_force_equal_to_a_payloads_weight_is_that_payload(one, two):
    for model, p in ((one, [40e3, 0.0, 10e3]), (two, [30e3, 0.0, 10e3, 5e3, 40e3, 0.0])):
        m = 0.05
        a = solve_forward(model, p, payload_kg=m)
        b = solve_forward(model, p, tip_force_n=m * G)
        assert a.success and b.success
        np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-12)
        target = a.position + [2e-3, -1e-3, 1e-3]
        z = None if model.cfg.n_segments == 1 else a.z_axis
        ia = solve_inverse(model, target, z, payload_kg=m)
        ib = solve_inverse(model, target, z, tip_force_n=m * G)
        assert ia.success and ib.success
        np.testing.assert_allclose(ib.pressures_pa, ia.pressures_pa, rtol=0, atol=1e-6)


def test_the_robot_yields_towards_a_force_linearly_and_alike_in_every_direction(one):
    p = [20e3, 20e3, 20e3]
    base = solve_forward(one, p)
    moves = []
    for ang in np.radians([0.0, 50.0, 120.0, 200.0]):
        d = np.array([np.cos(ang), np.sin(ang), 0.0])
        small = solve_forward(one, p, tip_force_n=0.01 * d)
        double = solve_forward(one, p, tip_force_n=0.02 * d)
        assert small.success and double.success
        ev = one.evaluate(small.x, small.stretch, 1.0, small.load, jacobian=False)
        assert np.max(np.abs(ev.residual * one.residual_scale)) < 1e-9
        du = small.position - base.position
        assert du @ d > 0.9 * np.linalg.norm(du)             # towards the force
        # linear for small forces: twice the force, twice the motion (to 2 %)
        np.testing.assert_allclose(double.position - base.position, 2 * du, rtol=0,
                                   atol=0.02 * np.linalg.norm(du))
        moves.append(np.linalg.norm(du))
    assert max(moves) / min(moves) < 1.02


@pytest.mark.parametrize('name, sideways, down', [('one_segment', 8.2e-3, 0.55e-3),
                                                  ('two_segment', 91e-3, 1.1e-3)])
def test_compliance_figures_of_an_independent_implementation(name, sideways, down, one, two):
    """Unpressurised tip motion per newton, sideways and down, as measured independently."""
    model = one if name == 'one_segment' else two
    vent = solve_forward(model, np.zeros(model.A))
    side = solve_forward(model, np.zeros(model.A), tip_force_n=[0.01, 0.0, 0.0])
    push = solve_forward(model, np.zeros(model.A), tip_force_n=[0.0, 0.0, -0.01])
    assert (side.position[0] - vent.position[0]) / 0.01 == pytest.approx(sideways, rel=0.02)
    assert (vent.position[2] - push.position[2]) / 0.01 == pytest.approx(down, rel=0.02)


def test_inverse_under_a_force_reaches_the_target_and_forward_agrees(two):
    fw0 = solve_forward(two, [30e3, 20e3, 10e3, 40e3, 0.0, 5e3])
    F = [0.2, -0.1, -0.3]
    inv = solve_inverse(two, fw0.position, fw0.z_axis, payload_kg=0.02, tip_force_n=F)
    assert inv.status == InverseStatus.REACHED and inv.success, inv.message
    assert inv.forward.load == TipLoad(0.02, (0.2, -0.1, -0.3))
    check = solve_forward(two, inv.pressures_pa, payload_kg=0.02, tip_force_n=F)
    np.testing.assert_allclose(check.position, fw0.position, rtol=0, atol=1e-8)
    d = inv.to_dict()
    assert d['tip_force_n'] == [0.2, -0.1, -0.3] and d['payload_kg'] == 0.02
    # the pressures differ from the answer without the force (the force matters)
    assert np.max(np.abs(inv.pressures_pa
                         - solve_inverse(two, fw0.position, fw0.z_axis,
                                         payload_kg=0.02).pressures_pa)) > 1e3


def test_a_warm_start_under_another_force_is_re_solved(one):
    fw0 = solve_forward(one, [30e3, 20e3, 10e3])
    free = solve_inverse(one, fw0.position)
    pushed = solve_inverse(one, fw0.position, warm_start=free, tip_force_n=[0.0, 0.1, 0.0])
    cold = solve_inverse(one, fw0.position, tip_force_n=[0.0, 0.1, 0.0])
    assert pushed.success and cold.success
    np.testing.assert_allclose(pushed.pressures_pa, cold.pressures_pa, rtol=0, atol=1e-3)
    fw1 = solve_forward(one, [30e3, 20e3, 10e3], warm_start=fw0, tip_force_n=[0.0, 0.1, 0.0])
    fw2 = solve_forward(one, [30e3, 20e3, 10e3], tip_force_n=[0.0, 0.1, 0.0])
    np.testing.assert_allclose(fw1.x, fw2.x, rtol=0, atol=1e-10)


@pytest.mark.parametrize('bad, match', [
    ([np.nan, 0.0, 0.0], 'three finite numbers'),
    ([0.0, np.inf, 0.0], 'three finite numbers'),
    ([1.0, 2.0], 'three finite numbers'),
    ('abc', 'three finite numbers'),
    ([0.0, 0.0, -2 * MAX_TIP_FORCE_N], 'refused as absurd'),
])
def test_bad_forces_are_refused_with_the_key_and_what_is_allowed(one, bad, match):
    for call in (lambda: solve_forward(one, np.zeros(3), tip_force_n=bad),
                 lambda: solve_inverse(one, [0.0, 0.0, 0.1], tip_force_n=bad)):
        with pytest.raises(ValueError, match=match) as info:
            call()
        assert 'tip_force_n' in str(info.value)


def test_a_force_beyond_the_buckling_load_is_reported(two):
    """Pushing the two-segment robot down hard: no usable equilibrium, and the status says why."""
    fw = solve_forward(two, np.zeros(6), tip_force_n=[0.0, 0.0, -20.0])
    assert not fw.success
    assert fw.status in (ForwardStatus.UNSTABLE, ForwardStatus.STEP_TOO_SMALL,
                         ForwardStatus.ITERATION_BUDGET), fw.message
    if fw.status == ForwardStatus.STEP_TOO_SMALL:
        assert 'tip force (0, 0, -20) N' in fw.message
