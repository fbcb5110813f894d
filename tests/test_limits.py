"""Sizes a user writes are estimated before anything is allocated: a term's table, a term of
too many variables, a question's joint, a file of millions of values; files a program names
are checked where it names them; an empty batch answers at once.

Memory is measured as the peak resident size of a child process (``ru_maxrss``), never time:
each case runs in a fresh interpreter with a time-out that only guards against a hang.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import bayesprog
from bayesprog.cli import main
from bayesprog.language.check import MAX_TERM_VARIABLES
from bayesprog.language.loader import MAX_VALUES
from bayesprog.limits import set_limits

BAYESPROG = str(Path(sys.executable).with_name("bayesprog"))


#: runs a command and prints its exit status and peak resident memory (KB) as JSON: a small
#: process, so that the memory of the test's own process never counts (a fork copies it)
_MEASURE = ("import json, resource, subprocess, sys\n"
            "r = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
            "peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss\n"
            "print(json.dumps([r.returncode, r.stderr, peak]))")


def _validate_in_a_child(path: Path, env: dict | None = None) -> tuple[int, str, float]:
    """``bayesprog validate PATH`` in a fresh process: its status, standard error, and peak
    resident memory in MB."""
    result = subprocess.run([sys.executable, "-c", _MEASURE, BAYESPROG, "validate", str(path)],
                            capture_output=True, text=True, timeout=120,
                            env=dict(os.environ, **(env or {})))
    status, err, peak = json.loads(result.stdout)
    return status, err, peak / 1024


def _term_text(parents: int, card: int, form: str = "uniform") -> str:
    names = [f"A{i}" for i in range(parents)]
    states = "[" + ", ".join(f"s{j}" for j in range(card)) + "]"
    lines = ["bayesprog: 1", "variables:"] + [f"  {n}: {{states: {states}}}" for n in names]
    lines += [f"  C: {{states: {states}}}", "decomposition:"]
    lines += [f"  - {{term: P({n}), form: uniform}}" for n in names]
    lines += [f"  - term: P(C | {', '.join(names)})", f"    form: {form}"]
    return "\n".join(lines) + "\n"


# single terms --------------------------------------------------------------------------------

@pytest.mark.parametrize("parents, card, expected", [
    (29, 2, "its table needs 1,073,741,824 entries (30 variables of 2 to 2 states), more than "
            "the limit of 100,000,000"),
    (40, 2, f"expected at most {MAX_TERM_VARIABLES}"),
    (40, 3, f"expected at most {MAX_TERM_VARIABLES}"),
])
def test_a_term_too_large_is_refused_at_its_place_in_little_memory(tmp_path, parents, card,
                                                                    expected):
    path = tmp_path / "big.yaml"
    path.write_text(_term_text(parents, card))
    status, err, peak = _validate_in_a_child(path)
    line = 3 + 2 * (parents + 1)  # the term's line: after the variables and the priors
    assert status == 2 and "Traceback" not in err
    assert f"big.yaml:{line}:11: term P(C | A0, " in err and expected in err, err
    assert peak < 300


def test_a_term_just_under_the_limit_is_answered_as_by_enumeration(tmp_path):
    # six ternary parents and a ternary child: 3^7 = 2187 entries, under a limit of 2200
    rng = np.random.default_rng(4)
    table = rng.dirichlet(np.ones(3), size=(3,) * 6)
    text = _term_text(6, 3, "table").replace("    form: table", "    form: table\n"
                                              f"    table: {json.dumps(table.tolist())}")
    set_limits(entries=2200)
    try:
        program = bayesprog.loads(text)
        evidence = {f"A{i}": "s1" for i in range(1, 6)}
        answer = program.ask("P(A0 | C, A1, A2, A3, A4, A5)", dict(evidence, C="s2"))
        joint = table[:, 1, 1, 1, 1, 1, 2] / 3  # P(A0) uniform, the rest fixed
        np.testing.assert_allclose(answer.probabilities, joint / joint.sum(), rtol=1e-12)
        set_limits(entries=2186)
        with pytest.raises(bayesprog.SpecError, match="2,187 entries"):
            bayesprog.loads(text)
    finally:
        set_limits()


def test_a_question_over_more_variables_than_arrays_take_is_refused(tmp_path, capsys):
    names = [f"V{i}" for i in range(MAX_TERM_VARIABLES + 1)]
    text = ("bayesprog: 1\nvariables:\n" + "".join(f"  {n}: {{states: [only]}}\n" for n in names)
            + "decomposition:\n" + "".join(f"  - {{term: P({n}), form: uniform}}\n" for n in names)
            + f"questions:\n  everything: P({' '.join(names)})\n")
    path = tmp_path / "wide.yaml"
    path.write_text(text)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"wide.yaml:{5 + 2 * len(names)}:15: question 'everything'" in err
    assert f"searches {len(names)} variables jointly" in err
    # one fewer is answered
    fewer = bayesprog.loads(text.replace(f" {names[-1]})", ")"))
    assert fewer.ask("everything").probabilities.shape == (1,) * MAX_TERM_VARIABLES


@settings(max_examples=25, deadline=None, derandomize=True)
@given(parents=st.integers(0, 6), card=st.integers(1, 6), limit=st.integers(1, 5000))
def test_terms_around_the_entries_limit_are_refused_exactly_past_it(parents, card, limit):
    entries = card ** (parents + 1)
    text = _term_text(parents, card)
    set_limits(entries=limit)
    try:
        if entries > limit:
            with pytest.raises(bayesprog.SpecError, match=f"needs {entries:,} entries"):
                bayesprog.loads(text)
        else:
            program = bayesprog.loads(text)
            answer = program.ask("P(C)")
            np.testing.assert_allclose(answer.probabilities, 1 / card)
    finally:
        set_limits()


# huge declarations ---------------------------------------------------------------------------

def test_a_file_of_millions_of_states_is_refused_before_it_is_parsed(tmp_path):
    path = tmp_path / "huge.yaml"
    with open(path, "w") as f:
        f.write("bayesprog: 1\nvariables:\n  X: {states: [")
        f.write(", ".join(f"s{i}" for i in range(4_400_000)))
        f.write("]}\ndecomposition:\n  - {term: P(X), form: uniform}\n")
    assert path.stat().st_size > 40e6
    status, err, peak = _validate_in_a_child(path)
    assert status == 2 and "Traceback" not in err
    assert "huge.yaml:1:1: the file holds about 4,400,00" in err and f"{MAX_VALUES:,}" in err
    assert peak < 500


def test_the_largest_file_under_the_limit_is_read(tmp_path):
    path = tmp_path / "large.yaml"
    n = MAX_VALUES - 100
    path.write_text("bayesprog: 1\nvariables:\n  X: {states: ["
                    + ", ".join(f"s{i}" for i in range(n))
                    + "]}\ndecomposition:\n  - {term: P(X), form: uniform}\n")
    status, err, peak = _validate_in_a_child(path)
    assert status == 0 and "ok" not in err, err
    assert peak < 500


# files named by others -----------------------------------------------------------------------

SUB = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  B: {states: [b0, b1]}
decomposition:
  - {term: P(A), form: uniform}
  - {term: P(B | A), form: program, program: NAME, question: "P(B | A)"}
"""


@pytest.mark.parametrize("name, make, expected", [
    ("missing.yaml", None, "no such file (looked for "),
    ("folder", lambda p: p.mkdir(), "a folder, expected a program file"),
    ("latin.yaml", lambda p: p.write_bytes(b"bayesprog: 1\n# caf\xe9\n"), "expected UTF-8 text"),
    ("scenario.yaml", lambda p: p.write_text("scenario: 1\nname: x\n"),
     "a scenario file, expected a program file"),
])
def test_a_sub_program_that_cannot_be_read_is_named_where_it_is_named(tmp_path, capsys, name,
                                                                      make, expected):
    if make is not None:
        make(tmp_path / name)
    path = tmp_path / "main.yaml"
    path.write_text(SUB.replace("NAME", name))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"main.yaml:7:46: term P(B | A): program {name!r}: " in err and expected in err, err
    assert "Traceback" not in err


def test_an_unreadable_file_is_said_so(tmp_path, capsys, monkeypatch):
    (tmp_path / "locked.yaml").write_text("bayesprog: 1\n")
    real_open = open

    def refusing(file, *args, **kwargs):
        if str(file).endswith("locked.yaml"):
            raise PermissionError(13, "Permission denied")
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr("builtins.open", refusing)
    path = tmp_path / "main.yaml"
    path.write_text(SUB.replace("NAME", "locked.yaml"))
    assert main(["validate", str(path)]) == 2
    assert "cannot read" in capsys.readouterr().err


# empty batches --------------------------------------------------------------------------------

STUDENT = """\
bayesprog: 1
variables:
  D: {states: [easy, hard]}
  G: {states: [A, B, C]}
  S: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(D), form: table, table: [0.6, 0.4]}
  - {term: P(G | D), form: table, table: {easy: [0.5, 0.3, 0.2], hard: [0.2, 0.3, 0.5]}}
  - {term: P(S | G), form: normal, mean: {A: 90, B: 75, C: 60}, sigma: 8}
"""


@pytest.mark.parametrize("empty", [np.array([]), np.empty((0,), dtype=str), [],
                                   np.empty((0, 3), dtype=object), np.empty((2, 0), dtype=int)])
def test_an_empty_batch_answers_empty_results_of_its_shape(empty):
    program = bayesprog.loads(STUDENT)
    batch = np.shape(empty)
    posterior = program.ask("P(D | G)", {"G": empty})
    assert posterior.probabilities.shape == batch + (2,)
    assert posterior.log_evidence.shape == batch and posterior.batch_shape == batch
    best = program.ask("P(D | G)", {"G": empty}, kind="map")
    assert best.indices.shape == batch + (1,) and best.probability.shape == batch
    assert np.shape(best.assignment["D"]) == batch
    real = program.ask("P(D | S)", {"S": np.zeros(batch)})
    assert real.probabilities.shape == batch + (2,)
    density = program.ask("P(S | D)", {"D": empty})
    assert np.shape(density.mean("S")) == batch and np.shape(density.quantile("S", 0.5)) == batch
    json.dumps(posterior.to_json()), json.dumps(best.to_json()), json.dumps(density.to_json())


def test_a_batch_with_rows_is_unchanged_by_the_empty_case():
    program = bayesprog.loads(STUDENT)
    answer = program.ask("P(D | G)", {"G": ["A", "C"]})
    prior, table = np.array([0.6, 0.4]), np.array([[0.5, 0.3, 0.2], [0.2, 0.3, 0.5]])
    for row, g in enumerate((0, 2)):
        joint = prior * table[:, g]
        np.testing.assert_allclose(answer.probabilities[row], joint / joint.sum(), rtol=1e-12)
    assert all(math.isfinite(x) for x in itertools.chain(answer.log_evidence))
