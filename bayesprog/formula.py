"""Arithmetic formulas that a program file may give as a parameter value.

``mean: "2*X + 1"`` or ``value: "sqrt(X**2 + Y**2)"``: numbers, variable names, ``+ - * / **``,
unary ``-`` and ``+``, parentheses, and calls of a fixed set of numpy functions. The text is
parsed by Python's own parser (:func:`ast.parse`) and the tree is walked against that grammar;
nothing is ever executed by Python, so no text can reach anything else.

>>> f = parse_formula("2*X + 1 - (Y - 3)/4", names=["X", "Y"])
>>> f.names, float(f.evaluate({"X": 1.0, "Y": 7.0}))
(('X', 'Y'), 2.0)
>>> f.affine()
(1.75, {'X': 2.0, 'Y': -0.25})
>>> parse_formula("X*Y").affine() is None
True
"""

from __future__ import annotations

import ast
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bayesprog.errors import BayesprogError

#: Functions a formula may call, by the number of their arguments.
FUNCTIONS: dict[str, tuple[int, Any]] = {
    **{name: (1, getattr(np, name)) for name in (
        "abs", "sqrt", "exp", "log", "log1p", "expm1", "sin", "cos", "tan", "arcsin",
        "arccos", "arctan", "sinh", "cosh", "tanh", "floor", "ceil")},
    **{name: (2, getattr(np, name)) for name in (
        "arctan2", "hypot", "minimum", "maximum", "power")},
}
CONSTANTS = {"pi": float(np.pi), "e": float(np.e)}
#: Longest text and deepest nesting accepted (Python's parser itself fails on deep nesting).
MAX_LENGTH = 1000
MAX_DEPTH = 50

_OPERATORS = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply,
              ast.Div: np.divide, ast.Pow: np.power}
_EXPECTED = ("expected numbers, variable names, + - * / **, parentheses and the functions "
             + ", ".join(FUNCTIONS))


class FormulaError(BayesprogError, ValueError):
    """A bad formula; ``offset`` is the 0-based column in the text where the problem is."""

    def __init__(self, message: str, offset: int = 0):
        super().__init__(message)
        self.offset = offset


@dataclass(frozen=True)
class Formula:
    """A parsed formula: ``names`` are the variables it uses, in order of first appearance."""

    text: str
    names: tuple[str, ...]
    tree: ast.expr = field(repr=False, compare=False)

    def __str__(self) -> str:
        return self.text

    @property
    def is_constant(self) -> bool:
        return not self.names

    def evaluate(self, values: Mapping[str, Any]) -> np.ndarray:
        """The value for ``values`` of the names (numbers or arrays that broadcast together);
        inf and nan are the caller's to handle."""
        missing = [n for n in self.names if n not in values]
        if missing:
            raise FormulaError(f"no value for {', '.join(missing)} in \"{self.text}\"")
        with np.errstate(all="ignore"):
            return np.asarray(_evaluate(self.tree, values), dtype=float)

    def affine_in(self, targets: Collection[str]) -> bool:
        """Whether the formula is affine in ``targets``, its other names taken as constants
        (``"gain*X + 1"`` is affine in X; its coefficient is then known once gain is).

        >>> parse_formula("gain*X + Y/2").affine_in(["X", "Y"]), parse_formula("X*Y").affine_in(["X"])
        (True, True)
        >>> parse_formula("X*Y").affine_in(["X", "Y"]), parse_formula("exp(X)").affine_in(["X"])
        (False, False)
        """
        return _degree(self.tree, targets) is not None

    def affine(self) -> tuple[float, dict[str, float]] | None:
        """``(intercept, {name: coefficient})`` when the formula is affine in its names (every
        name kept, with 0.0 where its terms cancel), else None (also when a coefficient is
        not finite, ``"X/0"``). Sub-expressions without names are folded to numbers first, so
        ``"exp(0)*X"`` is affine."""
        found = _affine(self.tree)
        if found is None:
            return None
        intercept, coefficients = found
        if not np.all(np.isfinite([intercept, *coefficients.values()])):
            return None
        return intercept, {n: coefficients.get(n, 0.0) for n in self.names}


def _degree(node: ast.AST, targets: Collection[str]) -> int | None:
    """0 where ``node`` holds none of ``targets``, 1 where it is affine in them, else None."""
    names = {n.id for n in ast.walk(node) if isinstance(n, ast.Name)}
    if not names & set(targets):
        return 0
    if isinstance(node, ast.Name):
        return 1
    if isinstance(node, ast.UnaryOp):
        return _degree(node.operand, targets)
    if not isinstance(node, ast.BinOp):
        return None  # a call or a power of a target
    left, right = _degree(node.left, targets), _degree(node.right, targets)
    if left is None or right is None:
        return None
    if isinstance(node.op, (ast.Add, ast.Sub)):
        return max(left, right)
    if isinstance(node.op, ast.Mult):
        return left + right if left + right <= 1 else None
    if isinstance(node.op, ast.Div):
        return left if right == 0 else None
    return None


def parse_formula(text: str, names: Collection[str] | None = None) -> Formula:
    """Parse ``text``; with ``names``, any other variable name is an error."""
    if len(text) > MAX_LENGTH:
        raise FormulaError(f"formula of {len(text)} characters: expected at most {MAX_LENGTH}")
    depth = deepest = 0
    for char in text:
        depth += char == "("
        depth -= char == ")"
        deepest = max(deepest, depth)
    if deepest > MAX_DEPTH:
        raise FormulaError(f"formula nested {deepest} parentheses deep: expected at most "
                           f"{MAX_DEPTH}")
    if not text.strip():
        raise FormulaError("empty formula: expected a number or an expression")
    for name in names or ():
        if name in FUNCTIONS or name in CONSTANTS:
            raise FormulaError(f"variable {name!r} has the name of a formula's "
                               f"{'function' if name in FUNCTIONS else 'constant'}; rename it")
    try:
        tree = ast.parse(text.strip(), mode="eval").body
    except SyntaxError as exc:
        raise FormulaError(f"syntax error in \"{text}\": {exc.msg}; {_EXPECTED}",
                           max((exc.offset or 1) - 1, 0)) from None
    except (RecursionError, MemoryError):
        raise FormulaError(f"formula \"{text[:40]}...\" is nested too deeply") from None
    used: dict[str, None] = {}
    _check(tree, text, names, used)
    return Formula(text, tuple(used), tree)


def substitute(formula: Formula, name: str, text: str) -> Formula:
    """``formula`` with the variable ``name`` replaced by the formula ``text``.

    >>> str(substitute(parse_formula("2*D + 1"), "D", "sqrt(X**2 + 9)"))
    '2 * sqrt(X ** 2 + 9) + 1'
    """
    inner = parse_formula(text).tree

    class _Swap(ast.NodeTransformer):
        def visit_Name(self, node: ast.Name) -> ast.AST:
            return inner if node.id == name else node

    tree = _Swap().visit(ast.parse(formula.text.strip(), mode="eval")).body
    return parse_formula(ast.unparse(tree))


def _check(node: ast.AST, text: str, names: Collection[str] | None, used: dict) -> None:
    offset = getattr(node, "col_offset", 0)
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise FormulaError(f"{node.value!r} in \"{text}\": {_EXPECTED}", offset)
    elif isinstance(node, ast.Name):
        if node.id in CONSTANTS:
            return
        if node.id in FUNCTIONS:
            raise FormulaError(f"function {node.id!r} used without arguments in \"{text}\"",
                               offset)
        if names is not None and node.id not in names:
            raise FormulaError(f"unknown name {node.id!r} in \"{text}\": expected one of "
                               f"{', '.join(names) or 'no variables'}", offset)
        used[node.id] = None
    elif isinstance(node, ast.BinOp):
        if type(node.op) not in _OPERATORS:
            symbol = ast.unparse(node)[len(ast.unparse(node.left)):].split()[0]
            raise FormulaError(f"unsupported operator {symbol!r} in \"{text}\": {_EXPECTED}",
                               offset)
        _check(node.left, text, names, used)
        _check(node.right, text, names, used)
    elif isinstance(node, ast.UnaryOp):
        if not isinstance(node.op, (ast.UAdd, ast.USub)):
            raise FormulaError(f"unsupported operator in \"{text}\": {_EXPECTED}", offset)
        _check(node.operand, text, names, used)
    elif isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            what = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
            raise FormulaError(f"unknown function {what!r} in \"{text}\": expected one of "
                               f"{', '.join(FUNCTIONS)}", offset)
        arity = FUNCTIONS[node.func.id][0]
        if node.keywords or any(isinstance(a, ast.Starred) for a in node.args):
            raise FormulaError(f"function {node.func.id!r} takes {arity} plain argument(s), "
                               f"found keywords or unpacking in \"{text}\"", offset)
        if len(node.args) != arity:
            raise FormulaError(f"function {node.func.id!r} takes {arity} argument(s), found "
                               f"{len(node.args)} in \"{text}\"", offset)
        for arg in node.args:
            _check(arg, text, names, used)
    else:
        kind = {ast.Attribute: "attribute access", ast.Subscript: "indexing",
                ast.Compare: "comparison", ast.BoolOp: "boolean operator",
                ast.IfExp: "conditional expression", ast.Lambda: "lambda"}.get(
            type(node), type(node).__name__)
        raise FormulaError(f"unsupported {kind} in \"{text}\": {_EXPECTED}", offset)


def _evaluate(node: ast.AST, values: Mapping[str, Any]) -> Any:
    if isinstance(node, ast.Constant):
        return float(node.value)  # type: ignore[arg-type]  # numbers only, checked by parsing
    if isinstance(node, ast.Name):
        return CONSTANTS[node.id] if node.id in CONSTANTS else values[node.id]
    if isinstance(node, ast.BinOp):
        return _OPERATORS[type(node.op)](_evaluate(node.left, values),
                                         _evaluate(node.right, values))
    if isinstance(node, ast.UnaryOp):
        inner = _evaluate(node.operand, values)
        return -inner if isinstance(node.op, ast.USub) else +inner
    assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
    return FUNCTIONS[node.func.id][1](*(_evaluate(a, values) for a in node.args))


def _affine(node: ast.AST) -> tuple[float, dict[str, float]] | None:
    """(intercept, coefficients) of an affine sub-tree, or None: one walk, sub-expressions
    without names folded to numbers on the way."""
    if isinstance(node, ast.Constant):
        return float(node.value), {}  # type: ignore[arg-type]  # numbers only, checked by parsing
    if isinstance(node, ast.Name):
        return (CONSTANTS[node.id], {}) if node.id in CONSTANTS else (0.0, {node.id: 1.0})
    if isinstance(node, ast.UnaryOp):
        inner = _affine(node.operand)
        if inner is None:
            return None
        sign = -1.0 if isinstance(node.op, ast.USub) else 1.0
        return sign * inner[0], {k: sign * v for k, v in inner[1].items()}
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):  # of numbers: folded
        numbers = []
        for arg in node.args:
            found = _affine(arg)
            if found is None or found[1]:
                return None
            numbers.append(found[0])
        with np.errstate(all="ignore"):
            return float(FUNCTIONS[node.func.id][1](*numbers)), {}
    if not isinstance(node, ast.BinOp):
        return None
    left, right = _affine(node.left), _affine(node.right)
    if left is None or right is None:
        return None
    if isinstance(node.op, (ast.Add, ast.Sub)):
        sign = 1.0 if isinstance(node.op, ast.Add) else -1.0
        coefficients = dict(left[1])
        for k, v in right[1].items():
            coefficients[k] = coefficients.get(k, 0.0) + sign * v
        return left[0] + sign * right[0], coefficients
    if isinstance(node.op, ast.Mult) and not (left[1] and right[1]):
        scale, (b, terms) = (left[0], right) if not left[1] else (right[0], left)
        return scale * b, {k: scale * v for k, v in terms.items()}
    if isinstance(node.op, ast.Div) and not right[1] and right[0] != 0:
        return left[0] / right[0], {k: v / right[0] for k, v in left[1].items()}
    if isinstance(node.op, ast.Pow) and not left[1] and not right[1]:
        with np.errstate(all="ignore"):
            return float(np.power(left[0], right[0])), {}
    return None
