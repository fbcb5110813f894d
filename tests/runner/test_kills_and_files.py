"""Nothing a user writes or does to a run leaves it broken: files named by experiments and
scenarios are checked where they are named, generated experiment and scenario files load or
are refused at a place, and a run killed at any moment (SIGKILL, SIGTERM, Ctrl-C to its
process group), during its units or its report, leaves no process behind, no traceback, no
leaked semaphore (but for SIGKILL), no half-written animation, and resumes to the numbers of
a run never killed.

Cases run in CI: 6 references, 2 x 40 generated files, 6 kills at drawn moments (each
followed by its resume)."""

from __future__ import annotations

import copy
import json
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import psutil
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bayesprog import BayesprogError
from bayesprog.cli import main
from runner.experiments.experiment import load_experiment
from runner.world.scenario import load_scenario

MODELS = Path(__file__).parents[2] / "models"
BAYESPROG = str(Path(sys.executable).with_name("bayesprog"))


# files named by others --------------------------------------------------------------------

def _experiment(folder: Path, scenario: str) -> Path:
    path = folder / "exp.yaml"
    path.write_text("experiment: 1\nname: e\nrunner: haptic\n"
                    f"scenario: {json.dumps(scenario)}\ntasks: [T1]\n"
                    "configurations: [full]\nruns: 2\niterations: 3\nseed: 1\n")
    return path


REFERENCES = [
    ("missing.yaml", None, "no such file (looked for "),
    ("folder", lambda p: p.mkdir(), "a folder, expected a scenario file"),
    ("latin.yaml", lambda p: p.write_bytes(b"scenario: 1\nname: caf\xe9\n"), "expected UTF-8"),
    ("program.yaml", lambda p: p.write_text("bayesprog: 1\n"),
     "a program file, expected a scenario file"),
]


@pytest.mark.parametrize("name, make, expected", REFERENCES)
def test_an_experiments_scenario_that_cannot_be_read_is_named_where_it_is_named(
        tmp_path, capsys, name, make, expected):
    if make is not None:
        make(tmp_path / name)
    path = _experiment(tmp_path, name)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert f"exp.yaml:4:11: scenario {name!r}: " in err and expected in err, err
    assert "Traceback" not in err and not (tmp_path / "out").exists()


@pytest.mark.parametrize("key, replaced, expected", [
    ("perception: ../pi_per.yaml", "perception: nowhere.yaml", "perception program 'nowhere.yaml'"),
    ("target: ../pi_tar.yaml", "target: ../scenarios/paper.yaml",
     "a scenario file, expected a program file"),
])
def test_a_scenarios_programs_are_checked_where_they_are_named(tmp_path, capsys, key, replaced,
                                                                expected):
    text = (MODELS / "scenarios" / "paper.yaml").read_text().replace(key, replaced)
    scenario = MODELS / "scenarios" / f".test_{uuid.uuid4().hex[:8]}.yaml"
    scenario.write_text(text)  # beside the shipped one, for its relative program paths
    try:
        path = _experiment(tmp_path, str(scenario))
        assert main(["run", str(path), "--out", str(tmp_path / "out"), "-q"]) == 2
        err = capsys.readouterr().err
        line = text.splitlines().index("  " + replaced) + 1
        assert f"{scenario.name}:{line}:" in err and expected in err, err
    finally:
        scenario.unlink()


# generated experiment and scenario files --------------------------------------------------

_VALUES = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10**12, 10**12),
              st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12)),
    lambda inner: st.one_of(st.lists(inner, max_size=4),
                            st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=8)


def _paths(data, prefix=()):
    yield prefix
    if isinstance(data, dict):
        for key, value in data.items():
            yield from _paths(value, prefix + (key,))
    elif isinstance(data, list):
        for i, value in enumerate(data):
            yield from _paths(value, prefix + (i,))


@st.composite
def _edited(draw, base: dict) -> dict:
    """``base`` with a few values replaced by anything, or removed."""
    data = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(data) if p]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = data
        for key in path[:-1]:
            parent = parent[key]
        if draw(st.booleans()) and isinstance(parent, dict):
            del parent[path[-1]]
        else:
            parent[path[-1]] = draw(_VALUES)
    return data


_SCENARIO = yaml.safe_load((MODELS / "scenarios" / "small_grid.yaml").read_text())
_EXPERIMENT = yaml.safe_load((MODELS / "experiments" / "small_grid.yaml").read_text())
_FUZZ = settings(max_examples=40, deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.too_slow])


def _loads_or_is_refused(folder: Path, data: dict, load) -> None:
    """``data`` written as a file beside the shipped ones (for their relative paths): it loads,
    or is refused with a bayesprog error (a message at its place), never anything else."""
    path = folder / f".fuzz_{os.getpid()}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    try:
        load(path)
    except BayesprogError as exc:
        assert str(exc)
    finally:
        path.unlink()


@_FUZZ
@given(_edited(_SCENARIO))
def test_generated_scenarios_load_or_are_refused_at_a_place(data):
    _loads_or_is_refused(MODELS / "scenarios", data, load_scenario)


@_FUZZ
@given(_edited(_EXPERIMENT))
def test_generated_experiments_load_or_are_refused_at_a_place(data):
    _loads_or_is_refused(MODELS / "experiments", data, load_experiment)


# kills at random moments -------------------------------------------------------------------

def _tiny(folder: Path) -> Path:
    path = folder / "tiny.yaml"
    path.write_text("experiment: 1\nname: tiny\nrunner: haptic\n"
                    f"scenario: {json.dumps(str(MODELS / 'scenarios' / 'small_grid.yaml'))}\n"
                    "tasks: [T1, T2]\nconfigurations: [full, without_S]\nruns: 4\n"
                    "iterations: 30\nseed: 5\nchunk: 2\n")
    return path


def _env(mark: str) -> dict:
    return dict(os.environ, BAYESPROG_TEST_MARK=mark)


def _status(process: psutil.Process) -> str:
    try:
        return process.status()
    except psutil.NoSuchProcess:
        return psutil.STATUS_DEAD


def _marked(mark: str) -> list[str]:
    """The processes still alive that a run of ``mark`` started."""
    found = []
    for process in psutil.process_iter():
        try:
            if process.environ().get("BAYESPROG_TEST_MARK") == mark:
                found.append(f"{process.pid} {' '.join(process.cmdline())[:80]}")
        except (psutil.Error, OSError):
            continue
    return found


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The tiny experiment run whole once, and how long that took (to draw kill moments)."""
    folder = tmp_path_factory.mktemp("reference")
    start = time.monotonic()
    subprocess.run([BAYESPROG, "run", str(_tiny(folder)), "--out", str(folder / "out"),
                    "--workers", "2", "-q"], check=True, capture_output=True, timeout=300)
    return folder / "out", time.monotonic() - start


#: (signal, moment as a fraction of a whole run): its workers still starting (0.05), its units
#: (0.3), its report (0.6 and later: Fig. 11 and its animation drawn by a second process)
_KILLS = [(signal.SIGKILL, 0.05), (signal.SIGKILL, 0.8), (signal.SIGTERM, 0.3),
          (signal.SIGTERM, 0.85), (signal.SIGINT, 0.6), (signal.SIGINT, 0.9)]


@pytest.mark.parametrize("kill", _KILLS, ids=lambda k: f"{k[0].name}@{k[1]}" if isinstance(
    k, tuple) else str(k))
@settings(max_examples=1, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(jitter=st.floats(-0.05, 0.05))
def test_a_run_killed_at_any_moment_leaves_nothing_behind_and_resumes(reference, tmp_path,
                                                                      kill, jitter):
    whole, duration = reference
    sig, moment = kill
    mark = uuid.uuid4().hex
    out = tmp_path / f"out_{mark[:8]}"
    command = [BAYESPROG, "run", str(_tiny(tmp_path)), "--out", str(out), "--workers", "2", "-q"]
    # a supervisor that reads the run's output to its end, as subprocess.run(capture_output)
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               env=_env(mark), start_new_session=True)
    time.sleep(max(0.02, (moment + jitter) * duration))
    if sig == signal.SIGINT:
        os.killpg(process.pid, sig)  # Ctrl-C reaches the whole process group
    else:
        process.send_signal(sig)
    _, err = process.communicate(timeout=5)  # the output ends within 5 s of the kill
    err_text = err.decode()
    time.sleep(0.3)
    assert _marked(mark) == [], err_text
    assert "Traceback" not in err_text, err_text
    if sig != signal.SIGKILL:
        assert "leaked" not in err_text, err_text
    report = out / "report"
    if report.is_dir():
        videos = [p for p in report.iterdir() if p.suffix == ".mp4" and not p.name.startswith(".")]
        for video in videos:  # whole or not there: a whole MP4 ends with its index
            data = video.read_bytes()
            assert b"moov" in data and video.stat().st_size > 1000
    # the resume finishes the work, sweeps what killed writes left, and gives the same numbers
    resumed = subprocess.run(command, capture_output=True, text=True, timeout=300, env=_env(mark))
    assert resumed.returncode == 0, resumed.stderr
    for folder in (out / "chunks", out / "report"):
        assert not [p.name for p in folder.iterdir() if ".tmp" in p.name]
    ours = json.loads((out / "report" / "statistics.json").read_text())
    assert ours == json.loads((whole / "report" / "statistics.json").read_text())


@pytest.mark.parametrize("after", [0.0, 0.4])
def test_a_worker_still_starting_dies_with_its_parent(tmp_path, after):
    """The parent killed the moment its first worker exists (before that worker runs any code
    of the project), or while the worker imports its modules: the worker ends too."""
    mark = uuid.uuid4().hex
    process = subprocess.Popen([BAYESPROG, "run", str(_tiny(tmp_path)), "--out",
                                str(tmp_path / "out"), "--workers", "2", "-q"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_env(mark))
    parent = psutil.Process(process.pid)
    children: list[psutil.Process] = []
    deadline = time.monotonic() + 60
    while not children and time.monotonic() < deadline:
        children = [c for c in parent.children() if "resource_tracker" not in
                    " ".join(c.cmdline())]
        time.sleep(0.005)
    assert children, "no worker was started"
    imported = " ".join(children[0].cmdline())
    time.sleep(after)
    process.send_signal(signal.SIGKILL)
    _, err = process.communicate(timeout=5)
    # ended by the kernel with its parent, not a second later when it would have looked
    gone, alive = psutil.wait_procs(children, timeout=1)
    running = [p for p in alive if _status(p) != psutil.STATUS_ZOMBIE]  # dead, not yet reaped
    assert not running and _marked(mark) == [], imported
    assert "Traceback" not in err.decode()


def test_a_folder_named_like_the_package_where_the_run_starts_does_not_hide_it(tmp_path):
    """Workers start with ``python -c``, which would put the current folder first on their
    path: a ``runner/`` folder there (a checkout's, say) must not replace the installed one."""
    decoy = tmp_path / "runner"
    decoy.mkdir()
    (decoy / "__init__.py").write_text("raise ImportError('the decoy was imported')\n")
    done = subprocess.run([BAYESPROG, "run", str(_tiny(tmp_path)), "--out", str(tmp_path / "out"),
                           "--workers", "2", "-q", "--no-report"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "decoy" not in done.stderr and (tmp_path / "out" / "chunks").is_dir()


STOPPED_IN_A_CALLBACK = """
import ctypes, os, signal, time
from runner.experiments.executors import _exit_quietly

signal.signal(signal.SIGTERM, _exit_quietly)
# a Python function called back from C, as llvmlite's object cache is while numba compiles
namespace = {}
exec(compile("def notify():\\n    os.kill(os.getpid(), signal.SIGTERM)\\n"
             "    for _ in range(200):\\n        time.sleep(0.01)\\n",
             "/site-packages/llvmlite/binding/executionengine.py", "exec"),
     {"os": os, "signal": signal, "time": time}, namespace)
callback = ctypes.CFUNCTYPE(None)(namespace["notify"])
callback()
print("still running", flush=True)
"""


def test_a_worker_stopped_inside_a_callback_from_compiled_code_leaves_without_a_traceback():
    done = subprocess.run([sys.executable, "-c", STOPPED_IN_A_CALLBACK], capture_output=True,
                          text=True, timeout=60, cwd=Path(__file__).parents[2])
    assert done.returncode == 128 + signal.SIGTERM, (done.returncode, done.stderr)
    assert "Traceback" not in done.stderr and "still running" not in done.stdout, done.stderr
