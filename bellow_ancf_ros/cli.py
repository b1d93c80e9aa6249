"""Command-line interface ``bellow-ancf`` (also ``python -m bellow_ancf_ros.cli``).

Subcommands::

    bellow-ancf forward [--config C] --pressures-kpa P1 P2 ... [--payload-kg M]
                        [--elements N] [--json]
    bellow-ancf forward [--config C] --pressures-csv FILE [--payload-kg M]
                        [--elements N] --json
    bellow-ancf inverse [--config C] --position X Y Z [--z-axis ZX ZY ZZ]
                        [--payload-kg M] [--elements N] [--json]
    bellow-ancf inverse [--config C] --targets-csv FILE [--payload-kg M]
                        [--elements N] --json

This interface is a contract other programs script against:

* ``--json`` prints one JSON object per line (strict JSON: non-finite numbers
  become ``null``).  The keys are those of ``ForwardResult.to_dict()`` /
  ``InverseResult.to_dict()`` (SI units); the batch modes add ``line``, the
  1-based line of the CSV row the object answers (the header is line 1).
* Batch modes (``--pressures-csv`` / ``--targets-csv``, ``-`` reads stdin)
  read a CSV file with a header row, solve the rows in order, each
  warm-started from the previous converged solution, and flush one JSON line
  per row.  A bad row is reported on stderr with its line number and skipped;
  the other rows are still answered.
* Exit status: 0 success; 1 a single solve did not converge (the result is
  still printed, ``converged`` false) or the solver failed internally; 2 bad
  input, reported as one line ``bellow-ancf: error: ...`` on stderr (in batch
  mode: 2 at the end if any row was bad).
* The identification and study subcommands (``identify``, ``convergence``,
  ``workspace``, ``compare-pcc``, ``track``) live in ``bellow_ancf_ros.cli_tools``,
  added through its ``register(subparsers)``; every subcommand's parser sets
  ``func`` (``set_defaults(func=...)``), a callable taking the parsed
  arguments and returning the exit status.

This module does not import ROS.
"""

from __future__ import annotations

import argparse
import csv
import importlib
import json
import math
import os
import sys
import time

import numpy as np

from .core import ConfigError, RobotModel, load_robot, solve_forward, solve_inverse

__all__ = ['main', 'build_parser', 'UsageError', 'json_safe']

PROG = 'bellow-ancf'
EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
TOOLS_MODULE = 'bellow_ancf_ros.cli_tools'
INVERSE_POSITION_COLUMNS = ('x', 'y', 'z')
INVERSE_AXIS_COLUMNS = ('zx', 'zy', 'zz')


# ----------------------------------------------------------------- errors
class UsageError(Exception):
    """Bad input: reported as one line on stderr, exit status 2."""


class SolverError(Exception):
    """The solver raised unexpectedly (a bug, not bad input): exit status 1."""


class _Parser(argparse.ArgumentParser):
    """Argument parser whose errors become :class:`UsageError` (one line, no usage dump)."""

    def error(self, message):
        raise UsageError(f"{message} (see '{self.prog} --help')")


def _one_line(text) -> str:
    return '; '.join(part.strip() for part in str(text).splitlines() if part.strip())


def _error(message: str) -> None:
    print(f'{PROG}: error: {_one_line(message)}', file=sys.stderr, flush=True)


def _warn(message: str) -> None:
    print(f'{PROG}: warning: {_one_line(message)}', file=sys.stderr, flush=True)


# ------------------------------------------------------- argument types
def _finite_float(text: str) -> float:
    text = text.strip()  # see _protect_negative_numbers
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'not a finite number: {text!r}')
    return value


def _is_negative_number(token: str) -> bool:
    """Whether ``token`` is a negative number in any notation Python reads (``-1e1``, ``-.5``)."""
    if not token.startswith('-') or token.startswith('--'):
        return False
    try:
        float(token)
    except ValueError:
        return False
    return True


def _protect_negative_numbers(argv):
    """Mark negative numbers as values, not options.

    argparse takes only ``-1`` and ``-1.5`` for negative numbers and reads
    ``-1e1`` or ``-1e-3`` as an unknown option.  A leading space makes
    argparse treat a token as a value; ``float()`` and ``int()`` ignore it.
    """
    return [' ' + a if _is_negative_number(a) else a for a in argv]


def _payload(text: str) -> float:
    value = _finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(
            f'payload must be a non-negative mass in kg, got {text!r}')
    return value


def _elements(text: str) -> int:
    text = text.strip()
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
    if value < 1:
        raise argparse.ArgumentTypeError(f'the element count must be >= 1, got {value}')
    return value


# ----------------------------------------------------------------- JSON
def json_safe(obj):
    """Copy of ``obj`` that ``json.dumps(..., allow_nan=False)`` accepts (NaN/inf -> None)."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        value = float(obj)
        return value if math.isfinite(value) else None
    return obj


def _emit_json(record: dict) -> None:
    print(json.dumps(json_safe(record), allow_nan=False), flush=True)


# ------------------------------------------------------------ the model
def _load_model(args) -> RobotModel:
    try:
        cfg = load_robot(args.config)
    except ConfigError as exc:
        raise UsageError(f'--config: {exc}') from None
    try:
        return RobotModel(cfg, args.elements)
    except ValueError as exc:
        raise UsageError(f'--elements: {exc}') from None


def _check_pressures_kpa(model: RobotModel, values_kpa) -> np.ndarray:
    """Pressures in kPa -> Pa, checked for count and hardware limits."""
    p = np.asarray(values_kpa, dtype=float)
    cfg = model.cfg
    if p.size != model.A:
        raise UsageError(f'expected {model.A} pressures in kPa (one per actuator of the '
                         f'{cfg.n_segments}-segment robot), got {p.size}')
    if not np.all(np.isfinite(p)):
        raise UsageError('pressures must be finite numbers')
    lo, hi = cfg.p_min / 1e3, cfg.p_max / 1e3
    for i, value in enumerate(p):
        if not lo <= value <= hi:
            raise UsageError(f'pressure {i + 1} = {value:g} kPa is outside the limits '
                             f'[{lo:g}, {hi:g}] kPa')
    return p * 1e3


def _solve(func, *args, **kwargs):
    """Call a core solver; its ValueError means bad input, anything else is a solver failure."""
    try:
        return func(*args, **kwargs)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    except Exception as exc:  # noqa: BLE001 - report, do not dump a traceback on the user
        raise SolverError(f'solver failed: {type(exc).__name__}: {exc}') from exc


# ------------------------------------------------------ human summaries
def _vec(values, fmt='{:9.3f}') -> str:
    if values is None:
        return '(none)'
    texts = []
    for v in values:
        text = fmt.format(v)
        if _is_number(text) and float(text) == 0:
            text = text.replace('-', ' ')  # no "-0.000"
        texts.append(text)
    return ' '.join(texts)


def _yes_no(value) -> str:
    return 'unknown' if value is None else ('yes' if value else 'no')


def _robot_line(model: RobotModel) -> str:
    cfg = model.cfg
    return (f'robot          {cfg.name}: {cfg.n_segments} segment(s), {model.A} actuators, '
            f'{model.n} elements per actuator, '
            f'limits [{cfg.p_min / 1e3:g}, {cfg.p_max / 1e3:g}] kPa')


def _forward_summary(model: RobotModel, d: dict, seconds: float) -> list[str]:
    pos = d.get('position_m')
    lines = [
        _robot_line(model),
        'payload        ' + ('n/a' if d.get('payload_kg') is None else f"{d['payload_kg']:g} kg"),
        f"pressures      {_vec(np.asarray(d['pressures_pa']) / 1e3)}  kPa",
        f"stretch        {_vec(d['stretch'], '{:9.5f}')}",
        f"tip position   {_vec(None if pos is None else np.asarray(pos) * 1e3)}  mm (x y z)",
        f"tip z-axis     {_vec(d.get('z_axis'), '{:9.5f}')}",
        f"converged      {_yes_no(d.get('converged'))}, stable {_yes_no(d.get('stable'))}, "
        f"{d.get('iterations')} iterations, {seconds:.3f} s",
        f"status         {d.get('status')}: {d.get('message')}",
    ]
    return lines


def _active_limits_text(model: RobotModel, active) -> str:
    cfg = model.cfg
    parts = [f'actuator {i + 1} at {"p_max" if a > 0 else "p_min"} '
             f'({(cfg.p_max if a > 0 else cfg.p_min) / 1e3:g} kPa)'
             for i, a in enumerate(active) if a]
    return ', '.join(parts) if parts else 'none'


def _inverse_summary(model: RobotModel, d: dict, seconds: float) -> list[str]:
    lines = _forward_summary(model, d, seconds)
    target = np.asarray(d['target_position_m']) * 1e3
    pos_err = d.get('position_error_m')
    ang_err = d.get('angle_error_rad')
    extra = [f"target         {_vec(target)}  mm (x y z)"]
    if d.get('target_z_axis') is not None:
        extra.append(f"target z-axis  {_vec(d['target_z_axis'], '{:9.5f}')}")
    extra += [
        f"reachable      {_yes_no(d.get('reachable'))} (success {_yes_no(d.get('success'))})",
        'position error ' + ('n/a' if pos_err is None or not math.isfinite(pos_err)
                             else f'{pos_err * 1e3:.3g} mm'),
    ]
    if d.get('target_z_axis') is not None:
        extra.append('angle error    ' + ('n/a' if ang_err is None or not math.isfinite(ang_err)
                                          else f'{math.degrees(ang_err):.3g} deg'))
    extra.append(f"active limits  {_active_limits_text(model, d.get('active_limits', []))}")
    return lines[:1] + extra + lines[1:]


def _print_lines(lines) -> None:
    print('\n'.join(lines), flush=True)


# ---------------------------------------------------------- CSV batches
class _CsvRows:
    """A CSV file with a header row: ``header`` and an iterator of ``(line, cells)``."""

    def __init__(self, path: str, option: str):
        self.path = path
        self.option = option
        self.label = '<stdin>' if path == '-' else path
        if path == '-':
            self._stream = sys.stdin
        else:
            try:
                # undecodable bytes become U+FFFD: that row is then reported as not numeric
                self._stream = open(path, newline='', encoding='utf-8-sig', errors='replace')
            except OSError as exc:
                raise UsageError(f'{option} {path}: cannot open file: '
                                 f'{exc.strerror or exc}') from None
        self._reader = csv.reader(self._stream)
        try:
            header = next(self._reader, None)
        except (csv.Error, UnicodeDecodeError) as exc:
            self.close()
            raise UsageError(f'{option} {self.label}, line 1: {exc}') from None
        if header is None or not any(cell.strip() for cell in header):
            self.close()
            raise UsageError(f'{option} {self.label}: no header row (the file is empty)')
        self.header = [cell.strip() for cell in header]
        if all(_is_number(cell) for cell in self.header):
            self.close()
            raise UsageError(f'{option} {self.label}, line 1: the first line must be a header '
                             f'row, got numbers only')

    def close(self):
        if self._stream is not sys.stdin:
            self._stream.close()

    def __iter__(self):
        """Yield ``(line, cells)``; a row the csv module cannot parse yields ``(line, exc)``."""
        while True:
            try:
                row = next(self._reader)
            except StopIteration:
                return
            except csv.Error as exc:
                yield self._reader.line_num, exc
                continue
            except UnicodeDecodeError as exc:  # stdin only; the stream cannot go on
                yield self._reader.line_num + 1, exc
                return
            if not any(cell.strip() for cell in row):
                continue  # blank line
            yield self._reader.line_num, [cell.strip() for cell in row]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _row_numbers(cells, names) -> list[float]:
    values = []
    for name, cell in zip(names, cells):
        try:
            value = float(cell)
        except ValueError:
            raise UsageError(f'column {name}: not a number: {cell!r}') from None
        if not math.isfinite(value):
            raise UsageError(f'column {name}: not a finite number: {cell!r}')
        values.append(value)
    return values


def _run_batch(rows: _CsvRows, parse_row, solve_row, to_dict) -> int:
    """Solve every row, warm-starting from the previous converged result; JSON Lines out.

    ``parse_row(cells) -> job`` and ``solve_row(job, previous) -> result`` raise
    :class:`UsageError` for a bad row; ``to_dict(result)`` gives the JSON record.
    """
    bad = failed = 0
    previous = None
    try:
        for line, cells in rows:
            where = f'{rows.option} {rows.label}, line {line}'
            try:
                if isinstance(cells, Exception):
                    raise UsageError(f'malformed CSV: {cells}')
                job = parse_row(cells)
                result = solve_row(job, previous)
            except UsageError as exc:
                _error(f'{where}: {exc}')
                bad += 1
                continue
            except SolverError as exc:
                _error(f'{where}: {exc}')
                failed += 1
                continue
            if result.converged:
                previous = result
            record = to_dict(result)
            record['line'] = line
            _emit_json(record)
    finally:
        rows.close()
    if bad:
        return EXIT_USAGE
    return EXIT_FAILED if failed else EXIT_OK


def _require_json(args, option: str) -> None:
    if not args.json:
        raise UsageError(f'{option} writes JSON Lines: add --json')


# ------------------------------------------------------------- forward
def _cmd_forward(args) -> int:
    model = _load_model(args)
    if args.pressures_csv is not None:
        return _forward_batch(args, model)
    pressures = _check_pressures_kpa(model, args.pressures_kpa)
    start = time.perf_counter()
    fw = _solve(solve_forward, model, pressures, payload_kg=args.payload_kg)
    seconds = time.perf_counter() - start
    d = fw.to_dict()
    if args.json:
        _emit_json(d)
    else:
        _print_lines(_forward_summary(model, d, seconds))
    return EXIT_OK if fw.converged else EXIT_FAILED


def _forward_batch(args, model: RobotModel) -> int:
    _require_json(args, '--pressures-csv')
    rows = _CsvRows(args.pressures_csv, '--pressures-csv')
    if len(rows.header) != model.A:
        rows.close()
        raise UsageError(f'--pressures-csv {rows.label}, line 1: the header has '
                         f'{len(rows.header)} columns, expected {model.A} '
                         '(one pressure in kPa per actuator)')
    names = rows.header

    def parse_row(cells):
        if len(cells) != model.A:
            raise UsageError(f'expected {model.A} pressures in kPa, got {len(cells)} fields')
        return _check_pressures_kpa(model, _row_numbers(cells, names))

    def solve_row(pressures, previous):
        return _solve(solve_forward, model, pressures, payload_kg=args.payload_kg,
                      warm_start=previous)

    return _run_batch(rows, parse_row, solve_row, lambda fw: fw.to_dict())


# ------------------------------------------------------------- inverse
def _target_axis(model: RobotModel, z_axis, source: str):
    """The z-axis argument for the core: required for >= 2 segments, dropped for one."""
    if model.cfg.n_segments >= 2:
        if z_axis is None:
            raise UsageError(f'the {model.cfg.n_segments}-segment robot needs a target z-axis '
                             f'({source})')
        return z_axis
    return None


def _cmd_inverse(args) -> int:
    model = _load_model(args)
    if args.targets_csv is not None:
        return _inverse_batch(args, model)
    z_axis = _target_axis(model, args.z_axis, 'add --z-axis ZX ZY ZZ')
    if args.z_axis is not None and z_axis is None:
        _warn('--z-axis is ignored for a one-segment robot (its tip has 3 DOF: position only)')
    start = time.perf_counter()
    inv = _solve(solve_inverse, model, args.position, z_axis=z_axis, payload_kg=args.payload_kg)
    seconds = time.perf_counter() - start
    d = _inverse_dict(inv)
    if args.json:
        _emit_json(d)
    else:
        _print_lines(_inverse_summary(model, d, seconds))
    return EXIT_OK if inv.converged else EXIT_FAILED


def _inverse_dict(inv) -> dict:
    d = inv.to_dict()
    d.setdefault('payload_kg', None)  # absent when the forward solve failed
    return d


def _inverse_batch(args, model: RobotModel) -> int:
    _require_json(args, '--targets-csv')
    if args.z_axis is not None:
        raise UsageError('--targets-csv takes the target z-axes from the file '
                         '(columns zx, zy, zz): drop --z-axis')
    rows = _CsvRows(args.targets_csv, '--targets-csv')
    header = [name.lower() for name in rows.header]
    multi = model.cfg.n_segments >= 2
    known = INVERSE_POSITION_COLUMNS + INVERSE_AXIS_COLUMNS
    problems = []
    unknown = [name for name in header if name not in known]
    if unknown:
        problems.append('unknown column(s) ' + ', '.join(repr(n) for n in unknown))
    duplicated = sorted({name for name in header if header.count(name) > 1})
    if duplicated:
        problems.append('duplicated column(s) ' + ', '.join(duplicated))
    wanted = INVERSE_POSITION_COLUMNS + (INVERSE_AXIS_COLUMNS if multi else ())
    missing = [name for name in wanted if name not in header]
    if missing:
        note = ''
        if multi and set(missing) & set(INVERSE_AXIS_COLUMNS):
            note = ' (a robot with two or more segments needs the target z-axis zx, zy, zz)'
        problems.append('missing column(s) ' + ', '.join(missing) + note)
    if problems:
        rows.close()
        raise UsageError(f'--targets-csv {rows.label}, line 1: ' + '; '.join(problems)
                         + f'; expected header {",".join(wanted)}')
    pos_idx = [header.index(name) for name in INVERSE_POSITION_COLUMNS]
    axis_idx = [header.index(name) for name in INVERSE_AXIS_COLUMNS] if multi else None

    def parse_row(cells):
        if len(cells) != len(header):
            raise UsageError(f'expected {len(header)} fields ({",".join(rows.header)}), '
                             f'got {len(cells)}')
        position = _row_numbers([cells[i] for i in pos_idx], INVERSE_POSITION_COLUMNS)
        z_axis = None
        if axis_idx is not None:
            z_axis = _row_numbers([cells[i] for i in axis_idx], INVERSE_AXIS_COLUMNS)
        return position, z_axis

    def solve_row(job, previous):
        position, z_axis = job
        return _solve(solve_inverse, model, position, z_axis=z_axis, payload_kg=args.payload_kg,
                      warm_start=previous)

    return _run_batch(rows, parse_row, solve_row, _inverse_dict)


# -------------------------------------------------------------- parser
def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument('--config', default='one_segment', metavar='C',
                   help="robot file path or shipped robot name (one_segment, two_segment); "
                        "default: %(default)s")
    p.add_argument('--payload-kg', type=_payload, default=0.0, metavar='M',
                   help='payload at the end effector [kg]; default: %(default)s')
    p.add_argument('--elements', type=_elements, default=None, metavar='N',
                   help="ANCF elements per actuator; default: the robot file's value")
    p.add_argument('--json', action='store_true',
                   help='print JSON (one object per line) instead of a readable summary')


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``bellow-ancf`` (including subcommands from ``cli_tools``)."""
    parser = _Parser(
        prog=PROG,
        description='Kinetostatic ANCF model of bellow-shaped soft continuum robots: '
                    'forward (pressures -> pose) and inverse (pose -> pressures) problems.',
        epilog='Exit status: 0 success, 1 a solve did not converge, 2 bad input.',
    )
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)

    fwd = subparsers.add_parser(
        'forward', help='pose of the robot for given pressures',
        description='Forward problem: actuator pressures (kPa, segment by segment, actuator 1 '
                    'first) -> end-effector pose.  With --pressures-csv, one solve per CSV row '
                    '(header row; one column per actuator in kPa), warm-started along the rows, '
                    'printed as JSON Lines.',
    )
    _add_common(fwd)
    src = fwd.add_mutually_exclusive_group(required=True)
    src.add_argument('--pressures-kpa', type=_finite_float, nargs='+', metavar='P',
                     help='one gauge pressure per actuator [kPa]')
    src.add_argument('--pressures-csv', metavar='FILE',
                     help="CSV file of actuations ('-' for stdin); requires --json")
    fwd.set_defaults(func=_cmd_forward)

    inv = subparsers.add_parser(
        'inverse', help='pressures for a target pose',
        description='Inverse problem: target end-effector position (m, base frame) and, for two '
                    'or more segments, target z-axis -> pressures within the hardware limits.  '
                    'With --targets-csv, one solve per CSV row (header row; columns x,y,z and, '
                    'for two or more segments, zx,zy,zz), warm-started along the rows, printed '
                    'as JSON Lines.',
    )
    _add_common(inv)
    tgt = inv.add_mutually_exclusive_group(required=True)
    tgt.add_argument('--position', type=_finite_float, nargs=3, metavar=('X', 'Y', 'Z'),
                     help='target end-effector position [m]')
    tgt.add_argument('--targets-csv', metavar='FILE',
                     help="CSV file of targets ('-' for stdin); requires --json")
    inv.add_argument('--z-axis', type=_finite_float, nargs=3, metavar=('ZX', 'ZY', 'ZZ'),
                     help='target end-effector z-axis (required for two or more segments)')
    inv.set_defaults(func=_cmd_inverse)

    try:
        tools = importlib.import_module(TOOLS_MODULE)
    except ModuleNotFoundError as exc:
        if exc.name != TOOLS_MODULE:
            raise  # cli_tools exists but one of its own imports is missing
    else:
        tools.register(subparsers)
    importlib.import_module('bellow_ancf_ros.cli_calibrate').register(subparsers)
    return parser


def main(argv=None) -> int:
    """Run ``bellow-ancf`` with ``argv`` (default ``sys.argv[1:]``); return the exit status."""
    try:
        return _main(argv)
    except BrokenPipeError:
        # the reader went away (e.g. `| head -1`): stop quietly
        _discard_stdout()
        return EXIT_FAILED
    except KeyboardInterrupt:
        return 130


def _main(argv) -> int:
    parser = build_parser()
    argv = _protect_negative_numbers(sys.argv[1:] if argv is None else list(argv))
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:
        _error(str(exc))
        return EXIT_USAGE
    except SystemExit as exc:  # --help / --version
        return exc.code if isinstance(exc.code, int) else EXIT_OK
    try:
        return int(args.func(args))
    except UsageError as exc:
        _error(str(exc))
        return EXIT_USAGE
    except SolverError as exc:
        _error(str(exc))
        return EXIT_FAILED


def _discard_stdout() -> None:
    """Point stdout at the null device, so that the flush at exit cannot fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # no real file descriptor (captured stdout)
        pass


if __name__ == '__main__':
    sys.exit(main())
