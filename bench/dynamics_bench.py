"""Real-time factor of the dynamic simulation and time of the modal analysis (`make bench`).

Issues 26 and 36.  For the shipped one-, two- and three-segment robots
(vented, no payload) at the default step
(:func:`bellow_ancf_ros.core.dynamics.default_step`, 1/40 of the first
period, at most 10 ms), two runs of four first-mode periods each:

* ``release``: from the static equilibrium under a small tip force along x
  (about 1 % of the robot's height at the tip), removed at t = 0;
* ``sine``: from rest at zero pressure, the first actuator of the top
  segment driven by ``P(t) = 15 kPa (1 - cos(2 pi t / T))`` with ``T`` two
  first-mode periods (a bending oscillation through the resonance's flank).

Each run twice: ``integrator``, one step per call of
``GeneralizedAlpha.advance`` (the step's CPU time measured around it), and
``simulate``, the run as ``bellow-ancf simulate`` makes it
(:func:`~bellow_ancf_ros.core.dynamics.sample_motion` sampling every step,
energy and constraint checks every ``cli.dynamics.CHECK_S``; the CPU time of
each sample: its step and its read-outs).  All times are CPU time of this
process (``time.process_time``): on a shared machine they move less than
wall time.

Printed per robot, run and way, over ``--reps`` repetitions after one
warm-up run (the two ways interleaved, run by run): the median and p99 of
the step or sample time, the median and lowest real-time factor (simulated
seconds per CPU second of the whole run), and PASS/MISS against the goals
(:data:`RTF_GOALS`: the integrator at 10x real time for one segment, 3x for
two; :data:`SIMULATE_GOALS`: ``simulate`` at 30x for one and two segments;
none for three).  Then the time of
``natural_modes`` (six modes) at that equilibrium, median of ``--reps``.
One BLAS thread, as the nodes run.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from bellow_ancf_ros.cli.dynamics import CHECK_S
from bellow_ancf_ros.core import (GeneralizedAlpha, RobotModel, limit_blas_threads, load_robot,
                                  natural_modes, solve_forward)
from bellow_ancf_ros.core.dynamics import sample_motion

ROBOTS = {1: "one_segment", 2: "two_segment", 3: "three_segment"}
#: Goal real-time factors (simulated s per CPU s) per segment count; MISS is printed, not raised.
RTF_GOALS = {1: 10.0, 2: 3.0}
#: The same for ``simulate`` (issue 36).
SIMULATE_GOALS = {1: 30.0, 2: 30.0}
PERIODS = 4.0
SINE_KPA = 15.0


def release_force(model, fw0):
    """A tip force along x moving the tip by about 1 % of its height (linear estimate)."""
    probe = 0.01
    fw = solve_forward(model, np.zeros(model.A), tip_force_n=[probe, 0.0, 0.0])
    moved = abs(fw.position[0] - fw0.position[0]) / probe
    return 0.01 * fw0.position[2] / max(moved, 1e-12)


def _inputs(model, kind, f1):
    """The pressures of a run: the start's (release) or the top segment's sine."""
    if kind != "sine":
        return np.zeros(model.A)
    top = model.A - model.cfg.segments[-1].n_actuators
    period = 2.0 / f1

    def pressures(t):
        p = np.zeros(model.A)
        p[top] = SINE_KPA * 1e3 * (1.0 - np.cos(2 * np.pi * t / period))
        return p
    return pressures


def run_once(model, fw_start, kind, f1, released, way):
    """One run: (CPU time per step or sample [s], real-time factor, steps, halvings, ok)."""
    ig = GeneralizedAlpha(model)
    if released:
        ig.start_released(fw_start)
    else:
        ig.start(fw_start)
    t_end = PERIODS / f1
    pressures = _inputs(model, kind, f1)
    if way == "simulate":
        marks = []
        advance = ig.advance

        def timed(*args, **kw):   # a mark per sample: its step and the previous read-outs
            marks.append(time.process_time())
            return advance(*args, **kw)
        ig.advance = timed
        c0 = time.process_time()
        run = sample_motion(ig, t_end, pressures_pa=pressures, check_s=CHECK_S)
        cpu = time.process_time() - c0
        times = np.diff(np.r_[marks, c0 + cpu])
        return times, ig.state.t / cpu, run.report.steps, run.report.halvings, run.success
    steps, halvings, ok = [], 0, True
    c_run = time.process_time()
    while ig.state.t < t_end - 1e-9 * ig.step_s:
        c0 = time.process_time()
        rep = ig.advance(min(ig.state.t + ig.step_s, t_end), pressures_pa=pressures)
        steps.append(time.process_time() - c0)
        halvings += rep.halvings
        if not rep.success:
            ok = False
            break
    cpu = time.process_time() - c_run
    return np.array(steps), ig.state.t / cpu, len(steps), halvings, ok


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
    ways = (("integrator", RTF_GOALS), ("simulate", SIMULATE_GOALS))
    for kind, start, released in (("release", fw_f, True), ("sine", fw0, False)):
        got = {way: ([], [], True, 0, 0) for way, _ in ways}
        for way, _ in ways:
            run_once(model, start, kind, f1, released, way)   # warm-up: caches, compilation
        for _ in range(reps):   # the two ways interleaved: both see the same machine load
            for way, _ in ways:
                times, rtfs, ok_all, _, n_halv = got[way]
                st, rtf, n, h, ok = run_once(model, start, kind, f1, released, way)
                times.append(st)
                rtfs.append(rtf)
                got[way] = (times, rtfs, ok_all and ok, n, n_halv + h)
        for way, goals in ways:
            times, rtfs, ok_all, n_steps, n_halv = got[way]
            st = np.concatenate(times)
            goal = goals.get(m)
            med = float(np.median(rtfs))
            verdict = "no goal" if goal is None else (
                f"{'PASS' if med >= goal else 'MISS'} (goal {goal:g}x)")
            what = "step  " if way == "integrator" else "sample"
            print(f"  {kind:<8} {way:<10} steps {n_steps:5d}  {what} CPU median "
                  f"{np.median(st) * 1e3:7.3f} ms  p99 {np.percentile(st, 99) * 1e3:7.3f} ms  "
                  f"RTF median {med:7.2f}x  lowest {min(rtfs):7.2f}x  halvings {n_halv}  "
                  f"{'completed' if ok_all else 'FAILED'}  {verdict}", flush=True)
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
    print(f"dynamics bench: GeneralizedAlpha at the default step, step by step (integrator) and "
          f"as `bellow-ancf simulate` runs it (simulate: every step sampled, checks every "
          f"{CHECK_S * 1e3:g} ms), {args.reps} repetitions after a warm-up run; real-time factor "
          f"= simulated s / CPU s; {os.cpu_count()} CPUs, load average {load} (1, 5, 15 min)",
          flush=True)
    for m in args.segments:
        bench_robot(m, args.reps)


if __name__ == "__main__":
    main()
