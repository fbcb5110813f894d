"""The haptic runner as a plugin of the ``bayesprog`` command line (entry point ``haptic`` of
the group ``bayesprog.runners``): ``bayesprog run EXPERIMENT --out DIR``, ``bayesprog report
DIR``, ``bayesprog tune EXPERIMENT --out DIR``, ``bayesprog explore SCENARIO --stdio`` (or
``--ros``), and its own command ``bayesprog robot SCENARIO --ros`` (:func:`add_commands`)."""

from __future__ import annotations

import argparse
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
    """Serve the step interface on standard input/output, or as a ROS 2 node (``ros``)."""
    if options.get("ros"):
        from runner.ros.run import catch_signals

        catch_signals()  # a node stopped while it loads still ends cleanly
        from runner.ros import require

        require()  # before the scenario is loaded: a missing extra is said at once
        print(f"bayesprog_explorer: loading {target}", file=sys.stderr, flush=True)
    from runner.explorer import Explorer
    from runner.scenario import load_scenario

    scenario = load_scenario(_scenario_path(target))
    task = options.get("task") or next(iter(scenario.spec.tasks))
    for term in options.get("ablate") or ():
        try:
            scenario.target.ablate(term)
        except BayesprogError as exc:
            raise BayesprogError(f"--ablate {term!r}: {exc}") from None
    explorer = Explorer(scenario, task, ablate=options.get("ablate") or ())
    if options.get("ros"):
        from runner.ros.run import explore as explore_ros
        from runner.session import Session

        return explore_ros(Session(explorer, seed=options.get("seed", 0)),
                           namespace=options.get("namespace") or "/bayesprog",
                           frame=options.get("frame") or "workspace")
    from runner.stdio import serve

    serve(explorer, sys.stdin, sys.stdout, seed=options.get("seed", 0))
    return 0


def robot(target: Path, options: dict) -> int:
    """A simulated robot node that drives ``bayesprog explore --ros`` (see runner.ros)."""
    from runner.ros.run import catch_signals

    catch_signals()
    from runner.ros import require
    from runner.scenario import load_scenario

    require()
    print(f"bayesprog_robot: loading {target}", file=sys.stderr, flush=True)
    scenario = load_scenario(_scenario_path(target))
    task = options.get("task") or next(iter(scenario.spec.tasks))
    if task not in scenario.spec.tasks:
        raise BayesprogError(f"--task: unknown task {task!r}: expected one of "
                             f"{', '.join(scenario.spec.tasks)}")
    from runner.ros.robot_node import RobotOptions
    from runner.ros.run import robot as run_robot

    robot_options = RobotOptions(task=task, steps=options["steps"], seed=options.get("seed", 0),
                                 run=options.get("run", 0), timeout=options["timeout"])
    return run_robot(scenario, robot_options, namespace=options.get("namespace") or "/bayesprog",
                     as_json=bool(options.get("json")))


def add_commands(commands: argparse._SubParsersAction) -> None:
    """The runner's own commands beside the framework's: ``bayesprog robot``."""
    p = commands.add_parser("robot", help="a simulated robot that drives `explore --ros` over "
                            "ROS 2 (install bayesprog[ros])")
    p.add_argument("target", metavar="SCENARIO_OR_MODELS",
                   help="a scenario file, or a models folder (its scenarios/paper.yaml)")
    p.add_argument("--ros", action="store_true",
                   help="talk to the explorer over ROS 2 (required: the only interface)")
    p.add_argument("--task", help="task of the scenario, for Gamma (default: its first)")
    p.add_argument("--steps", type=int, default=100, metavar="N",
                   help="probes to make, the start cell's included (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, metavar="S",
                   help="be run R of an experiment of this seed: its start cell, its readings, "
                   "and the explorer's decisions (default: %(default)s)")
    p.add_argument("--run", type=int, default=0, metavar="R",
                   help="the run (default: %(default)s)")
    p.add_argument("--namespace", default="/bayesprog", metavar="NS",
                   help="the explorer's namespace (default: %(default)s)")
    p.add_argument("--timeout", type=float, default=60.0, metavar="SECONDS",
                   help="how long to wait for the explorer, and for each of its answers "
                   "(default: %(default)s)")
    p.add_argument("--json", action="store_true",
                   help="print the outcome as one JSON object, with the path (default: a line)")
    p.set_defaults(func=_cmd_robot)


def _cmd_robot(args: argparse.Namespace) -> int:
    if not args.ros:
        raise BayesprogError("robot needs --ros (it talks to `bayesprog explore --ros` over "
                             "ROS 2)")
    for flag, value, least in (("--steps", args.steps, 1), ("--seed", args.seed, 0),
                               ("--run", args.run, 0)):
        if value is not None and value < least:
            raise BayesprogError(f"{flag}: expected at least {least}, found {value}")
    if not args.timeout > 0:
        raise BayesprogError(f"--timeout: expected a positive number of seconds, found "
                             f"{args.timeout}")
    return robot(Path(args.target), vars(args))
