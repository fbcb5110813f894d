"""The explorer's secret (``--secret FILE``): a line is answered only when it carries it, any
other changes nothing and is refused with ``"refused": "secret"``, and no reply ever holds it;
the file is written for the driver only; the recorder takes the same lines the same way.
Over the session (what stdio and the ROS 2 node serve alike) and the commands; the same over
DDS with an intruder is in test_ros_security.py."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from bayesprog import BayesprogError
from runner.attention.explorer import Explorer
from runner.robot.recording import Recorder
from runner.robot.secret import driver_secret, explorer_secret
from runner.robot.session import Session
from runner.world.scenario import load_scenario

ROOT = Path(__file__).parents[2]
PAPER = ROOT / "models" / "scenarios" / "paper.yaml"
BAYESPROG = str(Path(sys.executable).with_name("bayesprog"))
SECRET = "s3cr3t-word-of-the-lab-0123456789"


@pytest.fixture(scope="module")
def paper():
    return load_scenario(PAPER)


def probe(cell, texture=0.52, compliance=0.08, **extra) -> dict:
    return {"cell": cell, "texture": texture, "compliance": compliance, **extra}


def answers(paper, lines: list[dict | str], secret: str | None = SECRET) -> list[dict]:
    session = Session(Explorer(paper, "T2"), secret=secret)
    replies = [session.answer(line if isinstance(line, str) else json.dumps(line))
               for line in lines]
    return [r for r in replies if r is not None]


def signed(line: dict) -> dict:
    return {**line, "secret": SECRET}


def test_only_lines_with_the_secret_are_answered_and_the_others_change_nothing(paper):
    claim = {"reset": {"task": "T2", "seed": 1, "session": "arm-1"}}
    # the holder's lines, with a stranger's between them: the holder's session name, the step
    # it waits for and the cell it was sent to, as any listener to replies reads them
    mine = [signed(claim), signed(probe([5, 7], session="arm-1", k=0))]
    strangers = [probe([6, 7], session="arm-1", k=1),                    # no secret
                 {**probe([6, 7], session="arm-1", k=1), "secret": "a guess of 16 chars"},
                 {**probe([6, 7], session="arm-1", k=1), "secret": 12345678901234567},
                 {"reset": {"session": "intruder"}},                     # a take-over
                 {"maps": True, "session": "arm-1"}, "not json", "[1, 2]"]
    held = answers(paper, [*mine, *strangers, signed(probe([6, 7], session="arm-1", k=1))])
    alone = answers(paper, [{"reset": {"task": "T2", "seed": 1}}, probe([5, 7]), probe([6, 7])],
                    secret=None)
    assert held[0]["reset"] is True and held[0]["session"] == "arm-1"
    for refused in held[2:-1]:
        assert set(refused) == {"error", "refused"} and refused["refused"] == "secret"
    assert 'carries no "secret"' in held[2]["error"] and "nothing changed" in held[2]["error"]
    assert "not this explorer's" in held[3]["error"] and "not this explorer's" in held[4]["error"]
    # the holder's steps are those of a session alone, as if no stranger had spoken
    for got, reference in zip([held[1], held[-1]], alone[1:], strict=True):
        assert got["k"] == reference["k"] and got["next"] == reference["next"]
        assert got["chosen"] == reference["chosen"] and got["session"] == "arm-1"


def test_no_reply_holds_the_secret_even_when_a_line_is_wrong(paper):
    lines = [signed({"reset": {"sesion": "arm"}}),                  # a misspelt key
             signed({"reset": {"session": "arm"}, "extra": 1}),
             signed(probe([5, 7], compliace=0.1)),                  # an unknown key
             signed({"maps": "yes"}), signed({"maps": True}),
             signed(probe([99, 7])), signed(probe([5, 7], k=3)),
             signed({"reset": {"session": "arm"}}), signed(probe([5, 7], session="arm")),
             signed({"maps": True, "session": "arm"})]
    replies = answers(paper, lines)
    assert len(replies) == len(lines) and any("error" in r for r in replies)
    assert replies[-2]["k"] == 0 and "maps" in replies[-1]
    assert all("refused" not in r for r in replies)  # these carried the secret
    assert not [r for r in replies if SECRET in json.dumps(r)]
    # nor a reply of an explorer that has none, to a line that carries one
    refused = answers(paper, [signed(probe([5, 7]))], secret=None)[0]
    assert set(refused) == {"error"} and "started without one" in refused["error"]
    assert SECRET not in json.dumps(refused)


def test_without_a_secret_the_replies_are_as_they_always_were(paper):
    lines = [{"reset": {"session": "arm"}}, probe([5, 7], session="arm"), "not json",
             probe([6, 7], session="other")]
    replies = answers(paper, lines, secret=None)
    assert replies[2] == {"error": "line 3: Expecting value: line 1 column 1 (char 0)"}
    assert set(replies[3]) == {"error"} and 'held by session "arm"' in replies[3]["error"]


def test_the_recorder_records_only_the_presses_with_the_secret(paper, tmp_path):
    recorder = Recorder(paper, tmp_path / "presses.csv", secret=SECRET)
    try:
        replies = [recorder.answer(json.dumps(line)) for line in (
            {"material": "wood", "texture": 0.5, "compliance": 0.1},
            signed({"material": "wood", "texture": 0.5, "compliance": 0.1}))]
    finally:
        recorder.close()
    assert replies[0]["refused"] == "secret" and "nothing recorded" in replies[0]["error"]
    assert replies[1] == {"recorded": 1, "material": "wood"}
    rows = (tmp_path / "presses.csv").read_text().splitlines()
    assert len(rows) == 2 and rows[1].startswith("wood,")


def test_the_explorer_writes_a_secret_only_its_owner_reads_and_the_driver_reads_it(tmp_path):
    where = tmp_path / "explorer.secret"
    made = explorer_secret(where)
    assert stat.S_IMODE(where.stat().st_mode) == 0o600
    assert len(made) >= 32 and explorer_secret(where) == made == driver_secret(where)
    assert explorer_secret(tmp_path / "other.secret") != made  # drawn anew each time


@pytest.mark.parametrize("content, mode, expected", [
    (SECRET, 0o644, "may be read or written by others (mode 0644)"),
    (SECRET, 0o660, "chmod 600"),
    ("short", 0o600, "at least 16 printable characters, found 5"),
    ("two words of a secret", 0o600, "with spaces"),
])
def test_a_secret_file_that_will_not_do_is_refused(tmp_path, content, mode, expected):
    where = tmp_path / "secret"
    where.write_text(content + "\n")
    os.chmod(where, mode)
    with pytest.raises(BayesprogError, match="--secret") as raised:
        driver_secret(where)
    assert expected in str(raised.value) and content not in str(raised.value)


def test_a_driver_without_the_file_is_told_to_start_the_explorer_first(tmp_path):
    with pytest.raises(BayesprogError, match="start the explorer with --secret"):
        driver_secret(tmp_path / "none")


def test_explore_stdio_with_a_secret_writes_it_and_answers_only_lines_with_it(tmp_path):
    where = tmp_path / "lab.secret"
    run = subprocess.run([BAYESPROG, "explore", str(PAPER), "--stdio", "--task", "T2",
                          "--secret", str(where)], input=json.dumps(probe([5, 7])) + "\n",
                         capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert run.returncode == 0, run.stderr
    assert f"wrote a new secret to {where}" in run.stderr
    secret = where.read_text().strip()
    assert json.loads(run.stdout)["refused"] == "secret"
    again = subprocess.run([BAYESPROG, "explore", str(PAPER), "--stdio", "--task", "T2",
                            "--secret", str(where)],
                           input=json.dumps({**probe([5, 7]), "secret": secret}) + "\n",
                           capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert again.returncode == 0 and "wrote" not in again.stderr
    assert json.loads(again.stdout)["k"] == 0 and secret not in again.stdout


@pytest.mark.parametrize("command, expected", [
    (["robot", str(PAPER), "--physics", "--secret", "x"], "--secret: a ROS 2 node's option"),
    (["explore", str(PAPER), "--stdio", "--secure", "ks"], "--secure: a ROS 2 node's option"),
    (["record", str(PAPER), "-o", "x.csv", "--secret", "x"], "expected --stdio or --ros"),
])
def test_security_options_out_of_place_are_user_errors(command, expected, tmp_path):
    run = subprocess.run([BAYESPROG, *command], capture_output=True, text=True, cwd=tmp_path,
                         timeout=120)
    assert run.returncode == 2 and expected in run.stderr
    assert "Traceback" not in run.stderr and len(run.stderr.strip().splitlines()) == 1


def test_a_readable_secret_file_is_a_user_error_of_the_command(tmp_path):
    where = tmp_path / "open.secret"
    where.write_text(SECRET)
    os.chmod(where, 0o644)
    run = subprocess.run([BAYESPROG, "explore", str(PAPER), "--stdio", "--secret", str(where)],
                         input="", capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert run.returncode == 2 and "chmod 600" in run.stderr and "Traceback" not in run.stderr
    assert SECRET not in run.stderr
