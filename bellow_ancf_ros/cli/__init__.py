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
* Exit status, one rule for every subcommand: 0 every result asked for was
  reached; 1 a result asked for was not reached, the result still printed
  (``forward``: no converged equilibrium; ``inverse``: the target not reached,
  stably: ``reachable``/``success`` false, the best in-limit pressures
  printed; a batch: any such row; ``track``: any point; ``workspace``: any
  point without a stable equilibrium; ``identify da``: no root; a robot file
  refused) or the solver failed internally; 2 bad input, reported as one
  line ``bellow-ancf: error: ...`` on stderr (in batch mode: 2 at the end if
  any row was bad; the good rows are still answered).  Findings of a study
  (``compare-pcc``'s unusable points, ``stiffness``'s buckling payloads) are
  results, exit 0.
* One module per command family, each adding its subcommands through its
  ``register(subparsers)`` (:data:`COMMAND_FAMILIES`, in help order):
  :mod:`.solve` (``forward``, ``inverse``), :mod:`.loads` (``compliance``,
  ``stiffness``), :mod:`.dynamics` (``modes``, ``simulate``; also ``identify
  damping``), :mod:`.creep` (``identify creep``), :mod:`.play` (``identify
  play``), :mod:`.identify` (``identify stiffness|deff|da|damping|creep|play``),
  :mod:`.studies` (``convergence``, ``workspace``,
  ``compare-pcc``), :mod:`.track` (``track``), :mod:`.calibrate`
  (``calibrate``), :mod:`.record` (``record``), :mod:`.warmup` (``warm-up``);
  shared helpers in
  :mod:`.common`, :mod:`.output` and
  :mod:`.batch`.  Every subcommand's parser sets ``func``
  (``set_defaults(func=...)``), a callable taking the parsed arguments and
  returning the exit status.

This module does not import ROS.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from .common import (EXIT_FAILED, EXIT_OK, EXIT_USAGE, PROG, Parser, SolverError, UsageError,
                     error, json_safe, protect_negative_numbers)

__all__ = ['main', 'build_parser', 'UsageError', 'json_safe']

#: Modules of this package that add subcommands, in the order of ``--help``.
COMMAND_FAMILIES = ('solve', 'loads', 'dynamics', 'identify', 'studies', 'track', 'calibrate',
                    'record', 'warmup')


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``bellow-ancf`` (every family's subcommands)."""
    parser = Parser(
        prog=PROG,
        description='Kinetostatic ANCF model of bellow-shaped soft continuum robots: '
                    'forward (pressures -> pose) and inverse (pose -> pressures) problems.',
        epilog='Exit status: 0 every result asked for was reached; 1 a result asked for was '
               'not reached (a solve that did not converge, an inverse target not reached; '
               'the result is still printed); 2 bad input.',
    )
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for family in COMMAND_FAMILIES:
        importlib.import_module(f'{__name__}.{family}').register(subparsers)
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
    argv = protect_negative_numbers(sys.argv[1:] if argv is None else list(argv))
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:
        error(str(exc))
        return EXIT_USAGE
    except SystemExit as exc:  # --help / --version
        return exc.code if isinstance(exc.code, int) else EXIT_OK
    try:
        return int(args.func(args))
    except UsageError as exc:
        error(str(exc))
        return EXIT_USAGE
    except SolverError as exc:
        error(str(exc))
        return EXIT_FAILED


def _discard_stdout() -> None:
    """Point stdout at the null device, so that the flush at exit cannot fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # no real file descriptor (captured stdout)
        pass
