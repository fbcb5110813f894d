"""``bayesprog report``: the report of a stored experiment written into ``out/report/``, its
figures drawn (Fig. 11 by a second process where there is one), statistics.json and
findings.json, report.md and report.html."""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from runner.experiments.executors import process_pool, progress_bar, stop_pool
from runner.experiments.experiment import load_results, stored_experiment
from runner.experiments.metrics import border_band
from runner.experiments.store import ResultStore, atomic_write, hold, sweep_partial
from runner.report.build.decision import plot_decision
from runner.report.build.findings import comparison_lines
from runner.report.build.page import _html, _markdown
from runner.report.build.perception import perception_lines
from runner.report.build.plots import (
    plot_gamma_pooled,
    plot_gamma_tasks,
    plot_heatmaps,
    plot_slices,
)
from runner.report.verdicts import findings, judge_replications, pooled, statistics_table


def build_report(out: Path, animation: bool = True, compare: Path | None = None,
                 pool: Any = None) -> Path:
    """Write ``out/report/`` (figures, table, report.md, report.html) from stored results;
    ``compare``: another experiment's output folder whose findings are set beside these;
    ``pool``: a process pool (:func:`~runner.experiments.executors.process_pool`) started
    beforehand, on which Fig. 11 is drawn (else one is started here, where there is a second core).
    The folder is held while the report is written: a run, a report or a search of it started
    meanwhile is refused (:func:`~runner.experiments.store.hold`)."""
    with hold(out, "report", make=False):
        return _build_report(out, animation, compare, pool)


def _build_report(out: Path, animation: bool, compare: Path | None, pool: Any) -> Path:
    store = ResultStore(out)
    manifest = store.manifest()
    experiment = stored_experiment(out)
    spec = experiment.spec
    results = load_results(store, spec)
    # replication 0 is the experiment (its figures and tables); the findings pool them all
    replications = [results] + [load_results(store, spec, q)
                                for q in range(1, spec.replications)]
    scenario = experiment.scenario
    folder = out / "report"
    folder.mkdir(parents=True, exist_ok=True)
    sweep_partial(folder)  # what a report killed half-way left
    borders = {t: int(scenario.border(t).sum()) for t in spec.tasks}
    task = spec.tasks[0]
    shown = "full" if "full" in spec.configurations else spec.configurations[0]
    run, step = following_step(results[f"{task}/{shown}"]["paths"], scenario.border(task),
                               spec.iterations)
    video = "fig11_decision.mp4" if animation else None
    (folder / "fig11_decision.gif").unlink(missing_ok=True)  # an animation of earlier reports
    if video is None:
        (folder / "fig11_decision.mp4").unlink(missing_ok=True)  # not this report's
    fig11 = (out, task, shown, run, step, folder / "fig11_decision.png",
             folder / video if video else None, max(spec.iterations - 1, 1))
    # Fig. 11 (a replay and an animation, the longest part) is drawn by a second process
    # while this one draws the rest, where there is a second core
    with _beside(fig11, pool) as pending:
        rows = statistics_table(results, spec, borders, scenario)
        bar = progress_bar(3, "report figures")
        plot_gamma_tasks(results, spec, folder / "fig10_gamma.png")
        bar.update(1)
        plot_heatmaps(results, spec, scenario, folder / "fig9_visits.png",
                      experiment.start_cells())
        if scenario.dims == 3:
            plot_slices(results, spec, scenario, folder / "fig9_slices.png", shown)
        judged = judge_replications(replications, spec, borders)
        if len(replications) > 1:
            plot_gamma_pooled(pooled(replications), spec, folder / "fig10_gamma_pooled.png")
        else:
            (folder / "fig10_gamma_pooled.png").unlink(missing_ok=True)  # not this report's
        bar.update(1)
        pending()
        bar.update(1)
        bar.close()
    found = findings(rows, spec)
    atomic_write(folder / "statistics.json", json.dumps(_json_safe(rows), indent=1,
                                                        allow_nan=False).encode())
    atomic_write(folder / "findings.json", json.dumps(_json_safe(judged), indent=1,
                                                      allow_nan=False).encode())
    extra = perception_lines(scenario, rows, spec.tasks, folder)
    if compare is not None:
        extra += comparison_lines(found, compare, spec.name)
    md = _markdown(spec, rows, found, borders, step, task, manifest["hash"], run, extra, video,
                   shown, volume=scenario.dims == 3, judged=judged)
    atomic_write(folder / "report.md", md.encode())
    atomic_write(folder / "report.html", _html(md, spec, video).encode())
    return folder


def _plot_stored_decision(out: Path, task: str, configuration: str, run: int, step: int,
                          png: Path, video: Path | None, steps: int) -> None:
    plot_decision(stored_experiment(out), task, configuration, run, step, png, video, steps)


@contextlib.contextmanager
def _beside(fig11: tuple, pool: Any = None) -> Iterator[Callable[[], None]]:
    """Draw Fig. 11 in a second process, ``pool``'s or a new one (one core: here, when waited
    for); yields the wait."""
    if pool is None and (os.cpu_count() or 1) < 2:
        yield lambda: _plot_stored_decision(*fig11)
        return
    if pool is None:
        pool = process_pool(1)
    try:
        future = pool.submit(_plot_stored_decision, *fig11)
        yield future.result
    except BaseException:
        stop_pool(pool)  # Ctrl-C, or a figure that failed: the second process stops now
        raise
    pool.shutdown()


def following_step(paths: np.ndarray, border: np.ndarray, iterations: int) -> tuple[int, int]:
    """A (run, step) at which the walker follows the border: the step that ends the longest
    stretch of consecutive probes within one cell of it, over every run (the first run on a
    tie); (0, 40) when no probe is near it. Far into a stretch the shape cue is in force too.

    >>> border = np.zeros((1, 6), bool); border[0, 3] = True
    >>> following_step(np.array([[0, 3, 0, 0], [0, 2, 3, 4]]), border, 4)
    (1, 2)
    """
    band = border_band(border).ravel()[paths[:, : iterations - 1]]
    best, where = 0, (0, max(min(40, iterations - 2), 0))
    for run, row in enumerate(band):
        length = 0
        for k, near in enumerate(row):
            length = length + 1 if near else 0
            if length > best:
                best, where = length, (run, k)
    return where


def _json_safe(value: Any) -> Any:
    """``value`` for JSON, every number that is not finite (no run reached the border) as
    null, at any depth."""
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_json_safe(v) for v in value]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value
