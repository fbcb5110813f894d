"""The experiment report: figures (paper Fig. 9, 10, 11), a statistics table, and the paper's
findings (Sec. 6.3) beside what was measured. Built from stored results only.

:func:`build_report` (:mod:`~runner.report.build.write`) writes it: Figs. 9 and 10
(:mod:`~runner.report.build.plots`), Fig. 11 replayed and animated
(:mod:`~runner.report.build.decision`), the perception section
(:mod:`~runner.report.build.perception`), the findings in words
(:mod:`~runner.report.build.findings`), and the page itself, report.md and report.html
(:mod:`~runner.report.build.page`). The statistics and verdicts it reports are computed in
:mod:`runner.report.verdicts`, and read from here too.
"""

from runner.experiments.metrics import area_under, border_band, paired_test, visits
from runner.report.build.decision import (
    VIDEO_DPI,
    DecisionFigure,
    decision_slice,
    plot_decision,
    replay,
)
from runner.report.build.findings import comparison_lines
from runner.report.build.page import GLOSSARY, html_page
from runner.report.build.perception import (
    HELD_OUT,
    HELD_OUT_PRESSES,
    HELD_OUT_SEED,
    NOT_READINGS,
    RECORDINGS_FIGURES,
    RECORDINGS_ROLES,
    held_out_model,
    perception_lines,
    physics_confusion,
    recording_columns,
    recordings_section,
)
from runner.report.build.plots import (
    plot_gamma_pooled,
    plot_gamma_tasks,
    plot_heatmaps,
    plot_slices,
    slice_heights,
)
from runner.report.build.write import build_report, following_step
from runner.report.verdicts import (
    ALPHA,
    FINDINGS,
    POWER,
    SMALLEST_EFFECT,
    _full_auc,
    _heap_frozen,
    _unseen,
    findings,
    judge_replications,
    pooled,
    statistics_table,
)

__all__ = [
    "ALPHA", "FINDINGS", "GLOSSARY", "HELD_OUT", "HELD_OUT_PRESSES", "HELD_OUT_SEED",
    "NOT_READINGS", "POWER", "RECORDINGS_FIGURES", "RECORDINGS_ROLES", "SMALLEST_EFFECT",
    "VIDEO_DPI", "DecisionFigure", "_full_auc", "_heap_frozen", "_unseen", "area_under",
    "border_band", "build_report", "comparison_lines", "decision_slice", "findings",
    "following_step", "held_out_model", "html_page", "judge_replications", "paired_test",
    "perception_lines", "physics_confusion", "plot_decision", "plot_gamma_pooled",
    "plot_gamma_tasks", "plot_heatmaps", "plot_slices", "pooled", "recording_columns",
    "recordings_section", "replay", "slice_heights", "statistics_table", "visits",
]
