"""The report of a session's log (``bayesprog report LOG.csv``): the session replayed and drawn.

A log (:mod:`runner.experiments.log`) keeps every probe of an exploration driven over stdio or ROS 2,
or of a robot's closed loop, and beside it what was explored. The report replays the probes
through a fresh :class:`~runner.attention.explorer.Explorer` of the scenario, its task and
ablations, reset as the session was (its seed, or an experiment run's decisions' stream, and
the first probed cell), feeding each row's cell and readings to :meth:`Explorer.observe`, the
step every driver makes: the final maps are the replay's, and each of its decisions is set
beside the next cell the log says was chosen. A log of a real robot whose probes missed their
targets is replayed where the probes were made, and is drawn all the same; a decision that
differs (the scenario or its programs edited since) is said, not refused.

Written into ``LOG_report/`` beside the log: ``path.png`` (the probes in order over the
layout's materials and the task's border), ``maps.png`` (the final belief, the materials
decided, the last decision's cues and its posterior over the next cell), ``report.md`` and
``report.html`` (the session's numbers: probes, missing readings, warnings, the recognition of
the layout's materials, Gamma and the path length, the timings) and ``summary.json`` (the
same numbers).
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bayesprog import BayesprogError
from runner.attention.explorer import Explorer
from runner.experiments.log import PHASES, Probe, meta_path, read_meta, read_probes
from runner.experiments.loop import decision_seed
from runner.experiments.metrics import BorderDistance, behaviour, moves
from runner.world.scenario import Scenario

#: the report's files, in a session report's folder
PATH_FIGURE, MAPS_FIGURE = "path.png", "maps.png"


@dataclass
class LoggedSession:
    """A log read back: what was explored (``meta``, the scenario it names) and the probes of
    its last exploration (a log of a session reset mid-way holds several, each from step 0;
    ``LOG.json`` describes the last)."""

    log: Path
    meta: dict[str, Any]
    scenario: Scenario
    probes: list[Probe]
    #: the explorations in the file, the drawn one included
    explorations: int

    @property
    def task(self) -> str:
        return str(self.meta["task"])

    def flat(self) -> np.ndarray:
        """The probed cells in order, as flat indices."""
        return np.ravel_multi_index(tuple(np.array([p.cell for p in self.probes]).T),
                                    self.scenario.shape)


def load_session(log: Path) -> LoggedSession:
    """The log ``log`` and its scenario, checked against each other (every error one line
    that names the file)."""
    from runner.world.scenario import load_scenario

    log = Path(log)
    meta = read_meta(log)
    described = meta_path(log)
    scenario_path = Path(meta["scenario"])
    if not scenario_path.is_file():
        raise BayesprogError(f"{described}: the session's scenario {scenario_path} no longer "
                             "exists: restore it, or edit 'scenario' to where it is now")
    scenario = load_scenario(scenario_path)
    problems = []
    if meta["task"] not in scenario.spec.tasks:
        problems.append(f"task {meta['task']!r} is not one of the scenario's "
                        f"({', '.join(scenario.spec.tasks)})")
    if meta["dims"] != scenario.dims:
        problems.append(f"the session's grid had {meta['dims']} axes, the scenario's has "
                        f"{scenario.dims}")
    if list(meta["readings"]) != list(scenario.readings.names):
        problems.append(f"the session read {', '.join(meta['readings'])}; the scenario's "
                        f"perception reads {', '.join(scenario.readings.names)}")
    if problems:
        raise BayesprogError(f"{described}: {scenario_path.name} no longer matches the session: "
                             + "; ".join(problems))
    probes = read_probes(log, scenario.readings, scenario.shape)
    starts = [i for i, p in enumerate(probes) if p.step == 0] or [0]
    return LoggedSession(log, meta, scenario, probes[starts[-1]:], len(starts))


@dataclass
class Replay:
    """The explorer after the log's probes were fed to it, and its decision after each."""

    explorer: Explorer
    #: the replay's next cell after each probe
    next_cells: list[tuple[int, ...]]


def replay(session: LoggedSession, progress: bool | None = None) -> Replay:
    """Feed the session's probes, in order, to a fresh explorer reset as the session was."""
    from runner.experiments.executors import progress_bar

    meta = session.meta
    try:
        explorer = Explorer(session.scenario, session.task, ablate=tuple(meta["ablate"]))
    except BayesprogError as exc:
        raise BayesprogError(f"{meta_path(session.log)}: 'ablate': {exc}") from None
    seed = int(meta["seed"])
    seeds: int | list[tuple[int, ...]] = seed
    if meta.get("run") is not None:
        seeds = [decision_seed(seed, int(meta["run"]))]
    explorer.reset(start=session.probes[0].cell, seed=seeds)
    bar = progress_bar(len(session.probes), "replay", unit="probe", enabled=progress)
    next_cells = []
    try:
        for probe in session.probes:
            try:
                next_cells.append(explorer.observe(probe.cell, probe.readings))
            except BayesprogError as exc:
                raise BayesprogError(f"{probe.where}: {exc}") from None
            bar.update(1)
    finally:
        bar.close()
    return Replay(explorer, next_cells)


# the numbers -------------------------------------------------------------------------------
def confusion(laid: Sequence[str], decided: Sequence[str], materials: Sequence[str]
              ) -> tuple[list[str], list[str], np.ndarray]:
    """Per row of a log, the layout's material (``laid``) against the material decided: the
    materials laid (rows) and decided (columns), each in the scenario's order of
    ``materials`` (a name it does not know after them), and the counts [rows, columns].

    >>> rows, columns, counts = confusion(["wood", "wood", "plush"], ["wood", "brick", "plush"],
    ...                                   ("brick", "plush", "wood"))
    >>> rows, columns, counts.tolist()
    (['plush', 'wood'], ['brick', 'plush', 'wood'], [[0, 1, 0], [1, 0, 1]])
    """
    def ordered(names: set[str]) -> list[str]:
        return [m for m in materials if m in names] + sorted(names - set(materials))

    rows, columns = ordered(set(laid)), ordered(set(decided))
    counts = np.zeros((len(rows), len(columns)), dtype=int)
    for (t, d), n in Counter(zip(laid, decided, strict=True)).items():
        counts[rows.index(t), columns.index(d)] = n
    return rows, columns, counts


def _median(values: list[float]) -> float | None:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.median(finite)) if finite else None


def summary(session: LoggedSession, replayed: Replay) -> dict[str, Any]:
    """The session's numbers (what ``summary.json`` holds)."""
    scenario, probes = session.scenario, session.probes
    names = scenario.readings.names
    path = session.flat()
    n = len(probes)
    compared = [(p, r) for p, r in zip(probes, replayed.next_cells, strict=True)
                if p.next_cell is not None]
    differing = [(p, r) for p, r in compared if tuple(p.next_cell or ()) != r]
    missed = [p.step for before, p in zip(probes, probes[1:], strict=False)
              if before.next_cell is not None and p.cell != before.next_cell]
    layout = scenario.material_map.ravel()[path]
    moved = [p.step for p, m in zip(probes, layout, strict=True)
             if p.material and p.material != scenario.materials[int(m)]]
    truth, decided, counts = confusion([p.material for p in probes],
                                       [p.decided for p in probes], scenario.materials)
    border = scenario.border(session.task)
    gamma = BorderDistance(scenario.centres, border, 1)
    for cell in path:
        gamma.probe(np.array([cell]))
    final = float(gamma.gamma()[0])
    walked = behaviour(path[None], border, scenario.centres)
    first = None
    if differing:
        p, r = differing[0]
        first = {"step": p.step, "where": p.where, "log": list(p.next_cell or ()),
                 "replay": list(r)}
    correct = sum(counts[i, decided.index(m)] for i, m in enumerate(truth) if m in decided)
    return {
        "log": str(session.log), "scenario": str(scenario.path), "task": session.task,
        "task_material": scenario.materials[scenario.task_material(session.task)],
        "seed": session.meta["seed"], "run": session.meta.get("run"),
        "ablate": list(session.meta["ablate"]), "explorations": session.explorations,
        "probes": n,
        "missing": {r: sum(p.readings[r] is None for p in probes) / n for r in names},
        "probes_missing_any": sum(any(p.readings[r] is None for r in names) for p in probes),
        "warnings": sum(bool(p.warnings) for p in probes),
        "missed_targets": missed,
        "replay": {"compared": len(compared), "equal": len(compared) - len(differing),
                   "first_difference": first},
        "layout_differs": moved,
        "confusion": {"materials": truth, "decided": decided, "counts": counts.tolist()},
        "recognised": float(correct / n),
        "gamma_m": final, "border_cells": int(border.sum()),
        "gamma_per_border_cell_mm": 1000 * final / max(int(border.sum()), 1),
        "border_probed": walked["border_probed"], "path_m": float(moves(path[None],
                                                                        scenario.centres).sum()),
        "distinct_cells": int(len(np.unique(path))),
        "median_ms": {phase: _median([p.timings[phase] for p in probes])
                      for phase in (*PHASES, "total")},
    }


# the report --------------------------------------------------------------------------------
def report_folder(log: Path) -> Path:
    """Where the report of ``log`` goes: ``LOG_report/`` beside it."""
    return Path(log).with_name(f"{Path(log).stem}_report")


def build_session_report(log: Path, progress: bool | None = None) -> Path:
    """Replay the session of ``log`` and write its report (figures, report.md, report.html,
    summary.json) into :func:`report_folder`; returns the folder."""
    from bayesprog import atomic_write
    from runner.report import session_figures
    from runner.report.build import html_page

    session = load_session(log)
    replayed = replay(session, progress)
    numbers = summary(session, replayed)
    folder = report_folder(session.log)
    try:
        folder.mkdir(exist_ok=True)
    except (FileExistsError, FileNotFoundError, PermissionError) as exc:
        raise BayesprogError(f"cannot write the report of {log} into {folder}: "
                             f"{exc.strerror or exc}") from None
    title = f"{session.log.name}: task {session.task}"
    session_figures.path_figure(session, title).savefig(folder / PATH_FIGURE, dpi=110)
    session_figures.maps_figure(session, replayed, title).savefig(folder / MAPS_FIGURE, dpi=110)
    md = markdown(session, numbers)
    atomic_write(folder / "summary.json", (json.dumps(numbers, indent=1) + "\n").encode())
    atomic_write(folder / "report.md", md.encode())
    atomic_write(folder / "report.html", html_page(md, f"Session {session.log.name}").encode())
    return folder


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f}"


def replay_lines(numbers: dict[str, Any]) -> list[str]:
    """Whether the replay decided as the session did, and whether the probes were made where
    they were asked for."""
    r = numbers["replay"]
    if r["compared"] == 0:
        text = "The log gives no next cell: there is no decision to compare the replay with."
    elif r["first_difference"] is None:
        text = (f"The replay decides the log's next cell at every one of the {r['compared']} "
                "steps that give one: the maps below are the session's.")
    else:
        d = r["first_difference"]
        text = (f"**The replay differs from the session** at {r['compared'] - r['equal']} of "
                f"{r['compared']} steps, first at step {d['step']} ({d['where']}): the log says "
                f"{d['log']}, the replay {d['replay']}. The scenario, its programs or the "
                "explorer have changed since the session (or the log was written otherwise "
                "than by explore --log or robot --log); the maps below are the replay's.")
    missed = numbers["missed_targets"]
    text += (" Every probe was made at the cell asked for." if not missed else
             f" {len(missed)} probe(s) were made elsewhere than at the cell asked for (missed "
             f"targets; replayed where they were made): step(s) "
             f"{', '.join(map(str, missed[:12]))}{' ...' if len(missed) > 12 else ''}.")
    moved = numbers["layout_differs"]
    if moved:
        text += (f" At {len(moved)} probe(s) the log's material is not the layout's there now "
                 "(the scenario's objects have moved since): the figures show the layout now.")
    return [text, ""]


def markdown(session: LoggedSession, numbers: dict[str, Any]) -> str:
    """report.md of a session."""
    n = numbers["probes"]
    meta = session.meta
    stream = f"seed {meta['seed']}" + (f", the decisions of run {meta['run']}"
                                       if meta.get("run") is not None else "")
    earlier = numbers["explorations"] - 1
    lines = [f"# Session {session.log.name}", "",
             f"Scenario `{session.scenario.path}`, task {session.task} (the border of "
             f"{numbers['task_material']}), {stream}, "
             + (f"pi_tar without {', '.join(meta['ablate'])}" if meta["ablate"] else "full model")
             + f"; {n} probes."
             + (f" The log holds {earlier + 1} explorations (a reset starts another, from step "
                f"0); the last, which {meta_path(session.log).name} describes, is drawn."
                if earlier else ""), "",
             "## The path", "", f"![Path]({PATH_FIGURE})", "",
             "*The probes in order (the line; each marker a probe, coloured by its step), from "
             "the start (green triangle) to the last probe (purple square), over the materials "
             f"the layout has (legend) and the ground-truth border of {session.task} (black). "
             "An open orange circle marks a probe with a missing reading, a pink cross one with "
             "a warning (a reading out of range or far from every material, or a missed "
             "target). Axes in cm.*", "",
             "## The final maps", "", f"![Maps]({MAPS_FIGURE})", "",
             "*The session replayed. Top: the belief P(M = "
             f"{numbers['task_material']}) at every probed cell (grey: not probed), the "
             "material decided at each probed cell (its MAP; a cross where it is not the "
             "layout's) and the posterior over the next cell O after the last probe (eq. 13). "
             "Bottom: that decision's cues, inhibition I (eq. 10), saliency S (eq. 12; grey: "
             "nothing perceived to compare) and uncertainty U (eq. 11). The border in magenta "
             "(black over the materials), the last probe a purple square, the next cell a red "
             "star. Axes in cm."
             + (" In a volume the maps are the horizontal slice that holds the most probes, "
                "and the last probe and the next cell are drawn where they are seen from "
                "above; the path figure shows the volume from above."
                if session.scenario.dims == 3 else "") + "*", "",
             "## Replay", ""]
    lines += replay_lines(numbers)
    lines += ["## Numbers", "", "| | |", "|---|---|",
              f"| probes | {n} ({numbers['distinct_cells']} distinct cells) |",
              f"| Gamma at the end (eq. 16) | {numbers['gamma_m']:.4f} m over "
              f"{numbers['border_cells']} border cells, "
              f"{numbers['gamma_per_border_cell_mm']:.1f} mm per border cell |",
              f"| border cells probed | {100 * numbers['border_probed']:.0f}% |",
              f"| path length | {numbers['path_m']:.3f} m |",
              f"| probes with a warning | {numbers['warnings']} |",
              f"| probes with a missing reading | {numbers['probes_missing_any']} |",
              f"| materials recognised (decided = the layout's) | "
              f"{100 * numbers['recognised']:.1f}% |", "",
              "Missing readings, the share of the probes per reading:", "",
              "| " + " | ".join(numbers["missing"]) + " |",
              "|" + "---|" * len(numbers["missing"]),
              "| " + " | ".join(f"{100 * v:.1f}%" for v in numbers["missing"].values()) + " |",
              "", "Median time per probe (ms; a robot over ROS 2 times only the round trip):", "",
              "| " + " | ".join(numbers["median_ms"]) + " |",
              "|" + "---|" * len(numbers["median_ms"]),
              "| " + " | ".join(_ms(v) for v in numbers["median_ms"].values()) + " |", "",
              "## Recognition", "",
              "Per probe, the material the layout has at the cell (rows) against the material "
              "decided there after the probe (columns), counts:", ""]
    c = numbers["confusion"]
    lines += ["| layout \\ decided | " + " | ".join(c["decided"]) + " | recognised |",
              "|---|" + "---|" * (len(c["decided"]) + 1)]
    for name, row in zip(c["materials"], c["counts"], strict=True):
        right = row[c["decided"].index(name)] if name in c["decided"] else 0
        lines.append(f"| {name} | " + " | ".join(str(v) for v in row)
                     + f" | {100 * right / max(sum(row), 1):.0f}% |")
    return "\n".join(lines) + "\n"
