"""What a search of cue profiles (``bayesprog tune``) reports: ``tune.md`` (the verdict on the
validation scenarios, the profiles, a table per pair), ``tune.png`` (the objective per trial and
the validation ratios) and ``tune-visits.png`` (where both profiles' probes go); and the command
that runs the search (:mod:`runner.experiments.tune`) and writes them.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from bayesprog import BayesprogError, require_extra
from runner.experiments.store import hold
from runner.experiments.tune import (
    JOURNAL,
    Search,
    load_search,
    run_search,
    tuned_path,
)
from runner.report import figures


def search_and_report(search: Search, out: Path, trials: int | None = None, workers: int = 1,
                      progress: bool | None = None, scheduler: str | None = None) -> dict:
    """Run (or resume) the search in ``out`` (:func:`~runner.experiments.tune.run_search`), then
    write its report beside ``tune.json``; returns what ``tune.json`` holds."""
    with hold(out, "tune"):
        result = run_search(search, out, trials=trials, workers=workers, progress=progress,
                            scheduler=scheduler)
        write_report(search, out, result)
    return result


def write_report(search: Search, out: Path, result: dict) -> None:
    """``tune.png``, ``tune-visits.png`` and ``tune.md`` of a finished search in ``out``."""
    plot(result, out / "tune.png")
    plot_visits(search, result, out / "tune-visits.png")
    (out / "tune.md").write_text(markdown(result, tuned_path(search, out).name), encoding="utf-8")


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
    moves = {who: {key: float(np.mean([r[f"{who}_behaviour"][key] for r in result["validation"]]))
                   for key in ("precision", "border_probed", "path_length", "median_step")}
             for who in ("hand", "tuned")}
    following = (f"Border following on the validation pairs (means): precision (share of probes "
                 f"on the border) {100 * moves['hand']['precision']:.0f}% hand-chosen, "
                 f"{100 * moves['tuned']['precision']:.0f}% tuned; border recall "
                 f"{100 * moves['hand']['border_probed']:.0f}% and "
                 f"{100 * moves['tuned']['border_probed']:.0f}%; median step "
                 f"{100 * moves['hand']['median_step']:.1f} cm and "
                 f"{100 * moves['tuned']['median_step']:.1f} cm.")
    if moves["tuned"]["precision"] < 0.5 * moves["hand"]["precision"]:
        following += (" **The tuned explorer does not follow the border**: its probes fall on "
                      f"it {moves['hand']['precision'] / max(moves['tuned']['precision'], 1e-9):.1f}"
                      " times less often than the hand-chosen profiles'.")
    measure = ("area under Gamma over the probes" if result["objective"] == "probes" else
               "area under Gamma over the distance the hand travels, up to the distance the "
               "hand-chosen profiles travel in as many probes")
    constraint = ""
    if result.get("min_precision") is not None:
        constraint = (f" A candidate counts only if its share of probes on the border of the "
                      f"training scenarios is at least {result['min_precision']:g} times the "
                      "hand-chosen profiles'.")
    if not result.get("feasible", True):
        constraint += (" **No candidate kept it**: the profiles below are the first trial's"
                       " (the file's values when they lie in the searched ranges), not a better"
                       " search result.")
    lines = [
        "# Tuned cue profiles", "",
        f"Experiment `{result['experiment']}`: {len(result['trials'])} trials of Optuna's TPE "
        f"sampler (seed {result['seed']}), each running the full model {result['training_runs']} "
        f"times per task on the training scenarios "
        f"({', '.join(sorted({r['scenario'] for r in result['training']}))}) for "
        f"{result['iterations']} probes. The objective (`{result['objective']}`) is the mean "
        f"{measure}, relative to the hand-chosen profiles' (1 = the file's values; lower is "
        f"better).{constraint} Best: trial {result['best_trial']}, objective "
        f"{result['best_objective']:.4f}.", "",
        f"**Verdict**: {verdict}; {pooled['better']} of {pooled['pairs']} validation (scenario, "
        f"task) pairs better, {pooled['worse']} worse (Holm-adjusted p < 0.05).", "",
        following, "",
        "| parameter | meaning | hand-chosen | tuned | range |",
        "|---|---|---|---|---|",
    ]
    for p in result["parameters"]:
        lines.append(f"| {p['name']} | {p['meaning']} | {p['hand']:.3g} | {p['tuned']:.3g} | "
                     + (f"{p['low']:g} to {p['high']:g} |" if p["searched"] else
                        "not searched |"))
    lines += ["", f"The tuned program: `{tuned_name}`.", "",
              "## Validation (scenarios not used for tuning)", "",
              f"{result['validation_runs']} paired runs per (scenario, task) from the same start "
              f"cells and random streams; the {measure}; two-sided Wilcoxon signed-rank test, "
              "Holm-adjusted over the pairs (statsmodels multipletests). Precision, recall, path "
              "length and median step: hand-chosen / tuned.", "",
              "| scenario | task | runs | area hand-chosen | area tuned | tuned / hand | p | "
              "p (Holm) | precision | recall | path (m) | step (cm) |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["validation"]:
        lines.append(f"| {r['scenario']} | {r['task']} | {r['runs']} | "
                     f"{r['auc_hand']:.3f} ± {r['auc_hand_sem']:.3f} | "
                     f"{r['auc_tuned']:.3f} ± {r['auc_tuned_sem']:.3f} | {r['ratio']:.3f} | "
                     f"{r['p']:.2g} | {r['p_holm']:.2g} | "
                     + " | ".join(_pair(r, key, scale) for key, scale in _MOVES) + " |")
    lines.append(f"| pooled (each pair scaled by its hand-chosen mean) | | {pooled['runs']} | 1 | "
                 f"{pooled['ratio']:.3f} | {pooled['ratio']:.3f} | {pooled['p']:.2g} | | "
                 + " | ".join(f"{scale(moves['hand'][key])} / {scale(moves['tuned'][key])}"
                              for key, scale in _MOVES) + " |")
    lines += ["", "![objective per trial and validation](tune.png)", "",
              "Where the probes go on the validation scenarios (first task of each; visits "
              "summed over the runs, the task's border drawn):", "",
              "![visits of both profiles](tune-visits.png)", ""]
    return "\n".join(lines)


_MOVES = (("precision", lambda v: f"{100 * v:.0f}%"), ("border_probed", lambda v: f"{100 * v:.0f}%"),
          ("path_length", lambda v: f"{v:.2f}"), ("median_step", lambda v: f"{100 * v:.1f}"))


def _pair(row: dict, key: str, scale: Any) -> str:
    return f"{scale(row['hand_behaviour'][key])} / {scale(row['tuned_behaviour'][key])}"


def plot(result: dict, path: Path) -> None:
    rows = result["validation"]
    fig = figures.figure(figsize=(11, max(4.2, 1.5 + 0.28 * len(rows))))
    left, right = fig.subplots(1, 2)
    numbers = np.array([t["number"] for t in result["trials"]])
    values = np.array([t["objective"] for t in result["trials"]])
    least = result.get("min_precision")
    feasible = np.array([least is None or t["precision"] >= least for t in result["trials"]])
    left.scatter(numbers[feasible], values[feasible], s=14, color="0.5", label="trial")
    if not feasible.all():
        left.scatter(numbers[~feasible], values[~feasible], s=14, facecolors="none",
                     edgecolors="C3", label=f"border precision below {least:g} x hand-chosen")
    left.step(numbers, np.minimum.accumulate(np.where(feasible, values, np.inf)),
              where="post", color="C0", label="best so far")
    left.axhline(1.0, color="C3", ls="--", lw=1, label="hand-chosen profiles")
    left.set_xlabel("trial")
    left.set_ylabel("training area / hand-chosen area")
    left.set_title("search (training scenarios)")
    left.legend(fontsize=8)
    labels = [f"{r['scenario']} {r['task']}" for r in rows]
    ratios = [r["ratio"] for r in rows]
    errors = [r["auc_tuned_sem"] / r["auc_hand"] for r in rows]
    colors = ["C2" if r["ratio"] < 1 and r["p_holm"] < 0.05 else
              "C3" if r["ratio"] > 1 and r["p_holm"] < 0.05 else "0.6" for r in rows]
    positions = np.arange(len(rows))[::-1]  # the first pair on top, as in tune.md
    right.barh(positions, ratios, xerr=errors, color=colors, capsize=2)
    right.axvline(1.0, color="k", lw=1)
    right.set_yticks(positions, labels, fontsize=8)
    right.set_xlabel("tuned area / hand-chosen area (bar: standard error)")
    right.set_title("validation (green: better, red: worse, Holm p < 0.05)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_visits(search: Search, result: dict, path: Path) -> None:
    """Visits per cell of the hand-chosen and the tuned profiles on the first task of each
    validation scenario, side by side on one colour scale per scenario."""
    rows: dict[str, dict] = {}
    for row in result["validation"]:
        rows.setdefault(row["scenario"], row)
    scenarios = {s.name: s for s in search.validation}
    fig = figures.figure(figsize=(8, 2.3 * len(rows)))
    axes = fig.subplots(len(rows), 2, squeeze=False)
    for (name, row), (left, right) in zip(rows.items(), axes, strict=True):
        scenario = scenarios[name]
        # a volume seen from above: its visits summed over z
        view = figures.view(scenario)
        visits = {who: figures.field(view, row[f"{who}_visits"]) for who in ("hand", "tuned")}
        top = max(visits["hand"].max(), visits["tuned"].max(), 1)
        for ax, who in ((left, "hand"), (right, "tuned")):
            figures.draw_map(ax, np.log10(1 + visits[who]), view, cmap="magma", vmin=0,
                             vmax=np.log10(1 + top),
                             label="log10(1 + probes)" if who == "tuned" else None,
                             title=f"{name} {row['task']}: "
                             f"{'hand-chosen' if who == 'hand' else 'tuned'} (precision "
                             f"{100 * row[f'{who}_behaviour']['precision']:.0f}%)")
            figures.draw_border(ax, view, row["task"], colour="cyan", width=0.6)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def tune(experiment: Path, out: Path, trials: int | None = None, workers: int = 1,
         quiet: bool = False, scheduler: str | None = None) -> int:
    """The command: run or resume the search, write its outputs, print where."""

    require_extra("optuna", "tune", "bayesprog tune")
    search = load_search(experiment)
    if trials is not None and trials < 1:
        raise BayesprogError(f"--trials: expected at least 1, found {trials}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", category=UserWarning)  # optuna's experimental notes
            result = search_and_report(search, out, trials=trials, workers=workers,
                                       progress=False if quiet else None,
                                       scheduler=scheduler)
    except KeyboardInterrupt:
        print(f"interrupted: the finished trials are kept in {out / JOURNAL}; run the same "
              "command again to resume", file=sys.stderr)
        return 130
    pooled = result["pooled"]
    if not result["feasible"]:
        print(f"no trial kept min_precision {search.tune.min_precision:g}: the first trial "
              "is reported")
    print(f"best of {len(result['trials'])} trials: training objective "
          f"{result['best_objective']:.4f} (hand-chosen 1); validation tuned / hand-chosen "
          f"{pooled['ratio']:.3f}, pooled p = {pooled['p']:.2g}")
    print(f"written to {out / 'tune.md'} (and tune.json, tune.png, the tuned program)")
    return 0


