"""The report's perception section: how well pi_per recognises each material from one probe of the
scenario's sensor (held-out probes, or presses of the simulated fingertip), and the recordings
the scenario learns from, drawn."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bayesprog import BayesprogError
from runner.experiments.store import ResultStore
from runner.report import figures
from runner.world.physics import PhysicsSensor
from runner.world.scenario import Scenario
from runner.world.sensor import Pooled, ProgramNormals, SensorModel, confusion

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
