"""The haptic runner as a plugin of the ``bayesprog`` command line (entry point ``haptic`` of
the group ``bayesprog.runners``): ``bayesprog run EXPERIMENT --out DIR``, ``bayesprog report
DIR``, ``bayesprog tune EXPERIMENT --out DIR`` and ``bayesprog explore SCENARIO --stdio``."""

from __future__ import annotations

import sys
from pathlib import Path

from bayesprog.errors import BayesprogError


def run(experiment: Path, out: Path, options: dict) -> int:
    """Run an experiment file (resuming what ``out`` already holds), then write its report."""
    from runner.experiment import load_experiment, run_experiment

    exp = load_experiment(experiment)
    try:
        run_experiment(exp, out, workers=options.get("workers", 1),
                       scheduler=options.get("scheduler"),
                       progress=False if options.get("quiet") else None)
    except KeyboardInterrupt:
        print(f"interrupted: the finished chunks are kept in {out}; run the same command "
              "again to resume", file=sys.stderr)
        return 130
    if not options.get("no_report"):
        return report(out, options)
    print(f"results written to {out}")
    return 0


def tune(experiment: Path, out: Path, options: dict) -> int:
    """Search the cue profiles named in the experiment's ``tune:`` section (see
    :mod:`runner.tune`)."""
    from runner.tune import tune as run_tune

    return run_tune(experiment, out, options)


def report(out: Path, options: dict) -> int:
    """Rebuild ``out/report`` from the stored results."""
    from runner.report import build_report

    compare = options.get("compare")
    folder = build_report(out, animation=not options.get("no_gif", False),
                          compare=Path(compare) if compare else None)
    print(f"report written to {folder / 'report.md'} (and report.html)")
    return 0


def results(out: Path, options: dict) -> int:
    """Write the stored runs of ``out`` as one tidy table (Parquet or CSV)."""
    from runner.tables import write_runs

    try:
        path, rows = write_runs(out, options["output"])
    except OSError as exc:
        raise BayesprogError(f"cannot write {options['output']}: {exc.strerror or exc}") from None
    print(f"{path}: {rows} rows (task, configuration, run, step, probed cell, Gamma, cues)")
    return 0


def _scenario_path(target: Path) -> Path:
    from bayesprog.language.loader import wrong_kind

    if not target.exists():
        raise BayesprogError(f"cannot read {target}: no such file or folder")
    if target.is_file():
        hint = wrong_kind(target, "scenario", "explore takes a scenario file or a models folder")
        if hint:
            raise BayesprogError(hint)
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
    for term in options.get("ablate") or ():
        try:
            scenario.target.ablate(term)
        except BayesprogError as exc:
            raise BayesprogError(f"--ablate {term!r}: {exc}") from None
    explorer = Explorer(scenario, task, ablate=options.get("ablate") or ())
    serve(explorer, sys.stdin, sys.stdout, seed=options.get("seed", 0))
    return 0
