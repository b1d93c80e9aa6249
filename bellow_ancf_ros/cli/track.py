"""``bellow-ancf track``: offline feedforward tracking of a trajectory (paper VI.C).

::

    bellow-ancf track --trajectory NAME [--config C] [--payload-kg M] [--points N]
                      [--radius-mm R] [--height-mm H] [--bending-angle-deg B] [--period-s T]
                      [--controller ancf|pcc] [--csv FILE] [--plot PNG] [--json]

The pressure sequence goes to a CSV file: ``time_s`` and one column per
actuator, ``s<segment>_a<actuator>_kpa``, gauge pressure in kPa (1 kPa =
1000 Pa; the core and the JSON use Pa).  Exit status 1 when a target was not
reached.
"""

from __future__ import annotations

import csv
import math

import numpy as np

from ..core import limit_blas_threads, studies, trajectories
from .common import (EXIT_FAILED, EXIT_OK, UsageError, add_config, add_out, add_quiet,
                     emit_json, finite_float, int_at_least, load_config, make_model,
                     payload_mass, positive_float, print_lines, progress, run_study)
from .output import (actuator_columns, figure, fit_3d_axes, fmt, legend_outside, open_out,
                     save_figure, table)


# ------------------------------------------------------------- track
def _cmd_track(args):
    limit_blas_threads()
    cfg = load_config(args)
    model = make_model(cfg, args.elements)
    params = _trajectory_params(args, cfg)
    res = run_study(studies.tracking_study, model, args.trajectory, n_points=args.points,
                    payload_kg=args.payload_kg, params=params, controller=args.controller,
                    progress=progress(args, 'track'))
    st = res.stats()
    if args.csv:
        with open_out(args.csv, '--csv') as fh:
            w = csv.writer(fh)
            w.writerow(['time_s'] + actuator_columns(cfg))
            for t, p in zip(res.times_s, res.pressures_pa):
                w.writerow([f'{t:.6g}'] + [f'{v / 1e3:.6f}' for v in p])
    if args.plot:
        _plot_track(res, args.plot)
    ok = st['reachable_fraction'] == 1.0 and st['success_fraction'] == 1.0
    if args.json:
        d = res.to_dict()
        d.update(n_elements=model.n, csv=args.csv, plot=args.plot)
        emit_json(d)
    else:
        print_lines(_track_lines(args, cfg, model, res, st))
    return EXIT_OK if ok else EXIT_FAILED


def _trajectory_params(args, cfg):
    """The trajectory overrides given on the command line, checked against the robot."""
    names = trajectories.MULTI_SEGMENT_TRAJECTORIES if cfg.n_segments >= 2 else \
        trajectories.ONE_SEGMENT_TRAJECTORIES
    if args.trajectory not in names:
        raise UsageError(f'--trajectory: {args.trajectory!r} is not a trajectory of the '
                         f'{cfg.n_segments}-segment robot; choose from {", ".join(names)}')
    params = {}
    if args.radius_mm is not None:
        params['radius'] = args.radius_mm * 1e-3
    if args.height_mm is not None:
        params['height'] = args.height_mm * 1e-3
    if args.bending_angle_deg is not None:
        params['bending_angle_deg'] = args.bending_angle_deg
    if args.period_s is not None:
        params['period'] = args.period_s
    try:
        # validate the parameters
        trajectories.trajectory(args.trajectory, [0.0], config=cfg, **params)
    except ValueError as exc:
        raise UsageError(f'--trajectory {args.trajectory}: {exc}') from None
    return params


def _track_lines(args, cfg, model, res, st):
    """The readable report of a tracking run."""
    p = res.params
    centre = ', '.join(f'{c * 1e3:.2f}' for c in p['center'])
    lines = [
        f'robot         {cfg.name}, n = {model.n} elements, payload {args.payload_kg:g} kg, '
        f'feedforward from the {args.controller.upper()} inverse',
        f'trajectory    {args.trajectory}: {st["points"]} points over {p["period"]:g} s, radius '
        f'{p["radius"] * 1e3:.2f} mm, centre ({centre}) mm'
        + (f', bending angle {p["bending_angle_deg"]:g} deg' if 'bending_angle_deg' in p else ''),
        'errors        forward model at the feedforward pressures vs the target', '',
    ]
    rows = [['position error [mm]',
             fmt(st['position_rms_m'] and st['position_rms_m'] * 1e3, '.3e'),
             fmt(st['position_max_m'] and st['position_max_m'] * 1e3, '.3e')]]
    if st['angle_rms_rad'] is not None:
        rows.append(['angle error [deg]', f'{math.degrees(st["angle_rms_rad"]):.3e}',
                     f'{math.degrees(st["angle_max_rad"]):.3e}'])
    lines += table(['', 'RMS', 'max'], rows, ['<', '>', '>'])
    lines += ['',
              f'reachable     {100 * st["reachable_fraction"]:.1f} % of the points '
              f'(successful, stable: {100 * st["success_fraction"]:.1f} %)',
              f'solve time    median {st["solve_time_median_s"] * 1e3:.1f} ms, p99 '
              f'{st["solve_time_p99_s"] * 1e3:.1f} ms, '
              f'max {st["solve_time_max_s"] * 1e3:.1f} ms per inverse']
    if args.csv:
        lines.append(f'csv           {args.csv} (time_s, pressures in kPa)')
    if args.plot:
        lines.append(f'plot          {args.plot}')
    return lines


def _plot_track(res, path):
    fig = figure(14, 5, constrained=True)
    fig.get_layout_engine().set(wspace=0.1)   # room for the 3-D z label beside the top view
    ax1 = fig.add_subplot(1, 3, 1, projection='3d')
    ax2 = fig.add_subplot(1, 3, 2)
    ax3 = fig.add_subplot(1, 3, 3)
    T, Pp = res.targets_m * 1e3, res.predicted_m * 1e3
    ax1.plot(T[:, 0], T[:, 1], T[:, 2], '-', color='k', lw=1.5, label='desired')
    ax1.plot(Pp[:, 0], Pp[:, 1], Pp[:, 2], 'o', color='tab:orange', ms=2.5,
             label='predicted (forward model at the feedforward pressures)')
    ax1.set_xlabel('x [mm]')
    ax1.set_ylabel('y [mm]')
    ax1.set_zlabel('z [mm]')
    # a circle at one height: z varies by round-off; show at least 10 mm of each axis
    fit_3d_axes(ax1, np.concatenate([T, Pp]), min_span=10.0)
    ax1.set_title(f'{res.trajectory} ({res.config_name}, {res.payload_kg * 1e3:g} g)')
    ax2.plot(T[:, 0], T[:, 1], '-', color='k', lw=1.5)
    ax2.plot(Pp[:, 0], Pp[:, 1], 'o', color='tab:orange', ms=2.5)
    ax2.set_aspect('equal', adjustable='datalim')
    ax2.set_xlabel('x [mm]')
    ax2.set_ylabel('y [mm]')
    ax2.set_title('top view')
    ax2.grid(True, alpha=0.3)
    legend_outside(fig, ax1, 'lower center', ncol=2)
    cols = _actuator_columns_cfgless(res.pressures_pa.shape[1])
    for k in range(res.pressures_pa.shape[1]):
        ax3.plot(res.times_s, res.pressures_pa[:, k] / 1e3, '-', lw=1, label=cols[k])
    ax3.set_xlabel('time [s]')
    ax3.set_ylabel('pressure [kPa]')
    ax3.set_title('feedforward pressures')
    ax3.grid(True, alpha=0.3)
    fig.legend(*ax3.get_legend_handles_labels(), loc='outside right upper', fontsize=7,
               frameon=False, title='actuator', title_fontsize=8)
    save_figure(fig, path)


def _actuator_columns_cfgless(A):
    if A % 3 == 0 and A > 3:
        return [f's{k // 3 + 1},{k % 3 + 1}' for k in range(A)]
    return [f'a{k + 1}' for k in range(A)]


# ------------------------------------------------------------ parser
def register(subparsers):
    """Add ``track``."""
    p = subparsers.add_parser(
        'track', help='offline feedforward tracking of a trajectory (paper VI.C)',
        description='Run the inverse along a trajectory (warm-started point to point), write the '
                    'pressure sequence (CSV: time_s and one column s<segment>_a<actuator>_kpa per '
                    'actuator, gauge pressure in kPa; 1 kPa = 1000 Pa) and print tracking '
                    'statistics from the forward model at those pressures: position and angle '
                    'error RMS and max, reachable fraction, solve time median and p99. Exit '
                    'status 1 if a target was not reached.')
    p.add_argument('--trajectory', required=True, choices=trajectories.TRAJECTORY_NAMES,
                   metavar='NAME',
                   help='one of: ' + ', '.join(trajectories.TRAJECTORY_NAMES))
    add_config(p)
    p.add_argument('--payload-kg', type=payload_mass, default=0.0, metavar='M',
                   help='payload [kg]; default: %(default)s')
    p.add_argument('--points', type=int_at_least(1), default=100, metavar='N',
                   help='points over one period; default: %(default)s')
    p.add_argument('--elements', type=int_at_least(1), default=None, metavar='N',
                   help="ANCF elements per actuator; default: the robot file's")
    p.add_argument('--radius-mm', type=positive_float, default=None, metavar='R',
                   help='trajectory radius [mm]; default: from the robot')
    p.add_argument('--height-mm', type=finite_float, default=None, metavar='H',
                   help='height of the trajectory centre [mm]; default: from the robot')
    p.add_argument('--bending-angle-deg', type=finite_float, default=None, metavar='B',
                   help='bending angle (two or more segments, circles) [deg]')
    p.add_argument('--period-s', type=positive_float, default=None, metavar='T',
                   help='period of the trajectory [s] (time column only); default: from the robot')
    p.add_argument('--controller', choices=('ancf', 'pcc'), default='ancf',
                   help="model whose inverse gives the feedforward pressures (pcc: the paper's "
                        'baseline; the errors are always from the ANCF forward model); default: '
                        '%(default)s')
    p.add_argument('--csv', metavar='FILE',
                   help='write the pressure sequence (kPa) to this CSV file')
    add_out(p, 'print one JSON object with the statistics (SI units)')
    add_quiet(p)
    p.set_defaults(func=_cmd_track)
