"""A session's log: every probe of an exploration driven over stdio or ROS 2, or of a robot's
closed loop, one row each (``--log FILE.csv`` or ``FILE.parquet``).

Columns: ``step``; the probed cell ``ix, iy(, iz)`` and its centre ``x_m, y_m(, z_m)``; one
column per reading, by its name (empty where missing; a discrete reading by its state);
``missing`` (the missing readings' names, ``;``-separated) and ``warnings``; ``material``, the
material the scenario's layout has at that cell; ``decided``, the material perceived there
after the probe, and ``probability``, its posterior; the next cell ``next_ix, next_iy(,
next_iz)``; and the time the step took in milliseconds, ``perception_ms``, ``cues_ms``,
``shape_ms``, ``decision_ms`` and ``total_ms``.

A log is a recordings file: ``bayesprog learn PI_PER.yaml LOG.csv --column material=M``
identifies pi_per again from the sessions a lab ran (the readings' columns are named as the
readings; give ``--column NAME=VARIABLE`` where a reading is named otherwise than its
variable, as the paper's texture and compliance are). Beside it, ``LOG.json`` says what the
session explored (the scenario's absolute path, its task, seed and ablations, and ``run`` when
the decisions' random stream is an experiment run's), so that ``bayesprog report LOG.csv`` can
replay and draw it (:func:`read_meta`, :func:`read_probes`). A CSV log is written row by row
and flushed, so an interrupted session keeps every probe it answered; a Parquet log is written
in row groups, the last at the end.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from bayesprog import BayesprogError
from runner.world.readings import Perception, ReadingError

#: the file kinds a log is written as, by suffix
SUFFIXES = (".csv", ".parquet", ".pq")
#: rows of a Parquet log held before they are written as a row group
ROW_GROUP = 256
#: the timings a row gives, by the explorer's phases
PHASES = ("perception", "cues", "shape", "decision")


def meta_path(path: Path) -> Path:
    """The file beside a log that says what the session explored."""
    return path.with_suffix(".json")


def fixed_columns(dims: int) -> list[str]:
    """The columns of a log beside its readings'."""
    cell = ["ix", "iy", "iz"][:dims]
    return ["step", *cell, *["x_m", "y_m", "z_m"][:dims], "missing", "warnings", "material",
            "decided", "probability", *[f"next_{a}" for a in cell],
            *[f"{p}_ms" for p in PHASES], "total_ms"]


def reading_columns(names: Sequence[str], dims: int) -> dict[str, str]:
    """Each reading's column in a log: its name, or ``reading_NAME`` where its name is one of
    the log's other columns (a reading called ``material`` or ``step``)."""
    fixed = set(fixed_columns(dims))
    return {n: f"reading_{n}" if n in fixed else n for n in names}


class SessionLog:
    """Writes a session's probes to ``path`` (CSV or Parquet, by its suffix), for a session
    over ``perception``'s readings on a grid of ``dims`` axes; ``meta`` is what it explores
    (written beside it as JSON)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if self.path.suffix.lower() not in SUFFIXES:
            raise BayesprogError(f"--log {self.path}: expected a .csv or .parquet file, found "
                                 f"{self.path.suffix or 'no suffix'}")
        self.parquet = self.path.suffix.lower() != ".csv"
        if self.parquet:
            from bayesprog import require_extra

            require_extra("pyarrow", "parquet", "--log FILE.parquet")
        self.columns: list[str] | None = None
        self.reading_columns: dict[str, str] = {}
        self.discrete: set[str] = set()
        self._file: IO[str] | None = None
        self._writer: Any = None
        self._rows: list[dict] = []
        self.rows = 0
        try:
            self.path.touch()  # a folder that is not there, or not writable, is said at once
        except OSError as exc:
            raise BayesprogError(f"--log {self.path}: cannot write it: "
                                 f"{exc.strerror or exc}") from None

    def start(self, perception: Perception, dims: int, meta: dict[str, Any]) -> None:
        """The columns of the log, and what the session explores beside it (again at every
        reset: the last one's)."""
        meta = {"log": 1, **meta, "readings": list(perception.names),
                "material": perception.material, "dims": dims}
        meta_path(self.path).write_text(json.dumps(meta, indent=1) + "\n")
        if self.columns is not None:
            return
        fixed = fixed_columns(dims)
        #: each reading's column: its name, ``reading_NAME`` where that is one of the others'
        self.reading_columns = reading_columns(perception.names, dims)
        at = 1 + 2 * dims
        self.columns = [*fixed[:at], *self.reading_columns.values(), *fixed[at:]]
        self.discrete = {self.reading_columns[r.name] for r in perception.readings
                         if r.discrete}
        if not self.parquet:
            self._file = self.path.open("w", newline="")
            self._csv = csv.writer(self._file)
            self._csv.writerow(self.columns)
            self._file.flush()

    def write(self, step: int, cell: list[int], position: list[float],
              readings: dict[str, Any], missing: list[str], warnings: list[str],
              material: str | None, decided: str, probability: float,
              next_cell: list[int] | None, timings: dict[str, float], total: float) -> None:
        """One probe's row (readings by name as they are written out; times in seconds)."""
        assert self.columns is not None, "start() the log first"
        row: dict[str, Any] = {"step": step}
        row.update(zip(["ix", "iy", "iz"], cell, strict=False))
        row.update(zip(["x_m", "y_m", "z_m"], position, strict=False))
        row.update({self.reading_columns.get(n, n): v for n, v in readings.items()})
        row.update({"missing": ";".join(missing), "warnings": "; ".join(warnings),
                    "material": material, "decided": decided, "probability": probability})
        row.update(zip(["next_ix", "next_iy", "next_iz"], next_cell or [], strict=False))
        for phase in PHASES:
            row[f"{phase}_ms"] = round(1000 * timings.get(phase, 0.0), 4)
        row["total_ms"] = round(1000 * total, 4)
        self.rows += 1
        if self.parquet:
            self._rows.append({c: row.get(c) for c in self.columns})
            if len(self._rows) >= ROW_GROUP:
                self._flush_parquet()
            return
        assert self._file is not None
        self._csv.writerow(["" if row.get(c) is None or (isinstance(row[c], float)
                                                         and math.isnan(row[c])) else row[c]
                            for c in self.columns])
        self._file.flush()

    def _flush_parquet(self) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not self._rows:
            return
        if self._writer is None:
            assert self.columns is not None
            text = {"missing", "warnings", "material", "decided", *self.discrete}
            whole = {"step", "ix", "iy", "iz", "next_ix", "next_iy", "next_iz"}
            schema = pa.schema([(c, pa.string() if c in text else pa.int64() if c in whole
                                 else pa.float64()) for c in self.columns])
            self._writer = pq.ParquetWriter(str(self.path), schema)
        self._writer.write_table(pa.Table.from_pylist(self._rows, schema=self._writer.schema))
        self._rows = []

    def close(self) -> None:
        if self.parquet:
            self._flush_parquet()
            if self._writer is not None:
                self._writer.close()
                self._writer = None
        elif self._file is not None:
            self._file.close()
            self._file = None


# reading a log back ----------------------------------------------------------------------------
def is_log(path: Path) -> bool:
    """Whether ``path`` names a session log (by its suffix; a folder never is one)."""
    return Path(path).suffix.lower() in SUFFIXES and not Path(path).is_dir()


def read_meta(path: Path) -> dict[str, Any]:
    """What the session of the log ``path`` explored, from the file beside it, checked whole
    (every problem said at once)."""
    meta_file = meta_path(path)
    if not Path(path).is_file():
        raise BayesprogError(f"cannot read {path}: no such file")
    try:
        meta = json.loads(meta_file.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BayesprogError(f"{path}: no {meta_file.name} beside it, which says what the "
                             "session explored (explore --log and robot --log write it): "
                             "keep the two files together") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise BayesprogError(f"{meta_file}: not a readable session description: {exc}") from None
    if not isinstance(meta, dict):
        raise BayesprogError(f"{meta_file}: expected a JSON object, found {type(meta).__name__}")
    problems = []

    def natural(key: str, required: bool = True) -> None:
        value = meta.get(key)
        if value is None and not required:
            return
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            problems.append(f"{key!r} a non-negative integer, found {value!r}")

    for key in ("scenario", "task", "material"):
        if not isinstance(meta.get(key), str):
            problems.append(f"{key!r} a string, found {meta.get(key)!r}")
    natural("seed")
    natural("run", required=False)
    for key in ("ablate", "readings"):
        value = meta.get(key)
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            problems.append(f"{key!r} a list of strings, found {value!r}")
    if meta.get("dims") not in (2, 3):
        problems.append(f"'dims' 2 or 3, found {meta.get('dims')!r}")
    if problems:
        raise BayesprogError(f"{meta_file}: expected " + "; ".join(problems))
    return meta


@dataclass(frozen=True)
class Probe:
    """One row of a log, read back: where it is in the file (``where``), the step, the cell
    probed, its readings by name as they were sent (a number, a state's name, None where
    missing), the missing readings' names, the warnings, the layout's material there, the
    material decided and its probability, the next cell (None: no decision after it) and the
    timings in milliseconds by phase (``total`` too; NaN where the log has none)."""

    where: str
    step: int
    cell: tuple[int, ...]
    readings: dict[str, float | str | None]
    missing: tuple[str, ...]
    warnings: str
    material: str
    decided: str
    probability: float
    next_cell: tuple[int, ...] | None
    timings: dict[str, float]


def read_probes(path: Path, perception: Perception, shape: tuple[int, ...]) -> list[Probe]:
    """The rows of the log ``path`` of a session over ``perception``'s readings on a grid of
    ``shape``. A row that does not parse is an error at its line (the first one, and how many
    more there are)."""
    path = Path(path)
    records, first = _records(path)
    columns = reading_columns(perception.names, len(shape))
    cell = ["ix", "iy", "iz"][: len(shape)]
    needed = ["step", *cell, *columns.values(), "missing", "warnings", "material", "decided",
              "probability", *[f"next_{a}" for a in cell]]
    absent = [c for c in needed if c not in first]
    if absent:
        raise BayesprogError(f"{path}: no column {', '.join(map(repr, absent))}: expected the "
                             f"columns of a session log over {', '.join(perception.names)} on a "
                             f"{len(shape)}-D grid (its columns: {', '.join(first)})")
    probes, bad = [], []
    for where, row in records:
        try:
            probes.append(_probe(where, row, perception, shape, columns))
        except (ValueError, ReadingError) as exc:
            bad.append(f"{where}: {exc}")
    if bad:
        more = f" (and {len(bad) - 1} more row(s) that do not parse)" if len(bad) > 1 else ""
        raise BayesprogError(bad[0] + more)
    if not probes:
        raise BayesprogError(f"{path}: no probes: the session answered none")
    return probes


def _records(path: Path) -> tuple[list[tuple[str, dict[str, Any]]], list[str]]:
    """The rows of a log as (where, column -> value) and its columns."""
    if path.suffix.lower() == ".csv":
        try:
            with path.open(newline="", encoding="utf-8") as f:
                reader = csv.reader(f)
                header = next(reader, [])
                out = []
                for values in reader:
                    if len(values) != len(header):
                        raise BayesprogError(f"{path}:{reader.line_num}: expected "
                                             f"{len(header)} fields, found {len(values)}")
                    out.append((f"{path}:{reader.line_num}", dict(zip(header, values,
                                                                      strict=True))))
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise BayesprogError(f"cannot read {path}: {exc}") from None
        return out, header
    from bayesprog import require_extra

    require_extra("pyarrow", "parquet", f"reading {path}")
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(str(path))
    except (OSError, ValueError) as exc:  # pyarrow's errors are both
        raise BayesprogError(f"cannot read {path}: {exc}") from None
    return ([(f"{path}: row {i + 1}", row) for i, row in enumerate(table.to_pylist())],
            list(table.column_names))


def _blank(value: Any) -> bool:
    return value is None or value == "" or (isinstance(value, float) and math.isnan(value))


def _whole(row: dict[str, Any], column: str) -> int:
    value = row[column]
    try:
        if isinstance(value, str):
            value = int(value)
        if isinstance(value, bool) or int(value) != value or value < 0:
            raise ValueError
    except (TypeError, ValueError):
        raise ValueError(f"column {column!r}: expected a non-negative integer, found "
                         f"{value!r}") from None
    return int(value)


def _real(row: dict[str, Any], column: str) -> float:
    value = row.get(column)
    if _blank(value):
        return math.nan
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"column {column!r}: expected a number, found {value!r}") from None


def _probe(where: str, row: dict[str, Any], perception: Perception,
           shape: tuple[int, ...], columns: dict[str, str]) -> Probe:
    axes = ("ix", "iy", "iz")[: len(shape)]
    cell = tuple(_whole(row, a) for a in axes)
    if not all(i < n for i, n in zip(cell, shape, strict=True)):
        raise ValueError(f"cell {list(cell)} is outside the {' x '.join(map(str, shape))} grid")
    nexts = [row[f"next_{a}"] for a in axes]
    next_cell = None
    if not all(_blank(v) for v in nexts):
        next_cell = tuple(_whole(row, f"next_{a}") for a in axes)
    readings: dict[str, float | str | None] = {}
    for reading in perception.readings:
        raw = row[columns[reading.name]]
        if _blank(raw):
            readings[reading.name] = None
        elif reading.discrete:
            readings[reading.name] = str(raw)
        else:
            readings[reading.name] = _real(row, columns[reading.name])
        reading.value(readings[reading.name])  # a state not declared, a number not finite
    missing = str(row["missing"] or "")
    return Probe(where, _whole(row, "step"), cell, readings,
                 tuple(m for m in missing.split(";") if m), str(row["warnings"] or ""),
                 str(row["material"] or ""), str(row["decided"] or ""),
                 _real(row, "probability"), next_cell,
                 {p: _real(row, f"{p}_ms") for p in (*PHASES, "total")})
