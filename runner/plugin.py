"""The haptic runner's commands on the ``bayesprog`` command line (entry point ``haptic`` of
the group ``bayesprog.runners``): :func:`add_commands` registers ``run``, ``tune``,
``report``, ``results``, ``explore`` and ``robot``, with their help; each command reads its
arguments into a typed options object and calls the function of the same name here.

The framework's command line knows none of them: it asks every installed runner plugin for
its commands.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from bayesprog import BayesprogError, wrong_kind

if TYPE_CHECKING:
    from runner.world.physics import ProbeSpec
    from runner.world.scenario import Scenario

RUNNER = "haptic"


@dataclass(frozen=True)
class RunOptions:
    workers: int = 1
    #: a Dask scheduler's address, instead of local processes
    scheduler: str | None = None
    quiet: bool = False
    report: bool = True
    #: replaces the experiment's ``replications:`` (None: the file's)
    replications: int | None = None


@dataclass(frozen=True)
class ReportOptions:
    #: the animation of Fig. 11 (an MP4 video)
    animation: bool = True
    #: another experiment's output folder, its findings set beside these
    compare: Path | None = None


@dataclass(frozen=True)
class TuneOptions:
    workers: int = 1
    trials: int | None = None
    quiet: bool = False
    #: a Dask scheduler's address, instead of local processes
    scheduler: str | None = None


@dataclass(frozen=True)
class ExploreOptions:
    task: str | None = None
    seed: int = 0
    ablate: tuple[str, ...] = ()
    #: a ROS 2 node instead of JSON lines on standard input and output
    ros: bool = False
    namespace: str = "/bayesprog"
    frame: str = "workspace"
    #: every probe written to this CSV or Parquet file
    log: Path | None = None
    #: the file of the secret every line must carry (written there when it does not exist)
    secret: Path | None = None
    #: with ``ros``: the keystore of DDS Security (SROS2)
    secure: Path | None = None


@dataclass(frozen=True)
class RobotCommand:
    task: str | None = None
    steps: int = 100
    seed: int = 0
    run: int = 0
    namespace: str = "/bayesprog"
    timeout: float = 60.0
    json: bool = False
    #: readings from the simulated fingertip (MuJoCo); without ``ros``, the loop in one process
    physics: bool = False
    ros: bool = True
    #: every probe written to this CSV or Parquet file
    log: Path | None = None
    #: the file of the explorer's secret, sent with every line
    secret: Path | None = None
    #: the keystore of DDS Security (SROS2)
    secure: Path | None = None


@dataclass(frozen=True)
class RecordOptions:
    presses: int = 50
    seed: int = 1
    #: physics probes even when the scenario's sensor is not ``physics:``
    physics: bool = False
    #: where the per-step traces of physics probes go (a compressed .npz)
    traces: Path | None = None
    quiet: bool = False
    #: record a lab's own sensor: presses sent as JSON lines on standard input, or over ROS 2
    stdio: bool = False
    ros: bool = False
    namespace: str = "/bayesprog"
    #: the file of the secret every line must carry (written there when it does not exist)
    secret: Path | None = None
    #: with ``ros``: the keystore of DDS Security (SROS2)
    secure: Path | None = None


def run(experiment: Path, out: Path, options: RunOptions = RunOptions(),
        report_options: ReportOptions = ReportOptions()) -> int:
    """Run an experiment file (resuming what ``out`` already holds), then write its report,
    holding ``out`` throughout (a second command on it is refused). Local worker processes
    are started first: they import the simulation while this process reads the experiment."""
    from runner.experiments.executors import process_pool, stop_pool
    from runner.experiments.store import hold

    experiment = _experiment_file(experiment)
    with hold(out, "run"):  # the run and its report, nobody else between them
        pool = None
        if options.workers > 1 and options.scheduler is None:
            pool = process_pool(options.workers, preload=("runner.experiments.experiment",),
                                start=True)
        try:
            from runner.experiments.experiment import load_experiment, run_experiment

            exp = load_experiment(experiment, replications=options.replications)
            _say(exp.scenario.warnings)
            if exp.scenario.spec.sensor.physics is not None:
                from runner.world.physics import require as require_physics

                # said here, in one line, rather than by every worker
                require_physics(f"the sensor: {{physics:}} of {exp.scenario.path.name}")
            run_experiment(exp, out, workers=options.workers, scheduler=options.scheduler,
                           progress=False if options.quiet else None, pool=pool)
        except KeyboardInterrupt:
            print(f"interrupted: the finished chunks are kept in {out}; run the same command "
                  "again to resume", file=sys.stderr)
            return 130
        finally:
            if pool is not None:  # (shut down by the run, unless it stopped before)
                stop_pool(pool)
        if options.report:
            return report(out, report_options)
    print(f"results written to {out}")
    return 0


def tune(experiment: Path, out: Path, options: TuneOptions = TuneOptions()) -> int:
    """Search the cue profiles named in the experiment's ``tune:`` section (see
    :mod:`runner.experiments.tune`, :mod:`runner.report.tuning`)."""
    from runner.report.tuning import tune as run_tune

    return run_tune(_experiment_file(experiment), out, trials=options.trials,
                    workers=options.workers, quiet=options.quiet, scheduler=options.scheduler)


def report(out: Path, options: ReportOptions = ReportOptions()) -> int:
    """Rebuild ``out/report`` from the stored results; of a session's log (``out`` a .csv,
    .parquet or .pq file), write its report beside it (:func:`report_log`). Where there is a
    second core, the process that draws Fig. 11 is started first: it imports the figures
    while this process reads the results."""
    import os

    from runner.experiments.log import is_log

    if is_log(out):
        return report_log(out, options)
    from runner.experiments.executors import process_pool, stop_pool
    from runner.experiments.store import hold

    with hold(out, "report", make=False):  # before the pool: a refusal starts nothing
        _output_folder(out)
        pool = process_pool(1, preload=("runner.report.build",), start=True) \
            if (os.cpu_count() or 1) >= 2 else None
        try:
            from runner.report.build import build_report

            folder = build_report(out, animation=options.animation, compare=options.compare,
                                  pool=pool)
        except KeyboardInterrupt:
            print(f"interrupted while drawing the report: the results are kept in {out}; "
                  f"bayesprog report {out} draws it", file=sys.stderr)
            return 130
        finally:
            if pool is not None:
                stop_pool(pool)
    print(f"report written to {folder / 'report.md'} (and report.html)")
    return 0


def report_log(log: Path, options: ReportOptions = ReportOptions()) -> int:
    """The report of a session's log (``explore --log``, ``robot --log``): the session
    replayed, its path and final maps drawn, its numbers, into ``LOG_report/`` beside it
    (:mod:`runner.report.session`). It has no animation; ``--compare`` takes experiments."""
    if options.compare is not None:
        raise BayesprogError(f"--compare {options.compare}: compares an experiment's findings "
                             f"with another's; {log} is a session's log (report it alone)")
    from runner.report.session import build_session_report

    try:
        folder = build_session_report(log)
    except KeyboardInterrupt:
        print(f"interrupted while drawing the report of {log}", file=sys.stderr)
        return 130
    print(f"session report written to {folder / 'report.md'} (and report.html, "
          "path.png, maps.png, summary.json)")
    return 0


def results(out: Path, table: Path) -> int:
    """Write the stored runs of ``out`` as one tidy table (Parquet or CSV)."""
    from runner.report.tables import write_runs

    _output_folder(out)
    try:
        path, rows = write_runs(out, table)
    except OSError as exc:
        raise BayesprogError(f"cannot write {table}: {exc.strerror or exc}") from None
    print(f"{path}: {rows} rows (task, configuration, run, step, probed cell, Gamma, cues)")
    return 0


def _experiment_file(path: Path) -> Path:
    """``path`` as an experiment file of this runner, or a clear error."""
    from bayesprog import bundled_path, load_yaml

    path = bundled_path(str(path), "experiment")
    try:
        located, _ = load_yaml(path.read_text(encoding="utf-8"), str(path))
    except FileNotFoundError:
        raise BayesprogError(f"cannot read {path}: no such file, and no bundled experiment of "
                             "that name (bayesprog examples lists them)") from None
    except UnicodeDecodeError:
        raise BayesprogError(f"cannot read {path}: expected UTF-8 text (an experiment file)") \
            from None
    except IsADirectoryError:
        raise BayesprogError(f"cannot read {path}: it is a directory; expected an experiment "
                             "file") from None
    hint = wrong_kind(path, "experiment", "run takes an experiment file, for instance "
                      "models/experiments/quick.yaml")
    if hint:
        raise BayesprogError(hint)
    data = located.data
    name = data.get("runner") if isinstance(data, dict) else None
    if name not in (None, RUNNER):
        raise BayesprogError(f"{path}: its runner is {name!r}; this command is the {RUNNER!r} "
                             "runner's")
    return path


def _output_folder(out: Path) -> None:
    """``out`` holds an experiment's results written by this runner, or a clear error."""
    manifest = out / "experiment.json"
    try:
        name = json.loads(manifest.read_text(encoding="utf-8"))["experiment"].get("runner")
    except (FileNotFoundError, NotADirectoryError):
        raise BayesprogError(f"{out}: no experiment.json: not an experiment's output folder") \
            from None
    except (ValueError, KeyError, AttributeError, TypeError):
        raise BayesprogError(f"{manifest}: not a readable experiment manifest") from None
    if name not in (None, RUNNER):
        raise BayesprogError(f"{out}: written by the runner {name!r}, not {RUNNER!r}")


def _say(warnings: list) -> None:
    """A scenario's warnings (``FILE:LINE:COL: warning: ...``), on standard error."""
    for warning in warnings:
        print(warning, file=sys.stderr)


def _scenario_path(target: Path) -> Path:
    from bayesprog import bundled_path

    target = bundled_path(str(target), "scenario")
    if not target.exists():
        raise BayesprogError(f"cannot read {target}: no such file or folder, and no bundled "
                             "scenario of that name (bayesprog examples lists them)")
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


def explore(target: Path, options: ExploreOptions = ExploreOptions()) -> int:
    """Serve the step interface on standard input/output, or as a ROS 2 node (``ros``)."""
    if options.ros:
        from runner.robot.ros.run import catch_signals

        catch_signals()  # a node stopped while it loads still ends cleanly
        from runner.robot.ros import require

        require()  # before the scenario is loaded: a missing extra is said at once
    # the secret's file before the scenario: a file that will not do is said at once
    secret = _secret(options.secret, "bayesprog_explorer", "driver") if options.secret else None
    if options.ros:
        print(f"bayesprog_explorer: loading {target}", file=sys.stderr, flush=True)
    from runner.attention.explorer import Explorer
    from runner.world.scenario import load_scenario

    scenario = load_scenario(_scenario_path(target))
    _say(scenario.warnings)
    task = options.task or next(iter(scenario.spec.tasks))
    for term in options.ablate:
        try:
            scenario.target.ablate(term)
        except BayesprogError as exc:
            raise BayesprogError(f"--ablate {term!r}: {exc}") from None
    explorer = Explorer(scenario, task, ablate=options.ablate)
    from runner.experiments.log import SessionLog

    log = SessionLog(options.log) if options.log is not None else None
    try:
        if options.ros:
            from runner.robot.ros.run import explore as explore_ros
            from runner.robot.session import Session

            return explore_ros(Session(explorer, seed=options.seed, frame=options.frame,
                                       log=log, secret=secret),
                               namespace=options.namespace, frame=options.frame,
                               secure=options.secure)
        from runner.robot.stdio import serve

        serve(explorer, sys.stdin, sys.stdout, seed=options.seed, log=log, secret=secret)
        return 0
    finally:
        if log is not None:
            log.close()


def robot(target: Path, options: RobotCommand = RobotCommand()) -> int:
    """A simulated robot: a ROS 2 node that drives ``bayesprog explore --ros`` (see
    runner.robot.ros), or with ``physics`` and not ``ros`` the closed loop in one process
    (runner.robot.closed)."""
    if options.physics:
        from runner.world.physics import require as require_physics

        require_physics()
    if not options.ros:
        return _closed_loop(target, options)
    from runner.robot.ros.run import catch_signals

    catch_signals()
    from runner.robot.ros import require
    from runner.world.scenario import load_scenario

    require()
    from runner.robot.secret import driver_secret

    secret = driver_secret(options.secret) if options.secret is not None else None
    print(f"bayesprog_robot: loading {target}", file=sys.stderr, flush=True)
    scenario = load_scenario(_scenario_path(target))
    _say(scenario.warnings)
    task = _task(scenario, options.task)
    from runner.experiments.log import SessionLog
    from runner.robot.ros.robot_node import RobotOptions
    from runner.robot.ros.run import robot as run_robot

    log = SessionLog(options.log) if options.log is not None else None
    robot_options = RobotOptions(task=task, steps=options.steps, seed=options.seed,
                                 run=options.run, timeout=options.timeout,
                                 physics=_probe_spec(scenario) if options.physics else None,
                                 log=log, secret=secret)
    try:
        return run_robot(scenario, robot_options, namespace=options.namespace,
                         as_json=options.json, secure=options.secure)
    finally:
        if log is not None:
            log.close()


def _probe_spec(scenario: Scenario) -> ProbeSpec:
    """How the fingertip probes: the scenario's ``sensor: {physics:}``, else the defaults."""
    from runner.world.physics import ProbeSpec

    return scenario.spec.sensor.physics or ProbeSpec()


def _task(scenario: Scenario, task: str | None) -> str:
    task = task or next(iter(scenario.spec.tasks))
    if task not in scenario.spec.tasks:
        raise BayesprogError(f"--task: unknown task {task!r}: expected one of "
                             f"{', '.join(scenario.spec.tasks)}")
    return task


def _secret(path: Path, node: str, reader: str) -> str:
    """The secret of ``--secret FILE``: the file's, or a new one written there (said on
    stderr, for the ``reader`` to be given the file)."""
    from runner.robot.secret import explorer_secret

    existed = path.exists()
    secret = explorer_secret(path)
    if not existed:
        print(f"{node}: wrote a new secret to {path} (readable by you only): give the {reader} "
              f"--secret {path}", file=sys.stderr, flush=True)
    return secret


def _closed_loop(target: Path, options: RobotCommand) -> int:
    """``robot --physics`` without ``--ros``: explorer and fingertip in one process."""
    from runner.robot.closed import closed_loop
    from runner.world.scenario import load_scenario

    scenario = load_scenario(_scenario_path(target))
    _say(scenario.warnings)
    task = _task(scenario, options.task)
    from runner.experiments.log import SessionLog

    log = SessionLog(options.log) if options.log is not None else None
    try:
        outcome = closed_loop(scenario, task, options.steps, seed=options.seed,
                              run=options.run, physics=_probe_spec(scenario), log=log)
    finally:
        if log is not None:
            log.close()
    if options.json:
        print(json.dumps(outcome))
    else:
        print(f"bayesprog robot: task {task}, {outcome['steps']} probe(s) by the simulated "
              f"fingertip; Gamma (eq. 16) {outcome['gamma_m']:.4f} m over "
              f"{outcome['border_cells']} border cells; path {outcome['path_m']:.3f} m")
    return 0


def record(target: Path, out: Path, options: RecordOptions = RecordOptions()) -> int:
    """``bayesprog record``: labelled presses of every material of a scenario's layout."""
    if options.physics:
        from runner.world.physics import require as require_physics

        require_physics()
    from runner.experiments.executors import progress_bar
    from runner.robot.presses import record as record_presses
    from runner.robot.presses import write
    from runner.world.scenario import load_scenario

    scenario = load_scenario(_scenario_path(target))
    _say(scenario.warnings)
    if options.stdio or options.ros:
        return _record_driven(scenario, out, options)
    physics = _probe_spec(scenario) if options.physics else None
    kinds = len({int(m) for m in scenario.material_map.ravel()})
    bar = progress_bar(kinds * options.presses, "record", unit="press",
                       enabled=False if options.quiet else None)
    try:
        table, traces = record_presses(scenario, options.presses, options.seed, physics,
                                       keep_traces=options.traces is not None,
                                       progress=lambda done: bar.update(done - bar.n))
    finally:
        bar.close()
    write(table, out, traces, options.traces)
    source = "physics probes" if physics or scenario.spec.sensor.physics else "the sensor"
    print(f"{out}: {options.presses} presses of each of {kinds} materials ({source}, seed "
          f"{options.seed})" + (f"; traces in {options.traces}" if options.traces else ""))
    return 0


def _record_driven(scenario: Scenario, out: Path, options: RecordOptions) -> int:
    """``record --stdio`` or ``--ros``: the presses a lab's driver sends, as recordings."""
    from runner.robot.recording import Recorder, serve

    secret = _secret(options.secret, "bayesprog_recorder", "driver") if options.secret else None
    recorder = Recorder(scenario, out, secret=secret)
    try:
        if options.ros:
            from runner.robot.ros.run import record as record_ros

            return record_ros(recorder, options.namespace, secure=options.secure)
        serve(recorder, sys.stdin, sys.stdout)
    finally:
        recorder.close()
    print(recorder.summary(), file=sys.stderr)
    return 0


# the command line ---------------------------------------------------------------------------
def _at_least(flag: str, value: int | None, least: int) -> None:
    if value is not None and value < least:
        raise BayesprogError(f"{flag}: expected at least {least}, found {value}")


def _whole_number(flag: str, text: str | None, least: int) -> int | None:
    """``text`` as a whole number of at least ``least`` (None stays None): read here rather
    than by argparse, so that a wrong value is one line, not the usage."""
    if text is None:
        return None
    try:
        value = int(text.strip())
    except ValueError:
        raise BayesprogError(f"{flag}: expected a whole number of at least {least}, found "
                             f"{text!r}") from None
    _at_least(flag, value, least)
    return value


def _path(text: str | None) -> Path | None:
    return Path(text) if text else None


def _ros_only(flag: str, given: object, ros: bool) -> None:
    if given and not ros:
        raise BayesprogError(f"{flag}: a ROS 2 node's option: expected --ros with it")


def _cmd_run(args: argparse.Namespace) -> int:
    _at_least("--workers", args.workers, 1)
    replications = _whole_number("--replications", args.replications, 1)
    return run(Path(args.experiment), Path(args.out),
               RunOptions(workers=args.workers, scheduler=args.scheduler, quiet=args.quiet,
                          report=not args.no_report, replications=replications),
               ReportOptions(animation=not args.no_animation,
                             compare=Path(args.compare) if args.compare else None))


def _cmd_tune(args: argparse.Namespace) -> int:
    _at_least("--workers", args.workers, 1)
    _at_least("--trials", args.trials, 1)
    return tune(Path(args.experiment), Path(args.out),
                TuneOptions(workers=args.workers, trials=args.trials, quiet=args.quiet,
                            scheduler=args.scheduler))


def _cmd_report(args: argparse.Namespace) -> int:
    return report(Path(args.out), ReportOptions(
        animation=not args.no_animation, compare=Path(args.compare) if args.compare else None))


def _cmd_results(args: argparse.Namespace) -> int:
    return results(Path(args.out), Path(args.output))


def _cmd_explore(args: argparse.Namespace) -> int:
    if args.stdio == args.ros:
        raise BayesprogError("explore needs one of --stdio (JSON lines on standard input and "
                             "output) or --ros (a ROS 2 node)")
    _at_least("--seed", args.seed, 0)
    _ros_only("--secure", args.secure, args.ros)
    return explore(Path(args.target), ExploreOptions(
        task=args.task, seed=args.seed, ablate=tuple(args.ablate), ros=args.ros,
        namespace=args.namespace, frame=args.frame,
        log=Path(args.log) if args.log else None, secret=_path(args.secret),
        secure=_path(args.secure)))


def _cmd_robot(args: argparse.Namespace) -> int:
    if not args.ros and not args.physics:
        raise BayesprogError("robot needs --ros (it talks to `bayesprog explore --ros` over "
                             "ROS 2) or --physics (the closed loop with a simulated fingertip, "
                             "in one process)")
    _at_least("--steps", args.steps, 1)
    _at_least("--seed", args.seed, 0)
    _at_least("--run", args.run, 0)
    if not args.timeout > 0:
        raise BayesprogError(f"--timeout: expected a positive number of seconds, found "
                             f"{args.timeout}")
    _ros_only("--secret", args.secret, args.ros)
    _ros_only("--secure", args.secure, args.ros)
    return robot(Path(args.target), RobotCommand(
        task=args.task, steps=args.steps, seed=args.seed, run=args.run,
        namespace=args.namespace, timeout=args.timeout, json=args.json, physics=args.physics,
        ros=args.ros, log=Path(args.log) if args.log else None, secret=_path(args.secret),
        secure=_path(args.secure)))


def _cmd_keystore(args: argparse.Namespace) -> int:
    domain = _whole_number("--domain", args.domain, 0)
    return keystore(Path(args.dir), args.enclaves, args.explorer, tuple(args.viewers),
                    tuple(args.namespace), domain)


def _cmd_record(args: argparse.Namespace) -> int:
    presses = _whole_number("--presses", args.presses, 1)
    seed = _whole_number("--seed", args.seed, 0)
    if args.stdio and args.ros:
        raise BayesprogError("record takes one of --stdio and --ros, not both")
    driven = args.stdio or args.ros
    simulated = [flag for flag, given in (("--physics", args.physics), ("--traces", args.traces),
                                          ("--presses", presses is not None),
                                          ("--seed", seed is not None)) if given]
    if driven and simulated:
        raise BayesprogError(f"{', '.join(simulated)}: a simulated sensor's options; with "
                             f"{'--stdio' if args.stdio else '--ros'} the lab's driver sends "
                             "the presses")
    if args.secret and not driven:
        raise BayesprogError("--secret: the driver's lines carry it: expected --stdio or --ros "
                             "with it")
    _ros_only("--secure", args.secure, args.ros)
    if args.ros:
        from runner.robot.ros import require

        require()  # before the scenario is loaded: a missing extra is said at once
    return record(Path(args.target), Path(args.output), RecordOptions(
        presses=50 if presses is None else presses, seed=1 if seed is None else seed,
        physics=args.physics, traces=Path(args.traces) if args.traces else None,
        quiet=args.quiet, stdio=args.stdio, ros=args.ros, namespace=args.namespace,
        secret=_path(args.secret), secure=_path(args.secure)))


def keystore(root: Path, enclaves: list[str], explorer: str | None = None,
             viewers: tuple[str, ...] = (), namespaces: tuple[str, ...] = (),
             domain: int | None = None) -> int:
    """``bayesprog keystore create``: an SROS2 keystore for ``explore``/``robot --secure``."""
    from runner.robot.keystore import EXPLORER_ENCLAVE, NAMESPACE, create_keystore

    if explorer is not None and explorer not in enclaves:
        raise BayesprogError(f"--explorer {explorer}: not among --enclaves "
                             f"({', '.join(enclaves)}): expected the explorer's enclave listed")
    parts = create_keystore(root, enclaves, explorer or EXPLORER_ENCLAVE, viewers,
                            namespaces or (NAMESPACE,), domain)
    from runner.robot.keystore import Keystore

    governed = Keystore(root).domain
    print(f"{root}: " + ", ".join(f"{name} ({part})" for name, part in parts.items())
          + f"; topics in {', '.join(namespaces or (NAMESPACE,))}, domain {governed}; CA "
          f"{root / 'public' / 'ca.cert.pem'} (keep {root / 'private'} to yourself)")
    return 0


def validate(path: str, kind: str) -> list | None:
    """``bayesprog validate`` of this runner's files: a scenario (its programs, sensor model,
    materials, tasks and objects), an experiment (its scenario, tasks and sizes; its search
    when it has a ``tune:`` section), a sensor model or a file of materials' physical
    properties; its warnings, or None for another kind. Problems raise, each at its place."""
    if kind == "scenario":
        from runner.world.scenario import load_scenario

        return load_scenario(Path(path)).warnings
    if kind == "experiment":
        from runner.experiments.experiment import load_experiment

        experiment = load_experiment(Path(path))
        if experiment.spec.tune is not None:
            from runner.experiments.tune import load_search

            load_search(path)
        return experiment.scenario.warnings
    if kind == "sensor model":
        from runner.world.sensor import load_sensor_model

        load_sensor_model(path)
        return []
    if kind == "physics materials":
        from bayesprog import load_document
        from runner.world.physics import MaterialsFile

        load_document(Path(path), MaterialsFile)
        return []
    return None


def add_commands(commands: argparse._SubParsersAction) -> None:
    """Register the runner's commands, with their help, on the ``bayesprog`` command line."""
    p = commands.add_parser("run", help="run a haptic-exploration experiment file and write "
                            "its report (Fig. 9, 10, 11 of the paper, the findings)")
    p.add_argument("experiment", metavar="EXPERIMENT.yaml", help="an experiment file")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder for results and the report; an interrupted run resumes there")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar (default: a bar on a terminal)")
    p.add_argument("--workers", type=int, default=1, metavar="N",
                   help="local processes (default: %(default)s)")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="an existing Dask scheduler, instead of local processes (install "
                   "bayesprog[dask]; default: none)")
    p.add_argument("--replications", metavar="R",
                   help="run the protocol R times, each replication on its own sample of "
                   "start cells, readings and tie-breaks; the report pools them (default: the "
                   "experiment's replications:, else 1)")
    p.add_argument("--no-report", action="store_true",
                   help="do not build the report (default: build it)")
    _report_arguments(p)
    p.set_defaults(func=_cmd_run)

    p = commands.add_parser("tune", help="search the cue profiles of an experiment's tune: "
                            "section and compare them with the hand-chosen ones")
    p.add_argument("experiment", metavar="EXPERIMENT.yaml",
                   help="an experiment file with a tune: section")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder for the search's journal and results; an interrupted search "
                   "resumes there")
    p.add_argument("--trials", type=int, metavar="N",
                   help="candidates to evaluate (default: the file's tune.trials); more than "
                   "before continues the search")
    p.add_argument("--workers", type=int, default=1, metavar="N",
                   help="local processes (default: %(default)s)")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="an existing Dask scheduler, instead of local processes (install "
                   "bayesprog[dask]; default: none)")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar (default: a bar on a terminal)")
    p.set_defaults(func=_cmd_tune)

    p = commands.add_parser("report", help="rebuild an experiment's report from its stored "
                            "results, or draw a session from its log (explore --log, robot "
                            "--log)")
    p.add_argument("out", metavar="DIR|LOG.csv",
                   help="an experiment's output folder (bayesprog run --out), or a session's "
                   "log (.csv, .parquet, with its .json beside it): the session is replayed "
                   "and its report (the path over the layout, the final maps, the numbers) "
                   "written into LOG_report/ beside the log")
    _report_arguments(p)
    p.set_defaults(func=_cmd_report)

    p = commands.add_parser("results", help="write an experiment's stored runs as one tidy "
                            "table")
    p.add_argument("out", metavar="DIR", help="an experiment's output folder (bayesprog run --out)")
    p.add_argument("-o", "--output", required=True, metavar="RUNS.parquet|.csv",
                   help="the table: one row per task, configuration, run and step, with the "
                   "probed cell, Gamma and the cues at that cell; its format from the extension")
    p.set_defaults(func=_cmd_results)

    p = commands.add_parser("explore", help="drive an exploration step by step (JSON lines, "
                            "or a ROS 2 node)")
    p.add_argument("target", metavar="SCENARIO_OR_MODELS",
                   help="a scenario file, or a models folder (its scenarios/paper.yaml)")
    p.add_argument("--stdio", action="store_true",
                   help="JSON lines on stdin/stdout (this or --ros)")
    p.add_argument("--ros", action="store_true",
                   help="a ROS 2 node that takes the same lines on a topic (install "
                   "bayesprog[ros]; this or --stdio)")
    p.add_argument("--task", help="task of the scenario (default: its first)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the decisions' tie breaking (default: %(default)s)")
    p.add_argument("--ablate", action="append", default=[], metavar="TERM",
                   help="decide with this term of pi_tar uniform; repeatable (default: none)")
    p.add_argument("--namespace", default="/bayesprog", metavar="NS",
                   help="with --ros: the node's namespace (default: %(default)s)")
    p.add_argument("--frame", default="workspace", metavar="ID",
                   help="with --ros: the frame of what it publishes (default: %(default)s)")
    p.add_argument("--log", metavar="FILE.csv|.parquet", default=None,
                   help="write every probe (cell, readings, missing readings, warnings, the "
                   "material decided, the next cell, timings) to this file, a recordings file "
                   "`bayesprog learn` reads; what the session explored beside it (FILE.json)")
    _security_arguments(p, "the explorer")
    p.set_defaults(func=_cmd_explore)

    p = commands.add_parser("robot", help="a simulated robot that drives `explore --ros` over "
                            "ROS 2 (install bayesprog[ros])")
    p.add_argument("target", metavar="SCENARIO_OR_MODELS",
                   help="a scenario file, or a models folder (its scenarios/paper.yaml)")
    p.add_argument("--ros", action="store_true",
                   help="talk to the explorer over ROS 2 (this, or --physics alone for the "
                   "closed loop in one process)")
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
    p.add_argument("--physics", action="store_true",
                   help="probe with a simulated fingertip (MuJoCo; install bayesprog[physics]): "
                   "without --ros, the closed loop in one process")
    p.add_argument("--log", metavar="FILE.csv|.parquet", default=None,
                   help="write every probe (as explore --log does) to this file")
    p.add_argument("--secret", metavar="FILE", default=None,
                   help="with --ros: send the explorer's secret, read from FILE (the file "
                   "explore --secret wrote), with every line (default: none)")
    p.add_argument("--secure", metavar="KEYSTORE", default=None,
                   help="with --ros: run under DDS Security (SROS2) in the enclave "
                   "/bayesprog/driver of KEYSTORE (bayesprog keystore create; "
                   "ROS_SECURITY_ENCLAVE_OVERRIDE names another) (default: not secured)")
    p.set_defaults(func=_cmd_robot)

    p = commands.add_parser("record", help="record labelled presses of every material of a "
                            "scenario (CSV: material, the readings by name, the cell, raw "
                            "figures), or a lab's own sensor's presses sent by its driver "
                            "(--stdio, --ros)")
    p.add_argument("target", metavar="SCENARIO_OR_MODELS",
                   help="a scenario file, or a models folder (its scenarios/paper.yaml)")
    p.add_argument("--physics", action="store_true",
                   help="presses by a simulated fingertip (MuJoCo; install bayesprog[physics]) "
                   "(default: the scenario's sensor)")
    p.add_argument("--presses", metavar="N", default=None,
                   help="presses per material, at random cells of it (default: 50)")
    p.add_argument("--seed", metavar="S", default=None,
                   help="press i of material m is seeded by (S, m, i) (default: 1)")
    p.add_argument("-o", "--output", required=True, metavar="FILE.csv",
                   help="where the presses are written")
    p.add_argument("--traces", metavar="FILE.npz", default=None,
                   help="also write each physics press's force and height traces")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument("--stdio", action="store_true",
                   help='record the presses a driver sends as JSON lines on standard input, '
                   '{"material": NAME or "cell": [ix, iy], "readings": {...}}, one reply line '
                   "each")
    p.add_argument("--ros", action="store_true",
                   help="the same over ROS 2: the node bayesprog_recorder reads the lines on "
                   "NS/probe and replies on NS/reply (install bayesprog[ros])")
    p.add_argument("--namespace", default="/bayesprog", metavar="NS",
                   help="with --ros: the node's namespace (default: %(default)s)")
    _security_arguments(p, "the recorder")
    p.set_defaults(func=_cmd_record)

    _keystore_command(commands)


def _keystore_command(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("keystore", help="make the keys, certificates and signed "
                            "permissions of DDS Security (SROS2) for explore/robot --secure")
    verbs = p.add_subparsers(dest="verb", metavar="VERB", required=True,
                             help="create: a keystore, or more enclaves in one")
    q = verbs.add_parser("create", help="a keystore (as ros2 security create_keystore and "
                         "create_enclave make it), or more enclaves in one")
    q.add_argument("dir", metavar="DIR", help="the keystore's folder (new, or a keystore to add "
                   "enclaves to: its CA and governance are kept)")
    q.add_argument("--enclaves", nargs="+", required=True, metavar="ENCLAVE",
                   help="the enclaves to make: the explorer's (see --explorer), and the "
                   "drivers', each allowed to publish probes and read the explorer's topics")
    q.add_argument("--explorer", metavar="ENCLAVE", default=None,
                   help="which of --enclaves is the explorer's, allowed to read probes and "
                   "publish replies and maps (default: /bayesprog/explorer)")
    q.add_argument("--viewers", nargs="+", default=[], metavar="ENCLAVE",
                   help="enclaves that may only read (RViz) (default: none)")
    q.add_argument("--namespace", action="append", default=[], metavar="NS",
                   help="the explorer's namespace; repeatable (default: /bayesprog)")
    q.add_argument("--domain", metavar="ID", default=None,
                   help="the ROS_DOMAIN_ID the nodes will use (default: ROS_DOMAIN_ID's, else "
                   "the keystore's, else 0)")
    q.set_defaults(func=_cmd_keystore)


def _security_arguments(p: argparse.ArgumentParser, node: str) -> None:
    p.add_argument("--secret", metavar="FILE", default=None,
                   help="answer only lines that carry the secret in FILE (\"secret\": ...; "
                   "replies never hold it); a new one is written there, readable by you only, "
                   "when FILE does not exist (default: none)")
    p.add_argument("--secure", metavar="KEYSTORE", default=None,
                   help=f"with --ros: run {node} under DDS Security (SROS2) in the enclave "
                   "/bayesprog/explorer of KEYSTORE (bayesprog keystore create; "
                   "ROS_SECURITY_ENCLAVE_OVERRIDE names another) (default: not secured)")


def _report_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--no-animation", "--no-gif", dest="no_animation", action="store_true",
                   help="report without the animation of Fig. 11, an MP4 video (default: with)")
    p.add_argument("--compare", metavar="DIR", help="another experiment's output folder: its "
                   "findings are set beside these in the report (default: none)")
