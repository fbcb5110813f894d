"""Data sets for learning: one column per variable, one row per observation, missing values
allowed. Read from CSV or Parquet files, a pandas DataFrame or a mapping of columns, and checked
against a program's variables with the file, row and column of every bad value."""

from __future__ import annotations

import csv as csvlib
import hashlib
import io
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bayesprog.errors import ArgumentError, BayesprogError, short_repr
from bayesprog.variables import Continuous, Discrete, Variable


class DataError(BayesprogError):
    """A data set does not fit the program it is to teach (or cannot be read)."""


@dataclass
class Data:
    """Columns coded for learning: discrete values as state indices (-1 where missing),
    continuous values as floats (NaN where missing)."""

    source: str
    sha256: str
    rows: int
    discrete: dict[str, np.ndarray]
    continuous: dict[str, np.ndarray]
    csv: bool = False

    def where(self, row: int, column: str) -> str:
        """``FILE: row R (line L), column 'C'`` for 0-based data row ``row``."""
        line = f" (line {row + 2})" if self.csv else ""
        return f"{self.source}: row {row + 1}{line}, column {column!r}"

    def take(self, rows: np.ndarray) -> Data:
        return Data(self.source, self.sha256, int(len(rows)),
                    {k: v[rows] for k, v in self.discrete.items()},
                    {k: v[rows] for k, v in self.continuous.items()}, self.csv)


def read_frame(source: Any) -> tuple[Any, str, str, bool]:
    """(DataFrame of strings and numbers, source name, SHA-256, read from CSV?)."""
    import pandas as pd

    if isinstance(source, pd.DataFrame):
        hashed = pd.util.hash_pandas_object(source, index=False).to_numpy().tobytes()
        return source, "<data frame>", hashlib.sha256(hashed).hexdigest(), False
    if isinstance(source, Mapping):
        lengths = {str(k): len(v) for k, v in source.items()}
        if len(set(lengths.values())) > 1:
            raise DataError("columns of different lengths: " + ", ".join(
                f"{k} {n}" for k, n in lengths.items()) + "; expected one value per row in each")
        frame, _, hexdigest, _ = read_frame(pd.DataFrame({k: list(v) for k, v in source.items()}))
        return frame, "<columns>", hexdigest, False
    if not isinstance(source, (str, os.PathLike)):
        raise ArgumentError(f"data: expected a CSV or Parquet file, a pandas DataFrame or a "
                            f"mapping of columns, found {type(source).__name__} "
                            f"{short_repr(source)}")
    path = Path(source)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise DataError(f"cannot read data {path}: no such file") from None
    except IsADirectoryError:
        raise DataError(f"cannot read data {path}: it is a directory") from None
    hexdigest = hashlib.sha256(raw).hexdigest()
    suffix = path.suffix.lower()
    if suffix in (".parquet", ".pq"):
        from bayesprog.extras import require_extra

        require_extra("pyarrow", "parquet", f"reading {path}")
        try:
            frame = pd.read_parquet(path)
        except Exception as exc:  # pyarrow raises several types for a file that is not Parquet
            raise DataError(f"cannot read data {path} as Parquet: {exc}") from None
        return frame, str(path), hexdigest, False
    if suffix not in (".csv", ".txt", ".tsv"):
        raise DataError(f"cannot read data {path}: expected a .csv or .parquet file, found "
                        f"{suffix or 'no suffix'}")
    sep = "\t" if suffix == ".tsv" else ","
    try:
        lines = list(csvlib.reader(io.StringIO(raw.decode("utf-8-sig")), delimiter=sep,
                                   skipinitialspace=True))
    except (UnicodeDecodeError, csvlib.Error) as exc:
        raise DataError(f"cannot read data {path} as CSV: {exc}") from None
    if not lines:
        raise DataError(f"cannot read data {path} as CSV: the file is empty")
    header = [h.strip() for h in lines[0]]
    for line, fields in enumerate(lines[1:], start=2):
        if fields and len(fields) != len(header):
            raise DataError(f"{path}: row {line - 1} (line {line}) has {len(fields)} fields, "
                            f"the header {len(header)}: expected one value per column")
    # every cell as written: only an empty cell is missing (a state may be named NA or None);
    # a blank line is an empty row, so that row r is line r + 1
    rows = [[cell if cell.strip() else None for cell in fields] or [None] * len(header)
            for fields in lines[1:]]
    frame = pd.DataFrame(rows, columns=header, dtype=object)
    return frame, str(path), hexdigest, True


def load_data(source: Any, variables: Mapping[str, Variable],
              rename: Mapping[str, str] | None = None) -> Data:
    """Read ``source`` and code its columns for ``variables`` (``rename``: the variable each
    differently named column holds, ``{"material": "M"}``); every problem names its place."""
    frame, name, digest, csv = read_frame(source)
    if rename:
        found = [str(c) for c in frame.columns]
        for column, variable in rename.items():
            if column not in found:
                raise DataError(f"{name}: no column {column!r} to read as {variable} (columns: "
                                f"{', '.join(found)})")
            if variable not in variables:
                raise DataError(f"column {column!r}: the program has no variable {variable!r} "
                                f"(variables: {', '.join(variables)})")
        frame = frame.rename(columns=dict(rename))
    columns = [str(c) for c in frame.columns]
    if len(set(columns)) != len(columns):
        dup = next(c for c in columns if columns.count(c) > 1)
        raise DataError(f"{name}: column {dup!r} appears twice")
    for i, column in enumerate(columns):
        if column not in variables:
            raise DataError(f"{name}: column {column!r} (column {i + 1}): the program has no "
                            f"variable {column!r}; expected columns among "
                            f"{', '.join(variables)}")
    data = Data(name, digest, int(len(frame)), {}, {}, csv)
    for column, var in variables.items():
        if column not in columns:
            continue
        values = frame[column].to_numpy(dtype=object)
        if isinstance(var, Discrete):
            data.discrete[column] = _codes(values, var, data, column)
        elif var.index is not None:
            raise DataError(f"{name}: column {column!r}: {column} is a field (one value per "
                            f"state of {var.index}); fields are not learned from columns")
        else:
            data.continuous[column] = _numbers(values, var, data, column)
    return data


def _missing(value: Any) -> bool:
    """An empty cell (CSV), or a null (Parquet, a DataFrame): never a written word, which may be
    a state's name."""
    return value is None or type(value).__name__ in ("NAType", "NaTType") or (
        isinstance(value, float) and np.isnan(value)) or (
        isinstance(value, str) and value.strip() == "")


#: words a continuous column may hold for a missing value
_MISSING_NUMBERS = {"na", "nan", "n/a", "null", "none", "-"}


def _codes(values: np.ndarray, var: Discrete, data: Data, column: str) -> np.ndarray:
    lookup = {s: i for i, s in enumerate(var.states)}
    out = np.full(len(values), -1, dtype=np.int64)
    for row, value in enumerate(values):
        if _missing(value):
            continue
        if var.kind == "bins":  # a number falls in its bin; a bin's name is accepted too
            try:
                out[row] = var.index_of(value)
            except KeyError:
                raise DataError(f"{data.where(row, column)}: {short_repr(value)} is neither a "
                                f"number inside the support of {var.name} nor one of its bins "
                                f"{var.describe_states(10)}") from None
            continue
        key = str(value).strip()
        if isinstance(value, (bool, np.bool_)):
            key = key if key in lookup else key.lower()
        elif isinstance(value, float) and value.is_integer():
            key = str(int(value))
        elif var.kind == "range" and key not in lookup:
            try:
                number = float(key)
            except ValueError:
                number = np.nan
            if np.isfinite(number) and number.is_integer():
                key = str(int(number))  # a range's value written 3.0
        index = lookup.get(key)
        if index is None:
            raise DataError(f"{data.where(row, column)}: unknown state {short_repr(key)} of "
                            f"{var.name}: expected one of {var.describe_states(10)}")
        out[row] = index
    return out


def _numbers(values: np.ndarray, var: Continuous, data: Data, column: str) -> np.ndarray:
    out = np.full(len(values), np.nan)
    for row, value in enumerate(values):
        if _missing(value) or (isinstance(value, str) and value.strip().lower() in _MISSING_NUMBERS):
            continue
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise DataError(f"{data.where(row, column)}: expected a number for continuous "
                            f"{var.name}, found {short_repr(value)}") from None
        if not np.isfinite(x) or not var.low <= x <= var.high:
            raise DataError(f"{data.where(row, column)}: {x} is outside the support "
                            f"[{var.low}, {var.high}] of {var.name}")
        out[row] = x
    return out
