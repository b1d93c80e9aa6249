"""Text tables, output files and PNG figures of the ``bellow-ancf`` subcommands.

Figures use matplotlib's Agg canvas, imported on first use.
"""

from __future__ import annotations

import math

from .common import UsageError


# ------------------------------------------------------------ tables
def table(headers, rows, aligns=None):
    """Plain aligned text table: a list of lines."""
    cells = [[str(h) for h in headers]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    aligns = aligns or ['>'] * len(headers)
    out = []
    for k, r in enumerate(cells):
        out.append('  '.join(f'{c:{a}{w}}' for c, a, w in zip(r, aligns, widths)).rstrip())
        if k == 0:
            out.append('  '.join('-' * w for w in widths))
    return out


def fmt(value, spec='.4g', none='n/a'):
    """Format ``value`` with ``spec``; ``none`` for None and non-finite values."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return none
    return format(value, spec)


# ------------------------------------------------------------- files
def open_out(path, option):
    """Open an output file for ``option``; failure is a :class:`UsageError`."""
    try:
        return open(path, 'w', newline='', encoding='utf-8')
    except OSError as exc:
        raise UsageError(f'{option} {path}: cannot write file: {exc.strerror or exc}') from None


def actuator_columns(cfg):
    """CSV column names ``s<segment>_a<actuator>_kpa`` of the robot."""
    names = []
    for j, seg in enumerate(cfg.segments):
        names += [f's{j + 1}_a{i + 1}_kpa' for i in range(seg.n_actuators)]
    return names


# ----------------------------------------------------------- figures
def figure(width=10.0, height=4.5):
    """A matplotlib figure without a GUI backend."""
    from matplotlib.figure import Figure
    return Figure(figsize=(width, height), dpi=100)


def save_figure(fig, path):
    """Write ``fig`` as PNG to ``path``; failure is a :class:`UsageError`."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    FigureCanvasAgg(fig)
    fig.tight_layout()
    try:
        fig.savefig(path, format='png')
    except OSError as exc:
        raise UsageError(f'--plot {path}: cannot write file: {exc.strerror or exc}') from None
