"""``bellow-ancf identify play``: the pressure regulators' play from their own sensors.

::

    bellow-ancf identify play (--csv FILE | --bag DIR) [--settle-s S]
                              [--pressure-topic T] [--measured-topic T] [--json]

Reads the set-points and the regulators' measured pressures
(:func:`bellow_ancf_ros.core.fit.read_pressure_recording`) and reads each
regulator's play band (:func:`bellow_ancf_ros.core.fit.fit_play`): after a
set-point step the pressure settles half the band short of it.  The value
for the inverse node's ``regulator_play_kpa`` is the smallest band found
(a compensation wider than a regulator's play dithers it).  A recording
that cannot give it is bad input (one line, exit status 2).  Registered by
:mod:`.identify`.
"""

from __future__ import annotations

from ..core import fit as fitting
from .common import EXIT_OK, UsageError, emit_json, nonneg_float, one_line, print_lines

__all__ = ['register_identify_play']

#: Where the value goes.
DESTINATION = 'inverse node parameter regulator_play_kpa'


def _cmd_identify_play(args) -> int:
    option = '--bag' if args.bag else '--csv'
    try:
        rec = fitting.read_pressure_recording(args.csv, args.bag,
                                              command_topic=args.pressure_topic,
                                              measured_topic=args.measured_topic)
    except fitting.RecordingError as exc:
        raise UsageError(f'{option}: {exc}') from None
    fits = []
    for a in range(rec.command_pa.shape[1]):
        try:
            fits.append(fitting.fit_play(rec.times_s, rec.command_pa[:, a], rec.measured_pa[:, a],
                                         settle_s=args.settle_s))
        except ValueError as exc:
            fits.append(one_line(exc))
    found = [f for f in fits if not isinstance(f, str)]
    if not found:
        raise UsageError(f'no play from this recording: actuator 1: {fits[0]}')
    value = min(f.width_pa for f in found)
    if args.json:
        emit_json({'source': rec.source, 'samples': len(rec), 'regulator_play_kpa': value / 1e3,
                   'actuators': [{'error': f} if isinstance(f, str) else
                                 {'width_pa': f.width_pa, 'std_error_pa': f.std_error_pa,
                                  'holds_up': f.holds_up, 'holds_down': f.holds_down}
                                 for f in fits]})
        return EXIT_OK
    t = rec.times_s
    lines = [f'recording      {rec.source}: {len(rec)} measured samples, {t[0]:.6g} .. '
             f'{t[-1]:.6g} s']
    for a, f in enumerate(fits):
        lines.append(f'actuator {a + 1:<5d} ' + (
            f'no play read: {f}' if isinstance(f, str) else
            f'play {f.width_pa / 1e3:.3f} kPa (std. error {f.std_error_pa / 1e3:.2g} kPa; '
            f'{f.holds_up} holds after steps up, {f.holds_down} down)'))
    lines.append(f'regulator_play_kpa {value / 1e3:.3f}: {DESTINATION} (the smallest band read: '
                 'a compensation wider than a regulator\'s play dithers it)')
    print_lines(lines)
    return EXIT_OK


def register_identify_play(isub) -> None:
    """Add ``identify play`` to the ``identify`` subcommands."""
    p = isub.add_parser(
        'play', help="the pressure regulators' play (hysteresis band) from their own sensors",
        description="Read each regulator's play band from its set-points and its measured "
                    'pressure: after a set-point step the pressure settles half the band '
                    'below it (a step up) or above it (a step down). Counted: holds longer '
                    'than --settle-s reached by a step in the same direction as the step '
                    'before (a vent and the hold after it do not count); the band is the '
                    'median offset after steps up minus the median after steps down. '
                    'Record steps wider than the play, e.g. 10 to 40 kPa in five steps, up '
                    'and down twice, each held 1 s, or the excitation publisher\'s run. CSV: '
                    'columns t_s,p1_kpa..pN_kpa,m1_kpa..mN_kpa (set-point and measured '
                    'pressure per actuator, one row per measured sample); bag: '
                    'measured_pressure and pressure_command (Float64MultiArray). The value '
                    'goes to the ' + DESTINATION + '.',
        epilog='Example: bellow-ancf identify play --bag regulators_bag')
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument('--csv', metavar='FILE', help='recorded set-points and pressures (CSV)')
    src.add_argument('--bag', metavar='DIR', help='rosbag2 directory (sqlite3 or mcap)')
    p.add_argument('--settle-s', type=nonneg_float, default=fitting.PLAY_SETTLE_S, metavar='S',
                   help='a hold counts from this long after its step [s]; default: %(default)s')
    p.add_argument('--pressure-topic', default=fitting.PRESSURE_TOPIC, metavar='T',
                   help='bag topic of the set-points; default: %(default)s')
    p.add_argument('--measured-topic', default=fitting.MEASURED_PRESSURE_TOPIC, metavar='T',
                   help='bag topic of the measured pressures; default: %(default)s')
    p.add_argument('--json', action='store_true', help='print one JSON object (SI units)')
    p.set_defaults(func=_cmd_identify_play)
