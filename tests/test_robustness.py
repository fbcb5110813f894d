"""Nothing a user writes crashes, hangs or fills the memory: every bad input is exit status 2 (or
a bayesprog error from Python) with a message that says where and what was expected.

The named cases are regressions of inputs that once ended in a traceback; the properties
(hypothesis) generate malformed programs, questions and robot lines."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import bayesprog
from bayesprog.cli import main
from bayesprog.errors import ArgumentError, BayesprogError, QuestionError, SpecError
from bayesprog.limits import SizeError, set_limits

MODELS = Path(__file__).parents[1] / "models"
RAIN = MODELS / "examples" / "rain.yaml"


def program_text(variables: str, terms: str) -> str:
    return f"bayesprog: 1\nvariables:\n{variables}decomposition:\n{terms}"


def run_cli(tmp_path: Path, capsys, text: str | None, *args: str) -> tuple[int, str]:
    """``bayesprog ARGS`` on a program file holding ``text`` (named FILE in ``args``)."""
    file = tmp_path / "program.yaml"
    if text is not None:
        file.write_text(text)
    status = main([str(file) if a == "FILE" else a for a in args])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return status, err


# sizes: estimated before anything is allocated ------------------------------------------------
GRID = "  O: {grid: {shape: [100000, 100000], cell: 0.01}}\n"
MANY_AXES = "  O: {grid: {shape: [" + ", ".join(["2"] * 40) + "], cell: 0.01}}\n"
HUGE_RANGE = "  K: {range: [0, 1000000000000]}\n"


@pytest.mark.parametrize("variables, expected", [
    (GRID, "3:13: variables.O.grid: a grid of 100000 x 100000 has 10,000,000,000 states"),
    (MANY_AXES, "3:13: variables.O.grid: expected at most 16 axes, found 40"),
    (HUGE_RANGE, "3:6: variables.K: the range [0, 1000000000000] has 1,000,000,000,001 states"),
])
@pytest.mark.parametrize("command", [["validate", "FILE"], ["query", "FILE", "P(O)"]])
def test_a_variable_too_large_is_refused_at_its_place(tmp_path, capsys, variables, expected,
                                                       command):
    name = variables.split(":")[0].strip()
    text = program_text(variables, f"  - {{term: P({name}), form: uniform}}\n")
    status, err = run_cli(tmp_path, capsys, text, *command)
    assert status == 2
    assert f"program.yaml:{expected}" in err
    if "states" in expected:
        assert "BAYESPROG_MAX_STATES" in err  # and how to raise the limit


def test_the_states_limit_can_be_raised(monkeypatch):
    text = program_text("  K: {range: [0, 2500000]}\n", "  - {term: P(K), form: uniform}\n")
    with pytest.raises(SpecError, match="more than the limit of 2,000,000"):
        bayesprog.loads(text)
    monkeypatch.setenv("BAYESPROG_MAX_STATES", "3000000")
    assert bayesprog.loads(text).variables["K"].card == 2500001


def test_a_question_whose_joint_is_too_large_is_refused_before_it_allocates(tmp_path, capsys):
    variables = "".join(f"  V{i}: {{states: [a, b]}}\n" for i in range(41))
    terms = "".join(f"  - {{term: P(V{i}), form: uniform}}\n" for i in range(41))
    question = "P(" + " ".join(f"V{i}" for i in range(41)) + ")"
    status, err = run_cli(tmp_path, capsys, program_text(variables, terms), "query", "FILE",
                          question)
    assert status == 2
    assert "needs 2,199,023,255,552 entries, more than the limit" in err
    assert "BAYESPROG_MAX_ENTRIES" in err


def test_the_entries_limit_is_the_users_to_set():
    program = bayesprog.loads(program_text(
        "".join(f"  V{i}: {{states: [a, b]}}\n" for i in range(12)),
        "".join(f"  - {{term: P(V{i}), form: uniform}}\n" for i in range(12))))
    question = "P(" + " ".join(f"V{i}" for i in range(12)) + ")"
    try:
        set_limits(entries=1000)
        with pytest.raises(SizeError, match="needs 4,096 entries, more than the limit of 1,000"):
            program.ask(question)
    finally:
        set_limits()
    assert program.ask(question).probabilities.size == 4096


def test_the_intermediate_factors_count_not_only_the_answer():
    """A chain whose answer is small but whose elimination would not be: the estimate follows
    the contraction path (here a product of 24 binary variables that all share a factor)."""
    variables = "".join(f"  V{i}: {{states: [a, b]}}\n" for i in range(24))
    parents = ", ".join(f"V{i}" for i in range(23))
    terms = "".join(f"  - {{term: P(V{i}), form: uniform}}\n" for i in range(23))
    terms += f"  - {{term: 'P(V23 | {parents})', form: uniform}}\n"
    program = bayesprog.loads(program_text(variables, terms))
    try:
        set_limits(entries=1 << 20)
        with pytest.raises(SizeError):
            program.ask("P(V23)")
    finally:
        set_limits()


def test_many_states_are_checked_in_linear_time():
    states = ", ".join(f"s{i}" for i in range(40000))
    text = program_text(f"  X: {{states: [{states}, s7]}}\n", "  - {term: P(X), form: uniform}\n")
    with pytest.raises(SpecError, match=r"expected distinct state names, found \['s7'\] twice"):
        bayesprog.loads(text)  # quadratic, this took minutes


# the command line ---------------------------------------------------------------------------------
@pytest.mark.parametrize("command, expected", [
    (["show", str(RAIN), "--ablate", "P(("], "--ablate 'P((': expected the form"),
    (["query", str(RAIN), "P(Rain)", "--ablate", "Q(x"], "--ablate 'Q(x': expected the form"),
    (["export", str(RAIN), "-o", "x.bif", "--ablate", ")"], "--ablate ')': expected"),
    (["query", str(RAIN), "P(Rain)", "--limit", "0"], "--limit: expected at least 1"),
    (["query", str(RAIN), "P(Rain)", "--seed", "-1"], "--seed: expected a non-negative"),
])
def test_bad_options_are_user_errors(capsys, command, expected):
    assert main(command) == 2
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err


# the Python API -----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def rain():
    return bayesprog.load(RAIN)


API_MISUSES = [
    ("evidence as a list", lambda p: p.ask("P(Rain | Grass)", ["wet"]), ArgumentError,
     "evidence: expected a mapping"),
    ("evidence as a string", lambda p: p.ask("P(Rain | Grass)", "wet"), ArgumentError,
     "evidence: expected a mapping"),
    ("evidence keyed by a number", lambda p: p.ask("P(Rain | Grass)", {5: "wet"}),
     ArgumentError, "evidence: expected names"),
    ("inputs as a list", lambda p: p.ask("P(Rain)", inputs=[1]), ArgumentError,
     "inputs: expected a mapping"),
    ("soft as a list", lambda p: p.ask("P(Rain)", soft=[1, 2]), ArgumentError,
     "soft: expected a mapping"),
    ("soft of words", lambda p: p.ask("P(Rain)", soft={"Grass": "ab"}), QuestionError,
     "soft evidence on Grass: expected 2"),
    ("rng a word", lambda p: p.map("P(Rain | Grass)", {"Grass": "wet"}, rng="abc"),
     ArgumentError, "rng: expected a seed"),
    ("rng negative", lambda p: p.map("P(Rain | Grass)", {"Grass": "wet"}, rng=-1),
     QuestionError, "rng: expected a seed >= 0"),
    ("rng a fraction", lambda p: p.map("P(Rain | Grass)", {"Grass": "wet"}, rng=1.5),
     ArgumentError, "rng: expected a seed"),
    ("ablate(None)", lambda p: p.ablate(None), ArgumentError, "ablate: expected terms"),
    ("ablate(5)", lambda p: p.ablate(5), ArgumentError, "ablate: expected terms"),
    ("ablate([5])", lambda p: p.ablate([5]), ArgumentError, "ablate: expected terms"),
    ("loads(None)", lambda p: bayesprog.loads(None), ArgumentError, "loads: expected the text"),
    ("loads(5)", lambda p: bayesprog.loads(5), ArgumentError, "loads: expected the text"),
    ("load(None)", lambda p: bayesprog.load(None), ArgumentError, "load: expected a path"),
    ("variables not a mapping", lambda p: bayesprog.load(RAIN, variables=5), ArgumentError,
     "variables: expected a mapping"),
    ("terms not a mapping of mappings", lambda p: bayesprog.load(RAIN, terms={"P(Rain)": 5}),
     ArgumentError, "terms: expected a mapping of terms"),
    ("fit(None)", lambda p: p.fit(None), ArgumentError, "data: expected a CSV"),
    ("fit max_iter a word", lambda p: p.fit({"Rain": ["rain"]}, max_iter="a"), ArgumentError,
     "max_iter: expected an integer"),
    ("fit freeze a number", lambda p: p.fit({"Rain": ["rain"]}, freeze=5), ArgumentError,
     "freeze: expected terms"),
    ("question a number", lambda p: p.ask(5), QuestionError, "expected a string like"),
    ("kind unknown", lambda p: p.ask("P(Rain)", kind="foo"), QuestionError,
     "kind must be 'posterior', 'map'"),
]


@pytest.mark.parametrize("call, error, message", [case[1:] for case in API_MISUSES],
                         ids=[case[0] for case in API_MISUSES])
def test_the_api_checks_its_arguments_where_they_enter(rain, call, error, message):
    with pytest.raises(error, match=message.replace("(", r"\(").replace(")", r"\)")) as info:
        call(rain)
    # bayesprog's own errors, which are also the errors Python code expects of a bad argument
    assert isinstance(info.value, BayesprogError)
    assert isinstance(info.value, (TypeError, ValueError))


# properties: malformed programs, questions and robot lines -----------------------------------------
VALID = RAIN.read_text()
QUICK = settings(max_examples=60, deadline=3000, derandomize=True,
                 suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


@st.composite
def edited_program(draw) -> str:
    """The example program with a few characters deleted, inserted or replaced."""
    text = VALID
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(text)))
        what = draw(st.sampled_from(["delete", "insert", "replace"]))
        piece = draw(st.sampled_from(["", "-", ":", "[", "]", "{", "}", "&a", "*a", "!!python",
                                      "\t", "  ", "\n", "P(", "|", "1e999", "-1", "nan", "~",
                                      "'", '"', "\\", "\x00", "é", "Rain", "table"]))
        if what == "delete":
            text = text[:at] + text[at + draw(st.integers(1, 5)):]
        elif what == "insert":
            text = text[:at] + piece + text[at:]
        else:
            text = text[:at] + piece + text[at + 1:]
    return text


yaml_values = st.recursive(
    st.none() | st.booleans() | st.integers(-10**15, 10**15) | st.floats()
    | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner,
                                                                max_size=4),
    max_leaves=12)


@st.composite
def structured_program(draw) -> str:
    """A program whose parts are arbitrary YAML values, written out as YAML."""
    import yaml

    document = {"bayesprog": 1,
                "variables": draw(st.dictionaries(st.sampled_from(["A", "B", "O"]), yaml_values,
                                                  min_size=1, max_size=3)),
                "decomposition": draw(st.lists(yaml_values | st.fixed_dictionaries(
                    {"term": st.sampled_from(["P(A)", "P(B | A)", "P(A | B)", "P(O)", "bad"]),
                     "form": st.sampled_from(["uniform", "table", "normal", "beta", "gmm", "x"])},
                    optional={"table": yaml_values, "mean": yaml_values, "sigma": yaml_values,
                              "a": yaml_values, "b": yaml_values}), max_size=3))}
    if draw(st.booleans()):
        document["questions"] = draw(yaml_values)
    return yaml.safe_dump(document, allow_unicode=True)


def _answers_or_refuses(text: str) -> None:
    try:
        bayesprog.loads(text)
    except SpecError as exc:
        assert exc.diagnostics, "a SpecError lists where"
        for d in exc.diagnostics:
            assert d.line >= 1 and d.column >= 1


@QUICK
@given(edited_program())
def test_edited_programs_load_or_are_refused_at_a_place(text):
    _answers_or_refuses(text)


@QUICK
@given(structured_program())
def test_programs_of_any_yaml_load_or_are_refused_at_a_place(text):
    _answers_or_refuses(text)


@QUICK
@given(st.one_of(
    st.text(max_size=40),
    st.builds(lambda a, b, c: f"P({a} | {b}{c})", st.sampled_from(["Rain", "Grass", "Rain Grass",
                                                                    "", "X", "Rain Rain"]),
              st.sampled_from(["Grass", "Grass=wet", "Grass=", "Rain", "Grass=3", "Grass=-1",
                               "=wet", "Grass=wet=dry", "Grass, Grass"]),
              st.sampled_from(["", ", Rain", "|", ")", "((", ","]))))
def test_any_question_is_answered_or_refused(capsys, question):
    status = main(["query", str(RAIN), question, "--json"])
    out, err = capsys.readouterr()
    assert status in (0, 2)
    assert "Traceback" not in err
    if status == 0:
        answer = json.loads(out)
        assert np.isclose(sum(answer["probabilities"]), 1.0) or answer.get("map") is not None
    else:
        assert err.startswith("bayesprog: ")


@pytest.fixture(scope="module")
def explorer():
    from runner.attention.explorer import Explorer
    from runner.world.scenario import load_scenario

    return Explorer(load_scenario(MODELS / "scenarios" / "paper.yaml"), "T1")


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(
        st.sampled_from(["cell", "texture", "compliance", "maps", "reset", "seed", "x"]), inner,
        max_size=4),
    max_leaves=10)


@QUICK
@given(st.lists(st.one_of(
    st.text(max_size=30),
    json_values.map(json.dumps),
    st.integers(1, 5000).map(lambda n: "[" * n),
    st.builds(lambda x, y, e, c: json.dumps({"cell": [x, y], "texture": e, "compliance": c}),
              st.integers(-2, 70), st.integers(-2, 70), st.floats(), st.floats()),
), min_size=1, max_size=4))
def test_any_robot_line_is_answered_and_the_session_goes_on(explorer, lines):
    from runner.robot.stdio import serve

    stdin = io.StringIO("".join(line.replace("\n", " ") + "\n" for line in lines))
    stdout = io.StringIO()
    serve(explorer, stdin, stdout)
    replies = [json.loads(r) for r in stdout.getvalue().splitlines()]
    assert len(replies) == sum(1 for line in lines if line.replace("\n", " ").strip())
    for reply in replies:
        assert isinstance(reply, dict) and ("error" in reply or "next" in reply
                                            or "maps" in reply or "reset" in reply)


def test_programs_that_name_each_other_are_reported_where_the_circle_closes(tmp_path, capsys):
    program = """\
bayesprog: 1
variables:
  A: {states: [a, b]}
decomposition:
  - {term: P(A), form: uniform}
soft_evidence:
  - {variable: A, form: program, program: OTHER, question: q}
questions:
  q: P(A)
"""
    (tmp_path / "a.yaml").write_text(program.replace("OTHER", "b.yaml"))
    (tmp_path / "b.yaml").write_text(program.replace("OTHER", "a.yaml"))
    (tmp_path / "self.yaml").write_text(program.replace("OTHER", "self.yaml"))
    assert main(["validate", str(tmp_path / "a.yaml"), str(tmp_path / "self.yaml")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 3, err
    assert err[1].endswith("b.yaml:7:43: term P(A): program 'a.yaml': programs that name each "
                           "other in a circle (a.yaml -> b.yaml -> a.yaml): expected a program "
                           "that does not lead back to this one")
    assert "(self.yaml -> self.yaml)" in err[2]


_NAMES = st.sampled_from(["A", "B", "b_2", "x.y", "r-1", "A"])
_GAP = st.sampled_from(["", " ", "  ", ",", " , ", "\t"])


@settings(max_examples=300, deadline=None)
@given(left=st.lists(st.tuples(_NAMES, _GAP), min_size=0, max_size=3),
       right=st.lists(st.tuples(_NAMES, _GAP, st.sampled_from(["", "=s1", "= 2"])),
                      min_size=0, max_size=3),
       bar=st.sampled_from(["|", " | ", "", "||"]), pad=_GAP)
def test_the_quick_reading_of_a_question_is_the_general_one(left, right, bar, pad):
    """Texts of names only are read by one match; any text reads (or fails) as the general
    parser reads it."""
    from bayesprog.vocabulary.expressions import ExpressionError, _parse_general, parse_expression

    text = (f"{pad}P({pad}" + "".join(n + g for n, g in left) + bar
            + ",".join(n + g + v for n, g, v in right) + f"){pad}")

    def read(parse):
        try:
            e = parse(text)
        except ExpressionError as exc:
            return str(exc)
        return e.left, e.right, e.values

    assert read(parse_expression) == read(_parse_general)


def test_a_file_written_at_once_has_an_ordinary_files_mode_and_leaves_nothing_beside(
        tmp_path, monkeypatch):
    import os

    from bayesprog.support.files import atomic_write

    umask = os.umask(0o027)
    try:
        target = tmp_path / "out.yaml"
        atomic_write(target, b"first")
        atomic_write(target, b"second")
    finally:
        os.umask(umask)
    assert target.read_bytes() == b"second"
    assert target.stat().st_mode & 0o777 == 0o666 & ~0o027
    assert [p.name for p in tmp_path.iterdir()] == ["out.yaml"]

    class Interrupted(Exception):
        pass

    opened = os.fdopen

    def interrupted(fd, mode):  # a write that stops half-way
        f = opened(fd, mode)
        f.write = lambda data: (_ for _ in ()).throw(Interrupted())
        return f

    monkeypatch.setattr(os, "fdopen", interrupted)
    with pytest.raises(Interrupted):
        atomic_write(target, b"third")
    assert target.read_bytes() == b"second"
    assert [p.name for p in tmp_path.iterdir()] == ["out.yaml"]
