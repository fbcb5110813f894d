"""``bayesprog tune``: the Beta profiles of pi_tar's cue terms and the weight of its shape cue,
searched to minimise the area under Gamma on training scenarios, then compared with the
file's hand-chosen profiles on validation scenarios that the search never saw.

The search is Optuna's TPE sampler. It is seeded and resumable: trials are kept in a journal
in the output folder as they finish, the sampler of trial ``n`` is seeded from ``(seed, n)``, a
trial interrupted half-way is evaluated again with the parameters it was given, and the
objective is deterministic (every candidate runs from the same start cells with the same
random streams), so a search resumed after Ctrl-C ends exactly where an uninterrupted one does.

The objective of a candidate is the mean, over training (scenario, task) pairs, of its mean area
under Gamma divided by the hand-chosen profiles' (1 for the file's own values; below 1 is
better), so that every pair weighs the same whatever its grid size. The area is over the probes
(``objective: probes``) or over the distance the hand travels, up to what the hand-chosen
profiles travel (``objective: travel``); ``min_precision`` makes candidates that probe the
border less than the hand-chosen profiles (relative share) infeasible, and ``parameters``
leaves the others at the file's values.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bayesprog import (
    BayesprogError,
    SizeError,
    SpecError,
    canonical,
    check_size,
    load_document,
    reference_problem,
)
from runner.attention.explorer import Explorer
from runner.experiments.executors import progress_bar
from runner.experiments.experiment import ExperimentSpec, TuneSpec, simulate, start_cells
from runner.experiments.metrics import area_under, behaviour, moves, paired_test, visits
from runner.experiments.store import LOCK, hold
from runner.world.scenario import Scenario, load_scenario


@dataclass(frozen=True)
class Parameter:
    """One searched number: parameter ``key`` of the term ``term`` of pi_tar."""

    name: str
    term: str
    key: str
    low: float
    high: float
    log: bool
    meaning: str

    def to_file(self, value: float) -> float:
        """The value written in the program (the shape weight is stored as its floor)."""
        return 1.0 - value if self.key == "floor" else value

    def from_file(self, value: float) -> float:
        return 1.0 - value if self.key == "floor" else value


#: what is searched: the Beta profiles of the three cue terms, on a log scale from 1 to 16 (from
#: flat to sharply peaked; below 1 a profile is infinite at a cue value of 0 or 1, which the cue
#: fields reach), and the shape cue's weight, 1 - the floor of its mixture (0: the shape cue is
#: ignored; 0.95: it nearly vetoes cells off the template)
PARAMETERS = (
    Parameter("I.a", "P(I | O)", "a", 1.0, 16.0, True, "inhibition profile, Beta a"),
    Parameter("I.b", "P(I | O)", "b", 1.0, 16.0, True, "inhibition profile, Beta b"),
    Parameter("S.a", "P(S | O, T)", "a", 1.0, 16.0, True, "saliency profile, Beta a"),
    Parameter("S.b", "P(S | O, T)", "b", 1.0, 16.0, True, "saliency profile, Beta b"),
    Parameter("U.a", "P(U | O)", "a", 1.0, 16.0, True, "uncertainty profile, Beta a"),
    Parameter("U.b", "P(U | O)", "b", 1.0, 16.0, True, "uncertainty profile, Beta b"),
    Parameter("shape_weight", "P(R | O)", "floor", 0.0, 0.95, False,
              "shape cue weight, 1 - its mixture's floor"),
)

JOURNAL = "tune.journal"
MANIFEST = "tune-manifest.json"


def terms_of(values: Mapping[str, float]) -> dict[str, dict[str, float]]:
    """The ``terms=`` of :func:`bayesprog.load` that set the searched parameters to ``values``."""
    out: dict[str, dict[str, float]] = {}
    for p in PARAMETERS:
        out.setdefault(p.term, {})[p.key] = float(p.to_file(values[p.name]))
    return out


# evaluation -------------------------------------------------------------------------------------
@dataclass
class Search:
    """A loaded search: the experiment's settings and its training and validation scenarios."""

    path: Path
    spec: ExperimentSpec
    tune: TuneSpec
    training: list[Scenario]
    validation: list[Scenario]

    @property
    def iterations(self) -> int:
        return self.tune.iterations or self.spec.iterations

    @property
    def searched(self) -> tuple[Parameter, ...]:
        names = self.tune.parameters
        return PARAMETERS if names is None else tuple(p for p in PARAMETERS if p.name in names)

    def pairs(self, which: str) -> list[tuple[Scenario, str]]:
        return [(s, t) for s in getattr(self, which) for t in s.spec.tasks]


def load_search(path: str | Path) -> Search:
    """An experiment file with a ``tune:`` section; problems reported at their place."""
    path = Path(path)
    located, spec = load_document(path, ExperimentSpec)
    if spec.tune is None:
        raise SpecError([located.diagnostic((), "no tune: section: expected one naming the "
                                            "training and validation scenarios (see "
                                            "docs/experiments.md)", at_key=False)])
    diags = []
    loaded: dict[str, list[Scenario]] = {"training": [], "validation": []}
    seen: dict[Path, str] = {}
    for which in ("training", "validation"):
        for i, name in enumerate(getattr(spec.tune, which)):
            file = (path.parent / name).resolve()
            problem = reference_problem(file, "scenario", name)
            if problem:
                diags.append(located.diagnostic(("tune", which, i), f"{which} scenario "
                                                f"{name!r}: {problem}"))
                continue
            if file in seen:
                diags.append(located.diagnostic(("tune", which, i), f"{name} is already a "
                                                f"{seen[file]} scenario: the validation "
                                                "scenarios must be others than the training "
                                                "ones, each named once"))
                continue
            seen[file] = which
            loaded[which].append(load_scenario(file))
    known = [p.name for p in PARAMETERS]
    for i, name in enumerate(spec.tune.parameters or []):
        if name not in known:
            diags.append(located.diagnostic(("tune", "parameters", i), f"unknown parameter "
                                            f"{name!r}: expected one of {', '.join(known)}"))
        elif name in (spec.tune.parameters or [])[:i]:
            diags.append(located.diagnostic(("tune", "parameters", i), f"{name} is named "
                                            "twice"))
    # what one evaluation holds (Gamma and the path of every run of every pair), estimated
    # before anything runs
    pairs = sum(len(s.spec.tasks) for s in loaded["training"] + loaded["validation"])
    runs = max(spec.tune.runs, spec.tune.validation_runs)
    try:
        check_size(2 * pairs * runs * (spec.tune.iterations or spec.iterations),
                   f"{runs:,} runs of {spec.tune.iterations or spec.iterations:,} iterations "
                   f"on {pairs} (scenario, task) pairs")
    except SizeError as exc:
        diags.append(located.diagnostic(("tune", "runs"), str(exc)))
    if diags:
        raise SpecError(diags)
    search = Search(path, spec, spec.tune, loaded["training"], loaded["validation"])
    for scenario in search.training + search.validation:
        _check_terms(scenario)
    return search


def _check_terms(scenario: Scenario) -> None:
    """Every searched term is in the scenario's pi_tar with the searched parameters."""
    labels = _terms(scenario)
    for p in PARAMETERS:
        term = labels.get(canonical(p.term) or p.term)
        if term is None or p.key not in term.params:
            raise BayesprogError(f"{scenario.program_path('target')}: the search sets "
                                 f"parameter {p.key!r} of {p.term}, which this program (used "
                                 f"by {scenario.path}) does not have")


def _terms(scenario: Scenario) -> dict[str, Any]:
    """pi_tar's terms by their canonical label (soft evidence, not a term P(...), left out)."""
    labels = ((canonical(term.label), term) for term in scenario.target.terms)
    return {label: term for label, term in labels if label is not None}


def file_values(scenario: Scenario) -> dict[str, float]:
    """The searched parameters as the scenario's pi_tar file writes them (the hand-chosen
    profiles), each a single number."""
    out = {}
    terms = _terms(scenario)
    for p in PARAMETERS:
        value = np.asarray(terms[canonical(p.term) or p.term].params[p.key].array,
                           dtype=float).ravel()
        if value.size != 1 or not np.all(value == value[0]):
            raise BayesprogError(f"{scenario.program_path('target')}: {p.term} {p.key} is "
                                 "given per state; the search sets one number")
        out[p.name] = p.from_file(float(value[0]))
    return out


def evaluate(scenario: Scenario, task: str, values: Mapping[str, float] | None, runs: int,
             iterations: int, seed: int, chunk: int = 25) -> dict[str, np.ndarray]:
    """Gamma [runs, iterations] and the probed cells [runs, iterations] of ``runs`` runs of the
    full model (pi_tar with ``values``, or as the file writes it) from the seeded start cells,
    the same for every candidate; ``chunk`` runs at a time (the numbers do not depend on it)."""
    target = scenario.target if values is None else scenario.load_target(terms_of(values))
    starts = start_cells(scenario.shape, runs, seed)
    gamma, paths = [], []
    for first in range(0, runs, chunk):
        ids = np.arange(first, min(first + chunk, runs))
        explorer = Explorer(scenario, task, runs=len(ids), programs={"target": target})
        result = simulate(scenario, task, "full", starts[ids], ids, seed, iterations,
                          explorer=explorer)
        gamma.append(result["gamma"])
        paths.append(result["paths"])
    return {"gamma": np.concatenate(gamma), "paths": np.concatenate(paths)}


def travelled(scenario: Scenario, paths: np.ndarray) -> np.ndarray:
    """Distance (metres) travelled before each probe [runs, K], from the first probe."""
    return np.concatenate([np.zeros((len(paths), 1)),
                           np.cumsum(moves(paths, scenario.centres), axis=1)], axis=1)


def area_over_distance(gamma: np.ndarray, distance: np.ndarray, budget: float) -> np.ndarray:
    """Area under Gamma against the distance travelled, from 0 to ``budget`` metres, per run:
    Gamma after probe k holds from the distance of probe k to that of probe k + 1, and the last
    value to the budget (square metres).

    >>> area_over_distance(np.array([[3.0, 1.0]]), np.array([[0.0, 2.0]]), 5.0)
    array([9.])
    """
    reached = np.minimum(distance, budget)
    ends = np.concatenate([reached[:, 1:], np.full((len(reached), 1), budget)], axis=1)
    return np.sum(gamma * (ends - reached), axis=1)


def areas(scenario: Scenario, runs: Mapping[str, np.ndarray], objective: str,
          budget: float | None = None) -> np.ndarray:
    """The searched area per run: under Gamma over the probes (``probes``) or over the distance
    travelled up to ``budget`` (``travel``)."""
    if objective == "probes":
        return area_under(runs["gamma"])
    assert budget is not None
    return area_over_distance(runs["gamma"], travelled(scenario, runs["paths"]), budget)


def path_budget(scenario: Scenario, runs: Mapping[str, np.ndarray]) -> float:
    """Mean distance travelled per run (metres): the hand-chosen profiles' budget."""
    return float(travelled(scenario, runs["paths"])[:, -1].mean())


def _evaluate_at(scenario_path: str, task: str, values: Mapping[str, float] | None, runs: int,
                 iterations: int, seed: int) -> dict[str, np.ndarray]:
    """:func:`evaluate` from the scenario's file, for worker processes."""
    return evaluate(_scenario(scenario_path), task, values, runs, iterations, seed)


_SCENARIOS: dict[str, Scenario] = {}


def _scenario(path: str) -> Scenario:
    if path not in _SCENARIOS:
        _SCENARIOS[path] = load_scenario(path)
    return _SCENARIOS[path]


@dataclass(frozen=True)
class _Evaluation:
    """:func:`evaluate` of one candidate, for a (scenario file, task) pair: picklable, as a
    Dask cluster takes it."""

    values: Mapping[str, float] | None
    runs: int
    iterations: int
    seed: int

    def __call__(self, pair: tuple[str, str]) -> dict[str, np.ndarray]:
        return _evaluate_at(pair[0], pair[1], self.values, self.runs, self.iterations,
                            self.seed)


#: How often in a row the workers of a Dask cluster may die on one evaluation (it is then given
#: to others each time) before the search stops; seconds a cluster may go without any worker.
MAX_WORKER_DEATHS = 3
WORKER_TIMEOUT = 60.0


class Evaluator:
    """:func:`evaluate` over many (scenario, task) pairs, in this process, spread over local
    worker processes, or on an existing Dask cluster (``scheduler``: its address); the
    numbers do not depend on which."""

    def __init__(self, workers: int = 1, scheduler: str | None = None):
        self.pool: Any = None
        self.client: Any = None
        self.scheduler = scheduler
        if scheduler is not None:
            from runner.experiments.executors import dask_client

            self.client = dask_client(scheduler)
        elif workers > 1:
            from runner.experiments.executors import process_pool

            self.pool = process_pool(workers)

    def __call__(self, pairs: list[tuple[Scenario, str]], values: Mapping[str, float] | None,
                 runs: int, iterations: int, seed: int) -> list[dict[str, np.ndarray]]:
        if self.pool is None and self.client is None:
            return [evaluate(s, t, values, runs, iterations, seed) for s, t in pairs]
        values = None if values is None else dict(values)
        if self.client is not None:
            from runner.experiments.executors import dask_map

            assert self.scheduler is not None
            found: list[Any] = [None] * len(pairs)
            dask_map(self.client, self.scheduler,
                     _Evaluation(values, runs, iterations, seed),
                     [(str(s.path), t) for s, t in pairs], found.__setitem__,
                     MAX_WORKER_DEATHS, WORKER_TIMEOUT,
                     kept="the finished trials are kept", name=lambda pair: " ".join(pair))
            return found
        futures = [self.pool.submit(_evaluate_at, str(s.path), t, values, runs, iterations, seed)
                   for s, t in pairs]
        return [f.result() for f in futures]

    def close(self) -> None:
        if self.pool is not None:
            from runner.experiments.executors import stop_pool

            stop_pool(self.pool)
        if self.client is not None:
            self.client.close()


# the search -------------------------------------------------------------------------------------
def _manifest(search: Search) -> dict:
    """What the search depends on: its settings and what its files say (keyed by their role, not
    where they are, so a moved checkout resumes its searches)."""
    files = {"experiment": search.path}
    for which in ("training", "validation"):
        for i, scenario in enumerate(getattr(search, which)):
            files[f"{which} {i}"] = scenario.path
            for program in ("target", "perception", "shape"):
                files[f"{which} {i} {program}"] = scenario.program_path(program)
            if scenario.sensor_model is not None and scenario.sensor_model.path is not None:
                files[f"{which} {i} sensor"] = scenario.sensor_model.path
            for role, recorded in scenario.recordings_paths().items():
                files[f"{which} {i} {role}"] = recorded
    return {"tune": search.tune.model_dump(), "seed": search.spec.seed,
            "iterations": search.iterations,
            "files": {k: Path(v).read_text(encoding="utf-8") for k, v in sorted(files.items())}}


def _digest(manifest: dict) -> str:
    return hashlib.sha256(json.dumps(manifest, sort_keys=True).encode()).hexdigest()


def _open_journal(search: Search, out: Path) -> Any:
    """The study kept in ``out``; refused when ``out`` holds the search of other settings."""
    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    if out.exists() and not out.is_dir():
        raise BayesprogError(f"--out {out}: is a file, expected a folder")
    if out.is_dir() and any(f.name != LOCK for f in out.iterdir()) \
            and not (out / MANIFEST).exists():
        raise BayesprogError(f"--out {out}: holds files but no search ({MANIFEST}): choose an "
                             "empty or new folder")
    out.mkdir(parents=True, exist_ok=True)
    manifest_path = out / MANIFEST
    digest = _digest(_manifest(search))
    if manifest_path.exists():
        try:
            stored = json.loads(manifest_path.read_text(encoding="utf-8"))["digest"]
        except (ValueError, KeyError, TypeError):
            raise BayesprogError(f"{manifest_path}: not a readable search manifest") from None
        if stored != digest:
            raise BayesprogError(f"{out} holds a search of other settings or files than "
                                 f"{search.path}'s: choose another --out folder")
    else:
        manifest_path.write_text(json.dumps({"digest": digest}) + "\n", encoding="utf-8")
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    storage = JournalStorage(JournalFileBackend(str(out / JOURNAL)))
    return optuna.create_study(study_name="tune", storage=storage, direction="minimize",
                               load_if_exists=True)


def _distributions(searched: tuple[Parameter, ...]) -> dict[str, Any]:
    from optuna.distributions import FloatDistribution

    return {p.name: FloatDistribution(p.low, p.high, log=p.log) for p in searched}


def _sampler(seed: int, index: int) -> Any:
    """The sampler of the ``index``-th finished trial: seeded from (seed, index), so a resumed
    search draws what an uninterrupted one would."""
    from optuna.samplers import TPESampler

    state = int(np.random.SeedSequence([seed, index]).generate_state(1)[0])
    return TPESampler(seed=state)


def _feasible(trial: Any, min_precision: float | None) -> bool:
    return min_precision is None or trial.user_attrs["precision"] >= min_precision


def run_search(search: Search, out: Path, trials: int | None = None, workers: int = 1,
               progress: bool | None = None, scheduler: str | None = None) -> dict:
    """Run (or resume) the search in ``out``, then validate its best profiles; returns what
    ``tune.json`` holds and writes it with the tuned program (what the search reports,
    ``tune.md`` and its figures, is :func:`runner.report.tuning.write_report`'s)."""
    with hold(out, "tune"):
        return _run_search(search, out, trials, workers, progress, scheduler)


def _run_search(search: Search, out: Path, trials: int | None, workers: int,
                progress: bool | None, scheduler: str | None) -> dict:
    import optuna

    trials = trials or search.tune.trials
    seed = search.spec.seed
    objective = search.tune.objective
    min_precision = search.tune.min_precision
    study = _open_journal(search, out)
    pairs = search.pairs("training")
    evaluator = Evaluator(workers, scheduler)
    try:
        baseline = study.user_attrs.get("baseline")
        if baseline is None:  # the hand-chosen profiles' mean area (and distance) per pair
            baseline = [_measure(s, t, runs, objective) for (s, t), runs in zip(
                pairs, evaluator(pairs, None, search.tune.runs, search.iterations, seed),
                strict=True)]
            study.set_user_attr("baseline", baseline)
        paper = file_values(search.training[0])
        searched = search.searched
        if not study.trials and all(p.low <= paper[p.name] <= p.high for p in searched):
            study.enqueue_trial({p.name: paper[p.name] for p in searched})
        distributions = _distributions(searched)
        finished = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
        bar = progress_bar(trials, "tune", unit="trial", done=min(len(finished), trials),
                           enabled=progress, leave=True)
        try:
            while len(finished) < trials:
                for stale in study.trials:  # interrupted before it finished: asked again
                    if stale.state == optuna.trial.TrialState.RUNNING:
                        study.tell(stale.number, state=optuna.trial.TrialState.FAIL)
                        study.enqueue_trial(stale.params)
                study.sampler = _sampler(seed, len(finished))
                trial = study.ask(distributions)
                found = evaluator(pairs, paper | trial.params, search.tune.runs,
                                  search.iterations, seed)
                ratios = [float(areas(s, runs, objective, b["budget"]).mean()) / b["area"]
                          for (s, _), runs, b in zip(pairs, found, baseline, strict=True)]
                # the share of probes on the border, relative to the hand-chosen profiles'
                # (which, if they never probe it, any candidate keeps: 1)
                hand = float(np.mean([b["precision"] for b in baseline]))
                kept = float(np.mean([_precision(s, t, runs["paths"]) for (s, t), runs
                                      in zip(pairs, found, strict=True)])) / hand if hand else 1.0
                trial.set_user_attr("precision", kept)
                if min_precision is not None:  # Optuna's constrained TPE: <= 0 is feasible
                    trial.set_constraint("precision", min_precision - kept)
                study.tell(trial, float(np.mean(ratios)))
                finished = [t for t in study.trials
                            if t.state == optuna.trial.TrialState.COMPLETE]
                bar.update(1)
        finally:
            bar.close()
        # numbered in the order they finished (a trial asked again after an interruption
        # takes the place of the one it repeats)
        complete = sorted(finished, key=lambda t: t.number)[:trials]
        index, best = min(((i, t) for i, t in enumerate(complete)
                           if _feasible(t, min_precision)),
                          key=lambda it: (it[1].value, it[0]), default=(-1, complete[0]))
        feasible = index >= 0
        index = max(index, 0)  # none keeps the precision asked: the first trial, reported so
        validation = study.user_attrs.get("validation")
        if validation is None or validation.get("trial") != index:
            valid_pairs = search.pairs("validation")
            runs, vseed = search.tune.validation_runs, seed + 1
            hand_runs = evaluator(valid_pairs, None, runs, search.iterations, vseed)
            tuned_runs = evaluator(valid_pairs, paper | best.params, runs, search.iterations,
                                   vseed)
            validation = {"trial": index, "pairs": [
                _compare(s, t, h, u, objective)
                for (s, t), h, u in zip(valid_pairs, hand_runs, tuned_runs, strict=True)]}
            study.set_user_attr("validation", validation)
    finally:
        evaluator.close()
    result = summary(search, complete, index, baseline, validation, paper)
    result["feasible"] = feasible
    write_results(search, out, result)
    return result


def _measure(scenario: Scenario, task: str, runs: Mapping[str, np.ndarray],
             objective: str) -> dict:
    """The hand-chosen profiles' mean area on a pair, the distance budget it sets and their
    share of probes on the border."""
    budget = path_budget(scenario, runs) if objective == "travel" else None
    return {"area": float(areas(scenario, runs, objective, budget).mean()), "budget": budget,
            "precision": _precision(scenario, task, runs["paths"])}


def _precision(scenario: Scenario, task: str, paths: np.ndarray) -> float:
    """Share of the probes that fall on the task's border."""
    return float(scenario.border(task).ravel()[paths].mean())


def _compare(scenario: Scenario, task: str, hand: Mapping[str, np.ndarray],
             tuned: Mapping[str, np.ndarray], objective: str) -> dict:
    """One validation pair: both profiles' areas per run, and how each moved."""
    budget = path_budget(scenario, hand) if objective == "travel" else None
    border = scenario.border(task)
    return {"hand": areas(scenario, hand, objective, budget).tolist(),
            "tuned": areas(scenario, tuned, objective, budget).tolist(),
            "hand_behaviour": _moves(scenario, hand["paths"], border),
            "tuned_behaviour": _moves(scenario, tuned["paths"], border),
            "hand_visits": visits(hand["paths"], len(scenario.centres)).tolist(),
            "tuned_visits": visits(tuned["paths"], len(scenario.centres)).tolist()}


def _moves(scenario: Scenario, paths: np.ndarray, border: np.ndarray) -> dict[str, float]:
    b = behaviour(paths, border, scenario.centres)
    return {"precision": b["precision"], "border_probed": b["border_probed"],
            "path_length": b["path_length"],
            "median_step": float(np.median(moves(paths, scenario.centres)))}


# results ----------------------------------------------------------------------------------------
def summary(search: Search, trials: list, index: int, baseline: list[dict],
            validation: dict, paper: Mapping[str, float]) -> dict:
    """What ``tune.json`` holds: the ``trials`` (finished, in order), the best (``trials[index]``)
    and its validation."""
    from statsmodels.stats.multitest import multipletests

    rows = []
    hand_all, tuned_all = [], []
    for (scenario, task), pair in zip(search.pairs("validation"), validation["pairs"],
                                      strict=True):
        hand, tuned = np.asarray(pair["hand"]), np.asarray(pair["tuned"])
        scale = hand.mean()
        hand_all.append(hand / scale)
        tuned_all.append(tuned / scale)
        rows.append({"scenario": scenario.name, "task": task, "runs": int(hand.size),
                     "auc_hand": float(hand.mean()), "auc_hand_sem": _sem(hand),
                     "auc_tuned": float(tuned.mean()), "auc_tuned_sem": _sem(tuned),
                     "ratio": float(tuned.mean() / scale), "p": paired_test(tuned, hand),
                     "hand_behaviour": pair["hand_behaviour"],
                     "tuned_behaviour": pair["tuned_behaviour"],
                     "hand_visits": pair["hand_visits"], "tuned_visits": pair["tuned_visits"]})
    adjusted = multipletests([r["p"] for r in rows], method="holm")[1]
    for row, value in zip(rows, adjusted, strict=True):
        row["p_holm"] = float(value)
    hand_pooled, tuned_pooled = np.concatenate(hand_all), np.concatenate(tuned_all)
    pooled = {"pairs": len(rows), "runs": int(hand_pooled.size),
              "ratio": float(tuned_pooled.mean()),
              "p": paired_test(tuned_pooled, hand_pooled),
              "better": int(sum(r["ratio"] < 1 and r["p_holm"] < 0.05 for r in rows)),
              "worse": int(sum(r["ratio"] > 1 and r["p_holm"] < 0.05 for r in rows))}
    training = [{"scenario": s.name, "task": t, "auc_hand": b["area"], "budget": b["budget"],
                 "precision_hand": b["precision"]}
                for (s, t), b in zip(search.pairs("training"), baseline, strict=True)]
    return {
        "experiment": str(search.path), "objective": search.tune.objective,
        "seed": search.spec.seed, "iterations": search.iterations,
        "training_runs": search.tune.runs, "validation_runs": search.tune.validation_runs,
        "training": training,
        "validation_scenarios": sorted({s.name for s in search.validation}),
        "parameters": [{"name": p.name, "term": p.term, "key": p.key, "meaning": p.meaning,
                        "low": p.low, "high": p.high, "hand": paper[p.name],
                        "searched": p in search.searched,
                        "tuned": float((paper | trials[index].params)[p.name])}
                       for p in PARAMETERS],
        "best_trial": index, "best_objective": float(trials[index].value),
        "min_precision": search.tune.min_precision,
        "trials": [{"number": i, "objective": float(t.value), "params": t.params,
                    "precision": t.user_attrs["precision"]} for i, t in enumerate(trials)],
        "validation": rows, "pooled": pooled,
    }


def _sem(values: np.ndarray) -> float:
    return float(values.std(ddof=1) / math.sqrt(values.size)) if values.size > 1 else 0.0


def tuned_path(search: Search, out: Path) -> Path:
    """Where the search writes the training scenarios' pi_tar with the tuned profiles."""
    return out / f"{search.training[0].program_path('target').stem}.tuned.yaml"


def write_results(search: Search, out: Path, result: dict) -> Path:
    """``tune.json`` and the tuned program in ``out``; returns the program's path."""
    (out / "tune.json").write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    tuned_file = tuned_path(search, out)
    tuned_file.write_text(tuned_program(search, result, out), encoding="utf-8")
    return tuned_file


def tuned_program(search: Search, result: dict, out: Path) -> str:
    """The training scenarios' pi_tar file with the tuned parameters written in place (its
    comments and layout kept, its sub-programs named from ``out``)."""
    from bayesprog import render_values

    path = search.training[0].program_path("target")
    values = {p["name"]: p["tuned"] for p in result["parameters"]}
    params = terms_of({k: float(f"{v:.6g}") for k, v in values.items()})
    scenarios = ", ".join(sorted({r["scenario"] for r in result["training"]}))
    return render_values(path.read_text(encoding="utf-8"), params, header=(
        f"Profiles tuned by bayesprog tune on {scenarios} (trial {result['best_trial']}, "
        f"objective {result['best_objective']:.4f})"), moved=(path.parent, out))
