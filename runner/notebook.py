"""The haptic experiments in a notebook: an output folder shown as its findings and figures, and
one exploration run replayed step by step (belief map, cue maps, path, chosen cell).

>>> from runner.notebook import Results, step_view      # doctest: +SKIP
>>> Results("results/quick")                            # doctest: +SKIP
>>> step_view("results/quick", task="T2", run=0)        # doctest: +SKIP
"""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path
from typing import Any

import numpy as np

from runner.experiment import Experiment, ExperimentSpec, load_experiment
from runner.report import build_report, findings, replay
from runner.store import ResultStore

#: the figures of a report, in the order a reader meets them, with their captions
FIGURES = [("fig10_gamma.png", "Gamma(k) (paper Fig. 10)"),
           ("fig9_visits.png", "Visits (paper Fig. 9)"),
           ("fig11_decision.png", "One decision (paper Fig. 11)")]


class Results:
    """An experiment's output folder. Displays as its findings table and figures; ``statistics``
    is the statistics table (a list of rows), ``findings`` the paper's findings beside ours, and
    ``table()`` the statistics as a pandas DataFrame. The report is built if it is missing."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self.store = ResultStore(self.folder)
        manifest = self.store.manifest()
        self.spec = ExperimentSpec.model_validate(manifest["experiment"])
        stats = self.folder / "report" / "statistics.json"
        if not stats.is_file():
            build_report(self.folder, gif=False)
        self.statistics: list[dict] = json.loads(stats.read_text(encoding="utf-8"))
        self.findings = findings(self.statistics, self.spec)

    def table(self) -> Any:
        import pandas as pd

        return pd.DataFrame(self.statistics)

    def _repr_html_(self) -> str:
        rows = "".join(f"<tr><td>{html.escape(a)}</td><td>{html.escape(b)}</td>"
                       f"<td><b>{html.escape(c)}</b></td></tr>" for a, b, c in self.findings)
        parts = [f"<h3>Experiment {html.escape(self.spec.name)}</h3>",
                 f"<p>{html.escape(self.spec.description.strip())}</p>",
                 '<table style="font-size:12px"><tr><th>the paper</th><th>measured here</th>'
                 f"<th>verdict</th></tr>{rows}</table>"]
        for name, caption in FIGURES:
            path = self.folder / "report" / name
            if path.is_file():
                data = base64.b64encode(path.read_bytes()).decode()
                parts.append(f"<p><b>{html.escape(caption)}</b></p>"
                             f'<img src="data:image/png;base64,{data}" style="max-width:100%"/>')
        return "<div>" + "".join(parts) + "</div>"

    def __repr__(self) -> str:
        verdicts = ", ".join(f"{c}" for _, _, c in self.findings)
        return f"Results({str(self.folder)!r}, experiment={self.spec.name!r}, findings: {verdicts})"


#: the panels of a step: (frame key, title, colour bar label, fixed range or None)
PANELS = [("belief", "belief: P(M = task material)", "probability", (0, 1)),
          ("S", "saliency S", "S", (0, 1)), ("U", "uncertainty U", "U", (0, 1)),
          ("I", "inhibition I", "I", (0, 1)), ("shape", "shape cue R", "P(O | R)", None),
          ("posterior", "P(O | ...): next target", "P", None)]


class StepView:
    """One run replayed: per step, the material belief map, the cue maps, the shape cue and the
    posterior over the next target, with the path (white) and the chosen cell (red star).
    Displays as an inline animation with a slider; ``figure(k)`` draws step ``k`` alone."""

    def __init__(self, experiment: Experiment, task: str, configuration: str, run: int,
                 frames: list[dict]):
        self.experiment, self.task, self.configuration, self.run = (experiment, task,
                                                                    configuration, run)
        self.frames = frames

    def figure(self, k: int) -> Any:
        from matplotlib.figure import Figure

        fig = Figure(figsize=(2.3 * len(PANELS), 3.6))
        axes = fig.subplots(1, len(PANELS))
        self._draw(axes, k, colorbars=True)
        fig.tight_layout()
        return fig

    def _draw(self, axes: Any, k: int, colorbars: bool = False) -> None:
        import matplotlib

        scenario = self.experiment.scenario
        nx, ny = scenario.shape
        cell = scenario.cell * 100  # cm
        frame = self.frames[k]
        path = np.array(frame["path"])
        bx, by = np.nonzero(scenario.border(self.task))
        cmap = matplotlib.colormaps["viridis"].with_extremes(bad="0.55")
        for ax, (key, title, label, limits) in zip(axes, PANELS, strict=True):
            ax.clear()
            low, high = limits or (None, None)
            image = ax.imshow(np.asarray(frame[key], float).reshape(nx, ny).T, origin="lower",
                              extent=(0, nx * cell, 0, ny * cell), cmap=cmap, vmin=low, vmax=high)
            ax.scatter((bx + 0.5) * cell, (by + 0.5) * cell, s=0.4, c="c")
            ax.plot((path // ny + 0.5) * cell, (path % ny + 0.5) * cell, "w-", lw=0.6)
            ax.plot((path[0] // ny + 0.5) * cell, (path[0] % ny + 0.5) * cell, "wo", ms=3)
            nxt = frame["next"]
            ax.plot((nxt // ny + 0.5) * cell, (nxt % ny + 0.5) * cell, "r*", ms=8)
            ax.set_title(f"{title}\nk = {k}", fontsize=8)
            ax.tick_params(labelsize=6)
            ax.set_xlabel("x (cm)", fontsize=7)
            if colorbars:
                bar = ax.figure.colorbar(image, ax=ax, fraction=0.05, pad=0.02)
                bar.set_label(label, fontsize=6)
                bar.ax.tick_params(labelsize=5)
        axes[0].set_ylabel("y (cm)", fontsize=7)

    def _repr_html_(self) -> str:
        from matplotlib.animation import FuncAnimation
        from matplotlib.figure import Figure

        fig = Figure(figsize=(1.9 * len(PANELS), 3.0), dpi=72)
        axes = fig.subplots(1, len(PANELS))
        anim = FuncAnimation(fig, lambda k: self._draw(axes, k), frames=len(self.frames))
        title = (f"<p><b>{html.escape(self.experiment.spec.name)}</b>: task {self.task}, "
                 f"{self.configuration}, run {self.run}, {len(self.frames)} steps (path white, "
                 "start white dot, chosen cell red star, border cyan)</p>")
        return title + anim.to_jshtml(fps=6, default_mode="once")


def step_view(source: str | Path | Experiment, task: str | None = None,
              configuration: str = "full", run: int = 0, steps: int = 40) -> StepView:
    """Replay run ``run`` of ``configuration`` on ``task`` for ``steps`` steps. ``source`` is an
    experiment file, an experiment's output folder, or a loaded experiment; the run is the same
    as the stored one (same seeds)."""
    if isinstance(source, Experiment):
        experiment = source
    else:
        path = Path(source)
        if path.is_dir():
            path = Path(ResultStore(path).manifest()["files"]["experiment"]["path"])
        experiment = load_experiment(path)
    task = task or experiment.spec.tasks[0]
    frames = list(replay(experiment, task, configuration, run, steps))
    return StepView(experiment, task, configuration, run, frames)
