"""Real-time factor of the dynamic simulation and time of the modal analysis (`make bench`).

Issue 26.  For the shipped one-, two- and three-segment robots (vented, no
payload) at the default step (:func:`bellow_ancf_ros.core.dynamics.default_step`,
1/40 of the first period, at most 10 ms), two runs of four first-mode
periods each, integrated one step per call of ``GeneralizedAlpha.advance``
(the step's wall time measured around it):

* ``release``: from the static equilibrium under a small tip force along x
  (about 1 % of the robot's height at the tip), removed at t = 0;
* ``sine``: from rest at zero pressure, the first actuator of the top
  segment driven by ``P(t) = 15 kPa (1 - cos(2 pi t / T))`` with ``T`` two
  first-mode periods (a bending oscillation through the resonance's flank).

Printed per robot and run, over ``--reps`` repetitions after one warm-up run:
the median and p99 of the step time, the median and lowest real-time factor
(simulated seconds per wall second of the whole run), and PASS/MISS against
the goals (:data:`RTF_GOALS`: 10x real time for one segment, 3x for two;
none for three).  Then the time of ``natural_modes`` (six modes) at that
equilibrium, median of ``--reps``.  One BLAS thread, as the nodes run.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from bellow_ancf_ros.core import (GeneralizedAlpha, RobotModel, limit_blas_threads, load_robot,
                                  natural_modes, solve_forward)

ROBOTS = {1: "one_segment", 2: "two_segment", 3: "three_segment"}
#: Goal real-time factors (simulated s per wall s) per segment count; MISS is printed, not raised.
RTF_GOALS = {1: 10.0, 2: 3.0}
PERIODS = 4.0
SINE_KPA = 15.0


def release_force(model, fw0):
    """A tip force along x moving the tip by about 1 % of its height (linear estimate)."""
    probe = 0.01
    fw = solve_forward(model, np.zeros(model.A), tip_force_n=[probe, 0.0, 0.0])
    moved = abs(fw.position[0] - fw0.position[0]) / probe
    return 0.01 * fw0.position[2] / max(moved, 1e-12)


def run_once(model, fw_start, kind, f1, released):
    """One run; returns (step times [s], real-time factor, steps, halvings, success)."""
    ig = GeneralizedAlpha(model)
    if released:
        ig.start_released(fw_start)
    else:
        ig.start(fw_start)
    t_end = PERIODS / f1
    if kind == "sine":
        top = model.A - model.cfg.segments[-1].n_actuators
        period = 2.0 / f1

        def pressures(t):
            p = np.zeros(model.A)
            p[top] = SINE_KPA * 1e3 * (1.0 - np.cos(2 * np.pi * t / period))
            return p
    else:
        pressures = None  # the start pressures, kept
    steps, halvings, ok = [], 0, True
    t_wall = time.perf_counter()
    while ig.state.t < t_end - 1e-9 * ig.step_s:
        t0 = time.perf_counter()
        rep = ig.advance(min(ig.state.t + ig.step_s, t_end), pressures_pa=pressures)
        steps.append(time.perf_counter() - t0)
        halvings += rep.halvings
        if not rep.success:
            ok = False
            break
    wall = time.perf_counter() - t_wall
    return np.array(steps), ig.state.t / wall, len(steps), halvings, ok


def bench_robot(m, reps):
    """All runs of one robot; prints its rows."""
    model = RobotModel(load_robot(ROBOTS[m]))
    p0 = np.zeros(model.A)
    fw0 = solve_forward(model, p0)
    f1 = natural_modes(fw0, 1).first.frequency_hz
    force = release_force(model, fw0)
    fw_f = solve_forward(model, p0, tip_force_n=[force, 0.0, 0.0])
    step = GeneralizedAlpha(model)
    step.start(fw0)
    print(f"{m} segment(s) ({ROBOTS[m]}): first mode {f1:.3f} Hz, default step "
          f"{step.step_s * 1e3:.3f} ms, {PERIODS:g} periods = {PERIODS / f1:.3f} s simulated; "
          f"release from {force:.4g} N along x", flush=True)
    rows = []
    for kind, start, released in (("release", fw_f, True), ("sine", fw0, False)):
        run_once(model, start, kind, f1, released)           # warm-up: caches, compilation
        times, rtfs, ok_all, n_steps, n_halv = [], [], True, 0, 0
        for _ in range(reps):
            st, rtf, n, h, ok = run_once(model, start, kind, f1, released)
            times.append(st)
            rtfs.append(rtf)
            ok_all &= ok
            n_steps, n_halv = n, n_halv + h
        st = np.concatenate(times)
        goal = RTF_GOALS.get(m)
        med = float(np.median(rtfs))
        verdict = "no goal" if goal is None else (
            f"{'PASS' if med >= goal else 'MISS'} (goal {goal:g}x)")
        line = (f"  {kind:<8} steps {n_steps:5d}  step median {np.median(st) * 1e3:7.3f} ms  "
                f"p99 {np.percentile(st, 99) * 1e3:7.3f} ms  RTF median {med:7.2f}x  "
                f"lowest {min(rtfs):7.2f}x  halvings {n_halv}  "
                f"{'completed' if ok_all else 'FAILED'}  {verdict}")
        print(line, flush=True)
        rows.append(line)
    mt = []
    for _ in range(reps):
        t0 = time.perf_counter()
        natural_modes(fw0, 6)
        mt.append(time.perf_counter() - t0)
    print(f"  modes    natural_modes (6 modes) median {np.median(mt) * 1e3:8.1f} ms, "
          f"max {max(mt) * 1e3:8.1f} ms", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=5, help="repetitions per run (default 5)")
    ap.add_argument("--segments", type=int, nargs="+", default=[1, 2, 3], choices=[1, 2, 3])
    args = ap.parse_args()
    limit_blas_threads()
    load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"dynamics bench: GeneralizedAlpha at the default step, {args.reps} repetitions "
          f"after a warm-up run; real-time factor = simulated s / wall s; {os.cpu_count()} "
          f"CPUs, load average {load} (1, 5, 15 min)", flush=True)
    for m in args.segments:
        bench_robot(m, args.reps)


if __name__ == "__main__":
    main()
