"""Tables of numbers written as YAML flow lists, one row per line and aligned as numpy prints
them, so that a program with large tables stays readable and loads fast (the loader reads such
a table as one array: see ``bayesprog.language.loader``).

>>> print("table: " + flow_table([[0.1, 0.9], [0.25, 0.75]], column=7))
table: [[0.1, 0.9],
        [0.25, 0.75]]
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: the widest line a row is written on before it goes on under its first number
WIDTH = 100


def flow_table(values: Any, column: int, width: int = WIDTH) -> str:
    """``values`` (numbers in nested lists, or an array) as a flow list whose ``[`` stands at
    ``column`` (0-based) of its first line: each innermost row on its own line, a long row
    wrapped under its first number; numbers as Python writes them (the shortest text that reads
    back to the same float)."""
    array = np.asarray(values, dtype=float)
    if array.ndim == 0:
        return repr(float(array))
    # a row's last line also takes the brackets that close the levels above it, and a comma
    return _flow(array.tolist(), array.ndim, column, width - array.ndim)


def _flow(rows: list, ndim: int, column: int, width: int) -> str:
    if ndim == 1:
        return _row(list(map(repr, rows)), column, width)
    inner = ",\n".join(
        (" " * (column + 1) if i else "") + _flow(row, ndim - 1, column + 1, width)
        for i, row in enumerate(rows))
    return f"[{inner}]"


def _row(numbers: list[str], column: int, width: int) -> str:
    one = "[" + ", ".join(numbers) + "]"
    if column + len(one) <= width:  # most rows: one line
        return one
    lines: list[str] = []
    line = "["
    for i, text in enumerate(numbers):
        piece = text + ("," if i < len(numbers) - 1 else "")
        if len(line) > 1 and column + len(line) + 1 + len(piece) > width:
            lines.append(line)
            line = " " * (column + 1) + piece
        else:
            line += (" " if len(line) > 1 and not line.endswith("[") else "") + piece
    return "\n".join(lines + [line + "]"])
