"""The paper's findings in words beside the numbers: their stability, the power of the runs, the
replications pooled, and the findings of another experiment set beside these (``--compare``)."""

from __future__ import annotations

import json
from pathlib import Path

from bayesprog import BayesprogError
from runner.experiments.experiment import ExperimentSpec
from runner.experiments.store import ResultStore
from runner.report.verdicts import POWER, SMALLEST_EFFECT, _full_auc, _unseen, findings


def comparison_lines(found: list[tuple[str, str, str]], other: Path, name: str) -> list[str]:
    """The paper's findings as measured here and in another experiment's stored report."""
    stats_path = other / "report" / "statistics.json"
    try:
        other_rows = json.loads(stats_path.read_text(encoding="utf-8"))
        other_manifest = ResultStore(other).manifest()
    except (OSError, ValueError) as exc:
        raise BayesprogError(f"--compare {other}: expected an experiment's output folder with "
                             f"its report ({stats_path}): {exc}") from None
    other_spec = ExperimentSpec.model_validate(other_manifest["experiment"])
    theirs = {a: (b, c) for a, b, c in findings(other_rows, other_spec)}
    lines = [f"## The findings beside experiment {other_spec.name}", "",
             f"| the paper | {name} | {other_spec.name} |", "|---|---|---|"]
    for text, measured, verdict in found:
        there = theirs.get(text, ("", "not measured there"))
        lines.append(f"| {text} | {verdict}: {measured} | "
                     + (f"{there[1]}: {there[0]}" if there[0] else there[1]) + " |")
    return lines + [""]


def _share(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.0f}%"


def _stability_text(judged: dict) -> str:
    b = judged["bootstrap"]
    return (f"Stability: the share of {b['resamples']:,} bootstrap resamples of the paired runs "
            f"(drawn with replacement, seed {b['seed']}) in which the verdict comes out the "
            "same by the same rules: how firmly these runs decide it (50% is a coin toss). A "
            "verdict holds for the protocol, not for one sample: `bayesprog run EXPERIMENT "
            "--replications R` runs the protocol R times and pools them.")


def _effects(finding: dict) -> str:
    unit = "mm" if finding["finding"] == "T" else "%"
    sign = "" if finding["finding"] == "T" else "+"
    return "; ".join(f"{t}: {v['effect']:{sign}.1f} {unit} [{v['ci95'][0]:{sign}.1f}, "
                     f"{v['ci95'][1]:{sign}.1f}]" + ("" if finding["finding"] == "T" and t == "T3"
                                                     else f", p {v['p_holm']:.2g}")
                     for t, v in finding["tasks"].items())


def _replication_lines(judged: dict, spec: ExperimentSpec) -> list[str]:
    """The Replications section: the findings over every replication, pooled."""
    r, b = judged["replications"], judged["bootstrap"]
    lines = ["## Replications", "",
             f"The protocol run {r} times, each replication on its own sample of {spec.runs} "
             "start cells, readings and tie-breaks (replication q draws them from the seed and "
             f"q alone; replication 0 is the experiment above). Pooled: the report's rules "
             f"applied to all {r * spec.runs} paired runs together. Effect: the change of the "
             "mean area under Gamma against the full model (for T: the full model's final "
             "Gamma per border cell), with its 95% interval, the 2.5th and 97.5th percentiles "
             f"over {b['resamples']:,} bootstrap resamples of the paired runs (seed "
             f"{b['seed']}); p: the pooled Holm-adjusted p-value of the verdict's test (for T, "
             "the task against T3, paired by run). k of R: the replications whose own runs "
             "agree. Stability: the share of the resamples whose verdict is the pooled one.", "",
             "| finding | the paper | pooled effect per task [95% interval] | agrees in | "
             "pooled verdict | stability |", "|---|---|---|---|---|---|"]
    for f in judged["findings"]:
        lines.append(f"| {f['finding']} | {f['claim']} | {_effects(f)} | {f['agree']} of "
                     f"{f['of']} | {f['verdict']} | {_share(f['stability'])} |")
    lines += ["", "![Gamma pooled](fig10_gamma_pooled.png)", "",
              f"*Fig. 10 pooled: Gamma(k), the mean over the {r * spec.runs} runs of every "
              "replication, shaded its 95% interval (mean +- 1.96 SEM); one panel per task.*",
              ""]
    return lines


def _power_lines(rows: list[dict], spec: ExperimentSpec) -> list[str]:
    """What the runs could tell: the smallest change of the area under Gamma the paired tests
    find, and the runs the smallest effect of a verdict would need."""
    tested = [r for r in rows if "detectable_auc" in r]
    if not tested:
        return []
    worst = max(tested, key=lambda r: r["detectable_auc"])
    best = min(r["detectable_auc"] for r in tested)
    needed = max((r["runs_for_smallest"] or 0) for r in tested)
    text = (f"What {spec.runs} runs can tell: by the spread of the paired differences, the tests "
            f"find (with probability {POWER:.0%}, at the verdicts' threshold after Holm's "
            f"adjustment; a normal approximation, cautious for the signed-rank test) changes "
            f"of the area under Gamma of about {100 * best:.0f}% to "
            f"{100 * worst['detectable_auc']:.0f}% or more, depending on the task and the "
            f"ablation ({worst['task']}, {worst['configuration']}: the largest).")
    unseen = [r for r in tested if _unseen(r, r["auc_mean"] / _full_auc(rows, r["task"]) - 1,
                                           r.get("p_auc_holm", r["p_auc"]),
                                           r["configuration"].removeprefix("without_"))]
    needed = max((r["runs_for_smallest"] or 0) for r in unseen) if unseen else needed
    if unseen:
        text += (f" **These runs are too few to tell** {len(unseen)} of the changes the "
                 f"verdicts weigh (not significant, and not shown to be under "
                 f"{100 * SMALLEST_EFFECT:.0f}%: marked beside their verdicts); about {needed} "
                 f"runs would find a {100 * SMALLEST_EFFECT:.0f}% change there.")
    return [text, ""]
