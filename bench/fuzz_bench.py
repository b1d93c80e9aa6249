"""Worst-case inverse solve time over a seeded fuzz run (`make bench`), next to the median.

Targets as in test/test_inverse_fuzz.py: reachable ones (forward solves of
random in-limit pressures), perturbed ones, far away, behind the base, with
nearly opposite z-axes; payloads 0 to 0.1 kg.  Each target is solved cold
and warm-started along a walk; every call is timed.  The first unreachable
target of a payload also pays for the forward solves at the corners of the
pressure box (cached per model and payload).

Timing is wall-clock on a shared machine: read medians, not single runs.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from bellow_ancf_ros.core import (RobotModel, limit_blas_threads, load_robot, solve_forward,
                                  solve_inverse)


def _unit(v):
    return v / np.linalg.norm(v)


def fuzz_targets(model, rng, n_targets, payloads):
    """``(kind, position, z_axis, payload)`` of a seeded mix of targets."""
    multi = model.cfg.n_segments >= 2
    lo, hi = model.cfg.p_min, model.cfg.p_max
    out = []
    while len(out) < n_targets:
        m = float(rng.choice(payloads))
        fw = solve_forward(model, rng.uniform(lo, hi, model.A), m)
        if not fw.success:
            continue
        p, z = fw.position, fw.z_axis if multi else None
        kind = rng.choice(["reachable", "reachable", "perturbed", "far", "behind", "opposite z"])
        if kind == "perturbed":
            p = p + rng.normal(0, 5e-3, 3)
            z = None if z is None else _unit(z + rng.normal(0, 0.1, 3))
        elif kind == "far":
            p = _unit(rng.normal(size=3)) * rng.uniform(0.5, 3.0)
        elif kind == "behind":
            p = np.array(
                [rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(-0.5, -0.05)]
            )
        elif kind == "opposite z":
            if not multi:
                kind = "reachable"
            else:
                z = _unit(-z + rng.normal(0, 1e-3, 3))
        out.append((kind, p, z, m))
    return out


def run(name, n_targets, seed):
    """Time every cold and warm solve of the fuzz targets; return the row of the report."""
    model = RobotModel(load_robot(name))
    rng = np.random.default_rng(seed)
    payloads = [0.0, float(rng.uniform(0.0, 0.1)), 0.1]
    times, worst, statuses, prev = [], (0.0, ""), {}, None
    for kind, p, z, m in fuzz_targets(model, rng, n_targets, payloads):
        for label, warm in (("cold", None), ("warm", prev)):
            t0 = time.perf_counter()
            inv = solve_inverse(model, p, z, payload_kg=m, warm_start=warm)
            dt = time.perf_counter() - t0
            times.append(dt)
            statuses[inv.status] = statuses.get(inv.status, 0) + 1
            if dt > worst[0]:
                worst = (dt, f"{label} {kind}, payload {m:.3g} kg, status {inv.status}")
            if label == "warm":
                prev = inv
    t = np.array(times)
    return {
        "robot": name,
        "solves": len(t),
        "median_s": float(np.median(t)),
        "p99_s": float(np.percentile(t, 99)),
        "worst_s": worst[0],
        "worst_case": worst[1],
        "statuses": dict(sorted(statuses.items())),
    }


def main(argv=None):
    """Print median, p99 and worst solve time of the seeded inverse fuzz run per robot."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=7, help="random seed of the fuzz run")
    ap.add_argument(
        "--targets", type=int, default=30, help="targets per robot (each solved cold and warm)"
    )
    args = ap.parse_args(argv)
    limit_blas_threads()
    print(f"inverse fuzz run, seed {args.seed}, {args.targets} targets per robot, "
          "each cold and warm-started")
    print(
        f"{'robot':<12} {'solves':>6} {'median':>9} {'p99':>9} {'worst':>9}  worst case; statuses"
    )
    for name in ("one_segment", "two_segment"):
        r = run(name, args.targets, args.seed)
        print(
            f"{r['robot']:<12} {r['solves']:>6} {r['median_s'] * 1e3:7.1f}ms "
            f"{r['p99_s'] * 1e3:7.1f}ms {r['worst_s'] * 1e3:7.1f}ms  "
            f"{r['worst_case']}; {r['statuses']}",
            flush=True,
        )
    print("statuses: 0 reached, 1 unreachable (best in-limit answer), 6 unstable, "
          "7/8 budget exhausted")
    return 0


if __name__ == "__main__":
    sys.exit(main())
