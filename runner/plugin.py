"""The haptic runner as a plugin of the ``bayesprog`` command line (entry point ``haptic`` of
the group ``bayesprog.runners``): ``bayesprog run EXPERIMENT --out DIR`` and
``bayesprog explore SCENARIO --stdio``."""

from __future__ import annotations

import sys
from pathlib import Path

from bayesprog.errors import BayesprogError


def run(experiment: Path, out: Path, options: dict) -> int:
    """Run an experiment file and write its results and figures into ``out``."""
    from runner.experiment import load_experiment, run_quick

    exp = load_experiment(experiment)
    run_quick(exp, out, progress=not options.get("quiet", False))
    print(f"results and figures written to {out}")
    return 0


def _scenario_path(target: Path) -> Path:
    if target.is_dir():
        candidate = target / "scenarios" / "paper.yaml"
        if candidate.is_file():
            return candidate
        raise BayesprogError(f"{target} is a folder without scenarios/paper.yaml: expected a "
                             "scenario file or a models folder")
    return target


def explore(target: Path, options: dict) -> int:
    """Serve the step interface on standard input/output."""
    from runner.explorer import Explorer
    from runner.scenario import load_scenario
    from runner.stdio import serve

    scenario = load_scenario(_scenario_path(target))
    task = options.get("task") or next(iter(scenario.spec.tasks))
    explorer = Explorer(scenario, task, ablate=options.get("ablate") or ())
    serve(explorer, sys.stdin, sys.stdout, seed=options.get("seed", 0))
    return 0
