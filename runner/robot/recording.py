"""Recording a lab's own sensor, line by line: ``bayesprog record SCENARIO --stdio -o FILE.csv``
(or ``--ros``), the lab's driver sending each press it made.

A line is one press: the readings by name, as a probe gives them (``"readings": {...}``, or
beside the other keys as the paper's lines do), and where it was made: the material pressed,
``{"material": "steel", "readings": {"pdc": 17.2, ...}}``, or a cell of the scenario's layout,
``{"cell": [ix, iy], "readings": {...}}``, whose material the layout gives (both: they must
agree). A reading left out, null or NaN is missing (an empty cell of the file); a press with no
reading at all is refused. The reply is ``{"recorded": n, "material": name}``, n the presses
recorded so far; a malformed line gets ``{"error": "line N: ..."}`` and nothing is recorded.

The file is the recordings format (what ``programs: perception: {recordings: FILE}``, ``sensor:
{resample: FILE}`` and ``bayesprog learn --column material=M`` read): ``material``, the readings
by name, and ``ix, iy(, iz)`` where a cell was given. It is written row by row and flushed, so
an interrupted session keeps every press it answered.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import IO

import numpy as np

from bayesprog import BayesprogError, short_repr
from runner.robot.session import Refused, checked_cell, screened
from runner.world.readings import ReadingError, shown
from runner.world.scenario import Scenario

#: the keys a recording line may hold beside the readings
RECORD_KEYS = frozenset({"material", "cell", "readings"})


class Recorder:
    """Writes the presses of a lab's sensor on ``scenario`` to ``out`` as recordings; with a
    ``secret``, only the lines that carry it (as the explorer's session takes them)."""

    def __init__(self, scenario: Scenario, out: Path, secret: str | None = None):
        self.scenario = scenario
        self.secret = secret
        self.perception = scenario.readings
        self.out = out
        dims = scenario.dims
        self.columns = ["material", *self.perception.names, *["ix", "iy", "iz"][:dims]]
        try:  # folders the user names, never made
            self._file: IO[str] = out.open("w", newline="")
        except OSError as exc:
            raise BayesprogError(f"cannot write {out}: {exc.strerror or exc}") from None
        self._csv = csv.writer(self._file)
        self._csv.writerow(self.columns)
        self._file.flush()
        self.line_no = 0
        self.recorded = 0
        self.per_material: dict[str, int] = {}

    def answer(self, line: str) -> dict | None:
        """The reply to one line (None for a blank one, counted all the same)."""
        self.line_no += 1
        if not line.strip():
            return None
        try:
            return self._record(screened(line, self.secret, self.line_no, "nothing recorded"))
        except Refused as refused:
            return refused.reply
        except (ValueError, BayesprogError) as exc:
            return {"error": f"line {self.line_no}: {exc}"}

    def _record(self, obj: dict) -> dict:
        names = self.perception.names
        beside = {k: v for k, v in obj.items() if k in names}
        extra = sorted(set(obj) - RECORD_KEYS - set(beside))
        if extra:
            from bayesprog import did_you_mean

            raise ValueError(f"unknown key(s) {', '.join(map(repr, extra))}"
                             + did_you_mean(extra[0], sorted(RECORD_KEYS | set(names)))
                             + f": expected material or cell, and the readings "
                             f"({', '.join(names)})")
        sent = obj.get("readings", beside)
        if "readings" in obj and (beside or not isinstance(sent, dict)):
            raise ValueError("expected the readings either under 'readings' (an object of "
                             "name: value) or beside the other keys, not both")
        readings = self.perception.readings_of(sent)
        if readings.missing.all():
            raise ReadingError(f"nothing recorded: the press gives none of the readings "
                               f"{', '.join(names)}")
        material, cell = self._where(obj)
        values = shown(self.perception, readings)
        row = [material, *["" if values[n] is None else values[n] for n in names]]
        row += cell if cell is not None else [""] * self.scenario.dims
        self._csv.writerow(row)
        self._file.flush()
        self.recorded += 1
        self.per_material[material] = self.per_material.get(material, 0) + 1
        return {"recorded": self.recorded, "material": material}

    def _where(self, obj: dict) -> tuple[str, list[int] | None]:
        materials = self.perception.materials
        shape = self.scenario.shape
        cell = checked_cell(obj["cell"], shape) if "cell" in obj else None
        if "material" in obj:
            material = obj["material"]
            if not isinstance(material, str) or material not in materials:
                from bayesprog import did_you_mean

                raise ValueError(f"unknown material {short_repr(material, 40)}: expected one of "
                                 f"{', '.join(materials)}"
                                 + did_you_mean(str(material), materials))
        elif cell is None:
            raise ValueError("expected where the press was made: 'material' (its name) or "
                             "'cell' (of the scenario's layout)")
        if cell is not None:
            flat = int(np.ravel_multi_index(tuple(cell), shape))
            laid = self.scenario.materials[int(self.scenario.material_map.ravel()[flat])]
            if "material" in obj and obj["material"] != laid:
                raise ValueError(f"cell {cell} is {laid} in the scenario's layout, not "
                                 f"{obj['material']}: expected the two to agree")
            material = laid
        return material, cell

    def close(self) -> None:
        self._file.close()

    def summary(self) -> str:
        counts = ", ".join(f"{m} {n}" for m, n in sorted(self.per_material.items()))
        return (f"{self.out}: {self.recorded} press(es) recorded"
                + (f" ({counts})" if counts else ""))


def serve(recorder: Recorder, stdin: IO[str], stdout: IO[str]) -> int:
    """Record the presses of standard input until its end; returns the presses recorded."""
    from runner.robot.stdio import _lines

    for line in _lines(stdin):
        reply = recorder.answer(line)
        if reply is None:
            continue
        stdout.write(json.dumps(reply) + "\n")
        stdout.flush()
    return recorder.recorded

