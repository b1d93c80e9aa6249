"""The main demo's plot: 3-D paths and errors over time (:mod:`.closed_loop`)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ['MODES', 'MODE_NAMES', 'PAPER', 'figure', 'plot', 'rms']

PAPER = 'paper, real two-segment robot, feedforward: 4.14 mm and 1.58 deg on average'
MODES = ('none', 'dynamic', 'integral')
MODE_NAMES = {'none': 'feedforward', 'dynamic': 'dynamic FF', 'integral': 'closed loop'}


def rms(v: np.ndarray) -> float:
    """Root mean square."""
    return float(math.sqrt(np.mean(np.square(v))))


def plot(results: dict, cases, path: Path) -> None:
    """Write :func:`figure` as a PNG to ``path``."""
    import matplotlib.pyplot as plt
    fig = figure(results, cases)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100, bbox_inches='tight')
    plt.close(fig)


def figure(results: dict, cases):
    """3-D paths (target, robot under FF and CL) and errors over time, one column per case.

    ``cases``: objects with ``key`` (into ``results``), ``label`` and
    ``bending_angle_deg`` (None: one segment).

    Only the evaluated period is drawn (no lead-in from the straight robot, no hold), and
    the 3-D axes use plain tick labels (no offset label that would collide with them).
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.ticker import ScalarFormatter

    fig = plt.figure(figsize=(5.0 * len(cases), 11))
    gs = fig.add_gridspec(3, len(cases), height_ratios=[2.2, 1, 1], hspace=0.45, wspace=0.25)
    colours = {'none': 'tab:orange', 'dynamic': 'tab:blue', 'integral': 'tab:green'}
    for col, case in enumerate(cases):
        res = results.get(case.key, {})
        ax = fig.add_subplot(gs[0, col], projection='3d')
        ref = res.get('none') or res.get('dynamic') or res.get('integral')
        for mode in MODES:
            r = res.get(mode)
            if r and 'measured' in r:
                mp = r['measured'] * 1e3   # the evaluated period only: no lead-in, no return
                ax.plot(mp[:, 0], mp[:, 1], mp[:, 2], '-', lw=0.8, color=colours[mode],
                        label=f'robot, {MODE_NAMES[mode]}')
        if ref and 'target' in ref:   # drawn last, dashed: visible over the closed loop
            tp = ref['target'] * 1e3
            ax.plot(tp[:, 0], tp[:, 1], tp[:, 2], '--', lw=1.4, color='k', label='target',
                    zorder=10)
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            fmt = ScalarFormatter(useOffset=False)   # no offset label to collide with ticks
            fmt.set_scientific(False)
            axis.set_major_formatter(fmt)
        if ref and 'target' in ref:
            zc = float(np.mean(ref['target'][:, 2])) * 1e3
            ax.set_zlim(zc - 5.0, zc + 5.0)            # a 10 mm z window: few, short tick labels
        ax.locator_params(axis='z', nbins=5)
        ax.tick_params(axis='z', pad=6)
        ax.set_xlabel('x [mm]')
        ax.set_ylabel('y [mm]')
        ax.set_zlabel('z [mm]', labelpad=12)
        ax.set_title(case.label, fontsize=10)
        ax.legend(loc='upper center', bbox_to_anchor=(0.5, -0.04), ncol=3, fontsize=8,
                  frameon=False)   # below the axes, not over the paths
        for row, (key, unit, scale) in enumerate((('pos_err', 'position error [mm]', 1e3),
                                                  ('ang_err', 'angle error [deg]', 180 / math.pi)),
                                                 start=1):
            a = fig.add_subplot(gs[row, col])
            if key == 'ang_err' and case.bending_angle_deg is None:
                a.axis('off')
                a.text(0.5, 0.5, 'one segment: position control only', ha='center',
                       va='center', fontsize=9)
                continue
            for mode in MODES:
                r = res.get(mode)
                if r and key in r:
                    a.plot(r['t'], r[key] * scale, '-', lw=0.8, color=colours[mode],
                           label=f'{MODE_NAMES[mode]} (RMSE {rms(r[key] * scale):.2f})')
            a.set_ylabel(unit)
            a.set_xlabel('time in the evaluated period [s]')
            a.grid(True, alpha=0.3)
            a.set_ylim(bottom=0.0)
            a.legend(fontsize=7, loc='lower center', bbox_to_anchor=(0.5, 1.0), ncol=2,
                     frameon=False)   # above the plot, not over the data
    fig.suptitle('bellow_ancf_ros: mismatched simulated robot, true pose vs target '
                 f'({PAPER})', fontsize=10)
    return fig
