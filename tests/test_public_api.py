"""The public API walked with questions each program can and cannot answer: every call either
answers or raises bayesprog's own error (never an ``AssertionError``, a ``TypeError`` from
inside, or another bare Python error), so no ``assert`` guards a path a user can reach."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

import bayesprog

EXAMPLES = Path(__file__).parents[1] / "models" / "examples"

#: a discrete program, one with a real variable, and the paper's pi_per
MIXED = """
bayesprog: 1
variables:
  M: {states: [a, b]}
  E: {continuous: [-.inf, .inf]}
  F: {continuous: [0, 1]}
decomposition:
  - {term: P(M), form: uniform}
  - {term: P(E | M), form: normal, mean: {a: 0.9, b: 0.5}, sigma: 0.1}
  - {term: P(F | M), form: beta, a: {a: 2, b: 5}, b: 3}
"""


def programs() -> dict[str, bayesprog.Program]:
    out = {path.stem: bayesprog.load(path) for path in sorted(EXAMPLES.glob("*.yaml"))}
    out["mixed"] = bayesprog.loads(MIXED)
    return out


def questions(program: bayesprog.Program) -> list[tuple[str, dict]]:
    """Questions over one, two or every variable, each with no evidence, with evidence on
    another variable (a value it can take, and one it cannot), and malformed ones."""
    names = list(program.variables)
    out: list[tuple[str, dict]] = [("P()", {}), ("P(nothing)", {}), ("P(" + ", ".join(names) + ")",
                                                                       {})]

    def value(name: str, good: bool) -> object:
        variable = program.variables[name]
        states = getattr(variable, "states", None)
        if states:
            return [states[0]] if good else ["no_such_state"]
        if getattr(variable, "is_discrete", False):
            return [0] if good else [10**9]
        return [0.5] if good else [float("nan")]

    for a, b in itertools.permutations(names[:4], 2):
        out += [(f"P({a})", {}), (f"P({a} | {b})", {b: value(b, True)}),
                (f"P({a} | {b})", {b: value(b, False)}), (f"P({a} | {b})", {}),
                (f"P({a} {b})", {}), (f"P({a}=x)", {})]
        states = getattr(program.variables[a], "states", None)
        if states:
            out.append((f"P({a}={states[0]} | {b})", {b: value(b, True)}))
    # a conditional program's questions give the variables it is conditioned on
    given = {c: value(c, True) for c in program.conditioning}
    for a in [n for n in names if n not in given][:4] if given else ():
        out += [(f"P({a} | {', '.join(given)})", dict(given)),
                (f"P({a} | {', '.join(given)})", {})]
    return out


@pytest.mark.parametrize("name", sorted(programs()))
def test_every_call_answers_or_raises_bayesprogs_own_error(name):
    program = programs()[name]
    calls = ("ask", "posterior", "map", "density", "probability")
    reached = 0
    for (question, evidence), call in itertools.product(questions(program), calls):
        try:
            getattr(program, call)(question, evidence)
            reached += 1
        except bayesprog.BayesprogError:
            pass
        except Exception as exc:  # noqa: BLE001  (what the test is for)
            raise AssertionError(f"{name}: program.{call}({question!r}, {evidence!r}) raised "
                                 f"{type(exc).__name__}: {exc}") from None
    assert reached > 0  # some questions are answered: the walk reaches the engine


@pytest.mark.parametrize("bad", [42, None, ["bayesprog: 1"], b"\xff\xfe", 3.5])
def test_loads_takes_text_or_utf8_bytes_and_refuses_the_rest_clearly(bad):
    with pytest.raises(bayesprog.BayesprogError, match="loads: expected the text of a program"):
        bayesprog.loads(bad)


def test_loads_reads_bytes_as_utf8():
    text = (EXAMPLES / "rain.yaml").read_text(encoding="utf-8")
    from_bytes = bayesprog.loads(text.encode("utf-8"))
    from_text = bayesprog.loads(text)
    question = next(iter(from_text.questions))
    np.testing.assert_array_equal(from_bytes.ask(question).probabilities,
                                  from_text.ask(question).probabilities)


def test_map_and_probability_name_the_call_that_answers():
    program = bayesprog.loads(MIXED)
    with pytest.raises(bayesprog.QuestionError, match=r"program\.ask\(\.\.\.\)"):
        program.map("P(E | M)", {"M": ["a"]})
    with pytest.raises(bayesprog.QuestionError, match=r"program\.density\(\.\.\.\)"):
        program.posterior("P(E | M)", {"M": ["a"]})


def test_load_finds_a_bundled_program_by_its_name_as_the_command_line_does(tmp_path,
                                                                          monkeypatch):
    from bayesprog import bundled

    monkeypatch.chdir(tmp_path)  # no file called student here
    for name in ("student", "student.yaml", "examples/student"):
        program = bayesprog.load(name)
        assert program.path == bundled.find("student", "program")
        assert program.ask("P(G | D=easy, I=high)").probabilities.tolist() == pytest.approx(
            [0.9, 0.08, 0.02])
    with pytest.raises(FileNotFoundError, match="no bundled program of that name"):
        bayesprog.load("studnet")


def test_a_file_of_the_name_in_the_working_directory_wins_over_a_bundled_one(tmp_path,
                                                                            monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "student").write_text(
        "bayesprog: 1\nname: mine\nvariables: {G: {states: [pass, fail]}}\n"
        "decomposition:\n  - {term: P(G), form: table, table: [0.6, 0.4]}\n")
    mine = bayesprog.load("student")
    assert mine.name == "mine" and mine.ask("P(G)").probabilities.tolist() == [0.6, 0.4]
    (tmp_path / "student.yaml").write_text(
        "bayesprog: 1\nname: mine_too\nvariables: {G: {states: [pass, fail]}}\n"
        "decomposition:\n  - {term: P(G), form: table, table: [0.5, 0.5]}\n")
    assert bayesprog.load("student.yaml").name == "mine_too"
