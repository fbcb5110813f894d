"""``bayesprog record SCENARIO --presses N --seed S -o FILE.csv``: labelled presses, as a lab
records them to learn pi_per: N presses at random cells of each material of the scenario's
layout, one row each, ``material`` and the readings by name first (the columns a scenario's
``programs: perception: {recordings: FILE.csv}`` reads: for the paper's program
``material,texture,compliance``), then the cell and, with physics probes, the raw figures
(normal force in N, depth in m, friction ratio, the tangential force's fluctuation in N) and
every other feature of the press by its name (:data:`runner.world.physics.FEATURES`: those a
scenario can map its readings to). With ``--traces FILE.npz`` the per-step force and height traces too.

Press i of material m is seeded by (S, m, i): its cell, its positioning error and its noise, so
a file is the same whatever else is recorded.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bayesprog import BayesprogError, atomic_write
from runner.experiments.loop import make_sensor
from runner.world.physics import FEATURES, Probe, ProbeSpec, press_cells
from runner.world.scenario import Scenario

#: the raw figures of a physics press, and their columns (with their units)
RAW_COLUMNS = {"force": "force_n", "depth": "depth_m", "friction_ratio": "friction_ratio",
               "tangential_sd": "tangential_sd_n"}

#: the most presses per material a command may ask for
MAX_PRESSES = 10_000


def record(scenario: Scenario, presses: int, seed: int, physics: ProbeSpec | None = None,
           keep_traces: bool = False, progress: Any = None
           ) -> tuple[dict[str, list], dict[str, np.ndarray]]:
    """The table of the presses (columns as written) and, with physics probes and
    ``keep_traces``, their traces [rows, steps] per signal. ``progress``: called with the
    presses done after each material."""
    if not 1 <= presses <= MAX_PRESSES:
        raise BayesprogError(f"--presses: expected 1 to {MAX_PRESSES:,}, found {presses}")
    names = scenario.readings.names
    table: dict[str, list] = {"material": [], **{n: [] for n in names}, "ix": [], "iy": []}
    traces: dict[str, list] = {}
    done = 0
    for m, cells in press_cells(scenario.material_map, presses, seed):
        seeds = [(seed, m, i) for i in range(presses)]
        sensor = make_sensor(scenario, seeds, physics)
        readings = sensor.probe(cells)
        if not set(readings.names) <= set(names):
            raise BayesprogError(f"the fingertip gives the readings "
                                 f"{', '.join(readings.names)}, the perception program reads "
                                 f"{', '.join(names)}: map each of its readings to a feature "
                                 "under the scenario's sensor: physics: readings: {READING: "
                                 "FEATURE}")
        probes: list[Probe] = getattr(sensor, "last", [])
        index = np.unravel_index(cells, scenario.shape)
        table["material"] += [scenario.materials[m]] * presses
        for reading in scenario.readings.readings:
            given = (readings[reading.name] if reading.name in readings.names
                     else np.full(presses, np.nan))  # a reading the fingertip does not give
            table[reading.name] += [_written(reading.shown(float(v))) for v in given]
        table["ix"] += [int(i) for i in index[0]]
        table["iy"] += [int(i) for i in index[1]]
        for probe in probes:
            mapped = dict(sensor.scene.spec.readings)  # type: ignore[attr-defined]
            for column, value in figures_of(probe, mapped).items():
                table.setdefault(column, []).append(float(f"{value:.6g}"))
            for key, values in probe.traces.items() if keep_traces else ():
                traces.setdefault(key, []).append(values)
        done += presses
        if progress is not None:
            progress(done)
    return table, {key: np.stack(rows) for key, rows in traces.items()}


def figures_of(probe: Probe, mapped: dict[str, str]) -> dict[str, float]:
    """A physics press's raw figures (by :data:`RAW_COLUMNS`) and every other feature (by its
    name), written beside its readings (``mapped``: reading -> feature): a feature a reading
    of its name already is, is not written twice; a column another reading has is named
    ``feature_NAME``."""
    out = {column: (key, float(getattr(probe, key))) for key, column in RAW_COLUMNS.items()}
    out.update({feature: (feature, float(probe.features[feature])) for feature in FEATURES
                if feature not in RAW_COLUMNS})
    return {(f"feature_{column}" if column in mapped else column): value
            for column, (feature, value) in out.items() if mapped.get(column) != feature}


def _written(value: float | str | None) -> float | str | None:
    """A reading as a recordings file holds it: six significant digits, a state by its name,
    empty where missing."""
    return float(f"{value:.6g}") if isinstance(value, float) else value


def write(table: dict[str, list], out: Path, traces: dict[str, np.ndarray] | None = None,
          traces_out: Path | None = None) -> None:
    """The table as CSV at ``out`` (and the traces as a compressed ``.npz``), each written
    whole or not at all."""
    import io

    import pandas as pd

    if traces_out is not None and not traces:
        raise BayesprogError("--traces: only physics probes have traces (add --physics, or "
                             "a scenario whose sensor is physics:)")
    try:  # folders the user names, never made
        atomic_write(out, pd.DataFrame(table).to_csv(index=False).encode(), parents=False)
        if traces_out is not None:
            buffer = io.BytesIO()
            np.savez_compressed(buffer, **traces)  # type: ignore[arg-type]
            atomic_write(traces_out, buffer.getvalue(), parents=False)
    except OSError as exc:
        raise BayesprogError(f"cannot write {exc.filename or out}: {exc.strerror or exc}") \
            from None
