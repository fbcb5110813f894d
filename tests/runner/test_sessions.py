"""Who drives the explorer and which step a probe answers (over ``explore --stdio``, which the
ROS 2 node serves the same lines as), readings checked against what pi_per declares, a
misspelt key named, and one writer per results folder."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from runner.attention.explorer import Explorer
from runner.robot.session import Session
from runner.world.scenario import load_scenario

ROOT = Path(__file__).parents[2]
PAPER = ROOT / "models" / "scenarios" / "paper.yaml"
BAYESPROG = str(Path(sys.executable).with_name("bayesprog"))


def _text(lines: list[dict | str]) -> str:
    return "".join((line if isinstance(line, str) else json.dumps(line)) + "\n"
                   for line in lines)


_SCENARIO: list = []


def stdio(lines: list[dict | str]) -> list[dict]:
    """The replies to ``lines`` of the stdio interface, in this process (what ``explore
    paper.yaml --stdio --task T2`` serves; one test runs the command itself)."""
    import io

    from runner.robot.stdio import serve

    if not _SCENARIO:
        _SCENARIO.append(load_scenario(PAPER))
    out = io.StringIO()
    serve(Explorer(_SCENARIO[0], "T2"), io.StringIO(_text(lines)), out)
    return [json.loads(line) for line in out.getvalue().splitlines()]


@pytest.fixture(scope="module")
def paper():
    return load_scenario(PAPER)


def test_the_command_serves_the_same_lines():
    lines = [{"reset": {"task": "T2", "seed": 1, "session": "arm"}},
             {"cell": [5, 7], "texture": 1.3, "compliance": 0.08, "session": "arm", "k": 0},
             {"cell": [6, 7], "texture": 0.5, "compliace": 0.1, "session": "arm"},
             {"cell": [6, 7], "texture": 0.5, "compliance": 0.1}]
    done = subprocess.run([BAYESPROG, "explore", str(PAPER), "--stdio", "--task", "T2"],
                          input=_text(lines), capture_output=True, text=True, cwd=ROOT,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert [json.loads(line) for line in done.stdout.splitlines()] == stdio(lines)


def probe(cell, texture=0.52, compliance=0.08, **extra) -> dict:
    return {"cell": cell, "texture": texture, "compliance": compliance, **extra}


def test_a_claimed_explorer_refuses_a_strangers_probe_and_changes_nothing(paper):
    claim = {"reset": {"task": "T2", "seed": 1, "session": "arm"}}
    held = stdio([claim, probe([5, 7], session="arm"), probe([3, 4], 1.3, 0.1),
                  {"maps": True}, probe([6, 7], session="arm")])
    alone = stdio([{"reset": {"task": "T2", "seed": 1}}, probe([5, 7]), probe([6, 7])])
    assert held[0]["session"] == "arm" and held[0]["reset"] is True
    for refused in held[2:4]:
        assert 'held by session "arm"' in refused["error"] and set(refused) == {"error"}
    # the stranger's lines changed nothing: the holder's steps are those of a session alone
    for mine, reference in zip([held[1], held[4]], alone[1:], strict=True):
        assert mine["k"] == reference["k"] and mine["next"] == reference["next"]
        assert mine["session"] == "arm" and "session" not in reference
        assert mine["chosen"] == reference["chosen"]


def test_another_session_takes_the_explorer_over_and_says_so():
    replies = stdio([{"reset": {"session": "arm"}}, probe([5, 7], session="arm"),
                     {"reset": {"session": 2}}, probe([9, 9], session="arm"),
                     probe([9, 9], session=2), {"reset": {}}])
    assert replies[2]["session"] == 2 and replies[2]["taken_over_from"] == "arm"
    assert "held by session 2" in replies[3]["error"]
    assert replies[4]["k"] == 0 and replies[4]["session"] == 2  # a new exploration
    assert "must name a session" in replies[5]["error"]


def test_every_reset_describes_the_workspace(paper):
    for reset in ({"reset": {}}, {"reset": {"session": "x", "task": "T1"}}):
        reply = stdio([reset])[0]
        assert reply["workspace"] == {"cell_m": paper.cell, "size": list(paper.shape),
                                      "frame": "workspace"}


def test_without_a_claim_lines_need_no_session_and_a_session_no_one_claimed_is_refused():
    replies = stdio([probe([5, 7]), probe([6, 7], session="ghost")])
    assert replies[0]["k"] == 0 and "session" not in replies[0]
    assert "no session" in replies[1]["error"] and "ghost" in replies[1]["error"]


def test_a_stale_step_is_refused_and_changes_nothing():
    replies = stdio([probe([5, 7], k=0), probe([6, 7], k=0), probe([6, 7], k=5),
                     probe([6, 7], k=1)])
    assert replies[0]["k"] == 0 and replies[3]["k"] == 1
    for stale in replies[1:3]:
        assert "stale probe" in stale["error"] and "waits for step 1" in stale["error"]
    reference = stdio([probe([5, 7]), probe([6, 7])])
    assert replies[3]["next"] == reference[1]["next"]
    assert replies[3]["chosen"] == reference[1]["chosen"]


def test_a_probe_away_from_the_target_is_answered_and_flagged():
    first = stdio([probe([5, 7])])[0]
    target = first["next"]
    missed = [target[0] + 2, target[1]]
    replies = stdio([probe([5, 7]), probe(missed)])
    assert replies[1]["k"] == 1 and "not the cell asked for" in replies[1]["warning"]
    assert str(target) in replies[1]["warning"]
    on_target = stdio([probe([5, 7]), probe(target)])
    assert "warning" not in on_target[1]


def test_a_description_is_not_a_range_but_a_reading_far_from_every_material_is_warned(paper):
    # pi_per describes texture as "(0 smooth .. 1 rough)": a text, not a range
    replies = stdio([probe([5, 7], texture=1.05, compliance=0.1), probe([6, 7], 0.5, -0.05)])
    assert "warning" not in replies[0] and "warning" not in replies[1]
    far = stdio([probe([5, 7], texture=9.0)])[0]["warning"]
    assert "texture 9 is 101 standard deviations" in far and "outside [" not in far
    assert "k" in stdio([probe([5, 7], texture=9.0)])[0]  # decided on all the same


def test_a_reading_outside_a_bounded_support_is_taken_as_missing_with_a_warning(tmp_path):
    text = (ROOT / "models" / "pi_per.yaml").read_text().replace(
        'E: {continuous: [-.inf, .inf]', 'E: {continuous: [-1, 2]')
    (tmp_path / "pi_per.yaml").write_text(text)
    scenario = (ROOT / "models" / "scenarios" / "paper.yaml").read_text()
    for name in ("pi_per", "pi_obj", "pi_tar"):
        scenario = scenario.replace(f"../{name}.yaml", str(tmp_path / f"{name}.yaml")
                                    if name == "pi_per" else str(ROOT / "models" / f"{name}.yaml"))
    (tmp_path / "paper.yaml").write_text(scenario)
    session = Session(Explorer(load_scenario(tmp_path / "paper.yaml"), "T2"))
    reply = session.answer(json.dumps(probe([5, 7], texture=2.5)))
    assert reply["missing"] == ["texture"] and reply["k"] == 0
    assert ("texture 2.5 is outside [-1, 2], the support the perception program declares for "
            "it (E): taken as missing") in reply["warning"]
    second = session.answer(json.dumps(probe(reply["next"], texture=1.0)))
    assert "warning" not in second and "missing" not in second
    alone = session.answer(json.dumps({"cell": second["next"], "texture": 7.0}))
    assert alone["error"].startswith("line 3: nothing to perceive: texture 7 is outside")


@pytest.mark.parametrize("line, expected", [
    (probe([5, 7], compliace=0.1) | {"compliance": 0.1},
     "unknown key(s) 'compliace' (did you mean 'compliance'?)"),
    ({"cell": [5, 7], "texture": 0.5, "compliace": 0.1},
     "unknown key(s) 'compliace' (did you mean 'compliance'?) (missing compliance)"),
    ({"cell": [5, 7], "textur": 0.5, "compliance": 0.1},
     "unknown key(s) 'textur' (did you mean 'texture'?) (missing texture)"),
    ({"reset": {"sesion": "a"}}, "(did you mean 'session'?)"),
])
def test_a_misspelt_key_is_named_with_the_nearest_known_one(line, expected):
    reply = stdio([line])[0]
    assert expected in reply["error"]


def test_a_session_in_process_numbers_its_lines_like_stdio(paper):
    session = Session(Explorer(paper, "T2"), frame="table")
    reply = session.answer(json.dumps({"reset": {"session": "s"}}))
    assert reply["workspace"]["frame"] == "table"
    assert session.answer(json.dumps(probe([5, 7]))) == {
        "error": 'line 2: the explorer is held by session "s": send its lines with "session": '
                 '"s", or take it over with a reset that names another session (this line '
                 "named none; nothing changed)"}


# --- one writer per results folder -------------------------------------------------------------


def test_two_runs_on_one_folder_one_refused_in_one_line_nothing_mixed(tmp_path):
    out = tmp_path / "out"
    command = [BAYESPROG, "run", "quick", "--out", str(out), "-q", "--no-animation"]
    first = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not (out / ".lock").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    second = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=300)
    report = subprocess.run([BAYESPROG, "report", str(out), "--no-animation"], cwd=ROOT,
                            capture_output=True, text=True, timeout=300)
    _, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    for refused in (second, report):
        if refused.returncode == 0:  # the first had already finished: it ran after it
            continue
        assert refused.returncode == 2 and "Traceback" not in refused.stderr
        assert refused.stderr.count("\n") == 1 and "is in use by bayesprog run (pid " in \
            refused.stderr
    # released: the folder is whole and resumes (its report was drawn by the first)
    again = subprocess.run([*command, "--no-report"], cwd=ROOT, capture_output=True, text=True,
                           timeout=300)
    assert again.returncode == 0, again.stderr
    assert not list(out.rglob("*.tmp*"))


def test_the_same_process_may_hold_a_folder_twice_and_another_may_not(tmp_path):
    from runner.experiments.store import StoreError, hold

    code = ("import sys, time; from runner.experiments.store import hold\n"
            f"with hold({str(tmp_path)!r}, 'run'):\n"
            "    print('held', flush=True); time.sleep(30)\n")
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(StoreError, match=r"is in use by bayesprog run \(pid \d+\)"):
            with hold(tmp_path, "report"):
                pass
    finally:
        holder.kill()
        holder.communicate()
    with hold(tmp_path, "run"), hold(tmp_path, "report"):  # the kernel released the dead one's
        assert (tmp_path / ".lock").read_text().startswith("bayesprog run (pid ")
