"""Speed benchmarks (`make bench`): medians over repeated runs, ratios to the paper and to targets.

Paper (MATLAB, AMD Ryzen 7 3700X): 0.62 s (one segment) and 5.32 s (two segments)
to compute the maximum-deformation configuration.  Targets on a 2-core machine:
forward from the straight configuration <= 10 ms (one segment) / 30 ms (two);
inverse warm-started along a trajectory with 1 mm steps <= 2 ms / 5 ms per target;
end-to-end ROS latency target_pose -> pressure_command across processes: median 10 ms.

Timing is wall-clock on a shared machine: read medians, not single runs.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward, solve_inverse
from bellow_ancf_ros.core.solver import limit_blas_threads

PAPER_S = {"one_segment": 0.62, "two_segment": 5.32}
FORWARD_TARGET_S = {"one_segment": 0.010, "two_segment": 0.030}
INVERSE_TARGET_S = {"one_segment": 0.002, "two_segment": 0.005}


def _median_time(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), float(np.percentile(times, 99))


def extreme_pressures(model):
    """Maximum deformation: actuator 1 of every segment at p_max, the others at p_min."""
    p = np.full(model.A, model.cfg.p_min)
    for s in model.cfg.actuator_slices:
        p[s.start] = model.cfg.p_max
    return p


def circle_path(model, step_m=1e-3):
    """Targets 1 mm apart on a circle around the robot axis (with the z-axis for two segments)."""
    if model.cfg.n_segments == 1:
        centre = solve_forward(model, np.full(model.A, 40e3)).position
        radius, tilt = 0.010, None
    else:
        centre = solve_forward(model, np.full(model.A, 30e3)).position
        radius, tilt = 0.02, np.radians(10.0)
    n = int(np.ceil(2 * np.pi * radius / step_m))
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pos = centre + radius * np.stack([np.cos(phi), np.sin(phi), np.zeros(n)], axis=1)
    z = None
    if tilt is not None:
        z = np.stack([np.sin(tilt) * np.cos(phi), np.sin(tilt) * np.sin(phi), np.full(n, np.cos(tilt))], axis=1)
    return pos, z


def bench_forward(name, repeats):
    model = RobotModel(load_robot(name))
    p = extreme_pressures(model)
    res = solve_forward(model, p)
    assert res.converged and res.stable, res.message
    med, p99 = _median_time(lambda: solve_forward(model, p), repeats)
    med_ns, _ = _median_time(lambda: solve_forward(model, p, check_stability=False), repeats)
    return {
        "case": f"forward {name}, straight -> maximum deformation ({res.iterations} Newton it.)",
        "median_s": med, "p99_s": p99, "no_stability_median_s": med_ns,
        "paper_s": PAPER_S[name], "target_s": FORWARD_TARGET_S[name],
    }


def bench_inverse(name, laps):
    model = RobotModel(load_robot(name))
    pos, z = circle_path(model)
    prev = solve_inverse(model, pos[0], None if z is None else z[0])
    times, errs, ok = [], [], 0
    for lap in range(laps):
        for k in range(len(pos)):
            t0 = time.perf_counter()
            prev = solve_inverse(model, pos[k], None if z is None else z[k], warm_start=prev)
            times.append(time.perf_counter() - t0)
            ok += prev.success
            errs.append(prev.position_error_m)
    return {
        "case": f"inverse {name}, warm-started, 1 mm steps ({len(pos)} targets x {laps}, {ok} reached)",
        "median_s": float(np.median(times)), "p99_s": float(np.percentile(times, 99)),
        "paper_s": None, "target_s": INVERSE_TARGET_S[name],
        "max_position_error_m": float(np.max(errs)),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=30, help="repetitions of each forward solve")
    ap.add_argument("--laps", type=int, default=2, help="laps of the inverse circle")
    ap.add_argument("--no-ros", action="store_true", help="skip the end-to-end ROS latency benchmark")
    args = ap.parse_args(argv)
    limit_blas_threads()
    rows = []
    for name in ("one_segment", "two_segment"):
        rows.append(bench_forward(name, args.repeats))
        print(".", end="", file=sys.stderr, flush=True)
    for name in ("one_segment", "two_segment"):
        rows.append(bench_inverse(name, args.laps))
        print(".", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    print(f"{'case':<78} {'median':>9} {'p99':>9} {'vs paper':>9} {'vs target':>9}")
    for r in rows:
        paper = f"{r['paper_s'] / r['median_s']:.0f}x" if r["paper_s"] else "-"
        target = f"{r['median_s'] / r['target_s']:.2f}"
        print(f"{r['case']:<78} {r['median_s'] * 1e3:7.2f}ms {r['p99_s'] * 1e3:7.2f}ms {paper:>9} {target:>9}")
        if "no_stability_median_s" in r:
            print(f"{'   (same without the stability eigenvalue check)':<78} {r['no_stability_median_s'] * 1e3:7.2f}ms")
    if not args.no_ros:
        import ros_latency  # same folder; needs the ROS 2 client libraries of the venv
        ros_latency.main()
    print("vs paper: paper time / our median (faster = larger); vs target: our median / target (<= 1 meets it)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
