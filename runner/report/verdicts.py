"""The statistics of an experiment's runs and the paper's findings (Sec. 6.3) judged on them:
one sample of start cells (the report's tables), and every replication of the protocol
pooled, with a bootstrap interval per effect, the verdict per replication, and how firm each
verdict is (``report/findings.json``)."""

from __future__ import annotations

import contextlib
import gc
import math
from collections import defaultdict
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from runner.experiments.experiment import ExperimentSpec, mean_sem
from runner.experiments.metrics import area_under, behaviour, paired_test, phase_areas
from runner.world.scenario import Scenario


def statistics_table(results: dict, spec: ExperimentSpec, borders: dict[str, int],
                     scenario: Scenario | None = None) -> list[dict]:
    rows = []
    for task in spec.tasks:
        full = results.get(f"{task}/full")
        for conf in spec.configurations:
            g = results[f"{task}/{conf}"]["gamma"]
            final, auc = g[:, -1], area_under(g)
            fm, fs = mean_sem(final[:, None])
            am, as_ = mean_sem(auc[:, None])
            row = {"task": task, "configuration": conf, "runs": int(g.shape[0]),
                   "final_mean": float(fm[0]), "final_sem": float(fs[0]),
                   # a task whose material borders nothing has no border to follow
                   "final_per_border_cell_mm": (1000 * float(fm[0]) / borders[task]
                                                if borders[task] else float("nan")),
                   "auc_mean": float(am[0]), "auc_sem": float(as_[0])}
            if scenario is not None:
                paths = results[f"{task}/{conf}"]["paths"]
                row.update(behaviour(paths, scenario.border(task), scenario.centres))
                # the area under Gamma before each run first probes the border, and after
                search, follow = phase_areas(g, paths, scenario.border(task))
                row["auc_search"], row["auc_follow"] = float(search.mean()), float(follow.mean())
            if full is not None and conf != "full":
                row["p_final"] = paired_test(final, full["gamma"][:, -1])
                row["p_auc"] = paired_test(auc, area_under(full["gamma"]))
            rows.append(row)
    _runner_up_tests(rows, results)
    _detectable(rows, results)
    with _heap_frozen():
        for key in ("p_final", "p_auc", "p_runner_up"):  # Holm's correction over each column
            tested = [r for r in rows if key in r]
            if tested:
                from statsmodels.stats.multitest import multipletests

                adjusted = multipletests([r[key] for r in tested], method="holm")[1]
                for r, value in zip(tested, adjusted, strict=True):
                    r[f"{key}_holm"] = float(value)
    return rows


@contextlib.contextmanager
def _heap_frozen() -> Iterator[None]:
    """The objects alive now kept out of the garbage collector's reach while the block runs:
    statsmodels' Holm correction collects garbage at every call, and a report's heap
    (matplotlib, scipy) would make each collection last a tenth of a second. Nothing is done
    where a part of the heap is frozen already (that part stays so)."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


#: the power at which :func:`_detectable` says what the paired tests can see
POWER = 0.8
#: the smallest effect a verdict turns on: removing U must cost more than 5 %
SMALLEST_EFFECT = 0.05


def _detectable(rows: list[dict], results: dict) -> None:
    """Per ablation row, ``detectable_auc``: the smallest change of the area under Gamma,
    relative to the full model's, that its paired test finds with probability POWER at the
    verdicts' threshold after Holm's adjustment over the column's tests (at worst ALPHA / m),
    by the normal approximation of the paired differences; and ``runs_for_smallest``: how many
    runs would find SMALLEST_EFFECT so."""
    from scipy import stats

    tested = [r for r in rows if "p_auc" in r]
    if not tested:
        return
    z = stats.norm.ppf(1 - ALPHA / len(tested) / 2) + stats.norm.ppf(POWER)
    for row in tested:
        task = row["task"]
        full = area_under(results[f"{task}/full"]["gamma"])
        diff = area_under(results[f"{task}/{row['configuration']}"]["gamma"]) - full
        n, spread, scale = len(diff), float(np.std(diff, ddof=1)) if len(diff) > 1 else math.inf, \
            float(np.mean(full))
        row["detectable_auc"] = float(z * spread / math.sqrt(n) / scale) if scale > 0 else math.inf
        row["runs_for_smallest"] = (int(math.ceil((z * spread / (SMALLEST_EFFECT * scale)) ** 2))
                                    if scale > 0 and math.isfinite(spread) else None)


def _runner_up_tests(rows: list[dict], results: dict) -> None:
    """Per task, the ablation that degrades the most after removing S ("runner_up" in the
    without_S row) and the paired test of their areas under Gamma: whether removing S is
    distinguishable from the next worst ablation."""
    by_task: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        if r["configuration"] != "full":
            by_task[r["task"]].append(r)
    for task, ablations in by_task.items():
        s = next((r for r in ablations if r["configuration"] == "without_S"), None)
        others = [r for r in ablations if r is not s]
        if s is None or not others:
            continue
        runner_up = max(others, key=lambda r: r["auc_mean"])
        s["runner_up"], s["runner_up_auc"] = runner_up["configuration"], runner_up["auc_mean"]
        s["p_runner_up"] = paired_test(area_under(results[f"{task}/without_S"]["gamma"]),
                                       area_under(results[f"{task}/{runner_up['configuration']}"]
                                                  ["gamma"]))



#: The significance level where the paper claims a difference (S, U), and below which a change
#: counts as significant (I, R).
ALPHA = 0.01

FINDINGS = [
    ("S", "Removing S degrades the most (the exploration becomes random)."),
    ("U", "Removing U degrades considerably."),
    ("I", "Removing I stays near the full model."),
    ("R", "Removing R has no strong influence."),
    ("T", "T1 and T2 are followed more accurately than T3."),
]


def _s_is_worst(row: dict) -> bool:
    """In the without_S row: whether removing S has the largest area under Gamma."""
    return "runner_up" not in row or row["auc_mean"] >= row["runner_up_auc"]


def _s_the_worst(row: dict) -> bool:
    """Removing S degrades the most: its area under Gamma is the largest of the ablations, or
    the one that is larger is not distinguishable from it (paired test, Holm-adjusted p >= 0.01):
    a difference of means that the runs cannot tell from chance does not rank the two."""
    return _s_is_worst(row) or row.get("p_runner_up_holm", row.get("p_runner_up", 0.0)) >= ALPHA


def agrees(key: str, changes: Mapping[str, Any] | None = None,
           ps: Mapping[str, Any] | None = None, s_the_worst: Mapping[str, Any] | None = None,
           per: Mapping[str, Any] | None = None) -> np.ndarray:
    """The report's rule for finding ``key``, per task: ``changes`` (relative change of the
    area under Gamma against the full model), ``ps`` (Holm-adjusted p-values), for S whether
    it is the worst ablation or not distinguishable from the worst, for T the final Gamma per
    border cell of the full model. Numbers or arrays of resamples alike (elementwise)."""
    if key == "T":
        assert per is not None
        return np.asarray((per["T1"] < per["T3"]) & (per["T2"] < per["T3"]))
    assert changes is not None and ps is not None
    tasks = list(changes)
    if key == "S":
        assert s_the_worst is not None
        each = [(changes[t] > 0) & (ps[t] < ALPHA) & s_the_worst[t] for t in tasks]
    elif key == "U":
        each = [(changes[t] > SMALLEST_EFFECT) & (ps[t] < ALPHA) for t in tasks]
    elif key == "I":  # near the full model
        each = [(np.abs(changes[t]) < 0.10) | (ps[t] >= ALPHA) for t in tasks]
    else:  # R: no strong influence, or the full model is better; never a significant loss
        each = [(changes[t] > -0.10) | (ps[t] >= ALPHA) for t in tasks]
    return np.logical_and.reduce(np.broadcast_arrays(*each))


def findings(rows: list[dict], spec: ExperimentSpec) -> list[tuple[str, str, str]]:
    """Each finding of the paper, what was measured, and whether they agree."""
    return [(text, measured, verdict) for _, text, measured, verdict in keyed_findings(rows, spec)]


def keyed_findings(rows: list[dict], spec: ExperimentSpec) -> list[tuple[str, str, str, str]]:
    """:func:`findings`, each with its key (S, U, I, R, T) first."""
    by = {(r["task"], r["configuration"]): r for r in rows}
    out = []
    tasks = spec.tasks

    def rel(task: str, conf: str) -> float:
        return by[(task, conf)]["auc_mean"] / by[(task, "full")]["auc_mean"] - 1

    def have(conf: str) -> bool:
        return all((t, conf) in by for t in tasks) and all((t, "full") in by for t in tasks)

    for key, text in FINDINGS:
        if key == "T":
            per = {t: by[(t, "full")]["final_per_border_cell_mm"] for t in tasks if (t, "full") in by}
            if {"T1", "T2", "T3"} <= set(per):
                agree = bool(agrees("T", per=per))
                measured = ", ".join(f"{t}: {v:.1f} mm" for t, v in per.items())
                out.append((key, text, f"final Gamma per border cell (full model): {measured}",
                            "agrees" if agree else "differs"))
            continue
        conf = f"without_{key}"
        if not have(conf):
            continue
        changes = {t: rel(t, conf) for t in tasks}
        ps = {t: by[(t, conf)].get("p_auc_holm", by[(t, conf)]["p_auc"]) for t in tasks}
        measured = "; ".join(f"{t}: {100 * changes[t]:+.0f}% area under Gamma "
                             f"(Holm-adjusted p={ps[t]:.2g})" for t in tasks)
        agree = bool(agrees(key, changes, ps, {t: _s_the_worst(by[(t, conf)]) for t in tasks}
                            if key == "S" else None))
        if key == "S":
            ablations = [c for c in spec.configurations if c != "full"]
            worst = [ablations[int(np.argmax([by[(t, c)]["auc_mean"] for c in ablations]))]
                     for t in tasks]
            measured += f"; the worst ablation per task: {', '.join(worst)}"
            ahead = []
            for t in tasks:
                row = by[(t, conf)]
                if not _s_is_worst(row):
                    p = row.get("p_runner_up_holm", row["p_runner_up"])
                    ahead.append(f"{t}: {row['runner_up']} "
                                 f"{100 * (rel(t, row['runner_up']) - changes[t]):+.0f} points "
                                 f"(Holm-adjusted p={p:.2g})")
            if ahead:
                measured += ("; where another ablation degrades more, its paired test against "
                             "removing S: " + "; ".join(ahead))
        verdict = "agrees" if agree else "differs"
        # not significant where the test could not have seen a change as large as the
        # verdicts weigh: the runs, not the model, may have decided
        unseen = [t for t in tasks if _unseen(by[(t, conf)], changes[t], ps[t], key)]
        if unseen:
            said = ", ".join(f"{t} {100 * changes[t]:+.0f}%" for t in unseen)
            finds = max(by[(t, conf)].get("detectable_auc", math.nan) for t in unseen)
            verdict += (f" (runs too few to tell: {said} not significant; with these runs the "
                        f"test finds changes of about {100 * finds:.0f}% or more)")
        out.append((key, text, measured, verdict))
    return out



def _unseen(row: dict, change: float, p: float, key: str) -> bool:
    """Whether the verdict on ablation ``key`` rests, in this task, on a test that these runs
    were too few for: S and U agree only on a significant change, so one not significant
    where the test could not have found a 5% change (or the change is larger) is unsettled;
    I and R agree on a small change or a not significant one, so only a large change that is
    not significant is."""
    if p < ALPHA:
        return False
    if key in ("S", "U"):
        return abs(change) > SMALLEST_EFFECT or row.get("detectable_auc", 0.0) > SMALLEST_EFFECT
    if key == "I":
        return abs(change) >= 0.10
    return change <= -0.10


def _full_auc(rows: list[dict], task: str) -> float:
    return next(r["auc_mean"] for r in rows if r["task"] == task and r["configuration"] == "full")




# every replication of the protocol ----------------------------------------------------------
#: bootstrap resamples of the paired runs behind each interval and each stability, and their
#: seed (the same resamples for every finding: the verdicts are judged on one set)
RESAMPLES = 1000
RESAMPLE_SEED = 20_160_101
#: resampled runs held at once (resamples x runs): the bootstrap works in blocks of this size
BLOCK_ENTRIES = 2_000_000


def pooled(replications: Sequence[Mapping[str, Mapping[str, np.ndarray]]]
           ) -> dict[str, dict[str, np.ndarray]]:
    """The runs of every replication as one sample: per ``task/configuration``, each array's
    runs of replication 0, then 1, ... (paired runs stay paired: the same position in every
    configuration and task)."""
    first = replications[0]
    return {key: {name: np.concatenate([r[key][name] for r in replications])
                  for name in first[key]} for key in first}


def signed_rank_p(d: np.ndarray) -> np.ndarray:
    """Two-sided p-values of the Wilcoxon signed-rank test of paired differences ``d``
    [resamples, runs], one per row, by the normal approximation with the tie correction and
    zero differences dropped (scipy.stats.wilcoxon's ``method="approx"``, ``zero_method=
    "wilcox"``, no continuity correction); 1 where the two sides never differ (as
    :func:`~runner.experiments.metrics.paired_test`)."""
    from scipy import stats

    d = np.atleast_2d(np.asarray(d, dtype=float))
    size = d.shape[1]
    a = np.abs(d)
    order = np.argsort(a, axis=1, kind="stable")
    s = np.take_along_axis(a, order, axis=1)
    positive = np.take_along_axis(d > 0, order, axis=1)
    zeros = (a == 0).sum(axis=1)
    # ties: each sorted position's group of equal values, its first and last position
    index = np.broadcast_to(np.arange(size), s.shape)
    starts = np.ones(s.shape, bool)
    starts[:, 1:] = s[:, 1:] != s[:, :-1]
    ends = np.ones(s.shape, bool)
    ends[:, :-1] = starts[:, 1:]
    first = np.maximum.accumulate(np.where(starts, index, 0), axis=1)
    last = np.minimum.accumulate(np.where(ends, index, size - 1)[:, ::-1], axis=1)[:, ::-1]
    # zeros sort first and are dropped: the others' ranks start after them
    rank = (first + last) / 2 + 1 - zeros[:, None]
    r_plus = np.where(positive, rank, 0.0).sum(axis=1)
    ties = last - first + 1
    nonzero = s > 0
    tie_term = np.where(nonzero, ties.astype(float) ** 2 - 1, 0.0).sum(axis=1)
    n = (size - zeros).astype(float)
    mean = n * (n + 1) / 4
    var = (n * (n + 1) * (2 * n + 1) - tie_term / 2) / 24
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (r_plus - mean) / np.sqrt(var)
        p = np.minimum(2 * stats.norm.sf(np.abs(z)), 1.0)
    return np.where(np.isfinite(p), p, 1.0)


def holm(p: np.ndarray) -> np.ndarray:
    """Holm's step-down adjustment of the p-values of each row of ``p`` [resamples, tests]
    (as statsmodels' ``multipletests(method="holm")`` of one row)."""
    p = np.atleast_2d(p)
    m = p.shape[1]
    order = np.argsort(p, axis=1)
    ranked = np.take_along_axis(p, order, axis=1) * np.arange(m, 0, -1)
    adjusted = np.minimum(np.maximum.accumulate(ranked, axis=1), 1.0)
    out = np.empty_like(adjusted)
    np.put_along_axis(out, order, adjusted, axis=1)
    return out


def _allclose_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per row, numpy's ``allclose(a, b)`` (the paired test's "never differ")."""
    return np.all(np.abs(a - b) <= 1e-8 + 1e-5 * np.abs(b), axis=1)


def _paired_p(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.where(_allclose_rows(a, b), 1.0, signed_rank_p(a - b))


class Resampled:
    """The report's rules applied to resamples of the paired runs: per finding, whether it
    agrees, and its effect per task, for every row of run indices given."""

    def __init__(self, results: Mapping[str, Mapping[str, np.ndarray]], spec: ExperimentSpec,
                 borders: Mapping[str, int]):
        self.tasks = list(spec.tasks)
        self.configurations = list(spec.configurations)
        self.borders = borders
        self.auc = {k: area_under(v["gamma"]) for k, v in results.items()}
        self.final = {k: v["gamma"][:, -1] for k, v in results.items()}
        self.runs = len(next(iter(self.auc.values())))

    def keys(self) -> list[str]:
        """The findings these results can judge (as :func:`findings` gives them)."""
        have = {c for c in self.configurations
                if all(f"{t}/{c}" in self.auc and f"{t}/full" in self.auc for t in self.tasks)}
        out = [k for k, _ in FINDINGS if k != "T" and f"without_{k}" in have]
        if {"T1", "T2", "T3"} <= {t for t in self.tasks if f"{t}/full" in self.auc}:
            out.append("T")
        return out

    def __call__(self, rows: np.ndarray) -> dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]:
        """For run indices ``rows`` [resamples, runs]: per finding, whether it agrees
        [resamples] and its effect per task [resamples] (% change of the area under Gamma;
        for T the final Gamma per border cell in mm)."""
        auc = {k: v[rows] for k, v in self.auc.items()}
        mean = {k: v.mean(axis=1) for k, v in auc.items()}
        ablations = [c for c in self.configurations if c != "full"]
        tested = [(t, c) for t in self.tasks for c in ablations
                  if f"{t}/full" in auc]  # the statistics table's rows with a p_auc
        p = holm(np.stack([_paired_p(auc[f"{t}/{c}"], auc[f"{t}/full"]) for t, c in tested],
                          axis=1)) if tested else np.empty((len(rows), 0))
        p_holm = {tc: p[:, i] for i, tc in enumerate(tested)}
        out: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]] = {}
        for key in self.keys():
            if key == "T":
                per = {t: 1000 * self.final[f"{t}/full"][rows].mean(axis=1) / self.borders[t]
                       if self.borders[t] else np.full(len(rows), np.nan) for t in self.tasks}
                out[key] = (agrees("T", per=per), per)
                continue
            conf = f"without_{key}"
            changes = {t: mean[f"{t}/{conf}"] / mean[f"{t}/full"] - 1 for t in self.tasks}
            ps = {t: p_holm[(t, conf)] for t in self.tasks}
            worst = self._s_the_worst(auc, mean, ablations) if key == "S" else None
            out[key] = (agrees(key, changes, ps, worst),
                        {t: 100 * v for t, v in changes.items()})
        return out

    def _s_the_worst(self, auc: dict, mean: dict, ablations: list[str]) -> dict[str, np.ndarray]:
        """Per task, whether removing S has the largest area under Gamma, or the ablation with
        the largest (the first on a tie) is not distinguishable from it (Holm over tasks)."""
        others = [c for c in ablations if c != "without_S"]
        if not others:
            return {t: np.ones(len(mean[f"{t}/full"]), bool) for t in self.tasks}
        worst, p = {}, []
        for t in self.tasks:
            means = np.stack([mean[f"{t}/{c}"] for c in others], axis=1)
            pick = np.argmax(means, axis=1)  # the runner-up (the first on a tie, as max())
            worst[t] = mean[f"{t}/without_S"] >= means[np.arange(len(pick)), pick]
            each = np.stack([_paired_p(auc[f"{t}/without_S"], auc[f"{t}/{c}"]) for c in others],
                            axis=1)
            p.append(each[np.arange(len(pick)), pick])
        adjusted = holm(np.stack(p, axis=1))
        return {t: worst[t] | (adjusted[:, i] >= ALPHA) for i, t in enumerate(self.tasks)}


def bootstrap(resampled: Resampled, resamples: int = RESAMPLES, seed: int = RESAMPLE_SEED
              ) -> dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]:
    """:class:`Resampled` over ``resamples`` bootstrap resamples of the paired runs (drawn
    with replacement from ``seed``), computed in blocks (``BLOCK_ENTRIES``)."""
    rng = np.random.default_rng(seed)
    n = resampled.runs
    block = max(1, BLOCK_ENTRIES // max(n, 1))
    parts = []
    for start in range(0, resamples, block):
        rows = rng.integers(0, n, size=(min(block, resamples - start), n))
        parts.append(resampled(rows))
    return {key: (np.concatenate([part[key][0] for part in parts]),
                  {t: np.concatenate([part[key][1][t] for part in parts])
                   for t in parts[0][key][1]}) for key in parts[0]}


def _t_tests(results: Mapping[str, Mapping[str, np.ndarray]], tasks: list[str],
             borders: Mapping[str, int]) -> dict[str, float]:
    """For T: each task's final Gamma per border cell (full model) against T3's, paired by
    run (the same start cells), two-sided signed-rank, Holm-adjusted over the tasks compared;
    T3 against itself: 1."""
    per = {t: 1000 * results[f"{t}/full"]["gamma"][:, -1] / borders[t] if borders[t] else
           np.full(len(results[f"{t}/full"]["gamma"]), np.nan) for t in tasks}
    compared = [t for t in tasks if t != "T3"]
    raw = [paired_test(per[t], per["T3"]) for t in compared]
    adjusted = holm(np.asarray(raw)[None, :])[0] if raw else []
    return {**{t: float(v) for t, v in zip(compared, adjusted, strict=True)}, "T3": 1.0}


def judge_replications(replications: Sequence[Mapping[str, Mapping[str, np.ndarray]]],
                       spec: ExperimentSpec, borders: Mapping[str, int],
                       resamples: int = RESAMPLES, seed: int = RESAMPLE_SEED) -> dict:
    """The paper's findings over every replication: ``report/findings.json``.

    Per finding: ``verdict``, the report's rules applied to the runs of every replication
    pooled (paired runs: ``replications x runs`` of them); ``agree`` of ``of``, the
    replications whose own runs agree; ``stability``, the share of bootstrap resamples of
    the pooled runs whose verdict is the pooled one; per task the ``effect`` (the pooled
    change of the mean area under Gamma against the full model, in %; for T the full
    model's final Gamma per border cell, mm), its 95 % percentile bootstrap interval
    ``ci95`` over the same resamples, and ``p_holm``, the pooled Holm-adjusted p-value of
    the verdict's test (for T: the task against T3, see :func:`_t_tests`).
    """
    together = pooled(replications)
    rows = statistics_table(together, spec, dict(borders))
    found = {key: (text, measured, verdict)
             for key, text, measured, verdict in keyed_findings(rows, spec)}
    single = [{key: verdict for key, _, _, verdict
               in keyed_findings(statistics_table(dict(r), spec, dict(borders)), spec)}
              for r in replications] if len(replications) > 1 else None
    resampled = Resampled(together, spec, borders)
    if set(resampled.keys()) != set(found):
        raise RuntimeError(f"findings {sorted(found)} judged, {resampled.keys()} resampled")
    drawn = bootstrap(resampled, resamples, seed)
    by = {(r["task"], r["configuration"]): r for r in rows}
    out = []
    for key, (claim, measured, verdict) in found.items():
        agreed = verdict.startswith("agrees")
        agree_each = [v[key].startswith("agrees") for v in single] if single else [agreed]
        held, effects = drawn[key]
        t_p = _t_tests(together, spec.tasks, borders) if key == "T" else {}
        tasks = {}
        for t in spec.tasks:
            full = by[(t, "full")]
            effect = float(full["final_per_border_cell_mm"] if key == "T" else
                           100 * (by[(t, f"without_{key}")]["auc_mean"] / full["auc_mean"] - 1))
            lo, hi = (float(v) for v in np.nanpercentile(effects[t], [2.5, 97.5]))
            p = t_p[t] if key == "T" else by[(t, f"without_{key}")].get(
                "p_auc_holm", by[(t, f"without_{key}")]["p_auc"])
            tasks[t] = {"effect": effect, "ci95": [min(lo, effect), max(hi, effect)],
                        "p_holm": float(p)}
        out.append({"finding": key, "claim": claim, "verdict": "agrees" if agreed else "differs",
                    "agree": int(sum(agree_each)), "of": len(replications),
                    "stability": float(np.mean(held == agreed)),
                    "unit": "mm per border cell" if key == "T" else "% area under Gamma",
                    "measured": measured, "tasks": tasks})
    return {"replications": len(replications), "runs": int(spec.runs),
            "bootstrap": {"resamples": resamples, "seed": seed, "interval": "percentile",
                          "over": "paired runs, every replication pooled"},
            "findings": out}
