"""A data set summarised group by group: the rows of each state of one discrete column (a
material, a class, a condition) and, per other column and group, the count, the missing
cells, the mean, the standard deviation, the smallest and the largest value of a real column,
or the count of each state of a discrete one (``bayesprog show DATA.csv``).

A column is real when every cell that is not empty reads as a number, discrete otherwise.

>>> summary = summarise({"material": ["wood", "wood", "foam"], "E": [0.5, None, 0.1]})
>>> summary.counts, summary.real["E"].loc["wood", ["count", "missing", "mean"]].tolist()
({'foam': 1, 'wood': 2}, [1.0, 1.0, 0.5])
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import Any

from bayesprog.errors import did_you_mean
from bayesprog.learning.data import _MISSING_NUMBERS, DataError, read_frame

#: the columns a data set is grouped by, when none is named: the first of these it has, else
#: its first discrete column
GROUP_COLUMNS = ("material", "M")

#: the statistics of a real column, per group, in their order
REAL_STATISTICS = ("count", "missing", "mean", "sd", "min", "max")

#: the states of a discrete column written out by :meth:`Summary.text`; the rarer ones after
#: them are counted together
SHOWN_STATES = 12


def typed(frame: Any, discrete: Collection[str] = ()) -> Any:
    """``frame`` with each column as numbers when every cell that is not empty reads as a
    number, or as a word for a missing number (``NA``, ``NaN``, ``null``, ... as learning reads
    a real column), and the column is not among ``discrete``: NaN where empty or such a word;
    else as text (None where empty). Booleans are discrete.

    >>> import pandas as pd
    >>> frame = typed(pd.DataFrame({"E": ["0.5", "NA", None], "S": ["NA", "b", "b"]}))
    >>> frame["E"].tolist(), frame["S"].tolist()
    ([0.5, nan, nan], ['NA', 'b', 'b'])
    """
    import pandas as pd

    out = {}
    for name in frame.columns:
        column = frame[name]
        present = column.notna()
        if name not in discrete and not pd.api.types.is_bool_dtype(column):
            numbers = pd.to_numeric(column, errors="coerce")
            words = present & numbers.isna()
            if bool(numbers.notna().any()) and bool(column[words].map(
                    lambda v: str(v).strip().lower() in _MISSING_NUMBERS).all()):
                out[name] = numbers.astype(float)
                continue
        out[name] = column.map(str).where(present, None).astype(object)
    return pd.DataFrame(out, index=frame.index)


def is_real(column: Any) -> bool:
    """Whether a column of a :func:`typed` frame holds numbers."""
    import pandas as pd

    return bool(pd.api.types.is_float_dtype(column))


def group_column(frame: Any, by: str | None = None, source: str = "the data") -> str:
    """The column ``by``, or by default the column named ``material`` or ``M``, else the first
    discrete column of a :func:`typed` frame. Raises DataError naming ``source``."""
    columns = [str(c) for c in frame.columns]
    if by is not None:
        if by not in columns:
            raise DataError(f"{source}: no column {by!r} to group by" + did_you_mean(by, columns)
                            + f" (its columns: {', '.join(columns)})")
        return by
    for name in GROUP_COLUMNS:
        if name in columns:
            return name
    for name in columns:
        if not is_real(frame[name]):
            return name
    raise DataError(f"{source}: no column to group the rows by: expected a column named "
                    f"{' or '.join(GROUP_COLUMNS)}, or a column that is not numbers (its "
                    f"columns: {', '.join(columns) or 'none'}); name one with --by COLUMN")


def _sorted_groups(values: Any) -> list[Any]:
    """The distinct values of a column, in order: numbers as numbers, and the numbers within
    names too (s2 before s10)."""
    import re

    distinct = list(values.dropna().unique())
    try:
        return sorted(distinct, key=float)
    except (TypeError, ValueError):
        return sorted(distinct, key=lambda v: [(0, int(part), "") if part.isdigit()
                                               else (1, 0, part)
                                               for part in re.split(r"(\d+)", str(v))])


@dataclass(frozen=True)
class Summary:
    """The summary of a data set ``source`` of ``rows`` rows grouped by the column ``by``:
    ``counts`` the rows of each group (in order), ``ungrouped`` the rows whose ``by`` is empty
    (left out of the groups), ``columns`` the columns summarised (in the data's order); per
    real column a frame indexed by group with the columns :data:`REAL_STATISTICS` (``sd``
    with n - 1, NaN for a group of fewer than two values), per discrete column a frame
    indexed by group with one column of counts per state (in order) and ``missing``."""

    source: str
    rows: int
    by: str
    counts: dict[str, int]
    ungrouped: int
    columns: tuple[str, ...]
    real: dict[str, Any]
    discrete: dict[str, Any]

    @property
    def groups(self) -> tuple[str, ...]:
        return tuple(self.counts)

    def text(self) -> str:
        """The summary as aligned text, a block per column."""
        import textwrap

        # a group and its count on one line (a no-break space between them while wrapping)
        head = (f"{self.source}: {self.rows} rows; {self.by} ({len(self.counts)} values): "
                + ", ".join(f"{g}\xa0{n}" for g, n in self.counts.items())
                + (f"; {self.ungrouped} rows without a {self.by}, left out" if self.ungrouped
                   else ""))
        lines = [line.replace("\xa0", " ") for line in textwrap.wrap(
            head, 96, subsequent_indent="  ", break_long_words=False, break_on_hyphens=False)]
        for name in self.columns:
            lines.append("")
            if name in self.real:
                lines.append(f"{name} (real):")
                table = self.real[name]
                header = list(REAL_STATISTICS)
                cells = [[_count(row["count"]), _count(row["missing"])]
                         + [_number(row[k]) for k in ("mean", "sd", "min", "max")]
                         for _, row in table.iterrows()]
            else:
                table = self.discrete[name]
                states = [c for c in table.columns if c != "missing"]
                lines.append(f"{name} (discrete, {len(states)} states):")
                shown, rest = states[:SHOWN_STATES], states[SHOWN_STATES:]
                header = [*shown, *([f"{len(rest)} others"] if rest else []), "missing"]
                cells = [[_count(row[s]) for s in shown]
                         + ([_count(row[rest].sum())] if rest else []) + [_count(row["missing"])]
                         for _, row in table.iterrows()]
            lines += _aligned(self.by, [str(g) for g in table.index], header, cells)
        return "\n".join(lines)


def _count(value: Any) -> str:
    return str(int(value))


def _number(value: Any) -> str:
    import math

    return "-" if value is None or math.isnan(float(value)) else f"{float(value):.4g}"


def _aligned(corner: str, names: list[str], header: list[str], cells: list[list[str]]
             ) -> list[str]:
    """Rows of a table: the names left-aligned, the cells right-aligned under the header."""
    first = max(len(corner), *(len(n) for n in names)) if names else len(corner)
    widths = [max(len(h), *(len(row[i]) for row in cells)) if cells else len(h)
              for i, h in enumerate(header)]
    out = ["  " + corner.ljust(first) + "".join(f"  {h:>{w}}" for h, w in zip(header, widths,
                                                                             strict=True))]
    for name, row in zip(names, cells, strict=True):
        out.append("  " + name.ljust(first) + "".join(f"  {c:>{w}}" for c, w in zip(
            row, widths, strict=True)))
    return out


def read_typed(data: Any, discrete: Collection[str] = ()) -> tuple[Any, str]:
    """(a :func:`typed` frame, the source's name) of a CSV or Parquet file, a DataFrame or a
    mapping of columns. Raises DataError for a file that cannot be read."""
    read = read_frame(data)
    return typed(read.frame, discrete), read.source


def summarise(data: Any, by: str | None = None, columns: Sequence[str] | None = None,
              discrete: Collection[str] = (), source: str | None = None) -> Summary:
    """The :class:`Summary` of ``data`` (a CSV or Parquet file, a DataFrame, a mapping of
    columns) grouped by the column ``by`` (see :func:`group_column`): ``columns`` (default:
    every other column), each read as real or discrete (:func:`typed`; ``discrete`` names
    columns to count by state even when they hold numbers). ``source``: the data's name in
    the summary and its errors (default: the file's). Raises DataError."""
    frame, read = read_typed(data, discrete)
    return summarise_frame(frame, source or read, by, columns)


def summarise_frame(frame: Any, source: str, by: str | None = None,
                    columns: Sequence[str] | None = None) -> Summary:
    """:func:`summarise` of a :func:`typed` frame read from ``source`` (left as it is)."""
    frame = frame.copy(deep=False)
    by = group_column(frame, by, source)
    chosen = [c for c in map(str, frame.columns) if c != by] if columns is None else \
        [c for c in columns if c != by]
    unknown = [c for c in chosen if c not in frame.columns]
    if unknown:
        raise DataError(f"{source}: no column {', '.join(map(repr, unknown))}"
                        + did_you_mean(unknown[0], map(str, frame.columns))
                        + f" (its columns: {', '.join(map(str, frame.columns))})")
    if is_real(frame[by]):  # groups named by numbers: as written, 2 not 2.0
        frame[by] = frame[by].map(lambda v: f"{v:g}").where(frame[by].notna(), None)
    groups = _sorted_groups(frame[by])
    if not groups:
        raise DataError(f"{source}: no row has a value in the column {by!r} to group by "
                        f"({len(frame)} rows)" + ("" if len(frame) else ": the file has a "
                                                  "header only"))
    key = frame[by]
    names = [str(g) for g in groups]
    rows = frame[key.notna()]
    grouped = rows.groupby(key[key.notna()], sort=False)
    counts = {n: int((key == n).sum()) for n in names}
    real, counted = {}, {}
    for name in chosen:
        column = grouped[name]
        if is_real(frame[name]):
            stats = column.agg(["count", "mean", "std", "min", "max"]).reindex(names)
            stats.insert(1, "missing", [counts[n] for n in names] - stats["count"])
            real[name] = stats.rename(columns={"std": "sd"})[list(REAL_STATISTICS)]
        else:
            states = _sorted_groups(frame[name])
            table = (column.value_counts().unstack(fill_value=0).reindex(index=names,
                                                                        columns=states)
                     .fillna(0).astype(int)) if states else _empty(names)
            table["missing"] = [counts[n] for n in names] - table[states].sum(axis=1)
            counted[name] = table
    return Summary(source, int(len(frame)), by, counts, int(key.isna().sum()), tuple(chosen),
                   real, counted)


def _empty(names: list[str]) -> Any:
    import pandas as pd

    return pd.DataFrame(index=pd.Index(names))
