"""``bellow-ancf compliance`` and ``bellow-ancf stiffness``: the tip under forces.

::

    bellow-ancf compliance [--config C] --pressures-kpa P1 P2 ... [--payload-kg M]
                           [--tip-force-n FX FY FZ] [--elements N] [--json]
    bellow-ancf stiffness [--config C] [--payload-kg M ...] [--levels N]
                          [--trajectory NAME [--points N]] [--plot PNG] [--json] [--quiet]

``compliance``: the end effector's compliance and stiffness at one
equilibrium (:func:`bellow_ancf_ros.core.solve.tip_compliance`); JSON keys
``translational_compliance_m_per_n``, ``axis_compliance_per_n``,
``stiffness_n_per_m`` (nested 3x3 lists, ``[i][j]`` = d(output i)/d(force j),
base frame), and the equilibrium's ``status``, ``message`` and ``position_m``.
``stiffness``: the tip's vertical stiffness against equal actuation pressure,
per payload (:func:`bellow_ancf_ros.core.experiments.studies.stiffness_study`),
or along a trajectory (``--trajectory``).
"""

from __future__ import annotations

import numpy as np

from ..core import limit_blas_threads, solve_forward, studies, tip_compliance
from .common import (EXIT_FAILED, EXIT_OK, add_config, add_loads, add_out, add_quiet,
                     call_solver, element_count, emit_json, finite_float, int_at_least,
                     load_config, load_model, make_model, payload_mass, print_lines, progress,
                     run_study)
from .output import figure, save_figure, table
from .solve import check_pressures_kpa

__all__ = ['register']


def _matrix_lines(label, M, scale, unit):
    rows = [f'{label:<22}' + ' '.join(f'{v * scale:11.4g}' for v in M[0]) + f'   {unit}']
    rows += [' ' * 22 + ' '.join(f'{v * scale:11.4g}' for v in r) for r in M[1:]]
    return rows


def _cmd_compliance(args) -> int:
    limit_blas_threads()
    model = load_model(args)
    p = check_pressures_kpa(model, args.pressures_kpa)
    fw = call_solver(solve_forward, model, p, payload_kg=args.payload_kg,
                     tip_force_n=args.tip_force_n)
    if not fw.converged:
        d = dict(status=int(fw.status), message=fw.message, position_m=None)
        if args.json:
            emit_json(d)
        else:
            print_lines([f'status                {int(fw.status)}: {fw.message}',
                         'no compliance without a converged equilibrium'])
        return EXIT_FAILED
    c = tip_compliance(fw)
    d = c.to_dict() | dict(status=int(fw.status), message=fw.message,
                           position_m=fw.position.tolist(), stable=fw.stable,
                           vertical_stiffness_n_per_m=c.vertical_stiffness_n_per_m)
    if args.json:
        emit_json(d)
        return EXIT_OK if fw.success else EXIT_FAILED
    lines = [f'robot                 {model.cfg.name}, payload {args.payload_kg:g} kg, tip force '
             + ('none' if args.tip_force_n is None
                else ' '.join(f'{v:g}' for v in args.tip_force_n) + ' N'),
             'tip position          '
             + ' '.join(f'{v * 1e3:.3f}' for v in fw.position) + '  mm',
             f'status                {int(fw.status)}: {fw.message}']
    lines += _matrix_lines('compliance d p / d F', c.translational_m_per_n, 1e3, 'mm/N')
    lines += _matrix_lines('axis d z / d F', c.axis_per_n, 1.0, '1/N')
    lines += _matrix_lines('stiffness K = C^-1', c.stiffness_n_per_m, 1.0, 'N/m')
    lines.append(f'vertical stiffness    {c.vertical_stiffness_n_per_m:.4g} N/m '
                 '(vertical force per vertical motion, 1/C_zz)')
    print_lines(lines)
    return EXIT_OK if fw.success else EXIT_FAILED


def _fmt(v, fmt='.1f'):
    return '-' if v is None or not np.isfinite(v) else format(v, fmt)


def _cmd_stiffness(args) -> int:
    limit_blas_threads()
    cfg = load_config(args)
    payloads = args.payload_kg or [0.0, 0.05, 0.1]
    if args.trajectory:
        model = make_model(cfg, args.elements)
        res = run_study(studies.stiffness_along_trajectory, model, args.trajectory,
                        n_points=args.points, payload_kg=payloads[0])
        if args.plot:
            fig = figure(8, 4)
            ax = fig.add_subplot(1, 1, 1)
            for key, label in (('vertical_n_per_m', 'vertical'), ('lateral_x_n_per_m', 'x'),
                               ('lateral_y_n_per_m', 'y')):
                ax.plot(res['times_s'], res[key], label=label)
            ax.set_xlabel('time [s]')
            ax.set_ylabel('tip stiffness [N/m]')
            ax.set_yscale('log')
            ax.set_title(f'{cfg.name}: {args.trajectory}, payload {payloads[0]:g} kg')
            ax.legend()
            save_figure(fig, args.plot)
        if args.json:
            emit_json(res | {'plot': args.plot})
            return EXIT_OK
        rows = []
        for key, label in (('vertical_n_per_m', 'vertical (1/C_zz)'),
                           ('lateral_x_n_per_m', 'x (1/C_xx)'),
                           ('lateral_y_n_per_m', 'y (1/C_yy)')):
            v = res[key][np.isfinite(res[key])]
            rows.append([label] + ([_fmt(f(v)) for f in (np.min, np.median, np.max)]
                                   if v.size else ['-'] * 3))
        lines = [f'robot        {cfg.name}: {args.trajectory}, {args.points} points, payload '
                 f'{payloads[0]:g} kg; {int(res["usable"].sum())} usable answers', '']
        lines += table(['tip stiffness [N/m]', 'min', 'median', 'max'], rows,
                       ['<', '>', '>', '>'])
        if args.plot:
            lines.append(f'plot         {args.plot}')
        print_lines(lines)
        return EXIT_OK
    res = run_study(studies.stiffness_study, cfg, payloads, n_levels=args.levels,
                    n_elements=args.elements, progress=progress(args, 'stiffness'))
    if args.plot:
        fig = figure(8, 4)
        ax = fig.add_subplot(1, 1, 1)
        for m in res['payloads_kg']:
            sel = [r for r in res['rows'] if r['payload_kg'] == m]
            ax.plot([r['pressure_pa'] / 1e3 for r in sel],
                    [np.nan if r['vertical_n_per_m'] is None else r['vertical_n_per_m']
                     for r in sel], marker='o', label=f'{m * 1e3:g} g')
        ax.set_xlabel('pressure, every actuator [kPa gauge]')
        ax.set_ylabel('vertical tip stiffness [N/m]')
        ax.set_title(f'{cfg.name}: vertical stiffness against actuation pressure')
        ax.legend(title='payload')
        save_figure(fig, args.plot)
    if args.json:
        emit_json({k: v for k, v in res.items() if k != 'rows'}
                  | {'rows': [{k: v for k, v in r.items() if k != 'stiffness_n_per_m'}
                              for r in res['rows']], 'plot': args.plot})
        return EXIT_OK
    rows = [[f'{r["payload_kg"]:g}', f'{r["pressure_pa"] / 1e3:g}', _fmt(r['vertical_n_per_m']),
             _fmt(r['lateral_x_n_per_m'], '.2f'), 'yes' if r['usable'] else 'no (buckles)']
            for r in res['rows']]
    lines = [f'robot        {cfg.name}, n = {res["n_elements"]}: every actuator at the same '
             'pressure', '']
    lines += table(['payload [kg]', 'pressure [kPa]', 'vertical [N/m]', 'lateral [N/m]',
                    'usable'], rows, ['>', '>', '>', '>', '<'])
    if args.plot:
        lines.append(f'plot         {args.plot}')
    print_lines(lines)
    return EXIT_OK


def register(subparsers) -> None:
    """Add ``compliance`` and ``stiffness``."""
    p = subparsers.add_parser(
        'compliance', help="the tip's compliance and stiffness at an equilibrium",
        description='Forward solve at the given pressures (payload, tip force), then the end '
                    "effector's compliance d position/d force (m/N), d z-axis/d force (1/N) and "
                    'stiffness (N/m, the inverse of the first), exact from the equilibrium '
                    '(implicit-function theorem). [i][j] = d(output i)/d(force j), base frame.')
    add_config(p)
    p.add_argument('--pressures-kpa', type=finite_float, nargs='+', required=True, metavar='P',
                   help='one gauge pressure per actuator [kPa]')
    add_loads(p)
    p.add_argument('--elements', type=element_count, default=None, metavar='N',
                   help="ANCF elements per actuator; default: the robot file's value")
    p.add_argument('--json', action='store_true', help='print one JSON object (SI units)')
    p.set_defaults(func=_cmd_compliance)

    s = subparsers.add_parser(
        'stiffness', help='tip stiffness against actuation pressure, or along a trajectory',
        description="The tip's vertical (1/C_zz) and lateral (1/C_xx) stiffness with every "
                    'actuator at the same pressure, from p_min to p_max, per payload (the '
                    "paper's claim that the model predicts the vertical stiffness with different "
                    'actuation pressures); with --trajectory, at the feedforward answers along '
                    'that trajectory (the first payload).')
    add_config(s)
    s.add_argument('--payload-kg', type=payload_mass, nargs='+', default=None, metavar='M',
                   help='payloads [kg]; default: 0 0.05 0.1')
    s.add_argument('--levels', type=int_at_least(2), default=9, metavar='N',
                   help='pressure levels from p_min to p_max; default: %(default)s')
    s.add_argument('--trajectory', metavar='NAME', default=None,
                   help='stiffness along this trajectory instead (bellow-ancf track --help)')
    s.add_argument('--points', type=int_at_least(1), default=50, metavar='N',
                   help='trajectory points; default: %(default)s')
    s.add_argument('--elements', type=element_count, default=None, metavar='N',
                   help="ANCF elements per actuator; default: the robot file's value")
    add_out(s)
    add_quiet(s)
    s.set_defaults(func=_cmd_stiffness)
