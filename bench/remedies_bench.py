"""What the robot's swing costs, and what each remedy buys (`make bench`).

In simulated time (:class:`~bellow_ancf_ros.core.loop.LoopSimulation`,
the dynamic simulated robot at its documented damping), one row per
remedy against the case it is for:

* **gain**: the two-segment robot carrying 50 g (declared), mismatched
  robot file, realistic plant, a held target: a fixed 2.5 /s (what the loop
  had before the robot's mode was known; no watchdog) against
  ``feedback_gain_per_s: auto`` (the safe gain with the mode).  Printed: the
  largest error over 4-8 s and over the last 4 s of 20 s, and the gain;
* **watchdog**: the same fixed 2.5 /s with the oscillation watchdog watching
  the mode: when it trips and what it leaves;
* **shaping**: the matched two-segment robot (only its dynamics and the
  regulators' lag), a 10 mm step target: the residual swing from 1 s after
  the step (largest distance from the final pose over the next second) with
  no shaping, ZV and ZVD, and the shaper's delay; then the mismatched
  realistic robot (its 1 kPa play, creep): unshaped, ZVD, and ZVD with the
  commands compensated for the play (``regulator_play_kpa``);
* **spin-up**: the same robot with ``feedback_gain_per_s: auto`` on the
  10x circle with and without the path's spin-up (``spin_up_s``): what a
  smooth start buys;
* **dynamic feedforward**: the matched robots (no creep, no play) on the
  paper's circle at 10 times its speed (2 s period), fourth period: RMSE of
  the quasi-static feedforward (lag previewed as a delay) against the
  dynamic one (lag and mode inverted).

Every figure is measured by this run; the rows run in parallel on the
machine's cores.  The tests assert on the same runs (``step_residual``:
test_shaping, ``circle_10x``: test_dynamic_feedforward).
"""

from __future__ import annotations

import os
import time
from multiprocessing import Pool

import numpy as np

from bellow_ancf_ros.core import (RobotModel, limit_blas_threads, load_robot, solve_forward,
                                  solve_inverse)
from bellow_ancf_ros.core.sim import PlantEffects, SimulatedRobot
from bellow_ancf_ros.core.control import (AUTO_GAIN, FeedbackSettings, ModeCheck,
                                          StreamFeedforward, shaped, shaper_impulses)
from bellow_ancf_ros.core.loop import LoopSimulation, paper_circle
from bellow_ancf_ros.core.dynamics import natural_modes
from bellow_ancf_ros.core.experiments import trajectory_target

LAG_S, DELAY_S = 0.06, 0.05
PREVIEW_S = 0.09


def held_50g(gain):
    """Two segments, 50 g, held target: the errors over 4-8 s and 16-20 s, gain, watchdog."""
    model = RobotModel(load_robot('two_segment'))
    robot = SimulatedRobot('two_segment_mismatched', seed=1, payload_kg=0.05)
    watch = gain != 'fixed, no watchdog'
    k = AUTO_GAIN if gain == 'auto' else 2.5
    sim = LoopSimulation(model, robot, FeedbackSettings(gain_per_s=2.5),
                         preview_s=PREVIEW_S, physics_rate_hz=robot.auto_physics_rate_hz,
                         payload_kg=0.05,
                         mode_check=ModeCheck(k, LAG_S, DELAY_S) if watch else None)
    fw = solve_forward(model, [40e3, 0, 0, 0, 0, 0], payload_kg=0.05)
    rec = sim.run(20.0, lambda t: (fw.position, fw.z_axis))
    wd = sim.feedback.watchdog
    return {'early': rec.summary(start_s=4.0, end_s=8.0), 'late': rec.summary(start_s=16.0),
            'gain_per_s': sim.feedback.gain_per_s, 'trips': 0 if wd is None else wd.trips,
            'trip': None if wd is None or wd.last_trip is None else wd.last_trip.message}


def _held_50g_line(gain):
    r = held_50g(gain)
    early, s = r['early'], r['late']
    first = '' if r['trip'] is None else f'; {r["trip"]}'
    return (f'gain {gain:<18s} held 50 g: max {early["max_mm"]:6.3f} mm over 4-8 s, '
            f'{s["max_mm"]:6.3f} mm {s["max_deg"]:6.3f} deg over 16-20 s; gain in use '
            f'{r["gain_per_s"]:.3g} /s; watchdog trips {r["trips"]}{first}')


def step_residual(kind, robot_name='two_segment', play_pa=None):
    """Two-segment robot, 10 mm step at 8 s: the residual swing from 9 s to 10 s.

    ``robot_name`` ``'two_segment'``: the matched robot, only its dynamics
    and the regulators' lag and dead time; ``'two_segment_mismatched'``: the
    mismatched robot with every realistic effect (1 kPa play, creep), the
    swing measured as ``make demo`` does (a quadratic drift taken out), the
    commands compensated for a play of ``play_pa`` (None: none).  The shaper
    is at the model's mode, and its levels are solved at their impulse
    times (the inverse node's one-shot re-solves).

    Returns ``(largest distance from the final pose (matched) or from the
    drift (mismatched) [m], the shaper's delay [s], the mode (frequency
    [Hz], damping ratio))``.
    """
    from bellow_ancf_ros.demos.step_target import residual_swing
    model = RobotModel(load_robot('two_segment'))
    fw0 = solve_forward(model, [30e3, 0, 0, 0, 0, 0])
    goal = fw0.position + np.array([0.0, 0.010, 0.0])
    mode = natural_modes(solve_inverse(model, goal, fw0.z_axis, warm_start=fw0).forward,
                         1).first

    def step(t):
        return (fw0.position if t < 8.0 else goal), fw0.z_axis
    matched = robot_name == 'two_segment'
    e = (PlantEffects.ideal(dynamics=True, regulator_time_constant_s=0.06,
                            regulator_dead_time_s=0.015, position_noise_m=0.0,
                            angle_noise_rad=0.0) if matched else PlantEffects())
    robot = SimulatedRobot(robot_name, seed=0, effects=e)
    sim = LoopSimulation(model, robot, None, physics_rate_hz=robot.auto_physics_rate_hz,
                         play_compensation_pa=play_pa or 0.0)
    tgt = step if kind == 'none' else shaped(step, kind, mode.frequency_hz, mode.damping_ratio)
    times, amps = shaper_impulses(kind, mode.frequency_hz, mode.damping_ratio)
    rec = sim.run(11.0, tgt, solve_at=[8.0 + t + 1e-3 for t in times])
    a = rec.arrays()
    if matched:
        final = a['true_p'][a['t'] > 10.5].mean(axis=0)
        w = (a['t'] >= 9.0) & (a['t'] <= 10.0)
        swing = float(np.linalg.norm(a['true_p'][w] - final, axis=1).max())
    else:
        swing = residual_swing(a['t'] - 8.0, a['true_p'], 1.0, 2.0)
    return swing, float(amps @ times), (mode.frequency_hz, mode.damping_ratio)


def _step_line(args):
    kind, robot_name, play_pa = args
    swing, delay, (f, zeta) = step_residual(kind, robot_name, play_pa)
    what = ('matched robot' if robot_name == 'two_segment' else
            f'mismatched realistic robot, play compensation {(play_pa or 0) / 1e3:g} kPa')
    return (f'shaping {kind:<4s} 10 mm step ({what}; mode {f:.3g} Hz, zeta {zeta:.3f}): '
            f'residual swing 1-2 s after it {swing * 1e3:7.4f} mm; delay {delay * 1e3:4.0f} ms')


def circle_10x(name, dynamic):
    """Matched robot, 2 s circle: RMSE and maximum over the fourth period (``summary``).

    No creep or play: only the robot's dynamics and the regulators' lag
    differ from the model.  The quasi-static feedforward previews the lag
    as a delay; the dynamic one inverts it (and the first mode).
    """
    period = 2.0
    model = RobotModel(load_robot(name))
    cfg = model.cfg
    circ = paper_circle(cfg, period)
    p0, z0 = circ(0.0)
    mode = natural_modes(solve_inverse(model, p0, z0 if cfg.n_segments > 1 else None).forward,
                         1).first
    eff = PlantEffects(creep_fraction=0.0, regulator_hysteresis_pa=0.0)
    tau = eff.regulator_time_constant_s
    robot = SimulatedRobot(name, seed=1, effects=eff)
    ff = StreamFeedforward(mode.frequency_hz, mode.damping_ratio, lag_s=tau)
    sim = LoopSimulation(model, robot, None, physics_rate_hz=robot.auto_physics_rate_hz,
                         preview_s=eff.preview_s(50.0) - (tau if dynamic else 0.0),
                         feedforward=ff if dynamic else None)
    start = circ(0.0)
    sim.run(1.0, lambda t: start)
    t0 = sim.robot.time_s
    rec = sim.run(4 * period, lambda t: circ(t - t0))
    assert rec.out_of_limits == 0, 'a command outside the limits was computed'
    return rec.summary(t0 + 3 * period, t0 + 4 * period)


def _circle_line(args):
    name, dynamic = args
    s = circle_10x(name, dynamic)
    ang = f' {s["rmse_deg"]:6.3f} deg' if 'rmse_deg' in s else ''
    label = 'dynamic' if dynamic else 'quasi-static'
    return (f'feedforward {label:<12s} {name:<12s} circle at 10x: RMSE {s["rmse_mm"]:6.3f} mm'
            f'{ang} (max {s["max_mm"]:.3f} mm)')


def circle_10x_50g(spin_up_s=2.0):
    """Two segments carrying 50 g, mismatched realistic robot, closed loop on the automatic gain.

    The 2 s circle after its start held 3 s and a spin-up (``spin_up_s``, 0:
    the path starts at full speed); one period at full speed to learn, the
    next evaluated.  Returns ``(summary, gain [1/s], watchdog trips)``.
    """
    from bellow_ancf_ros.core.experiments import spin_up
    model = RobotModel(load_robot('two_segment'))
    robot = SimulatedRobot('two_segment_mismatched', seed=1, payload_kg=0.05)
    sim = LoopSimulation(model, robot, FeedbackSettings(), preview_s=PREVIEW_S,
                         physics_rate_hz=robot.auto_physics_rate_hz, payload_kg=0.05,
                         mode_check=ModeCheck(AUTO_GAIN, LAG_S, DELAY_S))
    circ = trajectory_target('bending_circle', model.cfg, period=2.0, bending_angle_deg=10.0)
    sim.run(3.0, lambda t: circ(0.0))
    t0 = sim.robot.time_s
    rec = sim.run(4.0 + spin_up_s, lambda t: circ(spin_up(t - t0, spin_up_s)))
    assert rec.out_of_limits == 0, 'a command outside the limits was computed'
    start = t0 + spin_up_s + 2.0
    return (rec.summary(start, start + 2.0), sim.feedback.gain_per_s,
            sim.feedback.watchdog.trips)


def _circle_50g_line(spin):
    s, gain, trips = circle_10x_50g(spin)
    return (f'closed loop, 50 g, circle at 10x, spin-up {spin:g} s: RMSE {s["rmse_mm"]:6.3f} mm '
            f'{s["rmse_deg"]:6.3f} deg (max {s["max_mm"]:.3f} mm); automatic gain {gain:.3g} /s; '
            f'watchdog trips {trips}')


def _run(job):
    limit_blas_threads()
    fn, arg = job
    t0 = time.perf_counter()
    out = fn(arg)
    return f'{out}   [{time.perf_counter() - t0:.0f} s]'


def main() -> None:
    jobs = ([(_held_50g_line, g) for g in ('fixed, no watchdog', 'fixed, watchdog', 'auto')]
            + [(_circle_50g_line, spin) for spin in (0.0, 2.0)]
            + [(_step_line, (k, 'two_segment', None)) for k in ('none', 'zv', 'zvd')]
            + [(_step_line, (k, 'two_segment_mismatched', p)) for k, p in
               (('none', None), ('zvd', None), ('zvd', 1e3))]
            + [(_circle_line, (n, d)) for n in ('one_segment', 'two_segment')
               for d in (False, True)])
    print('remedies bench: what the swing costs and what each remedy buys (LoopSimulation, '
          f'dynamic robot; {os.cpu_count()} CPUs)', flush=True)
    with Pool(min(len(jobs), os.cpu_count() or 1)) as pool:
        for line in pool.imap(_run, jobs):
            print('  ' + line, flush=True)


if __name__ == '__main__':
    main()
