"""The experiment report: figures (paper Fig. 9, 10, 11), a statistics table, and the paper's
findings (Sec. 6.3) beside what was measured. Built from stored results only."""

from __future__ import annotations

import contextlib
import html
import json
import os
import uuid
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bayesprog import BayesprogError
from runner.attention.explorer import CONFIGURATIONS, Explorer
from runner.experiments.executors import process_pool, progress_bar, stop_pool
from runner.experiments.experiment import (
    Experiment,
    ExperimentSpec,
    load_results,
    mean_sem,
    stored_experiment,
)
from runner.experiments.metrics import area_under, border_band, paired_test, visits  # noqa: F401
from runner.experiments.store import ResultStore, atomic_write, hold, sweep_partial
from runner.report import figures
from runner.report.verdicts import (  # noqa: F401  (the report's statistics, read from here too)
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
from runner.world.physics import PhysicsSensor
from runner.world.readings import shown
from runner.world.scenario import Scenario
from runner.world.sensor import Pooled, ProgramNormals, SensorModel, confusion


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


#: held-out probes per material for the report's confusion matrix, and their seed
HELD_OUT, HELD_OUT_SEED = 2000, 7


#: held-out presses per material of a physics sensor (each a simulation of a few milliseconds)
HELD_OUT_PRESSES = 200


def held_out_model(scenario: Scenario) -> SensorModel | ProgramNormals | Pooled:
    """What the report's held-out probes are drawn from when the scenario names no sensor:
    the perception program's Normals (the paper's, as a sensor model of its two readings, the
    draws its reports have always shown), else draws of the program given each material."""
    model = scenario.program_sensor()
    if isinstance(model, ProgramNormals) and set(model.names) == {"texture", "compliance"}:
        return SensorModel.from_program(scenario.readings)
    return model


def physics_confusion(scenario: Scenario, per_material: int, seed: int) -> np.ndarray:
    """Single-press confusion of the scenario's perception program on fresh presses of the
    simulated fingertip at random cells of each material of the layout (seeded by ``seed``,
    the material and the press, so none is a press it was learned from unless it was learned
    with that seed): row = true material, column = the MAP material; rows of materials not
    laid stay zero."""
    from runner.world.physics import press_cells

    scene = scenario.physics_scene()
    k = len(scenario.materials)
    out = np.zeros((k, k))
    for m, cells in press_cells(scenario.material_map, per_material, seed):
        readings = PhysicsSensor(scene, []).readings(
            [scene.probe(int(c), np.random.default_rng([seed, m, i]))
             for i, c in enumerate(cells)])
        post = scenario.readings.posterior(readings)
        np.add.at(out[m], post.argmax(-1), 1.0 / per_material)
    return out


def perception_lines(scenario: Scenario, rows: list[dict], tasks: list[str],
                     folder: Path | None = None) -> list[str]:
    """Which materials the perception program recognises from one probe of the scenario's
    sensor, and whether the least accurately followed task has the least recognised material;
    with the report's ``folder``, the recordings the scenario learns from drawn beside."""
    noise = scenario.spec.sensor.extra_noise
    held_out = HELD_OUT
    if scenario.spec.sensor.physics is not None:
        held_out = HELD_OUT_PRESSES
        matrix = physics_confusion(scenario, held_out, HELD_OUT_SEED)
        source = ("Probes are presses and strokes of a simulated fingertip (MuJoCo; the "
                  "materials' properties from models/physics/materials.yaml and the scenario's "
                  "physics:)")
    else:
        model = scenario.sensor_model or held_out_model(scenario)
        matrix = confusion(scenario.readings, model, held_out, HELD_OUT_SEED, noise)
        if isinstance(scenario.sensor_model, SensorModel):
            origin = f"the sensor model `{scenario.sensor_model.spec.name}`"
        elif isinstance(model, Pooled):
            origin = f"the {model.source}"
        else:
            origin = "the perception program's own Normals"
        source = "Probes are simulated from " + origin
    names = list(scenario.materials)
    learned = scenario.perception.learned
    origin = ("written by hand" if not learned else
              f"learned from {learned[-1].rows_used} probes of `{learned[-1].data}` "
              f"({learned[-1].method})")
    named = ", ".join(r.name + (f" ({r.variable})" if r.variable != r.name else "")
                      + (f", one of {'/'.join(r.states)}" if r.states else "")
                      for r in scenario.readings.readings)
    lines = ["## Perception (pi_per)", "",
             f"pi_per perceives the material {scenario.readings.material} of a probed cell "
             f"through {len(scenario.readings.readings)} reading(s): {named}. "
             f"Its parameters are {origin}. {source}"
             + (f" plus white noise of sd {noise}" if noise else "") + f". Single-probe "
             f"recognition on {held_out} held-out probes per material (seed {HELD_OUT_SEED}): "
             f"{100 * np.diag(matrix).mean():.1f}% on average over the {len(names)} materials.", "",
             "| material in the scenario | recognised | most often taken for |", "|---|---|---|"]
    used = list(dict.fromkeys([scenario.spec.background]
                              + [o.material for o in scenario.spec.objects]))
    for m in used:
        i = names.index(m)
        others = sorted(((matrix[i, j], names[j]) for j in range(len(names)) if j != i),
                        reverse=True)
        taken = ", ".join(f"{n} {100 * v:.1f}%" for v, n in others[:2] if v >= 0.001) or "-"
        lines.append(f"| {m} | {100 * matrix[i, i]:.1f}% | {taken} |")
    if folder is not None:
        perception = scenario.readings
        lines += recordings_section(scenario, folder, readings=list(perception.names),
                                    discrete=[r.name for r in perception.readings if r.discrete])
    per = {r["task"]: r["final_per_border_cell_mm"] for r in rows if r["configuration"] == "full"}
    if set(per) >= set(tasks) and len(tasks) > 1:
        rate = {t: matrix[scenario.task_material(t), scenario.task_material(t)] for t in tasks}
        worst_task = max(tasks, key=lambda t: per[t])
        hardest = min(tasks, key=lambda t: rate[t])
        lines += ["", ", ".join(f"{t} ({names[scenario.task_material(t)]}): recognised "
                                f"{100 * rate[t]:.1f}%, final Gamma per border cell "
                                f"{per[t]:.1f} mm" for t in tasks) + "."]
        if len({round(float(r), 3) for r in rate.values()}) == 1:
            pass  # every task's material recognised alike: perception does not order them
        elif worst_task == hardest:
            lines.append(f"The least accurately followed task, {worst_task}, is also the one "
                         "whose material is least recognised, as the paper explains its T3.")
        else:
            lines.append(f"The least accurately followed task is {worst_task}, but the least "
                         f"recognised material is {hardest}'s: perception alone does not "
                         "explain the order here (the layout of the border does too).")
    return lines + [""]


#: what each of a scenario's recordings is for (:meth:`Scenario.recordings_paths`)
RECORDINGS_ROLES = {"perception_recordings": "pi_per is learned from",
                    "sensor_recordings": "the simulated sensor is fitted to",
                    "sensor_resampled": "the simulated sensor resamples"}

#: the report's figures of recordings: the first file, the second (a scenario may learn pi_per
#: from one file and fit its sensor to another)
RECORDINGS_FIGURES = ("recordings.png", "recordings_2.png")


#: the columns of a recordings file that are not readings: the cell pressed, and the raw
#: figures of a physics press (runner.robot.presses.RAW_COLUMNS, which a test holds them to)
NOT_READINGS = ("ix", "iy", "iz", "force_n", "depth_m", "friction_ratio", "tangential_sd_n")


def recording_columns(columns: Sequence[str]) -> list[str]:
    """The readings among a recordings file's ``columns`` (its material's left out), until a
    perception names them: every column but the cell pressed and a physics press's raw
    figures."""
    return [c for c in columns if c not in NOT_READINGS]


def recordings_section(scenario: Scenario, folder: Path, readings: Sequence[str] | None = None,
                       material: str | None = None, discrete: Sequence[str] = ()) -> list[str]:
    """The recordings the scenario learns pi_per from or fits its sensor to, drawn into
    ``folder`` (:func:`figures.recordings_figure`), and the report's lines that show them; none
    for a scenario without recordings. ``readings``: the columns drawn (default:
    :func:`recording_columns`); ``material``: the material column (default: ``material``,
    ``M``, else the first that is not numbers); ``discrete``: readings drawn as states even if
    they are numbers. A file is read as it was stored with the results in ``folder``'s parent,
    when they hold it (else from its path): the report shows what the runs learned from."""
    import tempfile

    from bayesprog import summarise

    files: dict[Path, list[str]] = {}  # a file learned from and fitted to: one figure
    for role, path in scenario.recordings_paths().items():
        files.setdefault(Path(path), []).append(role)
    stored = _stored_files(folder.parent)
    lines: list[str] = []
    written: set[str] = set()
    for (path, roles), png in zip(files.items(), RECORDINGS_FIGURES, strict=False):
        text = next((stored[r].get("text") for r in roles if r in stored), None)
        with tempfile.TemporaryDirectory(prefix="bayesprog-recordings-") as tmp:
            source = path
            if isinstance(text, str):  # the stored copy, under the file's own name
                source = Path(tmp) / path.name
                source.write_text(text, encoding="utf-8")
            whole = summarise(source, material, source=path.name)
            shown = list(readings) if readings is not None else recording_columns(whole.columns)
            if not shown:
                continue
            summary = summarise(source, whole.by, shown, discrete, source=path.name)
            figures.recordings_figure(source, whole.by, shown, folder / png, discrete=discrete,
                                      title=f"{path.name}: {summary.rows} presses")
        written.add(png)
        counts = ", ".join(f"{m} {n}" for m, n in summary.counts.items())
        empty = {c: int(t["missing"].sum())
                 for c, t in {**summary.real, **summary.discrete}.items()}
        missing = ", ".join(f"{c} {empty[c]}" for c in shown if empty[c])
        uses = " and ".join(RECORDINGS_ROLES[r] for r in roles)
        lines += [f"![Recordings {path.name}]({png})", "",
                  f"*The recordings `{path.name}` that {uses}: {summary.rows} presses "
                  f"({counts}). Off the diagonal, every pair of the readings "
                  f"{', '.join(shown)}, one colour per material; on the diagonal, each "
                  "reading's histogram per material (a reading of states: the count of each). "
                  + (f"Missing readings, each left out of the pairs it is in: {missing}."
                     if missing else "No reading is missing.") + "*", ""]
    for png in set(RECORDINGS_FIGURES) - written:  # an earlier report's
        (folder / png).unlink(missing_ok=True)
    return [""] + lines if lines else []


def _stored_files(out: Path) -> dict[str, Any]:
    """The files stored with the results in ``out`` (role -> path and text); none when ``out``
    holds no readable manifest."""
    try:
        files = ResultStore(out).manifest().get("files", {})
    except (OSError, ValueError, BayesprogError):
        return {}
    return files if isinstance(files, dict) else {}


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
