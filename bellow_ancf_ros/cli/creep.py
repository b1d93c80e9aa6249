"""``bellow-ancf identify creep``: the bellows' creep from a recorded pressure step.

::

    bellow-ancf identify creep (--csv FILE | --bag DIR) [--t-step-s T] [--t-end-s T1]
                               [--settle-s S] [--pose-topic T] [--pressure-topic T]
                               [--json] [--plot PNG]

Reads the recorded poses (:func:`bellow_ancf_ros.core.fit.read_pose_stream`),
takes the step time from ``--t-step-s`` or from the recorded pressures
(:func:`bellow_ancf_ros.core.fit.pressure_step_time`: the command's largest
change) and fits the creep (:func:`bellow_ancf_ros.core.fit.fit_creep`): the
creep fraction and time constant for the inverse node's parameters
``creep_fraction`` and ``creep_time_constant_s``.  A recording that cannot
give them is bad input (one line, exit status 2).  Registered by
:mod:`.identify`.
"""

from __future__ import annotations

import numpy as np

from ..core import fit as fitting
from .common import (EXIT_OK, UsageError, emit_json, finite_float, nonneg_float, one_line,
                     print_lines)
from .output import figure, save_figure

__all__ = ['register_identify_creep']

#: Where the two values go.
DESTINATION = 'inverse node parameters creep_fraction, creep_time_constant_s'


def _kpa(p) -> str:
    return ' '.join(f'{v / 1e3:g}' for v in p)


def _direction_text(d) -> str:
    k = int(np.argmax(np.abs(d)))
    if abs(d[k]) > 0.999:
        return f'{"+" if d[k] > 0 else "-"}{"xyz"[k]}'
    return '(' + ', '.join(f'{v:.3f}' for v in d) + ')'


def _cmd_identify_creep(args) -> int:
    option = '--bag' if args.bag else '--csv'
    try:
        stream = fitting.read_pose_stream(args.csv, args.bag, pose_topic=args.pose_topic,
                                          pressure_topic=args.pressure_topic)
    except fitting.RecordingError as exc:
        raise UsageError(f'{option}: {exc}') from None
    before = after = None
    if args.t_step_s is not None:
        t_step, step_from = args.t_step_s, '--t-step-s'
    elif stream.has_pressures:
        try:
            t_step = fitting.pressure_step_time(stream.pressure_times_s, stream.pressures_pa)
        except ValueError as exc:
            raise UsageError(f"the recording's pressures: {one_line(exc)}; give --t-step-s "
                             '(when the step was commanded, recording time)') from None
        step_from = "the recording's pressures"
    else:
        raise UsageError('the recording has no pressures: give --t-step-s (when the step was '
                         'commanded, recording time)')
    if stream.has_pressures:
        before = stream.pressures_at(np.nextafter(t_step, -np.inf))
        after = stream.pressures_at(t_step)
    try:
        fit = fitting.fit_creep(stream.times_s, stream.positions_m, t_step,
                                t_end_s=args.t_end_s, settle_s=args.settle_s)
    except ValueError as exc:
        raise UsageError(f'no creep from this recording: {one_line(exc)}') from None
    if args.plot:
        _plot_creep(stream, fit, args.plot)
    if args.json:
        emit_json(fit.to_dict() | {
            'source': stream.source, 't_step_from': step_from,
            'pressures_before_pa': None if before is None else before.tolist(),
            'pressures_after_pa': None if after is None else after.tolist(),
            'notes': list(stream.notes), 'plot': args.plot})
        return EXIT_OK
    t = stream.times_s
    notes = f' ({"; ".join(stream.notes)})' if stream.notes else ''
    step = f'{t_step:.6g} s (from {step_from}'
    step += ')' if before is None else f': {_kpa(before)} -> {_kpa(after)} kPa)'
    creep_mm = fit.creep_fraction * fit.displacement_m * 1e3
    lines = [
        f'recording      {stream.source}: {len(stream)} poses, {t[0]:.6g} .. {t[-1]:.6g} s'
        f'{notes}',
        f'step           {step}',
        f'motion         {fit.displacement_m * 1e3:.3f} mm along '
        f'{_direction_text(fit.direction)}; the fast move {fit.delay_s * 1e3:.0f} ms after '
        f'the command (its mean time)',
        f'window         {fit.t_start_s:.6g} .. {fit.t_end_s:.6g} s ({fit.settle_s:.3g} s after '
        f'the step), {fit.n_samples} poses, {fit.outliers} outlier(s) dropped; noise '
        f'{fit.noise_m * 1e3:.3g} mm, RMS residual {fit.rms_residual_m * 1e3:.3g} mm',
        f'creep          {creep_mm:.3f} mm of the move: fraction {fit.creep_fraction:.4f} '
        f'(std. error {fit.creep_fraction_stderr:.2g}), time constant '
        f'{fit.creep_time_constant_s:.4g} s (std. error {fit.creep_time_constant_stderr_s:.2g}'
        ' s)',
        f'creep_fraction {fit.creep_fraction:.4f}, creep_time_constant_s '
        f'{fit.creep_time_constant_s:.4g}: {DESTINATION}']
    if args.plot:
        lines.append(f'plot           {args.plot}')
    print_lines(lines)
    return EXIT_OK


def _plot_creep(stream, fit, path):
    """The recorded step and the fit (left), the creep close up (right)."""
    t = stream.times_s
    y = (stream.positions_m - np.array(fit.start_position_m)) @ np.array(fit.direction)
    early = np.linspace(fit.t_step_s + fit.delay_s, fit.t_start_s, 50)
    late = np.linspace(fit.t_start_s, fit.t_end_s, 400)
    dmm = fit.displacement_m * 1e3
    creep = fit.creep_fraction * dmm
    noise = 3 * fit.noise_m * 1e3
    fig = figure(12, 4.4)
    for k, (lo, hi, title) in enumerate([
            (min(0.0, dmm) - 0.15 * abs(dmm), max(0.0, dmm) + 0.15 * abs(dmm),
             'the step'),
            (dmm - 1.3 * creep - noise, dmm + 0.3 * creep + noise, 'the creep, close up')]):
        ax = fig.add_subplot(1, 2, k + 1)
        ax.plot(t, y * 1e3, '.', ms=2, color='0.5', label='recorded')
        ax.plot(early, fit.curve(early) * 1e3, ':', color='tab:red')
        ax.plot(late, fit.curve(late) * 1e3, '-', color='tab:red',
                label=f'fit: creep fraction {fit.creep_fraction:.4f}, '
                      f'time constant {fit.creep_time_constant_s:.3g} s')
        ax.axhline(dmm, color='tab:red', ls='--', lw=0.8)
        ax.axvline(fit.t_step_s, color='tab:green', ls=':', lw=1, label='step commanded')
        ax.axvline(fit.t_start_s, color='tab:red', ls=':', lw=1, label='fit starts')
        ax.set_ylim(lo, hi)
        ax.set_xlabel('time [s]')
        ax.set_ylabel('tip position along the motion [mm]')
        ax.set_title(title, fontsize=10)
        ax.grid(True, alpha=0.3)
        if k == 1:
            ax.set_xlim(fit.t_step_s - 0.5, fit.t_end_s)
            ax.legend(fontsize=8, loc='lower right')
    save_figure(fig, path)


def register_identify_creep(isub) -> None:
    """Add ``identify creep`` to the ``identify`` subcommands."""
    p = isub.add_parser(
        'creep', help="the bellows' creep fraction and time constant from a recorded "
                      'pressure step',
        description='Fit the creep after a pressure step held still: the tip moves quickly '
                    'by (1 - c) of its displacement D, then creeps the rest as c D '
                    'exp(-t/T) decaying. The positions are projected on the motion (from '
                    'the median pose of the 0.5 s before the step to that of the last '
                    'second); y(t) = y_inf - B exp(-(t - t_step)/T) is fitted robustly '
                    '(soft-l1 loss, outliers dropped) from --settle-s after the step, with '
                    "the first mode's ringing (a damped sinusoid) in the curve when the robot "
                    'rang; c is '
                    "B at the fast move's mean time over the displacement. Record the "
                    'robot still before the step and for at least 4 time constants after '
                    'it (e.g. 20 s). CSV: columns t_s,x_m,y_m,z_m (optional p1_kpa,...; '
                    'others ignored); bag: measured_pose (PoseStamped) and pressure_command '
                    'if present. The values go to the ' + DESTINATION + '.',
        epilog='Example: bellow-ancf identify creep --csv step.csv --plot creep.png')
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument('--csv', metavar='FILE', help='recorded poses (CSV)')
    src.add_argument('--bag', metavar='DIR', help='rosbag2 directory (sqlite3 or mcap)')
    p.add_argument('--t-step-s', type=finite_float, default=None, metavar='T',
                   help='when the pressure step was commanded [s, recording time]; default: '
                        "the recorded pressure command's largest change")
    p.add_argument('--t-end-s', type=finite_float, default=None, metavar='T1',
                   help='end of the fitted window [s]; default: the last pose')
    p.add_argument('--settle-s', type=nonneg_float, default=None, metavar='S',
                   help='start the fit of the creep alone this long after the step [s]; '
                        "default: 0.5 with the first mode's ringing fitted where the robot "
                        'rang, else (or when that fit is refused) where the ringing has sunk '
                        'into the noise (0.5 to 3 s)')
    p.add_argument('--pressure-topic', default=fitting.PRESSURE_TOPIC, metavar='T',
                   help='bag topic of the pressure commands; default: %(default)s')
    p.add_argument('--pose-topic', default=fitting.POSE_TOPIC, metavar='T',
                   help='bag topic of the measured poses; default: %(default)s')
    p.add_argument('--json', action='store_true', help='print one JSON object (SI units)')
    p.add_argument('--plot', metavar='PNG', help='draw the recording and the fitted creep')
    p.set_defaults(func=_cmd_identify_creep)
