"""Experiments: tasks x configurations x seeded runs of the exploration loop, and their results.

Randomness is keyed by run, never by batch position: run ``r`` of an experiment with seed ``s``
starts at the ``r``-th of the start cells drawn from ``s``, decides with ``default_rng([s, r, 0])``
and senses with ``default_rng([s, r, 1])``, in every configuration. So the same seed gives the same
numbers whatever the batching, and the configurations are compared on paired runs.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from bayesprog.errors import SpecError
from bayesprog.spec.yamlload import load_yaml
from runner.explorer import CONFIGURATIONS, Explorer
from runner.metrics import BorderDistance
from runner.scenario import Scenario, load_scenario
from runner.sensor import SyntheticSensor


class ExperimentSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")

    experiment: int = Field(1, ge=1, le=1)
    name: str
    description: str = ""
    runner: str = "haptic"
    scenario: str
    tasks: list[str] = Field(min_length=1)
    configurations: list[str] = Field(min_length=1)
    runs: int = Field(ge=1)
    iterations: int = Field(ge=1)
    seed: int = 0


@dataclass
class Experiment:
    spec: ExperimentSpec
    path: Path
    scenario: Scenario

    def start_cells(self) -> np.ndarray:
        """The seeded start cells [runs, 2], shared by every task and configuration."""
        rng = np.random.default_rng([self.spec.seed, 0xC0FFEE])
        nx, ny = self.scenario.shape
        return np.stack([rng.integers(0, nx, self.spec.runs), rng.integers(0, ny, self.spec.runs)], 1)


def load_experiment(path: str | Path) -> Experiment:
    path = Path(path)
    located, problems = load_yaml(path.read_text(encoding="utf-8"), str(path))
    if problems:
        raise SpecError(problems)
    try:
        spec = ExperimentSpec.model_validate(located.data)
    except ValidationError as exc:
        raise SpecError([
            located.diagnostic(tuple(e["loc"]), f"{'.'.join(map(str, e['loc']))}: "
                               f"{e['msg'].removeprefix('Value error, ')}")
            for e in exc.errors()
        ]) from None
    scenario = load_scenario((path.parent / spec.scenario).resolve())
    diags = []
    for i, task in enumerate(spec.tasks):
        if task not in scenario.spec.tasks:
            diags.append(located.diagnostic(("tasks", i), f"unknown task {task!r}: expected one "
                                            f"of {', '.join(scenario.spec.tasks)}"))
    for i, conf in enumerate(spec.configurations):
        if conf not in CONFIGURATIONS:
            diags.append(located.diagnostic(("configurations", i), f"unknown configuration "
                                            f"{conf!r}: expected one of {', '.join(CONFIGURATIONS)}"))
    if diags:
        raise SpecError(diags)
    return Experiment(spec, path, scenario)


def simulate(
    scenario: Scenario,
    task: str,
    configuration: str,
    starts: np.ndarray,
    run_ids: np.ndarray,
    seed: int,
    iterations: int,
    explorer: Explorer | None = None,
) -> dict[str, np.ndarray]:
    """Run the loop for the given runs in lockstep. Returns gamma [runs, K] and paths [runs, K]."""
    runs = len(run_ids)
    explorer = explorer or Explorer(scenario, task, ablate=CONFIGURATIONS[configuration], runs=runs)
    explorer.reset(starts, seed=[(seed, int(r), 0) for r in run_ids])
    sensor = SyntheticSensor(scenario.material_map, explorer.perception,
                             [(seed, int(r), 1) for r in run_ids], scenario.spec.sensor.extra_noise)
    gamma = BorderDistance(scenario.centres, scenario.border(task), runs)
    out_gamma = np.empty((runs, iterations))
    out_paths = np.empty((runs, iterations), dtype=np.int64)
    cells = explorer.expected
    for k in range(iterations):
        texture, compliance = sensor.probe(cells)
        out_paths[:, k] = cells
        out_gamma[:, k] = gamma.probe(cells)
        if k + 1 < iterations:
            cells = explorer.step(cells, texture, compliance)
        else:
            explorer.perceive(cells, texture, compliance)
    return {"gamma": out_gamma, "paths": out_paths}


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that a reader never sees a partial file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def mean_sem(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error of the mean over axis 0 (ddof = 1; SEM 0 for a single run)."""
    n = values.shape[0]
    mean = values.mean(axis=0)
    sem = values.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros_like(mean)
    return mean, sem


def run_quick(experiment: Experiment, out: Path, progress: bool = False) -> dict[str, dict]:
    """Every task x configuration, all runs in one batch; writes results and figures to ``out``."""
    spec = experiment.spec
    starts = experiment.start_cells()
    run_ids = np.arange(spec.runs)
    results: dict[str, dict] = {}
    for task in spec.tasks:
        for conf in spec.configurations:
            res = simulate(experiment.scenario, task, conf, starts, run_ids, spec.seed,
                           spec.iterations)
            key = f"{task}/{conf}"
            results[key] = res
            mean, _ = mean_sem(res["gamma"])
            if progress:
                print(f"{key}: final Gamma {mean[-1]:.3f} m (mean over {spec.runs} runs)")
    out.mkdir(parents=True, exist_ok=True)
    summary = {
        "experiment": spec.model_dump(),
        "start_cells": starts.tolist(),
        "results": {
            key: {"gamma": r["gamma"].tolist(), "paths": r["paths"].tolist()}
            for key, r in results.items()
        },
    }
    atomic_write(out / "results.json", json.dumps(summary).encode())
    lines = ["task,configuration,k,gamma_mean,gamma_sem"]
    for key, r in results.items():
        task, conf = key.split("/")
        mean, sem = mean_sem(r["gamma"])
        lines += [f"{task},{conf},{k},{m:.6f},{s:.6f}" for k, (m, s) in enumerate(zip(mean, sem, strict=True))]
    atomic_write(out / "gamma.csv", ("\n".join(lines) + "\n").encode())
    from runner.plots import plot_gamma, plot_visits

    for task in spec.tasks:
        subset = {c: results[f"{task}/{c}"] for c in spec.configurations}
        plot_gamma(subset, out / f"gamma_{task}.png", title=f"Task {task}")
        plot_visits(experiment.scenario, task, subset, out / f"visits_{task}.png")
    return results
