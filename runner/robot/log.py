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
session explored (the scenario, its task, seed and ablations), so that ``bayesprog report
LOG.csv`` can draw it. A CSV log is written row by row and flushed, so an interrupted session
keeps every probe it answered; a Parquet log is written in row groups, the last at the end.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import IO, Any

from bayesprog import BayesprogError
from runner.world.readings import Perception

#: the file kinds a log is written as, by suffix
SUFFIXES = (".csv", ".parquet", ".pq")
#: rows of a Parquet log held before they are written as a row group
ROW_GROUP = 256
#: the timings a row gives, by the explorer's phases
PHASES = ("perception", "cues", "shape", "decision")


def meta_path(path: Path) -> Path:
    """The file beside a log that says what the session explored."""
    return path.with_suffix(".json")


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
        cell = ["ix", "iy", "iz"][:dims]
        self.columns = (["step", *cell, *["x_m", "y_m", "z_m"][:dims], *perception.names,
                         "missing", "warnings", "material", "decided", "probability",
                         *[f"next_{a}" for a in cell], *[f"{p}_ms" for p in PHASES],
                         "total_ms"])
        self.discrete = {r.name for r in perception.readings if r.discrete}
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
        row.update(readings)
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
