"""Inverse solves in wall-clock budget slices (`make bench`): overshoot and convergence.

Like the inverse node: each target of a seeded fuzz mix (bench/fuzz_bench.py) is solved
warm-started from the straight robot at vent pressure with ``time_budget_s``; a result that
ran out of budget is passed back as the warm start (the next slice) until the status is no
budget status (at most 40 slices).  Reported per robot: the overshoot of every call past its
budget (median, p90, worst), the slices per target, how many ended, and the largest pressure
difference to one unbudgeted solve of the same target from the same start.

Timing is wall-clock on a shared machine: read medians, not single runs.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from bellow_ancf_ros.core import (InverseStatus, RobotModel, limit_blas_threads, load_robot,
                                  precompute_corners, solve_forward, solve_inverse, warm_up)

from fuzz_bench import fuzz_targets

MAX_SLICES = 40
TIME_BUDGET, ITERATION_BUDGET = InverseStatus.TIME_BUDGET, InverseStatus.ITERATION_BUDGET


def run(name, n_targets, seed, budget):
    """Slice every fuzz target; return the row of the report."""
    model = RobotModel(load_robot(name))
    rng = np.random.default_rng(seed)
    payloads = [0.0, float(rng.uniform(0.0, 0.1)), 0.1]
    for m in payloads:
        precompute_corners(model, m)  # as the node does at configure
    warm_up(model)  # (so does this: the fast path's kernels loaded before the first slice)
    over, slices, ended, dp = [], [], 0, 0.0
    for kind, p, z, m in fuzz_targets(model, rng, n_targets, payloads):
        straight = solve_forward(model, np.zeros(model.A), m)
        ref = solve_inverse(model, p, z, payload_kg=m, warm_start=straight)
        warm = straight
        for k in range(1, MAX_SLICES + 1):
            t0 = time.perf_counter()
            inv = solve_inverse(model, p, z, payload_kg=m, warm_start=warm, time_budget_s=budget)
            over.append(time.perf_counter() - t0 - budget)
            if inv.status not in (TIME_BUDGET, ITERATION_BUDGET):
                ended += 1
                if ref.reachable:
                    dp = max(dp, float(np.max(np.abs(inv.pressures_pa - ref.pressures_pa))))
                break
            warm = inv
        slices.append(k)
    o = np.array(over)
    return {
        "robot": name,
        "targets": len(slices),
        "calls": len(o),
        "over_median_s": float(np.median(o)),
        "over_p90_s": float(np.percentile(o, 90)),
        "over_worst_s": float(o.max()),
        "slices_median": float(np.median(slices)),
        "slices_max": int(max(slices)),
        "ended": ended,
        "max_dp_pa": dp,
    }


def main(argv=None):
    """Print the overshoot and slice statistics of budgeted inverse solves per robot."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=7, help="random seed of the fuzz targets")
    ap.add_argument("--targets", type=int, default=10, help="targets per robot")
    ap.add_argument("--budget-ms", type=float, default=10.0, help="time_budget_s of a call [ms]")
    args = ap.parse_args(argv)
    limit_blas_threads()
    budget = args.budget_ms * 1e-3
    print(f"inverse in budget slices of {args.budget_ms:g} ms, seed {args.seed}, "
          f"{args.targets} targets per robot, warm-started from the straight robot")
    print(f"{'robot':<12} {'calls':>5} {'overshoot median':>17} {'p90':>8} {'worst':>8}  "
          "slices median/max; ended; max |dP| to one unbudgeted solve (reachable)")
    for name in ("one_segment", "two_segment"):
        r = run(name, args.targets, args.seed, budget)
        print(f"{r['robot']:<12} {r['calls']:>5} {r['over_median_s'] * 1e3:15.1f}ms "
              f"{r['over_p90_s'] * 1e3:6.1f}ms {r['over_worst_s'] * 1e3:6.1f}ms  "
              f"{r['slices_median']:g}/{r['slices_max']}; {r['ended']}/{r['targets']}; "
              f"{r['max_dp_pa']:.3g} Pa", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
