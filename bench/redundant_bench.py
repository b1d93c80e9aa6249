"""Cold and warm inverse solves for one to four segments (`make bench`; issue 21).

Targets as a lab makes them: forward solves of random in-limit pressures (10
to 90 % of the range) with their z-axes; payloads up to 0.1 kg for one and
two segments, up to 10 g for three (the shipped three-segment robot buckles
upright under 13 to 20 g), none for four.  Four segments: the benchmark's
lighter stack (``run_bench.scaling_robot``; the full-mass stack cannot stand).
Each target is solved cold (a new call without a warm start; the model's
caches of earlier calls are kept, as in a controller) and warm-started along
a walk through all of them (from one target straight to the next).  Printed
per robot: how many were reached and reproduced (1e-6 m, 1e-6 rad, by a
forward solve of the returned pressures), median, p99 and worst times, and
the largest difference between the cold and the walk's pressures.  Targets:
every solve under 5 s, the median under 1 s.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bellow_ancf_ros.core import (  # noqa: E402
    RobotModel, limit_blas_threads, load_robot, solve_forward, solve_inverse)
from run_bench import scaling_robot  # noqa: E402

WORST_S, MEDIAN_S = 5.0, 1.0
ROBOTS = {1: ("one_segment", 16, 0.1), 2: ("two_segment", 16, 0.1),
          3: ("three_segment", 16, 0.01), 4: (None, 8, 0.0)}


def targets(model, n, max_payload, rng):
    """``n`` (position, z-axis, payload) reached by stable forward solves."""
    cfg = model.cfg
    out = []
    while len(out) < n:
        p = cfg.p_min + rng.uniform(0.1, 0.9, model.A) * (cfg.p_max - cfg.p_min)
        payload = float(rng.uniform(0.0, max_payload))
        fw = solve_forward(model, p, payload_kg=payload)
        if fw.success:
            out.append((fw.position, fw.z_axis, payload))
    return out


def angle(a, b):
    """Angle between two directions [rad], accurate near zero (not ``arccos`` of the dot).

    The model's plate axes are unit vectors only to the constraint tolerance
    (about 1e-12): ``arccos`` of their dot product reads 1e-6 rad for parallel ones.
    """
    return float(np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b))


def reproduced(model, inv, position, z_axis, payload):
    """Whether the answer is reached and a forward solve of its pressures gives the target."""
    if not inv.success:
        return False
    fw = solve_forward(model, inv.pressures_pa, payload_kg=payload)
    ok = fw.success and np.linalg.norm(fw.position - position) <= 1e-6
    if model.cfg.n_segments > 1:
        ok = ok and angle(fw.z_axis, z_axis) <= 1e-6
    return bool(ok)


def run(m, seed):
    """One robot: cold solves, then the walk; returns a row of figures."""
    name, n, max_payload = ROBOTS[m]
    cfg = load_robot(name) if name else scaling_robot(m).replace(name="four_segment_light")
    model = RobotModel(cfg)
    rng = np.random.default_rng(seed + m)
    tg = targets(model, n, max_payload, rng)
    z = (lambda t: t[1]) if m > 1 else (lambda t: None)
    cold, t_cold, ok_cold = [], [], 0
    for t in tg:
        t0 = time.perf_counter()
        inv = solve_inverse(model, t[0], z(t), payload_kg=t[2])
        t_cold.append(time.perf_counter() - t0)
        ok_cold += reproduced(model, inv, t[0], t[1], t[2])
        cold.append(inv)
    prev, t_walk, ok_walk, dp = None, [], 0, 0.0
    for t, c in zip(tg, cold):
        t0 = time.perf_counter()
        inv = solve_inverse(model, t[0], z(t), payload_kg=t[2], warm_start=prev)
        t_walk.append(time.perf_counter() - t0)
        ok_walk += reproduced(model, inv, t[0], t[1], t[2])
        dp = max(dp, float(np.max(np.abs(inv.pressures_pa - c.pressures_pa))))
        prev = inv
    return dict(m=m, robot=cfg.name, n=n, ok_cold=ok_cold, ok_walk=ok_walk, cold=t_cold,
                walk=t_walk, dp=dp)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--segments", type=int, nargs="+", default=[1, 2, 3, 4], choices=[1, 2, 3, 4])
    ap.add_argument("--seed", type=int, default=2112)
    args = ap.parse_args(argv)
    limit_blas_threads()
    print("inverse from cold and along a walk (random in-limit targets; times per solve)")
    print(f"{'segments':>8} {'robot':>20} {'reached cold':>12} {'cold median':>11} "
          f"{'p99':>7} {'worst':>7} {'reached walk':>12} {'walk median':>11} {'worst':>7} "
          f"{'max |dP|':>9}  verdict")
    ok = True
    for m in args.segments:
        r = run(m, args.seed)
        times = r["cold"] + r["walk"]
        good = (r["ok_cold"] == r["n"] and r["ok_walk"] == r["n"] and max(times) < WORST_S
                and np.median(r["cold"]) < MEDIAN_S and np.median(r["walk"]) < MEDIAN_S)
        ok &= good
        print(f"{m:>8} {r['robot']:>20} {r['ok_cold']:>5} of {r['n']:<4} "
              f"{np.median(r['cold']):>10.3f}s {np.percentile(r['cold'], 99):>6.3f}s "
              f"{max(r['cold']):>6.3f}s {r['ok_walk']:>5} of {r['n']:<4} "
              f"{np.median(r['walk']):>10.3f}s {max(r['walk']):>6.3f}s {r['dp']:>7.3g}Pa  "
              f"{'PASS' if good else 'FAIL'}", flush=True)
    print(f"targets: every target reached and reproduced, each solve < {WORST_S:g} s, "
          f"medians < {MEDIAN_S:g} s: {'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
