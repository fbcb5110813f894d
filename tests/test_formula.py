"""Formulas in parameters: evaluated like numpy evaluates the same arithmetic, affine parts
read exactly, and everything outside the grammar refused with the column where it starts."""

from __future__ import annotations

import numpy as np
import pytest

from bayesprog.vocabulary.formula import (
    FUNCTIONS,
    MAX_DEPTH,
    FormulaError,
    parse_formula,
    substitute,
)

RNG = np.random.default_rng(7)
X = RNG.uniform(0.1, 3.0, 50)
Y = RNG.uniform(-2.0, 2.0, 50)


@pytest.mark.parametrize("text, expected", [
    ("2*X + 1", lambda x, y: 2 * x + 1),
    ("-X**2 + +Y", lambda x, y: -(x**2) + y),
    ("X - (Y - 3)/4", lambda x, y: x - (y - 3) / 4),
    ("2**-1 * X", lambda x, y: 0.5 * x),
    ("sqrt(X**2 + Y**2)", lambda x, y: np.hypot(x, y)),
    ("hypot(X, Y) - arctan2(Y, X)", lambda x, y: np.hypot(x, y) - np.arctan2(y, x)),
    ("exp(-X) * log(X) + log1p(X) - expm1(Y)", lambda x, y: np.exp(-x) * np.log(x)
     + np.log1p(x) - np.expm1(y)),
    ("maximum(X, Y) + minimum(X, 1) + power(X, 1.5)", lambda x, y: np.maximum(x, y)
     + np.minimum(x, 1) + x**1.5),
    ("floor(Y) + ceil(X) + abs(Y)", lambda x, y: np.floor(y) + np.ceil(x) + np.abs(y)),
    ("sin(pi*X) * cos(Y) + tan(X/4) + e", lambda x, y: np.sin(np.pi * x) * np.cos(y)
     + np.tan(x / 4) + np.e),
    ("arcsin(Y/2) + arccos(Y/2) + arctan(X) + sinh(Y) + cosh(Y) + tanh(X)",
     lambda x, y: np.arcsin(y / 2) + np.arccos(y / 2) + np.arctan(x) + np.sinh(y)
     + np.cosh(y) + np.tanh(x)),
    ("1e-3 * X + 2.5E2", lambda x, y: 1e-3 * x + 250.0),
])
def test_a_formula_evaluates_as_numpy_does(text, expected):
    f = parse_formula(text, names=["X", "Y"])
    got = f.evaluate({"X": X, "Y": Y})
    np.testing.assert_allclose(got, expected(X, Y), rtol=1e-14, atol=1e-14)
    assert set(f.names) <= {"X", "Y"}


@pytest.mark.parametrize("text, expected", [
    ("X < Y", lambda x, y: (x < y) * 1.0),
    ("X >= 1 and Y != 0 or not X > 2", lambda x, y: ((x >= 1) & (y != 0) | ~(x > 2)) * 1.0),
    ("0 <= Y < 1", lambda x, y: ((0 <= y) & (y < 1)) * 1.0),
    ("X == X and Y <= Y", lambda x, y: np.ones_like(x)),
    ("where(Y > 0, X, -X) + (1 if X > 1 else 2)",
     lambda x, y: np.where(y > 0, x, -x) + np.where(x > 1, 1, 2)),
    ("min(X, Y, 1) + max(X, Y)", lambda x, y: np.minimum(np.minimum(x, y), 1) + np.maximum(x, y)),
    ("round(3*Y) + floor(Y) + mod(3*Y, 2) + (3*Y) % 2 + (3*Y) // 2",
     lambda x, y: np.round(3 * y) + np.floor(y) + np.mod(3 * y, 2) + np.mod(3 * y, 2)
     + np.floor_divide(3 * y, 2)),
    ("clip(Y, -1, 1) + sign(Y)", lambda x, y: np.clip(y, -1, 1) + np.sign(y)),
    ("not (X > 1) + 0", lambda x, y: (~(x > 1 + 0)) * 1.0),
])
def test_comparisons_and_logic_give_one_for_true_and_zero_for_false(text, expected):
    got = parse_formula(text, names=["X", "Y"]).evaluate({"X": X, "Y": Y})
    np.testing.assert_array_equal(got, expected(X, Y))


def test_a_motion_kernel_stays_on_its_cells():
    f = parse_formula("min(max(X0 + U, 0), 9)")
    x0, u = np.arange(10.0)[:, None], np.array([-1.0, 0.0, 1.0])
    np.testing.assert_array_equal(f.evaluate({"X0": x0, "U": u}), np.clip(x0 + u, 0, 9))
    assert f.affine() is None and not f.affine_in(["X0"])


def test_named_states_are_compared_by_their_indices_and_nothing_else():
    states = {"A": ("n", "e", "s", "w"), "B": ("n", "e", "s", "w"), "C": ("lo", "hi")}
    a, b = np.arange(4.0)[:, None], np.arange(4.0)
    same = parse_formula("A == B").with_states(states)
    np.testing.assert_array_equal(same.evaluate({"A": a, "B": b}), np.eye(4))
    north = parse_formula("A != 'n' and 's' == B").with_states(states)
    np.testing.assert_array_equal(north.evaluate({"A": a, "B": b}), (a != 0) & (b == 2))
    for text, words in [("A == C", "'C'"), ("A < B", "only be compared with == or !="),
                        ("A == 'up'", "not one of A's"), ("A + 1 == B", "compared with .A \\+ 1."),
                        ("A == 1", "'1'"), ("X == 'n'", "compared with no variable")]:
        with pytest.raises(FormulaError, match=words):
            parse_formula(text).with_states(states)
    with pytest.raises(FormulaError, match="compared with no variable"):
        parse_formula("X == 'n'").evaluate({"X": 1.0})


def test_names_are_listed_in_order_of_first_use_and_constants_are_not_names():
    assert parse_formula("Y + 2*X*Y + pi").names == ("Y", "X")
    assert parse_formula("3 * pi").is_constant
    assert float(parse_formula("3 * pi").evaluate({})) == pytest.approx(3 * np.pi)


def test_a_formula_broadcasts_its_arrays():
    f = parse_formula("X + Y")
    out = f.evaluate({"X": np.arange(3.0)[:, None], "Y": np.arange(4.0)[None, :]})
    assert out.shape == (3, 4)
    assert out[2, 3] == 5.0


@pytest.mark.parametrize("text, intercept, coefficients", [
    ("2*X + 1", 1.0, {"X": 2.0}),
    ("0.8*East - 0.6*North + 2", 2.0, {"East": 0.8, "North": -0.6}),
    ("-(X - 2*Y)/4 + 3", 3.0, {"X": -0.25, "Y": 0.5}),
    ("X - X", 0.0, {"X": 0.0}),
    ("exp(0)*X + sqrt(4)", 2.0, {"X": 1.0}),
    ("(X + 1)*2 + Y*(3 - 1)", 2.0, {"X": 2.0, "Y": 2.0}),
    ("5", 5.0, {}),
])
def test_affine_parts_are_read_exactly(text, intercept, coefficients):
    f = parse_formula(text)
    assert f.affine() == (pytest.approx(intercept), pytest.approx(coefficients))
    # and they agree with evaluation at random points
    values = {n: RNG.normal(size=20) for n in f.names}
    a, c = f.affine()
    np.testing.assert_allclose(f.evaluate(values),
                               a + sum(c[n] * values[n] for n in f.names), atol=1e-12)


@pytest.mark.parametrize("text", ["X*Y", "X**2", "X**1", "1/X", "sqrt(X)", "abs(X)", "X/0",
                                  "exp(X) + 1", "2**X"])
def test_what_is_not_affine_is_said_so(text):
    assert parse_formula(text).affine() is None


@pytest.mark.parametrize("text, words, column", [
    ("X << 2", "unsupported operator '<<'", 0),
    ("np.exp(X)", "unknown function 'np.exp'", 0),
    ("X[0]", "unsupported indexing", 0),
    ("__import__('os').system('true')", "unknown function", 0),
    ("(lambda: 1)()", "unknown function", 0),
    ("X in Y", "unsupported comparison 'in'", 0),
    ("X is Y", "unsupported comparison 'is'", 0),
    ("min(X)", "takes 2 or more argument(s), found 1", 0),
    ("where(X, Y)", "takes 3 argument(s), found 2", 0),
    ("1 + Xx", "did you mean 'X'", 4),
    ("mxa(X, Y)", "did you mean 'max'", 0),
    ("X.real", "unsupported attribute access", 0),
    ("2*X + 'a'", "'a'", 6),
    ("2*X + True", "True", 6),
    ("1 + Z", "unknown name 'Z'", 4),
    ("1 + sqrt", "function 'sqrt' used without arguments", 4),
    ("hypot(X)", "takes 2 argument(s), found 1", 0),
    ("exp(X, Y)", "takes 1 argument(s), found 2", 0),
    ("exp(x=X)", "keywords", 0),
    ("2 * (X + ", "syntax error", None),
    ("", "empty formula", 0),
    ("   ", "empty formula", 0),
    ("X @ Y", "unsupported operator '@'", 0),
    ("~X", "unsupported operator", 0),
])
def test_bad_formulas_are_refused_with_where_and_why(text, words, column):
    with pytest.raises(FormulaError) as info:
        parse_formula(text, names=["X", "Y"])
    assert words in str(info.value)
    if column is not None:
        assert info.value.offset == column


def test_no_text_can_run_python_or_grow_without_bound():
    with pytest.raises(FormulaError, match="at most 1000"):
        parse_formula("X + " * 300 + "1")
    deep = "(" * (MAX_DEPTH + 1) + "X" + ")" * (MAX_DEPTH + 1)
    with pytest.raises(FormulaError, match="parentheses deep"):
        parse_formula(deep)
    # huge powers are floats, not Python integers: no hang, an infinity
    assert np.isinf(parse_formula("9**9**9").evaluate({}))


def test_a_variable_may_not_shadow_a_function_or_constant():
    with pytest.raises(FormulaError, match="rename it"):
        parse_formula("exp + 1", names=["exp"])
    with pytest.raises(FormulaError, match="constant"):
        parse_formula("pi", names=["pi"])


def test_every_function_listed_is_callable_with_its_arity():
    for name, (arity, _) in FUNCTIONS.items():
        text = f"{name}({', '.join(['X'] * arity)})"
        if name == "clip":
            text = "clip(X, 0, 1)"
        assert np.isfinite(parse_formula(text).evaluate({"X": 0.5}))


def test_substitution_replaces_a_name_by_a_formula():
    f = substitute(parse_formula("2*D + D/2"), "D", "sqrt(X**2 + 9)")
    assert f.names == ("X",)
    x = np.linspace(0, 4, 5)
    np.testing.assert_allclose(f.evaluate({"X": x}), 2.5 * np.sqrt(x**2 + 9))
