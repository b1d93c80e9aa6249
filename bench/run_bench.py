"""Speed benchmarks (`make bench`): median, p99, ratio to today's figure, scaling table.

Cases (issue 11): cold forward, straight -> maximum deformation (actuator 1 of
every segment at p_max, the others at p_min), stability check included, one
and two segments; warm-started inverse along a circle of targets 1 mm apart
(position; position and z-axis for two segments), stability of every answer
included.  Targets (medians on a shared 2-core machine): cold forward
<= 3 ms / 10 ms, warm inverse <= 1.0 ms / 2.5 ms, ROS end to end <= 2 ms / 4 ms.

"today" is the same case on the code before the real-time rewrite (commit
1f2d442).  ``--baseline DIR`` (a checkout of that commit, e.g. ``git worktree
add /tmp/base 1f2d442``) runs both codes in this process, interleaved call by
call, so that both see the same machine load; ``--write-today`` stores the
baseline's figures of such a run in ``bench/today.json``, which later runs
without ``--baseline`` quote.  The baseline runs with BLAS at one thread, as
its entry points did.  Interleaving gives fair ratios, but each call then
starts with caches the other code has just filled (the short solves pay most:
up to 1.5x); so the forward and inverse cases also run the new code alone,
call after call, as a controller runs it, straight after the interleaved
pass.  The medians and p99 of the table and the targets are those; the
interleaved median is printed beside them, and the speed-up is the
interleaved ratio.  The scaling table times a warm inverse step and the
stability check alone over elements per actuator n = 3, 6, 12, 24 and
segments m = 1..4.

The markdown table for the README goes to ``bench/speed_table.md``
(``make readme-speed`` puts it into README.md).  Timing is wall-clock on a
shared machine: read medians, not single runs.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib
import json
import os
import shutil
import sys
import tempfile
import time
import types

import numpy as np

import bellow_ancf_ros.core as new_core
from bellow_ancf_ros.core import load_robot, solve_forward

HERE = os.path.dirname(os.path.abspath(__file__))
TODAY_FILE = os.path.join(HERE, "today.json")
TABLE_FILE = os.path.join(HERE, "speed_table.md")

TARGET_S = {
    "forward one_segment": 0.003,
    "forward two_segment": 0.010,
    "inverse one_segment": 0.0010,
    "inverse two_segment": 0.0025,
    "ros one_segment": 0.002,
    "ros two_segment": 0.004,
}
PAPER_S = {"forward one_segment": 0.62, "forward two_segment": 5.32}  # MATLAB, Ryzen 7 3700X
ELEMENTS = (3, 6, 12, 24)
SEGMENTS = (1, 2, 3, 4)


def _times(fn, repeats):
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def _stats(times):
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
        z = np.stack(
            [np.sin(tilt) * np.cos(phi), np.sin(tilt) * np.sin(phi), np.full(n, np.cos(tilt))],
            axis=1,
        )
    return pos, z


def scaling_robot(m):
    """``m`` stacked default segments; from three segments on, lighter (masses, density (2/m)^2).

    The default segments stacked four high buckle under their own weight;
    the lighter stack stands, so that every timed answer is a stable one.
    """
    if m == 1:
        return load_robot("one_segment")
    two = load_robot("two_segment")
    segs = [two.segments[0]] + [two.segments[1]] * (m - 1)
    if m <= 2:
        return two
    f = (2.0 / m) ** 2
    segs = [
        dataclasses.replace(
            s,
            connector_mass=f * s.connector_mass,
            top_plate_mass=f * s.top_plate_mass,
            constraint_plate_mass=f * s.constraint_plate_mass,
        )
        for s in segs
    ]
    return two.replace(segments=tuple(segs), rho0=f * two.rho0)


def pressure_walk(model, n_targets, step_m=1e-3):
    """Reachable targets about 1 mm apart: forward poses along a circle in pressure space."""
    cfg = model.cfg
    mid = np.full(model.A, 30e3)
    amp = 20e3

    def pose(phi):
        p = mid.copy()
        for s in cfg.actuator_slices:
            k = np.arange(s.stop - s.start)
            p[s] += amp * np.cos(phi - 2 * np.pi * k / len(k))
        fw = solve_forward(model, p)
        return fw.position, fw.z_axis

    p0, _ = pose(0.0)
    p1, _ = pose(0.1)
    dphi = 0.1 * step_m / max(np.linalg.norm(p1 - p0), 1e-9)
    poses = [pose(k * dphi) for k in range(n_targets + 1)]
    return np.array([p for p, _ in poses]), np.array([z for _, z in poses])


def make_impl(core, blas_one_thread=False):
    """The entry points of one version of the core (``core``: its package module)."""
    solve = getattr(core, "solve", None)  # this tree: core.solve; the baseline: core.forward
    fwd = solve if hasattr(solve, "assess_stability") else importlib.import_module(
        core.__name__ + ".forward")
    ctx = contextlib.nullcontext
    if blas_one_thread:
        from threadpoolctl import threadpool_limits

        def ctx():  # noqa: F811
            return threadpool_limits(limits=1, user_api="blas")

    return types.SimpleNamespace(
        RobotModel=core.RobotModel,
        solve_forward=core.solve_forward,
        solve_inverse=core.solve_inverse,
        assess_stability=fwd.assess_stability,
        ctx=ctx,
    )


def load_baseline(checkout):
    """Import the core of another checkout under the name ``bellow_ancf_ros_baseline``."""
    src = os.path.join(checkout, "bellow_ancf_ros")
    if not os.path.isdir(os.path.join(src, "core")):
        raise SystemExit(f"--baseline: {checkout} has no bellow_ancf_ros/core")
    tmp = tempfile.mkdtemp(prefix="bench_baseline_")
    shutil.copytree(
        src,
        os.path.join(tmp, "bellow_ancf_ros_baseline"),
        ignore=shutil.ignore_patterns("__pycache__"),
    )
    sys.path.insert(0, tmp)
    return make_impl(
        importlib.import_module("bellow_ancf_ros_baseline.core"), blas_one_thread=True
    )


def _timed(impl, fn):
    with impl.ctx():
        t0 = time.perf_counter()
        out = fn()
        return time.perf_counter() - t0, out


def _row(key, case, times, extra=None):
    row = {"key": key, "case": case}
    row["median_s"], row["p99_s"] = _stats(times[0])
    if len(times) > 1:
        row["base_median_s"], row["base_p99_s"] = _stats(times[1])
    row.update(extra or {})
    return row


def bench_forward(impls, name, repeats):
    """Cold forward solve, straight -> maximum deformation, with the stability check."""
    cfg = load_robot(name)
    models = [im.RobotModel(cfg) for im in impls]
    p = extreme_pressures(models[0])
    res = solve_forward(models[0], p)
    assert res.converged and res.stable, res.message
    times = [[] for _ in impls]
    for _ in range(repeats):
        for i, (im, m) in enumerate(zip(impls, models)):
            times[i].append(_timed(im, lambda: im.solve_forward(m, p))[0])
    im, m = impls[0], models[0]
    alone = [_timed(im, lambda: im.solve_forward(m, p))[0] for _ in range(repeats)]
    return _row(
        f"forward {name}",
        f"forward {name}, straight -> maximum deformation "
        f"({res.iterations} Newton it. + {len(res.history) - 1 - res.iterations} chord steps)",
        times,
        {"iterations": res.iterations, **_alone(alone)},
    )


def _alone(times):
    """The new code timed on its own, back to back, as a controller runs it."""
    med, p99 = _stats(times)
    return {"alone_median_s": med, "alone_p99_s": p99}


def _inverse_chain(impls, models, targets, z, laps=1, start=None):
    """Warm-started inverse along the targets for every implementation, interleaved per target.

    ``start``: the warm starts of the first target (default: a cold solve of it).
    """
    times = [[] for _ in impls]
    prev = list(start) if start is not None else [
        im.solve_inverse(m, targets[0], None if z is None else z[0])
        for im, m in zip(impls, models)
    ]
    ok, errs, proved = 0, [], []
    for _ in range(laps):
        for k in range(len(targets)):
            for i, (im, m) in enumerate(zip(impls, models)):
                dt, prev[i] = _timed(
                    im,
                    lambda: im.solve_inverse(
                        m, targets[k], None if z is None else z[k], warm_start=prev[i]
                    ),
                )
                times[i].append(dt)
            ok += bool(prev[0].success and prev[0].forward.stable)
            errs.append(prev[0].position_error_m)
            # proved stable by the linear-time test (the rest: decided by the exact dense test)
            chk = prev[0].forward._reduced_hessian if prev[0].forward is not None else None
            proved.append(getattr(chk, "proved_by", None) is not None)
    return times, ok, errs, prev, int(np.sum(proved))


def bench_inverse(impls, name, laps):
    """Warm-started inverse along 1 mm steps; every answer must be reached and stable."""
    cfg = load_robot(name)
    models = [im.RobotModel(cfg) for im in impls]
    pos, z = circle_path(models[0])
    times, ok, errs, prev, proved = _inverse_chain(impls, models, pos, z, laps)
    n = len(times[0])
    alone, _, _, _, _ = _inverse_chain(impls[:1], models[:1], pos, z, laps, start=prev[:1])
    return _row(
        f"inverse {name}",
        f"inverse {name}, warm, 1 mm steps ({ok} of {n} reached and stable, "
        f"{proved} proved by the linear-time test)",
        times,
        {"answers": n, "stable_reached": ok, "banded_proofs": proved,
         "max_position_error_m": float(np.max(errs)), **_alone(alone[0])},
    )


def bench_scaling(impls, m, n, n_targets):
    """Warm inverse step and stability check alone: ``m`` segments, ``n`` elements each."""
    cfg = scaling_robot(m)
    models = [im.RobotModel(cfg, n) for im in impls]
    multi = m > 1
    pos, z = pressure_walk(models[0], n_targets)
    times, ok, _, prev, proved = _inverse_chain(impls, models, pos[1:], z[1:] if multi else None)
    st = [[] for _ in impls]
    for _ in range(5):
        for i, im in enumerate(impls):
            fw = prev[i].forward
            st[i].append(_timed(im, lambda: im.assess_stability(fw))[0])
    row = _row(
        f"scaling m={m} n={n}",
        f"scaling m={m} n={n}",
        times,
        {"m": m, "n": n, "unknowns": models[0].N, "stable_reached": ok, "answers": len(times[0]),
         "banded_proofs": proved},
    )
    row["stability_median_s"], row["stability_p99_s"] = _stats(st[0])
    if len(impls) > 1:
        row["base_stability_median_s"], row["base_stability_p99_s"] = _stats(st[1])
    return row


def _ratio(today, key, value):
    t = today.get(key)
    return None if t is None else t / value


def _fmt_ms(s):
    return "-" if s is None else f"{s * 1e3:.2f} ms"


def render_markdown(rows, today):
    """The README's speed table (medians, p99, today's figure, speed-up, target)."""
    lines = [
        "| case | median | p99 | interleaved median | before (1f2d442) | speed-up | target |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        t = today.get(r["key"], {}).get("median_s")
        target = TARGET_S.get(r["key"])
        ratio = "-" if t is None else f"{t / r['median_s']:.1f}x"
        med = r.get("alone_median_s", r["median_s"])
        met = (
            "-"
            if target is None
            else f"{target * 1e3:g} ms ({'met' if med <= target else 'not met'})"
        )
        lines.append(
            f"| {r['case']} | {_fmt_ms(med)} | {_fmt_ms(r.get('alone_p99_s', r['p99_s']))} "
            f"| {_fmt_ms(r['median_s'])} | {_fmt_ms(t)} | {ratio} | {met} |"
        )
    return "\n".join(lines) + "\n"


def render_scaling_markdown(cells, today):
    """Scaling table: warm inverse step and stability check per (segments, elements)."""
    lines = [
        "| segments m | elements n | unknowns | warm inverse step | stability check | "
        "before: inverse / stability |",
        "|---|---|---|---|---|---|",
    ]
    for c in cells:
        t = today.get(c["key"], {})
        before = (
            f"{_fmt_ms(t.get('median_s'))} / {_fmt_ms(t.get('stability_median_s'))}" if t else "-"
        )
        lines.append(
            f"| {c['m']} | {c['n']} | {c['unknowns']} | {_fmt_ms(c['median_s'])} "
            f"| {_fmt_ms(c['stability_median_s'])} | {before} |"
        )
    return "\n".join(lines) + "\n"


def _today_of(row, today, field="median_s"):
    """Today's figure of a row: the interleaved baseline's, else bench/today.json's."""
    v = row.get("base_" + field)
    return v if v is not None else today.get(row["key"], {}).get(field)


def _print_rows(rows, today):
    print(f"{'case':<82} {'median':>9} {'p99':>9} {'interl.':>9} {'today':>9} {'speed-up':>8} "
          f"{'target':>9}")
    for r in rows:
        t = _today_of(r, today)
        target = TARGET_S.get(r["key"])
        paper = PAPER_S.get(r["key"])
        med = r.get("alone_median_s", r["median_s"])
        t_s = "-" if t is None else f"{t * 1e3:7.2f}ms"
        up = "-" if t is None else f"{t / r['median_s']:.2f}x"
        tg = "-" if target is None else f"{target * 1e3:g}ms"
        extra = "" if paper is None else f"   (paper {paper:g} s: {paper / med:.0f}x)"
        print(
            f"{r['case']:<82} {med * 1e3:7.2f}ms {r.get('alone_p99_s', r['p99_s']) * 1e3:7.2f}ms "
            f"{r['median_s'] * 1e3:7.2f}ms {t_s:>9} {up:>8} {tg:>9}{extra}"
        )


def _print_cells(cells, today):
    print(
        "\nscaling: warm inverse step (1 mm steps, stability included) and stability check alone"
    )
    print(
        f"{'m':>2} {'n':>3} {'unknowns':>8} {'inverse':>9} {'p99':>9} {'us/unkn':>8} "
        f"{'stability':>9} {'p99':>9} {'today inv':>10} {'today stab':>10} {'speed-up':>8} "
        f"{'stable':>7} {'banded':>7}"
    )
    for c in cells:
        ti, ts = _today_of(c, today), _today_of(c, today, "stability_median_s")
        ti_s = "-" if ti is None else f"{ti * 1e3:8.2f}ms"
        ts_s = "-" if ts is None else f"{ts * 1e3:8.3f}ms"
        up = "-" if ti is None else f"{ti / c['median_s']:.1f}x"
        print(
            f"{c['m']:>2} {c['n']:>3} {c['unknowns']:>8} {c['median_s'] * 1e3:7.2f}ms "
            f"{c['p99_s'] * 1e3:7.2f}ms {c['median_s'] / c['unknowns'] * 1e6:8.2f} "
            f"{c['stability_median_s'] * 1e3:7.3f}ms {c['stability_p99_s'] * 1e3:7.3f}ms "
            f"{ti_s:>10} {ts_s:>10} {up:>8} {c['stable_reached']:>3}/{c['answers']} "
            f"{c['banded_proofs']:>3}/{c['answers']}"
        )


def _ros_row(r, robot, base=None):
    row = {
        "key": f"ros {robot}",
        "median_s": r["median_s"],
        "p99_s": r["p99_s"],
        "case": "ROS end to end, target_pose -> pressure_command reception, separate processes, "
        f"{robot.replace('_', ' ')} ({r['answered']} of {r['sent']} answered; at the client's "
        f"callback {r['callback_median_s'] * 1e3:.2f} ms)",
    }
    row["alone_median_s"], row["alone_p99_s"] = r["median_s"], r["p99_s"]  # one node at a time
    if base is not None:
        row["base_median_s"], row["base_p99_s"] = base["median_s"], base["p99_s"]
    return row


def main(argv=None):
    """Run the benchmarks, print them, write the markdown table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=30, help="repetitions of each forward solve")
    ap.add_argument("--laps", type=int, default=2, help="laps of the inverse circle")
    ap.add_argument("--scaling-targets", type=int, default=12, help="targets per scaling cell")
    ap.add_argument(
        "--no-ros", action="store_true", help="skip the end-to-end ROS latency benchmark"
    )
    ap.add_argument("--no-scaling", action="store_true", help="skip the scaling table")
    ap.add_argument("--baseline", metavar="DIR", help="checkout of the old code, run interleaved")
    ap.add_argument(
        "--write-today", action="store_true", help="with --baseline: write bench/today.json"
    )
    ap.add_argument("--json", help="write all figures to this JSON file")
    ap.add_argument("--no-table", action="store_true", help="do not write bench/speed_table.md")
    args = ap.parse_args(argv)
    today = {}
    if os.path.exists(TODAY_FILE) and not args.baseline:
        with open(TODAY_FILE) as f:
            today = {r["key"]: r for r in json.load(f)["rows"]}
    impls = [make_impl(new_core)]
    if args.baseline:
        impls.append(load_baseline(args.baseline))

    def dot():
        print(".", end="", file=sys.stderr, flush=True)

    rows = []
    for name in ("one_segment", "two_segment"):
        rows.append(bench_forward(impls, name, args.repeats))
        dot()
    for name in ("one_segment", "two_segment"):
        rows.append(bench_inverse(impls, name, args.laps))
        dot()
    cells = []
    if not args.no_scaling:
        for m in SEGMENTS:
            for n in ELEMENTS:
                cells.append(bench_scaling(impls, m, n, args.scaling_targets))
                dot()
    if not args.no_ros:
        import ros_latency  # same folder; needs the ROS 2 client libraries of the venv

        for robot in ("one_segment", "two_segment"):
            r = ros_latency.main(robot=robot, quiet=True)
            base = (ros_latency.main(robot=robot, quiet=True, pythonpath=args.baseline)
                    if args.baseline else None)
            rows.append(_ros_row(r, robot, base))
    print(file=sys.stderr)
    _print_rows(rows, today)
    if cells:
        _print_cells(cells, today)
    print("median, p99: the new code on its own, call after call (as a controller runs it; the "
          "ROS rows: one node at a time); interl.: the same calls interleaved call by call with "
          "today's code, which evicts the caches between them; speed-up: today / interl.")
    print("stable: answers reached and stable; banded: stability proved by the linear-time "
          "(envelope) test (the others by the exact dense test)")
    print(
        "today: the same case on the code before the rewrite (commit 1f2d442; "
        + (
            "interleaved in this run"
            if args.baseline
            else "bench/today.json, another run: ratios indicative only; --baseline DIR "
            "measures them side by side"
        )
        + "); speed-up > 1 is faster"
    )
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"rows": rows + cells}, f, indent=1)
    if args.write_today:
        if not args.baseline:
            raise SystemExit("--write-today needs --baseline")
        keep = ("median_s", "p99_s", "stability_median_s", "stability_p99_s")
        out = [
            {
                "key": r["key"],
                **{k: r["base_" + k] for k in keep if "base_" + k in r},
                "new_median_s_same_run": r["median_s"],
            }
            for r in rows + cells
        ]
        with open(TODAY_FILE, "w") as f:
            json.dump(
                {
                    "commit": "1f2d442",
                    "note": "baseline figures, measured interleaved with the new "
                    "code in one run (bench/run_bench.py --baseline --write-today)",
                    "rows": out,
                },
                f,
                indent=1,
            )
        print(f"wrote {os.path.relpath(TODAY_FILE)}")
    if not args.no_table:
        if args.baseline:
            today = {
                r["key"]: {
                    "median_s": r.get("base_median_s"),
                    "stability_median_s": r.get("base_stability_median_s"),
                }
                for r in rows + cells
            }
        with open(TABLE_FILE, "w") as f:
            f.write(render_markdown(rows, today))
            if cells:
                f.write("\n" + render_scaling_markdown(cells, today))
        print(f"wrote {os.path.relpath(TABLE_FILE)} (make readme-speed puts it into README.md)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
