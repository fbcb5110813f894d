"""The paper experiment's wall time, its split, and a naive reference (not a test).

Measured in one run on this machine:

* the whole experiment (``models/experiments/paper.yaml``: 3 tasks x 5 configurations x 100 runs
  x 100 iterations) through ``run_experiment``, in one process and with ``--workers 2``, each
  into a fresh folder (median of ``--repeats``);
* the split of one process's time into perception, cue fields, shape matching, decision and
  storage (from the explorer's own timers);
* a naive reference: one run at a time (one decision per engine call), no incremental updates
  (uncertainty of every cell and inhibition recomputed each step, a cold multi-start ICP at every
  step). It is measured on a sample of runs of one task and configuration and extrapolated to
  the 15,000 runs x iterations of the experiment; the output says so.

    python benchmarks/experiment.py [--repeats 3] [--naive-runs 2] [--out results/...json]
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from runner.cues import inhibition, uncertainty
from runner.experiment import load_experiment, run_experiment, simulate
from runner.explorer import CONFIGURATIONS, Explorer
from runner.shape import MIN_POINTS, match

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


def whole(workers: int, repeats: int) -> tuple[float, dict]:
    experiment = load_experiment(PAPER)
    times = []
    for _ in range(repeats):
        out = Path(tempfile.mkdtemp())
        try:
            start = time.perf_counter()
            run_experiment(experiment, out, workers=workers, progress=False)
            times.append(time.perf_counter() - start)
        finally:
            shutil.rmtree(out)
    return statistics.median(times), {}


def split() -> dict[str, float]:
    """One process, every (task, configuration): where the time goes."""
    experiment = load_experiment(PAPER)
    spec = experiment.spec
    totals: dict[str, float] = defaultdict(float)
    starts = experiment.start_cells()
    runs = np.arange(spec.runs)
    out = Path(tempfile.mkdtemp())
    try:
        from runner.store import ResultStore, Unit

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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--naive-runs", type=int, default=2)
    parser.add_argument("--out", default="results/benchmarks/experiment.json")
    args = parser.parse_args(argv)
    load_experiment(PAPER)  # compile the kernels before timing
    simulate(load_experiment(PAPER).scenario, "T1", "full", np.array([[3, 3]]), np.array([0]),
             0, 15)
    one, _ = whole(1, args.repeats)
    two, _ = whole(2, args.repeats)
    parts = split()
    ref = naive(args.naive_runs)
    lines = [
        f"paper experiment (150,000 decisions), median of {args.repeats}:",
        f"  one process      {one:8.1f} s",
        f"  --workers 2      {two:8.1f} s",
        "split of one process (seconds):",
        *(f"  {k:<28}{v:8.1f}" for k, v in parts.items()),
        f"naive reference: {ref['seconds_per_run']:.2f} s per run of 100 iterations, measured on "
        f"{ref['sample_runs']} run(s) and extrapolated to 1,500 runs: "
        f"{ref['extrapolated_seconds']:.0f} s",
        f"speed-up over the naive reference: {ref['extrapolated_seconds'] / one:.0f}x (one "
        f"process), {ref['extrapolated_seconds'] / two:.0f}x (--workers 2)",
    ]
    print("\n".join(lines))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"one_process_s": one, "two_workers_s": two, "split_s": parts,
                               "naive": ref}, indent=2))
    print(f"written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
