"""What each hardware effect alone costs the closed loop (`make bench`; issue 22).

The controller (default model, integral feedback, targets previewed by the
regulators' lag) closed around the mismatched simulated robot in simulated
time (:class:`~bellow_ancf_ros.core.control.LoopSimulation`, physics 200 Hz,
control 50 Hz): the paper's circle (one segment: planar circle; two: bending
circle at 10 deg) at the paper's speed (20 s period) and at four times it.
One row per effect alone (:data:`~bellow_ancf_ros.core.control.EFFECTS`, all
others off, i.e. the ideal robot with that one effect), then all of them (the
realistic robot), feedforward alone on it, and the closed loop with its
correction integrated in the base frame instead of the azimuthal one.

Printed per row: RMSE and maximum of the true position error over the second
period (and of the z-axis angle for two segments), the RMSE's cost against
the ideal row, the largest command step at a control step after an outlier
and the 99th percentile of the other steps (kPa), and the true error 2 s
after each dropout ended (mm).  ``--quick`` runs the four-times speed only.
"""

from __future__ import annotations

import argparse
import os
import time
from multiprocessing import Pool

import numpy as np

from bellow_ancf_ros.cli.output import number
from bellow_ancf_ros.core import RobotModel, limit_blas_threads, load_robot
from bellow_ancf_ros.core.control import (EFFECTS, FeedbackSettings, LoopSimulation,
                                          PlantEffects, SimulatedRobot, paper_circle)

PAPER_PERIOD_S = 20.0
CONTROL_HZ = 50.0
SEED = 1


def _rows():
    real = PlantEffects()
    rows = [('ideal robot', PlantEffects.ideal(), 'azimuthal', True)]
    rows += [(name, real.only(name), 'azimuthal', True) for name in EFFECTS]
    rows += [('all (realistic robot)', real, 'azimuthal', True),
             ('all, base-frame correction', real, 'base', True),
             ('all, feedforward only', real, 'azimuthal', False)]
    return rows


def run_one(job):
    """One row at one speed: the loop's errors over the second period, outliers, dropouts."""
    robot_name, speed, label, effects, frame, feedback = job
    limit_blas_threads()
    model = RobotModel(load_robot(robot_name))
    robot = SimulatedRobot(robot_name + '_mismatched', seed=SEED, effects=effects)
    sim = LoopSimulation(model, robot,
                         FeedbackSettings(correction_frame=frame) if feedback else None,
                         control_rate_hz=CONTROL_HZ, preview_s=effects.preview_s(CONTROL_HZ))
    period = PAPER_PERIOD_S / speed
    circle = paper_circle(model.cfg, period)
    t_wall = time.perf_counter()
    sim.run(1.0, lambda t: circle(0.0))           # lead-in at the path's first point
    t0 = robot.time_s
    rec = sim.run(2.0 * period, lambda t: circle(t - t0))
    out = rec.summary(t0 + period, t0 + 2.0 * period)
    steps, flagged = rec.command_steps()
    after = steps[flagged | np.roll(flagged, 1)]  # the step after an outlier and the next
    out['step_after_outlier_kpa'] = float(after.max() / 1e3) if after.size else None
    out['step_p99_kpa'] = float(np.percentile(steps[~flagged], 99) / 1e3)
    # dropouts: the true error 2 s after each one ended (the robot's own schedule)
    e = effects
    rec_t, err, _ = rec.errors()
    recover = []
    if e.dropout_every_s > 0 and e.dropout_duration_s > 0:
        start = robot.mocap.dropout_phase_s
        while start < robot.time_s:
            end = start + e.dropout_duration_s
            m = np.abs(rec_t - (end + 2.0)) <= 0.03
            if m.any() and end > t0:
                recover.append(float(err[m].mean() * 1e3))
            start += e.dropout_every_s
    out['after_dropout_mm'] = recover
    out['out_of_limits'] = rec.out_of_limits
    out['wall_s'] = time.perf_counter() - t_wall
    return job[:3], out


def main(argv=None) -> int:
    """Run every row at every speed for one and two segments; print the tables."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--quick', action='store_true', help='four times the speed only')
    ap.add_argument('--jobs', type=int, default=min(2, os.cpu_count() or 1))
    args = ap.parse_args(argv)
    speeds = (4.0,) if args.quick else (1.0, 4.0)
    robots = ('one_segment', 'two_segment')
    jobs = [(r, v, label, eff, frame, fb) for r in robots for v in speeds
            for label, eff, frame, fb in _rows()]
    t0 = time.perf_counter()
    with Pool(args.jobs) as pool:
        results = dict(pool.map(run_one, jobs, chunksize=1))
    print('closed loop against the mismatched simulated robot, one effect at a time '
          f'(seed {SEED}; true errors over the second period; {time.perf_counter() - t0:.0f} s)')
    bad = 0
    for r in robots:
        two = r == 'two_segment'
        for v in speeds:
            print(f'\n{r}, {v:g}x the paper speed ({PAPER_PERIOD_S / v:g} s period):')
            head = f'  {"row":30s} {"RMSE mm":>8s} {"max mm":>7s} {"cost mm":>8s}'
            if two:
                head += f' {"RMSE deg":>8s} {"max deg":>7s}'
            print(head + f' {"outlier step kPa":>17s} {"p99 step kPa":>12s}  after dropouts mm')
            base = results[(r, v, 'ideal robot')]['rmse_mm']
            for label, *_ in _rows():
                o = results[(r, v, label)]
                line = (f'  {label:30s} {o["rmse_mm"]:8.3f} {o["max_mm"]:7.3f} '
                        f'{number(o["rmse_mm"] - base, "+8.3f")}')
                if two:
                    line += f' {o["rmse_deg"]:8.3f} {o["max_deg"]:7.3f}'
                step = o['step_after_outlier_kpa']
                line += (f' {"-" if step is None else f"{step:.2f}":>17s}'
                         f' {o["step_p99_kpa"]:12.2f}  '
                         + (', '.join(f'{x:.3f}' for x in o['after_dropout_mm']) or '-'))
                print(line)
                bad += o['out_of_limits']
    print(f'\ncommands out of limits or not finite: {bad}')
    return 0 if bad == 0 else 1


if __name__ == '__main__':
    raise SystemExit(main())
