"""Tests of the correction carried to a new target (core/control/_mismatch.py).

The robot is a static model of its own (a robot file the controller does not
have); the correction that puts it at a target is found by iterating the
quasi-static loop to convergence, at the held target and at the new one.
"""

import dataclasses

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, parameter_keys as pk, solve_forward
from bellow_ancf_ros.core import robot_from_dict, solve_inverse
from bellow_ancf_ros.core.control import MismatchTransfer
from bellow_ancf_ros.core.geometry import rotation_between, rotation_from_vector


def _ideal(model, robot, p, z, c=None, r=None):
    """The correction (position, z-axis rotation) that puts ``robot`` at ``(p, z)``; the answer."""
    c = np.zeros(3) if c is None else c.copy()
    r = np.zeros(3) if r is None else r.copy()
    for _ in range(40):
        inv = solve_inverse(model, p + c, None if z is None else rotation_from_vector(r) @ z)
        got = solve_forward(robot, inv.pressures_pa)
        c = c + (p - got.position)
        if z is not None:
            r = r + rotation_between(got.z_axis, z)
            r = r - (r @ z) * z
    assert np.linalg.norm(p - got.position) < 1e-9
    return c, r, inv


def _carried(model, robot, step, tr=None):
    """(old correction, the goal's correction, the transferred one) for a step from a held pose."""
    orient = model.cfg.n_segments > 1
    p0 = np.zeros(model.A)
    p0[0] = 30e3
    held = solve_forward(model, p0)
    z = held.z_axis if orient else None
    c_old, r_old, inv_old = _ideal(model, robot, held.position, z)
    goal = held.position + np.asarray(step)
    c_new, r_new, _ = _ideal(model, robot, goal, z, c_old, r_old)
    new = solve_inverse(model, goal + c_old,
                        None if z is None else rotation_from_vector(r_old) @ z).forward
    got = (tr or MismatchTransfer(model)).transfer(inv_old.forward, c_old, r_old, new)
    return (c_old, r_old), (c_new, r_new), got


def test_a_mismatch_in_the_fitted_keys_is_carried_to_first_order(one, one_cfg):
    """Stiffness 6 % and pitch radius 5 % off: the new target's correction to within 15 %.

    (Measured: 10 % of a 1 mm change left across the bend; four keys for
    three equations, so the prior picks the smallest mismatch, not the drawn
    one.)
    """
    d = one_cfg.to_dict()
    keys = ['segments[0].pitch_radius_mm', pk.STIFFNESS_SCALE]
    values = [1.05 * pk.get_value(d, keys[0]), 1.06]
    robot = RobotModel(robot_from_dict(pk.with_values(d, keys, values)))
    for step in ([0.0, 0.01, 0.0], [0.01, 0.0, 0.0]):
        (c_old, _), (c_new, _), (c_got, _) = _carried(one, robot, step)
        change = np.linalg.norm(c_new - c_old)
        assert change > 0.3e-3, step   # (the offset does change with the pose)
        assert np.linalg.norm(c_got - c_new) < 0.15 * change, step


@pytest.mark.parametrize('name, share', [('one_segment', 0.3), ('two_segment', 0.2)])
def test_the_shipped_mismatched_robot_is_carried_most_of_the_way(name, share):
    """Masses and ``D_a`` off too: what is left after the transfer is a fraction of the change.

    (Measured: 26 % for one segment, 14 % for two, of about 2 mm for a
    10 mm step across the bend; the z-axis's change of 0.16 deg to 0.05.)
    Asked again at the goal's pressures with the carried correction, as the
    loop does (``CARRY_AGAIN`` times), 2 % and 3 % are left.
    """
    from bellow_ancf_ros.core.control._feedback import CARRY_AGAIN
    model = RobotModel(load_robot(name))
    truth = load_robot(f'{name}_mismatched')
    robot = RobotModel(dataclasses.replace(truth, n_elements=model.n))
    tr = MismatchTransfer(model)
    (c_old, r_old), (c_new, r_new), (c_got, r_got) = _carried(model, robot, [0.0, 0.01, 0.0],
                                                              tr)
    change = np.linalg.norm(c_new - c_old)
    assert change > 1e-3
    assert np.linalg.norm(c_got - c_new) < share * change
    if model.cfg.n_segments > 1:
        assert np.linalg.norm(r_got - r_new) < 0.5 * np.linalg.norm(r_new - r_old)
    goal = solve_forward(model, [30e3] + [0.0] * (model.A - 1)).position + [0.0, 0.01, 0.0]
    z = solve_forward(model, [30e3] + [0.0] * (model.A - 1)).z_axis
    for _ in range(CARRY_AGAIN):
        new = solve_inverse(model, goal + c_got, None if r_got is None
                            else rotation_from_vector(r_got) @ z).forward
        c_got, r_got = tr.again(new)
    assert np.linalg.norm(c_got - c_new) < 0.05 * change


def test_a_robot_that_is_its_model_keeps_a_zero_correction_and_a_failed_solve_refuses(one):
    """Nothing to carry gives nothing; a sensitivity solve that fails gives None, counted."""
    fw = solve_forward(one, [30e3, 0.0, 0.0])
    tr = MismatchTransfer(one)
    c, r = tr.transfer(fw, np.zeros(3), np.zeros(3), fw)
    assert np.all(c == 0.0) and r is None
    bad = dataclasses.replace(fw, pressures_pa=np.full(one.A, np.nan))
    assert tr.transfer(fw, np.ones(3) * 1e-3, None, bad) is None and tr.refused == 1
    with pytest.raises(ValueError, match='before a transfer'):
        MismatchTransfer(one).again(fw)


def test_a_fit_that_leaves_the_robot_files_ranges_is_refused(one):
    """A correction no plausible robot explains: the fitted file is invalid, nothing is carried."""
    fw = solve_forward(one, [30e3, 0.0, 0.0])
    tr = MismatchTransfer(one, keys=['actuator.d_eff_mm'])
    assert tr.transfer(fw, np.array([0.0, 0.0, -5.0]), None, fw) is None and tr.refused == 1
