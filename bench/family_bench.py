"""The closed loop on a family of robots (`make bench`): each goal's distribution, not one run.

Draws ``--robots`` robots per segment count from the documented family
(:func:`bellow_ancf_ros.core.control.draw_robot`, seeds 0 to N-1: mode
0.7-1.4x the model's, damping ratio 0.02-0.25, regulators, creep, motion
capture, stiffness and geometry off by up to 10 %), runs the closed loop's
cases on each (:mod:`bellow_ancf_ros.core.control`: ``held_case``,
``circle_case`` at 10x, ``step_case``; ``--slow`` adds the circle at 1x)
with the inverse node's defaults (``feedback: integral``, automatic gain,
targets nobody previewed), in simulated time, on joblib's process pool (its
Dask or Ray backend takes the same code to a cluster: ``--backend``).

Prints, for each goal, the median, the 95th percentile and the worst over the
robots, how many meet it, and, for a goal missed at the 95th percentile, the
drawn parameter whose rank correlates most with the figure (what drives the
miss).  Writes every robot's figures and parameters to ``--out``
(``bench/family.json``).  Seeded: the same robots and figures on every run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed
from scipy.stats import spearmanr

from bellow_ancf_ros.core import RobotModel, limit_blas_threads, load_robot
from bellow_ancf_ros.core.control import circle_case, draw_robot, held_case, step_case

HERE = Path(__file__).resolve().parent
ROBOTS = ('one_segment', 'two_segment')
#: goal -> (case, figure, limit for one segment, limit for two segments); None: not a goal there
GOALS = {
    'held position RMSE [mm]': ('held', 'rmse_mm', 0.1, 0.2),
    'held angle RMSE [deg]': ('held', 'rmse_deg', None, 0.1),
    'circle 10x position RMSE [mm]': ('circle_10x', 'rmse_mm', 0.3, 0.6),
    'circle 10x angle RMSE [deg]': ('circle_10x', 'rmse_deg', None, 0.3),
    'circle 1x position RMSE [mm]': ('circle_1x', 'rmse_mm', 0.15, 0.15),
    'circle 1x angle RMSE [deg]': ('circle_1x', 'rmse_deg', None, 0.1),
    'step overshoot [mm]': ('step', 'overshoot_mm', 0.5, 0.5),
    'step error 1.5 s after [mm]': ('step', 'late_mm', 0.2, 0.2),
    'step commands beyond settled [%]': ('step', 'command_excess', 10.0, 10.0),
    'watchdog trips': (None, 'trips', 0, 0),
    'commands refused': (None, 'refused', 0, 0),
}


def evaluate(robot: str, seed: int, slow: bool) -> dict:
    """Every case on robot ``seed`` of the family around ``robot``: figures and parameters."""
    limit_blas_threads()
    t0 = time.process_time()
    model = RobotModel(load_robot(robot))
    draw = draw_robot(robot, seed)
    cases = {'held': held_case(model, draw.robot()),
             'circle_10x': circle_case(model, draw.robot(), 10.0),
             'step': step_case(model, draw.robot())}
    if slow:
        cases['circle_1x'] = circle_case(model, draw.robot(), 1.0)
    cases['step']['command_excess'] *= 100.0
    return {'robot': robot, 'seed': seed, 'values': draw.values,
            'first_mode_hz': draw.first_mode_hz, 'model_mode_hz': draw.model_mode_hz,
            'cases': cases, 'cpu_s': time.process_time() - t0}


def figure(run: dict, case: str | None, key: str) -> float | None:
    """One robot's figure of a goal (summed over the cases for trips and refusals)."""
    if case is None:
        return float(sum(c[key] for c in run['cases'].values()))
    c = run['cases'].get(case)
    return None if c is None or key not in c else float(c[key])


def table(runs: list, robot: str) -> list:
    """One row per goal of ``robot``: median, p95, worst, met, and what drives a miss."""
    mine = [r for r in runs if r['robot'] == robot]
    two = robot != 'one_segment'
    rows = []
    for goal, (case, key, lim1, lim2) in GOALS.items():
        limit = lim2 if two else lim1
        vals = [figure(r, case, key) for r in mine]
        if limit is None or any(v is None for v in vals) or not vals:
            continue
        v = np.array(vals)
        p95 = float(np.percentile(v, 95))
        row = {'goal': goal, 'limit': limit, 'median': float(np.median(v)), 'p95': p95,
               'worst': float(v.max()), 'met': int(np.sum(v <= limit)), 'n': len(v),
               'driver': ''}
        if p95 > limit and np.ptp(v) > 0:
            corr = {}
            for name in mine[0]['values']:
                x = np.array([r['values'][name] for r in mine])
                if np.ptp(x) == 0:
                    continue
                rho = spearmanr(x, v).statistic
                if math.isfinite(rho):
                    corr[name] = rho
            if corr:
                name = max(corr, key=lambda k: abs(corr[k]))
                row['driver'] = f'{name} (rank correlation {corr[name]:+.2f})'
        rows.append(row)
    return rows


def render(runs: list) -> str:
    """The tables as text, one per robot."""
    out = []
    for robot in ROBOTS:
        rows = table(runs, robot)
        if not rows:
            continue
        out.append(f'{robot}: {rows[0]["n"]} robots of the family, the inverse node\'s '
                   'defaults, targets not previewed')
        out.append(f'  {"goal":34s} {"limit":>7s} {"median":>8s} {"p95":>8s} {"worst":>8s} '
                   f'{"met":>7s}  p95 missed: driven by')
        for r in rows:
            miss = r['driver'] if r['p95'] > r['limit'] else ''
            out.append(f'  {r["goal"]:34s} {r["limit"]:7.3g} {r["median"]:8.3f} '
                       f'{r["p95"]:8.3f} {r["worst"]:8.3f} {r["met"]:3d}/{r["n"]:<3d}  {miss}')
    return '\n'.join(out)


def main(argv=None) -> int:
    """Run the family, print the tables, write the runs."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--robots', type=int, default=100, help='robots per segment count')
    ap.add_argument('--jobs', type=int, default=os.cpu_count() or 1,
                    help="joblib's n_jobs (default: every core)")
    ap.add_argument('--backend', default='loky', help="joblib backend (loky, dask, ray...)")
    ap.add_argument('--slow', action='store_true', help='add the circle at 1x (20 s period)')
    ap.add_argument('--out', type=Path, default=HERE / 'family.json')
    args = ap.parse_args(argv)
    if args.robots < 1:
        print(f'--robots: {args.robots} is not allowed; at least 1', file=sys.stderr)
        return 2
    t0 = time.monotonic()
    jobs = [(robot, seed) for robot in ROBOTS for seed in range(args.robots)]
    runs = Parallel(n_jobs=args.jobs, backend=args.backend)(
        delayed(evaluate)(robot, seed, args.slow) for robot, seed in jobs)
    wall = time.monotonic() - t0
    print(render(runs))
    cpu = [r['cpu_s'] for r in runs]
    print(f'{len(runs)} robots in {wall:.0f} s on {args.jobs} worker(s); CPU per robot: '
          f'median {np.median(cpu):.1f} s, p99 {np.percentile(cpu, 99):.1f} s')
    args.out.write_text(json.dumps({'robots_per_count': args.robots, 'slow': args.slow,
                                    'runs': runs}, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
