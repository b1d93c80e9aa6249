"""The command sent for the one wanted: the bellows' creep inverted (and the play)."""

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward
from bellow_ancf_ros.core.sim import BellowCreep, PlantEffects, SimulatedRobot
from bellow_ancf_ros.core.control import CommandOutput, CreepCompensation
from bellow_ancf_ros.core.loop import LoopSimulation

C, T = 0.15, 2.0


@pytest.fixture(scope='module')
def model():
    return RobotModel(load_robot('one_segment'))


def test_the_creeping_bellows_stand_where_wanted_at_every_command(model):
    """Round trip through the simulated robot's creep: effective pressure == wanted, exactly."""
    cfg = model.cfg
    comp = CreepCompensation(model.stage1, model.A, C, T, cfg.p_min, cfg.p_max)
    plant = BellowCreep(model.stage1, C, T, np.zeros(model.A))
    rng = np.random.default_rng(3)
    wanted = np.array([20e3, 5e3, 1e3])
    dt, t, leads = 0.02, 0.0, []
    for k in range(400):
        if k % 100 == 0:    # a new held pressure every 2 s, within the limits
            wanted = rng.uniform(1e3, 0.6 * cfg.p_max, model.A)
        sent = comp.command(wanted, t)
        np.testing.assert_allclose(plant.step(sent, 0.0), wanted, rtol=1e-9, atol=1e-6)
        leads.append(np.max(np.abs(sent - wanted)))
        plant.step(sent, dt)
        t += dt
    # the lead: large after each step, gone once the creep has settled (2 s = one T: e^-1)
    assert max(leads) > 1e3 and leads[99] < 0.45 * leads[1]


def test_held_it_relaxes_onto_the_wanted_pressure_and_the_limits_hold(model):
    cfg = model.cfg
    comp = CreepCompensation(model.stage1, model.A, C, T, cfg.p_min, cfg.p_max)
    w = np.array([0.9 * cfg.p_max, 10e3, 0.0])
    first = comp.command(w, 0.0)
    assert first[0] == cfg.p_max                  # the lead is cut at the limit, never past it
    assert first[1] > 10e3 and first[2] == 0.0    # leads the creep; the vent passes as it is
    for t in np.arange(0.05, 30.0, 0.05):         # held, updated at 20 Hz (as republished)
        late = comp.command(w, t)                 # 15 T later: the creep has settled
    np.testing.assert_allclose(late, w, rtol=1e-6)
    with pytest.raises(ValueError, match='creep_fraction'):
        CreepCompensation(model.stage1, model.A, 1.0, T, cfg.p_min, cfg.p_max)
    with pytest.raises(ValueError, match='creep_time_constant_s'):
        CreepCompensation(model.stage1, model.A, C, 0.0, cfg.p_min, cfg.p_max)


def test_command_output_chains_creep_then_play(model):
    cfg = model.cfg
    out = CommandOutput(model, play_pa=1e3, creep=(C, T))
    alone = CreepCompensation(model.stage1, model.A, C, T, cfg.p_min, cfg.p_max)
    assert out.timed and out.again(0.0) is None
    w = np.array([20e3, 10e3, 5e3])
    a = out.command(w, 0.0)                       # rising: the play's upper edge
    np.testing.assert_allclose(a, alone.command(w, 0.0) + 500.0)
    assert np.all(a > w + 500.0)                  # (the creep's lead)
    b = out.again(0.05)                           # the same wanted, later: less lead
    np.testing.assert_allclose(b, alone.command(w, 0.05) - 500.0)   # falling: lower edge
    assert np.all(b < a)
    out.vent(2.0)
    assert out.wanted is None
    plain = CommandOutput(model)
    assert not plain.timed and np.array_equal(plain.command(w, 0.0), w)


def test_a_step_on_a_creeping_robot_arrives_at_once_with_the_creep_compensated(model):
    """Feedforward only, matched robot with 15 % creep over 2 s: 1 s after an 80 kPa step."""
    errs = {}
    for comp in (None, (C, T)):
        effects = PlantEffects.ideal(creep_fraction=C, creep_time_constant_s=T,
                                     regulator_time_constant_s=0.02)
        robot = SimulatedRobot('one_segment', effects=effects)
        sim = LoopSimulation(model, robot, None, creep_compensation=comp)
        goal = solve_forward(model, np.array([80e3, 0.0, 0.0])).position
        rec = sim.run(1.0, lambda t: (goal, None))
        a = rec.arrays()
        errs[comp is not None] = np.linalg.norm(a['true_p'][-1] - goal)
    assert errs[False] > 5e-4 and errs[True] < 0.02 * errs[False]   # 0.84 -> 0.008 mm
