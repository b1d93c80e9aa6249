"""``bellow-ancf modes``, ``simulate`` and ``identify damping``: the robot in motion.

::

    bellow-ancf modes [--config C] --pressures-kpa P1 P2 ... [--payload-kg M]
                      [--tip-force-n FX FY FZ] [--modes N] [--damping-time-s B]
                      [--json] [--plot PNG]
    bellow-ancf simulate [--config C] --pressures-kpa P1 P2 ... [--payload-kg M]
                         --duration-s T [--step-s H] [--sample-s S] [--damping-time-s B]
                         (--release-tip-force-n FX FY FZ | --step-pressures-kpa Q1 Q2 ...
                          | --pressures-csv FILE) [--json] [--csv OUT] [--plot PNG]
    bellow-ancf identify damping [--config C] (--csv FILE | --bag DIR) [--pressures-kpa P ...]
                                 [--payload-kg M] [--t-start-s T0] [--t-end-s T1]
                                 [--json] [--plot PNG]

``modes``: the equilibrium (``solve_forward``), then its natural modes
(:func:`bellow_ancf_ros.core.natural_modes`); JSON ``{"modes": [{"frequency_hz",
"damped_frequency_hz", "damping_ratio", "direction"}, ...]}`` lowest first,
beside the equilibrium's loads and damping.  ``simulate``: the
generalized-alpha integration (:class:`bellow_ancf_ros.core.GeneralizedAlpha`)
of a release, a pressure step or pressures over time, sampled by
:func:`bellow_ancf_ros.core.dynamics.sample_motion`; JSON ``{"samples": [{"t_s",
"position_m", "z_axis"}, ...]}`` beside the run's status.  ``identify
damping``: the first mode's frequency and damping ratio fitted to a recorded
ring-down (:func:`bellow_ancf_ros.core.fit.fit_free_vibration`, window from
:func:`bellow_ancf_ros.core.fit.ringdown_window`) and the
``dynamics.damping_time_s`` that reproduces them
(:func:`bellow_ancf_ros.core.fit.identify_damping`), and the model's first
mode against the measured one (``dynamics.first_mode_error``).
"""

from __future__ import annotations

import csv
import math

import numpy as np

from ..core import GeneralizedAlpha, limit_blas_threads, solve_forward
from ..core import dynamics as dyn
from ..core import fit as fitting
from ..core.control import KNOWN_MODE_ERROR
from .common import (EXIT_FAILED, EXIT_OK, UsageError, add_config, add_loads, call_solver,
                     element_count, emit_json, error, finite_float, int_at_least, load_model,
                     nonneg_float, one_line, payload_mass, positive_float, print_lines)
from .output import figure, open_out, save_figure, table
from .solve import check_pressures_kpa

__all__ = ['register', 'register_identify_damping']

#: Mode shapes drawn by ``modes --plot``.
PLOT_MODES = 4
#: ``simulate``: interval [s] of the energy and constraint checks (and the first and last sample).
CHECK_S = 0.01


# ----------------------------------------------------------- helpers
def _equilibrium(model, p, payload_kg, tip_force_n, what='the equilibrium'):
    """A converged, stable equilibrium, or a one-line failure (exit 1)."""
    fw = call_solver(solve_forward, model, p, payload_kg=payload_kg, tip_force_n=tip_force_n)
    if not fw.converged:
        return fw, f'{what} did not converge (status {int(fw.status)}: {fw.message})'
    if fw.stable is False:
        return fw, f'{what} is not stable (status {int(fw.status)}: {fw.message}): no motion ' \
                   'about it'
    return fw, None


def _direction_text(d) -> str:
    names = 'xyz'
    k = int(np.argmax(np.abs(d)))
    if not np.any(d):
        return 'none (the tip does not move)'
    if abs(d[k]) > 0.999:
        return f'{"+" if d[k] > 0 else "-"}{names[k]}'
    return '(' + ', '.join(f'{v:.3f}' for v in d) + ')'


def _vec_mm(x) -> str:
    return ' '.join(f'{v * 1e3:9.3f}' for v in x)


# ------------------------------------------------------------- modes
def _cmd_modes(args) -> int:
    limit_blas_threads()
    model = load_model(args)
    p = check_pressures_kpa(model, args.pressures_kpa)
    fw, problem = _equilibrium(model, p, args.payload_kg, args.tip_force_n)
    if problem:
        error(problem)
        return EXIT_FAILED
    try:
        ma = dyn.natural_modes(fw, args.modes, damping_time_s=args.damping_time_s)
    except dyn.ModalError as exc:
        error(f'no modes: {exc}')
        return EXIT_FAILED
    if args.plot:
        _plot_modes(model, fw, ma, args.plot)
    if args.json:
        emit_json(ma.to_dict() | {'config': model.cfg.name, 'pressures_pa': p.tolist(),
                                  'position_m': fw.position.tolist(), 'plot': args.plot})
        return EXIT_OK
    rows = [[k + 1, f'{m.frequency_hz:.4f}',
             f'{m.damped_frequency_hz:.4f}' if m.damped_frequency_hz > 0 else 'overdamped',
             f'{m.damping_ratio:.4f}', _direction_text(m.direction)]
            for k, m in enumerate(ma.modes)]
    lines = [f'robot          {model.cfg.name}: {model.cfg.n_segments} segment(s), payload '
             f'{args.payload_kg:g} kg, tip force '
             + ('none' if args.tip_force_n is None
                else ' '.join(f'{v:g}' for v in args.tip_force_n) + ' N'),
             f'pressures      {" ".join(f"{v / 1e3:g}" for v in p)} kPa',
             f'tip position   {_vec_mm(fw.position)}  mm (x y z)',
             f'damping        damping_time_s {ma.damping_time_s:g} s, mass_damping_per_s '
             f'{ma.mass_damping_per_s:g} 1/s', '']
    lines += table(['mode', 'frequency [Hz]', 'damped [Hz]', 'damping ratio', 'tip direction'],
                   rows, ['>', '>', '>', '>', '<'])
    if args.plot:
        lines.append(f'plot           {args.plot}')
    print_lines(lines)
    return EXIT_OK


def _plot_modes(model, fw, ma, path):
    shown = ma.modes[:PLOT_MODES]
    eq = model.backbones(fw.q, fw.stretch)
    length = float(np.ptp(eq[..., 2]))
    amp = 0.1 * max(length, 1e-3)
    fig = figure(4.0 * len(shown), 4.6)
    for k, mode in enumerate(shown):
        ax = fig.add_subplot(1, len(shown), k + 1, projection='3d')
        delta = ma.backbones(k, 1e-3) - eq          # the shape is linear: scaled below
        delta *= amp / max(float(np.abs(delta).max()), 1e-300)
        pts = [eq]
        for line in eq:
            ax.plot(*(line.T * 1e3), color='0.6', lw=1.0)
        for sign, color in ((1.0, 'tab:red'), (-1.0, 'tab:blue')):
            moved = eq + sign * delta
            pts.append(moved)
            for line in moved:
                ax.plot(*(line.T * 1e3), color=color, lw=1.2)
        _equal_axes(ax, np.concatenate([p.reshape(-1, 3) for p in pts]) * 1e3)
        ax.set_xlabel('x [mm]')
        ax.set_ylabel('y [mm]')
        ax.set_zlabel('z [mm]')
        ax.set_title(f'mode {k + 1}: {mode.frequency_hz:.3f} Hz, zeta {mode.damping_ratio:.3f}',
                     fontsize=9)
    fig.suptitle(f'{model.cfg.name}: equilibrium (grey) moved along each mode (red, blue: '
                 f'+/- {amp * 1e3:.0f} mm at the point that moves most)', fontsize=10)
    save_figure(fig, path)


def _equal_axes(ax, pts):
    centre = 0.5 * (pts.max(axis=0) + pts.min(axis=0))
    half = 0.5 * float(np.ptp(pts, axis=0).max())
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        setter(c - half, c + half)


# ---------------------------------------------------------- simulate
def _read_pressure_table(path, model):
    """``t_s, p1_kpa ... pN_kpa`` rows -> (times [s], pressures [Pa]); problems are UsageErrors."""
    label = f'--pressures-csv {path}'
    want = ['t_s'] + [f'p{i + 1}_kpa' for i in range(model.A)]

    def check(header, line):
        if header != want:
            raise UsageError(f'{label}, line {line}: expected the header {",".join(want)}, '
                             f'got {",".join(header)}')

    header, records = fitting.numeric_csv_rows(path, check, UsageError, label)
    times, rows = [], []
    for line, values in records:
        where = f'{label}, line {line}'
        if not all(math.isfinite(v) for v in values):
            raise UsageError(f'{where}: not a finite number in '
                             f'{",".join(f"{v:g}" for v in values)!r}')
        try:
            rows.append(check_pressures_kpa(model, values[1:]))
        except UsageError as exc:
            raise UsageError(f'{where}: {exc}') from None
        if times and values[0] <= times[-1]:
            raise UsageError(f'{where}: t_s = {values[0]:g} does not increase')
        times.append(values[0])
    if header is None or not rows:
        raise UsageError(f'{label}: no data rows (expected the header {",".join(want)})')
    return np.array(times), np.array(rows)


def _cmd_simulate(args) -> int:
    limit_blas_threads()
    model = load_model(args)
    load = args.payload_kg
    if args.pressures_csv:
        tt, pp = _read_pressure_table(args.pressures_csv, model)
        pressures = dyn.piecewise_linear(tt, pp)
        p = check_pressures_kpa(model, args.pressures_kpa) if args.pressures_kpa is not None \
            else pressures(0.0)
        kind = 'pressures-csv'
    else:
        if args.pressures_kpa is None:
            raise UsageError('--pressures-kpa is required (the start equilibrium), except with '
                             '--pressures-csv')
        p = check_pressures_kpa(model, args.pressures_kpa)
        if args.step_pressures_kpa is not None:
            pressures = check_pressures_kpa(model, args.step_pressures_kpa)
            kind = 'step'
        else:
            pressures = p
            kind = 'release'
    force = args.release_tip_force_n if kind == 'release' else None
    fw, problem = _equilibrium(model, p, load, force, 'the start equilibrium')
    if problem:
        error(problem)
        return EXIT_FAILED
    try:
        ig = GeneralizedAlpha(model, step_s=args.step_s, damping_time_s=args.damping_time_s)
        if kind == 'release':
            ig.start_released(fw)
        else:
            ig.start(fw)
        run = dyn.sample_motion(ig, args.duration_s, sample_s=args.sample_s,
                                pressures_pa=pressures, check_s=CHECK_S)
    except dyn.ModalError as exc:
        error(f'no default step: {exc}')
        return EXIT_FAILED
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    d = {'samples': run.samples(), 'config': model.cfg.name, 'input': kind,
         'pressures_pa': p.tolist(), 'payload_kg': load,
         'release_tip_force_n': None if force is None else list(force),
         'step_s': run.step_s, 'sample_s': args.sample_s or run.step_s,
         'duration_s': args.duration_s, 'damping_time_s': ig.inertia.damping_time,
         'mass_damping_per_s': ig.inertia.mass_damping, 'status': int(run.report.status),
         'message': run.report.message, 'success': run.success, 'steps': run.report.steps,
         'halvings': run.report.halvings, 'wall_s': run.report.wall_s,
         'real_time_factor': run.real_time_factor,
         'energy_start_j': float(run.energy_j[0]), 'energy_end_j': float(run.energy_j[-1]),
         'max_constraint_violation_m': run.constraint_violation, 'check_s': CHECK_S,
         'csv': args.csv, 'plot': args.plot}
    if args.csv:
        _write_samples_csv(args.csv, run)
    if args.plot:
        _plot_motion(model, run, kind, args.plot)
    if not run.success:
        error(f'the integration stopped: {run.report.message}; '
              f'{len(run.times_s)} samples up to t = {run.times_s[-1]:.6g} s kept')
    if args.json:
        emit_json(d)
        return EXIT_OK if run.success else EXIT_FAILED
    x = run.positions_m
    dev = np.linalg.norm(x - x[-1], axis=1)
    lines = [f'robot          {model.cfg.name}: {model.cfg.n_segments} segment(s), payload '
             f'{load:g} kg, input: {kind}',
             f'start          {" ".join(f"{v / 1e3:g}" for v in p)} kPa'
             + ('' if force is None else
                f', released from a tip force {" ".join(f"{v:g}" for v in force)} N'),
             f'damping        damping_time_s {ig.inertia.damping_time:g} s, '
             f'mass_damping_per_s {ig.inertia.mass_damping:g} 1/s',
             f'integration    step {run.step_s * 1e3:.4g} ms, {run.report.steps} steps, '
             f'{run.report.halvings} halvings, {run.report.wall_s:.3f} s wall, '
             f'{run.real_time_factor:.3g}x real time',
             f'status         {int(run.report.status)}: {run.report.message}',
             f'tip start      {_vec_mm(x[0])}  mm (x y z)',
             f'tip end        {_vec_mm(x[-1])}  mm at t = {run.times_s[-1]:.6g} s',
             f'farthest       {dev.max() * 1e3:.4g} mm from the end position',
             f'energy drift   {run.energy_j[-1] - run.energy_j[0]:.4g} J; constraints '
             f'max |C| = {run.constraint_violation:.3g} (checked every {CHECK_S * 1e3:g} ms)', '']
    k = max(1, math.ceil(len(run.times_s) / 20))
    rows = [[f'{t:.4f}', *(f'{v * 1e3:.3f}' for v in xx), *(f'{v:.5f}' for v in zz)]
            for t, xx, zz in zip(run.times_s[::k], x[::k], run.z_axes[::k])]
    lines += table(['t [s]', 'x [mm]', 'y [mm]', 'z [mm]', 'zx', 'zy', 'zz'], rows)
    if k > 1:
        lines.append(f'(every {k}th of {len(run.times_s)} samples; all in --json and --csv)')
    lines += [f'csv            {args.csv}'] if args.csv else []
    lines += [f'plot           {args.plot}'] if args.plot else []
    print_lines(lines)
    return EXIT_OK if run.success else EXIT_FAILED


def _write_samples_csv(path, run):
    n_p = run.pressures_pa.shape[1]
    with open_out(path, '--csv') as fh:
        w = csv.writer(fh)
        w.writerow(['t_s', 'x_m', 'y_m', 'z_m', 'zx', 'zy', 'zz']
                   + [f'p{i + 1}_kpa' for i in range(n_p)])
        for t, x, z, p in zip(run.times_s, run.positions_m, run.z_axes, run.pressures_pa):
            w.writerow([repr(float(t))] + [repr(float(v)) for v in x]
                       + [repr(float(v)) for v in z] + [repr(float(v)) for v in p / 1e3])


def _plot_motion(model, run, kind, path):
    fig = figure(11, 4.5)
    ax = fig.add_subplot(1, 2, 1)
    for i, name in enumerate('xyz'):
        ax.plot(run.times_s, (run.positions_m[:, i] - run.positions_m[-1, i]) * 1e3, label=name)
    ax.set_xlabel('time [s]')
    ax.set_ylabel('tip position - end position [mm]')
    ax.set_title(f'{model.cfg.name}: {kind}, step {run.step_s * 1e3:.3g} ms', fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend()
    ax3 = fig.add_subplot(1, 2, 2, projection='3d')
    ax3.plot(*(run.positions_m.T * 1e3), lw=1.0)
    ax3.scatter(*(run.positions_m[0] * 1e3), color='tab:green', label='start')
    ax3.scatter(*(run.positions_m[-1] * 1e3), color='tab:red', label='end')
    ax3.set_xlabel('x [mm]')
    ax3.set_ylabel('y [mm]')
    ax3.set_zlabel('z [mm]')
    _equal_axes(ax3, run.positions_m * 1e3)
    ax3.set_title("the tip's path", fontsize=9)
    ax3.legend(fontsize=8)
    save_figure(fig, path)


# -------------------------------------------------- identify damping
def _cmd_identify_damping(args) -> int:
    limit_blas_threads()
    model = load_model(args)
    try:
        stream = fitting.read_pose_stream(args.csv, args.bag, pose_topic=args.pose_topic,
                                          pressure_topic=args.pressure_topic)
    except fitting.RecordingError as exc:
        raise UsageError(f'{"--bag" if args.bag else "--csv"}: {exc}') from None
    t, x = stream.times_s, stream.positions_m
    try:
        window = None
        t0, t1 = args.t_start_s, args.t_end_s
        if t0 is None or t1 is None:
            window = fitting.ringdown_window(t, x, t_end_s=args.t_end_s)
            t0 = window.t_start_s if t0 is None else t0
            t1 = window.t_end_s if t1 is None else t1
        fit = fitting.fit_free_vibration(t, x, t0, t1)
    except ValueError as exc:
        raise UsageError(f'no free vibration to fit: {one_line(exc)}') from None
    if args.pressures_kpa is not None:
        p = check_pressures_kpa(model, args.pressures_kpa)
        p_source = '--pressures-kpa'
    elif stream.has_pressures:
        p = stream.pressures_at(t1)
        p_source = 'the recording (in effect at the window\'s end)'
        try:
            p = check_pressures_kpa(model, p / 1e3)
        except UsageError as exc:
            raise UsageError(f'the recording\'s pressures: {exc}') from None
    else:
        raise UsageError('the recording has no pressures: give --pressures-kpa (the pressures '
                         'the robot rings at)')
    fw, problem = _equilibrium(model, p, args.payload_kg, None, 'the recorded equilibrium')
    if problem:
        error(problem)
        return EXIT_FAILED
    try:
        res = fitting.identify_damping(fit, fw)
    except ValueError as exc:
        error(f'no damping time reproduces the recording: {one_line(exc)}')
        return EXIT_FAILED
    if args.plot:
        _plot_ringdown(stream, fit, window, args.plot)
    d = res.to_dict() | {
        'config': model.cfg.name, 'source': stream.source, 'pressures_pa': p.tolist(),
        'pressures_from': p_source, 'payload_kg': args.payload_kg,
        't_motion_s': None if window is None else window.t_motion_s, 't_end_s': t1,
        'frequency_error': res.model_frequency_hz / fit.frequency_hz - 1.0,
        'notes': list(stream.notes), 'plot': args.plot}
    if args.json:
        emit_json(d)
        return EXIT_OK
    notes = f' ({"; ".join(stream.notes)})' if stream.notes else ''
    lines = [f'recording      {stream.source}: {len(stream)} poses, '
             f'{t[0]:.4g} .. {t[-1]:.4g} s{notes}',
             'window         ' + (f'{fit.t_start_s:.4g} .. {t1:.4g} s, {fit.n_samples} poses'
                                  + ('' if window is None else
                                     f' (motion starts at {window.t_motion_s:.4g} s; fit from '
                                     'half a period later)')),
             f'measured       {fit.frequency_hz:.4f} Hz undamped ({fit.damped_frequency_hz:.4f} '
             f'Hz damped), damping ratio {fit.damping_ratio:.4f}, amplitude '
             f'{fit.amplitude_m * 1e3:.3f} mm along {_direction_text(fit.direction)}, RMS '
             f'residual {fit.rms_residual_m * 1e3:.3g} mm',
             f'equilibrium    {" ".join(f"{v / 1e3:g}" for v in p)} kPa (from {p_source}), '
             f'payload {args.payload_kg:g} kg',
             f'model          first mode {res.model_frequency_hz:.4f} Hz '
             f'({100 * d["frequency_error"]:+.2f} % against the measured one)',
             f'damping_time_s {res.damping_time_s:.6g} s (model damping ratio '
             f'{res.model_damping_ratio:.4f}); robot file key dynamics.damping_time_s',
             f'first_mode_err {d["frequency_error"]:+.4f}; robot file key '
             'dynamics.first_mode_error ' + (
                 '(a target jump then moves in 1.5 periods of the measured mode)'
                 if abs(d['frequency_error']) <= KNOWN_MODE_ERROR else
                 f'(beyond +-{KNOWN_MODE_ERROR:g}: not used; calibrate the file with '
                 'mass_scale)')]
    if args.plot:
        lines.append(f'plot           {args.plot}')
    print_lines(lines)
    return EXIT_OK


def _plot_ringdown(stream, fit, window, path):
    t = stream.times_s
    y = stream.positions_m @ fit.direction
    sel = (t >= fit.t_start_s)
    ts = t[sel] - fit.t_start_s
    sigma = 2 * np.pi * fit.frequency_hz * fit.damping_ratio
    w = 2 * np.pi * fit.damped_frequency_hz
    basis = np.column_stack([np.ones_like(ts), np.exp(-sigma * ts) * np.cos(w * ts),
                             np.exp(-sigma * ts) * np.sin(w * ts)])
    coef = np.linalg.lstsq(basis, y[sel], rcond=None)[0]
    fig = figure(9, 4.2)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(t, (y - coef[0]) * 1e3, '.', ms=2, color='0.5', label='recorded')
    ax.plot(t[sel], (basis @ coef - coef[0]) * 1e3, '-', color='tab:red',
            label=f'fit: {fit.frequency_hz:.3f} Hz, zeta {fit.damping_ratio:.4f}')
    ax.axvline(fit.t_start_s, color='tab:red', ls=':', lw=1)
    if window is not None:
        ax.axvline(window.t_motion_s, color='tab:green', ls=':', lw=1, label='motion starts')
    ax.set_xlabel('time [s]')
    ax.set_ylabel('tip position along the motion [mm]')
    ax.set_title('free vibration of the first mode', fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, path)


# ------------------------------------------------------------ parser
def _add_pressures(p, required=True):
    p.add_argument('--pressures-kpa', type=finite_float, nargs='+', required=required,
                   default=None, metavar='P', help='one gauge pressure per actuator [kPa]')


def _add_elements(p):
    p.add_argument('--elements', type=element_count, default=None, metavar='N',
                   help="ANCF elements per actuator; default: the robot file's value")


def _add_damping(p):
    p.add_argument('--damping-time-s', type=nonneg_float, default=None, metavar='B',
                   help="Kelvin-Voigt retardation time [s]; default: the robot file's "
                        'dynamics.damping_time_s')


def register(subparsers) -> None:
    """Add ``modes`` and ``simulate``."""
    p = subparsers.add_parser(
        'modes', help='natural frequencies, damping ratios and mode shapes of an equilibrium',
        description='Forward solve at the given pressures (payload, tip force), then the natural '
                    'modes of that equilibrium, lowest first: undamped and damped frequency, '
                    "damping ratio and the end effector's direction of motion (base frame). "
                    'An unconverged or unstable equilibrium is an error (exit 1).',
        epilog='Example: bellow-ancf modes --pressures-kpa 0 0 0 --payload-kg 0.05')
    add_config(p)
    _add_pressures(p)
    add_loads(p)
    p.add_argument('--modes', type=int_at_least(1), default=6, metavar='N',
                   help='how many of the lowest modes; default: %(default)s')
    _add_damping(p)
    _add_elements(p)
    p.add_argument('--json', action='store_true',
                   help='print one JSON object {"modes": [...], ...} (SI units)')
    p.add_argument('--plot', metavar='PNG',
                   help=f'draw the first {PLOT_MODES} mode shapes (3-D) to this PNG file')
    p.set_defaults(func=_cmd_modes)

    s = subparsers.add_parser(
        'simulate', help='time simulation of a release, a pressure step or pressures over time',
        description='Generalized-alpha time integration from rest at the static equilibrium at '
                    '--pressures-kpa (and --payload-kg), sampling the end effector. One input: '
                    '--release-tip-force-n (start at the equilibrium under that tip force, '
                    'removed at t = 0), --step-pressures-kpa (the pressures jump to these at '
                    't = 0) or --pressures-csv (pressures over time, columns t_s,p1_kpa,...,'
                    'pN_kpa: linear between rows, held before the first row and after the '
                    'last; the start equilibrium is at the table\'s pressures at t = 0 unless '
                    '--pressures-kpa is given). The step is shortened so that the samples fall '
                    'on steps. A failed integration is reported with its status (exit 1), and '
                    'what was computed is still written.',
        epilog='Example: bellow-ancf simulate --pressures-kpa 0 0 0 --payload-kg 0.05 '
               '--release-tip-force-n 0.5 0 0 --duration-s 0.5')
    add_config(s)
    _add_pressures(s, required=False)
    s.add_argument('--payload-kg', type=payload_mass, default=0.0, metavar='M',
                   help='payload at the end effector [kg]; default: %(default)s')
    s.add_argument('--duration-s', type=positive_float, required=True, metavar='T',
                   help='simulated time [s]')
    s.add_argument('--step-s', type=positive_float, default=None, metavar='H',
                   help='integration step [s]; default: 1/40 of the first period (at most 10 ms)')
    s.add_argument('--sample-s', type=positive_float, default=None, metavar='S',
                   help='sampling interval [s]; default: every step')
    _add_damping(s)
    _add_elements(s)
    src = s.add_mutually_exclusive_group(required=True)
    src.add_argument('--release-tip-force-n', type=finite_float, nargs=3, default=None,
                     metavar=('FX', 'FY', 'FZ'),
                     help='start under this tip force [N, base frame], released at t = 0')
    src.add_argument('--step-pressures-kpa', type=finite_float, nargs='+', default=None,
                     metavar='Q', help='pressures from t = 0 on [kPa], one per actuator')
    src.add_argument('--pressures-csv', metavar='FILE',
                     help='pressures over time (CSV t_s,p1_kpa,...; linear between rows)')
    s.add_argument('--json', action='store_true',
                   help='print one JSON object {"samples": [{"t_s", "position_m", "z_axis"}, '
                        '...], ...} (SI units)')
    s.add_argument('--csv', metavar='OUT',
                   help='write the samples: t_s,x_m,y_m,z_m,zx,zy,zz,p1_kpa,... (identify '
                        'damping reads it)')
    s.add_argument('--plot', metavar='PNG',
                   help="draw the tip's position against time and its 3-D path")
    s.set_defaults(func=_cmd_simulate)


def register_identify_damping(isub) -> None:
    """Add ``identify damping`` to the ``identify`` subcommands."""
    p = isub.add_parser(
        'damping', help='first-mode frequency and damping from a recorded release or step',
        description='Fit the free vibration of the first mode, x(t) = c + A exp(-zeta w t) '
                    'cos(w_d t + phi) along its principal direction, to the recorded '
                    "end-effector positions, then find the robot file's dynamics.damping_time_s"
                    ' that gives the model the measured damping ratio at the recorded '
                    "equilibrium (--pressures-kpa, else the recording's pressures, and "
                    '--payload-kg). Default window: the motion starts where the tip (a running '
                    'median of five poses) has left its first position by a tenth of its '
                    'largest excursion; the fit starts half a period of the strongest '
                    'oscillation later (about the first peak after a release, when the faster '
                    "modes have died out) and ends where a first fit's envelope has sunk to "
                    'twice its RMS residual (the noise), after at least three periods, or at '
                    'the end. CSV: columns t_s,x_m,y_m,z_m (optional p1_kpa,...; others '
                    'ignored); bag: measured_pose (PoseStamped) and pressure_command if '
                    'present.',
        epilog='Example: bellow-ancf identify damping --csv release.csv --payload-kg 0.05')
    add_config(p)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument('--csv', metavar='FILE', help='recorded poses (CSV)')
    src.add_argument('--bag', metavar='DIR', help='rosbag2 directory (sqlite3 or mcap)')
    _add_pressures(p, required=False)
    p.add_argument('--payload-kg', type=payload_mass, default=0.0, metavar='M',
                   help='payload at the end effector [kg]; default: %(default)s')
    p.add_argument('--t-start-s', type=finite_float, default=None, metavar='T0',
                   help='start of the fitted window [s, recording time]; default: see above')
    p.add_argument('--t-end-s', type=finite_float, default=None, metavar='T1',
                   help='end of the fitted window [s]; default: see above')
    p.add_argument('--pressure-topic', default=fitting.PRESSURE_TOPIC, metavar='T',
                   help='bag topic of the pressure commands; default: %(default)s')
    p.add_argument('--pose-topic', default=fitting.POSE_TOPIC, metavar='T',
                   help='bag topic of the measured poses; default: %(default)s')
    _add_elements(p)
    p.add_argument('--json', action='store_true', help='print one JSON object (SI units)')
    p.add_argument('--plot', metavar='PNG', help='draw the recording and the fitted vibration')
    p.set_defaults(func=_cmd_identify_damping)
