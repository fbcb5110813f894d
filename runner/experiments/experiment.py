"""Experiments: tasks x configurations x seeded runs of the exploration loop, and their results.

Randomness is keyed by run, never by batch position: run ``r`` of an experiment with seed ``s``
starts at the ``r``-th of the start cells drawn from ``s``, decides with ``default_rng([s, r, 0])``
and senses with ``default_rng([s, r, 1])``, in every configuration. So the same seed gives the same
numbers whatever the batching, and the configurations are compared on paired runs.

``replications: R`` runs the whole protocol R times, each on a sample of its own: replication
``q`` draws its start cells and every stream from (seed, q) alone
(:mod:`runner.experiments.loop`), and replication 0 is the experiment without replications, stored where it always was. The results
do not depend on R: asking for more replications in a folder keeps the ones it holds.
"""

from __future__ import annotations

import functools
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from bayesprog import (
    BayesprogError,
    SizeError,
    SpecError,
    check_size,
    load_document,
    reference_problem,
)
from runner.attention.explorer import CONFIGURATIONS, Explorer, state_entries
from runner.experiments.executors import progress_bar, run_dask, run_processes
from runner.experiments.loop import (  # noqa: F401  (re-exported: the runs' seeds and start cells)
    decision_seed,
    make_sensor,
    reading_seed,
    start_cell,
    start_cells,
    start_runs,
    steps,
)
from runner.experiments.metrics import BorderDistance
from runner.experiments.store import ResultStore, Unit, config_hash, hold
from runner.world.scenario import Scenario, load_scenario


class TuneSpec(BaseModel):
    """``tune:``: the search of ``bayesprog tune`` (see :mod:`runner.experiments.tune`)."""

    model_config = ConfigDict(extra="forbid")

    training: list[str] = Field(min_length=1, description="scenario files the profiles are "
                                "tuned on (relative to the experiment file)")
    validation: list[str] = Field(min_length=1, description="scenario files, none of the "
                                  "training ones, the tuned profiles are compared on")
    trials: int = Field(40, ge=1, le=10_000, description="candidate profiles evaluated")
    runs: int = Field(20, ge=2, description="runs per scenario and task of each trial")
    validation_runs: int = Field(50, ge=2, description="runs per scenario and task compared")
    iterations: int | None = Field(None, ge=1, description="probes per run (default: the "
                                   "experiment's)")
    objective: Literal["probes", "travel"] = Field(
        "probes", description="area under Gamma over the probes (probes) or over the distance "
        "the hand travels, up to what the hand-chosen profiles travel (travel)")
    parameters: list[str] | None = Field(
        None, min_length=1, description="the searched parameters (names as in tune.md: I.a, "
        "I.b, S.a, S.b, U.a, U.b, shape_weight); the others keep the file's values (default: "
        "all)")
    min_precision: float | None = Field(
        None, gt=0, le=10, description="the share of probes on the border a candidate must "
        "keep on the training scenarios, relative to the hand-chosen profiles' (1: at least as "
        "much; none: any)")


#: the most replications an experiment may ask for (each is the whole protocol again)
MAX_REPLICATIONS = 1000


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
    seed: int = Field(0, ge=0)
    replications: int = Field(1, ge=1, le=MAX_REPLICATIONS, description="how many times the "
                              "protocol runs, each on its own sample of start cells, readings "
                              "and tie-breaks (replication 0 is the experiment itself)")
    chunk: int = Field(25, ge=1, description="runs per stored piece of results")
    tune: TuneSpec | None = None


@dataclass
class Experiment:
    spec: ExperimentSpec
    path: Path
    scenario: Scenario

    def start_cells(self, replication: int = 0) -> np.ndarray:
        """The seeded start cells [runs, dims] of a replication, shared by every task and
        configuration."""
        return start_cells(self.scenario.shape, self.spec.runs, self.spec.seed, replication)


def load_experiment(path: str | Path, replications: int | None = None) -> Experiment:
    """The experiment file at ``path``; ``replications`` replaces the file's ``replications:``
    (``bayesprog run --replications``)."""
    path = Path(path)
    located, spec = load_document(path, ExperimentSpec)
    if replications is not None:
        if not 1 <= replications <= MAX_REPLICATIONS:
            raise BayesprogError(f"--replications: expected a whole number from 1 to "
                                 f"{MAX_REPLICATIONS:,}, found {replications}")
        spec = spec.model_copy(update={"replications": replications})
    problem = reference_problem(path.parent / spec.scenario, "scenario", spec.scenario)
    if problem:
        raise SpecError([located.diagnostic(("scenario",), f"scenario {spec.scenario!r}: "
                                            f"{problem}")])
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
    # what the results of every run take (stored per step, and held together by the report),
    # estimated before anything is allocated
    entries = spec.runs * spec.iterations * (2 + len(CUES)) * len(spec.tasks) \
        * len(spec.configurations) * spec.replications
    try:
        check_size(entries, f"{spec.runs:,} runs of {spec.iterations:,} iterations"
                   + (f" in {spec.replications:,} replications" if spec.replications > 1 else ""))
    except SizeError as exc:
        diags.append(located.diagnostic(("runs",), str(exc)))
    chunk = min(spec.chunk, spec.runs)  # the runs one process explores at once
    try:
        check_size(state_entries(scenario, chunk), f"a chunk of {chunk:,} runs on the "
                   f"{' x '.join(map(str, scenario.shape))} grid", hint="; a smaller chunk "
                   "needs less")
    except SizeError as exc:
        diags.append(located.diagnostic(("chunk",), str(exc)))
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
    replication: int = 0,
) -> dict[str, np.ndarray]:
    """Run the loop for the given runs (of ``replication``) in lockstep. Returns gamma
    [runs, K] and paths [runs, K]."""
    runs = len(run_ids)
    explorer = explorer or Explorer(scenario, task, ablate=CONFIGURATIONS[configuration], runs=runs)
    sensor = start_runs(explorer, starts, seed, run_ids, replication)
    gamma = BorderDistance(scenario.centres, scenario.border(task), runs)
    out_gamma = np.empty((runs, iterations))
    out_paths = np.empty((runs, iterations), dtype=np.int64)
    # the cues behind each probed cell, at that cell (from the decision that chose it; none
    # for the start cell)
    cues = {name: np.full((runs, iterations), np.nan) for name in CUES}
    readings = {READING + name: np.full((runs, iterations), np.nan)
                for name in explorer.readings.names}
    rows = np.arange(runs)
    for step in steps(explorer, sensor, iterations):
        k = step.k
        out_paths[:, k] = step.cells
        for name, values in step.readings.columns().items():
            readings[READING + name][:, k] = values
        out_gamma[:, k] = gamma.probe(step.cells)
        if step.next is not None:
            d, cells = explorer.decision, step.next
            cues["inhibition"][:, k + 1] = d.inhibition[rows, cells]
            cues["saliency"][:, k + 1] = d.saliency[rows, cells]
            cues["uncertainty"][:, k + 1] = d.uncertainty[rows, cells]
            cues["target_probability"][:, k + 1] = explorer.target_probabilities[rows, cells]
    return {"gamma": out_gamma, "paths": out_paths, **cues, **readings}


#: stored per probe beside Gamma and the path: the cues at the probed cell when it was chosen,
#: and its probability under pi_tar's posterior then
CUES = ("inhibition", "saliency", "uncertainty", "target_probability")
#: and each reading of the probe, stored under this prefix and its name (NaN: missing; a
#: discrete reading its state's index)
READING = "reading:"


def mean_sem(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error of the mean over axis 0 (ddof = 1; SEM 0 for a single run)."""
    n = values.shape[0]
    mean = values.mean(axis=0)
    sem = values.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros_like(mean)
    return mean, sem


def units(spec: ExperimentSpec) -> list[Unit]:
    """The experiment cut into (replication, task, configuration, chunk of runs) pieces, in a
    fixed order (replication 0's first, as an experiment without replications)."""
    out = []
    for replication in range(spec.replications):
        for task in spec.tasks:
            for conf in spec.configurations:
                for i, start in enumerate(range(0, spec.runs, spec.chunk)):
                    runs = tuple(range(start, min(start + spec.chunk, spec.runs)))
                    out.append(Unit(task, conf, i, runs, replication))
    return out


#: What a step of a run with the shape cue costs beside one without it (ICP registrations;
#: measured on the paper's experiment, chunks of 100 runs: 0.5 s without it, 0.8-2.2 s with it).
SHAPE_COST = 3.0


def expected_cost(unit: Unit, iterations: int) -> float:
    """A unit's expected work, in steps of a run without the shape cue: the order in which
    workers take the units (the longest first, so that none is left to run alone at the end)."""
    shape = "P(R | O)" not in CONFIGURATIONS.get(unit.configuration, ())
    return len(unit.runs) * iterations * (SHAPE_COST if shape else 1.0)


def stored_experiment(out: str | Path) -> Experiment:
    """The experiment whose results ``out`` holds, rebuilt from the texts stored with them (its
    spec, and every scenario, program and sensor file as they were when it ran): what a report
    draws does not depend on the folder it is asked from, nor on files edited since."""
    import tempfile

    from pydantic import ValidationError

    store = ResultStore(Path(out))
    stored = store.manifest()
    try:
        # the number of replications it was last run with is kept outside the hashed spec
        spec = ExperimentSpec.model_validate(
            {**stored["experiment"], "replications": stored.get("replications", 1)})
        files = {k: (Path(v["path"]), v["text"]) for k, v in stored["files"].items()}
        scenario_path = files["scenario"][0]
    except (KeyError, TypeError, ValidationError) as exc:
        raise BayesprogError(f"{store.manifest_path}: not a readable experiment manifest "
                             f"({str(exc).splitlines()[0]})") from None
    with tempfile.TemporaryDirectory(prefix="bayesprog-stored-") as folder:
        root = Path(folder)

        def mirrored(path: Path) -> Path:  # the same place under the temporary root
            return root / path.resolve().relative_to(path.resolve().anchor)

        for key, (path, text) in files.items():
            if key != "experiment":
                target = mirrored(path)
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_text(text, encoding="utf-8")
        scenario = load_scenario(mirrored(scenario_path))
    scenario.path = scenario_path
    return Experiment(spec, files["experiment"][0], scenario)


def manifest(experiment: Experiment) -> dict:
    """What identifies the results: the spec, the start cells and every file it resolved."""
    scenario = experiment.scenario
    files = {"experiment": experiment.path, "scenario": scenario.path}
    for which in ("perception", "shape", "target"):
        files[which] = scenario.program_path(which)
    if scenario.sensor_model is not None and scenario.sensor_model.path is not None:
        files["sensor_model"] = scenario.sensor_model.path
    files.update(scenario.recordings_paths())  # what a lab's programs are learned from
    return {
        # a search's settings (tune:) do not change what a run computes, nor does the number
        # of replications (each is computed alone): kept beside, outside what the hash covers
        "experiment": experiment.spec.model_dump(exclude={"tune", "replications"}),
        "replications": experiment.spec.replications,
        "start_cells": experiment.start_cells().tolist(),
        "files": {k: {"path": str(v), "text": Path(v).read_text(encoding="utf-8")}
                  for k, v in files.items()},
    }


@functools.lru_cache(maxsize=4)
def _loaded(experiment_path: str, digest: str) -> Experiment:
    experiment = load_experiment(experiment_path)
    if config_hash(manifest(experiment)) != digest:
        raise BayesprogError(f"{experiment_path}, or a file it names, changed while the "
                             "experiment ran: run it again (the finished chunks are kept)")
    return experiment


def compute_unit(experiment_path: str, unit: Unit, digest: str | None = None
                 ) -> dict[str, np.ndarray]:
    """One unit of work, from the experiment file alone (so that any process can do it).
    ``digest``, the configuration's hash (every file it resolved), lets a process load the
    experiment once for all the units of that configuration it computes."""
    experiment = load_experiment(experiment_path) if digest is None else \
        _loaded(experiment_path, digest)
    starts = experiment.start_cells(unit.replication)[list(unit.runs)]
    spec = experiment.spec
    return simulate(experiment.scenario, unit.task, unit.configuration, starts,
                    np.asarray(unit.runs), spec.seed, spec.iterations,
                    replication=unit.replication)


@dataclass(frozen=True)
class _Job:
    """One unit of the experiment at ``path`` (its configuration hash ``digest``), as the
    executors call it: picklable, and reading :func:`compute_unit` when it runs."""

    path: str
    digest: str

    def __call__(self, unit: Unit) -> dict[str, np.ndarray]:
        return compute_unit(self.path, unit, self.digest)


def run_experiment(
    experiment: Experiment,
    out: Path,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool | None = None,
    pool: Any = None,
) -> ResultStore:
    """Compute every unit not yet stored in ``out``, saving each as soon as it is finished.

    ``workers > 1`` uses local processes (those of ``pool`` first, when given: started by
    :func:`~runner.experiments.executors.process_pool` while the caller prepared; it is shut down),
    ``scheduler`` an existing Dask cluster; the numbers do not depend on either, nor on the
    chunk size (randomness is keyed by run). The folder is held while the run writes it
    (:func:`~runner.experiments.store.hold`): a second run, report or search of it is refused.
    """
    with hold(out, "run"):
        return _run(experiment, out, workers, scheduler, progress, pool)


def _run(experiment: Experiment, out: Path, workers: int, scheduler: str | None,
         progress: bool | None, pool: Any) -> ResultStore:
    store = ResultStore(out)
    store.open(manifest(experiment))
    todo = [u for u in units(experiment.spec) if not store.done(u, experiment.spec.iterations)]
    if workers > 1 or scheduler is not None:  # the longest first (the numbers do not change)
        todo.sort(key=lambda u: -expected_cost(u, experiment.spec.iterations))
    for path in store.set_aside:
        print(f"{path}: damaged (it does not read back whole): set aside; its results are "
              "computed again", file=sys.stderr)
    total = len(units(experiment.spec))
    bar = progress_bar(total, "experiment", unit="chunk", done=total - len(todo),
                       enabled=progress, leave=True)
    path = str(experiment.path.resolve())
    digest = store.hash
    assert digest is not None  # set by store.open
    job = _Job(path, digest)
    try:
        if scheduler is not None:
            run_dask(scheduler, job, todo, store, bar, MAX_WORKER_DEATHS, WORKER_TIMEOUT)
        elif workers > 1:
            run_processes(workers, job, todo, store, bar, MAX_WORKER_DEATHS, pool)
        else:
            for unit in todo:
                store.save(unit, compute_unit(path, unit, digest))
                bar.update(1)
    finally:
        bar.close()
    return store


#: How often in a row workers may die before the run stops (each time the units they held
#: are given to new workers); finished units reset the count.
MAX_WORKER_DEATHS = 3
#: Seconds a Dask scheduler may go without any worker before the run stops.
WORKER_TIMEOUT = 60.0


def load_results(store: ResultStore, spec: ExperimentSpec, replication: int = 0
                 ) -> dict[str, dict[str, np.ndarray]]:
    """``{"T1/full": {"gamma": [runs, K], "paths": [runs, K], "runs": [runs]}, ...}`` of one
    replication (0: the experiment itself)."""
    all_units = units(spec)
    return {f"{t}/{c}": store.load(t, c, all_units, replication)
            for t in spec.tasks for c in spec.configurations}


def load_replications(store: ResultStore, spec: ExperimentSpec
                      ) -> list[dict[str, dict[str, np.ndarray]]]:
    """The results of every replication, in order (:func:`load_results` of each)."""
    return [load_results(store, spec, q) for q in range(spec.replications)]
