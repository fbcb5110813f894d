"""The haptic experiments in a notebook: an output folder shown as its findings and figures, and
one exploration run replayed step by step (belief map, cue maps, path, chosen cell).

>>> from runner.report.notebook import Results, step_view      # doctest: +SKIP
>>> Results("results/quick")                            # doctest: +SKIP
>>> step_view("results/quick", task="T2", run=0)        # doctest: +SKIP
"""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path
from typing import Any

from bayesprog import BayesprogError
from runner.attention.explorer import CONFIGURATIONS
from runner.experiments.experiment import (
    Experiment,
    ExperimentSpec,
    load_experiment,
    stored_experiment,
)
from runner.experiments.store import ResultStore
from runner.report.build import DecisionFigure, build_report, decision_slice, findings, replay

#: the figures of a report, in the order a reader meets them, with their captions
FIGURES = [("fig10_gamma.png", "Gamma(k) (paper Fig. 10)"),
           ("fig9_visits.png", "Visits (paper Fig. 9)"),
           ("fig9_slices.png", "Visits in slices of the volume (Fig. 9 of a 3-D workspace)"),
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
            build_report(self.folder, animation=False)
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


class StepView:
    """One run replayed: per step, the ground truth, the material belief map, the cue maps, the
    shape cue and the posterior over the next target, with the path, its start and the chosen
    cell (Fig. 11 at every step). Displays as a video with a seek bar; ``figure(k)`` draws step
    ``k`` alone."""

    def __init__(self, experiment: Experiment, task: str, configuration: str, run: int,
                 frames: list[dict]):
        self.experiment, self.task, self.configuration, self.run = (experiment, task,
                                                                    configuration, run)
        self.frames = frames

    def _figure(self, z: int | None) -> DecisionFigure:
        return DecisionFigure(self.experiment.scenario, self.task,
                              f"Experiment {self.experiment.spec.name}: task {self.task}, "
                              f"{self.configuration}, run {self.run}", z)

    def figure(self, k: int) -> Any:
        """Step ``k`` as a matplotlib figure (in a volume, the slice of the chosen cell), its
        caption with the probe's readings by name."""
        figure = self._figure(decision_slice(self.experiment.scenario, [self.frames[k]]))
        figure.show(self.frames[k], k)
        read = self.frames[k].get("readings", {})
        shown = [f"{name} {'missing' if v is None else (f'{v:.4g}' if isinstance(v, float) else v)}"
                 for name, v in read.items()]
        figure.caption.axes.text(0.0, 0.0, "the probe's readings:\n  " + "\n  ".join(shown),
                                 va="bottom", fontsize=8, transform=figure.caption.axes.transAxes)
        return figure.fig

    def readings(self) -> Any:
        """The replayed run's probes as a pandas DataFrame: the step, the probed cell and each
        reading by its name (None where missing)."""
        import pandas as pd

        return pd.DataFrame([{"step": k, "cell": f["cell"], **f.get("readings", {})}
                             for k, f in enumerate(self.frames)])

    def _repr_html_(self) -> str:
        import tempfile

        # in a volume, one slice for the whole video: where most chosen cells lie
        figure = self._figure(decision_slice(self.experiment.scenario, self.frames))
        figure.fig.set_dpi(80)
        with tempfile.TemporaryDirectory() as folder:
            video = Path(folder) / "run.mp4"
            figure.video(self.frames, video, fps=4)
            data = base64.b64encode(video.read_bytes()).decode()
        title = (f"<p><b>{html.escape(self.experiment.spec.name)}</b>: task {self.task}, "
                 f"{self.configuration}, run {self.run}, {len(self.frames)} steps</p>")
        return (f'{title}<video controls loop style="max-width:100%" '
                f'src="data:video/mp4;base64,{data}"></video>')


def step_view(source: str | Path | Experiment, task: str | None = None,
              configuration: str = "full", run: int = 0, steps: int = 40) -> StepView:
    """Replay run ``run`` of ``configuration`` on ``task`` for ``steps`` steps. ``source`` is an
    experiment file, an experiment's output folder, or a loaded experiment; the run is the same
    as the stored one (same seeds)."""
    if isinstance(source, Experiment):
        experiment = source
    else:
        path = Path(source)
        experiment = stored_experiment(path) if path.is_dir() else load_experiment(path)
    task = task or experiment.spec.tasks[0]
    if steps < 1:
        raise BayesprogError(f"steps: expected at least 1, found {steps}")
    if configuration not in CONFIGURATIONS:
        raise BayesprogError(f"configuration: expected one of {', '.join(CONFIGURATIONS)}, "
                             f"found {configuration!r}")
    if task not in experiment.scenario.spec.tasks:
        raise BayesprogError(f"task: expected one of {', '.join(experiment.scenario.spec.tasks)}"
                             f", found {task!r}")
    if not 0 <= run < experiment.spec.runs:
        raise BayesprogError(f"run: expected 0 .. {experiment.spec.runs - 1}, found {run}")
    frames = list(replay(experiment, task, configuration, run, steps))
    return StepView(experiment, task, configuration, run, frames)
