"""CSV batch mode of ``bellow-ancf forward`` / ``inverse``: rows in, JSON Lines out.

A CSV file (``-`` reads stdin) with a header row; the rows are solved in
order, each warm-started from the previous converged solution, one JSON line
per row with its 1-based ``line``.  A bad row is reported on stderr with its
line number and skipped; the exit status is 2 at the end if any row was bad.
"""

from __future__ import annotations

import csv
import math
import sys

from .common import (EXIT_FAILED, EXIT_OK, EXIT_USAGE, SolverError, UsageError, emit_json,
                     error, is_number)


class CsvRows:
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
        if all(is_number(cell) for cell in self.header):
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


def row_numbers(cells, names) -> list[float]:
    """The cells as finite floats; a bad cell is a :class:`UsageError` naming its column."""
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


def run_batch(rows: CsvRows, parse_row, solve_row, to_dict, reached) -> int:
    """Solve every row, warm-starting from the previous converged result; JSON Lines out.

    ``parse_row(cells) -> job`` and ``solve_row(job, previous) -> result`` raise
    :class:`UsageError` for a bad row; ``to_dict(result)`` gives the JSON record;
    ``reached(result)``: whether the row got what was asked for (else exit status 1
    at the end, :data:`~bellow_ancf_ros.cli.common.EXIT_FAILED`; a bad row: 2).
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
                error(f'{where}: {exc}')
                bad += 1
                continue
            except SolverError as exc:
                error(f'{where}: {exc}')
                failed += 1
                continue
            if result.converged:
                previous = result
            if not reached(result):
                failed += 1
            record = to_dict(result)
            record['line'] = line
            emit_json(record)
    finally:
        rows.close()
    if bad:
        return EXIT_USAGE
    return EXIT_FAILED if failed else EXIT_OK


def require_json(args, option: str) -> None:
    """Refuse a batch mode without ``--json``."""
    if not args.json:
        raise UsageError(f'{option} writes JSON Lines: add --json')
