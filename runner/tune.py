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
better), so that every pair weighs the same whatever its grid size.
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bayesprog.errors import BayesprogError, SpecError
from bayesprog.expressions import ExpressionError, parse_expression
from bayesprog.language.document import load_document
from runner.experiment import ExperimentSpec, TuneSpec, progress_bar, simulate, start_cells
from runner.explorer import Explorer
from runner.report import area_under, paired_test
from runner.scenario import Scenario, load_scenario


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
            if not file.is_file():
                diags.append(located.diagnostic(("tune", which, i), f"no scenario file "
                                                f"{name!r} (looked for {file})"))
                continue
            if file in seen:
                diags.append(located.diagnostic(("tune", which, i), f"{name} is already a "
                                                f"{seen[file]} scenario: the validation "
                                                "scenarios must be others than the training "
                                                "ones, each named once"))
                continue
            seen[file] = which
            loaded[which].append(load_scenario(file))
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
        term = labels.get(str(parse_expression(p.term)))
        if term is None or p.key not in term.params:
            raise BayesprogError(f"{scenario.program_path('target')}: the search sets "
                                 f"parameter {p.key!r} of {p.term}, which this program (used "
                                 f"by {scenario.path}) does not have")


def _terms(scenario: Scenario) -> dict[str, Any]:
    """pi_tar's terms by their canonical label (soft evidence, not a term P(...), left out)."""
    out = {}
    for term in scenario.target.terms:
        try:
            out[str(parse_expression(term.label))] = term
        except ExpressionError:
            continue
    return out


def file_values(scenario: Scenario) -> dict[str, float]:
    """The searched parameters as the scenario's pi_tar file writes them (the hand-chosen
    profiles), each a single number."""
    out = {}
    terms = _terms(scenario)
    for p in PARAMETERS:
        value = np.asarray(terms[str(parse_expression(p.term))].params[p.key].array, float)
        if value.size != 1 or not np.all(value == value.flat[0]):
            raise BayesprogError(f"{scenario.program_path('target')}: {p.term} {p.key} is "
                                 "given per state; the search sets one number")
        out[p.name] = p.from_file(float(value.flat[0]))
    return out


def evaluate(scenario: Scenario, task: str, values: Mapping[str, float] | None, runs: int,
             iterations: int, seed: int) -> np.ndarray:
    """Area under Gamma of ``runs`` runs of the full model (pi_tar with ``values``, or as the
    file writes it), from the seeded start cells: the same for every candidate."""
    target = scenario.target if values is None else scenario.load_target(terms_of(values))
    explorer = Explorer(scenario, task, runs=runs, programs={"target": target})
    result = simulate(scenario, task, "full", start_cells(scenario.shape, runs, seed),
                      np.arange(runs), seed, iterations, explorer=explorer)
    return area_under(result["gamma"])


def _evaluate_at(scenario_path: str, task: str, values: Mapping[str, float] | None, runs: int,
                 iterations: int, seed: int) -> np.ndarray:
    """:func:`evaluate` from the scenario's file, for worker processes."""
    return evaluate(_scenario(scenario_path), task, values, runs, iterations, seed)


_SCENARIOS: dict[str, Scenario] = {}


def _scenario(path: str) -> Scenario:
    if path not in _SCENARIOS:
        _SCENARIOS[path] = load_scenario(path)
    return _SCENARIOS[path]


class Evaluator:
    """Areas under Gamma of many (scenario, task) pairs, in this process or spread over local
    worker processes (the numbers do not depend on which)."""

    def __init__(self, workers: int = 1):
        self.pool = None
        if workers > 1:
            import multiprocessing
            import os
            from concurrent.futures import ProcessPoolExecutor

            from runner.experiment import _worker_init

            self.pool = ProcessPoolExecutor(
                max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                initializer=_worker_init, initargs=(os.getpid(),))

    def __call__(self, pairs: list[tuple[Scenario, str]], values: Mapping[str, float] | None,
                 runs: int, iterations: int, seed: int) -> list[np.ndarray]:
        if self.pool is None:
            return [evaluate(s, t, values, runs, iterations, seed) for s, t in pairs]
        values = None if values is None else dict(values)
        futures = [self.pool.submit(_evaluate_at, str(s.path), t, values, runs, iterations, seed)
                   for s, t in pairs]
        return [f.result() for f in futures]

    def close(self) -> None:
        if self.pool is not None:
            from runner.experiment import _stop

            _stop(self.pool)


# the search -------------------------------------------------------------------------------------
def _manifest(search: Search) -> dict:
    files = {"experiment": search.path}
    for which in ("training", "validation"):
        for scenario in getattr(search, which):
            files[f"{which}:{scenario.path}"] = scenario.path
            files[f"target:{scenario.path}"] = scenario.program_path("target")
            files[f"perception:{scenario.path}"] = scenario.program_path("perception")
            files[f"shape:{scenario.path}"] = scenario.program_path("shape")
            if scenario.sensor_model is not None and scenario.sensor_model.path is not None:
                files[f"sensor:{scenario.path}"] = scenario.sensor_model.path
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


def _distributions() -> dict[str, Any]:
    from optuna.distributions import FloatDistribution

    return {p.name: FloatDistribution(p.low, p.high, log=p.log) for p in PARAMETERS}


def _sampler(seed: int, number: int) -> Any:
    """Trial ``number``'s sampler: seeded from (seed, number), so a resumed search draws what an
    uninterrupted one would."""
    from optuna.samplers import TPESampler

    state = int(np.random.SeedSequence([seed, number]).generate_state(1)[0])
    return TPESampler(seed=state)


def run_search(search: Search, out: Path, trials: int | None = None, workers: int = 1,
               progress: bool | None = None) -> dict:
    """Run (or resume) the search in ``out``, then validate its best profiles; returns what
    ``tune.json`` holds and writes it with ``tune.md``, ``tune.png`` and the tuned program."""
    import optuna

    trials = trials or search.tune.trials
    seed = search.spec.seed
    study = _open_journal(search, out)
    pairs = search.pairs("training")
    evaluator = Evaluator(workers)
    try:
        baseline = study.user_attrs.get("baseline")
        if baseline is None:
            areas = evaluator(pairs, None, search.tune.runs, search.iterations, seed)
            baseline = [float(a.mean()) for a in areas]
            study.set_user_attr("baseline", baseline)
        paper = file_values(search.training[0])
        if not study.trials and all(p.low <= paper[p.name] <= p.high for p in PARAMETERS):
            study.enqueue_trial(paper)
        distributions = _distributions()
        finished = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
        bar = progress_bar(trials, "tune", unit="trial", done=min(len(finished), trials),
                           enabled=progress, leave=True)
        try:
            while len(finished) < trials:
                stale = [t for t in study.trials if t.state == optuna.trial.TrialState.RUNNING]
                if stale:  # interrupted before it finished: evaluated again as it was asked
                    number, params = stale[0].number, stale[0].params
                else:
                    study.sampler = _sampler(seed, len(study.trials))
                    trial = study.ask(distributions)
                    number, params = trial.number, trial.params
                areas = evaluator(pairs, params, search.tune.runs, search.iterations, seed)
                ratios = [float(a.mean()) / b for a, b in zip(areas, baseline, strict=True)]
                study.tell(number, float(np.mean(ratios)))
                finished = [t for t in study.trials
                            if t.state == optuna.trial.TrialState.COMPLETE]
                bar.update(1)
        finally:
            bar.close()
        complete = sorted(finished, key=lambda t: t.number)[:trials]
        best = min(complete, key=lambda t: (t.value, t.number))
        validation = study.user_attrs.get("validation")
        if validation is None or validation.get("trial") != best.number:
            valid_pairs = search.pairs("validation")
            runs, vseed = search.tune.validation_runs, seed + 1
            hand = evaluator(valid_pairs, None, runs, search.iterations, vseed)
            tuned = evaluator(valid_pairs, best.params, runs, search.iterations, vseed)
            validation = {"trial": best.number, "hand": [a.tolist() for a in hand],
                          "tuned": [a.tolist() for a in tuned]}
            study.set_user_attr("validation", validation)
    finally:
        evaluator.close()
    result = summary(search, complete, best, baseline, validation, paper)
    write_outputs(search, out, result)
    return result


# results ----------------------------------------------------------------------------------------
def summary(search: Search, trials: list, best: Any, baseline: list[float], validation: dict,
            paper: Mapping[str, float]) -> dict:
    from statsmodels.stats.multitest import multipletests

    rows = []
    hand_all, tuned_all = [], []
    for (scenario, task), hand, tuned in zip(search.pairs("validation"), validation["hand"],
                                             validation["tuned"], strict=True):
        hand, tuned = np.asarray(hand), np.asarray(tuned)
        scale = hand.mean()
        hand_all.append(hand / scale)
        tuned_all.append(tuned / scale)
        rows.append({"scenario": scenario.name, "task": task, "runs": int(hand.size),
                     "auc_hand": float(hand.mean()), "auc_hand_sem": _sem(hand),
                     "auc_tuned": float(tuned.mean()), "auc_tuned_sem": _sem(tuned),
                     "ratio": float(tuned.mean() / scale), "p": paired_test(tuned, hand)})
    adjusted = multipletests([r["p"] for r in rows], method="holm")[1]
    for row, value in zip(rows, adjusted, strict=True):
        row["p_holm"] = float(value)
    hand_pooled, tuned_pooled = np.concatenate(hand_all), np.concatenate(tuned_all)
    pooled = {"pairs": len(rows), "runs": int(hand_pooled.size),
              "ratio": float(tuned_pooled.mean()),
              "p": paired_test(tuned_pooled, hand_pooled),
              "better": int(sum(r["ratio"] < 1 and r["p_holm"] < 0.05 for r in rows)),
              "worse": int(sum(r["ratio"] > 1 and r["p_holm"] < 0.05 for r in rows))}
    training = [{"scenario": s.name, "task": t, "auc_hand": b}
                for (s, t), b in zip(search.pairs("training"), baseline, strict=True)]
    return {
        "experiment": str(search.path),
        "seed": search.spec.seed, "iterations": search.iterations,
        "training_runs": search.tune.runs, "validation_runs": search.tune.validation_runs,
        "training": training,
        "validation_scenarios": sorted({s.name for s in search.validation}),
        "parameters": [{"name": p.name, "term": p.term, "key": p.key, "meaning": p.meaning,
                        "low": p.low, "high": p.high, "hand": paper[p.name],
                        "tuned": float(best.params[p.name])} for p in PARAMETERS],
        "best_trial": best.number, "best_objective": float(best.value),
        "trials": [{"number": t.number, "objective": float(t.value), "params": t.params}
                   for t in trials],
        "validation": rows, "pooled": pooled,
    }


def _sem(values: np.ndarray) -> float:
    return float(values.std(ddof=1) / math.sqrt(values.size)) if values.size > 1 else 0.0


def write_outputs(search: Search, out: Path, result: dict) -> None:
    (out / "tune.json").write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    tuned_file = out / f"{search.training[0].program_path('target').stem}.tuned.yaml"
    tuned_file.write_text(tuned_program(search, result, out), encoding="utf-8")
    plot(result, out / "tune.png")
    (out / "tune.md").write_text(markdown(result, tuned_file.name), encoding="utf-8")


def tuned_program(search: Search, result: dict, out: Path) -> str:
    """The training scenarios' pi_tar file with the tuned parameters written in place (its
    comments and layout kept, its sub-programs named from ``out``)."""
    from bayesprog.learning.write import render_values

    path = search.training[0].program_path("target")
    values = {p["name"]: p["tuned"] for p in result["parameters"]}
    params = terms_of({k: float(f"{v:.6g}") for k, v in values.items()})
    scenarios = ", ".join(sorted({r["scenario"] for r in result["training"]}))
    return render_values(path.read_text(encoding="utf-8"), params, header=(
        f"Profiles tuned by bayesprog tune on {scenarios} (trial {result['best_trial']}, "
        f"objective {result['best_objective']:.4f})"), moved=(path.parent, out))


def markdown(result: dict, tuned_name: str) -> str:
    pooled = result["pooled"]
    change = 100 * (pooled["ratio"] - 1)
    if pooled["p"] < 0.05 and pooled["ratio"] < 1:
        verdict = (f"the tuned profiles lower the area under Gamma on the validation scenarios by "
                   f"{-change:.1f}% (pooled paired Wilcoxon p = {pooled['p']:.2g})")
    elif pooled["p"] < 0.05:
        verdict = (f"the tuned profiles raise the area under Gamma on the validation scenarios by "
                   f"{change:.1f}% (pooled paired Wilcoxon p = {pooled['p']:.2g}): the search "
                   "fitted the training scenarios, not border following in general")
    else:
        verdict = (f"the tuned profiles do not differ from the hand-chosen ones on the validation "
                   f"scenarios ({change:+.1f}%, pooled paired Wilcoxon p = {pooled['p']:.2g})")
    lines = [
        "# Tuned cue profiles", "",
        f"Experiment `{result['experiment']}`: {len(result['trials'])} trials of Optuna's TPE "
        f"sampler (seed {result['seed']}), each running the full model {result['training_runs']} "
        f"times per task on the training scenarios "
        f"({', '.join(sorted({r['scenario'] for r in result['training']}))}) for "
        f"{result['iterations']} probes. The objective is the mean area under Gamma relative to "
        "the hand-chosen profiles' (1 = the file's values; lower is better). Best: trial "
        f"{result['best_trial']}, objective {result['best_objective']:.4f}.", "",
        f"**Verdict**: {verdict}; {pooled['better']} of {pooled['pairs']} validation (scenario, "
        f"task) pairs better, {pooled['worse']} worse (Holm-adjusted p < 0.05).", "",
        "| parameter | meaning | hand-chosen | tuned | range |",
        "|---|---|---|---|---|",
    ]
    for p in result["parameters"]:
        lines.append(f"| {p['name']} | {p['meaning']} | {p['hand']:.3g} | {p['tuned']:.3g} | "
                     f"{p['low']:g} to {p['high']:g} |")
    lines += ["", f"The tuned program: `{tuned_name}`.", "",
              "## Validation (scenarios not used for tuning)", "",
              f"{result['validation_runs']} paired runs per (scenario, task) from the same start "
              "cells and random streams; two-sided Wilcoxon signed-rank test of the areas under "
              "Gamma, Holm-adjusted over the pairs (statsmodels multipletests).", "",
              "| scenario | task | runs | AUC hand-chosen | AUC tuned | tuned / hand | p | p (Holm) |",
              "|---|---|---|---|---|---|---|---|"]
    for r in result["validation"]:
        lines.append(f"| {r['scenario']} | {r['task']} | {r['runs']} | "
                     f"{r['auc_hand']:.3f} ± {r['auc_hand_sem']:.3f} | "
                     f"{r['auc_tuned']:.3f} ± {r['auc_tuned_sem']:.3f} | {r['ratio']:.3f} | "
                     f"{r['p']:.2g} | {r['p_holm']:.2g} |")
    lines.append(f"| pooled (each pair scaled by its hand-chosen mean) | | {pooled['runs']} | 1 | "
                 f"{pooled['ratio']:.3f} | {pooled['ratio']:.3f} | {pooled['p']:.2g} | |")
    lines += ["", "![objective per trial and validation](tune.png)", ""]
    return "\n".join(lines)


def plot(result: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    numbers = [t["number"] for t in result["trials"]]
    values = [t["objective"] for t in result["trials"]]
    left.scatter(numbers, values, s=14, color="0.5", label="trial")
    left.plot(numbers, np.minimum.accumulate(values), color="C0", label="best so far")
    left.axhline(1.0, color="C3", ls="--", lw=1, label="hand-chosen profiles")
    left.set_xlabel("trial")
    left.set_ylabel("training AUC / hand-chosen AUC")
    left.set_title("search (training scenarios)")
    left.legend(fontsize=8)
    rows = result["validation"]
    labels = [f"{r['scenario']}\n{r['task']}" for r in rows]
    ratios = [r["ratio"] for r in rows]
    errors = [r["auc_tuned_sem"] / r["auc_hand"] for r in rows]
    colors = ["C2" if r["ratio"] < 1 and r["p_holm"] < 0.05 else
              "C3" if r["ratio"] > 1 and r["p_holm"] < 0.05 else "0.6" for r in rows]
    right.bar(range(len(rows)), ratios, yerr=errors, color=colors, capsize=2)
    right.axhline(1.0, color="k", lw=1)
    right.set_xticks(range(len(rows)), labels, fontsize=7)
    right.set_ylabel("tuned AUC / hand-chosen AUC")
    right.set_title("validation (green: better, red: worse, Holm p < 0.05)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def tune(experiment: Path, out: Path, options: Mapping[str, Any]) -> int:
    """The command: run or resume the search, write its outputs, print where."""
    search = load_search(experiment)
    trials = options.get("trials")
    if trials is not None and trials < 1:
        raise BayesprogError(f"--trials: expected at least 1, found {trials}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", category=UserWarning)  # optuna's experimental notes
            result = run_search(search, out, trials=trials, workers=options.get("workers", 1),
                                progress=False if options.get("quiet") else None)
    except KeyboardInterrupt:
        print(f"interrupted: the finished trials are kept in {out / JOURNAL}; run the same "
              "command again to resume", file=sys.stderr)
        return 130
    pooled = result["pooled"]
    print(f"best of {len(result['trials'])} trials: training objective "
          f"{result['best_objective']:.4f} (hand-chosen 1); validation tuned / hand-chosen "
          f"{pooled['ratio']:.3f}, pooled p = {pooled['p']:.2g}")
    print(f"written to {out / 'tune.md'} (and tune.json, tune.png, the tuned program)")
    return 0


