"""A CSV file read row by row by the csv module: quotes, blank lines (a row of missing values)
and the rows that cannot be split as the header is, each named by its line (1-based, the
header line 1, as an editor shows it) and why: a line of more or fewer fields than the header,
bytes that are not UTF-8 text, a line the csv module refuses. Such a row is kept as a row of
missing values, so that the file's rows keep their numbers; what to do with it (refuse it, or
set it aside) is the caller's choice (:mod:`.data`).

:mod:`.plain_csv` reads a plain file (no quotes, a row per line, every line as long as the
header) faster; any other file is read here.

>>> rows = read_csv_rows(b"A,B\\nyes,1\\nno,2,7\\n\\nyes,\\n", ",")
>>> rows.header, rows.rows
(['A', 'B'], [['yes', '1'], [None, None], [None, None], ['yes', None]])
>>> [str(bad) for bad in rows.bad]
['line 3: 3 fields, expected 2']
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass
from typing import NamedTuple

#: what bytes that are not UTF-8 become in the decoded text (errors="surrogateescape"): no
#: valid UTF-8 text decodes to them, so a row holding one held such bytes
_UNDECODED = re.compile("[\udc80-\udcff]")


class BadRow(NamedTuple):
    """A row that cannot be read for a program, set aside: its ``line`` in a CSV file (1-based,
    the header line 1; None in a Parquet file, a data frame or columns), ``why``, and its
    ``row`` (1-based, the header not counted)."""

    line: int | None
    why: str
    row: int

    def __str__(self) -> str:
        return (f"line {self.line}: {self.why}" if self.line is not None
                else f"row {self.row}: {self.why}")


class CsvProblem(Exception):
    """The file as a whole cannot be read as CSV (the message: why, without the file's name)."""


@dataclass
class CsvRows:
    """The header's names, each row's cells as written (None for an empty cell; every cell of
    a bad row None), each row's first line, and the bad rows."""

    header: list[str]
    rows: list[list[str | None]]
    lines: list[int]
    bad: list[BadRow]


def read_csv_rows(raw: bytes, sep: str) -> CsvRows:
    """``raw`` (a CSV file's bytes, ``sep`` its delimiter) split into rows by the csv module,
    the spaces after a delimiter skipped; raises :class:`CsvProblem` for an empty file or a
    header that cannot be read."""
    try:
        text, undecoded = raw.decode("utf-8-sig"), False
    except UnicodeDecodeError:  # the rows that hold such bytes are named below
        text, undecoded = raw.decode("utf-8-sig", errors="surrogateescape"), True
    reader = csv.reader(io.StringIO(text), delimiter=sep, skipinitialspace=True)
    try:
        header = next(reader)
    except StopIteration:
        raise CsvProblem("the file is empty") from None
    except csv.Error as exc:
        raise CsvProblem(f"line 1 (the header): {exc}") from None
    found = _UNDECODED.search(sep.join(header)) if undecoded else None
    if found:
        raise CsvProblem(f"line 1 (the header): {_not_utf8(found)}")
    header = [h.strip() for h in header]
    width = len(header)
    empty: list[str | None] = [None] * width
    rows: list[list[str | None]] = []
    lines: list[int] = []
    bad: list[BadRow] = []
    line = reader.line_num + 1  # where the next record starts

    def set_aside(why: str) -> None:
        bad.append(BadRow(line, why, len(rows) + 1))
        rows.append(empty)
        lines.append(line)

    while True:
        try:
            for fields in reader:
                found = _UNDECODED.search(sep.join(fields)) if undecoded else None
                if found:
                    set_aside(_not_utf8(found))
                elif len(fields) == width:  # only an empty cell is missing (not NA: a state)
                    rows.append([cell if cell.strip() else None for cell in fields])
                    lines.append(line)
                elif not fields:  # a blank line: a row of missing values
                    rows.append(empty)
                    lines.append(line)
                else:
                    n = len(fields)
                    set_aside(f"{n} field{'s' if n != 1 else ''}, expected {width}")
                line = reader.line_num + 1
            break
        except csv.Error as exc:  # the reader starts afresh at the next line
            set_aside(f"cannot be split into fields: {exc}")
            line = reader.line_num + 1
    return CsvRows(header, rows, lines, bad)


def _not_utf8(found: re.Match[str]) -> str:
    """Why a row holding bytes that are not UTF-8 (the first found) is bad."""
    return f"not UTF-8 text (byte 0x{ord(found.group()) - 0xDC00:02x})"
