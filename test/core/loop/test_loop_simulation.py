"""The closed loop against the realistic simulated robot, in simulated time (core, no ROS).

The issue's acceptance in the core: a mismatched robot file, regulators with
lag, dead time and hysteresis, creeping bellows, a motion capture with 0.15
mm noise, latency, outliers and dropouts; the controller is the default model
with integral feedback.  Errors are true errors (the robot's pose, not the
motion capture's samples).
"""

import math

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward
from bellow_ancf_ros.core.sim import PlantEffects, SimulatedRobot, draw_robot
from bellow_ancf_ros.core.control import FeedbackSettings, StreamFeedforward
from bellow_ancf_ros.core.loop import LoopSimulation, default_loop, paper_circle
from bellow_ancf_ros.core.control._feedback import MOVING

PREVIEW_S = 0.09     # regulator dead time + lag + half a control period


def _loop(name, feedback=True, seed=1, effects=None, preview=PREVIEW_S):
    model = RobotModel(load_robot(name))
    robot = SimulatedRobot(name + '_mismatched', seed=seed, effects=effects)
    return LoopSimulation(model, robot, FeedbackSettings() if feedback else None,
                          preview_s=preview)


def _held(model, pressures):
    fw = solve_forward(model, pressures)
    return lambda t: (fw.position, fw.z_axis if model.cfg.n_segments > 1 else None)


@pytest.mark.parametrize('name, goal_mm, goal_deg',
                         [('one_segment', 0.3, None), ('two_segment', 0.5, 0.5)])
def test_held_target_within_the_goal(name, goal_mm, goal_deg):
    """The held target, after the swing the step to it started has died out (5 s).

    The two-segment robot's first mode rings at 2.6 Hz with a damping ratio of 0.05.
    """
    sim = _loop(name)
    A = sim.model.A
    target = _held(sim.model, np.linspace(60e3, 0.0, A))
    rec = sim.run(6.0, target)
    s = rec.summary(start_s=5.0)
    assert s['max_mm'] <= goal_mm, s
    if goal_deg is not None:
        assert s['max_deg'] <= goal_deg, s
    assert rec.out_of_limits == 0


@pytest.mark.parametrize('name, goal_mm, goal_deg',
                         [('one_segment', 1.0, None), ('two_segment', 1.5, 1.0)])
def test_circle_at_four_times_the_papers_speed(name, goal_mm, goal_deg):
    """After one period (5 s) the circle is tracked within the goals; feedforward is not."""
    period = 5.0
    out = {}
    for fb in (False, True):
        sim = _loop(name, feedback=fb)
        circle = paper_circle(sim.model.cfg, period)
        start = circle(0.0)
        sim.run(1.0, lambda t: start)            # lead-in at the path's first point
        t0 = sim.robot.time_s
        rec = sim.run(2 * period, lambda t: circle(t - t0))
        out[fb] = rec.summary(t0 + period, t0 + 2 * period)
        assert rec.out_of_limits == 0
    assert out[True]['rmse_mm'] <= goal_mm, out
    assert out[False]['rmse_mm'] > 3 * out[True]['rmse_mm'], out
    if goal_deg is not None:
        assert out[True]['rmse_deg'] <= goal_deg, out


def test_an_outlier_moves_no_command():
    """Two identical runs, one with a 25 mm swapped-marker sample: the commands are the same."""
    runs = []
    for corrupt in (False, True):
        sim = _loop('one_segment', seed=4, effects=PlantEffects(outlier_probability=0.0))
        target = _held(sim.model, [50e3, 20e3, 0.0])
        rec = sim.run(2.0, target)
        if corrupt:
            def swap(s):
                return s._replace(position=s.position + np.array([0.0, 0.025, 0.0]),
                                  outlier=True)
            sim.corrupt = swap
        sim.run(1.0, target, rec)
        runs.append(rec)
    steps, flagged = runs[1].command_steps()
    assert flagged.sum() == 1
    diff = np.max(np.abs(np.array(runs[1].command_pa) - np.array(runs[0].command_pa)))
    assert diff <= 2e3, f'{diff:.0f} Pa'
    assert sim.feedback.rejected == 1


def test_a_dropout_is_bridged_and_the_loop_is_back_within_2_s():
    e = PlantEffects(outlier_probability=0.0)
    sim = _loop('one_segment', seed=2, effects=e)
    sim.robot.mocap.dropout_phase_s = 3.0          # 0.5 s without samples from t = 3 s
    target = _held(sim.model, [70e3, 10e3, -30e3])
    rec = sim.run(6.0, target)
    t, err, _ = rec.errors()
    assert {'holding the correction: measured_pose too old (dropout)'} <= set(rec.state)
    during = err[(t >= 3.0) & (t <= 3.5)]
    assert during.max() <= 0.3e-3            # the held correction keeps the robot there
    assert err[t >= 3.5 + 2.0].max() <= 0.3e-3
    steps, _ = rec.command_steps()
    normal = steps[(rec.arrays()['t'][1:] > 2.0) & (rec.arrays()['t'][1:] < 3.0)].max()
    back = steps[(rec.arrays()['t'][1:] >= 3.5) & (rec.arrays()['t'][1:] <= 4.0)].max()
    assert back <= max(1.5 * normal, 500.0), (back, normal)   # no jump on the return


def test_azimuthal_frame_learns_the_mismatch_once_base_frame_lags():
    """On a circle about the axis the mismatch turns with the azimuth (symmetric robot)."""
    out = {}
    for frame in ('azimuthal', 'base'):
        model = RobotModel(load_robot('two_segment'))
        robot = SimulatedRobot('two_segment_mismatched', seed=1,
                               effects=PlantEffects.ideal(position_noise_m=0.0,
                                                          angle_noise_rad=0.0))
        sim = LoopSimulation(model, robot, FeedbackSettings(correction_frame=frame),
                             preview_s=0.1)
        circle = paper_circle(model.cfg, 5.0)
        sim.run(1.0, lambda t: circle(0.0))
        t0 = robot.time_s
        rec = sim.run(10.0, lambda t: circle(t - t0))
        out[frame] = rec.summary(t0 + 5.0)
    assert out['azimuthal']['rmse_mm'] < 0.3 and out['base']['rmse_mm'] > 1.0, out


def test_two_segments_carrying_50_g_on_the_automatic_gain_hold_the_target():
    """The gain from the model's mode with 50 g (about 0.4 /s) keeps the loop stable.

    At the default 2.5 /s this loop has a gain margin below one with the
    robot's mode (module _loop_margins); on the automatic gain it holds the
    target within 0.5 mm / 0.5 deg, and the watchdog, watching the mode,
    never trips.
    """
    from bellow_ancf_ros.core.control import ModeCheck
    model = RobotModel(load_robot('two_segment'))
    robot = SimulatedRobot('two_segment_mismatched', seed=1, payload_kg=0.05)
    sim = LoopSimulation(model, robot, FeedbackSettings(), preview_s=PREVIEW_S,
                         physics_rate_hz=robot.auto_physics_rate_hz, payload_kg=0.05,
                         mode_check=ModeCheck('auto', 0.06, 0.05))
    fw = solve_forward(model, [40e3, 0, 0, 0, 0, 0], payload_kg=0.05)

    def target(t):
        return fw.position, fw.z_axis
    rec = sim.run(20.0, target)
    (t_gain, gain), = sim.gains
    assert 0.3 < gain < 0.5 and sim.feedback.gain_per_s == gain
    s = rec.summary(start_s=16.0)
    assert s['max_mm'] <= 0.5 and s['max_deg'] <= 0.5, s
    assert sim.feedback.watchdog.trips == 0
    assert rec.out_of_limits == 0


def test_a_fixed_gain_that_rings_the_loop_up_trips_the_watchdog_and_the_cut_settles_it():
    """8 /s on the two-segment robot (its margin allows about 5.5): the loop rings up at its mode.

    The watchdog trips within seven periods of the 2.6 Hz mode (three
    windows of two periods, after the first move's own swing), the gain is
    halved on every trip, and the robot settles at the target.
    """
    from bellow_ancf_ros.core.control import ModeCheck
    model = RobotModel(load_robot('two_segment'))
    robot = SimulatedRobot('two_segment_mismatched', seed=1)
    sim = LoopSimulation(model, robot, FeedbackSettings(gain_per_s=8.0), preview_s=0.0,
                         physics_rate_hz=robot.auto_physics_rate_hz,
                         mode_check=ModeCheck(8.0, 0.06, 0.05))
    trips = []
    rec = None
    target = _held(model, [30e3, 0, 0, 0, 0, 0])
    while robot.time_s < 14.0:
        rec = sim.run(0.5, target, record=rec)
        if sim.feedback.watchdog.trips > len(trips):
            trips.append(sim.feedback.watchdog.last_trip.time_s)
    wd = sim.feedback.watchdog
    assert trips and trips[0] <= 3.0 and 'oscillation at' in wd.last_trip.message
    assert sim.feedback.gain_per_s <= 4.0
    s = rec.summary(start_s=10.0)   # (2.6 and 6.1 s, then 0.17 mm RMSE, 0.59 mm at most)
    assert s['rmse_mm'] <= 0.3 and s['max_mm'] <= 1.0 and rec.out_of_limits == 0, (s, trips)


def _ten_x(name, payload_kg):
    """Mismatched realistic robot, closed loop on the automatic gain, 2 s circle.

    Its start is held 3 s, then the path spins up over one period
    (``spin_up``); one period at full speed lets the loop learn, the next
    is evaluated (as ``make demo`` does).
    """
    from bellow_ancf_ros.core.control import ModeCheck
    from bellow_ancf_ros.core.experiments import spin_up
    model = RobotModel(load_robot(name))
    robot = SimulatedRobot(name + '_mismatched', seed=1, payload_kg=payload_kg)
    sim = LoopSimulation(model, robot, FeedbackSettings(), preview_s=PREVIEW_S,
                         physics_rate_hz=robot.auto_physics_rate_hz, payload_kg=payload_kg,
                         mode_check=ModeCheck('auto', 0.06, 0.05))
    circle = paper_circle(model.cfg, 2.0)
    sim.run(3.0, lambda t: circle(0.0))
    t0 = robot.time_s
    rec = sim.run(6.0, lambda t: circle(spin_up(t - t0, 2.0)))
    assert rec.out_of_limits == 0
    return rec.summary(t0 + 4.0, t0 + 6.0), sim


def test_two_segments_carrying_50_g_at_ten_times_the_speed():
    """The lightly damped mode keeps the automatic gain low; the 10x goal is met all the same.

    With the spin-up the circle does not start the mode ringing.
    """
    s, sim = _ten_x('two_segment', 0.05)
    assert sim.gains[-1][1] < 0.45
    assert s['rmse_mm'] <= 1.5 and s['rmse_deg'] <= 0.75, s
    assert sim.feedback.watchdog.trips == 0


@pytest.mark.parametrize('name, goal_mm, goal_deg', [('one_segment', 0.5, None),
                                                     ('two_segment', 1.0, 0.5)])
def test_ten_times_the_papers_speed_after_one_period(name, goal_mm, goal_deg):
    s, sim = _ten_x(name, 0.0)
    assert s['rmse_mm'] <= goal_mm, s
    assert goal_deg is None or s['rmse_deg'] <= goal_deg, s
    assert sim.feedback.watchdog.trips == 0


def _stop_mid_circle(sim, cfg, stop_after_s):
    """The 10x circle streamed (not previewed) until ``stop_after_s``, then no more targets."""
    from bellow_ancf_ros.core.experiments import spin_up
    path = paper_circle(cfg, 2.0)
    sim.run(2.0, lambda t: path(0.0))
    t0 = sim.robot.time_s
    sim.run(stop_after_s, lambda t: path(spin_up(t - t0, 1.0)))
    return path(spin_up(sim.robot.time_s - t0, 1.0))[0]


def test_a_stream_that_stops_leaves_the_robot_at_its_last_target_not_past_it():
    """Feedforward alone, a matched robot: the shift of the moving stream is braked away.

    Held, the shift (the regulators' lag times the speed, here about 3 mm)
    would stay in the command for ever: nothing measures the robot.
    """
    model = RobotModel(load_robot('one_segment'))
    robot = SimulatedRobot('one_segment', effects=PlantEffects.ideal())
    ff = StreamFeedforward(1.0, 0.0, lag_s=0.1)
    sim = LoopSimulation(model, robot, None, preview_s=0.0, feedforward=ff)
    last = _stop_mid_circle(sim, model.cfg, 2.2)
    shift = np.linalg.norm(ff.target()[0] - last)
    assert shift > 1e-3                                  # moving: the command led the target
    rec = sim.run(3.0, lambda t: None)
    err = np.linalg.norm(rec.arrays()['true_p'][-10:] - last, axis=1)
    assert err.max() < 2e-5 and rec.out_of_limits == 0


def test_a_stream_that_stops_brings_a_swinging_robot_to_rest():
    """The closed loop's defaults, a two-segment robot of the family (2.1 Hz, damping 0.09)."""
    model = RobotModel(load_robot('two_segment'))
    draw = draw_robot('two_segment', 2)
    sim = default_loop(model, draw.robot())
    last = _stop_mid_circle(sim, model.cfg, 2.2)
    rec = sim.run(4.0, lambda t: None)
    a = rec.arrays()
    t = a['t'] - a['t'][0]
    rest = a['true_p'][t > 3.0]
    assert np.ptp(rest, axis=0).max() < 0.5e-3           # no ringing left after 3 s
    assert np.linalg.norm(rest - last, axis=1).max() < 0.5e-3
    assert sim.feedback.watchdog.trips == 0 and rec.out_of_limits == 0


def test_a_planner_that_stalls_mid_circle_is_followed_on():
    """The closed loop's defaults, two segments, the 10x circle; the stream stalls 0.1 s.

    A busy computer stalls a planner for 0.1 s (the busy bench saw 104 ms).
    Read as a jump, the target after the stall made the next 1.2 s of the
    circle a move: 15.9 mm RMSE over the period, 32 mm at most (0.74 mm
    without the stall).  Now the stream is followed on through it.
    """
    from bellow_ancf_ros.core.experiments import spin_up
    model = RobotModel(load_robot('two_segment'))
    sim = default_loop(model, SimulatedRobot('two_segment_mismatched', seed=1))
    path = paper_circle(model.cfg, 2.0)
    sim.run(3.0, lambda t: path(0.0))
    t0 = sim.robot.time_s
    start = t0 + 3.0

    def stalled(t):
        return None if start + 0.3 <= t < start + 0.4 else path(spin_up(t - t0, 1.0))
    rec = sim.run(5.0, stalled)
    a = rec.arrays()
    m = (a['t'] >= start) & (a['t'] <= start + 2.0)
    wanted = np.array([path(spin_up(t - t0, 1.0))[0] for t in a['t'][m]])
    err = np.linalg.norm(a['true_p'][m] - wanted, axis=1)
    assert sim.jumps.moves == 1                          # the first target's, none since
    assert np.sqrt(np.mean(err ** 2)) < 2.5e-3 and err.max() < 6e-3, \
        (np.sqrt(np.mean(err ** 2)), err.max())
    assert sim.feedback.watchdog.trips == 0 and rec.out_of_limits == 0


@pytest.mark.parametrize('name', ['one_segment', 'two_segment'])
def test_the_model_frame_carries_the_mismatch_to_a_step_target(name):
    """The shipped mismatched robot, creep and play compensated, a 10 mm step after a hold.

    Azimuthal: the correction learned at the held pose is wrong at the goal
    (one segment: 1.7 mm of overshoot; two: 0.58 mm off 1.5 s after);
    ``model`` carries it there (0.05 mm of overshoot; 0.17 mm off 1.5 s after).
    """
    from functools import partial
    from bellow_ancf_ros.core.loop import step_case
    e = PlantEffects()
    out = {}
    for frame in ('azimuthal', 'model'):
        loop = partial(default_loop, creep_compensation=(e.creep_fraction,
                                                         e.creep_time_constant_s),
                       play_compensation_pa=e.regulator_hysteresis_pa, correction_frame=frame)
        out[frame] = step_case(RobotModel(load_robot(name)),
                               SimulatedRobot(f'{name}_mismatched', seed=3), loop=loop)
    assert out['model']['refused'] == 0 and out['model']['trips'] == 0
    if name == 'one_segment':
        assert out['azimuthal']['overshoot_mm'] > 1.0
        assert out['model']['overshoot_mm'] < 0.3 and out['model']['late_mm'] < 0.2
    else:
        assert out['azimuthal']['late_mm'] > 0.4
        assert out['model']['late_mm'] < 0.2 and out['model']['overshoot_mm'] < 0.5


def test_a_planner_whose_sends_come_late_is_followed_on():
    """A lab's planner on a busy computer: poses on its 50 Hz timer, stamped when sent.

    One send in 33 comes 3-40 ms late (a tick whose time passed is skipped,
    as a ROS timer does); the node solves each target when it comes.  A late
    send's stamp put the stream's last step off its time: the target after it
    lay 2.7-3.4 mm off the heading, and this stream made 5 false jumps in
    7 s on the two-segment circle at 10x (6 moves in all; 0.75 mm RMSE over
    the period with sends on time).  Read by its timer's grid, and against
    the heading before a late send too, no false jump.  The node's shaping
    tick re-solves while a late send's brake runs; the target that comes
    after all ends the brake's hold of the correction (it held a whole brake
    time, a third of the circle's period).
    """
    from bellow_ancf_ros.core.experiments import spin_up
    model = RobotModel(load_robot('two_segment'))
    sim = default_loop(model, SimulatedRobot('two_segment_mismatched', seed=1))
    path = paper_circle(model.cfg, 2.0)
    sim.run(3.0, lambda t: path(0.0))
    t0 = sim.robot.time_s
    rng = np.random.default_rng(1)
    late = rng.exponential(5e-4, 400)
    tail = rng.random(400) < 0.03
    late[tail] = rng.uniform(3e-3, 0.04, tail.sum())
    sends, k = [], 0
    while k < 400:   # (stamp, tick) of each send
        sends.append((t0 + k * 0.02 + late[k], t0 + k * 0.02))
        k = max(k + 1, math.ceil((sends[-1][0] - t0) / 0.02))
    sends.append((math.inf, math.inf))
    sim._next['control'] = sends[0][0]
    control, at = sim._control, iter(sends)
    now = [next(at)]

    def sent(t, target, rec):   # (the control step at each send, the next at the next one)
        if t != now[0][0]:   # the node's 50 Hz shaping tick: it re-solves while braking
            if sim.targets.busy(t):
                control(t, lambda _t: None, rec)
            return
        control(t, target, rec)
        now[0] = next(at)
        sim.control_dt = now[0][0] - t

    def target(t):   # the pose of the tick being sent; the path itself as the reference
        tick = now[0][1] if t == now[0][0] else t
        return path(spin_up(tick - t0, 1.0))
    sim._control = sent
    rec = sim.run(7.0, target, solve_at=t0 + 0.013 + 0.02 * np.arange(350))
    a = rec.arrays()
    start = t0 + 3.0
    m = (a['t'] >= start) & (a['t'] <= start + 2.0)
    wanted = np.array([path(spin_up(t - t0, 1.0))[0] for t in a['t'][m]])
    err = np.linalg.norm(a['true_p'][m] - wanted, axis=1)
    held = np.mean([s == MOVING for s, t in zip(rec.state, rec.t) if start <= t <= start + 2.0])
    assert max(s - tick for s, tick in sends[:-1]) > 0.03        # (some sends a tick late)
    assert sim.jumps.moves == 1                                  # the first target's only
    assert held < 0.1, held   # (a brake held the correction for 0.42 s: 34 % of the period)
    assert np.sqrt(np.mean(err ** 2)) < 2.0e-3, np.sqrt(np.mean(err ** 2))
    assert rec.out_of_limits == 0
