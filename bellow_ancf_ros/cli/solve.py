"""``bellow-ancf forward`` and ``bellow-ancf inverse``: the model's two problems.

::

    bellow-ancf forward [--config C] --pressures-kpa P1 P2 ... [--payload-kg M]
                        [--tip-force-n FX FY FZ] [--elements N] [--json]
    bellow-ancf forward [--config C] --pressures-csv FILE [--payload-kg M]
                        [--tip-force-n FX FY FZ] [--elements N] --json
    bellow-ancf inverse [--config C] --position X Y Z [--z-axis ZX ZY ZZ]
                        [--payload-kg M] [--tip-force-n FX FY FZ] [--elements N] [--json]
    bellow-ancf inverse [--config C] --targets-csv FILE [--payload-kg M]
                        [--tip-force-n FX FY FZ] [--elements N] --json

A readable summary, or with ``--json`` the keys of ``ForwardResult.to_dict()``
/ ``InverseResult.to_dict()`` (SI units); the CSV batch modes are in
:mod:`bellow_ancf_ros.cli.batch`.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from ..core import RobotModel, solve_forward, solve_inverse
from .batch import CsvRows, require_json, row_numbers, run_batch
from .common import (EXIT_FAILED, EXIT_OK, UsageError, add_loads, call_solver, config_help,
                     element_count, emit_json, finite_float, load_model, print_lines, warn)
from .output import count, number

INVERSE_POSITION_COLUMNS = ('x', 'y', 'z')
INVERSE_AXIS_COLUMNS = ('zx', 'zy', 'zz')


# ------------------------------------------------------------- input
def check_pressures_kpa(model: RobotModel, values_kpa) -> np.ndarray:
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


# --------------------------------------------------- human summaries
def _vec(values, spec='9.3f') -> str:
    if values is None:
        return '(none)'
    return ' '.join(number(v, spec) for v in values)


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
        'tip force      ' + ('none' if not any(d.get('tip_force_n') or ())
                             else f"{_vec(d['tip_force_n'], 'g')}  N (x y z, base frame)"),
        f"pressures      {_vec(np.asarray(d['pressures_pa']) / 1e3)}  kPa",
        f"stretch        {_vec(d['stretch'], '9.5f')}",
        f"tip position   {_vec(None if pos is None else np.asarray(pos) * 1e3)}  mm (x y z)",
        f"tip z-axis     {_vec(d.get('z_axis'), '9.5f')}",
        f"converged      {_yes_no(d.get('converged'))}, stable {_yes_no(d.get('stable'))}, "
        f"{count(d.get('iterations'), 'iteration')}, {seconds:.3f} s",
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
        extra.append(f"target z-axis  {_vec(d['target_z_axis'], '9.5f')}")
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


# ----------------------------------------------------------- forward
def _cmd_forward(args) -> int:
    model = load_model(args)
    if args.pressures_csv is not None:
        return _forward_batch(args, model)
    pressures = check_pressures_kpa(model, args.pressures_kpa)
    start = time.perf_counter()
    fw = call_solver(solve_forward, model, pressures, payload_kg=args.payload_kg,
                     tip_force_n=args.tip_force_n)
    seconds = time.perf_counter() - start
    d = fw.to_dict()
    if args.json:
        emit_json(d)
    else:
        print_lines(_forward_summary(model, d, seconds))
    return EXIT_OK if _forward_reached(fw) else EXIT_FAILED


def _forward_reached(fw) -> bool:
    """What ``forward`` was asked for: a converged equilibrium (exit status 0)."""
    return bool(fw.converged)


def _inverse_reached(inv) -> bool:
    """What ``inverse`` was asked for: pressures that reach the target, stably (exit status 0)."""
    return bool(inv.success and inv.reachable)


def _forward_batch(args, model: RobotModel) -> int:
    require_json(args, '--pressures-csv')
    rows = CsvRows(args.pressures_csv, '--pressures-csv')
    if len(rows.header) != model.A:
        rows.close()
        raise UsageError(f'--pressures-csv {rows.label}, line 1: the header has '
                         f'{len(rows.header)} columns, expected {model.A} '
                         '(one pressure in kPa per actuator)')
    names = rows.header

    def parse_row(cells):
        if len(cells) != model.A:
            raise UsageError(f'expected {model.A} pressures in kPa, got {len(cells)} fields')
        return check_pressures_kpa(model, row_numbers(cells, names))

    def solve_row(pressures, previous):
        return call_solver(solve_forward, model, pressures, payload_kg=args.payload_kg,
                           warm_start=previous, tip_force_n=args.tip_force_n)

    return run_batch(rows, parse_row, solve_row, lambda fw: fw.to_dict(), _forward_reached)


# ----------------------------------------------------------- inverse
def _target_axis(model: RobotModel, z_axis, source: str):
    """The z-axis argument for the core: required for >= 2 segments, dropped for one."""
    if model.cfg.n_segments >= 2:
        if z_axis is None:
            raise UsageError(f'the {model.cfg.n_segments}-segment robot needs a target z-axis '
                             f'({source})')
        return z_axis
    return None


def _cmd_inverse(args) -> int:
    model = load_model(args)
    if args.targets_csv is not None:
        return _inverse_batch(args, model)
    z_axis = _target_axis(model, args.z_axis, 'add --z-axis ZX ZY ZZ')
    if args.z_axis is not None and z_axis is None:
        warn('--z-axis is ignored for a one-segment robot (its tip has 3 DOF: position only)')
    start = time.perf_counter()
    inv = call_solver(solve_inverse, model, args.position, z_axis=z_axis,
                      payload_kg=args.payload_kg, tip_force_n=args.tip_force_n)
    seconds = time.perf_counter() - start
    d = _inverse_dict(inv)
    if args.json:
        emit_json(d)
    else:
        print_lines(_inverse_summary(model, d, seconds))
    return EXIT_OK if _inverse_reached(inv) else EXIT_FAILED


def _inverse_dict(inv) -> dict:
    d = inv.to_dict()
    d.setdefault('payload_kg', None)  # absent when the forward solve failed
    d.setdefault('tip_force_n', None)
    return d


def _inverse_batch(args, model: RobotModel) -> int:
    require_json(args, '--targets-csv')
    if args.z_axis is not None:
        raise UsageError('--targets-csv takes the target z-axes from the file '
                         '(columns zx, zy, zz): drop --z-axis')
    rows = CsvRows(args.targets_csv, '--targets-csv')
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
        position = row_numbers([cells[i] for i in pos_idx], INVERSE_POSITION_COLUMNS)
        z_axis = None
        if axis_idx is not None:
            z_axis = row_numbers([cells[i] for i in axis_idx], INVERSE_AXIS_COLUMNS)
        return position, z_axis

    def solve_row(job, previous):
        position, z_axis = job
        return call_solver(solve_inverse, model, position, z_axis=z_axis,
                           payload_kg=args.payload_kg, warm_start=previous,
                           tip_force_n=args.tip_force_n)

    return run_batch(rows, parse_row, solve_row, _inverse_dict, _inverse_reached)


# ------------------------------------------------------------ parser
def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument('--config', default='one_segment', metavar='C',
                   help=config_help() + '; default: %(default)s')
    add_loads(p)
    p.add_argument('--elements', type=element_count, default=None, metavar='N',
                   help="ANCF elements per actuator; default: the robot file's value")
    p.add_argument('--json', action='store_true',
                   help='print JSON (one object per line) instead of a readable summary')


def register(subparsers) -> None:
    """Add ``forward`` and ``inverse``."""
    fwd = subparsers.add_parser(
        'forward', help='pose of the robot for given pressures',
        description='Forward problem: actuator pressures (kPa, segment by segment, actuator 1 '
                    'first) -> end-effector pose.  With --pressures-csv, one solve per CSV row '
                    '(header row; one column per actuator in kPa), warm-started along the rows, '
                    'printed as JSON Lines.',
    )
    _add_common(fwd)
    src = fwd.add_mutually_exclusive_group(required=True)
    src.add_argument('--pressures-kpa', type=finite_float, nargs='+', metavar='P',
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
                    'as JSON Lines.  Exit status 1 when a target is not reached (the best '
                    'in-limit pressures are still printed, reachable false).',
    )
    _add_common(inv)
    tgt = inv.add_mutually_exclusive_group(required=True)
    tgt.add_argument('--position', type=finite_float, nargs=3, metavar=('X', 'Y', 'Z'),
                     help='target end-effector position [m]')
    tgt.add_argument('--targets-csv', metavar='FILE',
                     help="CSV file of targets ('-' for stdin); requires --json")
    inv.add_argument('--z-axis', type=finite_float, nargs=3, metavar=('ZX', 'ZY', 'ZZ'),
                     help='target end-effector z-axis (required for two or more segments)')
    inv.set_defaults(func=_cmd_inverse)
