"""Figs. 9 and 10 of the paper as measured: the visits per cell of each task and configuration
(and, in a volume, slice by slice), and Gamma(k), the mean over the runs with its band, per task
and pooled over replications."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from runner.experiments.experiment import ExperimentSpec, mean_sem
from runner.experiments.metrics import visits
from runner.report import figures
from runner.world.scenario import Scenario


def plot_gamma_tasks(results: dict, spec: ExperimentSpec, out: Path, band: float = 1.0,
                     title: str = "") -> None:
    """Fig. 10: Gamma(k), the mean over runs shaded +- ``band`` SEM (1: the SEM, as the paper
    draws it; 1.96: a 95% interval), one curve per configuration, a panel per task."""
    fig = figures.figure(figsize=(5 * len(spec.tasks), 3.9))
    axes = fig.subplots(1, len(spec.tasks), squeeze=False)
    for ax, task in zip(axes[0], spec.tasks, strict=True):
        for conf in spec.configurations:
            mean, sem = mean_sem(results[f"{task}/{conf}"]["gamma"])
            k = np.arange(mean.size)
            # the full model drawn wide underneath: an ablation equal to it stays visible
            style = ({"color": "black", "lw": 3.0, "alpha": 0.55, "zorder": 1} if conf == "full"
                     else {"lw": 1.3, "ls": "--" if conf == "without_R" else "-", "zorder": 2})
            line, = ax.plot(k, mean, label=conf.replace("_", " "), **style)
            ax.fill_between(k, mean - band * sem, mean + band * sem, alpha=0.2,
                            color=line.get_color(), lw=0)
        ax.set_title(f"Task {task}{title}")
        ax.set_xlabel("iteration k")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, title="mean +- SEM" if band == 1.0 else "mean, 95% interval",
                  title_fontsize=7)
    axes[0, 0].set_ylabel(r"$\Gamma(k)$ (m): summed distance to the border")
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def plot_gamma_pooled(results: dict, spec: ExperimentSpec, out: Path) -> None:
    """Fig. 10 over every replication: Gamma(k), the mean over all their runs with its 95%
    interval (mean +- 1.96 SEM)."""
    runs = next(iter(results.values()))["gamma"].shape[0]
    plot_gamma_tasks(results, spec, out, band=1.96,
                     title=f": {runs} runs, {spec.replications} replications")


def plot_heatmaps(results: dict, spec: ExperimentSpec, scenario: Scenario, out: Path,
                  starts: np.ndarray | None = None) -> None:
    """Fig. 9: per task, the materials with the task's border and the start cells, then the
    visits per run of each configuration (each with its colour bar), the border over them."""
    from matplotlib.lines import Line2D

    view = figures.view(scenario)
    nx, ny = view.shape
    cols = len(spec.configurations) + 1
    # panels as tall as the grid's aspect asks (the paper's 30 x 60: 3.9 in), the first column
    # wider for its legend
    fig = figures.figure(figsize=(2.6 * cols + 1.0, (1.6 * ny / nx + 0.7) * len(spec.tasks)))
    axes = fig.subplots(len(spec.tasks), cols, squeeze=False,
                        gridspec_kw={"width_ratios": [1.45] + [1.0] * (cols - 1)})
    for r, task in enumerate(spec.tasks):
        ax = axes[r, 0]
        extra = [Line2D([], [], color="black", lw=1.2, label=f"{task} border")]
        if starts is not None:
            sx, sy = figures.centre_cm(view, np.ravel_multi_index(tuple(starts.T),
                                                                  scenario.shape))
            ax.plot(sx, sy, "x", color="0.25", ms=3, mew=0.8)
            extra.append(Line2D([], [], ls="", marker="x", color="0.25", ms=4,
                                label="start cells"))
        figures.draw_materials(ax, view, extra=extra)
        figures.draw_border(ax, view, task, colour="black", width=1.2)
        ax.set_title(f"{task}: ground truth" + (f",\n{view.label}"
                                                if isinstance(view, figures.Plane) else ""),
                     fontsize=8)
        for c, conf in enumerate(spec.configurations, 1):
            paths = results[f"{task}/{conf}"]["paths"]
            counts = visits(paths, len(scenario.centres)) / paths.shape[0]
            figures.draw_map(axes[r, c], figures.field(view, counts), view, cmap="hot", vmin=0,
                             label="visits per run" + ("" if view is scenario else
                                                       ", summed over z"),
                             title=f"{task} {conf.replace('_', ' ')}")
            figures.draw_border(axes[r, c], view, task, colour=figures.HOT_BORDER, width=0.7)
    figures.axes_in_cm(axes)
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def slice_heights(scenario: Scenario, count: int = 4) -> list[int]:
    """``count`` z indices evenly spread over the heights that hold an object of a volume."""
    background = scenario.materials.index(scenario.spec.background)
    held = np.flatnonzero((scenario.material_map != background).any(axis=(0, 1)))
    if not held.size:
        held = np.arange(scenario.shape[2])
    return sorted({int(z) for z in np.linspace(held[0], held[-1], count).round()})


def plot_slices(results: dict, spec: ExperimentSpec, scenario: Scenario, out: Path,
                configuration: str) -> None:
    """Fig. 9 of a volume, slice by slice: per task, the visits per run of ``configuration``
    in horizontal slices through the objects, the slice's border of the task over them."""
    heights = slice_heights(scenario)
    nx, ny = scenario.shape[:2]
    fig = figures.figure(figsize=(2.6 * len(heights) + 0.6, (1.6 * ny / nx + 0.7)
                                  * len(spec.tasks)))
    axes = fig.subplots(len(spec.tasks), len(heights), squeeze=False)
    for r, task in enumerate(spec.tasks):
        paths = results[f"{task}/{configuration}"]["paths"]
        counts = visits(paths, len(scenario.centres)) / paths.shape[0]
        top = float(counts.max()) or 1.0  # one colour scale per task: slices compare
        for c, z in enumerate(heights):
            plane = figures.Plane(scenario, z)
            # a slice the task's material does not reach has no border to draw: say so
            absent = "" if (plane.material_map == scenario.task_material(task)).any() else \
                f"\n(no {scenario.spec.tasks[task]} at this height)"
            figures.draw_map(axes[r, c], plane.field(counts), plane, cmap="hot", vmin=0,
                             vmax=top, label="visits per run",
                             title=f"{task} {configuration.replace('_', ' ')}, {plane.label}"
                             + absent)
            figures.draw_border(axes[r, c], plane, task, colour=figures.HOT_BORDER, width=0.7)
    figures.axes_in_cm(axes)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
