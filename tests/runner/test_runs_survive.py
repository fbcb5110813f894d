"""Runs survive what happens to real runs: damaged files, paths written another way, edited
experiment files, workers that die, a parent that is killed, a cluster without workers."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import psutil
import pytest

from bayesprog.cli import main
from bayesprog.errors import BayesprogError
from runner.experiments import experiment as experiment_module
from runner.experiments.experiment import load_experiment, run_experiment, units
from runner.experiments.store import ResultStore
from tests.runner.test_experiment import assert_same, results_of, write_experiment


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished small experiment, and its results."""
    folder = tmp_path_factory.mktemp("finished")
    path = write_experiment(folder)
    run_experiment(load_experiment(path), folder / "out", progress=False)
    return path, folder / "out", results_of(folder / "out")


def copy_of(out: Path, tmp_path: Path) -> Path:
    import shutil

    return Path(shutil.copytree(out, tmp_path / "out"))


def mtimes(store: ResultStore, spec) -> dict:
    return {u: store.path(u).stat().st_mtime_ns for u in units(spec)}


def test_a_truncated_chunk_is_set_aside_and_computed_again(finished, tmp_path, capsys):
    path, out, reference = finished
    out = copy_of(out, tmp_path)
    experiment = load_experiment(path)
    store = ResultStore(out)
    all_units = units(experiment.spec)
    damaged = store.path(all_units[2])
    data = damaged.read_bytes()
    damaged.write_bytes(data[: len(data) // 2])  # as a full disk leaves it
    before = mtimes(store, experiment.spec)
    assert main(["run", str(path), "--out", str(out), "--no-report", "-q"]) == 0
    assert "damaged" in capsys.readouterr().err
    assert damaged.with_name(damaged.name + ".damaged").is_file()
    after = mtimes(ResultStore(out), experiment.spec)
    assert [u for u in all_units if after[u] != before[u]] == [all_units[2]]  # only that one
    assert_same(results_of(out), reference)


def test_an_empty_manifest_is_written_again_and_the_chunks_are_kept(finished, tmp_path):
    path, out, reference = finished
    out = copy_of(out, tmp_path)
    experiment = load_experiment(path)
    before = mtimes(ResultStore(out), experiment.spec)
    (out / "experiment.json").write_text("")
    assert main(["run", str(path), "--out", str(out), "--no-report", "-q"]) == 0
    assert (out / "experiment.json.damaged").is_file()
    assert json.loads((out / "experiment.json").read_text())["hash"]
    assert mtimes(ResultStore(out), experiment.spec) == before  # each chunk vouched for itself
    assert_same(results_of(out), reference)


def test_with_a_damaged_manifest_a_chunk_of_another_configuration_is_not_taken(finished,
                                                                               tmp_path):
    path, out, reference = finished
    out = copy_of(out, tmp_path)
    other = write_experiment(tmp_path, seed=8)
    run_experiment(load_experiment(other), tmp_path / "other", progress=False)
    unit = units(load_experiment(path).spec)[0]
    store = ResultStore(out)
    store.path(unit).write_bytes(ResultStore(tmp_path / "other").path(unit).read_bytes())
    (out / "experiment.json").write_text("{")
    run_experiment(load_experiment(path), out, progress=False)
    assert store.path(unit).with_name(store.path(unit).name + ".damaged").is_file()
    assert_same(results_of(out), reference)


def test_the_configuration_does_not_depend_on_how_its_path_is_written(finished, tmp_path):
    path, out, _ = finished
    out = copy_of(out, tmp_path)
    spec = load_experiment(path).spec
    before = mtimes(ResultStore(out), spec)
    relative = os.path.relpath(path, tmp_path)
    done = subprocess.run([sys.executable, "-m", "bayesprog.cli", "run", relative, "--out",
                           "out", "--no-report", "-q"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert mtimes(ResultStore(out), spec) == before  # resumed as finished: nothing recomputed


def test_report_from_another_folder_draws_what_was_stored(finished, tmp_path):
    path, out, _ = finished
    out = copy_of(out, tmp_path)
    moved = tmp_path / "elsewhere"
    moved.mkdir()
    # the experiment file is edited afterwards: the report still draws the stored experiment
    edited = path.read_text().replace("iterations: 6", "iterations: 60")
    original = path.read_text()
    try:
        path.write_text(edited)
        done = subprocess.run([sys.executable, "-m", "bayesprog.cli", "report",
                               os.path.relpath(out, moved), "--no-animation"], cwd=moved,
                              capture_output=True, text=True, timeout=300)
    finally:
        path.write_text(original)
    assert done.returncode == 0, done.stderr
    assert "4 runs x 6 iterations" in (out / "report" / "report.md").read_text()


def _workers(process: subprocess.Popen) -> list[psutil.Process]:
    """The worker processes of a run (not the resource tracker beside them)."""
    found = []
    for child in psutil.Process(process.pid).children(recursive=True):
        try:
            if "child_main" in " ".join(child.cmdline()):
                found.append(child)
        except psutil.NoSuchProcess:
            pass
    return found


def _slow_experiment(folder: Path) -> Path:
    return write_experiment(folder, tasks=["T1"], configurations=["full"], runs=8,
                            iterations=60, chunk=1)


def test_a_killed_worker_is_replaced_and_the_numbers_do_not_change(tmp_path):
    path = _slow_experiment(tmp_path)
    out = tmp_path / "out"
    process = subprocess.Popen([sys.executable, "-m", "bayesprog.cli", "run", str(path),
                                "--out", str(out), "--no-report", "-q", "--workers", "2"],
                               stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        workers: list[psutil.Process] = []
        while not workers and time.monotonic() < deadline:
            time.sleep(0.05)
            workers = _workers(process)
        assert workers, "no worker process started"
        time.sleep(0.5)  # importing or computing: either way it dies holding a unit
        workers[0].send_signal(signal.SIGKILL)
        _, err = process.communicate(timeout=300)
    finally:
        process.kill()
    assert process.returncode == 0, err
    assert "worker process died" in err
    run_experiment(load_experiment(path), tmp_path / "alone", progress=False)
    assert_same(results_of(out), results_of(tmp_path / "alone"))


def test_killing_the_parent_leaves_no_worker_behind(tmp_path):
    path = _slow_experiment(tmp_path)
    process = subprocess.Popen([sys.executable, "-m", "bayesprog.cli", "run", str(path),
                                "--out", str(tmp_path / "out"), "--no-report", "-q",
                                "--workers", "2"])
    deadline = time.monotonic() + 120
    workers: list[psutil.Process] = []
    while len(workers) < 2 and time.monotonic() < deadline:
        time.sleep(0.2)
        workers = _workers(process)
    assert workers, "no worker process started"
    process.send_signal(signal.SIGKILL)
    process.wait()
    gone, alive = psutil.wait_procs(workers, timeout=10)
    for p in alive:
        p.kill()
    assert not alive


def test_dask_a_unit_whose_worker_died_is_computed_again(finished, tmp_path, monkeypatch):
    from dask.distributed import LocalCluster
    from distributed.scheduler import KilledWorker

    path, _, reference = finished
    real = experiment_module.compute_unit
    killed = tmp_path / "killed"  # a file: Dask copies the function, and a list with it

    def dies_once(experiment_path, unit, *rest):
        if not killed.exists():
            killed.write_text(unit.name)
            raise KilledWorker(unit.name, SimpleNamespace(address="tcp://gone:1"), 3)
        return real(experiment_path, unit, *rest)

    monkeypatch.setattr(experiment_module, "compute_unit", dies_once)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address="127.0.0.1:0") as cluster:
        run_experiment(load_experiment(path), tmp_path / "out",
                       scheduler=cluster.scheduler_address, progress=False)
    assert killed.exists()
    assert_same(results_of(tmp_path / "out"), reference)


def test_dask_a_scheduler_without_workers_is_reported(finished, tmp_path, monkeypatch):
    from dask.distributed import LocalCluster

    path = finished[0]
    monkeypatch.setattr(experiment_module, "WORKER_TIMEOUT", 2.0)
    with LocalCluster(n_workers=0, processes=False, dashboard_address="127.0.0.1:0") as cluster:
        started = time.monotonic()
        with pytest.raises(BayesprogError, match="no worker"):
            run_experiment(load_experiment(path), tmp_path / "out",
                           scheduler=cluster.scheduler_address, progress=False)
        assert time.monotonic() - started < 60


def test_a_report_on_a_damaged_chunk_says_so(finished, tmp_path, capsys):
    path, out, _ = finished
    out = copy_of(out, tmp_path)
    unit = units(load_experiment(path).spec)[0]
    ResultStore(out).path(unit).write_bytes(b"PK\x03\x04 not a whole archive")
    assert main(["report", str(out), "--no-animation"]) == 2
    err = capsys.readouterr().err
    assert "damaged chunk" in err and "run the experiment again" in err and "Traceback" not in err


# what a user can write in experiment and scenario files, and on the command line ---------------
MODELS = Path(__file__).parents[2] / "models"


def _scenario(folder: Path, old: str, new: str) -> Path:
    text = (MODELS / "scenarios" / "paper.yaml").read_text().replace("../", f"{MODELS}/")
    assert old in text
    path = folder / "scenario.yaml"
    path.write_text(text.replace(old, new))
    return path


TRIANGLE = "triangle: [[-0.09, -0.06], [0.09, -0.06], [0.0, 0.09]]"


@pytest.mark.parametrize("changes, scenario_edit, expected", [
    ({"runs": 10**9}, None, "small_0.yaml:11:7: 1,000,000,000 runs of 6 iterations needs"),
    ({"iterations": 10**9}, None, "4 runs of 1,000,000,000 iterations needs"),
    ({"seed": -1}, None, "seed: Input should be greater than or equal to 0"),
    ({}, ("shape: [30, 60]", "shape: [100000, 100000]"),
     "scenario.yaml:10:7: grid: a grid of 100000 x 100000 has 10,000,000,000 cells"),
    ({}, ("shape: [30, 60]", "shape: [0, 60]"), "scenario.yaml:10:7: grid: expected sizes >= 1"),
    ({}, ("pi_obj.yaml", "nothere.yaml"), re.compile(r"scenario.yaml:8:10: shape program "
                                                     r"'[^']*nothere.yaml': no such file")),
    ({}, (TRIANGLE, "triangle: [[-0.09, -0.06], [0.09, -0.06]]"),
     "scenario.yaml:15:13: templates.triangle: polygon: expected at least 3 points"),
])
def test_bad_experiments_and_scenarios_are_refused_at_their_place(tmp_path, capsys, changes,
                                                                  scenario_edit, expected):
    if scenario_edit:
        changes = dict(changes, scenario=str(_scenario(tmp_path, *scenario_edit)))
    path = write_experiment(tmp_path, **changes)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "-q", "--no-report"]) == 2
    err = capsys.readouterr().err
    found = expected.search(err) if isinstance(expected, re.Pattern) else expected in err
    assert found and "Traceback" not in err, err
    assert not (tmp_path / "out").exists()  # refused before anything is written


@pytest.mark.parametrize("out, scheduler, expected", [
    ("afile", None, "cannot write results there"),
    ("/dev/null/x", None, "cannot write results there"),
    ("out", "notaurl", "--scheduler notaurl: cannot reach a Dask scheduler"),
    ("out", "tcp://localhost", "cannot reach a Dask scheduler (missing port"),
])
def test_bad_out_folders_and_schedulers_are_user_errors(finished, tmp_path, capsys, out,
                                                        scheduler, expected):
    (tmp_path / "afile").write_text("x")
    target = out if out.startswith("/") else str(tmp_path / out)
    extra = ["--scheduler", scheduler] if scheduler else []
    assert main(["run", str(finished[0]), "--out", target, "-q", "--no-report", *extra]) == 2
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err


@pytest.mark.parametrize("content", ["[1, 2]", "", "{", '{"experiment": 5}'])
def test_report_on_a_manifest_that_is_not_one(tmp_path, capsys, content):
    (tmp_path / "experiment.json").write_text(content)
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "not a readable experiment manifest" in err and "Traceback" not in err


def test_one_deeply_nested_robot_line_does_not_end_the_session(tmp_path):
    lines = "[" * 3000 + "\n" + "x" * 3_000_000 + "\n" + \
        json.dumps({"cell": [1, 1], "texture": 0.1, "compliance": 0.2}) + "\n"
    done = subprocess.run([sys.executable, "-m", "bayesprog.cli", "explore",
                           str(MODELS / "scenarios" / "paper.yaml"), "--stdio"], input=lines,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    replies = [json.loads(line) for line in done.stdout.splitlines()]
    assert "nested too deeply" in replies[0]["error"]
    assert "more than 1,048,576 characters" in replies[1]["error"]
    assert replies[2]["k"] == 0 and len(replies[2]["next"]) == 2
