"""``bellow-ancf identify``: parameters of the equivalent actuator (paper section V).

::

    bellow-ancf identify stiffness --csv FILE [--order N] [--force-per segment|actuator]
                                   [--gravity-share-n F] [--l0-m L] [--config C]
                                   [--plot PNG] [--yaml-out FILE] [--json]
    bellow-ancf identify deff --csv FILE [--confidence C] [--config C] [--plot PNG]
                              [--yaml-out FILE] [--json]
    bellow-ancf identify da --drop-mm D --tip-mass-kg M [--config C] [--elements N] [--json]
    bellow-ancf identify damping (--csv FILE | --bag DIR) ...   (module :mod:`.dynamics`)
    bellow-ancf identify creep (--csv FILE | --bag DIR) ...     (module :mod:`.creep`)
    bellow-ancf identify play (--csv FILE | --bag DIR) ...      (module :mod:`.play`)

A readable table on stdout, or with ``--json`` one JSON object on one line
(SI units, non-finite numbers as ``null``); plots are PNG files.  ``--yaml-out``
writes the ``--config`` robot file with the identified values in their places
(its comments and layout kept; :func:`~bellow_ancf_ros.cli.output.robot_file_text`),
named after the output file.

Data files are CSV with ``#`` comment lines, one header row of column names
and numeric rows:

* ``identify stiffness``: ``dl_mm`` (or ``dl_m``): actuator length change,
  positive in tension; ``force_n``: measured force [N], of the whole segment
  (``--force-per segment``, the default: ``F_e = F_m/n_a - F_g``) or of one
  actuator (``--force-per actuator``: ``F_e = F_m - F_g``).
* ``identify deff``: ``pressure_kpa`` (or ``pressure_pa``) and either
  ``force_n`` (actuation force) or ``length_mm`` (or ``length_m``, the
  measured actuator length, converted with the robot's ``k(lam)`` and ``l0``:
  ``F_a = k(lam)(lam - 1) l0 - F_g``).
"""

from __future__ import annotations

import datetime

import numpy as np

from ..core import Stage1
from ..core import identification as ident
from .common import (EXIT_FAILED, EXIT_OK, UsageError, add_config, add_out, emit_json,
                     finite_float, fraction, int_at_least, load_config, nonneg_float, one_line,
                     positive_float, print_lines, run_study, warn)
from .creep import register_identify_creep
from .dynamics import register_identify_damping
from .play import register_identify_play
from .output import (figure, fmt, robot_file_text, robot_name_for, save_figure, source_text,
                     table, write_text)


# -------------------------------------------------------- data files
def _read_data(path, option='--csv'):
    try:
        return ident.read_table(path)
    except OSError as exc:
        raise UsageError(f'{option} {path}: cannot read file: {exc.strerror or exc}') from None
    except ValueError as exc:
        raise UsageError(f'{option} {path}: {exc}') from None


def _column(data, path, choices, what):
    """First present column of ``choices`` = [(name, factor to SI)] -> SI array."""
    for name, factor in choices:
        if name in data:
            return data[name] * factor, name
    raise UsageError(f'--csv {path}: no {what} column; expected one of '
                     + ', '.join(n for n, _ in choices) + f' (found: {", ".join(data) or "none"})')


# ------------------------------------------------ identify stiffness
def _cmd_identify_stiffness(args):
    cfg = load_config(args)
    data = _read_data(args.csv)
    dl, dl_name = _column(data, args.csv, [('dl_mm', 1e-3), ('dl_m', 1.0)], 'length change')
    force, _ = _column(data, args.csv, [('force_n', 1.0)], 'force')
    n_a = args.n_actuators if args.n_actuators is not None else cfg.segments[0].n_actuators
    fg = args.gravity_share_n
    if fg is None:
        fg = ident.default_gravity_share(cfg, args.force_per)
    l0 = args.l0_m if args.l0_m is not None else cfg.l0
    fit = run_study(ident.fit_stiffness, dl, force, order=args.order, l0=l0,
                    force_per=args.force_per, n_actuators=n_a, gravity_share_n=fg)
    # is the derived k(lam) usable by stage 1 of this robot?
    stage1_ok, stage1_msg = _stage1_check(fit.k_coeffs, l0, cfg.d_eff, cfg)
    d = fit.to_dict()
    d.update(csv=args.csv, config=cfg.name, stage1_ok=stage1_ok, stage1_message=stage1_msg,
             yaml_out=args.yaml_out)
    status = EXIT_OK
    if args.yaml_out:
        if not stage1_ok:
            warn('--yaml-out not written: the fitted k(lam) is not usable with this robot: '
                 f'{stage1_msg}')
            status = EXIT_FAILED
        else:
            fitted = cfg.replace(l0=float(l0),
                                 stiffness_coeffs=tuple(_digits(c) for c in fit.k_coeffs))
            _write_robot_file(args.yaml_out, cfg, fitted, [
                f'Robot description written by `bellow-ancf identify stiffness` from {args.csv}:',
                'actuator.l0_m and actuator.stiffness_coeffs_n_per_m (k(lam) ascending in lam, '
                'N/m) come from',
                f'the fit F(dl) = {ident.poly_text([0.0] + list(fit.f_coeffs), "dl")} '
                f'(R^2 = {fit.r2:.6f}, RMS = {fit.rms_n:.4g} N);',
                f'the rest is robot {cfg.name} ({cfg.source}).'],
                'stiffness', args.csv, ['actuator.l0_m', 'actuator.stiffness_coeffs_n_per_m'])
    if args.plot:
        _plot_stiffness(fit, args.plot)
    if args.json:
        emit_json(d)
        return status
    who = (f'whole segment ({n_a} actuators): F_e = F_m/{n_a} - F_g' if args.force_per == 'segment'
           else 'one actuator: F_e = F_m - F_g')
    lines = [
        f'data          {args.csv}: {fit.n_points} points, dl {fit.dl_range_m[0] * 1e3:.3f} .. '
        f'{fit.dl_range_m[1] * 1e3:.3f} mm (column {dl_name})',
        f'force         {who}, F_g = {fg:.4g} N per actuator',
        f'F(dl)         {d["f_text"]}   [N, dl in m]',
    ]
    rows = [[f'a{j + 1}', f'N/m^{j + 1}', f'{a:.6g}', fmt(s, '.3g')]
            for j, (a, s) in enumerate(zip(fit.f_coeffs, fit.f_coeffs_stderr))]
    rows += [[f'k{p}', 'N/m', f'{c:.6g}', fmt(s, '.3g')]
             for p, (c, s) in enumerate(zip(fit.k_coeffs, fit.k_coeffs_stderr))]
    lines += [''] + table(['coefficient', 'unit', 'value', 'std. error'], rows,
                          ['<', '<', '>', '>']) + ['']
    lines += [
        f'k(lam)        {d["k_text"]}   [N/m], with l0 = {l0:.6g} m (dl = l0 (lam - 1))',
        f'fit quality   R^2 = {fit.r2:.6f}, RMS residual = {fit.rms_n:.4g} N, '
        f'max |residual| = {fit.max_abs_residual_n:.4g} N',
        f'stage 1       {"ok" if stage1_ok else "NOT usable"}: {stage1_msg}',
    ]
    if args.yaml_out and stage1_ok:
        lines.append(f'robot file    {args.yaml_out}: robot {robot_name_for(args.yaml_out)!r}, '
                     f'{cfg.name} with this l0 and k(lam)')
    if args.plot:
        lines.append(f'plot          {args.plot}')
    print_lines(lines)
    return status


def _stage1_check(k_coeffs, l0, d_eff, cfg):
    """``(usable, message)``: whether stage 1 of ``cfg`` with these values is monotonic."""
    try:
        Stage1(k_coeffs, l0, d_eff, cfg.p_min, cfg.p_max)
    except ValueError as exc:
        return False, one_line(exc)
    return True, 'P -> lam monotonic over the pressure limits'


def _digits(value):
    """``value`` to 6 significant digits (far below a fit's standard error) for a robot file."""
    return float(f'{value:.6g}')


def _write_robot_file(path, cfg, fitted, header, command, csv, keys):
    """Write robot ``fitted`` (``cfg`` with identified values) in the layout of ``cfg``'s file.

    The comments of ``keys`` (the values ``identify <command>`` fitted from
    ``csv``) name that fit as their source.
    """
    d = fitted.to_dict()
    d['name'] = robot_name_for(path)
    note = (f'identified by bellow-ancf identify {command} on '
            f'{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d} from {csv}')
    write_text(path, '--yaml-out',
               robot_file_text(d, header, source_text(cfg.source), note, keys))


def _plot_stiffness(fit, path):
    fig = figure(10, 4.2)
    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    dl = fit.dl
    xs = np.linspace(dl.min(), dl.max(), 200)
    ax1.plot(dl * 1e3, fit.force_elastic, 'o', ms=3, label='data (elastic force per actuator)')
    ax1.plot(xs * 1e3, fit.force(xs), '-', label=f'fit, order {fit.order} (R$^2$ = {fit.r2:.5f})')
    ax1.set_xlabel('length change $\\Delta l$ [mm]')
    ax1.set_ylabel('elastic force $F_e$ [N]')
    ax1.grid(True, alpha=0.3)
    ax1.legend(fontsize=8)
    lam = 1.0 + xs / fit.l0
    ax2.plot(lam, fit.k(lam), '-')
    ax2.set_xlabel('stretch $\\lambda$')
    ax2.set_ylabel('structural stiffness $k(\\lambda)$ [N/m]')
    ax2.set_title('k = ' + ident.poly_text(fit.k_coeffs, 'λ'), fontsize=9)
    ax2.grid(True, alpha=0.3)
    save_figure(fig, path)


# ----------------------------------------------------- identify deff
def _cmd_identify_deff(args):
    data = _read_data(args.csv)
    p, _ = _column(data, args.csv, [('pressure_kpa', 1e3), ('pressure_pa', 1.0)], 'pressure')
    source = 'force_n'
    cfg = load_config(args) if args.yaml_out or 'force_n' not in data else None
    if 'force_n' in data:
        f = data['force_n']
    else:
        length, source = _column(data, args.csv, [('length_mm', 1e-3), ('length_m', 1.0)],
                                 'actuation force (force_n) or length')
        f = ident.actuation_force_from_length(length, cfg.stiffness_coeffs, cfg.l0,
                                              args.gravity_share_n)
    fit = run_study(ident.fit_deff, p, f, confidence=args.confidence)
    d = fit.to_dict()
    d.update(csv=args.csv, force_source=source, yaml_out=args.yaml_out)
    status = EXIT_OK
    if args.yaml_out:
        stage1_ok, stage1_msg = _stage1_check(cfg.stiffness_coeffs, cfg.l0, fit.d_eff_m, cfg)
        d.update(config=cfg.name, stage1_ok=stage1_ok, stage1_message=stage1_msg)
        if not stage1_ok:
            warn('--yaml-out not written: the fitted D_eff is not usable with this robot: '
                 f'{stage1_msg}')
            status = EXIT_FAILED
        else:
            lo, hi = fit.d_eff_ci_m
            _write_robot_file(args.yaml_out, cfg, cfg.replace(d_eff=_digits(fit.d_eff_m)), [
                f'Robot description written by `bellow-ancf identify deff` from {args.csv}:',
                f'actuator.d_eff_mm comes from the fit F_a = pi/4 D_eff^2 P + c '
                f'(D_eff = {fit.d_eff_m * 1e3:.4f} mm, {100 * fit.confidence:g} % interval '
                f'[{lo * 1e3:.4f}, {hi * 1e3:.4f}] mm, R^2 = {fit.r2:.6f});',
                f'the rest is robot {cfg.name} ({cfg.source}).'],
                'deff', args.csv, ['actuator.d_eff_mm'])
    if args.plot:
        _plot_deff(fit, args.plot)
    if args.json:
        emit_json(d)
        return status
    lo, hi = fit.d_eff_ci_m
    lines = [
        f'data          {args.csv}: {fit.n_points} points, {fit.pressure_range_pa[0] / 1e3:g} .. '
        f'{fit.pressure_range_pa[1] / 1e3:g} kPa (force from {source})',
        f'slope         A_eff = {fit.area_m2 * 1e6:.5g} mm^2 '
        f'(std. error {fit.area_stderr_m2 * 1e6:.3g} mm^2), intercept {fit.intercept_n:.4g} N',
        f'D_eff         {fit.d_eff_m * 1e3:.4f} mm, '
        f'{100 * fit.confidence:g} % confidence interval [{lo * 1e3:.4f}, {hi * 1e3:.4f}] mm',
        f'fit quality   R^2 = {fit.r2:.6f}, RMS residual = {fit.rms_n:.4g} N',
    ]
    if args.yaml_out and status == EXIT_OK:
        lines.append(f'robot file    {args.yaml_out}: robot {robot_name_for(args.yaml_out)!r}, '
                     f'{cfg.name} with this D_eff')
    if args.plot:
        lines.append(f'plot          {args.plot}')
    print_lines(lines)
    return status


def _plot_deff(fit, path):
    fig = figure(6.5, 4.5)
    ax = fig.add_subplot(1, 1, 1)
    ps = np.linspace(fit.pressure.min(), fit.pressure.max(), 100)
    ax.plot(fit.pressure / 1e3, fit.force, 'o', ms=3, label='data')
    ax.plot(ps / 1e3, fit.intercept_n + fit.area_m2 * ps, '-',
            label=f'fit: D_eff = {fit.d_eff_m * 1e3:.3f} mm '
                  f'[{fit.d_eff_ci_m[0] * 1e3:.3f}, {fit.d_eff_ci_m[1] * 1e3:.3f}]')
    ax.set_xlabel('pressure P [kPa]')
    ax.set_ylabel('actuation force $F_a$ [N]')
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, path)


# ------------------------------------------------------- identify da
def _cmd_identify_da(args):
    cfg = load_config(args)
    res = run_study(ident.identify_da, cfg, args.drop_mm * 1e-3, args.tip_mass_kg, n=args.elements)
    d = res.to_dict()
    d['config'] = cfg.name
    if args.json:
        emit_json(d)
        return EXIT_OK if res.converged else EXIT_FAILED
    print_lines([
        f'rig           actuator of {cfg.name} clamped horizontally, lam = 1, '
        f'l0 = {cfg.l0 * 1e3:.4g} mm, rho0 = {cfg.rho0:g} kg/m, end mass {args.tip_mass_kg:g} kg, '
        f'{res.n_elements} elements',
        f'stiffness     k(1) = {res.k1_n_per_m:.5g} N/m, k_t = k(1) l0 = {res.kt_n:.5g} N, '
        f'k_b = D_a^2 l0 k(1)/8 = {res.kb_n_m2:.5g} N m^2',
        f'D_a           {res.D_a_m * 1e3:.4f} mm',
        f'tip drop      measured {res.drop_m * 1e3:.4f} mm, model {res.model_drop_m * 1e3:.6f} mm',
        f'root finder   brentq on '
        f'[{res.bracket_m[0] * 1e3:.4g}, {res.bracket_m[1] * 1e3:.4g}] mm, '
        f'xtol {res.xtol_m * 1e3:g} mm, rtol {res.rtol:g}, {res.iterations} iterations, '
        f'{res.function_calls} model solves, converged {"yes" if res.converged else "no"}',
    ])
    return EXIT_OK if res.converged else EXIT_FAILED


# ------------------------------------------------------------ parser
def register(subparsers):
    """Add ``identify`` and its subcommands: stiffness, deff, da, damping and creep."""
    ip = subparsers.add_parser(
        'identify', help='identify k(lam), D_eff, D_a (paper section V), the damping time or '
                         'the creep from experiments',
        description='Parameter identification of the equivalent actuator (paper section V).')
    isub = ip.add_subparsers(dest='identify_command', metavar='WHAT', required=True)
    _register_stiffness(isub)
    _register_deff(isub)
    _register_da(isub)
    register_identify_damping(isub)
    register_identify_creep(isub)
    register_identify_play(isub)


def _register_stiffness(isub):
    """Add ``identify stiffness``."""
    p = isub.add_parser(
        'stiffness', help='structural stiffness k(lam) from a tensile/compression test',
        description='Fit F_e(dl) = a1 dl + ... + aN dl^N (no constant term) to a '
                    'tensile/compression test and derive k(lam) = F/dl with dl = l0 (lam - 1) '
                    '(paper V.A). CSV columns: dl_mm (or dl_m), actuator length change, positive '
                    'in tension; force_n, the measured force [N] of the whole segment '
                    '(--force-per segment: F_e = F_m/n_a - F_g) or of one actuator (--force-per '
                    'actuator: F_e = F_m - F_g). Lines starting with # are comments.',
        epilog='Example: bellow-ancf identify stiffness --csv data/tensile_test_segment.csv '
               '--plot k.png')
    p.add_argument('--csv', required=True, metavar='FILE', help='force-displacement data (CSV)')
    p.add_argument('--order', type=int_at_least(1), default=2, metavar='N',
                   help="order of the polynomial F(dl); default: %(default)s (the paper's "
                        'quadratic)')
    p.add_argument('--force-per', choices=('segment', 'actuator'), default='segment',
                   help='whose force the force_n column holds; default: %(default)s')
    p.add_argument('--n-actuators', type=int_at_least(1), default=None, metavar='N',
                   help="actuators sharing the segment force; default: the robot file's")
    p.add_argument('--gravity-share-n', type=finite_float, default=None, metavar='F',
                   help='gravity share F_g per actuator [N] to subtract; default: segment: '
                        'top-plate weight / n_a from the robot file, actuator: 0')
    p.add_argument('--l0-m', type=positive_float, default=None, metavar='L',
                   help="unpressurised actuator length [m]; default: the robot file's l0")
    add_config(p)
    p.add_argument('--yaml-out', metavar='FILE',
                   help='write a robot file: the --config robot file with the identified l0 and '
                        'k(lam) in place (comments kept), named after FILE')
    add_out(p)
    p.set_defaults(func=_cmd_identify_stiffness)


def _register_deff(isub):
    """Add ``identify deff``."""
    p = isub.add_parser(
        'deff', help='effective actuation diameter D_eff from force vs pressure',
        description='Fit the actuation force F_a = pi/4 D_eff^2 P (paper V.B): least-squares line '
                    'with intercept, D_eff = sqrt(4 slope / pi) with a Student-t confidence '
                    'interval. CSV columns: pressure_kpa (or pressure_pa) and force_n (actuation '
                    'force [N]) or length_mm / length_m (measured actuator length; F_a = '
                    "k(lam)(lam-1) l0 - F_g with the --config robot's k and l0). Lines starting "
                    'with # are comments.',
        epilog='Example: bellow-ancf identify deff --csv data/pressure_force.csv --plot deff.png')
    p.add_argument('--csv', required=True, metavar='FILE',
                   help='pressure vs actuation force data (CSV)')
    p.add_argument('--confidence', type=fraction, default=0.95, metavar='C',
                   help='confidence level of the interval; default: %(default)s')
    p.add_argument('--gravity-share-n', type=finite_float, default=0.0, metavar='F',
                   help='gravity load F_g [N] subtracted in length mode; default: %(default)s')
    add_config(p)
    p.add_argument('--yaml-out', metavar='FILE',
                   help='write a robot file: the --config robot file with the identified D_eff '
                        'in place (comments kept), named after FILE')
    add_out(p)
    p.set_defaults(func=_cmd_identify_deff)


def _register_da(isub):
    """Add ``identify da``."""
    p = isub.add_parser(
        'da', help='cross-sectional diameter D_a from a cantilever tip drop',
        description='One actuator clamped horizontally, unactuated (lam = 1), under its own '
                    'weight (linear density from the robot file) and an end mass (paper V.C): '
                    "find D_a (k_b = D_a^2 l0 k(1)/8) such that the model's tip drop equals the "
                    'measured drop, with a bracketing root finder (brentq) on the ANCF '
                    'cantilever.',
        epilog='Example: bellow-ancf identify da --drop-mm 34.35 --tip-mass-kg 0.02397  '
               '(gives D_a = 17.90 mm for the shipped robot)')
    p.add_argument('--drop-mm', type=positive_float, required=True, metavar='D',
                   help='measured vertical tip drop [mm]')
    p.add_argument('--tip-mass-kg', type=nonneg_float, required=True, metavar='M',
                   help='end mass at the free end [kg]')
    p.add_argument('--elements', type=int_at_least(1), default=20, metavar='N',
                   help='ANCF elements of the cantilever; default: %(default)s (paper)')
    add_config(p)
    p.add_argument('--json', action='store_true',
                   help='print one JSON object (key D_a_m, SI units)')
    p.set_defaults(func=_cmd_identify_da)
