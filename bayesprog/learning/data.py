"""Data sets for learning: one column per variable, one row per observation, missing values
allowed. Read from CSV or Parquet files, a pandas DataFrame or a mapping of columns, and checked
against a program's variables with the file, row and column of every bad value.

A plain CSV file (no quotes, a row per line) is split by numpy (:mod:`.plain_csv`), any other
by the csv module; either way each column comes as codes into its distinct values, and only the
distinct values are looked up among the variable's states."""

from __future__ import annotations

import csv as csvlib
import functools
import hashlib
import io
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bayesprog.errors import ArgumentError, BayesprogError, short_repr
from bayesprog.learning.plain_csv import ReadAhead, read_file
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

    if isinstance(source, ReadAhead):  # read again as a frame: the path it reads
        source = source.path
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
    differently named column holds, ``{"material": "M"}``); every problem names its place.

    Each column is coded through its distinct values: a value is looked up once, however many
    rows hold it, and the rows take its code by indexing."""
    read = read_columns(source)
    name = read.source
    columns = list(read.names)
    if rename:
        for column, variable in rename.items():
            if column not in columns:
                raise DataError(f"{name}: no column {column!r} to read as {variable} (columns: "
                                f"{', '.join(columns)})")
            if variable not in variables:
                raise DataError(f"column {column!r}: the program has no variable {variable!r} "
                                f"(variables: {', '.join(variables)})")
        columns = [rename.get(c, c) for c in columns]
    if len(set(columns)) != len(columns):
        dup = next(c for c in columns if columns.count(c) > 1)
        raise DataError(f"{name}: column {dup!r} appears twice")
    for i, column in enumerate(columns):
        if column not in variables:
            raise DataError(f"{name}: column {column!r} (column {i + 1}): the program has no "
                            f"variable {column!r}; expected columns among "
                            f"{', '.join(variables)}")
    data = Data(name, read.sha256, read.rows, {}, {}, read.csv)
    for column, var in variables.items():
        if column not in columns:
            continue
        codes, values = read.column(columns.index(column))
        if isinstance(var, Discrete):
            data.discrete[column] = _coded(codes, values, data, column, _state_reader(var),
                                           missing=-1)
        elif var.index is not None:
            raise DataError(f"{name}: column {column!r}: {column} is a field (one value per "
                            f"state of {var.index}); fields are not learned from columns")
        else:
            data.continuous[column] = _coded(codes, values, data, column,
                                             functools.partial(_number, var=var),
                                             missing=np.nan)
    return data


@dataclass
class Columns:
    """A data set's columns, each as codes into its distinct values (-1: a null) by
    ``column(i)``: the values as read, looked up once each. Learning takes one as its data
    (``discover`` gives the columns it coded, so that they are not read or hashed again)."""

    source: str
    sha256: str
    rows: int
    csv: bool
    names: list[str]
    column: Callable[[int], tuple[np.ndarray, Sequence[Any]]]


def read_columns(source: Any, factorised: Callable[[Any], tuple[np.ndarray, Sequence[Any]]]
                 | None = None) -> Columns:
    """A plain CSV file (or one read ahead) by :mod:`bayesprog.learning.plain_csv`, columns
    already coded as they are, anything else through a data frame (:func:`read_frame`), each
    of its columns coded by ``factorised`` (by default nulls coded -1)."""
    if isinstance(source, Columns):
        return source
    plain = None
    if isinstance(source, ReadAhead):
        plain, source = source.result(), source.path
    elif isinstance(source, (str, os.PathLike)):
        source = Path(source)
        plain = read_file(source)
    if plain is not None:
        return Columns(str(source), plain.sha256, plain.rows, True, plain.names,
                       plain.columns.__getitem__)
    frame, name, digest, csv = read_frame(source)
    code = factorised or _factorised
    return Columns(name, digest, int(len(frame)), csv, [str(c) for c in frame.columns],
                   lambda i: code(frame.iloc[:, i]))


def _factorised(series: Any) -> tuple[np.ndarray, Any]:
    """A column as codes into its distinct values, nulls coded -1. A column of mixed types
    keeps each row's own value (1, 1.0 and True are equal keys to a hash table, not to a
    state's name)."""
    import pandas as pd

    if isinstance(series.dtype, pd.CategoricalDtype):
        return (series.cat.codes.to_numpy(np.int64),
                series.cat.categories.to_numpy(dtype=object))
    if series.dtype == object and pd.api.types.infer_dtype(series, skipna=True) not in (
            "string", "empty"):
        return np.arange(len(series)), series.to_numpy(dtype=object)
    codes, uniques = pd.factorize(series)
    return codes.astype(np.int64, copy=False), np.asarray(uniques, dtype=object)


def _missing(value: Any) -> bool:
    """An empty cell (CSV), or a null (Parquet, a DataFrame): never a written word, which may be
    a state's name."""
    return value is None or type(value).__name__ in ("NAType", "NaTType") or (
        isinstance(value, float) and np.isnan(value)) or (
        isinstance(value, str) and value.strip() == "")


#: words a continuous column may hold for a missing value
_MISSING_NUMBERS = {"na", "nan", "n/a", "null", "none", "-"}


class _BadValue(Exception):
    """A value that cannot be read for its variable (the message, without its place)."""


def _coded(codes: np.ndarray, values: Sequence[Any], data: Data, column: str,
           read: Callable[[Any], float], missing: float) -> np.ndarray:
    """Each distinct value read once by ``read`` (a state's index, or a number; ``missing``
    for a missing value), the rows coded by indexing; a bad value is said at the first row
    holding it."""
    table = np.empty(len(values) + 1, dtype=np.int64 if missing == -1 else float)
    table[-1] = missing  # the null code -1 indexes this
    bad: dict[int, str] = {}
    for j, value in enumerate(values):
        try:
            table[j] = read(value)
        except _BadValue as exc:
            bad[j] = str(exc)
    if bad:
        row = int(np.flatnonzero(np.isin(codes, list(bad)))[0])
        raise DataError(f"{data.where(row, column)}: {bad[int(codes[row])]}")
    return table[codes]


def _state_reader(var: Discrete) -> Callable[[Any], int]:
    lookup = {s: i for i, s in enumerate(var.states)}
    return lambda value: _state_index(value, var, lookup)


def _state_index(value: Any, var: Discrete, lookup: Mapping[str, int]) -> int:
    if _missing(value):
        return -1
    if var.kind == "bins":  # a number falls in its bin; a bin's name is accepted too
        try:
            return var.index_of(value)
        except KeyError:
            raise _BadValue(f"{short_repr(value)} is neither a number inside the support of "
                            f"{var.name} nor one of its bins {var.describe_states(10)}") from None
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
        raise _BadValue(f"unknown state {short_repr(key)} of {var.name}: expected one of "
                        f"{var.describe_states(10)}")
    return index


def _number(value: Any, var: Continuous) -> float:
    if _missing(value) or (isinstance(value, str) and value.strip().lower() in _MISSING_NUMBERS):
        return np.nan
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise _BadValue(f"expected a number for continuous {var.name}, found "
                        f"{short_repr(value)}") from None
    if not np.isfinite(x) or not var.low <= x <= var.high:
        raise _BadValue(f"{x} is outside the support [{var.low}, {var.high}] of {var.name}")
    return x
