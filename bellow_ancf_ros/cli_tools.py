"""Identification, study and tracking subcommands of ``bellow-ancf`` (paper sections V, VI).

Registered by :func:`register` into the parser of :mod:`bellow_ancf_ros.cli`::

    bellow-ancf identify stiffness --csv FILE [--order N] [--force-per segment|actuator]
                                   [--gravity-share-n F] [--l0-m L] [--config C]
                                   [--plot PNG] [--yaml-out FILE] [--json]
    bellow-ancf identify deff --csv FILE [--confidence C] [--config C] [--plot PNG] [--json]
    bellow-ancf identify da --drop-mm D --tip-mass-kg M [--config C] [--elements N] [--json]
    bellow-ancf convergence [--config C] [--max-elements N] [--reference N] [--tol-mm T]
                            [--payload-kg M] [--repeats R] [--plot PNG] [--json]
    bellow-ancf workspace [--config C] [--payload-kg M ...] [--points N] [--elements N]
                          [--plot PNG] [--csv FILE] [--json]
    bellow-ancf compare-pcc [--config C] [--payload-kg M ...] [--points N] [--no-gravity]
                            [--plot PNG] [--csv FILE] [--json]
    bellow-ancf track --trajectory NAME [--config C] [--payload-kg M] [--points N]
                      [--radius-mm R] [--height-mm H] [--bending-angle-deg B] [--period-s T]
                      [--controller ancf|pcc] [--csv FILE] [--plot PNG] [--json]

Conventions (those of :mod:`bellow_ancf_ros.cli`): a readable table on
stdout, or with ``--json`` one JSON object on one line (SI units, non-finite
numbers as ``null``); progress of long runs on stderr (``--quiet`` silences
it); plots are PNG files (matplotlib, Agg canvas); bad input is reported as
one line ``bellow-ancf: error: ...`` on stderr with exit status 2; exit
status 1 when a solve failed (``track``: a target was not reached).

Data files read by ``identify`` are CSV with ``#`` comment lines, one header
row of column names and numeric rows:

* ``identify stiffness``: ``dl_mm`` (or ``dl_m``): actuator length change,
  positive in tension; ``force_n``: measured force [N], of the whole segment
  (``--force-per segment``, the default: ``F_e = F_m/n_a - F_g``) or of one
  actuator (``--force-per actuator``: ``F_e = F_m - F_g``).
* ``identify deff``: ``pressure_kpa`` (or ``pressure_pa``) and either
  ``force_n`` (actuation force) or ``length_mm`` (or ``length_m``, the
  measured actuator length, converted with the robot's ``k(lam)`` and ``l0``:
  ``F_a = k(lam)(lam - 1) l0 - F_g``).

``track`` writes the pressure sequence as CSV: ``time_s`` and one column per
actuator, ``s<segment>_a<actuator>_kpa``, gauge pressure in kPa (1 kPa =
1000 Pa; the core and the JSON use Pa).  ``workspace --csv`` writes one row
per solve: ``payload_kg, scheme, scheme_name, step``, the pressures in kPa
(same column names), ``x_mm, y_mm, z_mm``, the z-axis ``zx, zy, zz``,
``converged, stable``.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time

import numpy as np
import yaml

from . import cli
from .cli import EXIT_FAILED, EXIT_OK, SolverError, UsageError, json_safe
from .core import ConfigError, RobotModel, Stage1, load_robot, studies
from .core import identification as ident
from .core.solver import limit_blas_threads

__all__ = ['register']

PROG = cli.PROG


def _bind(parser):
    """Raise the error classes of the ``cli`` module actually running (also as ``__main__``).

    ``python -m bellow_ancf_ros.cli`` runs that module as ``__main__``, a second
    copy with its own ``UsageError``; the parser classes tell which one calls us.
    """
    global UsageError, SolverError
    mod = sys.modules.get(type(parser).__module__)
    if mod is not None and hasattr(mod, 'UsageError') and hasattr(mod, 'SolverError'):
        UsageError, SolverError = mod.UsageError, mod.SolverError


# =============================================================== helpers
def _positive_float(text):
    value = cli._finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f'must be positive, got {text!r}')
    return value


def _nonneg_float(text):
    value = cli._finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f'must not be negative, got {text!r}')
    return value


def _int_at_least(minimum):
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f'must be >= {minimum}, got {value}')
        return value
    return parse


def _fraction(text):
    value = cli._finite_float(text)
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f'must lie strictly between 0 and 1, got {text!r}')
    return value


def _config(args):
    try:
        return load_robot(args.config)
    except ConfigError as exc:
        raise UsageError(f'--config: {exc}') from None


def _model(cfg, elements=None):
    try:
        return RobotModel(cfg, elements)
    except ValueError as exc:
        raise UsageError(f'--elements: {exc}') from None


def _progress(args, command):
    """A progress callback printing to stderr (nothing with --quiet)."""
    if getattr(args, 'quiet', False):
        return None
    start = time.perf_counter()

    def report(done, total, text):
        print(f'{PROG}: {command}: [{done}/{total}] {text} ({time.perf_counter() - start:.1f} s)',
              file=sys.stderr, flush=True)
    return report


def _emit_json(obj):
    print(json.dumps(json_safe(obj), allow_nan=False), flush=True)


def _print(lines):
    print('\n'.join(lines), flush=True)


def _table(headers, rows, aligns=None):
    """Plain aligned text table (list of lines)."""
    cells = [[str(h) for h in headers]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    aligns = aligns or ['>'] * len(headers)
    out = []
    for k, r in enumerate(cells):
        out.append('  '.join(f'{c:{a}{w}}' for c, a, w in zip(r, aligns, widths)).rstrip())
        if k == 0:
            out.append('  '.join('-' * w for w in widths))
    return out


def _fmt(value, spec='.4g', none='n/a'):
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return none
    return format(value, spec)


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


def _solve(func, *args, **kwargs):
    """Run a study; ValueError means bad input, RuntimeError a solver failure."""
    try:
        return func(*args, **kwargs)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    except RuntimeError as exc:
        raise SolverError(f'solver failed: {exc}') from exc


# ----------------------------------------------------------------- plots
def _figure(width=10.0, height=4.5):
    from matplotlib.figure import Figure
    return Figure(figsize=(width, height), dpi=100)


def _save(fig, path):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    FigureCanvasAgg(fig)
    fig.tight_layout()
    try:
        fig.savefig(path, format='png')
    except OSError as exc:
        raise UsageError(f'--plot {path}: cannot write file: {exc.strerror or exc}') from None


def _actuator_columns(cfg):
    names = []
    for j, seg in enumerate(cfg.segments):
        names += [f's{j + 1}_a{i + 1}_kpa' for i in range(seg.n_actuators)]
    return names


def _open_out(path, option):
    try:
        return open(path, 'w', newline='', encoding='utf-8')
    except OSError as exc:
        raise UsageError(f'{option} {path}: cannot write file: {exc.strerror or exc}') from None


# ==================================================== identify stiffness
def _cmd_identify_stiffness(args):
    cfg = _config(args)
    data = _read_data(args.csv)
    dl, dl_name = _column(data, args.csv, [('dl_mm', 1e-3), ('dl_m', 1.0)], 'length change')
    force, _ = _column(data, args.csv, [('force_n', 1.0)], 'force')
    n_a = args.n_actuators if args.n_actuators is not None else cfg.segments[0].n_actuators
    fg = args.gravity_share_n
    if fg is None:
        fg = ident.default_gravity_share(cfg, args.force_per)
    l0 = args.l0_m if args.l0_m is not None else cfg.l0
    fit = _solve(ident.fit_stiffness, dl, force, order=args.order, l0=l0, force_per=args.force_per,
                 n_actuators=n_a, gravity_share_n=fg)
    # is the derived k(lam) usable by stage 1 of this robot?
    try:
        Stage1(fit.k_coeffs, l0, cfg.d_eff, cfg.p_min, cfg.p_max)
        stage1_ok, stage1_msg = True, 'P -> lam monotonic over the pressure limits'
    except ValueError as exc:
        stage1_ok, stage1_msg = False, cli._one_line(exc)
    d = fit.to_dict()
    d.update(csv=args.csv, config=cfg.name, stage1_ok=stage1_ok, stage1_message=stage1_msg,
             yaml_out=args.yaml_out)
    status = EXIT_OK
    if args.yaml_out:
        if not stage1_ok:
            cli._warn('--yaml-out not written: the fitted k(lam) is not usable with this robot: '
                      f'{stage1_msg}')
            status = EXIT_FAILED
        else:
            fitted = cfg.replace(l0=float(l0), stiffness_coeffs=tuple(fit.k_coeffs))
            _write_robot_yaml(args.yaml_out, fitted, fit, args.csv)
    if args.plot:
        _plot_stiffness(fit, args.plot)
    if args.json:
        _emit_json(d)
        return status
    who = (f'whole segment ({n_a} actuators): F_e = F_m/{n_a} - F_g' if args.force_per == 'segment'
           else 'one actuator: F_e = F_m - F_g')
    lines = [
        f'data          {args.csv}: {fit.n_points} points, dl {fit.dl_range_m[0] * 1e3:.3f} .. '
        f'{fit.dl_range_m[1] * 1e3:.3f} mm (column {dl_name})',
        f'force         {who}, F_g = {fg:.4g} N per actuator',
        f'F(dl)         {d["f_text"]}   [N, dl in m]',
    ]
    rows = [[f'a{j + 1}', f'N/m^{j + 1}', f'{a:.6g}', _fmt(s, '.3g')]
            for j, (a, s) in enumerate(zip(fit.f_coeffs, fit.f_coeffs_stderr))]
    rows += [[f'k{p}', 'N/m', f'{c:.6g}', _fmt(s, '.3g')]
             for p, (c, s) in enumerate(zip(fit.k_coeffs, fit.k_coeffs_stderr))]
    lines += [''] + _table(['coefficient', 'unit', 'value', 'std. error'], rows,
                           ['<', '<', '>', '>']) + ['']
    lines += [
        f'k(lam)        {d["k_text"]}   [N/m], with l0 = {l0:.6g} m (dl = l0 (lam - 1))',
        f'fit quality   R^2 = {fit.r2:.6f}, RMS residual = {fit.rms_n:.4g} N, '
        f'max |residual| = {fit.max_abs_residual_n:.4g} N',
        f'stage 1       {"ok" if stage1_ok else "NOT usable"}: {stage1_msg}',
    ]
    if args.yaml_out and stage1_ok:
        lines.append(f'robot file    {args.yaml_out} (robot {cfg.name} with this l0 and k(lam))')
    if args.plot:
        lines.append(f'plot          {args.plot}')
    _print(lines)
    return status


def _write_robot_yaml(path, cfg, fit, source):
    text = yaml.safe_dump(cfg.to_dict(), sort_keys=False, default_flow_style=None)
    header = (f'# Robot description written by `bellow-ancf identify stiffness` from {source}.\n'
              '# actuator.l0_m and actuator.stiffness_coeffs_n_per_m '
              '(k(lam) ascending in lam, N/m)\n'
              f'# come from the fit F(dl) = {ident.poly_text([0.0] + list(fit.f_coeffs), "dl")}\n'
              f'# (R^2 = {fit.r2:.6f}, RMS = {fit.rms_n:.4g} N); the rest is robot {cfg.name}.\n')
    with _open_out(path, '--yaml-out') as fh:
        fh.write(header + text)


def _plot_stiffness(fit, path):
    fig = _figure(10, 4.2)
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
    _save(fig, path)


# ========================================================= identify deff
def _cmd_identify_deff(args):
    data = _read_data(args.csv)
    p, _ = _column(data, args.csv, [('pressure_kpa', 1e3), ('pressure_pa', 1.0)], 'pressure')
    source = 'force_n'
    if 'force_n' in data:
        f = data['force_n']
    else:
        length, source = _column(data, args.csv, [('length_mm', 1e-3), ('length_m', 1.0)],
                                 'actuation force (force_n) or length')
        cfg = _config(args)
        f = ident.actuation_force_from_length(length, cfg.stiffness_coeffs, cfg.l0,
                                              args.gravity_share_n)
    fit = _solve(ident.fit_deff, p, f, confidence=args.confidence)
    d = fit.to_dict()
    d.update(csv=args.csv, force_source=source)
    if args.plot:
        _plot_deff(fit, args.plot)
    if args.json:
        _emit_json(d)
        return EXIT_OK
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
    if args.plot:
        lines.append(f'plot          {args.plot}')
    _print(lines)
    return EXIT_OK


def _plot_deff(fit, path):
    fig = _figure(6.5, 4.5)
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
    _save(fig, path)


# =========================================================== identify da
def _cmd_identify_da(args):
    cfg = _config(args)
    res = _solve(ident.identify_da, cfg, args.drop_mm * 1e-3, args.tip_mass_kg, n=args.elements)
    d = res.to_dict()
    d['config'] = cfg.name
    if args.json:
        _emit_json(d)
        return EXIT_OK if res.converged else EXIT_FAILED
    _print([
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


# ============================================================ convergence
def _cmd_convergence(args):
    limit_blas_threads()
    cfg = _config(args)
    res = _solve(studies.convergence_study, cfg, counts=range(1, args.max_elements + 1),
                 reference_n=args.reference, threshold_m=args.tol_mm * 1e-3,
                 payload_kg=args.payload_kg, repeats=args.repeats,
                 progress=_progress(args, 'convergence'))
    if args.plot:
        _plot_convergence(res, args.plot)
    if args.json:
        _emit_json(res.to_dict())
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
    lines += _table(['n', 'nodes on plates', 'error [mm]', 'time [ms]', ''], rows)
    if res.recommended is not None:
        lines += ['', f'recommended   n = {res.recommended}: {res.reason}']
    else:
        lines += ['', f'recommended   none: {res.reason}']
    if args.plot:
        lines.append(f'plot          {args.plot}')
    _print(lines)
    return EXIT_OK


def _plot_convergence(res, path):
    fig = _figure(7.5, 4.5)
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
    ax2.plot(ns, [r.time_s * 1e3 for r in res.rows], 's-', color='tab:red', ms=4)
    ax2.set_ylabel('solve time [ms]', color='tab:red')
    ax.legend(fontsize=8, loc='upper right')
    ax.set_title(f'element convergence ({res.config_name})')
    _save(fig, path)


# ============================================================== workspace
def _cmd_workspace(args):
    limit_blas_threads()
    cfg = _config(args)
    payloads = args.payload_kg or [0.0]
    res = _solve(studies.workspace_study, cfg, payloads, n_points=args.points,
                 n_elements=args.elements, progress=_progress(args, 'workspace'))
    rows = res['rows']
    if args.csv:
        cols = _actuator_columns(cfg)
        with _open_out(args.csv, '--csv') as fh:
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
        _emit_json({'config': cfg.name, 'schemes': res['schemes'], 'n_points': res['n_points'],
                    'n_elements': res['n_elements'], 'summary': summary, 'csv': args.csv,
                    'plot': args.plot})
        return EXIT_FAILED if failed else EXIT_OK
    lines = [f'robot         {cfg.name}: {len(res["schemes"])} actuation schemes x '
             f'{res["n_points"]} points, n = {res["n_elements"]} elements', '']
    lines += _table(['payload [kg]', 'solved', 'x [mm]', 'y [mm]', 'z [mm]', 'max radius [mm]'],
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
    _print(lines)
    return EXIT_FAILED if failed else EXIT_OK


def _payload_colors(n):
    from matplotlib import colormaps
    cmap = colormaps['viridis']
    return [cmap(0.15 + 0.7 * k / max(1, n - 1)) for k in range(n)]


def _plot_workspace(res, path):
    fig = _figure(11, 5)
    ax3 = fig.add_subplot(1, 2, 1, projection='3d')
    ax2 = fig.add_subplot(1, 2, 2)
    colors = _payload_colors(len(res['payloads_kg']))
    for m, col in zip(res['payloads_kg'], colors):
        for k in range(len(res['schemes'])):
            pts = np.array([r['position_m'] for r in res['rows']
                            if r['payload_kg'] == m and r['scheme'] == k
                            and r['converged'] and r['stable'] is not False]) * 1e3
            if pts.size == 0:
                continue
            label = f'{m * 1e3:g} g' if k == 0 else None
            ax3.plot(pts[:, 0], pts[:, 1], pts[:, 2], '-', color=col, lw=1, label=label)
            ax2.plot(pts[:, 0], pts[:, 1], '-', color=col, lw=1, label=label)
    ax3.set_xlabel('x [mm]')
    ax3.set_ylabel('y [mm]')
    ax3.set_zlabel('z [mm]')
    ax3.set_title(f'workspace boundaries ({res["config"]})')
    ax3.legend(fontsize=8, title='payload')
    ax2.set_xlabel('x [mm]')
    ax2.set_ylabel('y [mm]')
    ax2.set_aspect('equal', adjustable='datalim')
    ax2.set_title('top view')
    ax2.grid(True, alpha=0.3)
    _save(fig, path)


# ============================================================ compare-pcc
def _cmd_compare_pcc(args):
    limit_blas_threads()
    cfg = _config(args)
    payloads = args.payload_kg or [0.0, 0.05, 0.1]
    res = _solve(studies.compare_pcc, cfg, payloads, n_points=args.points,
                 n_elements=args.elements, gravity=not args.no_gravity,
                 progress=_progress(args, 'compare-pcc'))
    if args.csv:
        cols = _actuator_columns(cfg)
        with _open_out(args.csv, '--csv') as fh:
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
        _emit_json({k: v for k, v in res.items() if k != 'rows'}
                   | {'csv': args.csv, 'plot': args.plot})
        return EXIT_OK
    gravity = 'on' if res['gravity'] else 'off'
    lines = [f'robot         {cfg.name}: ANCF (gravity {gravity}, payload at the tip, '
             f'n = {res["n_elements"]}) vs PCC (kinematic: no gravity, no payload)',
             'difference    |p_ANCF - p_PCC| of the end effector; dz = z_ANCF - z_PCC; '
             'angle between the z-axes', '']
    table = [[f'{s["payload_kg"]:g}', s['category'], s['points'], f'{s["rms_m"] * 1e3:.3f}',
              f'{s["max_m"] * 1e3:.3f}', f'{s["mean_dz_m"] * 1e3:+.3f}',
              f'{math.degrees(s["max_angle_rad"]):.2f}'] for s in res['summary']]
    lines += _table(['payload [kg]', 'actuations', 'points', 'RMS [mm]', 'max [mm]',
                     'mean dz [mm]', 'max angle [deg]'], table,
                    ['>', '<', '>', '>', '>', '>', '>'])
    if args.csv:
        lines.append(f'csv           {args.csv}')
    if args.plot:
        lines.append(f'plot          {args.plot}')
    _print(lines)
    return EXIT_OK


def _plot_pcc(res, path):
    fig = _figure(11, 4.8)
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
    ax1.legend(fontsize=8)
    ax2.set_xlabel('actuation index (elongation sweep, then the workspace schemes)')
    ax2.set_ylabel('|ANCF - PCC| [mm]')
    ax2.set_title(f'PCC vs ANCF ({res["config"]})')
    ax2.grid(True, alpha=0.3)
    ax2.legend(fontsize=8, title='payload')
    _save(fig, path)


# ================================================================== track
def _cmd_track(args):
    limit_blas_threads()
    from .core import trajectories

    cfg = _config(args)
    model = _model(cfg, args.elements)
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
    res = _solve(studies.tracking_study, model, args.trajectory, n_points=args.points,
                 payload_kg=args.payload_kg, params=params, controller=args.controller,
                 progress=_progress(args, 'track'))
    st = res.stats()
    if args.csv:
        with _open_out(args.csv, '--csv') as fh:
            w = csv.writer(fh)
            w.writerow(['time_s'] + _actuator_columns(cfg))
            for t, p in zip(res.times_s, res.pressures_pa):
                w.writerow([f'{t:.6g}'] + [f'{v / 1e3:.6f}' for v in p])
    if args.plot:
        _plot_track(res, args.plot)
    ok = st['reachable_fraction'] == 1.0 and st['success_fraction'] == 1.0
    if args.json:
        d = res.to_dict()
        d.update(n_elements=model.n, csv=args.csv, plot=args.plot)
        _emit_json(d)
        return EXIT_OK if ok else EXIT_FAILED
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
             _fmt(st['position_rms_m'] and st['position_rms_m'] * 1e3, '.3e'),
             _fmt(st['position_max_m'] and st['position_max_m'] * 1e3, '.3e')]]
    if st['angle_rms_rad'] is not None:
        rows.append(['angle error [deg]', f'{math.degrees(st["angle_rms_rad"]):.3e}',
                     f'{math.degrees(st["angle_max_rad"]):.3e}'])
    lines += _table(['', 'RMS', 'max'], rows, ['<', '>', '>'])
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
    _print(lines)
    return EXIT_OK if ok else EXIT_FAILED


def _plot_track(res, path):
    fig = _figure(13, 4.5)
    ax1 = fig.add_subplot(1, 3, 1, projection='3d')
    ax2 = fig.add_subplot(1, 3, 2)
    ax3 = fig.add_subplot(1, 3, 3)
    T, Pp = res.targets_m * 1e3, res.predicted_m * 1e3
    ax1.plot(T[:, 0], T[:, 1], T[:, 2], '-', color='k', lw=1.5, label='desired')
    ax1.plot(Pp[:, 0], Pp[:, 1], Pp[:, 2], 'o', color='tab:orange', ms=2.5,
             label='predicted (forward)')
    ax1.set_xlabel('x [mm]')
    ax1.set_ylabel('y [mm]')
    ax1.set_zlabel('z [mm]')
    ax1.legend(fontsize=8)
    ax1.set_title(f'{res.trajectory} ({res.config_name}, {res.payload_kg * 1e3:g} g)')
    ax2.plot(T[:, 0], T[:, 1], '-', color='k', lw=1.5, label='desired')
    ax2.plot(Pp[:, 0], Pp[:, 1], 'o', color='tab:orange', ms=2.5, label='predicted')
    ax2.set_aspect('equal', adjustable='datalim')
    ax2.set_xlabel('x [mm]')
    ax2.set_ylabel('y [mm]')
    ax2.set_title('top view')
    ax2.grid(True, alpha=0.3)
    cols = _actuator_columns_cfgless(res.pressures_pa.shape[1])
    for k in range(res.pressures_pa.shape[1]):
        ax3.plot(res.times_s, res.pressures_pa[:, k] / 1e3, '-', lw=1, label=cols[k])
    ax3.set_xlabel('time [s]')
    ax3.set_ylabel('pressure [kPa]')
    ax3.set_title('feedforward pressures')
    ax3.grid(True, alpha=0.3)
    ax3.legend(fontsize=7, ncol=2)
    _save(fig, path)


def _actuator_columns_cfgless(A):
    if A % 3 == 0 and A > 3:
        return [f's{k // 3 + 1},{k % 3 + 1}' for k in range(A)]
    return [f'a{k + 1}' for k in range(A)]


# =============================================================== register
def _add_config(p):
    p.add_argument('--config', default='one_segment', metavar='C',
                   help='robot file path or shipped robot name (one_segment, two_segment); '
                        'default: %(default)s')


def _add_out(p, json_help='print one JSON object (SI units) instead of the table'):
    p.add_argument('--plot', metavar='PNG', help='write a PNG plot to this file')
    p.add_argument('--json', action='store_true', help=json_help)


def _add_quiet(p):
    p.add_argument('--quiet', action='store_true', help='no progress output on stderr')


def register(subparsers):
    """Add ``identify``, ``convergence``, ``workspace``, ``compare-pcc`` and ``track``."""
    # ------------------------------------------------------------ identify
    ip = subparsers.add_parser(
        'identify', help='identify k(lam), D_eff or D_a from experiments (paper section V)',
        description='Parameter identification of the equivalent actuator (paper section V).')
    _bind(ip)
    isub = ip.add_subparsers(dest='identify_command', metavar='WHAT', required=True)

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
    p.add_argument('--order', type=_int_at_least(1), default=2, metavar='N',
                   help="order of the polynomial F(dl); default: %(default)s (the paper's "
                        'quadratic)')
    p.add_argument('--force-per', choices=('segment', 'actuator'), default='segment',
                   help='whose force the force_n column holds; default: %(default)s')
    p.add_argument('--n-actuators', type=_int_at_least(1), default=None, metavar='N',
                   help="actuators sharing the segment force; default: the robot file's")
    p.add_argument('--gravity-share-n', type=cli._finite_float, default=None, metavar='F',
                   help='gravity share F_g per actuator [N] to subtract; default: segment: '
                        'top-plate weight / n_a from the robot file, actuator: 0')
    p.add_argument('--l0-m', type=_positive_float, default=None, metavar='L',
                   help="unpressurised actuator length [m]; default: the robot file's l0")
    _add_config(p)
    p.add_argument('--yaml-out', metavar='FILE',
                   help='write a robot file (--config robot with the identified l0 and k(lam))')
    _add_out(p)
    p.set_defaults(func=_cmd_identify_stiffness)

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
    p.add_argument('--confidence', type=_fraction, default=0.95, metavar='C',
                   help='confidence level of the interval; default: %(default)s')
    p.add_argument('--gravity-share-n', type=cli._finite_float, default=0.0, metavar='F',
                   help='gravity load F_g [N] subtracted in length mode; default: %(default)s')
    _add_config(p)
    _add_out(p)
    p.set_defaults(func=_cmd_identify_deff)

    p = isub.add_parser(
        'da', help='cross-sectional diameter D_a from a cantilever tip drop',
        description='One actuator clamped horizontally, unactuated (lam = 1), under its own '
                    'weight (linear density from the robot file) and an end mass (paper V.C): '
                    "find D_a (k_b = D_a^2 l0 k(1)/8) such that the model's tip drop equals the "
                    'measured drop, with a bracketing root finder (brentq) on the ANCF '
                    'cantilever.',
        epilog='Example: bellow-ancf identify da --drop-mm 34.35 --tip-mass-kg 0.02397  '
               '(gives D_a = 17.90 mm for the shipped robot)')
    p.add_argument('--drop-mm', type=_positive_float, required=True, metavar='D',
                   help='measured vertical tip drop [mm]')
    p.add_argument('--tip-mass-kg', type=_nonneg_float, required=True, metavar='M',
                   help='end mass at the free end [kg]')
    p.add_argument('--elements', type=_int_at_least(1), default=20, metavar='N',
                   help='ANCF elements of the cantilever; default: %(default)s (paper)')
    _add_config(p)
    p.add_argument('--json', action='store_true',
                   help='print one JSON object (key D_a_m, SI units)')
    p.set_defaults(func=_cmd_identify_da)

    # --------------------------------------------------------- convergence
    p = subparsers.add_parser(
        'convergence', help='tip error and solve time vs element count (paper Fig. 4(d))',
        description='End-effector error of n = 1..N elements per actuator against a converged '
                    'reference at extreme actuations (largest error over: actuator 1 at p_max and '
                    'the others at 0 as in the paper; actuator 1 at p_max, others at p_min; '
                    'actuators 1, 2 at p_max, others at p_min), the median solve time, and the '
                    'recommended count: the smallest with an error below --tol-mm that puts a '
                    'node on every plate.')
    _add_config(p)
    p.add_argument('--max-elements', type=_int_at_least(1), default=12, metavar='N',
                   help='test n = 1..N; default: %(default)s')
    p.add_argument('--reference', type=_int_at_least(1), default=48, metavar='N',
                   help='element count of the reference solution; default: %(default)s')
    p.add_argument('--tol-mm', type=_positive_float, default=0.01, metavar='T',
                   help='error threshold of the recommendation [mm]; default: %(default)s')
    p.add_argument('--payload-kg', type=cli._payload, default=0.0, metavar='M',
                   help='payload [kg]; default: %(default)s')
    p.add_argument('--repeats', type=_int_at_least(1), default=3, metavar='R',
                   help='timed solves per count and actuation (median); default: %(default)s')
    _add_out(p)
    _add_quiet(p)
    p.set_defaults(func=_cmd_convergence)

    # ----------------------------------------------------------- workspace
    p = subparsers.add_parser(
        'workspace', help='workspace boundaries of the paper\'s actuation schemes (paper VI.B)',
        description="Sweep the paper's actuation schemes from p_min to p_max with warm-started "
                    'forward solves, for each payload. One segment: 18 schemes (one actuator '
                    'swept, the other two at every p_min/p_max combination; two swept, the third '
                    'at p_min or p_max). Two segments: s11+s21, s11+s22, s11+s21+s22, s11+s22+s23 '
                    'swept, the others at 0 kPa. Plot: boundary curves in 3-D and top view; CSV: '
                    'one row per solve.')
    _add_config(p)
    p.add_argument('--payload-kg', type=cli._payload, nargs='+', default=[0.0], metavar='M',
                   help='payloads [kg]; default: 0')
    p.add_argument('--points', type=_int_at_least(2), default=21, metavar='N',
                   help='points per scheme; default: %(default)s')
    p.add_argument('--elements', type=_int_at_least(1), default=None, metavar='N',
                   help="ANCF elements per actuator; default: the robot file's")
    p.add_argument('--csv', metavar='FILE', help='write every solve as a CSV row')
    _add_out(p, 'print one JSON summary object instead of the table')
    _add_quiet(p)
    p.set_defaults(func=_cmd_workspace)

    # --------------------------------------------------------- compare-pcc
    p = subparsers.add_parser(
        'compare-pcc', help='where the PCC model and the ANCF model disagree',
        description='End-effector positions of the ANCF model (gravity, payload) and the '
                    'kinematic piecewise-constant-curvature model (same stage 1, no forces) along '
                    'a pure elongation sweep and the workspace schemes, per payload.')
    _add_config(p)
    p.add_argument('--payload-kg', type=cli._payload, nargs='+', default=None, metavar='M',
                   help='payloads [kg]; default: 0 0.05 0.1')
    p.add_argument('--points', type=_int_at_least(2), default=11, metavar='N',
                   help='points per scheme; default: %(default)s')
    p.add_argument('--elements', type=_int_at_least(1), default=None, metavar='N',
                   help="ANCF elements per actuator; default: the robot file's")
    p.add_argument('--no-gravity', action='store_true',
                   help="switch the ANCF model's gravity off (the payload then has no weight "
                        'either)')
    p.add_argument('--csv', metavar='FILE', help='write every compared actuation as a CSV row')
    _add_out(p, 'print one JSON summary object instead of the table')
    _add_quiet(p)
    p.set_defaults(func=_cmd_compare_pcc)

    # ---------------------------------------------------------------- track
    from .core import trajectories
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
    _add_config(p)
    p.add_argument('--payload-kg', type=cli._payload, default=0.0, metavar='M',
                   help='payload [kg]; default: %(default)s')
    p.add_argument('--points', type=_int_at_least(1), default=100, metavar='N',
                   help='points over one period; default: %(default)s')
    p.add_argument('--elements', type=_int_at_least(1), default=None, metavar='N',
                   help="ANCF elements per actuator; default: the robot file's")
    p.add_argument('--radius-mm', type=_positive_float, default=None, metavar='R',
                   help='trajectory radius [mm]; default: from the robot')
    p.add_argument('--height-mm', type=cli._finite_float, default=None, metavar='H',
                   help='height of the trajectory centre [mm]; default: from the robot')
    p.add_argument('--bending-angle-deg', type=cli._finite_float, default=None, metavar='B',
                   help='bending angle (two or more segments, circles) [deg]')
    p.add_argument('--period-s', type=_positive_float, default=None, metavar='T',
                   help='period of the trajectory [s] (time column only); default: from the robot')
    p.add_argument('--controller', choices=('ancf', 'pcc'), default='ancf',
                   help="model whose inverse gives the feedforward pressures (pcc: the paper's "
                        'baseline; the errors are always from the ANCF forward model); default: '
                        '%(default)s')
    p.add_argument('--csv', metavar='FILE',
                   help='write the pressure sequence (kPa) to this CSV file')
    _add_out(p, 'print one JSON object with the statistics (SI units)')
    _add_quiet(p)
    p.set_defaults(func=_cmd_track)
