"""Text tables, output files, robot files and PNG figures of the ``bellow-ancf`` subcommands.

Robot files written by a command (``identify ... --yaml-out``, ``calibrate
--out``) are the source robot file's text with the new values put in their
places (its unit comments and layout stay), provenance comments on top, and
the output file's name (without ``.yaml``) as the robot's ``name``.  The
comment of a value the command fitted or changed tells where the new value
comes from (its old source, a trailing ``(...)``, is dropped: ``l0_m: 0.0963
# unpressurised actuator length [m] (identified by bellow-ancf identify
stiffness on 2025-01-31 from test.csv)``).
Figures use matplotlib's Agg canvas, imported on first use.
"""

from __future__ import annotations

import math
from pathlib import Path
import re

import yaml

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


def number(value, spec='.3f') -> str:
    """``value`` formatted with ``spec``, never as a negative zero.

    A value that rounds to zero prints as zero, at the same width and with a
    ``+`` if ``spec`` asks for one: ``number(-1e-5, '+.3f')`` is ``'+0.000'``,
    not ``'-0.000'``.
    """
    text = format(value, spec)
    if '-' in text:
        try:
            zero = float(text.strip().rstrip('%')) == 0
        except ValueError:
            zero = False
        if zero:
            return format(0.0, spec)
    return text


def numbers(values, spec='.3f') -> str:
    """A bracketed list of :func:`number` texts: ``'[0.000, 0.100, -0.294]'``."""
    return '[' + ', '.join(number(v, spec) for v in values) + ']'


def count(n, noun, plural=None) -> str:
    """``n`` and the noun, singular for one: ``'1 dropout'``, ``'0 dropouts'``."""
    return f'{n} {noun if n == 1 else (plural or noun + "s")}'


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


# ------------------------------------------------------- robot files
def _flow(value) -> str:
    """``value`` as YAML flow text (a scalar, or ``[a, b]``)."""
    return yaml.safe_dump([value], default_flow_style=True, width=10**6).strip()[1:-1]


#: A comment's trailing parenthesis: the source of the value (``(paper V.B)``, ``(assumed)``).
_SOURCE = re.compile(r'\s*\((?:[^()]|\([^()]*\))*\)\s*$')


def _line_key(path: tuple) -> str:
    """A value line's path as a parameter key: ``segments[0].pitch_radius_mm``, ``payload_kg``."""
    if len(path) == 3:
        return f'{path[0]}[{path[1]}].{path[2]}'
    return '.'.join(path)


def _is_fitted(line_key: str, fitted) -> bool:
    """Whether one of the keys ``fitted`` names this line (an element or ``[*]``: its line)."""
    for key in fitted:
        key = re.sub(r'\[\d+\]$', '', key)   # an element of a flow list: the whole line
        if re.fullmatch(re.escape(key).replace(r'\[\*\]', r'\[\d+\]'), line_key):
            return True
    return False


def restamped(comment: str, note: str) -> str:
    """``comment`` (``# what [unit] (old source)``) with ``note`` as its source instead."""
    return f'{_SOURCE.sub("", comment.rstrip())} ({note})'


def values_in_place(original: str, d: dict, note: str | None = None,
                    fitted=()) -> str | None:
    """``original``'s text (its comments, order, layout) with the values of ``d`` put in.

    Handles the robot-file schema: top-level keys, one level of nested
    mappings, and the ``segments`` list of mappings; values are scalars or
    flow lists, comments after them.  Keys of ``d`` the text lacks are
    appended.  None when the result would not read back as ``d`` (the
    caller then writes a plain dump).

    ``note``: the new values' source (``identified by ... on <date> from
    <file>``); the comment of every value that changed, or whose key is
    among ``fitted`` (parameter keys: ``actuator.l0_m``,
    ``segments[*].top_plate_mass_kg``, ...), gets it in place of its old
    source (:func:`restamped`), a value without a comment gets one.  The
    name is never stamped (it is the output file's).
    """
    out, section, seg = [], None, -1
    seen = set()
    lines = original.splitlines()
    while lines and (not lines[0].strip() or lines[0].lstrip().startswith('#')):
        lines.pop(0)   # the nominal file's own header: the provenance lines replace it
    for line in lines:
        body = line.lstrip()
        indent = len(line) - len(body)
        m = re.match(r'(- )?([A-Za-z_]\w*):(\s*)([^#]*?)(\s*)(#.*)?$', body)
        if not body or body.startswith('#') or m is None:
            out.append(line)
            continue
        item, key, gap, value, pad, comment = m.groups()
        if indent == 0:
            section, path = key, (key,)
        elif item:
            seg += 1
            path = (section, seg, key)
        elif section == 'segments':
            path = (section, seg, key)
        else:
            path = (section, key)
        target = d
        try:
            for k in path:
                target = target[k]
        except (KeyError, IndexError, TypeError):
            out.append(line)
            continue
        seen.add(path[0])
        if isinstance(target, dict) or not value:
            out.append(line)
            continue
        try:
            same = yaml.safe_load(value) == target
        except yaml.YAMLError:
            return None
        new = value if same else _flow(target)
        head = line[:indent] + (item or '') + key + ':' + (gap or ' ')
        text = head + new
        stamp = not same or _is_fitted(_line_key(path), fitted)
        space = 1 if comment else 2   # (a new comment: two spaces before it)
        if note and stamp and path != ('name',):
            comment = restamped(comment or '#', note)
        if comment:
            width = len(head) + len(value) + len(pad or '')
            text += ' ' * max(space, width - len(text)) + comment
        out.append(text)
    extra = {k: v for k, v in d.items() if k not in seen}
    text = '\n'.join(out) + '\n'
    if extra:
        text += yaml.safe_dump(extra, sort_keys=False, default_flow_style=None)
    try:
        same = yaml.safe_load(text) == yaml.safe_load(yaml.safe_dump(d))
    except yaml.YAMLError:
        return None
    return text if same else None


def robot_name_for(path) -> str:
    """The robot name a written robot file gets: its file name without ``.yaml`` / ``.yml``."""
    name = Path(str(path)).name
    for suffix in ('.yaml', '.yml'):
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[:-len(suffix)]
    return name


def source_text(source) -> str | None:
    """The text of the robot file ``source`` came from (None when not from a readable file)."""
    try:
        return Path(str(source)).read_text(encoding='utf-8')
    except OSError:
        return None


def robot_file_text(d: dict, header: list[str], original: str | None = None,
                    note: str | None = None, fitted=()) -> str:
    """A robot file: ``header`` comment lines, then ``d`` in ``original``'s layout.

    With the source file's text (``original``), its comments and layout are
    kept and the values of ``d`` put in their places (its own header comment
    lines are replaced by ``header``; the comments of new values name
    ``note`` as their source, :func:`values_in_place`); without it, or when
    its layout cannot be kept, a plain YAML dump of ``d``.
    """
    text = None if original is None else values_in_place(original, d, note, fitted)
    if text is None:
        text = yaml.safe_dump(d, sort_keys=False, default_flow_style=None)
    return ''.join(f'# {line}\n' if line else '#\n' for line in header) + text


def write_text(path, option, text: str) -> None:
    """Write ``text`` to ``path`` for ``option``; failure is a :class:`UsageError`."""
    with open_out(path, option) as fh:
        fh.write(text)


# ----------------------------------------------------------- figures
def figure(width=10.0, height=4.5, constrained=False):
    """A matplotlib figure without a GUI backend.

    ``constrained``: matplotlib's constrained layout, which makes room for
    legends placed outside the axes (:func:`legend_outside`).
    """
    from matplotlib.figure import Figure
    return Figure(figsize=(width, height), dpi=100,
                  layout='constrained' if constrained else None)


def legend_outside(fig, ax, where='lower center', **kwargs):
    """The legend of ``ax`` (and its twin axes) outside every axes, at ``where`` of ``fig``.

    The figure must be ``constrained`` (:func:`figure`), which reserves the
    room; the legend then never hides a data point.  ``where``: ``'lower
    center'``, ``'upper center'``, ``'right upper'``, ... (matplotlib's
    ``'outside ...'`` locations).
    """
    handles, labels = [], []
    for a in [ax, *ax.get_shared_x_axes().get_siblings(ax)]:
        for h, label in zip(*a.get_legend_handles_labels()):
            if label not in labels:
                handles.append(h)
                labels.append(label)
    kwargs.setdefault('fontsize', 8)
    kwargs.setdefault('frameon', False)
    return fig.legend(handles, labels, loc=f'outside {where}', **kwargs)


def fit_3d_axes(ax, points, min_span, pad=0.05):
    """Limits of a 3-D axes around ``points`` (n, 3), each axis at least ``min_span`` wide.

    A coordinate that barely moves (z of a circle at a constant height) would
    otherwise be scaled to its round-off (an offset label like
    ``1e-11+2.09e2`` over the axis label); the tick labels never use an offset,
    and the axes box is shrunk a little so that the z label stays inside the figure.
    """
    import numpy as np
    from matplotlib.ticker import ScalarFormatter

    P = np.asarray(points, dtype=float).reshape(-1, 3)
    P = P[np.all(np.isfinite(P), axis=1)]
    setters = (ax.set_xlim, ax.set_ylim, ax.set_zlim)
    for k, (axis, setter) in enumerate(zip((ax.xaxis, ax.yaxis, ax.zaxis), setters)):
        formatter = ScalarFormatter(useOffset=False)
        axis.set_major_formatter(formatter)
        if len(P):
            lo, hi = float(P[:, k].min()), float(P[:, k].max())
            half = max(hi - lo, min_span) * (0.5 + pad)
            mid = 0.5 * (lo + hi)
            setter(mid - half, mid + half)
    ax.set_box_aspect(None, zoom=0.85)


def save_figure(fig, path):
    """Write ``fig`` as PNG to ``path``; failure is a :class:`UsageError`."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    FigureCanvasAgg(fig)
    if fig.get_layout_engine() is None:
        fig.tight_layout()
    try:
        fig.savefig(path, format='png')
    except OSError as exc:
        raise UsageError(f'--plot {path}: cannot write file: {exc.strerror or exc}') from None
