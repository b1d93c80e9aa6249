"""Shared pieces of the ``bellow-ancf`` subcommands.

Exit statuses, the error classes and their one-line report on stderr,
argument types, JSON output and the calls into the core that turn its
exceptions into exit statuses (see the contract in :mod:`bellow_ancf_ros.cli`).
No ROS import.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

from ..core import ConfigError, RobotModel, load_robot
from ..core.model import shipped_robot_names

PROG = 'bellow-ancf'
EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2


# ------------------------------------------------------------ errors
class UsageError(Exception):
    """Bad input: reported as one line on stderr, exit status 2."""


class SolverError(Exception):
    """The solver raised unexpectedly (a bug, not bad input): exit status 1."""


class Parser(argparse.ArgumentParser):
    """Argument parser whose errors become :class:`UsageError` (one line, no usage dump)."""

    def error(self, message):
        raise UsageError(f"{message} (see '{self.prog} --help')")


def one_line(text) -> str:
    """Join the non-blank lines of ``text`` with ``; `` (reports are one line)."""
    return '; '.join(part.strip() for part in str(text).splitlines() if part.strip())


def error(message: str) -> None:
    """Report ``bellow-ancf: error: ...`` on stderr, on one line."""
    print(f'{PROG}: error: {one_line(message)}', file=sys.stderr, flush=True)


def warn(message: str) -> None:
    """Report ``bellow-ancf: warning: ...`` on stderr, on one line."""
    print(f'{PROG}: warning: {one_line(message)}', file=sys.stderr, flush=True)


# ---------------------------------------------------- argument types
def finite_float(text: str) -> float:
    """Argument type: a finite float."""
    text = text.strip()  # see protect_negative_numbers
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'not a finite number: {text!r}')
    return value


def is_negative_number(token: str) -> bool:
    """Whether ``token`` is a negative number in any notation Python reads (``-1e1``, ``-.5``)."""
    if not token.startswith('-') or token.startswith('--'):
        return False
    try:
        float(token)
    except ValueError:
        return False
    return True


def protect_negative_numbers(argv):
    """Mark negative numbers as values, not options.

    argparse takes only ``-1`` and ``-1.5`` for negative numbers and reads
    ``-1e1`` or ``-1e-3`` as an unknown option.  A leading space makes
    argparse treat a token as a value; ``float()`` and ``int()`` ignore it.
    """
    return [' ' + a if is_negative_number(a) else a for a in argv]


def payload_mass(text: str) -> float:
    """Argument type: a non-negative payload mass [kg]."""
    value = finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(
            f'payload must be a non-negative mass in kg, got {text!r}')
    return value


def element_count(text: str) -> int:
    """Argument type: an element count >= 1."""
    text = text.strip()
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
    if value < 1:
        raise argparse.ArgumentTypeError(f'the element count must be >= 1, got {value}')
    return value


def positive_float(text):
    """Argument type: a finite float > 0."""
    value = finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f'must be positive, got {text!r}')
    return value


def nonneg_float(text):
    """Argument type: a finite float >= 0."""
    value = finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f'must not be negative, got {text!r}')
    return value


def int_at_least(minimum):
    """Argument type: an integer >= ``minimum``."""
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f'must be >= {minimum}, got {value}')
        return value
    return parse


def fraction(text):
    """Argument type: a float strictly between 0 and 1."""
    value = finite_float(text)
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f'must lie strictly between 0 and 1, got {text!r}')
    return value


def is_number(text: str) -> bool:
    """Whether ``float(text)`` succeeds."""
    try:
        float(text)
    except ValueError:
        return False
    return True


# ---------------------------------------------------- common options
def config_help(what: str = 'robot file path or shipped robot name') -> str:
    """``--config`` help: ``what`` and the shipped robot names (from the config folders)."""
    return f"{what} ({', '.join(shipped_robot_names()) or 'none found'})"


def add_config(p):
    """Add ``--config`` (robot file path or shipped robot name)."""
    p.add_argument('--config', default='one_segment', metavar='C',
                   help=config_help() + '; default: %(default)s')


def add_loads(p):
    """Add ``--payload-kg M`` and ``--tip-force-n FX FY FZ`` (a single solve's loads)."""
    p.add_argument('--payload-kg', type=payload_mass, default=0.0, metavar='M',
                   help='payload at the end effector [kg]; default: %(default)s')
    p.add_argument('--tip-force-n', type=finite_float, nargs=3, default=None,
                   metavar=('FX', 'FY', 'FZ'),
                   help='force at the end effector [N, base frame], a dead load on top of the '
                        "payload's weight; default: none")


def add_out(p, json_help='print one JSON object (SI units) instead of the table'):
    """Add ``--plot`` and ``--json``."""
    p.add_argument('--plot', metavar='PNG', help='write a PNG plot to this file')
    p.add_argument('--json', action='store_true', help=json_help)


def add_quiet(p):
    """Add ``--quiet`` (no progress on stderr)."""
    p.add_argument('--quiet', action='store_true', help='no progress output on stderr')


# ------------------------------------------------------------ output
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


def emit_json(record: dict) -> None:
    """Print ``record`` as one line of strict JSON (see :func:`json_safe`)."""
    print(json.dumps(json_safe(record), allow_nan=False), flush=True)


def print_lines(lines) -> None:
    """Print ``lines`` to stdout."""
    print('\n'.join(lines), flush=True)


def progress(args, command):
    """A progress callback printing to stderr (nothing with --quiet)."""
    if getattr(args, 'quiet', False):
        return None
    start = time.perf_counter()

    def report(done, total, text):
        print(f'{PROG}: {command}: [{done}/{total}] {text} ({time.perf_counter() - start:.1f} s)',
              file=sys.stderr, flush=True)
    return report


# -------------------------------------------- the model and the core
def load_config(args):
    """The robot of ``--config``; a bad file is a :class:`UsageError`."""
    try:
        return load_robot(args.config)
    except ConfigError as exc:
        raise UsageError(f'--config: {exc}') from None


def make_model(cfg, elements=None):
    """The model of ``cfg``; a refused element count is a :class:`UsageError`."""
    try:
        return RobotModel(cfg, elements)
    except ValueError as exc:
        raise UsageError(f'--elements: {exc}') from None


def load_model(args) -> RobotModel:
    """The model of ``--config`` with ``--elements`` elements per actuator."""
    return make_model(load_config(args), args.elements)


def call_solver(func, *args, **kwargs):
    """Call a core solver; its ValueError means bad input, anything else is a solver failure."""
    try:
        return func(*args, **kwargs)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    except Exception as exc:  # noqa: BLE001 - report, do not dump a traceback on the user
        raise SolverError(f'solver failed: {type(exc).__name__}: {exc}') from exc


def run_study(func, *args, **kwargs):
    """Run a study; ValueError means bad input, RuntimeError a solver failure."""
    try:
        return func(*args, **kwargs)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    except RuntimeError as exc:
        raise SolverError(f'solver failed: {exc}') from exc
