"""``bellow-ancf convergence``, ``workspace`` and ``compare-pcc``: model studies.

::

    bellow-ancf convergence [--config C] [--max-elements N] [--reference N] [--tol-mm T]
                            [--payload-kg M] [--repeats R] [--plot PNG] [--json]
    bellow-ancf workspace [--config C] [--payload-kg M ...] [--points N] [--elements N]
                          [--plot PNG] [--csv FILE] [--json]
    bellow-ancf compare-pcc [--config C] [--payload-kg M ...] [--points N] [--no-gravity]
                            [--plot PNG] [--csv FILE] [--json]

The studies themselves are :mod:`bellow_ancf_ros.core.experiments.studies`.  A readable
table on stdout, or with ``--json`` one JSON summary object on one line (SI
units); progress of long runs on stderr (``--quiet`` silences it); plots are
PNG files.  ``workspace --csv`` writes one row per solve: ``payload_kg,
scheme, scheme_name, step``, the pressures in kPa (one column
``s<segment>_a<actuator>_kpa`` per actuator), ``x_mm, y_mm, z_mm``, the
z-axis ``zx, zy, zz``, ``converged, stable``.
"""

from __future__ import annotations

import csv
import math

import numpy as np

from ..core import limit_blas_threads, studies
from .common import (EXIT_FAILED, EXIT_OK, add_config, add_out, add_quiet, emit_json,
                     int_at_least, load_config, payload_mass, positive_float, print_lines,
                     progress, run_study)
from .output import (actuator_columns, figure, fit_3d_axes, legend_outside, open_out,
                     save_figure, table)


# ------------------------------------------------------- convergence
def _cmd_convergence(args):
    limit_blas_threads()
    cfg = load_config(args)
    res = run_study(studies.convergence_study, cfg, counts=range(1, args.max_elements + 1),
                    reference_n=args.reference, threshold_m=args.tol_mm * 1e-3,
                    payload_kg=args.payload_kg, repeats=args.repeats,
                    progress=progress(args, 'convergence'))
    if args.plot:
        _plot_convergence(res, args.plot)
    if args.json:
        emit_json(res.to_dict())
        return EXIT_OK

    def error_text(r):
        if r.error_m is None:
            return 'refused' if r.refused else 'failed'
        return f'{r.error_m * 1e3:.3e}'

    rows = [[r.n, 'yes' if r.nodes_on_plates else 'no', error_text(r),
             '-' if r.refused else f'{r.time_s * 1e3:.1f}', '<-' if r.n == res.recommended else '']
            for r in res.rows]
    lines = [f'robot         {cfg.name}: reference n = {res.reference_n} '
             f'({res.reference_time_s * 1e3:.0f} ms), payload {res.payload_kg:g} kg, '
             f'actuations: {", ".join(res.actuations_pa)}',
             'error         largest end-effector position error over the actuations', '']
    lines += table(['n', 'nodes on plates', 'error [mm]', 'time [ms]', ''], rows)
    if res.recommended is not None:
        lines += ['', f'recommended   n = {res.recommended}: {res.reason}']
    else:
        lines += ['', f'recommended   none: {res.reason}']
    if args.plot:
        lines.append(f'plot          {args.plot}')
    print_lines(lines)
    return EXIT_OK


def _plot_convergence(res, path):
    fig = figure(7.5, 5.0, constrained=True)
    ax = fig.add_subplot(1, 1, 1)
    ns = np.array([r.n for r in res.rows])
    err = np.array([np.nan if r.error_m is None else max(r.error_m, 1e-12)
                    for r in res.rows]) * 1e3
    on = np.array([r.nodes_on_plates for r in res.rows])
    ax.semilogy(ns, err, '-', color='tab:blue')
    ax.semilogy(ns[on], err[on], 'o', color='tab:blue', label='error, nodes on plates')
    ax.semilogy(ns[~on], err[~on], 'o', mfc='none', color='tab:blue',
                label='error, plates inside elements')
    ax.axhline(res.threshold_m * 1e3, ls=':', color='gray',
               label=f'threshold {res.threshold_m * 1e3:g} mm')
    if res.recommended is not None:
        ax.axvline(res.recommended, ls='--', color='tab:green',
                   label=f'recommended n = {res.recommended}')
    ax.set_xlabel('elements per actuator n')
    ax.set_ylabel(f'tip error vs n = {res.reference_n} [mm]', color='tab:blue')
    ax.grid(True, alpha=0.3, which='both')
    ax2 = ax.twinx()
    ax2.plot(ns, [r.time_s * 1e3 for r in res.rows], 's-', color='tab:red', ms=4,
             label='solve time (right axis)')
    ax2.set_ylabel('solve time [ms]', color='tab:red')
    legend_outside(fig, ax, 'lower center', ncol=3)
    ax.set_title(f'element convergence ({res.config_name})')
    save_figure(fig, path)


# --------------------------------------------------------- workspace
def _cmd_workspace(args):
    limit_blas_threads()
    cfg = load_config(args)
    payloads = args.payload_kg or [0.0]
    res = run_study(studies.workspace_study, cfg, payloads, n_points=args.points,
                    n_elements=args.elements, progress=progress(args, 'workspace'))
    rows = res['rows']
    if args.csv:
        cols = actuator_columns(cfg)
        with open_out(args.csv, '--csv') as fh:
            w = csv.writer(fh)
            w.writerow(['payload_kg', 'scheme', 'scheme_name', 'step'] + cols
                       + ['x_mm', 'y_mm', 'z_mm', 'zx', 'zy', 'zz', 'converged', 'stable'])
            for r in rows:
                w.writerow([f'{r["payload_kg"]:g}', r['scheme'] + 1, r['scheme_name'], r['step']]
                           + [f'{v / 1e3:.6g}' for v in r['pressures_pa']]
                           + [f'{v * 1e3:.6f}' for v in r['position_m']]
                           + [f'{v:.8f}' for v in r['z_axis']]
                           + [int(r['converged']),
                              '' if r['stable'] is None else int(bool(r['stable']))])
    summary = []
    for m in res['payloads_kg']:
        sel = [r for r in rows if r['payload_kg'] == m]
        good = [r for r in sel if r['converged'] and r['stable'] is not False]
        P = np.array([r['position_m'] for r in good]) if good else np.full((1, 3), np.nan)
        summary.append(dict(payload_kg=m, points=len(sel), solved=len(good),
                            x_range_m=[float(np.min(P[:, 0])), float(np.max(P[:, 0]))],
                            y_range_m=[float(np.min(P[:, 1])), float(np.max(P[:, 1]))],
                            z_range_m=[float(np.min(P[:, 2])), float(np.max(P[:, 2]))],
                            max_radius_m=float(np.max(np.hypot(P[:, 0], P[:, 1])))))
    if args.plot:
        _plot_workspace(res, args.plot)
    failed = any(s['solved'] < s['points'] for s in summary)
    if args.json:
        emit_json({'config': cfg.name, 'schemes': res['schemes'], 'n_points': res['n_points'],
                   'n_elements': res['n_elements'], 'summary': summary, 'csv': args.csv,
                   'plot': args.plot})
        return EXIT_FAILED if failed else EXIT_OK
    lines = [f'robot         {cfg.name}: {len(res["schemes"])} actuation schemes x '
             f'{res["n_points"]} points, n = {res["n_elements"]} elements', '']
    lines += table(['payload [kg]', 'solved', 'x [mm]', 'y [mm]', 'z [mm]', 'max radius [mm]'],
                   [[f'{s["payload_kg"]:g}', f'{s["solved"]}/{s["points"]}',
                     f'{s["x_range_m"][0] * 1e3:.2f} .. {s["x_range_m"][1] * 1e3:.2f}',
                     f'{s["y_range_m"][0] * 1e3:.2f} .. {s["y_range_m"][1] * 1e3:.2f}',
                     f'{s["z_range_m"][0] * 1e3:.2f} .. {s["z_range_m"][1] * 1e3:.2f}',
                     f'{s["max_radius_m"] * 1e3:.2f}'] for s in summary])
    lines += ['', 'schemes:'] + [f'  {k + 1:2d}  {name}' for k, name in enumerate(res['schemes'])]
    if args.csv:
        lines.append(f'csv           {args.csv}')
    if args.plot:
        lines.append(f'plot          {args.plot}')
    print_lines(lines)
    return EXIT_FAILED if failed else EXIT_OK


def _payload_colors(n):
    from matplotlib import colormaps
    cmap = colormaps['viridis']
    return [cmap(0.15 + 0.7 * k / max(1, n - 1)) for k in range(n)]


def _scheme_colors(n):
    """``n`` distinct colours (tab10 up to 10, tab20 up to 20, then spread over a hue circle)."""
    from matplotlib import colormaps
    if n <= 10:
        return [colormaps['tab10'](k) for k in range(n)]
    if n <= 20:
        return [colormaps['tab20'](k) for k in range(n)]
    return [colormaps['hsv'](k / n) for k in range(n)]


#: line styles of the payloads in the workspace plot (cycled)
_PAYLOAD_STYLES = ('-', '--', ':', '-.')


def _plot_workspace(res, path):
    """Boundary curves: one colour per actuation scheme, one line style per payload."""
    from matplotlib.lines import Line2D

    n_schemes = len(res['schemes'])
    fig = figure(13, 5.5, constrained=True)
    ax3 = fig.add_subplot(1, 2, 1, projection='3d')
    ax2 = fig.add_subplot(1, 2, 2)
    colors = _scheme_colors(n_schemes)
    styles = [_PAYLOAD_STYLES[i % len(_PAYLOAD_STYLES)] for i in range(len(res['payloads_kg']))]
    drawn = []
    for m, style in zip(res['payloads_kg'], styles):
        for k in range(n_schemes):
            pts = np.array([r['position_m'] for r in res['rows']
                            if r['payload_kg'] == m and r['scheme'] == k
                            and r['converged'] and r['stable'] is not False]) * 1e3
            if pts.size == 0:
                continue
            drawn.append(pts)
            ax3.plot(pts[:, 0], pts[:, 1], pts[:, 2], style, color=colors[k], lw=1)
            ax2.plot(pts[:, 0], pts[:, 1], style, color=colors[k], lw=1)
    ax3.set_xlabel('x [mm]')
    ax3.set_ylabel('y [mm]')
    ax3.set_zlabel('z [mm]')
    ax3.set_title(f'workspace boundaries ({res["config"]})')
    if drawn:
        fit_3d_axes(ax3, np.concatenate(drawn), min_span=5.0)
    ax2.set_xlabel('x [mm]')
    ax2.set_ylabel('y [mm]')
    ax2.set_aspect('equal', adjustable='datalim')
    ax2.set_title('top view')
    ax2.grid(True, alpha=0.3)
    handles = [Line2D([], [], color=colors[k], lw=1.5, label=f'{k + 1}: {name}')
               for k, name in enumerate(res['schemes'])]
    fig.legend(handles=handles, loc='outside right upper', fontsize=7, frameon=False,
               title='actuation scheme', title_fontsize=8)
    if len(res['payloads_kg']) > 1:
        fig.legend(handles=[Line2D([], [], color='k', ls=st, lw=1, label=f'{m * 1e3:g} g')
                            for m, st in zip(res['payloads_kg'], styles)],
                   loc='outside right lower', fontsize=7, frameon=False, title='payload',
                   title_fontsize=8)
    save_figure(fig, path)


# ------------------------------------------------------- compare-pcc
def _cmd_compare_pcc(args):
    limit_blas_threads()
    cfg = load_config(args)
    payloads = args.payload_kg or [0.0, 0.05, 0.1]
    res = run_study(studies.compare_pcc, cfg, payloads, n_points=args.points,
                    n_elements=args.elements, gravity=not args.no_gravity,
                    progress=progress(args, 'compare-pcc'))
    if args.csv:
        cols = actuator_columns(cfg)
        with open_out(args.csv, '--csv') as fh:
            w = csv.writer(fh)
            w.writerow(['payload_kg', 'category', 'scheme_name', 'step'] + cols
                       + ['ancf_x_mm', 'ancf_y_mm', 'ancf_z_mm',
                          'pcc_x_mm', 'pcc_y_mm', 'pcc_z_mm', 'diff_mm', 'angle_deg', 'converged'])
            for r in res['rows']:
                w.writerow([f'{r["payload_kg"]:g}', r['category'], r['scheme_name'], r['step']]
                           + [f'{v / 1e3:.6g}' for v in r['pressures_pa']]
                           + [f'{v * 1e3:.6f}' for v in r['ancf_m']]
                           + [f'{v * 1e3:.6f}' for v in r['pcc_m']]
                           + [f'{r["diff_m"] * 1e3:.6f}', f'{math.degrees(r["angle_rad"]):.6f}',
                              int(r['converged'])])
    if args.plot:
        _plot_pcc(res, args.plot)
    if args.json:
        emit_json({k: v for k, v in res.items() if k != 'rows'}
                  | {'csv': args.csv, 'plot': args.plot})
        return EXIT_OK
    gravity = 'on' if res['gravity'] else 'off'
    lines = [f'robot         {cfg.name}: ANCF (gravity {gravity}, payload at the tip, '
             f'n = {res["n_elements"]}) vs PCC (kinematic: no gravity, no payload)',
             'difference    |p_ANCF - p_PCC| of the end effector; dz = z_ANCF - z_PCC; '
             'angle between the z-axes', '']

    def fig(v, fmt, scale=1e3):
        return '-' if v is None else format(v * scale, fmt)

    summary_rows = [[f'{s["payload_kg"]:g}', s['category'], f'{s["usable"]} of {s["points"]}',
                     fig(s['rms_m'], '.3f'), fig(s['max_m'], '.3f'), fig(s['mean_dz_m'], '+.3f'),
                     fig(s['max_angle_rad'], '.2f', math.degrees(1.0))]
                    for s in res['summary']]
    lines += table(['payload [kg]', 'actuations', 'usable points', 'RMS [mm]', 'max [mm]',
                   'mean dz [mm]', 'max angle [deg]'], summary_rows,
                   ['>', '<', '>', '>', '>', '>', '>'])
    if any(s['usable'] < s['points'] for s in res['summary']):
        lines.append('not usable    points without a converged, stable equilibrium (the robot '
                     'buckles there); figures over the usable points only, - when none')
    if args.csv:
        lines.append(f'csv           {args.csv}')
    if args.plot:
        lines.append(f'plot          {args.plot}')
    print_lines(lines)
    return EXIT_OK


def _plot_pcc(res, path):
    fig = figure(11, 5.4, constrained=True)
    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    colors = _payload_colors(len(res['payloads_kg']))
    rows = res['rows']
    names = []
    for r in rows:
        if r['scheme_name'] not in names:
            names.append(r['scheme_name'])
    first = True
    for name in names:
        sel = [r for r in rows
               if r['scheme_name'] == name and r['payload_kg'] == res['payloads_kg'][0]]
        pts = np.array([r['pcc_m'] for r in sel]) * 1e3
        ax1.plot(pts[:, 0], pts[:, 2], '--', color='k', lw=0.8, label='PCC' if first else None)
        first = False
    for m, col in zip(res['payloads_kg'], colors):
        first = True
        for name in names:
            sel = [r for r in rows
                   if r['scheme_name'] == name and r['payload_kg'] == m and r['converged']]
            if not sel:
                continue
            pts = np.array([r['ancf_m'] for r in sel]) * 1e3
            ax1.plot(pts[:, 0], pts[:, 2], '-', color=col, lw=1,
                     label=f'ANCF {m * 1e3:g} g' if first else None)
            first = False
        sel = [r for r in rows if r['payload_kg'] == m]
        ax2.plot(np.arange(len(sel)), [r['diff_m'] * 1e3 for r in sel], '.-', color=col, ms=3,
                 lw=0.6, label=f'{m * 1e3:g} g')
    ax1.set_xlabel('x [mm]')
    ax1.set_ylabel('z [mm]')
    ax1.set_title('end effector, side view (x-z)')
    ax1.grid(True, alpha=0.3)
    legend_outside(fig, ax1, 'lower center', ncol=len(res['payloads_kg']) + 1)
    ax2.set_xlabel('actuation index (elongation sweep, then the workspace schemes)')
    ax2.set_ylabel('|ANCF - PCC| [mm]')
    ax2.set_title(f'PCC vs ANCF ({res["config"]})')
    ax2.grid(True, alpha=0.3)
    save_figure(fig, path)


# ------------------------------------------------------------ parser
def register(subparsers):
    """Add ``convergence``, ``workspace`` and ``compare-pcc``."""
    _register_convergence(subparsers)
    _register_workspace(subparsers)
    _register_compare_pcc(subparsers)


def _register_convergence(subparsers):
    """Add ``convergence``."""
    p = subparsers.add_parser(
        'convergence', help='tip error and solve time vs element count (paper Fig. 4(d))',
        description='End-effector error of n = 1..N elements per actuator against a converged '
                    'reference at extreme actuations (largest error over: actuator 1 at p_max and '
                    'the others at 0 as in the paper; actuator 1 at p_max, others at p_min; '
                    'actuators 1, 2 at p_max, others at p_min), the median solve time, and the '
                    'recommended count: the smallest with an error below --tol-mm that puts a '
                    'node on every plate.')
    add_config(p)
    p.add_argument('--max-elements', type=int_at_least(1), default=12, metavar='N',
                   help='test n = 1..N; default: %(default)s')
    p.add_argument('--reference', type=int_at_least(1), default=48, metavar='N',
                   help='element count of the reference solution; default: %(default)s')
    p.add_argument('--tol-mm', type=positive_float, default=0.01, metavar='T',
                   help='error threshold of the recommendation [mm]; default: %(default)s')
    p.add_argument('--payload-kg', type=payload_mass, default=0.0, metavar='M',
                   help='payload [kg]; default: %(default)s')
    p.add_argument('--repeats', type=int_at_least(1), default=3, metavar='R',
                   help='timed solves per count and actuation (median); default: %(default)s')
    add_out(p)
    add_quiet(p)
    p.set_defaults(func=_cmd_convergence)


def _register_workspace(subparsers):
    """Add ``workspace``."""
    p = subparsers.add_parser(
        'workspace', help='workspace boundaries of the paper\'s actuation schemes (paper VI.B)',
        description="Sweep the paper's actuation schemes from p_min to p_max with warm-started "
                    'forward solves, for each payload. One segment: 18 schemes (one actuator '
                    'swept, the other two at every p_min/p_max combination; two swept, the third '
                    'at p_min or p_max). Two segments: s11+s21, s11+s22, s11+s21+s22, s11+s22+s23 '
                    'swept, the others at 0 kPa. Plot: boundary curves in 3-D and top view; CSV: '
                    'one row per solve.')
    add_config(p)
    p.add_argument('--payload-kg', type=payload_mass, nargs='+', default=[0.0], metavar='M',
                   help='payloads [kg]; default: 0')
    p.add_argument('--points', type=int_at_least(2), default=21, metavar='N',
                   help='points per scheme; default: %(default)s')
    p.add_argument('--elements', type=int_at_least(1), default=None, metavar='N',
                   help="ANCF elements per actuator; default: the robot file's")
    p.add_argument('--csv', metavar='FILE', help='write every solve as a CSV row')
    add_out(p, 'print one JSON summary object instead of the table')
    add_quiet(p)
    p.set_defaults(func=_cmd_workspace)


def _register_compare_pcc(subparsers):
    """Add ``compare-pcc``."""
    p = subparsers.add_parser(
        'compare-pcc', help='where the PCC model and the ANCF model disagree',
        description='End-effector positions of the ANCF model (gravity, payload) and the '
                    'kinematic piecewise-constant-curvature model (same stage 1, no forces) along '
                    'a pure elongation sweep and the workspace schemes, per payload.')
    add_config(p)
    p.add_argument('--payload-kg', type=payload_mass, nargs='+', default=None, metavar='M',
                   help='payloads [kg]; default: 0 0.05 0.1')
    p.add_argument('--points', type=int_at_least(2), default=11, metavar='N',
                   help='points per scheme; default: %(default)s')
    p.add_argument('--elements', type=int_at_least(1), default=None, metavar='N',
                   help="ANCF elements per actuator; default: the robot file's")
    p.add_argument('--no-gravity', action='store_true',
                   help="switch the ANCF model's gravity off (the payload then has no weight "
                        'either)')
    p.add_argument('--csv', metavar='FILE', help='write every compared actuation as a CSV row')
    add_out(p, 'print one JSON summary object instead of the table')
    add_quiet(p)
    p.set_defaults(func=_cmd_compare_pcc)
