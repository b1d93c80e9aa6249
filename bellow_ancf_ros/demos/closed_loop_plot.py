"""The main job's pictures (:mod:`.closed_loop`), drawn from its results file.

``demo_tracking.png`` (``--plot``) is the summary: one row per case (one
segment; two segments; two segments carrying 50 g), one column per speed.
Each cell shows, on a log scale (feedforward errors of millimetres next to
closed-loop ones of hundredths), the RMSE of each controller as bars
(position, for two segments also angle) and the error of the held target;
a black dash over a bar group is the closed loop's goal; a closed-loop bar
that misses its goal is red, and the line under the cell names every goal
the closed loop missed and by how much (``MISSED: held 0.612 > 0.500 mm``).
The last row: the step phase (the residual swing unshaped and ZVD-shaped
against its goal) and the run (date, machine load, PASS or FAIL).

``demo_tracking_<n>seg.png`` (next to it) is the detail page of the
``n``-segment cases: one row per case and speed, the path seen from above
(the target wide and grey underneath, each controller's path over it, the
closed loop on top), the position error and, for two segments, the angle
error over the evaluated period (log scale).

The results file (``--results``, :func:`.closed_loop.run_record`) carries
the time series the pages need, so they can be redrawn without a new run::

    python -m bellow_ancf_ros.demos.closed_loop_plot demo_results.json
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
import sys

import numpy as np

from ..cli.common import UsageError
from ..cli.output import figure as new_figure
from ..cli.output import save_figure

__all__ = ['MODES', 'MODE_NAMES', 'PAPER', 'detail_figure', 'detail_path', 'main', 'pages',
           'plot', 'rms', 'summary_figure']

PAPER = 'paper, real two-segment robot, feedforward: 4.14 mm and 1.58 deg on average'
MODES = ('none', 'dynamic', 'integral')
MODE_NAMES = {'none': 'feedforward', 'dynamic': 'dynamic FF', 'integral': 'closed loop'}
COLOURS = {'none': 'tab:orange', 'dynamic': 'tab:blue', 'integral': 'tab:green'}
MISSED = 'tab:red'
FLOOR_MM = 1e-4     # errors drawn on a log scale are clipped to this from below


def rms(v: np.ndarray) -> float:
    """Root mean square."""
    return float(math.sqrt(np.mean(np.square(v))))


def _counts(data: dict) -> list:
    """The segment counts of the cases, each once, ascending."""
    return sorted({c['segments'] for c in data['cases']})


def detail_path(path: Path, segments: int) -> Path:
    """The detail page of ``segments`` next to the summary ``path``: ``<name>_<n>seg.png``."""
    path = Path(path)
    return path.with_name(f'{path.stem}_{segments}seg{path.suffix}')


def pages(path: Path, data: dict) -> list:
    """The files :func:`plot` writes: ``path``, then one detail page per segment count."""
    return [Path(path)] + [detail_path(path, n) for n in _counts(data)]


def plot(data: dict, path: Path) -> list:
    """Write the summary to ``path`` and the detail pages next to it; the files written."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(summary_figure(data), path)
    for n in _counts(data):
        save_figure(detail_figure(data, n), detail_path(path, n))
    return pages(path, data)


def _rows(data: dict) -> tuple:
    """The summary's row labels (cases) and column speeds, in run order."""
    cases, speeds = [], []
    for c in data['cases']:
        if c['case'] not in cases:
            cases.append(c['case'])
        if c['speed'] not in speeds:
            speeds.append(c['speed'])
    return cases, speeds


def _legend_handles(goal=True) -> list:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch
    out = [Patch(color=COLOURS[m], label=MODE_NAMES[m]) for m in MODES]
    out.append(Patch(color=MISSED, label='closed loop, goal missed'))
    if goal:
        out.append(Line2D([], [], color='k', ls='--', label="closed loop's goal"))
    return out


def _bar_cell(ax, c: dict) -> None:
    """One case at one speed: RMSE and held-target bars per controller, goals, misses."""
    two = c['segments'] == 2
    groups = [('RMSE\n[mm]', 'rmse_mm'), ('RMSE\n[deg]', 'rmse_deg'), ('held\n[mm]', 'held_mm'),
              ('held\n[deg]', 'held_deg')]
    groups = [g for g in groups if two or not g[1].endswith('deg')]
    goals = {g['figure']: g for g in c['goals']}
    modes = [m for m in MODES if m in c['modes']]
    width = 0.8 / len(modes)
    values = []
    for x, (_, key) in enumerate(groups):
        g = goals.get(key)
        for k, mode in enumerate(modes):
            r = c['runs'].get(mode) or {}
            v = r.get(key)
            if v is None:
                continue
            v = max(v, FLOOR_MM)
            values.append(v)
            colour = COLOURS[mode]
            if mode == 'integral' and g is not None and not g['met']:
                colour = MISSED
            xb = x - 0.4 + width * (k + 0.5)
            ax.bar(xb, v, width * 0.9, color=colour)
            ax.text(xb, v * 1.25, f'{v:.2g}', ha='center', va='bottom', fontsize=6,
                    rotation=90)
        if g is not None:
            values.append(g['limit'])
            ax.hlines(g['limit'], x - 0.45, x + 0.45, colors='k', linestyles='--', lw=1.2)
    ax.set_yscale('log')
    if values:
        ax.set_ylim(min(values) / 3.0, max(values) * 12.0)
    ax.set_xticks(range(len(groups)), [g[0] for g in groups], fontsize=7)
    ax.tick_params(axis='y', which='both', labelsize=7)
    ax.set_xlim(-0.5, len(groups) - 0.5)
    ax.grid(True, axis='y', alpha=0.3)
    missed = c['missed'] or [f'{MODE_NAMES[m]}: run failed' for m in modes
                             if c['runs'].get(m) is None]
    ax.set_title(f'{c["speed"]:g}x ({c["period_s"]:g} s)', fontsize=9)
    if missed:
        ax.set_xlabel('MISSED: ' + '\n'.join(missed), color=MISSED, fontsize=7)
    else:
        ax.set_xlabel('closed loop: every goal met', color='tab:green', fontsize=7)


def _step_cell(ax, step: dict | None) -> None:
    """The step phase: the feedforward runs' residual swing, the closed loop's step figures."""
    ax.set_title('10 mm step, two segments:\nresidual swing 1-2 s after [mm]', fontsize=9)
    if step is None:
        ax.axis('off')
        ax.text(0.5, 0.5, 'step phase not run', ha='center', va='center', fontsize=8,
                transform=ax.transAxes)
        return
    goals = {g['figure']: g for g in step['goals']}
    g = goals['swing_mm']
    values = []
    for x, (key, name) in enumerate((('none', 'unshaped'), ('zvd', 'ZVD-shaped'))):
        r = step['runs'].get(key)
        if r is None:
            continue
        v = max(r['swing_mm'], FLOOR_MM)
        values.append(v)
        colour = MISSED if key == 'zvd' and not g['met'] else 'tab:gray'
        ax.bar(x, v, 0.6, color=colour)
        ax.text(x, v * 1.25, f'{v:.2g}', ha='center', va='bottom', fontsize=7)
    ax.hlines(g['limit'], 0.55, 1.45, colors='k', linestyles='--', lw=1.2)
    values.append(g['limit'])
    ax.set_yscale('log')
    ax.set_ylim(min(values) / 3.0, max(values) * 8.0)
    ax.set_xticks([0, 1], ['unshaped', 'ZVD-shaped'], fontsize=7)
    ax.set_xlim(-0.5, 1.5)
    ax.tick_params(axis='y', which='both', labelsize=7)
    ax.grid(True, axis='y', alpha=0.3)
    closed = [goals[k] for k in ('overshoot_mm', 'late_mm') if k in goals]
    if closed:   # the closed loop's step: its figures against their goals, in the corner
        text = 'closed loop: ' + ', '.join(
            f'{c["goal"].removeprefix("closed-loop ")} '
            + ('n/a' if c['value'] is None else f'{c["value"]:.2f}') + f' (<= {c["limit"]:g})'
            for c in closed)
        ax.text(0.02, 0.97, text.replace(', ', '\n  '), transform=ax.transAxes, fontsize=6,
                va='top', color='tab:green' if all(c['met'] for c in closed) else MISSED)
    if step['missed'] or not step['ran']:
        ax.set_xlabel('MISSED: ' + ('\n'.join(step['missed']) or 'a run failed'),
                      color=MISSED, fontsize=7)
    else:
        ax.set_xlabel('goals met', color='tab:green', fontsize=7)


def _run_text(data: dict) -> str:
    """The run: when, which machine and how loaded, options, the verdict."""
    m, o = data['machine'], data['options']

    def load(v):
        return 'n/a' if v is None else ', '.join(f'{x:.2f}' for x in v)
    return '\n'.join([
        f'{data["date"]}: {"PASS" if data["passed"] else "FAIL"}'
        + ('' if o['goals_checked'] else ' (goals not checked)'),
        f'{m["cpus"]} CPUs; load average (1, 5, 15 min)',
        f'  at the start {load(m["load_start"])}', f'  at the end {load(m["load_end"])}',
        f'{o["plant"]} plant, periods scaled by {o["period_scale"]:g};',
        f'{data["wall_s"]:.0f} s in all'])


def summary_figure(data: dict):
    """The summary: a cell per case and speed, the step phase and the run (module doc)."""
    cases, speeds = _rows(data)
    ncols = max(len(speeds), 3)
    fig = new_figure(3.3 * ncols, 2.9 * len(cases) + 3.2, constrained=True)
    subs = fig.subfigures(len(cases) + 1, 1, squeeze=False,
                          height_ratios=[1.0] * len(cases) + [1.05])[:, 0]
    by_cell = {(c['case'], c['speed']): c for c in data['cases']}
    for sub, case in zip(subs, cases):
        sub.suptitle(case, fontsize=10, fontweight='bold')
        axes = sub.subplots(1, ncols, squeeze=False)[0]
        for ax, speed in zip(axes, speeds + [None] * (ncols - len(speeds))):
            c = by_cell.get((case, speed))
            if c is None:
                ax.axis('off')
                if speed is not None:
                    ax.text(0.5, 0.5, f'{speed:g}x: not run', ha='center', va='center',
                            fontsize=8, transform=ax.transAxes)
                continue
            _bar_cell(ax, c)
        axes[0].set_ylabel('RMSE, held error\n[mm or deg]', fontsize=8)
    bottom = subs[-1]
    bottom.suptitle('step phase and this run', fontsize=10, fontweight='bold')
    axes = bottom.subplots(1, ncols, squeeze=False)[0]
    _step_cell(axes[0], data.get('step'))
    axes[1].axis('off')
    axes[1].legend(handles=_legend_handles(), loc='center', fontsize=8, frameon=False)
    for ax in axes[2:]:
        ax.axis('off')
    axes[2].text(0.0, 0.5, _run_text(data), ha='left', va='center', fontsize=8,
                 transform=axes[2].transAxes)
    fig.suptitle('make demo: the mismatched simulated robot, true pose against target over the '
                 'second period at full speed\n' + data.get('paper', PAPER), fontsize=10)
    return fig


def _plain_ticks(ax) -> None:
    """Plain tick labels: no offset label that could collide with the title."""
    from matplotlib.ticker import ScalarFormatter
    for axis in (ax.xaxis, ax.yaxis):
        fmt = ScalarFormatter(useOffset=False)
        fmt.set_scientific(False)
        axis.set_major_formatter(fmt)


def detail_figure(data: dict, segments: int):
    """The detail page of the ``segments``-segment cases (module doc)."""
    cols = [c for c in data['cases'] if c['segments'] == segments]
    two = segments > 1
    ncols = 3 if two else 2
    fig = new_figure(4.4 * ncols, 3.1 * len(cols) + 1.0, constrained=True)
    subs = fig.subfigures(len(cols), 1, squeeze=False)[:, 0]
    for sub, c in zip(subs, cols):
        met = c['met'] and all(c['runs'].values())
        status = ('every goal met' if met
                  else 'MISSED: ' + ', '.join(c['missed'] or ['a run failed']))
        sub.suptitle(f'{c["label"]}; closed loop: {status}', fontsize=9,
                     color='k' if met else MISSED)
        axes = sub.subplots(1, ncols, width_ratios=[1.0] + [1.5] * (ncols - 1))
        ax = axes[0]
        target = next((r['series'] for r in c['runs'].values() if r and 'series' in r), None)
        if target is not None:
            tp = np.asarray(target['target_mm'])
            ax.plot(tp[:, 0], tp[:, 1], '-', lw=5, color='0.8', zorder=1, label='target')
        for z, mode in enumerate(MODES, start=2):   # the closed loop drawn last, on top
            r = c['runs'].get(mode)
            if r and 'series' in r:
                mp = np.asarray(r['series']['measured_mm'])
                ax.plot(mp[:, 0], mp[:, 1], '-', lw=1.0, color=COLOURS[mode], zorder=z,
                        label=MODE_NAMES[mode])
        ax.set_aspect('equal', adjustable='datalim')
        _plain_ticks(ax)
        ax.set_title('path seen from above', fontsize=9)
        ax.set_xlabel('x [mm]', fontsize=8)
        ax.set_ylabel('y [mm]', fontsize=8)
        ax.tick_params(labelsize=7)
        for ax, key, unit, goal_key in ((axes[1], 'pos_err_mm', 'mm', 'rmse_mm'),
                                        (axes[2] if two else None, 'ang_err_deg', 'deg',
                                         'rmse_deg')):
            if ax is None:
                continue
            for mode in MODES:
                r = c['runs'].get(mode)
                if r and 'series' in r and key in r['series']:
                    s = r['series']
                    ax.plot(s['t_s'], np.maximum(s[key], FLOOR_MM), '-', lw=0.9,
                            color=COLOURS[mode], label=MODE_NAMES[mode])
            g = next((g for g in c['goals'] if g['figure'] == goal_key), None)
            if g is not None:
                ax.axhline(g['limit'], color='k', ls='--', lw=1.0)
            ax.set_yscale('log')
            ax.set_title(('position' if unit == 'mm' else 'angle') + ' error', fontsize=9)
            ax.set_ylabel(f'[{unit}]', fontsize=8)
            ax.set_xlabel('time in the evaluated period [s]', fontsize=8)
            ax.tick_params(which='both', labelsize=7)
            ax.grid(True, alpha=0.3)
    handles = _legend_handles(goal=False)[:3]
    from matplotlib.lines import Line2D
    handles += [Line2D([], [], color='0.8', lw=5, label='target'),
                Line2D([], [], color='k', ls='--', label="closed loop's RMSE goal")]
    fig.legend(handles=handles, loc='outside lower center', ncol=len(handles), fontsize=8,
               frameon=False)
    fig.suptitle(f'make demo {data["date"]}, {segments} segment{"s" if two else ""}: true '
                 'pose against target over the evaluated period', fontsize=10)
    return fig


def main(argv=None) -> int:
    """Redraw the pictures from a results file."""
    ap = argparse.ArgumentParser(prog='python -m bellow_ancf_ros.demos.closed_loop_plot',
                                 description=__doc__.splitlines()[0])
    ap.add_argument('results', type=Path, help='the results file make demo wrote (--results)')
    ap.add_argument('--plot', type=Path, default=Path('demo_tracking.png'),
                    help='the summary picture (default: %(default)s); the detail pages go '
                         'next to it as <name>_<n>seg.png')
    args = ap.parse_args(argv)
    try:
        data = json.loads(args.results.read_text())
    except (OSError, ValueError) as exc:
        print(f'{args.results}: cannot read a results file: {exc}', file=sys.stderr)
        return 2
    try:
        for path in plot(data, args.plot):
            print(f'{path} written')
    except (KeyError, TypeError) as exc:
        print(f'{args.results}: not a make demo results file ({exc!r} missing or wrong)',
              file=sys.stderr)
        return 2
    except UsageError as exc:
        print(exc, file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
