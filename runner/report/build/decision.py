"""Fig. 11 of the paper: one decision of pi_tar replayed step by step (the fields behind it: the
belief, the cues S, U, I, the shape cue and the posterior over the next cell), drawn at one step
as a PNG and over the run as an MP4."""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from runner.attention.explorer import CONFIGURATIONS, Explorer
from runner.experiments.executors import progress_bar
from runner.experiments.experiment import Experiment
from runner.report import figures
from runner.world.readings import shown
from runner.world.scenario import Scenario


def replay(experiment: Experiment, task: str, configuration: str, run: int, steps: int
           ) -> Iterator[dict[str, Any]]:
    """Re-run one run (deterministic) and yield, per step, the fields behind its decision."""
    from runner.experiments.loop import start_runs
    from runner.experiments.loop import steps as loop_steps

    spec = experiment.spec
    scenario = experiment.scenario
    explorer = Explorer(scenario, task, ablate=CONFIGURATIONS[configuration])
    sensor = start_runs(explorer, experiment.start_cells()[run : run + 1], spec.seed, [run])
    shape_only = explorer.target.ablate("P(I | O)", "P(S | O, T)", "P(U | O)")
    for step in loop_steps(explorer, sensor, steps, decide_last=True):
        assert step.next is not None
        cells, decision_cells = step.cells, step.next
        d = explorer.decision
        evidence = {"T": task, "I": d.inhibition, "S": d.saliency, "U": d.uncertainty}
        if d.templates is not None and d.shape_ready is not None and d.shape_ready[0]:
            inputs = {"templates": d.templates, "errors": d.shape_error}
            shape = shape_only.posterior("P(O | T, I, S, U)", evidence, inputs=inputs)
            shape_field = shape.probabilities[0]
        else:
            shape_field = np.full(len(scenario.centres), 1.0 / len(scenario.centres))
        posterior = explorer.target_probabilities[0]
        belief = explorer.belief()[0]
        yield {"I": d.inhibition[0], "S": d.saliency[0], "U": d.uncertainty[0], "belief": belief,
               "shape": shape_field, "posterior": posterior, "cell": int(cells[0]),
               "next": int(decision_cells[0]), "path": [int(p[0]) for p in explorer.path],
               "readings": shown(explorer.readings, step.readings)}


class DecisionFigure:
    """Fig. 11: the fields behind one decision of pi_tar, with the ground truth. Built once;
    ``show(frame, k)`` draws a step (the animation redraws only what changes)."""

    #: (frame key, title, colour bar label, fixed range)
    PANELS = [("belief", "belief P(M = task material)", "probability (grey: not probed)", (0, 1)),
              ("S", "saliency S (eq. 12)", "S (grey: not observed)", (0, 1)),
              ("U", "uncertainty U (eq. 11)", "U: normalised entropy", (0, 1)),
              ("I", "inhibition I (eq. 10)", "I: inhibition level", (0, 1)),
              ("shape", "shape cue P(O | R)", "probability per cell", None),
              ("posterior", "P(O | t, i, s, u, R) (eq. 13)", "probability per cell", None)]

    def __init__(self, scenario: Scenario, task: str, title: str = "", z: int | None = None):
        """``z``: in a volume, the height index of the slice drawn."""
        self.scenario, self.task = scenario, task
        self.view = figures.view(scenario, z or 0)
        view = self.view
        nx, ny = view.shape  # rows as tall as the grid's aspect asks (30 x 60: 4.8 in)
        self.fig = figures.figure(figsize=(13, 2 * (2.0 * ny / nx + 0.8)))
        axes = self.fig.subplots(2, 4)
        self.axes = axes
        flat = list(axes.ravel())
        nan = np.full(nx * ny, np.nan)
        truth = flat[0]
        figures.draw_materials(truth, view)
        figures.draw_border(truth, view, task, colour="black", width=1.2)
        where = "" if view is scenario else f", {view.label}"  # type: ignore[union-attr]
        truth.set_title(f"ground truth, {task} border{where}", fontsize=8)
        self.images = {}
        for ax, (key, name, label, limits) in zip(flat[1:7], self.PANELS, strict=True):
            low, high = limits or (0, 1)
            self.images[key] = figures.draw_map(ax, nan, view, vmin=low, vmax=high,
                                                label=label, title=name + where)
            figures.draw_border(ax, view, task, width=0.6)
        self.path_axes = [flat[0], *flat[1:7]]
        self.lines: list = []
        self.fixed = False
        flat[7].axis("off")
        # the caption's first two lines change with the step; the legend below them does not
        # (a video redraws only the first, and the fewer glyphs the faster)
        self.caption = flat[7].text(0.0, 0.98, "", va="top", fontsize=8,
                                    transform=flat[7].transAxes)
        # three lines below the caption's top, whatever the panel's height
        flat[7].annotate("red star: the next cell, the MAP\n  of P(O | ...)\n"
                         "white line: the path so far" + (" (seen from above;\n  dots: its "
                                                           "probes in this slice)" if where
                                                           else "")
                         + "\nwhite circle: the start cell\n"
                         f"magenta (black in the first panel):\n  the ground-truth border of "
                         f"{task}\n\ngrey: a cell not probed (belief),\n  or a saliency with "
                         "nothing perceived\n  to compare (the term is left out)",
                         xy=(0.0, 0.98), xycoords="axes fraction", xytext=(0, -3 * 8 * 1.25),
                         textcoords="offset points", va="top", fontsize=8)
        figures.axes_in_cm(axes)
        self.fig.suptitle(title, fontsize=10)
        self.fig.tight_layout()

    def video(self, frames: list[dict], out: Path, fps: int = 6) -> None:
        """Every frame into an MP4 at the figure's resolution. The axes, ticks and colour bars
        are drawn once; each frame redraws only the maps, borders, path and caption."""
        import imageio_ffmpeg

        for key, _, _, limits in self.PANELS:  # one colour scale over the whole run
            if limits is None:
                top = max((float(np.nanmax(f[key])) for f in frames), default=1.0)
                self.images[key].set_clim(0, top if top > 0 else 1.0)
        self.fixed = True
        dynamic = [*self.images.values(), self.caption]
        for ax in self.path_axes:
            dynamic += list(ax.collections)
        for artist in dynamic:
            artist.set_animated(True)
        canvas = self.fig.canvas
        width, height = canvas.get_width_height()
        if width % 2 or height % 2:  # H.264 in yuv420p takes even sizes: one pixel more
            dpi = self.fig.get_dpi()
            self.fig.set_size_inches((width + width % 2) / dpi, (height + height % 2) / dpi)
        self.show(frames[0], 0)
        canvas.draw()
        background = canvas.copy_from_bbox(self.fig.bbox)
        width, height = canvas.get_width_height()
        # written beside, then renamed over ``out``: the animation is whole or not there
        # (a name of its own: another process's report may be writing beside it)
        partial = out.with_name(f".{out.stem}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp"
                                f"{out.suffix}")
        writer = imageio_ffmpeg.write_frames(
            str(partial), (width, height), fps=fps, codec="libx264", pix_fmt_in="rgba",
            pix_fmt_out="yuv420p", macro_block_size=2, ffmpeg_log_level="fatal",
            output_params=["-crf", "26", "-preset", "ultrafast"])
        writer.send(None)
        bar = progress_bar(len(frames), "Fig. 11 animation")
        try:
            for k, frame in enumerate(frames):
                canvas.restore_region(background)
                self.show(frame, k)
                for artist in dynamic + self.lines:
                    self.fig.draw_artist(artist)
                writer.send(canvas.buffer_rgba())  # (the canvas's memory, not a copy)
                bar.update(1)
            writer.close()
            os.replace(partial, out)
        except BaseException:
            writer.close()
            partial.unlink(missing_ok=True)
            raise
        finally:
            bar.close()
        for artist in dynamic:
            artist.set_animated(False)
        self.fixed = False

    def show(self, frame: dict, k: int) -> None:
        for key, _, _, limits in self.PANELS:
            values = figures.field(self.view, frame[key])
            image = self.images[key]
            image.set_data(values.reshape(self.view.shape).T)
            if limits is None and not self.fixed:
                finite = values[np.isfinite(values)]
                image.set_clim(0, float(finite.max()) if finite.size and finite.max() > 0 else 1)
        if not self.lines:  # the path, its start, the next cell (and a slice's probes)
            for ax in self.path_axes:
                self.lines += figures.draw_path(ax, self.view, frame["path"], frame["next"])
        else:  # moved, not drawn anew
            points = figures.path_points(self.view, frame["path"], frame["next"])
            for i in range(0, len(self.lines), len(points)):
                for line, (x, y) in zip(self.lines[i : i + len(points)], points, strict=True):
                    line.set_data(x, y)
        for line in self.lines:
            line.set_animated(self.fixed)  # in a video, never part of the static background
        at = self.scenario.centres[frame["next"]] * 100
        self.caption.set_text(f"step k = {k}\nnext cell: ({', '.join(f'{v:.1f}' for v in at)}) cm")


def decision_slice(scenario: Scenario, frames: list[dict]) -> int | None:
    """In a volume, the height index of the slice to draw ``frames`` on: the one most of their
    chosen cells lie in (None on a 2-D workspace). The path is drawn seen from above."""
    if scenario.dims == 2:
        return None
    heights = np.unravel_index([f["next"] for f in frames], scenario.shape)[2]
    return int(np.bincount(heights).argmax())


#: The animation's resolution: 1,040 x 770 pixels for the paper's grid (the PNG has 110 dpi);
#: 100 frames are drawn and encoded in about a second and a half.
VIDEO_DPI = 80


def plot_decision(experiment: Experiment, task: str, configuration: str, run: int, step: int,
                  out_png: Path, out_video: Path | None, steps: int) -> None:
    """Fig. 11 at ``step`` (PNG), and (MP4) every step of the run (``VIDEO_DPI``)."""
    bar = progress_bar(steps, "Fig. 11 replay")
    frames = []
    for frame in replay(experiment, task, configuration, run, steps):
        frames.append(frame)
        bar.update(1)
    bar.close()
    title = (f"Experiment {experiment.spec.name}: task {task}, "
             f"{'full model' if configuration == 'full' else configuration}, run {run}")
    shown = frames[min(step, len(frames) - 1)]
    z = decision_slice(experiment.scenario, [shown])  # in a volume, the chosen cell's slice
    figure = DecisionFigure(experiment.scenario, task, title, z)
    figure.show(shown, step)
    figure.fig.savefig(out_png, dpi=110)
    if out_video is not None:
        # in a volume the video keeps one slice: the one most chosen cells lie in (as a
        # notebook's step view)
        whole = decision_slice(experiment.scenario, frames)
        if whole != z:
            figure = DecisionFigure(experiment.scenario, task, title, whole)
        figure.fig.set_dpi(VIDEO_DPI)
        figure.video(frames, out_video)
