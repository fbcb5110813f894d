"""What a modeller coming from pgmpy or pyAgrum meets on the command line and in the Python
answers: options that name their fix, numbers as state names, keys that name their variable,
a quiet closed pipe, answers over time that say what they are, one type per state, tables
printed and read back, learned values written to the digits their data support.

Numbers are checked against pgmpy, scipy.stats or enumeration written here.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

import bayesprog
from bayesprog.cli import build_parser, main

ROOT = Path(__file__).parents[1]
UMBRELLA = ROOT / "models" / "examples" / "umbrella.yaml"
BAYESPROG = str(Path(sys.executable).with_name("bayesprog"))

MONTY = """\
bayesprog: 1
variables:
  Choice: {states: [1, 2, 3]}
  Prize: {states: [1, 2, 3]}
  Opened: {states: [1, 2, 3]}
decomposition:
  - {term: P(Choice), form: uniform}
  - {term: P(Prize), form: table, table: {1: 0.5, 2: 0.3, 3: 0.2}}
  - term: P(Opened | Choice, Prize)
    form: table
    table:
      Choice=1: {Prize=1: [0, 0.5, 0.5], Prize=2: [0, 0, 1], Prize=3: [0, 1, 0]}
      Choice=2: {Prize=1: [0, 0, 1], Prize=2: [0.5, 0, 0.5], Prize=3: [1, 0, 0]}
      Choice=3: {Prize=1: [0, 1, 0], Prize=2: [1, 0, 0], Prize=3: {Opened=1: 0.4, Opened=2: 0.6, Opened=3: 0}}
"""
# the host's table as nested lists: Choice, then Prize, then Opened
HOST = [[[0, 0.5, 0.5], [0, 0, 1], [0, 1, 0]],
        [[0, 0, 1], [0.5, 0, 0.5], [1, 0, 0]],
        [[0, 1, 0], [1, 0, 0], [0.4, 0.6, 0]]]


def run(capsys, *args) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return code, out, err


# 1. a malformed or misplaced option names the fix --------------------------------------------

def test_a_comma_list_of_evidence_without_a_question_over_steps_names_over_time(capsys):
    code, out, err = run(capsys, "query", UMBRELLA, "P(Rain | Umbrella)",
                         "--evidence", "Umbrella=yes,no,yes")
    assert code == 2 and not out
    assert "--over-time filter|smooth|sequence" in err and "Umbrella=yes,no,yes" in err
    # with the option added, the same evidence is three steps
    code, out, _ = run(capsys, "query", UMBRELLA, "P(Rain | Umbrella)", "--evidence",
                       "Umbrella=yes,no,yes", "--over-time", "filter", "--json")
    assert code == 0 and len(json.loads(out)["probabilities"]) == 3


def test_a_comma_list_on_a_program_without_time_says_what_commas_mean(capsys, tmp_path):
    path = tmp_path / "monty.yaml"
    path.write_text(MONTY)
    code, _, err = run(capsys, "query", path, "P(Prize | Opened)", "--evidence", "Opened=1,2")
    assert code == 2
    assert "expected one value" in err and "time:" in err and "Opened=FILE.npy" in err


def test_a_state_whose_name_has_a_comma_is_still_evidence(capsys, tmp_path):
    path = tmp_path / "comma.yaml"
    path.write_text('bayesprog: 1\nvariables:\n  A: {states: ["x,y", z]}\n  B: {states: [b0, b1]}\n'
                    "decomposition:\n  - {term: P(A), form: uniform}\n"
                    '  - {term: P(B | A), form: table, table: {"x,y": [0.9, 0.1], z: [0.2, 0.8]}}\n')
    code, out, _ = run(capsys, "query", path, "P(B | A)", "--evidence", "A=x,y", "--json")
    assert code == 0 and json.loads(out)["probabilities"] == [0.9, 0.1]


@pytest.mark.parametrize("option, first, second", [
    ("--evidence", "Umbrella=yes", "Umbrella=no"),
    ("--soft", "Rain=1,2", "Rain=2,1"),
])
def test_the_same_variable_twice_is_an_error_naming_it(capsys, option, first, second):
    code, out, err = run(capsys, "query", UMBRELLA, "P(Rain | Umbrella)", option, first,
                         option, second)
    assert code == 2 and not out
    name = first.split("=")[0]
    assert f"{option} {name} is given twice" in err and first in err and second in err


def test_map_and_over_time_together_are_refused(capsys):
    code, _, err = run(capsys, "query", UMBRELLA, "P(Rain | Umbrella)", "--evidence",
                       "Umbrella=yes,no", "--over-time", "sequence", "--map")
    assert code == 2 and "--map and --over-time" in err


def _options(parser: argparse.ArgumentParser) -> set[str]:
    """A command's options, and those of its own sub-commands (``examples copy``)."""
    out = set()
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        if isinstance(action, argparse._SubParsersAction):
            for inner in action.choices.values():
                out |= _options(inner)
        out.update(action.option_strings)
    return out


def test_the_command_line_summary_lists_every_option_of_every_command():
    text = (ROOT / "docs" / "language.md").read_text()
    section = text[text.index("## Command-line summary"):]
    section = section[:section.index("\n## ")] if "\n## " in section else section
    rows = {m.group(1): m.group(0) for m in re.finditer(r"^\| `bayesprog (\w+)[^|]*\|.*$",
                                                        section, re.M)}
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert set(rows) == set(sub.choices), set(rows) ^ set(sub.choices)
    for name, parser in sub.choices.items():
        documented = set(re.findall(r"`(-{1,2}[a-z][a-z-]*)", rows[name]))
        documented |= set(re.findall(r"/`(-{1,2}[a-z][a-z-]*)", rows[name]))
        documented |= set(re.findall(r"\(or `(-{1,2}[a-z][a-z-]*)`\)", rows[name]))
        assert documented == _options(parser), (name, documented ^ _options(parser))


# 2. numbers where a name stands are names ------------------------------------------------------

def test_numbers_as_state_names_and_keys_answer_as_quoted_names_and_as_pgmpy():
    from pgmpy.factors.discrete import TabularCPD
    from pgmpy.inference import VariableElimination
    from pgmpy.models import DiscreteBayesianNetwork

    numbers = bayesprog.loads(MONTY)
    quoted = bayesprog.loads(MONTY.replace("[1, 2, 3]", '["1", "2", "3"]')
                             .replace("{1: 0.5, 2: 0.3, 3: 0.2}", '{"1": 0.5, "2": 0.3, "3": 0.2}'))
    nested = bayesprog.loads(MONTY.split("    table:\n      Choice=1")[0]
                             + f"    table: {json.dumps(HOST)}\n")
    assert numbers.variables["Prize"].states == ("1", "2", "3")
    net = DiscreteBayesianNetwork([("Choice", "Opened"), ("Prize", "Opened")])
    names = {"Choice": ["1", "2", "3"], "Prize": ["1", "2", "3"], "Opened": ["1", "2", "3"]}
    net.add_cpds(
        TabularCPD("Choice", 3, [[1 / 3]] * 3, state_names=names),
        TabularCPD("Prize", 3, [[0.5], [0.3], [0.2]], state_names=names),
        TabularCPD("Opened", 3, np.transpose(HOST, (2, 0, 1)).reshape(3, 9),
                   evidence=["Choice", "Prize"], evidence_card=[3, 3], state_names=names))
    engine = VariableElimination(net)
    for choice, opened in itertools.permutations("123", 2):
        expected = engine.query(["Prize"], evidence={"Choice": choice, "Opened": opened},
                                show_progress=False).values
        for program in (numbers, quoted, nested):
            answer = program.ask("P(Prize | Choice, Opened)", {"Choice": choice, "Opened": opened})
            np.testing.assert_allclose(answer.probabilities, expected, atol=1e-12)
        # an integer is the state of that name, not an index
        by_int = numbers.ask("P(Prize | Choice, Opened)", {"Choice": int(choice),
                                                           "Opened": int(opened)})
        np.testing.assert_allclose(by_int.probabilities, expected, atol=1e-12)


def test_floats_as_state_names_keep_their_text(tmp_path):
    program = bayesprog.loads("bayesprog: 1\nvariables:\n  G: {states: [0.5, 1.5, 2.0]}\n"
                              "decomposition:\n  - {term: P(G), form: table, "
                              "table: {0.5: 0.2, 1.5: 0.3, 2.0: 0.5}}\n")
    assert program.variables["G"].states == ("0.5", "1.5", "2.0")
    assert program.ask("P(G)").probabilities.tolist() == [0.2, 0.3, 0.5]


# 7. keys that name their variable --------------------------------------------------------------

@pytest.mark.parametrize("table, message", [
    ("{Choice=1: [0.2, 0.8], 2: [0.5, 0.5], Choice=3: [0.1, 0.9]}", "every key to name its variable"),
    ("{Chioce=1: [0.2, 0.8], Chioce=2: [0.5, 0.5], Chioce=3: [0.1, 0.9]}", "names 'Chioce'"),
    ("{Choice=1: [0.2, 0.8], Choice=2: [0.5, 0.5], Choice=4: [0.1, 0.9]}", "unknown state '4' of Choice"),
    ("{Choice=1: [0.2, 0.8], Choice=2: [0.5, 0.5]}", "misses state(s) 3"),
    ("{Choice=1: [0.2, 0.8], Prize=2: [0.5, 0.5], Choice=3: [0.1, 0.9]}", "name one variable"),
])
def test_keys_naming_their_variable_are_checked_at_their_line(tmp_path, table, message):
    path = tmp_path / "bad.yaml"
    path.write_text("bayesprog: 1\nvariables:\n  Choice: {states: [1, 2, 3]}\n"
                    "  Prize: {states: [1, 2, 3]}\n  W: {states: [w0, w1]}\n"
                    "decomposition:\n  - {term: P(Choice), form: uniform}\n"
                    "  - {term: P(Prize), form: uniform}\n"
                    f"  - term: P(W | Choice, Prize)\n    form: table\n    table: {table}\n")
    result = subprocess.run([BAYESPROG, "validate", str(path)], capture_output=True, text=True)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert f"{path}:11:" in result.stderr and message in result.stderr, result.stderr


def test_the_levels_of_named_keys_may_come_in_any_order():
    outer_prize = MONTY.split("    table:\n")[0] + "    table:\n" + "".join(
        f"      Prize={p}: {{" + ", ".join(
            f"Choice={c}: {json.dumps(HOST[c - 1][p - 1])}" for c in (1, 2, 3)) + "}\n"
        for p in (1, 2, 3))
    a = bayesprog.loads(MONTY).table("P(Opened | Choice, Prize)")
    b = bayesprog.loads(outer_prize).table("P(Opened | Choice, Prize)")
    pd.testing.assert_frame_equal(a, b)


# 3. a closed pipe ends quietly -----------------------------------------------------------------

BIG = "bayesprog: 1\nvariables:\n  X: {range: [0, 99999]}\ndecomposition:\n  - {term: P(X), form: uniform}\n"


@pytest.mark.parametrize("args", [
    ["query", "{big}", "P(X)", "--limit", "100000"],
    ["query", "{big}", "P(X)", "--json"],
    ["schema"],
    ["show", "{big}"],
    ["validate", "{big}"],
    ["--help"],
    ["run", "--help"],
])
def test_output_to_a_closed_pipe_ends_quietly(tmp_path, args):
    big = tmp_path / "big.yaml"
    big.write_text(BIG)
    argv = [BAYESPROG] + [a.replace("{big}", str(big)) for a in args]
    # the reader takes one byte and goes away
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.read(1)
    proc.stdout.close()
    with proc.stderr:
        err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) in (0, 141)
    assert "Traceback" not in err and "Error" not in err, err


def test_explore_over_stdio_ends_quietly_when_its_reader_goes_away():
    line = json.dumps({"cell": [3, 4], "texture": 0.5, "compliance": 0.5}) + "\n"
    proc = subprocess.Popen([BAYESPROG, "explore", str(ROOT / "models/scenarios/paper.yaml"),
                             "--stdio", "--task", "T1"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdin and proc.stdout and proc.stderr
    proc.stdin.write(line.encode())
    proc.stdin.flush()
    proc.stdout.readline()
    proc.stdout.close()
    try:
        for _ in range(2000):
            proc.stdin.write(line.encode())
        proc.stdin.close()
    except BrokenPipeError:
        try:
            proc.stdin.close()
        except BrokenPipeError:
            pass
    with proc.stderr:
        err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) in (0, 141)
    assert "Traceback" not in err, err


# 4. answers over time say what they are ------------------------------------------------------

def _umbrella_joint(observed: list[str]) -> dict[tuple[int, ...], float]:
    """P(rain_1..T, umbrella_1..T) of every weather sequence, by enumeration."""
    before, transition = np.array([0.5, 0.5]), np.array([[0.7, 0.3], [0.3, 0.7]])
    umbrella = np.array([[0.9, 0.1], [0.2, 0.8]])  # P(yes, no | rain), P(. | dry)
    y = [0 if o == "yes" else 1 for o in observed]
    out = {}
    for path in itertools.product((0, 1), repeat=len(y)):
        p = sum(before[b] * transition[b, path[0]] for b in (0, 1))
        for t in range(1, len(y)):
            p *= transition[path[t - 1], path[t]]
        out[path] = p * math.prod(umbrella[path[t], y[t]] for t in range(len(y)))
    return out


@pytest.mark.parametrize("observed", [["yes"], ["yes", "no", "yes"], ["no", "no", "yes", "yes"]])
def test_the_most_likely_sequence_says_sequence_and_gives_its_probability_and_ties(capsys,
                                                                                  observed):
    joint = _umbrella_joint(observed)
    best = max(joint, key=joint.__getitem__)
    expected = joint[best] / sum(joint.values())
    code, out, _ = run(capsys, "query", UMBRELLA, "most_likely", "--evidence",
                       "Umbrella=" + ",".join(observed), "--json")
    answer = json.loads(out)
    tied = sum(p >= joint[best] * (1 - 1e-12) for p in joint.values())
    assert code == 0 and answer["method"] == "sequence" and answer["ties"] == tied
    assert isinstance(answer["probability"], float)
    assert answer["probability"] == pytest.approx(expected, rel=1e-12)
    assert answer["map"]["Rain"] == [("rain", "dry")[s] for s in best]
    steps = len(observed)
    title = f"(the most likely sequence, {steps} step{'s' if steps > 1 else ''})"
    assert answer["question"].endswith(title)
    code, out, _ = run(capsys, "query", UMBRELLA, "most_likely", "--evidence",
                       "Umbrella=" + ",".join(observed))
    assert out.splitlines()[0].endswith(title)
    assert out.count("probability of the sequence") == 1 and " p = " not in out


def test_a_batch_of_sequences_has_one_probability_per_sequence():
    program = bayesprog.load(UMBRELLA)
    observed = [["yes", "no"], ["no", "no"], ["yes", "yes"]]  # time first, two sequences
    answer = program.ask("most_likely", {"Umbrella": observed})
    assert answer.kind == "sequence" and answer.steps == 3
    assert answer.probability.shape == (2,) and answer.assignment["Rain"].shape == (3, 2)
    for row in range(2):
        joint = _umbrella_joint([observed[t][row] for t in range(3)])
        assert answer.probability[row] == pytest.approx(max(joint.values()) / sum(joint.values()))
    assert answer.to_json()["probability"] == answer.probability.tolist()


@pytest.mark.parametrize("kind, word", [("filter", "filtered"), ("smooth", "smoothed")])
def test_titles_over_time_count_their_steps(kind, word):
    program = bayesprog.load(UMBRELLA)
    one = program.ask("P(Rain | Umbrella)", {"Umbrella": ["yes"]}, kind=kind)
    two = program.ask("P(Rain | Umbrella)", {"Umbrella": ["yes", "no"]}, kind=kind)
    assert one.question.endswith(f"({word}, 1 step)") and two.question.endswith(f"({word}, 2 steps)")
    assert one.to_json()["method"] == kind


# 5. one type per state; scalar in, scalar out ----------------------------------------------------

RANGE = """\
bayesprog: 1
variables:
  Count: {range: [2, 5]}
  Cell: {grid: {shape: [2, 2]}}
  Alarm: {states: ["off", "on"]}
decomposition:
  - {term: P(Count), form: table, table: [0.1, 0.2, 0.3, 0.4]}
  - {term: P(Cell), form: uniform}
  - {term: P(Alarm | Count), form: table, table: {2: [0.9, 0.1], 3: [0.6, 0.4], 4: [0.3, 0.7], 5: [0.1, 0.9]}}
"""


def test_a_ranges_states_are_integers_in_python_as_in_json_and_map():
    program = bayesprog.loads(RANGE)
    answer = program.ask("P(Count | Alarm)", {"Alarm": "on"})
    assert answer.states == {"Count": (2, 3, 4, 5)}
    assert all(type(s) is int for s in answer.states["Count"])
    assert answer.to_json()["states"]["Count"] == [2, 3, 4, 5]
    assert answer.names == {"Count": ("2", "3", "4", "5")}
    best = program.ask("P(Count | Alarm)", {"Alarm": "on"}, kind="map")
    assert best.assignment["Count"] == 5 and type(best.assignment["Count"]) is int
    assert best.states == answer.states
    cells = program.ask("P(Cell)")
    assert cells.states["Cell"] == ((0, 0), (0, 1), (1, 0), (1, 1))
    assert json.loads(json.dumps(cells.to_json()))["states"]["Cell"] == [[0, 0], [0, 1], [1, 0], [1, 1]]
    assert program.ask("P(Alarm)").states == {"Alarm": ("off", "on")}


GAUSS = """\
bayesprog: 1
variables:
  Pos: {continuous: [-.inf, .inf]}
  Obs: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(Pos), form: normal, mean: 1.0, sigma: 2.0}
  - {term: P(Obs | Pos), form: normal, mean: Pos, sigma: 1.0}
"""


def test_a_density_answers_a_number_for_a_number_and_arrays_for_arrays():
    program = bayesprog.loads(GAUSS)
    # Pos | Obs=3: precision 1/4 + 1 = 5/4, mean (1/4 * 1 + 3) / (5/4) = 2.6
    exact = stats.norm(2.6, math.sqrt(0.8))
    d = program.ask("P(Pos | Obs)", {"Obs": 3.0})
    for name, ours, theirs, at in (("pdf", d.pdf, exact.pdf, 2.0), ("cdf", d.cdf, exact.cdf, 2.0),
                                   ("quantile", d.quantile, exact.ppf, 0.3)):
        one = ours("Pos", at)
        assert np.ndim(one) == 0 and isinstance(one, np.floating), name
        assert float(one) == pytest.approx(theirs(at), rel=1e-9), name
        grid = np.array([[0.2, 0.4, 0.6], [0.1, 0.5, 0.9]])
        np.testing.assert_allclose(ours("Pos", grid), theirs(grid), rtol=1e-9)
        assert ours("Pos", [at]).shape == (1,)
    for summary in (d.mean("Pos"), d.sd("Pos"), d.map("Pos")):
        assert np.ndim(summary) == 0 and isinstance(summary, np.floating)
    batched = program.ask("P(Pos | Obs)", {"Obs": [3.0, -1.0]})
    assert batched.pdf("Pos", 2.0).shape == (2,)
    assert batched.cdf("Pos", [1.0, 2.0, 3.0]).shape == (2, 3)
    assert batched.quantile("Pos", 0.5).shape == (2,) and batched.mean("Pos").shape == (2,)
    np.testing.assert_allclose(batched.cdf("Pos", [1.0, 2.0]),
                               [stats.norm(2.6, math.sqrt(0.8)).cdf([1.0, 2.0]),
                                stats.norm(-0.6, math.sqrt(0.8)).cdf([1.0, 2.0])], rtol=1e-9)


# 6. tables printed, read back as DataFrames; learned values to the digits the data support ----

STUDENT = (ROOT / "models" / "examples" / "student.yaml").read_text()
G_TABLE = [[[0.3, 0.4, 0.3], [0.05, 0.25, 0.7]], [[0.9, 0.08, 0.02], [0.5, 0.3, 0.2]]]


def test_show_prints_a_table_of_parent_states_by_child_states(capsys, tmp_path):
    path = tmp_path / "student.yaml"
    path.write_text(STUDENT)
    code, out, _ = run(capsys, "show", path)
    assert code == 0 and "shape [2, 2, 3]" not in out
    lines = out.splitlines()
    head = next(i for i, line in enumerate(lines) if re.match(r"\s+I\s+D\s+\|\s+A\s+B\s+C$", line))
    for k, (i, d) in enumerate(itertools.product(("low", "high"), ("easy", "hard"))):
        cells = lines[head + 1 + k].split()
        assert cells[:2] == [i, d] and cells[2] == "|"
        assert [float(x) for x in cells[3:]] == G_TABLE[k // 2][k % 2]


def test_show_elides_what_does_not_fit_and_says_so(capsys, tmp_path):
    table = np.full((30, 40, 15), 1 / 15).tolist()
    path = tmp_path / "wide.yaml"
    path.write_text("bayesprog: 1\nvariables:\n  A: {range: [0, 29]}\n  B: {range: [0, 39]}\n"
                    "  C: {range: [0, 14]}\ndecomposition:\n  - {term: P(A), form: uniform}\n"
                    "  - {term: P(B), form: table, table: " + json.dumps([1 / 40] * 40) + "}\n"
                    f"  - term: P(C | A, B)\n    form: table\n    table: {json.dumps(table)}\n")
    code, out, _ = run(capsys, "show", path)
    rows = [line for line in out.splitlines() if re.match(r"\s+\d+\s+\d+\s+\|", line)]
    assert code == 0 and 0 < len(rows) <= 24
    header = next(line for line in out.splitlines() if re.match(r"\s+A\s+B\s+\|", line))
    shown = len(header.split("|")[1].split()) - 1  # the states of C, then "..."
    assert header.rstrip().endswith("...")
    assert f"{1200 - len(rows):,} more rows and {15 - shown} more columns" in out
    assert 'program.table("P(C | A, B)")' in out
    # a long table without parents: one state per line, elided alike
    listed = [line for line in out.splitlines() if re.match(r"\s+\d+\s+\|\s+0.025$", line)]
    assert 0 < len(listed) <= 24 and f"{40 - len(listed)} more rows" in out
    assert 'program.table("P(B)")' in out


def test_show_lays_out_a_wide_table_of_one_parent_in_full(capsys, tmp_path):
    rows = {f"a{i}": list(np.round(np.arange(1, 13) / 78, 6)) for i in range(3)}
    for row in rows.values():
        row[-1] = round(1 - sum(row[:-1]), 6)
    path = tmp_path / "one.yaml"
    path.write_text("bayesprog: 1\nvariables:\n  A: {states: [a0, a1, a2]}\n  X: {range: [0, 11]}\n"
                    "decomposition:\n  - {term: P(A), form: uniform}\n"
                    f"  - {{term: P(X | A), form: table, table: {json.dumps(rows)}}}\n")
    code, out, _ = run(capsys, "show", path)
    assert code == 0 and "more columns" not in out
    lines = out.splitlines()
    head = next(i for i, line in enumerate(lines) if re.match(r"\s+A\s+\|\s+0\s+1\s", line))
    for k in range(3):
        cells = lines[head + 1 + k].split()
        assert cells[0] == f"a{k}" and [float(x) for x in cells[2:]] == rows[f"a{k}"]
        assert not lines[head + 1 + k].rstrip().endswith("...")


def test_program_table_is_a_dataframe_of_parent_states_by_child_states():
    program = bayesprog.loads(STUDENT)
    table = program.table("P(G | D, I)")  # parents in any order: the term's order is kept
    assert list(table.index.names) == ["I", "D"] and table.columns.tolist() == ["A", "B", "C"]
    assert table.columns.name == "G"
    for (i, d), row in table.iterrows():
        expected = G_TABLE[["low", "high"].index(i)][["easy", "hard"].index(d)]
        assert row.tolist() == expected  # as written, not through a logarithm
    prior = program.table("P(D)")
    assert prior.shape == (1, 2) and prior.iloc[0].tolist() == [0.6, 0.4]
    uniform = program.ablate("P(G | I, D)").table("P(G | I, D)")
    np.testing.assert_allclose(uniform.to_numpy(), 1 / 3)
    with pytest.raises(bayesprog.QuestionError, match="not a table"):
        bayesprog.loads(GAUSS).table("P(Obs | Pos)")
    with pytest.raises(bayesprog.QuestionError, match="no term"):
        program.table("P(G | I)")


@pytest.mark.parametrize("rows, digits", [(12, 3), (300, 4), (20_000, 5)])
def test_learn_writes_the_digits_its_rows_support_and_says_so(capsys, tmp_path, rows, digits):
    source = tmp_path / "student.yaml"
    source.write_text(STUDENT)
    data = bayesprog.loads(STUDENT).sample(rows, rng=rows)
    csv = tmp_path / "grades.csv"
    data.to_csv(csv, index=False)
    out = tmp_path / "fitted.yaml"
    code, said, _ = run(capsys, "learn", source, csv, "-o", out, "--rounded")
    assert code == 0 and f"the precision {rows} rows support ({digits} significant digits" in said
    fitted = bayesprog.load(out)
    assert fitted.learned[-1].digits == digits and f"digits: {digits}" in out.read_text()
    counts = pd.crosstab([data["I"], data["D"]], data["G"]).reindex(
        index=pd.MultiIndex.from_product([["low", "high"], ["easy", "hard"]], names=["I", "D"]),
        columns=["A", "B", "C"], fill_value=0)
    maximum_likelihood = counts.to_numpy() / counts.to_numpy().sum(axis=1, keepdims=True)
    written = fitted.table("P(G | I, D)").to_numpy()
    # each row sums to one as written, and rounding moved no value by more than a twentieth
    # of the standard error of an average of that many rows
    np.testing.assert_allclose(written.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    error = np.abs(written - maximum_likelihood) / np.maximum(maximum_likelihood, 1e-300)
    assert error[maximum_likelihood > 0].max() <= 2 * 0.5 * 10.0 ** (1 - digits)
    assert 0.5 * 10.0 ** (1 - digits) <= 1 / 20 / math.sqrt(rows)
    for line in out.read_text().split("learned:")[0].splitlines():
        if line.strip().startswith("table:"):
            for number in re.findall(r"\d\.\d+(?:e-?\d+)?", line):
                mantissa = number.split("e")[0].replace(".", "").lstrip("0")
                assert len(mantissa) <= digits + 2, number  # the largest entry takes the rest


FAR = """\
bayesprog: 1
variables:
  M: {states: [a, b]}
  T: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(M), form: table, table: [0.5, 0.5]}
  - {term: P(T | M), form: normal, mean: {a: 999, b: 1001}, sigma: 1}
"""


def test_a_learned_mean_far_from_zero_keeps_the_decimals_its_standard_error_needs(tmp_path):
    rng = np.random.default_rng(3)
    states = np.repeat(["a", "b"], 6)
    values = np.where(states == "a", 1000.121, 1000.164) + rng.normal(0, 0.01, 12)
    csv = tmp_path / "far.csv"
    pd.DataFrame({"M": states, "T": values}).to_csv(csv, index=False)
    (tmp_path / "far.yaml").write_text(FAR)
    assert main(["learn", str(tmp_path / "far.yaml"), str(csv), "-o", str(tmp_path / "l.yaml"),
                 "--rounded"]) == 0
    written = bayesprog.load(tmp_path / "l.yaml")
    for state in ("a", "b"):
        x = values[states == state]
        mean, sd = x.mean(), x.std()  # maximum likelihood, as scipy.stats.norm.fit
        assert stats.norm.fit(x) == pytest.approx((mean, sd))
        got = written.term("P(T | M)").params["mean"].array[("a", "b").index(state)]
        assert abs(got - mean) <= sd / math.sqrt(12) / 20  # a twentieth of its standard error
    # the written program answers as the fitted one, to what its sigmas' 3 digits (12 rows)
    # allow; with the means rounded to 3 significant digits (1000) it gave a: 1, b: 2e-11
    exact = bayesprog.load(tmp_path / "far.yaml").fit(csv).program
    for t in (1000.123, 1000.14, 1000.16):
        np.testing.assert_allclose(written.ask("P(M | T)", {"T": t}).probabilities,
                                   exact.ask("P(M | T)", {"T": t}).probabilities, atol=5e-3)


def test_a_continued_fit_writes_the_digits_of_all_its_rows(capsys, tmp_path):
    source = tmp_path / "student.yaml"
    source.write_text(STUDENT)
    first, second = tmp_path / "first.csv", tmp_path / "second.csv"
    bayesprog.loads(STUDENT).sample(20_000, rng=1).to_csv(first, index=False)
    bayesprog.loads(STUDENT).sample(2, rng=2).to_csv(second, index=False)
    run(capsys, "learn", source, first, "-o", tmp_path / "f1.yaml")
    code, said, _ = run(capsys, "learn", tmp_path / "f1.yaml", second, "-o", tmp_path / "f2.yaml",
                        "--rounded")
    record = bayesprog.load(tmp_path / "f2.yaml").learned[-1]
    assert code == 0 and record.rows_used == 2 and record.rows_supporting == 20_002
    assert record.digits == 5 and "the precision 20002 rows support" in said


def test_tables_and_batched_maps_keep_the_type_of_their_states():
    program = bayesprog.loads(RANGE)
    table = program.table("P(Alarm | Count)")
    assert table.index.tolist() == [2, 3, 4, 5] and table.loc[4].tolist() == [0.3, 0.7]
    assert program.table("P(Count)").columns.tolist() == [2, 3, 4, 5]
    assert program.table("P(Cell)").columns.tolist() == [(0, 0), (0, 1), (1, 0), (1, 1)]
    best = program.ask("P(Count | Alarm)", {"Alarm": ["on", "off"]}, kind="map")
    assert best.assignment["Count"].dtype.kind == "i"
    # P(Count | on) ~ (0.01, 0.08, 0.21, 0.36), P(Count | off) ~ (0.09, 0.12, 0.09, 0.04)
    assert best.assignment["Count"].tolist() == [5, 3]


def test_a_cell_given_back_as_answers_give_it_is_that_cell():
    program = bayesprog.loads(RANGE.replace("  - {term: P(Cell), form: uniform}\n", "")
                              .replace("decomposition:\n", "decomposition:\n  - {term: P(Cell), "
                                       "form: table, table: [0.1, 0.2, 0.3, 0.4]}\n"))
    cells = program.ask("P(Cell)").states["Cell"]
    by_tuple = program.ask("P(Alarm | Cell)", {"Cell": cells[2]}).probabilities
    by_name = program.ask("P(Alarm | Cell)", {"Cell": "1_0"}).probabilities
    np.testing.assert_array_equal(by_tuple, by_name)
    batch = program.ask("P(Alarm | Cell)", {"Cell": [cells[0], cells[3]]})
    assert batch.batch_shape == (2,)
    with pytest.raises(bayesprog.QuestionError, match="unknown cell"):
        program.ask("P(Alarm | Cell)", {"Cell": (5, 0)})


def test_a_float_state_is_named_as_written(capsys, tmp_path):
    path = tmp_path / "f.yaml"
    path.write_text("bayesprog: 1\nvariables:\n  F: {states: [0.50, 1.50, 2]}\n"
                    "  G: {states: [g0, g1]}\ndecomposition:\n"
                    "  - {term: P(F), form: table, table: {0.50: 0.2, 1.50: 0.3, 2: 0.5}}\n"
                    "  - {term: P(G | F), form: table, table: {0.50: [0.1, 0.9], 1.50: [0.5, 0.5], "
                    "2: [0.9, 0.1]}}\n")
    assert bayesprog.load(path).variables["F"].states == ("0.50", "1.50", "2")
    code, out, _ = run(capsys, "query", path, "P(G | F)", "--evidence", "F=1.50", "--json")
    assert code == 0 and json.loads(out)["probabilities"] == [0.5, 0.5]


def test_map_on_a_question_over_steps_names_the_conflict(capsys):
    code, _, err = run(capsys, "query", UMBRELLA, "today", "--map", "--evidence",
                       "Umbrella=yes,no")
    assert code == 2 and "'today' is a filter question over steps; leave out --map" in err


def test_the_ends_of_a_gaussian_density_are_infinite_and_no_quantiles_are_none():
    d = bayesprog.loads(GAUSS).ask("P(Pos)")
    assert d.quantile("Pos", 1.0) == np.inf and d.quantile("Pos", 0.0) == -np.inf
    assert d.quantile("Pos", []).shape == (0,) and d.pdf("Pos", []).shape == (0,)


def test_show_says_which_variable_is_the_previous_step(capsys):
    code, out, _ = run(capsys, "show", UMBRELLA)
    assert code == 0 and "Rain_before is Rain one step earlier" in out
