"""The paper experiment's wall time, its split, and a naive reference (not a test).

Measured in one run on this machine:

* the whole experiment (``models/experiments/paper.yaml``: 3 tasks x 5 configurations x 100 runs
  x 100 iterations) through ``run_experiment``, in one process and with ``--workers 2``, each
  into a fresh folder (median of ``--repeats``);
* the split of one process's time into perception, cue fields, shape matching, decision and
  storage (from the explorer's own timers);
* the decision step beside a direct numpy implementation of the same decision (eq. 13 with the
  shape cue), written only for this benchmark: the same runs decided both ways, the seconds
  spent deciding, and the share of decisions that agree;
* scaling: one (task, configuration) of the paper (T1, the full model, 100 iterations), each
  point in a fresh process, for 25, 100 and 400 runs on the paper's 30 x 60 grid and for 100
  runs on the same workspace cut into 30 x 60, 60 x 120 and 120 x 240 cells: wall seconds,
  peak resident memory, and the cost per run x cell relative to the smallest point (``--plot``
  draws them);
* a robot session over standard input and output: ``bayesprog explore --stdio`` fed 4,000
  probes of the paper's workspace, each at the cell the last reply asked for (``--session-cells
  random``: at random cells) with readings from the scenario's simulated sensor, one line in
  and its reply read before the next (as a robot would), and the same lines answered by
  ``Session.answer`` in this process: the probes answered per second in each block of 1,000,
  the medians of ``--session-repeats`` sessions each way and the last block's rate over the
  second's, so that a cost per step that grows with the session's length shows
  (``--only-session``: this alone; ``--session-scenario``: on another scenario, its readings
  sent by name);
* a naive reference: one run at a time (one decision per engine call), no incremental updates
  (uncertainty of every cell and inhibition recomputed each step, a cold multi-start ICP at every
  step). It is measured on a sample of runs of one task and configuration and extrapolated to
  the 15,000 runs x iterations of the experiment; the output says so.

* whole commands, as a user runs them (fresh processes: worker start-up, imports and kernel
  loading included): ``bayesprog run`` on the paper's experiment with two workers and no
  report, ``bayesprog report`` on its results, and the volume experiment's run; each beside
  the bound it is held to (10 s, 4 s, 60 s), the ratio in the JSON; and a small search of
  ``bayesprog tune`` on two local processes beside a Dask LocalCluster of two workers.

* with ``--against DIR`` (a checkout of another version, e.g. ``git worktree add DIR HEAD~1``),
  only a paired comparison: ``bayesprog run`` on the paper's experiment (two workers, no
  report) by this checkout and by that one in turn, ``--pairs`` times, each a fresh process
  into a fresh folder; every pair's seconds, the medians, their ratio (this checkout's over
  the other's), and whether the two wrote the same results (every array of every chunk).

    python benchmarks/experiment.py [--repeats 3] [--naive-runs 2] [--out results/...json]
        [--plot docs/performance.png] [--volume-repeats 1] [--only-commands]
        [--against DIR [--pairs 5]] [--only-session] [--session-repeats 3]
        [--session-cells next] [--session-scenario SCENARIO]
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.special import betaln, logsumexp

from runner.attention.cues import inhibition, uncertainty
from runner.attention.explorer import CONFIGURATIONS, Explorer
from runner.attention.shape import MIN_POINTS, match
from runner.experiments.experiment import load_experiment, make_sensor, run_experiment, simulate
from runner.robot.session import Session, probe_line
from runner.world.scenario import load_scenario

ROOT = Path(__file__).parents[1]
PAPER = ROOT / "models" / "experiments" / "paper.yaml"


class NaiveExplorer(Explorer):
    """The same decisions, computed without any incremental update or warm start."""

    def cue_fields(self):
        i, s, _ = super().cue_fields()
        last = self.centres[self.path[-1]]
        return inhibition(self.centres, last, self.diagonal), s, uncertainty(self.posterior)

    def shape_cue(self):
        points, counts = self.border_points(self.border_cells())
        registration = match(points, self.outlines, self.template_points,
                             counts=np.maximum(counts, 1))
        return registration, counts >= MIN_POINTS


class DirectExplorer(Explorer):
    """The same decisions without the engine: pi_tar's terms evaluated by hand in numpy (their
    parameters read from the program), summed in log space, the MAP taken with the same tie
    rule and the same generators."""

    def decide(self):
        start = time.perf_counter()
        i, s, u = self.cue_fields()
        shape_start = time.perf_counter()
        self.timings["cues"] += shape_start - start
        shape = "P(R | O)" not in self.target.ablated
        reg, ready = (self.shape_cue() if shape else (None, np.zeros(self.runs, bool)))
        self.registration = reg
        ask_start = time.perf_counter()
        self.timings["shape"] += ask_start - shape_start
        terms = {t.label: t for t in self.target.active_terms}
        log = np.zeros((self.runs, len(self.centres)))
        for label, x in (("P(I | O)", i), ("P(S | O, T)", s), ("P(U | O)", u)):
            term = terms[label]
            if term.form.name != "beta":
                continue  # ablated: uniform
            a, b = float(term.params["a"].array), float(term.params["b"].array)
            with np.errstate(divide="ignore", invalid="ignore"):
                # the log density, its terms with an exponent of 0 left out
                part = np.full(x.shape, -betaln(a, b))
                if a != 1:
                    part += (a - 1) * np.log(x)
                if b != 1:
                    part += (b - 1) * np.log1p(-x)
            log += np.where(np.isnan(x), 0.0, part)  # a NaN field value is not observed
        if shape and ready.any():
            log[ready] += self._shape_log(terms["P(R | O)"], reg, ready)
        nxt = np.empty(self.runs, dtype=np.int64)
        p = np.exp(log - log.max(axis=1, keepdims=True))
        p /= p.sum(axis=1, keepdims=True)
        best = p.max(axis=1)
        for r in range(self.runs):
            tied = np.flatnonzero(p[r] >= best[r] * (1 - 1e-12))
            nxt[r] = tied[self.rngs[r].integers(tied.size)] if tied.size > 1 else tied[0]
        self.target_probabilities = p
        self.timings["decision"] += time.perf_counter() - ask_start
        from runner.attention.explorer import Decision

        self.last = Decision(len(self.path), i, s, u, None if reg is None else reg.error,
                             None if reg is None else reg.points, nxt, ready)
        return nxt

    def _shape_log(self, term, reg, ready):
        """log sum_R P(R | L1, L2) gmm_R(cell): the isotropic mixtures factor along the grid's
        two axes, so each is a product of per-axis Gaussians (one matrix product)."""
        sigma, floor = float(term.params["sigma"].array), float(term.params["floor"].array)
        nx, ny = self.scenario.shape
        centre = self.centres.mean(axis=0)
        xs = self.centres.reshape(nx, ny, 2)[:, 0, 0] - centre[0]
        ys = self.centres.reshape(nx, ny, 2)[0, :, 1] - centre[1]
        m = reg.points[ready] - centre  # [runs, R, K, 2]
        gx = np.exp(-0.5 * ((xs - m[..., 0:1]) / sigma) ** 2)  # [runs, R, K, nx]
        gy = np.exp(-0.5 * ((ys - m[..., 1:2]) / sigma) ** 2)  # [runs, R, K, ny]
        mix = (np.swapaxes(gx, -1, -2) @ gy).reshape(m.shape[:2] + (nx * ny,))
        mix /= m.shape[2] * 2 * np.pi * sigma**2
        gmm = np.log((1 - floor) * mix + floor / (nx * ny * self.scenario.cell**2))
        # pi_obj (models/pi_obj.yaml): P(L1 | R) is Beta(1, 4.5) for the rectangle, uniform
        # for the triangle, and the reverse for L2; the share of agreeing decisions checks it
        error = reg.error[ready]
        log_r = np.stack([np.log(4.5) + 3.5 * np.log1p(-error[:, 0]),
                          np.log(4.5) + 3.5 * np.log1p(-error[:, 1])], axis=1)
        log_r -= logsumexp(log_r, axis=1, keepdims=True)
        return logsumexp(gmm + log_r[..., None], axis=1)


def decision_ratio(runs: int = 100) -> dict:
    """The seconds spent deciding, through the engine and directly, on the same runs of the
    paper scenario (every task, the full model and the model without the shape cue)."""
    experiment = load_experiment(PAPER)
    spec = experiment.spec
    starts = experiment.start_cells()[:runs]
    ids = np.arange(runs)
    out: dict = {"engine_s": 0.0, "direct_s": 0.0, "decisions": 0, "agree": 0}
    for task in spec.tasks:
        for conf in ("full", "without_R"):
            paths = []
            for kind, cls in (("engine_s", Explorer), ("direct_s", DirectExplorer)):
                explorer = cls(experiment.scenario, task, ablate=CONFIGURATIONS[conf], runs=runs)
                result = simulate(experiment.scenario, task, conf, starts, ids, spec.seed,
                                  spec.iterations, explorer=explorer)
                out[kind] += explorer.timings["decision"]
                paths.append(result["paths"])
            out["decisions"] += paths[0].size
            out["agree"] += int((paths[0] == paths[1]).all(axis=1).sum() * paths[0].shape[1])
    out["ratio"] = out["engine_s"] / out["direct_s"]
    out["agreeing_runs_share"] = out["agree"] / out["decisions"]
    return out


SCALING_RUNS = [25, 100, 400]
SCALING_GRIDS = [(30, 60), (60, 120), (120, 240)]


def _memory_mib(field: str) -> float:
    """This process's resident memory (VmRSS) or its peak (VmHWM), from /proc (Linux; the peak
    of ``getrusage`` elsewhere, which a spawned process may inherit from its parent)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _scaling_point(runs: int, shape: tuple[int, int]) -> dict:
    """One point, in its own process: T1 with the full model on the paper's workspace cut into
    ``shape`` cells (the same 30 x 60 cm), ``runs`` runs in lockstep."""
    import yaml

    from runner.world.scenario import load_scenario

    text = yaml.safe_load((ROOT / "models" / "scenarios" / "paper.yaml").read_text())
    cell = 0.30 / shape[0]
    text["grid"] = {"shape": list(shape), "cell": cell}
    text["programs"] = {k: str((ROOT / "models" / "scenarios" / v).resolve())
                        for k, v in text["programs"].items()}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scaled.yaml"
        path.write_text(yaml.safe_dump(text))
        scenario = load_scenario(path)
    rng = np.random.default_rng(7)
    starts = np.stack([rng.integers(0, shape[0], runs), rng.integers(0, shape[1], runs)], 1)
    simulate(scenario, "T1", "full", starts[:2], np.arange(2), 1, 3)  # kernels loaded
    before = _memory_mib("VmRSS")
    start = time.perf_counter()
    simulate(scenario, "T1", "full", starts, np.arange(runs), 1, 100)
    seconds = time.perf_counter() - start
    peak = _memory_mib("VmHWM")
    return {"runs": runs, "grid": list(shape), "cells": shape[0] * shape[1],
            "seconds": seconds, "peak_mib": peak, "before_mib": before}


def scaling() -> list[dict]:
    """Every scaling point, each in a fresh process (its own peak memory)."""
    import concurrent.futures
    import multiprocessing

    points = [(r, SCALING_GRIDS[0]) for r in SCALING_RUNS]
    points += [(100, g) for g in SCALING_GRIDS[1:]]
    out = []
    context = multiprocessing.get_context("spawn")
    for runs, shape in points:
        with concurrent.futures.ProcessPoolExecutor(1, mp_context=context) as pool:
            out.append(pool.submit(_scaling_point, runs, shape).result())
    base = out[0]["seconds"] / (out[0]["runs"] * out[0]["cells"])
    for point in out:
        point["cost_per_run_cell_relative"] = (point["seconds"] / (point["runs"] * point["cells"])
                                               / base)
    return out


def plot_scaling(points: list[dict], path: Path) -> None:
    from runner.report import figures

    fig = figures.figure(figsize=(9, 3.4))
    axes = fig.subplots(1, 2)
    by_runs = [p for p in points if p["cells"] == points[0]["cells"]]
    by_grid = [p for p in points if p["runs"] == 100]
    def added(p):  # the memory the simulation adds to the process
        return p["peak_mib"] - p["before_mib"]

    for ax, value, label in ((axes[0], lambda p: p["seconds"],
                              "wall seconds (T1, full model, 100 steps)"),
                             (axes[1], added, "peak memory added (MiB)")):
        for group, name, marker in ((by_runs, "runs 25 / 100 / 400 on 30 x 60", "o"),
                                    (by_grid, "100 runs on 30 x 60 / 60 x 120 / 120 x 240",
                                     "s")):
            x = [p["runs"] * p["cells"] for p in group]
            ax.plot(x, [value(p) for p in group], marker=marker, label=name)
        # linear growth from the smallest point: the measured points stay at or below it
        low = min(points, key=lambda p: p["runs"] * p["cells"])
        x = np.array([low["runs"] * low["cells"], max(p["runs"] * p["cells"] for p in points)])
        ax.plot(x, value(low) * x / x[0], ":", color="0.5", label="linear from the smallest")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("runs x cells")
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def whole(workers: int, repeats: int, report: bool = False) -> tuple[float, float | None]:
    """Median wall seconds of the experiment, and of its report (with the animation) when
    ``report``, each into a fresh folder."""
    from runner.report.build import build_report

    experiment = load_experiment(PAPER)
    times, reports = [], []
    for _ in range(repeats):
        out = Path(tempfile.mkdtemp())
        try:
            start = time.perf_counter()
            run_experiment(experiment, out, workers=workers, progress=False)
            times.append(time.perf_counter() - start)
            if report:
                start = time.perf_counter()
                build_report(out)
                reports.append(time.perf_counter() - start)
        finally:
            shutil.rmtree(out)
    return statistics.median(times), statistics.median(reports) if reports else None


#: What a user waits for, as whole commands (worker start-up, imports and kernel loading
#: included), and the bound each is held to.
COMMANDS = {
    "run paper --workers 2 --no-report": 10.0,
    "report paper": 4.0,
    "run volume --workers 2 --no-report": 60.0,
}


def commands(repeats: int, volume_repeats: int = 1) -> dict[str, dict[str, float]]:
    """Median wall seconds of ``bayesprog run`` on the paper's experiment (two workers, no
    report) and of ``bayesprog report`` on its results, each a fresh process into a fresh
    folder, and of the volume experiment's run (``volume_repeats`` times: a minute each);
    with each one's bound and its ratio to it."""
    volume = ROOT / "models" / "experiments" / "volume.yaml"
    times: dict[str, list[float]] = defaultdict(list)

    def timed(*arguments: str) -> float:
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "bayesprog", *arguments], check=True,
                       capture_output=True)
        return time.perf_counter() - start

    for experiment, count in ((PAPER, repeats), (volume, volume_repeats)):
        for _ in range(count):
            out = Path(tempfile.mkdtemp())
            try:
                times[f"run {experiment.stem} --workers 2 --no-report"].append(timed(
                    "run", str(experiment), "--workers", "2", "--no-report", "--out", str(out),
                    "-q"))
                if experiment == PAPER:
                    times["report paper"].append(timed("report", str(out)))
            finally:
                shutil.rmtree(out)
    return {name: {"seconds": statistics.median(found), "bound_s": COMMANDS[name],
                   "ratio_to_bound": statistics.median(found) / COMMANDS[name],
                   "repeats": len(found)}
            for name, found in times.items()}


def _run_paper(root: Path, out: Path) -> float:
    """Wall seconds of ``bayesprog run`` on the paper's experiment by the code of the checkout
    ``root`` (first on the module path, from a folder outside it), two workers, no report."""
    import os

    env = dict(os.environ, PYTHONPATH=str(root))
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "bayesprog", "run",
                    str(root / "models" / "experiments" / "paper.yaml"), "--workers", "2",
                    "--no-report", "--out", str(out), "-q"],
                   check=True, capture_output=True, env=env, cwd=out.parent)
    return time.perf_counter() - start


def _same_chunks(a: Path, b: Path) -> bool:
    """Whether two experiments' folders hold the same chunks with the same arrays (their
    configuration hashes aside): every array both store equal (a checkout may store more per
    probe than another, as the readings are since they are stored), the paths and Gamma
    among them."""
    files = sorted(p.relative_to(a) for p in (a / "chunks").rglob("*.npz"))
    if files != sorted(p.relative_to(b) for p in (b / "chunks").rglob("*.npz")):
        return False
    for name in files:
        with np.load(a / name) as x, np.load(b / name) as y:
            keys = sorted(set(x.files) & set(y.files) - {"config"})
            if not {"gamma", "paths"} <= set(keys) or not all(
                    np.array_equal(x[k], y[k], equal_nan=x[k].dtype.kind == "f") for k in keys):
                return False
    return True


def paired(reference: Path, pairs: int) -> dict:
    """``bayesprog run`` on the paper's experiment by this checkout and by ``reference`` in
    turn (the order alternating from pair to pair, so that a drift of the machine's load
    weighs on both), ``pairs`` times: the seconds of each, their medians and ratio, and
    whether every pair wrote the same results."""
    reference = reference.resolve()
    this, other, same = [], [], True
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(pairs):
            order = [(ROOT, this), (reference, other)]
            folders = {}
            for root, times in order if k % 2 == 0 else order[::-1]:
                folders[root] = Path(tmp) / f"{k}-{'this' if root == ROOT else 'other'}"
                times.append(_run_paper(root, folders[root]))
            same &= _same_chunks(folders[ROOT], folders[reference])
            for folder in folders.values():
                shutil.rmtree(folder)
    return {"reference": str(reference), "this_s": this, "reference_s": other,
            "this_median_s": statistics.median(this),
            "reference_median_s": statistics.median(other),
            "ratio": statistics.median(this) / statistics.median(other), "same_results": same}


def sweeps(trials: int = 4) -> dict[str, float | bool]:
    """A small search of ``bayesprog tune`` (``trials`` candidates on the small grid, three
    runs each) on two local processes and on a Dask LocalCluster of two worker processes,
    each into a fresh folder: their wall seconds, the ratio, and whether their trials agree."""
    import yaml
    from dask.distributed import LocalCluster

    from runner.experiments.tune import load_search, run_search

    scenarios = ROOT / "models" / "scenarios"
    spec = {"experiment": 1, "name": "sweep", "runner": "haptic",
            "scenario": str(scenarios / "small_grid.yaml"), "tasks": ["T1"],
            "configurations": ["full"], "runs": 4, "iterations": 25, "seed": 3,
            "tune": {"training": [str(scenarios / "small_grid.yaml")],
                     "validation": [str(scenarios / "corners.yaml")],
                     "trials": trials, "runs": 3, "validation_runs": 5}}
    folder = Path(tempfile.mkdtemp())
    try:
        path = folder / "sweep.yaml"
        path.write_text(yaml.safe_dump(spec, sort_keys=False))
        start = time.perf_counter()
        local = run_search(load_search(path), folder / "local", workers=2, progress=False)
        local_s = time.perf_counter() - start
        with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster:
            start = time.perf_counter()
            dask = run_search(load_search(path), folder / "dask", progress=False,
                              scheduler=cluster.scheduler_address)
            dask_s = time.perf_counter() - start
    finally:
        shutil.rmtree(folder)
    return {"trials": trials, "local_workers_2_s": local_s, "dask_local_cluster_2_s": dask_s,
            "dask_over_local": dask_s / local_s,
            "same_trials": local["trials"] == dask["trials"]}


def split() -> dict[str, float]:
    """One process, every (task, configuration): where the time goes."""
    experiment = load_experiment(PAPER)
    spec = experiment.spec
    totals: dict[str, float] = defaultdict(float)
    starts = experiment.start_cells()
    runs = np.arange(spec.runs)
    out = Path(tempfile.mkdtemp())
    try:
        from runner.experiments.store import ResultStore, Unit

        store = ResultStore(out)
        for task in spec.tasks:
            for conf in spec.configurations:
                explorer = Explorer(experiment.scenario, task, ablate=CONFIGURATIONS[conf],
                                    runs=spec.runs)
                start = time.perf_counter()
                result = simulate(experiment.scenario, task, conf, starts, runs, spec.seed,
                                  spec.iterations, explorer=explorer)
                totals["total"] += time.perf_counter() - start
                for phase, seconds in explorer.timings.items():
                    totals[phase] += seconds
                t = time.perf_counter()
                store.save(Unit(task, conf, 0, tuple(int(r) for r in runs)), result)
                totals["storage"] += time.perf_counter() - t
    finally:
        shutil.rmtree(out)
    accounted = sum(v for k, v in totals.items() if k not in ("total", "storage"))
    totals["other (sensor, Gamma, loop)"] = totals["total"] - accounted
    return dict(totals)


def naive(sample_runs: int) -> dict[str, float]:
    experiment = load_experiment(PAPER)
    spec = experiment.spec
    starts = experiment.start_cells()
    seconds = 0.0
    for r in range(sample_runs):
        explorer = NaiveExplorer(experiment.scenario, "T1", runs=1)
        start = time.perf_counter()
        simulate(experiment.scenario, "T1", "full", starts[r : r + 1], np.array([r]), spec.seed,
                 spec.iterations, explorer=explorer)
        seconds += time.perf_counter() - start
    per_run = seconds / sample_runs
    total_runs = len(spec.tasks) * len(spec.configurations) * spec.runs
    return {"sample_runs": sample_runs, "seconds_per_run": per_run,
            "extrapolated_seconds": per_run * total_runs}


def _session_blocks(probe: Callable[[int, dict | None], str], probes: int, block: int,
                    answer: Callable[[str], dict | None]) -> list[float]:
    """Seconds per block of ``probes`` lines, each made by ``probe`` from its step and the last
    reply and handed to ``answer``, whose reply comes before the next line is made."""
    seconds, reply = [], None
    for start in range(0, probes, block):
        began = time.perf_counter()
        for k in range(start, min(start + block, probes)):
            reply = answer(probe(k, reply)) or {}
            if "error" in reply:
                raise RuntimeError(f"explore --stdio: {reply['error']}")
        seconds.append(time.perf_counter() - began)
    return seconds


def _piped_session(command: list[str], probe: Callable[[int, dict | None], str], probes: int,
                   block: int) -> list[float]:
    """Seconds per block of lines written to a fresh ``command``'s standard input, each
    reply read from its output before the next line is written."""
    with subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                          bufsize=1) as process:
        stdin, stdout = process.stdin, process.stdout
        assert stdin is not None and stdout is not None

        def through_pipe(line: str) -> dict:
            stdin.write(line)
            stdin.flush()
            return json.loads(stdout.readline())

        seconds = _session_blocks(probe, probes, block, through_pipe)
        stdin.close()
    return seconds


def _session_rates(runs: list[list[float]], block: int) -> dict:
    """Probes per second by block for every repeat, their median by block, and the last
    block's median over the second's and the first's (the first block pays the compilation of
    the questions and kernels; a cost per step that grows with the session's length shows as
    a ratio below 1 against the second)."""
    rates = [[block / s for s in seconds] for seconds in runs]
    medians = [statistics.median(column) for column in zip(*rates, strict=True)]
    return {"probes_per_second": rates, "median_per_block": medians,
            "last_over_first": medians[-1] / medians[0],
            "last_over_second": medians[-1] / medians[min(1, len(medians) - 1)]}


def session(probes: int = 4000, block: int = 1000, task: str = "T2", repeats: int = 1,
            cells: str = "next", scenario_path: Path | None = None) -> dict:
    """Probes per second by block of ``block`` in a session of ``probes`` probes, ``repeats``
    times each way: fed one line at a time to ``bayesprog explore --stdio`` in a fresh process,
    and to :meth:`Session.answer` in this process (the same lines and replies without the pipe,
    the replies' JSON text or the process's start), each with a fresh explorer and sensor.

    With ``cells="next"`` each probe is made at the cell the last reply asked for, as a robot
    does (the first at a random cell); with ``"random"``, at random cells. The readings come
    from the scenario's simulated sensor (``scenario_path``, by default the paper's; its
    first task when it has no task ``task``), sent by name. Following the explorer, the shape cue is in force
    from the first block on, and every block does the same work; at random cells it comes
    into force only in the second or third block, whose rate drops for that reason alone."""
    scenario = load_scenario(scenario_path) if scenario_path else load_experiment(PAPER).scenario
    task = task if task in scenario.spec.tasks else next(iter(scenario.spec.tasks))
    at_random = np.random.default_rng(0).integers(scenario.centres.shape[0], size=probes)
    ny = scenario.shape[1]

    def prober() -> Callable[[int, dict | None], str]:
        sensor = make_sensor(scenario, [(0, 0, 1)])

        def probe(k: int, reply: dict | None) -> str:
            if cells == "next" and reply is not None:
                cell = reply["next"][0] * ny + reply["next"][1]
            else:
                cell = int(at_random[k])
            line = probe_line([cell // ny, cell % ny], sensor.probe(np.array([cell])),
                              perception=scenario.readings)
            return json.dumps(line) + "\n"

        return probe

    command = [sys.executable, "-m", "bayesprog.cli", "explore", str(scenario.path),
               "--stdio", "--task", task]
    piped, in_process = [], []
    for _ in range(repeats):
        piped.append(_piped_session(command, prober(), probes, block))
        in_process.append(_session_blocks(prober(), probes, block,
                                          Session(Explorer(scenario, task, runs=1)).answer))
    found = {"probes": probes, "block": block, "task": task, "cells": cells,
             "repeats": repeats, "stdio": _session_rates(piped, block),
             "in_process": _session_rates(in_process, block)}
    # the keys of earlier results (one session over the pipe): the median by block
    found["probes_per_second"] = found["stdio"]["median_per_block"]
    found["last_over_first_time"] = 1 / found["stdio"]["last_over_first"]
    return found


def _session_lines(robot: dict) -> list[str]:
    where = "the cells asked for" if robot["cells"] == "next" else "random cells"
    return [f"{name}, {robot['probes']:,} probes at {where}, median of {robot['repeats']}: "
            + ", ".join(f"{r:.0f}" for r in robot[key]["median_per_block"])
            + f" probes per second by block of {robot['block']:,}; the last block's rate "
            f"{robot[key]['last_over_second']:.2f}x the second's"
            for name, key in (("explore --stdio", "stdio"), ("Session.answer in process",
                                                             "in_process"))]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--naive-runs", type=int, default=2)
    parser.add_argument("--out", default="results/benchmarks/experiment.json")
    parser.add_argument("--plot", default=None, help="a PNG of the scaling points")
    parser.add_argument("--volume-repeats", type=int, default=1,
                        help="runs of the volume experiment as a command (a minute each)")
    parser.add_argument("--only-commands", action="store_true",
                        help="time the whole commands only")
    parser.add_argument("--only-scaling", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--only-session", action="store_true",
                        help="a robot session of 4,000 probes only: probes per second "
                             "by block of 1,000, through explore --stdio and in process")
    parser.add_argument("--session-repeats", type=int, default=3,
                        help="sessions each way (the medians by block)")
    parser.add_argument("--session-cells", choices=("next", "random"), default="next",
                        help="probe the cells the replies ask for, or random cells")
    parser.add_argument("--session-scenario", type=Path, default=None, metavar="SCENARIO",
                        help="the session on another scenario (its readings by name, e.g. "
                             "models/scenarios/fingertip.yaml: five readings, one discrete)")
    parser.add_argument("--against", type=Path, default=None,
                        help="another checkout: only the paired comparison of the commands")
    parser.add_argument("--pairs", type=int, default=5)
    args = parser.parse_args(argv)
    if args.against is not None:
        found = paired(args.against, args.pairs)
        print(f"bayesprog run paper --workers 2 --no-report, {args.pairs} pairs, this checkout "
              f"against {found['reference']}:")
        for k, (a, b) in enumerate(zip(found["this_s"], found["reference_s"], strict=True)):
            print(f"  pair {k + 1}: {a:6.1f} s against {b:6.1f} s")
        print(f"  medians {found['this_median_s']:.1f} s against "
              f"{found['reference_median_s']:.1f} s: ratio {found['ratio']:.2f}; the same "
              f"results: {found['same_results']}")
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps({"paired": found}, indent=2))
        print(f"written to {out}")
        return 0
    if args.only_session:
        robot = session(repeats=args.session_repeats, cells=args.session_cells,
                        scenario_path=args.session_scenario)
        print("\n".join(_session_lines(robot)))
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps({"session": robot}, indent=2))
        print(f"written to {out}")
        return 0
    if args.only_scaling:
        points = scaling()
        print(json.dumps(points, indent=1))
        if args.plot:
            plot_scaling(points, Path(args.plot))
        return 0
    if args.only_commands:
        found = commands(args.repeats, args.volume_repeats)
        sweep = sweeps()
        print("\n".join(_command_lines(found, sweep)))
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps({"commands": found, "sweep": sweep}, indent=2))
        print(f"written to {out}")
        return 0
    load_experiment(PAPER)  # compile the kernels before timing
    simulate(load_experiment(PAPER).scenario, "T1", "full", np.array([[3, 3]]), np.array([0]),
             0, 15)
    one, _ = whole(1, args.repeats)
    two, report = whole(2, args.repeats, report=True)
    parts = split()
    decision = decision_ratio()
    points = scaling()
    if args.plot:
        plot_scaling(points, Path(args.plot))
    robot = session(repeats=args.session_repeats, cells=args.session_cells)
    ref = naive(args.naive_runs)
    found = commands(args.repeats, args.volume_repeats)
    sweep = sweeps()
    lines = [
        f"paper experiment (150,000 decisions), median of {args.repeats}:",
        f"  one process      {one:8.1f} s",
        f"  --workers 2      {two:8.1f} s",
        f"  its report       {report:8.1f} s (figures, tables and the animation of Fig. 11)",
        "split of one process (seconds):",
        *(f"  {k:<28}{v:8.1f}" for k, v in parts.items()),
        f"decision step through the engine: {decision['engine_s']:.2f} s; the direct numpy "
        f"implementation of the same decisions: {decision['direct_s']:.2f} s; ratio "
        f"{decision['ratio']:.2f} ({decision['decisions']:,} decisions, every task, full and "
        f"without_R; {100 * decision['agreeing_runs_share']:.0f}% in runs whose paths agree "
        "step for step)",
        "scaling (T1, full model, 100 steps, one process):",
        *(f"  {p['runs']:>4} runs on {p['grid'][0]:>3} x {p['grid'][1]:<3} {p['seconds']:7.2f} s"
          f"  peak {p['peak_mib']:6.0f} MiB ({p['peak_mib'] - p['before_mib']:5.0f} MiB added)"
          f"  cost per run x cell "
          f"{p['cost_per_run_cell_relative']:.2f}x the smallest" for p in points),
        *_session_lines(robot),
        f"naive reference: {ref['seconds_per_run']:.2f} s per run of 100 iterations, measured on "
        f"{ref['sample_runs']} run(s) and extrapolated to 1,500 runs: "
        f"{ref['extrapolated_seconds']:.0f} s",
        f"speed-up over the naive reference: {ref['extrapolated_seconds'] / one:.0f}x (one "
        f"process), {ref['extrapolated_seconds'] / two:.0f}x (--workers 2)",
        *_command_lines(found, sweep),
    ]
    print("\n".join(lines))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"one_process_s": one, "two_workers_s": two, "report_s": report,
                               "split_s": parts, "decision": decision, "scaling": points,
                               "session": robot, "naive": ref, "commands": found,
                               "sweep": sweep},
                              indent=2))
    print(f"written to {out}")
    return 0


def _command_lines(found: dict[str, dict[str, float]], sweep: dict) -> list[str]:
    return ["whole commands, as a user runs them (fresh processes), median seconds:",
            *(f"  bayesprog {name:<36}{row['seconds']:7.1f} s  (bound {row['bound_s']:.0f} s: "
              f"{row['ratio_to_bound']:.2f}x; {row['repeats']} run(s))"
              for name, row in found.items()),
            f"a search of {sweep['trials']} candidates: two local processes "
            f"{sweep['local_workers_2_s']:.1f} s, a Dask LocalCluster of two worker processes "
            f"{sweep['dask_local_cluster_2_s']:.1f} s ({sweep['dask_over_local']:.2f}x); the "
            f"same trials: {sweep['same_trials']}"]


if __name__ == "__main__":
    sys.exit(main())
