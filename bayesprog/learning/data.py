"""Data sets for learning: one column per variable, one row per observation, missing values
allowed. Read from CSV or Parquet files, a pandas DataFrame or a mapping of columns, and checked
against a program's variables with the file, row and column of every bad value.

A plain CSV file (no quotes, a row per line) is split by numpy (:mod:`.plain_csv`), any other
by the csv module (:mod:`.csv_rows`); either way each column comes as codes into its distinct
values, and only the distinct values are looked up among the variable's states.

A bad row (more or fewer fields than the header, a line that is not UTF-8 text, a value that is
not a number of a continuous column, a state a discrete column does not declare) is refused by
default, the earliest in the file; ``on_bad_lines="skip"`` (or ``"warn"``, the names of pandas'
``read_csv``) sets every bad row aside instead, as a row of missing values, each named by its
line and why (:class:`~bayesprog.learning.csv_rows.BadRow`). A missing value is not bad."""
from __future__ import annotations

import functools
import hashlib
import os
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from bayesprog.errors import ArgumentError, BayesprogError, did_you_mean, short_repr
from bayesprog.learning.csv_rows import BadRow, CsvProblem, read_csv_rows
from bayesprog.learning.plain_csv import ReadAhead, read_file
from bayesprog.vocabulary.variables import Continuous, Discrete, Variable

#: what is done with a bad row, as pandas' ``read_csv(on_bad_lines=...)`` names it: refuse
#: the earliest, or set every one aside (``warn`` also says which)
ON_BAD_LINES = ("error", "warn", "skip")


class DataError(BayesprogError):
    """A data set does not fit the program it is to teach (or cannot be read)."""


class BadRowError(DataError):
    """A bad row refused (``on_bad_lines="error"``): ``bad`` names it, ``message`` says where
    and why; :meth:`fixed` adds how to set such rows aside, in the caller's words."""

    def __init__(self, message: str, bad: BadRow, fix: str = ""):
        self.message, self.bad = message, bad
        super().__init__(f"{message} ({fix})" if fix else message)

    def fixed(self, fix: str) -> BadRowError:
        return BadRowError(self.message, self.bad, fix)


class BadRowsWarning(UserWarning):
    """Bad rows were set aside (``on_bad_lines="warn"``); the message lists them."""


def check_on_bad_lines(value: object) -> str:
    """``value`` if it is one of :data:`ON_BAD_LINES`."""
    if not isinstance(value, str) or value not in ON_BAD_LINES:
        raise ArgumentError(f"on_bad_lines: expected one of "
                            f"{', '.join(map(repr, ON_BAD_LINES))}, found {short_repr(value)}")
    return value


def set_aside_message(source: str, bad: Sequence[BadRow], limit: int = 20) -> str:
    """``FILE: N bad rows set aside:`` and the first ``limit`` of them, one a line."""
    listed = "".join(f"\n  {b}" for b in bad[:limit])
    more = f"\n  ... and {len(bad) - limit} more" if len(bad) > limit else ""
    return f"{source}: {len(bad)} bad row{'s' if len(bad) != 1 else ''} set aside:{listed}{more}"


def _place(source: str, row: int, csv: bool, lines: np.ndarray | None) -> str:
    """``FILE: row R (line L)`` for 0-based data row ``row`` (the line of a CSV file only)."""
    if not csv:
        return f"{source}: row {row + 1}"
    return f"{source}: row {row + 1} (line {_line(row, lines)})"


def _line(row: int, lines: np.ndarray | None) -> int:
    """The first line of a CSV file's 0-based data row ``row``."""
    return int(lines[row]) if lines is not None else row + 2


@dataclass
class Data:
    """Columns coded for learning: discrete values as state indices (-1 where missing),
    continuous values as floats (NaN where missing). A row set aside (``set_aside``; None when
    bad rows are refused) is missing in every column; ``states`` are those of the variables
    that take theirs from the data (sorted, as written)."""

    source: str
    sha256: str
    rows: int
    discrete: dict[str, np.ndarray]
    continuous: dict[str, np.ndarray]
    csv: bool = False
    #: each row's first line in a CSV file where a quoted value spans lines (else row r is on
    #: line r + 2); indexed by the rows as read, also in a copy of some rows (:meth:`take`)
    lines: np.ndarray | None = None
    set_aside: list[BadRow] | None = None
    states: dict[str, list[str]] = field(default_factory=dict)

    def place(self, row: int) -> str:
        """``FILE: row R (line L)`` for 0-based data row ``row`` (as read)."""
        return _place(self.source, row, self.csv, self.lines)

    def where(self, row: int, column: str) -> str:
        """``FILE: row R (line L), column 'C'`` for 0-based data row ``row`` (as read)."""
        return f"{self.place(row)}, column {column!r}"

    def take(self, rows: np.ndarray) -> Data:
        return Data(self.source, self.sha256, int(len(rows)),
                    {k: v[rows] for k, v in self.discrete.items()},
                    {k: v[rows] for k, v in self.continuous.items()}, self.csv, self.lines,
                    self.set_aside, self.states)


class Frame(NamedTuple):
    """A data set read as a DataFrame of strings and numbers (:func:`read_frame`)."""

    frame: Any
    source: str
    sha256: str
    csv: bool
    #: a CSV file's: each row's first line, where a quoted value spans lines (else None)
    lines: np.ndarray | None = None
    #: a CSV file's rows that cannot be split as the header is (their cells null)
    bad: tuple[BadRow, ...] = ()


def read_frame(source: Any, keep_bad: bool = False) -> Frame:
    """``source`` as a DataFrame of strings and numbers, its name and SHA-256. A CSV file's row
    that cannot be split as the header is (:mod:`.csv_rows`) is refused, unless ``keep_bad``:
    then it is a row of nulls, named in :attr:`Frame.bad`."""
    import pandas as pd

    if isinstance(source, ReadAhead):  # read again as a frame: the path it reads
        source = source.path
    if isinstance(source, pd.DataFrame):
        hashed = pd.util.hash_pandas_object(source, index=False).to_numpy().tobytes()
        return Frame(source, "<data frame>", hashlib.sha256(hashed).hexdigest(), False)
    if isinstance(source, Mapping):
        lengths = {str(k): len(v) for k, v in source.items()}
        if len(set(lengths.values())) > 1:
            raise DataError("columns of different lengths: " + ", ".join(
                f"{k} {n}" for k, n in lengths.items()) + "; expected one value per row in each")
        frame = pd.DataFrame({k: list(v) for k, v in source.items()})
        return read_frame(frame)._replace(source="<columns>")
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
        from bayesprog.support.extras import require_extra

        require_extra("pyarrow", "parquet", f"reading {path}")
        try:
            frame = pd.read_parquet(path)
        except Exception as exc:  # pyarrow raises several types for a file that is not Parquet
            raise DataError(f"cannot read data {path} as Parquet: {exc}") from None
        return Frame(frame, str(path), hexdigest, False)
    if suffix not in (".csv", ".txt", ".tsv"):
        raise DataError(f"cannot read data {path}: expected a .csv or .parquet file, found "
                        f"{suffix or 'no suffix'}")
    try:
        read = read_csv_rows(raw, "\t" if suffix == ".tsv" else ",")
    except CsvProblem as exc:
        raise DataError(f"cannot read data {path} as CSV: {exc}") from None
    first_lines = np.asarray(read.lines, dtype=np.int64)
    spans = not np.array_equal(first_lines, np.arange(2, len(read.lines) + 2))
    lines = first_lines if spans else None  # else row r on line r + 2: nothing to keep
    if read.bad and not keep_bad:
        first = read.bad[0]
        raise BadRowError(f"{_place(str(path), first.row - 1, True, lines)}: {first.why}", first)
    frame = pd.DataFrame(read.rows, columns=read.header, dtype=object)
    return Frame(frame, str(path), hexdigest, True, lines, tuple(read.bad))


def load_data(source: Any, variables: Mapping[str, Variable],
              rename: Mapping[str, str] | None = None, *, on_bad_lines: str = "error",
              states_from_data: Collection[str] = (), other_columns: str = "refuse") -> Data:
    """Read ``source`` and code its columns for ``variables`` (``rename``: the variable each
    differently named column holds, ``{"material": "M"}``); every problem names its place. A
    bad row is refused (``on_bad_lines="error"``: the earliest) or set aside (``"skip"``,
    ``"warn"``: the caller warns). A variable of ``states_from_data`` takes the states found in
    its column's rows that are kept (sorted, as written). A column that is no variable's is
    refused (``other_columns="refuse"``: a misspelt name) or read past (``"ignore"``: a
    session log's cells and timings beside its readings). Data already coded are returned as
    they are.

    Each column is coded through its distinct values: a value is looked up once, however many
    rows hold it, and the rows take its code by indexing."""
    if isinstance(source, Data):
        return source
    skip = check_on_bad_lines(on_bad_lines) != "error"
    if other_columns not in ("refuse", "ignore"):
        raise DataError(f"other_columns: expected 'refuse' or 'ignore', found "
                        f"{other_columns!r}")
    read = read_columns(source, keep_bad=True)  # bad rows refused below, the earliest first
    columns = _columns(read, variables, rename, refuse_others=other_columns == "refuse")
    readers = {c: _reader(variables[c]) for c in columns
               if c not in states_from_data and c in variables}
    coded, bad = _checked(read, columns, readers, skip)
    data = Data(read.source, read.sha256, read.rows, {}, {}, read.csv, read.lines,
                bad if skip else None)
    for name in states_from_data:
        data.states[name], coded[name] = _states_found(read, columns, name, bad)
    for column in variables:  # in the program's order
        values = coded.get(column)
        if values is not None:
            (data.discrete if values.dtype.kind == "i" else data.continuous)[column] = values
    return data


def read_data(source: Any, variables: Mapping[str, Variable] | None = None, *,
              columns: Mapping[str, str] | None = None, states_from_data: Collection[str] = (),
              on_bad_lines: str = "skip") -> tuple[Any, list[BadRow]]:
    """The rows of a data set that can be read, as a pandas DataFrame, and the bad rows set
    aside: ``(frame, set_aside)``, each :class:`BadRow` a ``(line, why, row)`` named tuple.

    ``source`` is a CSV or Parquet file, a DataFrame or a mapping of columns; ``columns`` maps
    a column of another name to the variable it holds (``{"material": "M"}``), and the frame's
    columns are named so. A column of one of ``variables`` (a program's) is checked against it
    and holds its values (a discrete variable's state names, a continuous one's numbers; None
    or NaN where missing), except that a variable of ``states_from_data`` takes any value.
    Other columns are kept as read (a CSV file's column of numbers as numbers). Every bad row
    is set aside: a row of more or fewer fields than the header, a line that is not UTF-8
    text, a value that is not a number of a continuous column or outside its support, a state
    its variable does not declare; a missing value is not bad. ``on_bad_lines="warn"`` also
    warns (:class:`BadRowsWarning`); ``"error"`` refuses the earliest (:class:`BadRowError`).

    >>> import bayesprog
    >>> program = bayesprog.loads('''
    ... bayesprog: 1
    ... variables: {M: {states: [wood, silk]}, E: {continuous: [-.inf, .inf]}}
    ... decomposition:
    ...   - {term: P(M), form: uniform}
    ...   - {term: P(E | M), form: normal, mean: 0.0, sigma: 1.0}
    ... ''')
    >>> frame, set_aside = read_data({"M": ["wood", "sil", "silk"], "E": ["0.5", "0.1", ""]},
    ...                              program.variables)
    >>> frame.to_dict("list")
    {'M': ['wood', 'silk'], 'E': [0.5, nan]}
    >>> print(*set_aside)
    row 2: column 'M': unknown state 'sil' of M (did you mean 'silk'?): expected one of wood, silk
    """
    import warnings

    import pandas as pd

    mode = check_on_bad_lines(on_bad_lines)
    variables = variables or {}
    for name in states_from_data:
        open_variable(variables, name)
    read = read_columns(source, keep_bad=True)
    names = _columns(read, variables, columns, refuse_others=False)
    readers = {c: _reader(variables[c]) for c in names
               if c in variables and c not in states_from_data}
    coded, bad = _checked(read, names, readers, mode != "error")
    kept = np.ones(read.rows, bool)
    kept[[b.row - 1 for b in bad]] = False
    out: dict[str, Any] = {}
    for i, name in enumerate(names):
        var = variables.get(name)
        if name in states_from_data:
            states, codes = _states_found(read, names, name, bad)
            out[name] = np.array([*states, None], dtype=object)[codes[kept]]
        elif isinstance(var, Discrete):
            out[name] = np.array([*var.states, None], dtype=object)[coded[name][kept]]
        elif var is not None:
            out[name] = coded[name][kept]
        elif read.frame is not None and not read.csv:  # a data frame's or a Parquet file's
            out[name] = read.frame.iloc[kept, i].to_numpy()
        else:  # a CSV file's cells, as numbers when they all are (as pandas reads them)
            codes, values = read.column(i)
            cells = np.array([*(None if _missing(v) else v for v in values), None],
                             dtype=object)[codes[kept]]
            try:
                out[name] = pd.to_numeric(pd.Series(cells)).to_numpy()
            except (TypeError, ValueError):
                out[name] = cells
    frame = pd.DataFrame(out, index=pd.RangeIndex(int(kept.sum())), columns=names)
    if mode == "warn" and bad:
        warnings.warn(set_aside_message(read.source, bad), BadRowsWarning, stacklevel=2)
    return frame, bad


def open_variable(variables: Mapping[str, Variable], name: str) -> Discrete:
    """The variable ``name``, which is to take the states found in its column: one of named
    states."""
    var = variables.get(name)
    if not isinstance(var, Discrete) or var.kind != "states":
        raise ArgumentError(f"states from the data: {name!r} is not a variable with named "
                            "states of this program")
    return var


@dataclass
class Columns:
    """A data set's columns, each as codes into its distinct values (-1: a null) by
    ``column(i)``: the values as read, looked up once each. Learning takes one as its data
    (``discover`` gives the columns it coded, so that they are not read or hashed again).
    ``lines`` and ``bad`` are a CSV file's, as :class:`Frame` has them; ``frame`` is the data
    frame the columns were read from, if any."""

    source: str
    sha256: str
    rows: int
    csv: bool
    names: list[str]
    column: Callable[[int], tuple[np.ndarray, Sequence[Any]]]
    lines: np.ndarray | None = None
    bad: Sequence[BadRow] = ()
    frame: Any = None


def read_columns(source: Any, factorised: Callable[[Any], tuple[np.ndarray, Sequence[Any]]]
                 | None = None, keep_bad: bool = False) -> Columns:
    """A plain CSV file (or one read ahead) by :mod:`bayesprog.learning.plain_csv`, columns
    already coded as they are, anything else through a data frame (:func:`read_frame`, which
    keeps the rows it cannot split if ``keep_bad``), each of its columns coded by
    ``factorised`` (by default nulls coded -1)."""
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
    read = read_frame(source, keep_bad)
    frame = read.frame
    code = factorised or _factorised
    return Columns(read.source, read.sha256, int(len(frame)), read.csv,
                   [str(c) for c in frame.columns], lambda i: code(frame.iloc[:, i]),
                   read.lines, read.bad, frame)


def frame_columns(frame: Any, factorised: Callable[[Any], tuple[np.ndarray, Sequence[Any]]]
                  ) -> Columns:
    """A data frame's columns as :func:`read_columns` reads them (each coded by
    ``factorised``), coded at once, with the SHA-256 :func:`read_frame` gives the frame (of
    pandas' ``hash_pandas_object(frame, index=False)``) computed from the codes: a column of
    strings is hashed through its distinct values, each once, as pandas hashes it (each value's
    hash, a null's ``2**64 - 1``), instead of being encoded a second time; any other column by
    pandas itself."""
    coded = [factorised(frame.iloc[:, j]) for j in range(frame.shape[1])]
    hashes = [_column_hash(frame.iloc[:, j], *coded[j]) for j in range(frame.shape[1])]
    digest = hashlib.sha256(_combined(hashes, len(frame)).tobytes()).hexdigest()
    return Columns("<data frame>", digest, int(len(frame)), False,
                   [str(c) for c in frame.columns], coded.__getitem__, frame=frame)


def _column_hash(column: Any, which: np.ndarray, values: Sequence[Any]) -> np.ndarray:
    """``hash_pandas_object(column, index=False)``, from the column's codes into its distinct
    values when it holds strings and nulls only (pandas then hashes its distinct values, each
    once, as here)."""
    import pandas as pd

    strings = column.dtype == object or isinstance(column.dtype, pd.StringDtype)
    if strings and all(
            type(v) is str or v is None or v is pd.NA or (type(v) is float and v != v)
            for v in values):
        distinct = np.empty(len(values), dtype=object)
        distinct[:] = list(values)
        hashed = (pd.util.hash_array(distinct, categorize=False) if len(distinct)
                  else np.zeros(0, dtype=np.uint64))
        hashed[pd.isna(distinct)] = np.iinfo(np.uint64).max
        return hashed[np.asarray(which)]
    return pd.util.hash_pandas_object(column, index=False).to_numpy()


def _combined(hashes: Sequence[np.ndarray], rows: int) -> np.ndarray:
    """The rows' hashes from their columns' (pandas' ``combine_hash_arrays``, as CPython
    combines a tuple's)."""
    if not hashes:
        return np.full(rows, 0x345678 + 97531, dtype=np.uint64)
    mult = np.uint64(1000003)
    out = np.zeros_like(hashes[0]) + np.uint64(0x345678)
    for i, column in enumerate(hashes):
        inverse = len(hashes) - i
        out ^= column
        out *= mult
        mult += np.uint64(82520 + inverse + inverse)
    out += np.uint64(97531)
    return out


def _columns(read: Columns, variables: Mapping[str, Variable],
             rename: Mapping[str, str] | None, refuse_others: bool) -> list[str]:
    """The names of ``read``'s columns, each renamed to the variable it holds; a column that is
    no variable's is refused if ``refuse_others``."""
    name = read.source
    columns = list(read.names)
    if rename:
        for column, variable in rename.items():
            if column not in columns:
                raise DataError(f"{name}: no column {column!r} to read as {variable} (columns: "
                                f"{', '.join(columns)})")
            if variable not in variables and (refuse_others or variables):
                raise DataError(f"column {column!r}: the program has no variable {variable!r} "
                                f"(variables: {', '.join(variables)})")
        columns = [rename.get(c, c) for c in columns]
    if len(set(columns)) != len(columns):
        dup = next(c for c in columns if columns.count(c) > 1)
        raise DataError(f"{name}: column {dup!r} appears twice")
    for i, column in enumerate(columns):
        var = variables.get(column)
        if var is None and refuse_others:
            raise DataError(f"{name}: column {column!r} (column {i + 1}): the program has no "
                            f"variable {column!r}; expected columns among "
                            f"{', '.join(variables)} (a column of another name is read as "
                            f"its variable with --column {column}=VARIABLE; columns that are no "
                            "variable's, as a log's, are read past with --ignore-other-columns, "
                            "in Python other_columns='ignore')")
        if isinstance(var, Continuous) and var.index is not None:
            raise DataError(f"{name}: column {column!r}: {column} is a field (one value per "
                            f"state of {var.index}); fields are not learned from columns")
    return columns


def _reader(var: Variable) -> tuple[Callable[[Any], float], float]:
    """How a value of ``var``'s column is read (to a state's index, or a number), and the code
    of a missing value."""
    if isinstance(var, Discrete):
        return _state_reader(var), -1
    return functools.partial(_number, var=var), np.nan


def _checked(read: Columns, columns: list[str],
             readers: Mapping[str, tuple[Callable[[Any], float], float]], skip: bool
             ) -> tuple[dict[str, np.ndarray], list[BadRow]]:
    """Each column of ``readers`` (``columns`` name ``read``'s columns) coded by its reader:
    each distinct value read once, the rows coded by indexing; and the bad rows, those
    ``read`` could not split and those holding a value their column's reader refuses. Unless
    ``skip``, the earliest is refused (:class:`BadRowError`); else each is missing in every
    column, every problem of a row named, in the file's order."""
    coded: dict[str, np.ndarray] = {}
    problems: dict[int, list[tuple[int, str]]] = {}  # row -> (column, why) of each problem
    for name, (reader, missing) in readers.items():
        i = columns.index(name)
        codes, values = read.column(i)
        table = np.empty(len(values) + 1, dtype=np.int64 if missing == -1 else float)
        table[-1] = missing  # the null code -1 indexes this
        bad: dict[int, str] = {}
        for j, value in enumerate(values):
            try:
                table[j] = reader(value)
            except _BadValue as exc:
                bad[j] = str(exc)
                table[j] = missing
        coded[name] = table[codes]
        if bad:
            rows = np.flatnonzero(np.isin(codes, list(bad)))
            for row in (rows if skip else rows[:1]).tolist():
                problems.setdefault(row, []).append((i, bad[int(codes[row])]))
    structural = {b.row - 1: b for b in read.bad}
    if not skip:
        first = min([*problems, *structural], default=None)
        if first is None:
            return coded, []
        place = _place(read.source, first, read.csv, read.lines)
        if first in structural:
            raise BadRowError(f"{place}: {structural[first].why}", structural[first])
        i, why = min(problems[first])
        raise BadRowError(f"{place}, column {columns[i]!r}: {why}",
                          _bad_row(read, first, [(i, why)], columns))
    out = [*structural.values(), *(_bad_row(read, row, sorted(found), columns)
                                   for row, found in problems.items())]
    out.sort(key=lambda b: b.row)
    if problems:
        rows = np.fromiter(problems, dtype=np.intp, count=len(problems))
        for name, array in coded.items():
            array[rows] = readers[name][1]
    return coded, out


def _bad_row(read: Columns, row: int, found: list[tuple[int, str]], columns: list[str]
             ) -> BadRow:
    """The 0-based data row ``row``, its problems ``found`` (column, why) named."""
    why = "; ".join(f"column {columns[i]!r}: {why}" for i, why in found)
    return BadRow(_line(row, read.lines) if read.csv else None, why, row + 1)


def _states_found(read: Columns, columns: list[str], name: str, bad: Sequence[BadRow]
                  ) -> tuple[list[str], np.ndarray]:
    """The states of the variable ``name`` found in its column's rows other than ``bad``
    (sorted, as written), and the column coded into them (-1 where missing, and in the rows
    set aside)."""
    if name not in columns:
        raise DataError(f"{read.source}: no column for {name} to take its states from")
    codes, values = read.column(columns.index(name))
    if bad:
        codes = codes.copy()
        codes[[b.row - 1 for b in bad]] = -1
    keys = {j: _state_key(values[j]) for j in np.unique(codes[codes >= 0]).tolist()
            if not _missing(values[j])}
    states = sorted(set(keys.values()))
    if not states:
        raise DataError(f"{read.source}: column {name} holds no value to take states from")
    index = {s: k for k, s in enumerate(states)}
    table = np.full(len(values) + 1, -1, dtype=np.int64)
    for j, key in keys.items():
        table[j] = index[key]
    return states, table[codes]


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
    key = _state_key(value)
    if isinstance(value, (bool, np.bool_)):
        key = key if key in lookup else key.lower()
    elif var.kind == "range" and key not in lookup:
        try:
            number = float(key)
        except ValueError:
            number = np.nan
        if np.isfinite(number) and number.is_integer():
            key = str(int(number))  # a range's value written 3.0
    index = lookup.get(key)
    if index is None:
        near = did_you_mean(key, var.states) if var.kind == "states" else ""
        hint = f" ({near[2:]})" if near else ""  # " (did you mean 'glass'?)"
        raise _BadValue(f"unknown state {short_repr(key)} of {var.name}{hint}: expected one "
                        f"of {var.describe_states(10)}")
    return index


def _state_key(value: Any) -> str:
    """The name a state is looked up by, for a value as read: its text without the spaces
    around it, a whole float without its decimals (a Parquet column of 1.0, 2.0)."""
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value).strip()


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
