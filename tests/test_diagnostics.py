"""Diagnostics for bad program files and errors for bad questions / evidence.

Every expected line and column is computed from the test's own YAML text (see :func:`loc`),
never copied from what bayesprog prints.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

import bayesprog

PROGRAMS = Path(__file__).parent / "programs"

FILE = "model.yaml"


# helpers ----------------------------------------------------------------------------------------
def loc(text: str, line_has: str, token: str | None = None, *, nth_line: int | None = None,
        nth_token: int = 0) -> tuple[int, int]:
    """1-based (line, column) of ``token`` on the line of ``text`` containing ``line_has``.

    ``line_has`` must pick out a single line unless ``nth_line`` says which of them to take;
    ``token`` defaults to ``line_has``; ``nth_token`` picks a later occurrence on that line.
    """
    token = line_has if token is None else token
    hits = [(i, line) for i, line in enumerate(text.splitlines(), 1) if line_has in line]
    if nth_line is None:
        assert len(hits) == 1, f"{line_has!r} is on {len(hits)} lines, expected exactly one"
        nth_line = 0
    assert len(hits) > nth_line, f"{line_has!r} not found {nth_line + 1} time(s) in the text"
    number, line = hits[nth_line]
    col = -1
    for _ in range(nth_token + 1):
        col = line.find(token, col + 1)
        assert col >= 0, f"{token!r} not found {nth_token + 1} time(s) in {line!r}"
    return number, col + 1


def diagnostics(text: str) -> list[bayesprog.Diagnostic]:
    with pytest.raises(bayesprog.SpecError) as info:
        bayesprog.loads(text, FILE)
    diags = info.value.diagnostics
    assert diags, "a SpecError must carry at least one diagnostic"
    return diags


def matching(diags, words) -> list[bayesprog.Diagnostic]:
    return [d for d in diags if all(w in d.message for w in words)]


def dump(diags) -> str:
    return "\n".join(str(d) for d in diags)


@dataclass
class Expect:
    """One expected diagnostic: words its message must contain and where it must point.

    ``where`` lists the acceptable (line, column) positions (e.g. a key or its value).
    """

    words: tuple[str, ...]
    where: list[tuple[int, int]]
    regex: str | None = None


@dataclass
class Case:
    id: str
    text: str
    expect: list[Expect]
    exact: bool = True  # the file has exactly these diagnostics and no others
    marks: list = field(default_factory=list)


def check_case(case: Case) -> None:
    diags = diagnostics(case.text)
    for d in diags:
        assert d.file == FILE, d
        assert d.line >= 1 and d.column >= 1, d
    for exp in case.expect:
        found = matching(diags, exp.words)
        if exp.regex:
            found = [d for d in found if re.search(exp.regex, d.message)]
        assert len(found) == 1, (
            f"expected one diagnostic with {exp.words} (regex {exp.regex}), got:\n{dump(diags)}"
        )
        d = found[0]
        assert (d.line, d.column) in exp.where, (
            f"{d} points at {(d.line, d.column)}, expected one of {exp.where}"
        )
    if case.exact:
        assert len(diags) == len(case.expect), f"unexpected extra diagnostics:\n{dump(diags)}"


BASE = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  B: {states: [b0, b1]}
decomposition:
  - {term: P(A), form: table, table: [0.3, 0.7]}
  - {term: P(B | A), form: table, table: [[0.9, 0.1], [0.2, 0.8]]}
"""


def test_base_program_is_valid():
    """The fixture every 'BASE + ...' case builds on is itself a valid program."""
    program = bayesprog.loads(BASE, FILE)
    # P(A=a0 | B=b0) = .3*.9 / (.3*.9 + .7*.2)
    expected = 0.3 * 0.9 / (0.3 * 0.9 + 0.7 * 0.2)
    assert program.ask("P(A | B=b0)").probabilities[0] == pytest.approx(expected)


# malformed YAML ---------------------------------------------------------------------------------
T_MALFORMED = """\
bayesprog: 1
variables:
  A: {states: [a0, a1}
decomposition:
  - {term: P(A), form: uniform}
"""

T_MALFORMED_EOF = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]
"""

# duplicate keys ---------------------------------------------------------------------------------
T_DUP_VAR = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  A: {states: [a0, a1, a2]}
decomposition:
  - {term: P(A), form: uniform}
"""

T_DUP_NESTED = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
decomposition:
  - term: P(A)
    form: table
    table: {a0: 0.5, a1: 0.5, a0: 0.5}
"""

# YAML 1.1 booleans as state names: YAML 1.2 words, names as written ---------------------------
T_BOOL_FLOW = """\
bayesprog: 1
variables:
  Answer: {states: [yes, no]}
decomposition:
  - {term: P(Answer), form: uniform}
"""

T_BOOL_BLOCK = """\
bayesprog: 1
variables:
  Sprinkler:
    states:
      - on
      - off
decomposition:
  - {term: P(Sprinkler), form: uniform}
"""

T_BOOL_KEY = """\
bayesprog: 1
variables:
  S: {states: ["on", "off"]}
  A: {states: [a0, a1]}
decomposition:
  - {term: P(S), form: uniform}
  - term: P(A | S)
    form: table
    table:
      on: [0.5, 0.5]
      "off": [0.1, 0.9]
"""

# unknown form -----------------------------------------------------------------------------------
T_FORM = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
decomposition:
  - term: P(A)
    form: tabel
    table: [0.5, 0.5]
"""

# parameters outside their constraints ---------------------------------------------------------------
T_SIGMA_NEG = """\
bayesprog: 1
variables:
  X: {continuous: [-.inf, .inf]}
decomposition:
  - term: P(X)
    form: normal
    mean: 0
    sigma: -1
"""

T_SIGMA_ZERO = """\
bayesprog: 1
variables:
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(X), form: normal, mean: 0.5, sigma: 0}
"""

T_BETA_A = """\
bayesprog: 1
variables:
  L: {continuous: [0, 1]}
decomposition:
  - term: P(L)
    form: beta
    a: 0
    b: 2.5
"""

T_BETA_A_NEG = """\
bayesprog: 1
variables:
  L: {continuous: [0, 1]}
decomposition:
  - {term: P(L), form: beta, a: -0.5, b: 1}
"""

T_GMM_WEIGHTS = """\
bayesprog: 1
variables:
  X: {continuous: [-.inf, .inf]}
decomposition:
  - term: P(X)
    form: gmm
    means: [0.0, 1.0]
    sigma: 0.3
    weights: [0.5, 0.6]
"""

T_GMM_WEIGHTS_NEG = """\
bayesprog: 1
variables:
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(X), form: gmm, means: [0, 1], sigma: 1, weights: [1.5, -0.5]}
"""

# CPTs ---------------------------------------------------------------------------------------------
T_TABLE_SUM = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
decomposition:
  - term: P(A)
    form: table
    table: [0.3, 0.6]
"""

T_TABLE_ROW_SUM_FLOW = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  B: {states: [b0, b1]}
decomposition:
  - {term: P(A), form: table, table: [0.3, 0.7]}
  - {term: P(B | A), form: table, table: [[0.9, 0.1], [0.5, 0.6]]}
"""

T_TABLE_ROW_SUM_BLOCK = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  B: {states: [b0, b1]}
decomposition:
  - {term: P(A), form: table, table: [0.3, 0.7]}
  - term: P(B | A)
    form: table
    table:
      a0: [0.9, 0.1]
      a1: [0.5, 0.6]
"""

T_TABLE_TOO_MANY = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
decomposition:
  - term: P(A)
    form: table
    table: [0.2, 0.3, 0.5]
"""

T_TABLE_TOO_MANY_ALL_ROWS = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  B: {states: [b0, b1]}
decomposition:
  - {term: P(A), form: table, table: [0.3, 0.7]}
  - term: P(B | A)
    form: table
    table: {a0: [0.9, 0.05, 0.05], a1: [0.5, 0.3, 0.2]}
"""

T_TABLE_TOO_MANY_ONE_ROW = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  B: {states: [b0, b1]}
decomposition:
  - {term: P(A), form: table, table: [0.3, 0.7]}
  - term: P(B | A)
    form: table
    table:
      a0: [0.9, 0.1]
      a1: [0.5, 0.3, 0.2]
"""

T_TABLE_RAGGED_LIST = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  B: {states: [b0, b1]}
decomposition:
  - {term: P(A), form: table, table: [0.3, 0.7]}
  - term: P(B | A)
    form: table
    table: [[0.9, 0.1], [0.5, 0.3, 0.2]]
"""

T_TABLE_MISSING_STATE = """\
bayesprog: 1
variables:
  A: {states: [a0, a1, a2]}
  B: {states: [b0, b1]}
decomposition:
  - {term: P(A), form: uniform}
  - term: P(B | A)
    form: table
    table: {a0: [0.9, 0.1], a1: [0.5, 0.5]}
"""

T_TABLE_MISSING_ROW = """\
bayesprog: 1
variables:
  A: {states: [a0, a1, a2]}
  B: {states: [b0, b1]}
decomposition:
  - {term: P(A), form: uniform}
  - term: P(B | A)
    form: table
    table: [[0.9, 0.1], [0.5, 0.5]]
"""

# references between terms --------------------------------------------------------------------------
T_UNDECLARED = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
decomposition:
  - {term: P(A | Zed), form: uniform}
"""

T_TWO_TERMS = BASE + "  - {term: P(B), form: uniform}\n"

T_CYCLE2 = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  B: {states: [b0, b1]}
decomposition:
  - {term: P(A | B), form: uniform}
  - {term: P(B | A), form: uniform}
"""

T_CYCLE3 = """\
bayesprog: 1
variables:
  X: {states: [x0, x1]}
  A: {states: [a0, a1]}
  B: {states: [b0, b1]}
  C: {states: [c0, c1]}
decomposition:
  - {term: P(X), form: uniform}
  - {term: P(A | C), form: uniform}
  - {term: "P(B | A, X)", form: uniform}
  - {term: P(C | B), form: uniform}
"""

# questions ----------------------------------------------------------------------------------------
T_Q_UNDECLARED = BASE + "questions:\n  q1: P(A | Zed)\n"
T_Q_UNDECLARED_LEFT = BASE + "questions:\n  q1: P(Foo | B)\n"
T_Q_STATE = BASE + "questions:\n  q1:\n    ask: P(A | B=nonsense)\n"

# parameter names, terms, versions -----------------------------------------------------------------
T_SIGM = """\
bayesprog: 1
variables:
  X: {continuous: [-.inf, .inf]}
decomposition:
  - term: P(X)
    form: normal
    mean: 0
    sigm: 1
"""

T_NO_TERM = BASE.replace("decomposition:", "  C: {states: [c0, c1]}\ndecomposition:")

T_VERSION = BASE.replace("bayesprog: 1", "bayesprog: 2")
T_VERSION_STR = BASE.replace("bayesprog: 1", 'bayesprog: "1.0"')
T_VERSION_BOOL = BASE.replace("bayesprog: 1", "bayesprog: true")


def _cases() -> list[Case]:
    return [
        Case("malformed-yaml", T_MALFORMED, [
            Expect(("malformed YAML", "expected", "']'", "'}'"),
                   [loc(T_MALFORMED, "A: {states", "}")]),
        ]),
        Case("malformed-yaml-unclosed", T_MALFORMED_EOF, [
            # the unclosed '{' is only noticed at the end of the text (line 4, column 1), or
            # could be reported where it opens
            Expect(("malformed YAML", "expected", "'}'"),
                   [(4, 1), loc(T_MALFORMED_EOF, "A: {", "{")]),
        ]),
        Case("duplicate-variable", T_DUP_VAR, [
            Expect(("duplicate key 'A'", "first at line 3"),
                   [loc(T_DUP_VAR, "  A: {", "A", nth_line=1)]),
        ]),
        Case("duplicate-table-key", T_DUP_NESTED, [
            Expect(("duplicate key 'a0'",), [loc(T_DUP_NESTED, "table:", "a0", nth_token=1)]),
        ]),
        Case("unknown-form", T_FORM, [
            Expect(("unknown form 'tabel'", "expected", "table", "normal", "beta"),
                   [loc(T_FORM, "form: tabel", "tabel")]),
        ]),
        Case("normal-sigma-negative", T_SIGMA_NEG, [
            Expect(("sigma", "> 0", "-1"), [loc(T_SIGMA_NEG, "sigma: -1", "-1")]),
        ]),
        Case("normal-sigma-zero", T_SIGMA_ZERO, [
            Expect(("sigma", "> 0", "got 0"), [loc(T_SIGMA_ZERO, "sigma: 0", "0}")]),
        ]),
        Case("beta-a-zero", T_BETA_A, [
            Expect(("'a'", "> 0", "got 0"), [loc(T_BETA_A, "a: 0", "0")]),
        ]),
        Case("beta-a-negative", T_BETA_A_NEG, [
            Expect(("'a'", "> 0", "-0.5"), [loc(T_BETA_A_NEG, "a: -0.5", "-0.5")]),
        ]),
        Case("gmm-weights-sum", T_GMM_WEIGHTS, [
            Expect(("weights", "summing to 1", "1.1"), [loc(T_GMM_WEIGHTS, "weights:", "[")]),
        ]),
        Case("gmm-weights-negative", T_GMM_WEIGHTS_NEG, [
            Expect(("weights", "non-negative", "-0.5"), [loc(T_GMM_WEIGHTS_NEG, "weights:", "[1.5")]),
        ]),
        Case("table-sum", T_TABLE_SUM, [
            Expect(("table", "summing to 1", "0.9"), [loc(T_TABLE_SUM, "table:", "[")]),
        ]),
        Case("cpt-row-sum-nested-list", T_TABLE_ROW_SUM_FLOW, [
            # the offending row [0.5, 0.6]; the whole table value is acceptable too
            Expect(("P(B | A)", "summing to 1", "1.1"),
                   [loc(T_TABLE_ROW_SUM_FLOW, "[[0.9", "[0.5"),
                    loc(T_TABLE_ROW_SUM_FLOW, "[[0.9", "[[")]),
        ]),
        Case("cpt-row-sum-keyed", T_TABLE_ROW_SUM_BLOCK, [
            # the offending row is `a1: [0.5, 0.6]` (its key or its value), not the a0 row
            Expect(("P(B | A)", "summing to 1", "1.1"),
                   [loc(T_TABLE_ROW_SUM_BLOCK, "a1: [0.5", "a1"),
                    loc(T_TABLE_ROW_SUM_BLOCK, "a1: [0.5", "[")]),
        ]),
        Case("cpt-too-many-values", T_TABLE_TOO_MANY, [
            Expect(("expected 2 values per row", "a0, a1", "found 3"),
                   [loc(T_TABLE_TOO_MANY, "table:", "[")]),
        ]),
        Case("cpt-too-many-values-every-row", T_TABLE_TOO_MANY_ALL_ROWS, [
            Expect(("P(B | A)", "expected 2 values per row", "b0, b1", "found 3"),
                   [loc(T_TABLE_TOO_MANY_ALL_ROWS, "table: {a0", "[")]),
        ]),
        Case("cpt-too-many-values-one-keyed-row", T_TABLE_TOO_MANY_ONE_ROW, [
            Expect(("P(B | A)", "expected 2 values", "found 3"),
                   [loc(T_TABLE_TOO_MANY_ONE_ROW, "a1: [0.5", "a1"),
                    loc(T_TABLE_TOO_MANY_ONE_ROW, "a1: [0.5", "[")]),
        ]),
        Case("cpt-too-many-values-ragged-list", T_TABLE_RAGGED_LIST, [
            Expect(("P(B | A)", "expected 2 values", "found 3"),
                   [loc(T_TABLE_RAGGED_LIST, "table: [[", "[["),
                    loc(T_TABLE_RAGGED_LIST, "table: [[", "[0.5")]),
        ]),
        Case("cpt-missing-parent-state", T_TABLE_MISSING_STATE, [
            Expect(("P(B | A)", "misses state", "a2"), [loc(T_TABLE_MISSING_STATE, "table:", "{")]),
        ]),
        Case("cpt-missing-parent-row", T_TABLE_MISSING_ROW, [
            Expect(("P(B | A)", "expected shape (3, 2)", "found (2, 2)"),
                   [loc(T_TABLE_MISSING_ROW, "table:", "[[")]),
        ]),
        Case("undeclared-variable-in-term", T_UNDECLARED, [
            Expect(("undeclared variable 'Zed'", "declared: A"),
                   [loc(T_UNDECLARED, "P(A | Zed)", "P("),
                    loc(T_UNDECLARED, "P(A | Zed)", "Zed")]),
        ]),
        Case("variable-with-two-terms", T_TWO_TERMS, [
            Expect(("'B'", "second term", "P(B)", "one term per variable", "decomposition[1]"),
                   [loc(T_TWO_TERMS, "{term: P(B),", "P(B)")]),
        ]),
        Case("cycle-two", T_CYCLE2, [
            Expect(("cycle", "acyclic"), [loc(T_CYCLE2, "P(A | B)", "P("),
                                         loc(T_CYCLE2, "P(B | A)", "P(")],
                   regex=r"(A -> B -> A|B -> A -> B)"),
        ]),
        Case("cycle-three", T_CYCLE3, [
            # edges C -> A, A -> B, B -> C; X is a parent outside the loop
            Expect(("cycle", "acyclic"),
                   [loc(T_CYCLE3, "P(A | C)", "P("), loc(T_CYCLE3, "P(B | A, X)", "P("),
                    loc(T_CYCLE3, '"P(B | A, X)"', '"'), loc(T_CYCLE3, "P(C | B)", "P(")],
                   regex=r"(A -> B -> C -> A|B -> C -> A -> B|C -> A -> B -> C)"),
        ]),
        Case("question-undeclared-known", T_Q_UNDECLARED, [
            Expect(("q1", "undeclared variable 'Zed'", "declared: A, B"),
                   [loc(T_Q_UNDECLARED, "q1: P(A | Zed)", "P(")]),
        ]),
        Case("question-undeclared-searched", T_Q_UNDECLARED_LEFT, [
            Expect(("q1", "undeclared variable 'Foo'", "declared: A, B"),
                   [loc(T_Q_UNDECLARED_LEFT, "q1: P(Foo | B)", "P(")]),
        ]),
        Case("question-unknown-state", T_Q_STATE, [
            Expect(("q1", "unknown state 'nonsense'", "B", "b0, b1"),
                   [loc(T_Q_STATE, "ask: P(A | B=nonsense)", "P(")]),
        ]),
        Case("unknown-parameter-sigm", T_SIGM, [
            # the misspelt key (or its value, on the same line)
            Expect(("unknown parameter 'sigm'", "normal", "expected mean, sigma"),
                   [loc(T_SIGM, "sigm: 1", "sigm"), loc(T_SIGM, "sigm: 1", "1")]),
            # and, consequently, the missing sigma, at the term
            Expect(("needs parameter 'sigma'",),
                   [loc(T_SIGM, "- term: P(X)", "term"), loc(T_SIGM, "- term: P(X)", "P(X)")]),
        ]),
        Case("variable-without-term", T_NO_TERM, [
            Expect(("variable 'C' has no term", "P(C | ...)"),
                   [loc(T_NO_TERM, "  C: {", "C"), loc(T_NO_TERM, "  C: {", "{")]),
        ]),
        Case("format-version-2", T_VERSION, [
            Expect(("format version", "expected 'bayesprog: 1'", "found 2"),
                   [loc(T_VERSION, "bayesprog: 2", "2")]),
        ]),
        Case("format-version-string", T_VERSION_STR, [
            Expect(("format version", "expected 'bayesprog: 1'", "'1.0'"),
                   [loc(T_VERSION_STR, "bayesprog:", '"')]),
        ]),
        Case("format-version-bool", T_VERSION_BOOL, [
            Expect(("format version", "expected 'bayesprog: 1'", "True"),
                   [loc(T_VERSION_BOOL, "bayesprog: true", "true")]),
        ]),
    ]


@pytest.mark.parametrize(
    "case", [pytest.param(c, id=c.id, marks=c.marks) for c in _cases()]
)
def test_bad_file_diagnostic(case: Case):
    check_case(case)


# schema-level problems with less obvious positions ------------------------------------------------
T_UNKNOWN_TOP_KEY = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
decomposition:
  - {term: P(A), form: uniform}
questons:
  q: P(A)
"""

T_UNKNOWN_PARAM_BLOCK = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(A), form: uniform}
  - term: P(X | A)
    form: normal
    mean: 0
    sigma: 1
    meen:
      a0: 0.0
      a1: 1.0
"""


@pytest.mark.parametrize(
    "text, key, words",
    [
        (T_UNKNOWN_TOP_KEY, "questons", ("unknown key 'questons'", "expected ", "ablate",
                                          "(did you mean 'questions'?)")),
        (T_UNKNOWN_PARAM_BLOCK, "meen", ("unknown parameter 'meen'", "expected mean, sigma")),
    ],
    ids=["top-level-key", "term-parameter"],
)
def test_unknown_key_points_at_the_key(text, key, words):
    diags = diagnostics(text)
    found = matching(diags, words)
    assert len(found) == 1, dump(diags)
    assert (found[0].line, found[0].column) == loc(text, f"{key}:", key)


def test_question_kind_typo_is_one_clear_diagnostic():
    text = BASE + "questions:\n  q: {ask: P(A), kind: mapp}\n"
    diags = diagnostics(text)
    assert len(diags) == 1, dump(diags)
    d = diags[0]
    assert "'mapp'" in d.message and "posterior" in d.message and "map" in d.message
    assert (d.line, d.column) == loc(text, "kind: mapp", "mapp")


def test_duplicate_state_names_message():
    text = BASE.replace("A: {states: [a0, a1]}", "A: {states: [a0, a0]}")
    diags = diagnostics(text)
    assert len(diags) == 1, dump(diags)
    d = diags[0]
    assert "distinct" in d.message and "'a0'" in d.message
    assert d.line == loc(text, "A: {states")[0]
    assert d.message.count("found") == 1, d.message


def test_gmm_weights_count_mismatch_is_reported_at_load_time():
    text = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(A), form: uniform}
  - {term: P(X | A), form: gmm, means: [0, 1], sigma: 1, weights: [0.2, 0.3, 0.5]}
"""
    diags = diagnostics(text)
    found = matching(diags, ("weights",))
    assert len(found) == 1, dump(diags)
    assert (found[0].line, found[0].column) == loc(text, "weights:", "[0.2")


# several problems in one file ---------------------------------------------------------------------
T_MANY = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  B: {states: [b0, b1]}
  C: {states: [c0, c1]}
decomposition:
  - {term: P(A), form: tabel}
  - {term: P(B | Q), form: uniform}
  - term: P(C | A)
    form: table
    table: [[0.5, 0.6], [0.5, 0.5]]
questions:
  q: P(A | B=zz)
"""


def test_several_problems_are_all_listed():
    diags = diagnostics(T_MANY)
    expected = [
        (("unknown form 'tabel'",), loc(T_MANY, "form: tabel", "tabel")),
        (("undeclared variable 'Q'",), loc(T_MANY, "P(B | Q)", "P(")),
        (("summing to 1", "1.1"), loc(T_MANY, "table: [[", "[0.5")),
        (("unknown state 'zz'",), loc(T_MANY, "q: P(A | B=zz)", "P(")),
    ]
    assert len(diags) >= 3
    for words, where in expected:
        found = matching(diags, words)
        assert len(found) == 1, f"{words} not listed once:\n{dump(diags)}"
        assert (found[0].line, found[0].column) == where, str(found[0])
        assert found[0].file == FILE
    assert len({(d.line, d.column, d.message) for d in diags}) == len(diags), "duplicates"
    # listed in file order, and the exception text has one FILE:LINE:COL line per problem
    assert [(d.line, d.column) for d in diags] == sorted((d.line, d.column) for d in diags)
    with pytest.raises(bayesprog.SpecError) as info:
        bayesprog.loads(T_MANY, FILE)
    lines = str(info.value).splitlines()
    assert lines == [f"{FILE}:{d.line}:{d.column}: {d.message}" for d in diags]


def test_yaml_problems_and_checker_problems_are_reported_together():
    text = T_DUP_NESTED.replace("form: table", "form: tabel")
    diags = diagnostics(text)
    assert matching(diags, ("duplicate key 'a0'",))
    found = matching(diags, ("unknown form 'tabel'",))
    assert len(found) == 1 and (found[0].line, found[0].column) == loc(text, "tabel")


def test_yaml11_words_are_names_as_written_quoted_or_not():
    """YAML 1.2: yes, no, on, off are words; a name is the text as written."""
    for text in (T_BOOL_FLOW, T_BOOL_BLOCK, T_BOOL_KEY):
        quoted = (text.replace("[yes, no]", '["yes", "no"]').replace("- on", '- "on"')
                  .replace("- off", '- "off"'))
        plain = bayesprog.loads(text, FILE)
        assert {n: v.states for n, v in plain.variables.items()} == {
            n: v.states for n, v in bayesprog.loads(quoted, FILE).variables.items()}
    assert bayesprog.loads(T_BOOL_FLOW, FILE).variables["Answer"].states == ("yes", "no")
    assert bayesprog.loads(T_BOOL_BLOCK, FILE).variables["Sprinkler"].states == ("on", "off")


def test_error_types():
    assert issubclass(bayesprog.SpecError, bayesprog.BayesprogError)
    assert issubclass(bayesprog.QuestionError, bayesprog.BayesprogError)
    assert issubclass(bayesprog.ZeroEvidenceError, bayesprog.QuestionError)


# evidence-time errors -----------------------------------------------------------------------------
SPRINKLER = """\
bayesprog: 1
variables:
  Rain: {states: [rain, dry]}
  Sprinkler: {states: ["on", "off"]}
  Grass: {states: [wet, dry]}
decomposition:
  - {term: P(Rain), form: table, table: [0.2, 0.8]}
  - {term: P(Sprinkler | Rain), form: table, table: [[0.01, 0.99], [0.4, 0.6]]}
  - term: P(Grass | Sprinkler, Rain)
    form: table
    table: [[[0.99, 0.01], [0.9, 0.1]], [[0.8, 0.2], [0.0, 1.0]]]
"""


@pytest.fixture(scope="module")
def sprinkler():
    return bayesprog.loads(SPRINKLER, FILE)


def test_evidence_ok(sprinkler):
    # enumeration: P(rain, wet) = .2 (.01 .99 + .99 .8), P(dry, wet) = .8 (.4 .9 + .6 0)
    rain = 0.2 * (0.01 * 0.99 + 0.99 * 0.8)
    dry = 0.8 * (0.4 * 0.9 + 0.6 * 0.0)
    result = sprinkler.ask("P(Rain | Grass)", {"Grass": "wet"})
    np.testing.assert_allclose(result.probabilities, [rain / (rain + dry), dry / (rain + dry)])


@pytest.mark.parametrize(
    "question, evidence, words",
    [
        ("P(Rain | Grass)", {"Grass": "soggy"}, ("unknown state 'soggy'", "Grass", "wet, dry")),
        ("P(Rain | Grass)", {"Grass": ["wet", "soggy"]}, ("unknown state 'soggy'", "wet, dry")),
        ("P(Rain | Grass)", {"Grass": 5}, ("state index 5", "Grass", "0..1")),
        ("P(Rain | Grass)", {"Grass": "wet", "Zed": "x"},
         ("unknown variable 'Zed'", "Rain, Sprinkler, Grass")),
        ("P(Rain | Grass)", {"Grass": "wet", "Sprinkler": "on"},
         ("'Sprinkler'", "not known", "expected evidence for Grass")),
        ("P(Rain | Grass)", {}, ("missing evidence for Grass",)),
        ("P(Rain | Grass, Sprinkler)", {"Grass": "wet"}, ("missing evidence for Sprinkler",)),
        ("P(Rain | Grass=wet)", {"Grass": "dry"}, ("Grass", "fixed to 'wet'")),
        ("P(Rain | Zed)", {}, ("undeclared variable 'Zed'", "declared: Rain, Sprinkler, Grass")),
        ("P(Rain | Grass=soggy)", {}, ("unknown state 'soggy'", "wet, dry")),
        ("P(Rain | | Grass)", {}, ("expected",)),
    ],
    ids=["unknown-state", "unknown-state-in-batch", "index-out-of-range", "unknown-variable",
         "not-a-known-variable", "missing-evidence", "missing-one-of-two", "fixed-twice",
         "question-undeclared", "question-unknown-state", "malformed-question"],
)
def test_question_errors(sprinkler, question, evidence, words):
    with pytest.raises(bayesprog.QuestionError) as info:
        sprinkler.ask(question, evidence)
    assert not isinstance(info.value, bayesprog.ZeroEvidenceError)
    message = str(info.value)
    for w in words:
        assert w in message, message


@pytest.mark.parametrize("question, evidence, soft, suggested", [
    ("P(Rian | Grass=wet)", {}, {}, "undeclared variable 'Rian' in P(Rian | Grass=wet): did "
     "you mean 'Rain'?"),
    ("P(Rain | grass=wet)", {}, {}, "did you mean 'Grass'?"),
    ("P(Rain | Grass=wte)", {}, {}, "unknown state 'wte' of Grass: did you mean 'wet'?"),
    ("P(Rain | Grass)", {"Grass": "Wet"}, {}, "unknown state 'Wet' of Grass: did you mean "
     "'wet'?"),
    ("P(Rain | Grass)", {"Gras": "wet"}, {}, "unknown variable 'Gras': did you mean 'Grass'?"),
    ("P(Rain | Grass)", {"Grass": "wet"}, {"Sprinkle": [0.5, 0.5]}, "did you mean "
     "'Sprinkler'?"),
    ("P(Rain=yse)", {}, {}, "unknown state 'yse' of Rain"),
    ("Rain", {}, {}, "ask P(Rain) for its distribution"),
])
def test_a_misspelt_name_in_a_question_is_pointed_at_the_one_meant(sprinkler, question,
                                                                   evidence, soft, suggested):
    with pytest.raises(bayesprog.QuestionError) as info:
        sprinkler.ask(question, evidence, soft=soft or None)
    assert suggested in str(info.value), str(info.value)
    with pytest.raises(bayesprog.QuestionError, match="did you mean 'P\\(Grass \\| Sprinkler, "
                       "Rain\\)'"):
        sprinkler.ablate("P(Grass | Rain)")


def test_a_misspelt_variable_on_the_command_line_is_pointed_at(tmp_path, capsys):
    from bayesprog.cli import main

    (tmp_path / "sprinkler.yaml").write_text(SPRINKLER)
    assert main(["query", str(tmp_path / "sprinkler.yaml"), "P(Rian | Grass=wet)"]) == 2
    err = capsys.readouterr().err
    assert "did you mean 'Rain'?" in err and "Traceback" not in err
    # and in a term of a file, as in a question
    (tmp_path / "bad.yaml").write_text(SPRINKLER.replace("P(Sprinkler | Rain)",
                                                         "P(Sprinkler | Rian)"))
    assert main(["validate", str(tmp_path / "bad.yaml")]) == 2
    assert "undeclared variable 'Rian': did you mean 'Rain'?" in capsys.readouterr().err


# a program with a grid, fields, beta, gmm, runtime inputs and a soft-evidence sub-program ------------
OBJ = (PROGRAMS / "obj.yaml").read_text(encoding="utf-8")

TAR = (PROGRAMS / "tar.yaml").read_text(encoding="utf-8")

N_CELLS = 20
TEMPLATES = np.array([[[0.01, 0.01], [0.02, 0.03]], [[0.03, 0.04], [0.01, 0.02]]])  # [R, K, 2]


@pytest.fixture(scope="module")
def tar(tmp_path_factory):
    folder: Path = tmp_path_factory.mktemp("tar")
    (folder / "obj.yaml").write_text(OBJ, encoding="utf-8")
    (folder / "tar.yaml").write_text(TAR, encoding="utf-8")
    return bayesprog.load(folder / "tar.yaml")


@pytest.fixture(scope="module")
def obj():
    return bayesprog.loads(OBJ, "obj.yaml")


def _tar_args(**override):
    rng = np.random.default_rng(1)
    evidence = {"T": "T1", "I": rng.uniform(0.05, 0.95, N_CELLS),
                "S": rng.uniform(0.05, 0.95, N_CELLS)}
    inputs = {"templates": TEMPLATES, "l1": 0.3, "l2": 0.5}
    for key, value in override.items():
        (inputs if key in inputs else evidence)[key] = value
    return evidence, {k: v for k, v in inputs.items() if v is not None}


def test_tar_with_good_inputs_answers(tar):
    evidence, inputs = _tar_args()
    result = tar.ask("next", evidence, inputs=inputs)
    assert isinstance(result, bayesprog.MapResult)
    assert result.assignment["O"] in tar.variables["O"].typed_states  # a cell (ix, iy)
    posterior = tar.ask("P(O | T, I, S)", evidence, inputs=inputs)
    assert posterior.probabilities.shape == (N_CELLS,)
    assert posterior.probabilities.sum() == pytest.approx(1.0)
    # a batch of templates (leading dimension 3) gives a batch of answers
    batched = tar.ask("P(O | T, I, S)", evidence,
                      inputs={**inputs, "templates": np.stack([TEMPLATES] * 3)})
    assert batched.probabilities.shape == (3, N_CELLS)
    np.testing.assert_allclose(batched.probabilities[1], posterior.probabilities, rtol=1e-10)


@pytest.mark.parametrize(
    "override, words",
    [
        ({"templates": TEMPLATES[0]}, ("input 'templates'", "['R', 'K', 2]", "found [2, 2]")),
        ({"templates": np.zeros((2, 3, 3))}, ("input 'templates'", "['R', 'K', 2]",
                                               "found [2, 3, 3]")),
        ({"templates": np.zeros((3, 2, 2))}, ("input 'templates'", "found [3, 2, 2]")),
        ({"templates": np.full((2, 2, 2), np.nan)}, ("input 'templates'", "finite")),
        ({"l2": None}, ("missing input 'l2'",)),
        ({"I": np.full(5, 0.5)}, ("field I", str(N_CELLS), "found shape (5,)")),
        ({"S": np.full(N_CELLS, 1.5)}, ("S=1.5", "outside its support", "[0, 1]")),
        ({"T": "T3"}, ("unknown state 'T3'", "T1, T2")),
    ],
    ids=["templates-missing-axis", "templates-wrong-trailing", "templates-wrong-R-axis",
         "templates-nan", "missing-input", "field-wrong-length", "field-out-of-support",
         "unknown-state"],
)
def test_tar_input_and_evidence_errors(tar, override, words):
    evidence, inputs = _tar_args(**override)
    with pytest.raises(bayesprog.QuestionError) as info:
        tar.ask("next", evidence, inputs=inputs)
    message = str(info.value)
    for w in words:
        assert w in message, message


def test_unknown_input(tar):
    evidence, inputs = _tar_args()
    with pytest.raises(bayesprog.QuestionError, match=r"unknown input 'zz'.*templates, l1, l2"):
        tar.ask("next", evidence, inputs={**inputs, "zz": 1.0})


@pytest.mark.parametrize(
    "evidence, words",
    [
        ({"L1": 1.5, "L2": 0.5}, ("L1=1.5", "outside its support", "[0, 1]")),
        ({"L1": 0.5, "L2": -0.25}, ("L2=-0.25", "outside its support")),
        ({"L1": [0.2, 0.5, 1.01], "L2": 0.5}, ("L1=1.01", "outside its support")),
        ({"L1": float("nan"), "L2": 0.5}, ("L1",)),
        ({"L1": "abc", "L2": 0.5}, ("L1", "expected numbers", "'abc'")),
    ],
    ids=["above", "below", "in-batch", "nan", "not-a-number"],
)
def test_continuous_value_errors(obj, evidence, words):
    with pytest.raises(bayesprog.QuestionError) as info:
        obj.ask("shape", evidence)
    message = str(info.value)
    for w in words:
        assert w in message, message


def test_continuous_value_on_support_edge_is_fine(obj):
    # Beta(1, 4.5) vs Beta(1, 1) for L1, Beta(1, 1) vs Beta(1, 4.5) for L2, uniform prior on R
    from scipy.stats import beta

    l1, l2 = 0.0, 0.5
    rect = beta.pdf(l1, 1, 4.5) * beta.pdf(l2, 1, 1)
    tri = beta.pdf(l1, 1, 1) * beta.pdf(l2, 1, 4.5)
    result = obj.ask("shape", {"L1": l1, "L2": l2})
    np.testing.assert_allclose(result.probabilities, [rect / (rect + tri), tri / (rect + tri)])


# zero evidence ------------------------------------------------------------------------------------
ZERO = """\
bayesprog: 1
variables:
  A: {states: [a0, a1, a2, a3]}
  C: {states: [c0, c1]}
decomposition:
  - {term: P(A), form: table, table: [0.1, 0.2, 0.3, 0.4]}
  - {term: P(C | A), form: table, table: [[1, 0], [1, 0], [0.5, 0.5], [1, 0]]}
"""


@pytest.fixture(scope="module")
def zero():
    # C=c1 is possible only when A=a2; with P(A) modified below it becomes impossible
    return bayesprog.loads(ZERO.replace("[0.1, 0.2, 0.3, 0.4]", "[0.2, 0.3, 0.0, 0.5]"), FILE)


def test_zero_evidence_posterior_raises(zero):
    with pytest.raises(bayesprog.ZeroEvidenceError) as info:
        zero.ask("P(A | C=c1)")
    assert isinstance(info.value, bayesprog.QuestionError)
    assert "probability zero" in str(info.value)
    assert "P(A | C=c1)" in str(info.value)
    # the other state of C is fine: P(A | C=c0) is P(A) restricted to the rows where C=c0 is possible
    prior = np.array([0.2, 0.3, 0.0, 0.5])
    like = np.array([1, 1, 0.5, 1])
    expected = prior * like / (prior * like).sum()
    np.testing.assert_allclose(zero.ask("P(A | C=c0)").probabilities, expected)


def test_zero_evidence_map_is_a_seeded_choice(zero):
    choices = []
    for seed in range(16):
        first = zero.ask("P(A | C=c1)", kind="map", rng=seed)
        again = zero.ask("P(A | C=c1)", kind="map", rng=seed)
        assert isinstance(first, bayesprog.MapResult)
        assert bool(first.zero_evidence) is True
        assert first.assignment == again.assignment, f"seed {seed} is not reproducible"
        assert first.assignment["A"] in ("a0", "a1", "a2", "a3")
        choices.append(first.assignment["A"])
    # a choice, not a fixed answer: 16 seeds do not all pick the same of the four states
    assert len(set(choices)) > 1, choices
    # a generator works as well as a seed
    a = zero.ask("P(A | C=c1)", kind="map", rng=np.random.default_rng(7)).assignment
    b = zero.ask("P(A | C=c1)", kind="map", rng=np.random.default_rng(7)).assignment
    assert a == b


def test_zero_evidence_in_a_batch(zero):
    with pytest.raises(bayesprog.ZeroEvidenceError, match=r"batch rows \(1,\)"):
        zero.ask("P(A | C)", {"C": ["c0", "c1", "c0"]})
    result = zero.ask("P(A | C)", {"C": ["c0", "c1", "c0"]}, kind="map", rng=0)
    assert result.zero_evidence.tolist() == [False, True, False]
    # rows with evidence keep the true argmax: P(A | C=c0) is largest for a3 (.5 vs .3, .2)
    assert result.assignment["A"][0] == "a3" and result.assignment["A"][2] == "a3"


def test_impossible_evidence_that_bears_on_the_answer_is_refused_and_map_draws_uniformly():
    # no state of A gives B=b3: P(A | B=b3) does not exist
    program = bayesprog.loads("""\
bayesprog: 1
variables:
  A: {states: [a0, a1, a2]}
  B: {states: [b0, b1, b2, b3]}
decomposition:
  - {term: P(A), form: table, table: [0.5, 0.3, 0.2]}
  - {term: P(B | A), form: table, table: [[0.4, 0.3, 0.3, 0], [0.1, 0.2, 0.7, 0], [1, 0, 0, 0]]}
""", FILE)
    with pytest.raises(bayesprog.ZeroEvidenceError):
        program.ask("P(A | B=b3)")
    results = [program.ask("P(A | B=b3)", kind="map", rng=seed) for seed in range(16)]
    assert all(bool(r.zero_evidence) for r in results)
    assert len({r.assignment["A"] for r in results}) > 1


def test_impossible_evidence_that_does_not_bear_on_the_answer_is_left_out():
    # P(A=a1) = 0, but P(B | A=a1) is the term's row: the answer does not depend on P(A)
    # (as pyAgrum's relevance reasoning answers); the evidence's probability is still zero
    program = bayesprog.loads("""\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  B: {states: [b0, b1, b2, b3]}
decomposition:
  - {term: P(A), form: table, table: [1.0, 0.0]}
  - {term: P(B | A), form: table, table: [[0.4, 0.3, 0.2, 0.1], [0.1, 0.2, 0.3, 0.4]]}
""", FILE)
    answer = program.ask("P(B | A=a1)")
    np.testing.assert_allclose(answer.probabilities, [0.1, 0.2, 0.3, 0.4], atol=1e-15)
    assert answer.log_evidence == -np.inf
    result = program.ask("P(B | A=a1)", kind="map", rng=0)
    assert result.assignment["B"] == "b3" and not bool(result.zero_evidence)


def test_second_term_reported_even_if_the_first_is_bad():
    text = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
decomposition:
  - {term: P(A), form: table, table: [0.2, 0.9]}
  - {term: P(A), form: uniform}
"""
    diags = diagnostics(text)
    bad_sum = matching(diags, ("summing to 1",))
    assert len(bad_sum) == 1 and (bad_sum[0].line, bad_sum[0].column) == loc(text, "[0.2")
    second = matching(diags, ("second term",))
    assert len(second) == 1, dump(diags)
    assert (second[0].line, second[0].column) == loc(text, "form: uniform", "P(A)")


def test_nan_evidence_on_unbounded_support_message():
    program = bayesprog.loads("""\
bayesprog: 1
variables:
  M: {states: [m0, m1]}
  E: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(M), form: uniform}
  - {term: P(E | M), form: normal, mean: {m0: 0.2, m1: 0.8}, sigma: 0.1}
""", FILE)
    with pytest.raises(bayesprog.QuestionError) as info:
        program.ask("P(M | E)", {"E": float("nan")})
    message = str(info.value)
    assert "E" in message and "[-inf, inf]" not in message, message


@pytest.mark.parametrize("written, bad", [('"2*X + W"', "W"), ("3*X + foo(X)", "foo"),
                                          ("'X + + * 2'", "*")])
def test_a_formula_error_points_at_its_character(written, bad):
    text = ("bayesprog: 1\nvariables:\n  X: {continuous: [-.inf, .inf]}\n"
            "  Y: {continuous: [-.inf, .inf]}\ndecomposition:\n"
            "  - {term: P(X), form: normal, mean: 0.0, sigma: 1.0}\n"
            f"  - {{term: P(Y | X), form: normal, sigma: 0.5, mean: {written}}}\n")
    diags = diagnostics(text)
    assert len(diags) == 1
    line = text.splitlines()[6]
    assert (diags[0].line, diags[0].column) == (7, line.index(bad, line.index("mean")) + 1)
