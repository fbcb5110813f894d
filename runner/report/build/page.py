"""The report's page: report.md (the words, the statistics table, where the visits go, the figures
with their captions, the findings) and report.html, the same page."""

from __future__ import annotations

import html
from collections.abc import Sequence

from runner.experiments.experiment import ExperimentSpec
from runner.report.build.findings import _power_lines, _replication_lines, _share, _stability_text


def _behaviour_lines(rows: list[dict]) -> list[str]:
    lines = ["| task | configuration | enrichment near the border | runs reaching it | median "
             "step of first reach | border cells probed (recall) | probes on the border "
             "(precision) | path length per run (m) | distinct cells per run | returns to the "
             "cell of two steps before | area under Gamma: search + following | change against "
             "the full model: search, following |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    full = {r["task"]: r for r in rows if r["configuration"] == "full"}
    for r in rows:
        if "enrichment" in r:
            length = f"{r['path_length']:.2f}" if "path_length" in r else "-"
            phases = change = "-"
            if "auc_search" in r:
                phases = f"{r['auc_search']:.0f} + {r['auc_follow']:.0f}"
                base = full.get(r["task"])
                if base is not None and r is not base and base["auc_mean"] > 0:
                    change = ", ".join(f"{100 * (r[k] - base[k]) / base['auc_mean']:+.1f}%"
                                       for k in ("auc_search", "auc_follow"))
            lines.append(f"| {r['task']} | {r['configuration']} | {r['enrichment']:.2f}x | "
                         f"{100 * r['reached']:.0f}% | {r['reach_step']:.0f} | "
                         f"{100 * r['border_probed']:.0f}% | {100 * r['precision']:.0f}% | "
                         f"{length} | {r['distinct']:.1f} | {100 * r['returns']:.0f}% | "
                         f"{phases} | {change} |")
    return lines


def _table_lines(rows: list[dict]) -> list[str]:
    lines = ["| task | configuration | final Gamma (m) | per border cell (mm) | area under "
             "Gamma (m x steps) | p (final) | p (area) | Holm p (final) | Holm p (area) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ps = " | ".join(_p(r, key) for key in ("p_final", "p_auc", "p_final_holm", "p_auc_holm"))
        lines.append(f"| {r['task']} | {r['configuration']} | {r['final_mean']:.3f} +- "
                     f"{r['final_sem']:.3f} | {r['final_per_border_cell_mm']:.1f} | "
                     f"{r['auc_mean']:.1f} +- {r['auc_sem']:.1f} | {ps} |")
    return lines


#: What the report's words mean, for a reader who has not read the paper (Martins, Ferreira,
#: Castelo-Branco and Dias, "Integration of touch attention mechanisms to improve the robotic
#: haptic exploration of surfaces"): its equations are cited by their numbers there
GLOSSARY = [
    "## What the words mean", "",
    "A simulated hand probes one cell of a grid at a time, looking for the border between two "
    "materials, and decides where to probe next from what it has felt so far. The "
    "configurations compare that decision with and without each of the cues it weighs. "
    "'eq. N' cites the equations of the paper the experiment reproduces (Martins, Ferreira, "
    "Castelo-Branco and Dias, *Integration of touch attention mechanisms to improve the robotic "
    "haptic exploration of surfaces*).", "",
    "- **Task (T1, T2, ...).** Find and follow the border between two given materials (a haptic "
    "discontinuity); each task has its ground-truth border, drawn in black in Fig. 9.",
    "- **pi_tar** (π_tar). The Bayesian program that chooses the next cell to probe, O: the "
    "most probable cell given the task and the cues S, U, I and R (eq. 13). **full** is pi_tar "
    "as written; **without_S** (likewise R, I, U) is pi_tar with that cue's term replaced by a "
    "uniform, so that the cue no longer counts: what the ablation study removes.",
    "- **S, haptic saliency** (eq. 12). How sharply the material map felt so far changes around "
    "a cell (an edge detector on the probed cells, from 0 to 1): high on a border between the "
    "task's two materials. It draws the hand to the border (exploitation).",
    "- **U, uncertainty** (eq. 11). How unsure the hand still is of a cell's material: the "
    "entropy of its material posterior, scaled to [0, 1] (1 for a cell never probed, near 0 "
    "for one whose material is known). It draws the hand to what it has not explored "
    "(curiosity).",
    "- **I, inhibition of return** (eq. 10). A level set by the distance to the cell just "
    "probed, which holds a cell back the more, the higher it is: 1 there, so that the hand does "
    "not probe it again at once, lowest beside it and rising with distance, so that the hand "
    "keeps moving on without jumping far.",
    "- **R, shape cues** (eq. 14-15). Known shapes (templates such as a rectangle and a "
    "triangle) registered onto the path probed so far, each weighted by how well the path "
    "matches it (the program pi_obj): a cell on a registered outline is favoured, so that the "
    "hand goes on along the shape it is following.",
    "- **Gamma** (Γ, eq. 16). How far the probes left the task's border: for each cell of the "
    "ground-truth border, the distance to the nearest probed cell, summed over the border "
    "(metres); divided by the number of border cells, the mean distance of a border cell to "
    "the nearest probe (mm, 'per border cell'). **Lower is better**: 0 when every border "
    "cell has been probed. Gamma(k) is its value after k probes (Fig. 10); the **area under "
    "Gamma(k)** sums it over a run's steps (metre x steps), **lower is better** too: the border "
    "found sooner and followed more closely. A cue helps when removing it raises the area.",
    "",
]


def _markdown(spec: ExperimentSpec, rows: list[dict], found: list[tuple[str, str, str]],
              borders: dict[str, int], step: int, task: str, digest: str, run: int = 0,
              extra: Sequence[str] = (), animation: str | None = None, shown: str = "full",
              volume: bool = False, judged: dict | None = None) -> str:
    lines = [f"# Experiment {spec.name}", "",
             f"{spec.description.strip()}", "",
             f"{len(spec.tasks)} task(s) x {len(spec.configurations)} configuration(s) x "
             f"{spec.runs} runs x {spec.iterations} iterations, seed {spec.seed}, configuration "
             f"hash `{digest}`. Border cells per task: "
             + ", ".join(f"{t} {n}" for t, n in borders.items()) + ".", "",
             *GLOSSARY,
             "## Gamma(k) (paper Fig. 10)", "", "![Gamma](fig10_gamma.png)", "",
             "*Fig. 10. Gamma (eq. 16) sums, over the task's border cells, the distance in metres "
             "to the nearest probed cell; lower is better. Mean over the runs, shaded +- SEM; "
             "one panel per task, one curve per configuration of pi_tar.*", "",
             "## Visits (paper Fig. 9)", "", "![Visits](fig9_visits.png)", "",
             "*Fig. 9. First column: the materials, the task's ground-truth border (black) and "
             "the runs' start cells (crosses). Then, per configuration, the visits per run of "
             "each cell (each panel with its own colour scale: compare shapes, not colours "
             "across panels), the border in blue. Axes in cm.*", "",
             *(["The workspace is a volume: Fig. 9 shows it from above, each column's visits "
                "summed over z and the outline of the task's solid as seen from above. The "
                "slices below show where the visits of the "
                f"{'full model' if shown == 'full' else shown} lie in height, each slice with "
                "the border of its own cross-section.", "", "![Slices](fig9_slices.png)", "",
                "*Fig. 9, slices: horizontal slices through the objects, one colour scale per "
                "task.*", ""] if volume else []),
             f"## One decision (paper Fig. 11): task {task}, "
             f"{'full model' if shown == 'full' else shown}, run {run}, step {step}",
             "", "![Decision](fig11_decision.png)", "",
             "*Fig. 11. The step that ends the longest stretch of probes within one cell of the "
             "border over every run: the walker follows the border. The ground truth, the "
             "belief map P(M = task material) at the probed cells, the cues S, U, I, the shape "
             "cue and the posterior over the next cell O (eq. 13), each with its colour bar; "
             "the path, its start and the chosen cell on every panel. Axes in cm."
             + (" In a volume the maps are the horizontal slice of the chosen cell, and the "
                "path is drawn seen from above." if volume else "") + "*", ""]
    if animation:
        lines += [f"The animation over every step of that run: [{animation}]({animation}).", ""]
    lines += ["## Final Gamma and area under Gamma(k)", "",
              "Mean +- SEM over runs; p: two-sided Wilcoxon signed-rank test of each ablation "
              "against the full model over the shared start cells; Holm p: the same p-values "
              "adjusted by Holm's method over all the tests of the column (statsmodels' "
              "multipletests), which the verdicts below use.", ""]
    lines += _table_lines(rows)
    lines += ["", "## Where the visits go", "",
              "Enrichment: the share of visits within one cell of the task's border divided by "
              "that band's share of the grid (1 = visits spread evenly). Without U the walker "
              "can only be kept from a cell by I, which inhibits the last probed cell alone "
              "(eq. 10): on a border the cell behind it is as salient and as near as the cell "
              "ahead, and it goes back and forth between two salient cells, which the column "
              "of returns counts. With the shape cue the same pair wins every time: while the walker "
              "stays on cells it has probed the registered templates do not change, and the "
              "cells nearest them win each tie of S and I. The last two columns split each run's "
              "area under Gamma at the step it first probes the task's border: the search "
              "before it, the following after it (a run that never reaches the border is all "
              "search), and an ablation's change of each part against the full model, in % of "
              "the full model's whole area (the two add up to the change of the area).", ""]
    lines += _behaviour_lines(rows)
    stability = {f["claim"]: f["stability"] for f in (judged or {}).get("findings", [])}
    several = judged is not None and judged["replications"] > 1
    lines += ["", "## The paper's findings (Sec. 6.3) and ours", ""]
    if several:
        lines += [f"On the runs above (replication 0, one sample of {spec.runs} start cells, "
                  "the paper's protocol); the verdicts over every replication are under "
                  "[Replications](#replications).", ""]
    if stability and not several:
        lines += ["| the paper | measured here | verdict | stability |", "|---|---|---|---|"]
        lines += [f"| {a} | {b} | {c} | {_share(stability.get(a))} |" for a, b, c in found]
    else:
        lines += ["| the paper | measured here | verdict |", "|---|---|---|"]
        lines += [f"| {a} | {b} | {c} |" for a, b, c in found]
    lines += ["", "Verdicts (on Holm-adjusted p-values): *S* agrees when removing S raises the area "
              "under Gamma with p < 0.01 in every task and no other ablation raises it more, "
              "or none by a margin the paired runs tell from chance (Wilcoxon signed-rank of "
              "the two ablations, p >= 0.01); *U* "
              "when removing U raises it by more than 5% with p < 0.01 in every task; *I* when "
              "the change is under 10% or not significant (p >= 0.01); *R* when the change is "
              "under 10%, not significant, or in the full model's favour; *T* compares the "
              "final Gamma per border cell.", ""]
    if stability and not several and judged is not None:
        lines += [_stability_text(judged), ""]
    lines += _power_lines(rows, spec)
    if several and judged is not None:
        lines += _replication_lines(judged, spec)
    lines += list(extra)
    return "\n".join(lines)


def _p(row: dict, key: str) -> str:
    return f"{row[key]:.3g}" if key in row else ""


def _html(md: str, spec: ExperimentSpec, animation: str | None) -> str:
    """report.md as HTML (the same text, tables and figures), the animation as a video."""
    return html_page(md, spec.name, animation)


def html_page(md: str, title: str, animation: str | None = None) -> str:
    """A report's markdown as an HTML page titled ``title`` (the same text, tables and
    figures); the link to ``animation``, when given, as a video."""
    import markdown

    body = markdown.markdown(md, extensions=["tables"])
    if animation:
        body = body.replace(
            f'<a href="{animation}">{animation}</a>',
            f'<br><video src="{animation}" controls loop style="max-width:100%"></video>')
    style = ("body{font-family:sans-serif;max-width:1300px;margin:1em auto;padding:0 1em}"
             "table{border-collapse:collapse;font-size:13px}td,th{border:1px solid #bbb;"
             "padding:2px 6px}img{max-width:100%}")
    return ("<!doctype html><html><head><meta charset='utf-8'><title>"
            f"{html.escape(title)}</title><style>{style}</style></head><body>{body}"
            "</body></html>")
