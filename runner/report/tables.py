"""An experiment's stored runs as one tidy table: a row per (task, configuration, replication,
run, step), for pandas, R or a spreadsheet (``bayesprog results DIR -o runs.parquet``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bayesprog import BayesprogError, atomic_write, require_extra
from runner.experiments.executors import progress_bar
from runner.experiments.experiment import CUES, READING, load_replications, stored_experiment
from runner.experiments.metrics import border_band
from runner.experiments.store import ResultStore
from runner.report.figures import centre_cm

#: the table's columns, in order, with what each holds
COLUMNS = {
    "task": "the task (T1, T2, ...)",
    "configuration": "full, or the ablated term (without_S, ...)",
    "replication": "the replication of the protocol (0: the experiment itself), each with its "
                   "own start cells and streams",
    "run": "the run (same start cell and seeds in every configuration)",
    "step": "k, from 0 (the start cell)",
    "cell": "the probed cell (flat index, x-major)",
    "ix": "its index along x, as explore names cells [ix, iy]",
    "iy": "its index along y",
    "iz": "its index along z (in a volume; absent on a 2-D grid)",
    "x_cm": "its centre, cm",
    "y_cm": "its centre, cm",
    "z_cm": "its centre, cm (in a volume; absent on a 2-D grid)",
    "near_border": "within one cell of the task's ground-truth border",
    "gamma_m": "Gamma(k): summed distance from the border cells to the probed ones, m",
    "inhibition": "I at the probed cell when it was chosen (none at step 0)",
    "saliency": "S there (NaN: not observed, or step 0)",
    "uncertainty": "U there",
    "target_probability": "its probability under pi_tar's posterior when it was chosen",
}
#: then one column per reading of the scenario's perception, by its name (empty: missing; a
#: discrete reading by its state), prefixed ``reading_`` where a name is one of the columns


def runs_table(out: str | Path) -> Any:
    """The stored runs of the experiment in ``out`` as a pandas DataFrame (COLUMNS)."""
    import pandas as pd

    store = ResultStore(Path(out))
    experiment = stored_experiment(out)
    spec, scenario = experiment.spec, experiment.scenario
    replications = load_replications(store, spec)
    frames = []
    bar = progress_bar(len(spec.tasks) * len(spec.configurations) * len(replications),
                       "runs table")
    for task in spec.tasks:
        band = border_band(scenario.border(task)).ravel()
        for conf in spec.configurations:
            for replication, results in enumerate(replications):
                r = results[f"{task}/{conf}"]
                paths = r["paths"]
                runs, steps = paths.shape
                x, y = centre_cm(scenario, paths.ravel())
                indices = np.unravel_index(paths.ravel(), scenario.shape)
                columns = {
                    "task": np.full(paths.size, task), "configuration": np.full(paths.size, conf),
                    "replication": np.full(paths.size, replication),
                    "run": np.repeat(r["runs"], steps), "step": np.tile(np.arange(steps), runs),
                    "cell": paths.ravel(),
                    **{axis: index for axis, index in zip(("ix", "iy", "iz"), indices, strict=False)},
                    "x_cm": x, "y_cm": y,
                    "near_border": band[paths.ravel()], "gamma_m": r["gamma"].ravel()}
                if scenario.dims == 3:
                    columns["z_cm"] = scenario.centres[paths.ravel(), 2] * 100
                for name in CUES:
                    columns[name] = r.get(name, np.full(paths.shape, np.nan)).ravel()
                for reading in scenario.readings.readings:  # results of before: not stored
                    values = r.get(READING + reading.name)
                    if values is None:
                        continue
                    column = reading.name if reading.name not in COLUMNS else \
                        f"reading_{reading.name}"
                    flat = values.ravel()
                    columns[column] = flat if reading.states is None else pd.Categorical(
                        [None if np.isnan(v) else reading.states[int(v)] for v in flat],
                        categories=list(reading.states))
                frames.append(pd.DataFrame(columns))
                bar.update(1)
    bar.close()
    table = pd.concat(frames, ignore_index=True)
    for name in ("task", "configuration"):
        table[name] = table[name].astype("category")
    readings = [c for c in table.columns if c not in COLUMNS]
    return table[[c for c in COLUMNS if c in table.columns] + readings]


def write_runs(out: str | Path, path: str | Path) -> tuple[Path, int]:
    """Write the runs table to ``path``: Parquet (.parquet) or CSV (.csv); (path, rows)."""
    import io

    path = Path(path)
    if path.suffix.lower() not in (".parquet", ".pq", ".csv"):
        raise BayesprogError(f"-o {path}: expected a .parquet or .csv file, found "
                             f"{path.suffix or 'no suffix'}")
    if path.suffix.lower() in (".parquet", ".pq"):  # said before the table is built
        require_extra("pyarrow", "parquet", f"writing {path}")
    table = runs_table(out)
    if path.suffix.lower() in (".parquet", ".pq"):
        require_extra("pyarrow", "parquet", f"writing {path}")
        buffer = io.BytesIO()
        table.to_parquet(buffer, index=False)
        data = buffer.getvalue()
    elif path.suffix.lower() == ".csv":
        data = table.to_csv(index=False).encode()
    else:
        raise BayesprogError(f"-o {path}: expected a .parquet or .csv file, found "
                             f"{path.suffix or 'no suffix'}")
    try:
        atomic_write(path, data, parents=False)  # a folder the user names, never made
    except OSError as exc:
        raise BayesprogError(f"cannot write {path}: {exc.strerror or exc}") from None
    return path, len(table)
