"""Formulas that a program file may give as a parameter value.

``mean: "2*X + 1"``, ``value: "sqrt(X**2 + Y**2)"``, ``value: "A == B"`` or
``value: "min(max(X0 + U, 0), 9)"``: numbers, variable names, ``+ - * / ** % //``, unary ``-``
and ``+``, parentheses, comparisons (``== != < <= > >=``, chained as in Python), ``and``,
``or``, ``not``, ``a if cond else b``, and calls of a fixed set of numpy functions. A
comparison or a boolean operator gives 1 for true and 0 for false; ``and``, ``or``, ``not``,
``where`` and ``if`` read any value but 0 as true. The text is parsed by Python's own parser
(:func:`ast.parse`) and the tree is walked against that grammar; nothing is ever executed by
Python, so no text can reach anything else.

A variable whose states are names (``states: [red, green]``) may only be compared, for equality,
with another of the same states or with one of its states quoted (``Colour == 'red'``):
:meth:`Formula.with_states` checks that and reads the states as their indices.

>>> f = parse_formula("2*X + 1 - (Y - 3)/4", names=["X", "Y"])
>>> f.names, float(f.evaluate({"X": 1.0, "Y": 7.0}))
(('X', 'Y'), 2.0)
>>> f.affine()
(1.75, {'X': 2.0, 'Y': -0.25})
>>> parse_formula("X*Y").affine() is None
True
>>> g = parse_formula("min(max(X0 + U, 0), 9)")
>>> g.evaluate({"X0": np.array([0.0, 5.0, 9.0]), "U": 1.0}).tolist(), g.evaluate({"X0": 0.0, "U": -1.0}).tolist()
([1.0, 6.0, 9.0], 0.0)
>>> parse_formula("A == B").evaluate({"A": np.arange(3.0)[:, None], "B": np.arange(3.0)}).tolist()
[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
"""

from __future__ import annotations

import ast
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bayesprog.errors import BayesprogError, did_you_mean


def _where(condition: Any, a: Any, b: Any) -> Any:
    return np.where(np.asarray(condition) != 0, a, b)


#: Functions a formula may call, by the number of their arguments (``min`` and ``max`` take
#: two or more). ``round`` rounds halves to the even integer, as Python and numpy do; ``mod``
#: (and ``%``) takes the sign of the divisor, as Python's ``%``.
FUNCTIONS: dict[str, tuple[int, Any]] = {
    **{name: (1, getattr(np, name)) for name in (
        "abs", "sqrt", "exp", "log", "log1p", "expm1", "sin", "cos", "tan", "arcsin",
        "arccos", "arctan", "sinh", "cosh", "tanh", "floor", "ceil", "sign")},
    "round": (1, np.round),
    **{name: (2, getattr(np, name)) for name in (
        "arctan2", "hypot", "minimum", "maximum", "power")},
    "min": (2, np.minimum), "max": (2, np.maximum), "mod": (2, np.mod),
    "clip": (3, np.clip), "where": (3, _where),
}
#: Functions that take two or more arguments (``min(a, b, c)``).
VARIADIC = frozenset({"min", "max"})
CONSTANTS = {"pi": float(np.pi), "e": float(np.e)}
#: Longest text and deepest nesting accepted (Python's parser itself fails on deep nesting).
MAX_LENGTH = 1000
MAX_DEPTH = 50

_OPERATORS = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply,
              ast.Div: np.divide, ast.Pow: np.power, ast.Mod: np.mod,
              ast.FloorDiv: np.floor_divide}
_COMPARISONS = {ast.Eq: np.equal, ast.NotEq: np.not_equal, ast.Lt: np.less,
                ast.LtE: np.less_equal, ast.Gt: np.greater, ast.GtE: np.greater_equal}
_EXPECTED = ("expected numbers, variable names, + - * / ** % //, comparisons, and, or, not, "
             "parentheses and the functions " + ", ".join(FUNCTIONS))


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
        inf and nan are the caller's to handle. A variable of named states takes the index of
        its state (see :meth:`with_states`)."""
        missing = [n for n in self.names if n not in values]
        if missing:
            raise FormulaError(f"no value for {', '.join(missing)} in \"{self.text}\"")
        quoted = next((n for n in ast.walk(self.tree)
                       if isinstance(n, ast.Constant) and isinstance(n.value, str)), None)
        if quoted is not None:
            raise FormulaError(f"the quoted state {quoted.value!r} in \"{self.text}\" is "
                               "compared with no variable of named states", quoted.col_offset)
        with np.errstate(all="ignore"):
            return np.asarray(_evaluate(self.tree, values), dtype=float)

    def with_states(self, states: Mapping[str, tuple[str, ...]]) -> Formula:
        """The formula with the variables of named states in ``states`` read as the indices of
        their states: each may only be compared for equality (``==``, ``!=``) with another
        variable of the same states or with one of its states quoted, which becomes its index.

        >>> f = parse_formula("Colour == 'green' or Colour == Other")
        >>> states = {"Colour": ("red", "green"), "Other": ("red", "green")}
        >>> f.with_states(states).evaluate({"Colour": np.array([0.0, 1.0]), "Other": 0.0}).tolist()
        [1.0, 1.0]
        >>> parse_formula("Colour + 1").with_states(states)
        Traceback (most recent call last):
        ...
        bayesprog.vocabulary.formula.FormulaError: Colour has named states (red, green): in "Colour + 1" it may only be compared with == or != to a variable of the same states or to one of its states quoted ('red')
        """
        names = {n for n in self.names if n in states}
        quoted = [n for n in ast.walk(self.tree)
                  if isinstance(n, ast.Constant) and isinstance(n.value, str)]
        if not names and not quoted:
            return self
        tree = ast.parse(self.text.strip(), mode="eval").body
        compared: set[int] = set()  # ids of the nodes a comparison of states reads
        for node in ast.walk(tree):
            if not isinstance(node, ast.Compare):
                continue
            sides = [node.left, *node.comparators]
            named = [s for s in sides if isinstance(s, ast.Name) and s.id in names]
            if not named:
                continue
            first = states[named[0].id]
            for side in sides:
                if isinstance(side, ast.Name) and side.id in names and states[side.id] == first:
                    compared.add(id(side))
                elif (isinstance(side, ast.Constant) and isinstance(side.value, str)
                      and side.value in first):
                    compared.add(id(side))
                else:
                    what = (f"the state {side.value!r}, which is not one of "
                            f"{named[0].id}'s ({', '.join(first)})"
                            if isinstance(side, ast.Constant) and isinstance(side.value, str)
                            else f"{ast.unparse(side)!r}")
                    raise FormulaError(f"{named[0].id} has named states: in \"{self.text}\" it "
                                       f"is compared with {what}; expected another variable "
                                       "of the same states or one of its states quoted",
                                       side.col_offset)
            if not all(isinstance(op, (ast.Eq, ast.NotEq)) for op in node.ops):
                raise FormulaError(f"{named[0].id} has named states: in \"{self.text}\" it may "
                                   "only be compared with == or !=", node.col_offset)
            index = {state: i for i, state in enumerate(first)}
            for i, side in enumerate(node.comparators):
                if isinstance(side, ast.Constant) and isinstance(side.value, str):
                    node.comparators[i] = ast.copy_location(ast.Constant(index[side.value]), side)
            if isinstance(node.left, ast.Constant) and isinstance(node.left.value, str):
                node.left = ast.copy_location(ast.Constant(index[node.left.value]), node.left)
        for node in ast.walk(tree):
            if isinstance(node, ast.Name) and node.id in names and id(node) not in compared:
                shown = ", ".join(states[node.id])
                raise FormulaError(f"{node.id} has named states ({shown}): in \"{self.text}\" "
                                   "it may only be compared with == or != to a variable of the "
                                   "same states or to one of its states quoted "
                                   f"({states[node.id][0]!r})", node.col_offset)
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                raise FormulaError(f"the quoted state {node.value!r} in \"{self.text}\" is "
                                   "compared with no variable of named states", node.col_offset)
        return Formula(self.text, self.names, tree)

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
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
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


def _check(node: ast.AST, text: str, names: Collection[str] | None, used: dict,
           compared: bool = False) -> None:
    """Walk ``node`` against the grammar; ``compared``: ``node`` is a side of a comparison,
    where a quoted state may stand."""
    offset = getattr(node, "col_offset", 0)
    if isinstance(node, ast.Constant):
        if isinstance(node.value, str) and compared:
            return  # a state's name, read by Formula.with_states
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
                               f"{', '.join(names) or 'no variables'}"
                               f"{did_you_mean(node.id, names)}", offset)
        used[node.id] = None
    elif isinstance(node, ast.BinOp):
        if type(node.op) not in _OPERATORS:
            symbol = ast.unparse(node)[len(ast.unparse(node.left)):].split()[0]
            raise FormulaError(f"unsupported operator {symbol!r} in \"{text}\": {_EXPECTED}",
                               offset)
        _check(node.left, text, names, used)
        _check(node.right, text, names, used)
    elif isinstance(node, ast.UnaryOp):
        if not isinstance(node.op, (ast.UAdd, ast.USub, ast.Not)):
            raise FormulaError(f"unsupported operator in \"{text}\": {_EXPECTED}", offset)
        _check(node.operand, text, names, used)
    elif isinstance(node, ast.Compare):
        for op in node.ops:
            if type(op) not in _COMPARISONS:
                word = "is" if isinstance(op, (ast.Is, ast.IsNot)) else "in"
                raise FormulaError(f"unsupported comparison {word!r} in \"{text}\": expected "
                                   "== != < <= > >=", offset)
        for side in (node.left, *node.comparators):
            _check(side, text, names, used, compared=True)
    elif isinstance(node, ast.BoolOp):
        for value in node.values:
            _check(value, text, names, used)
    elif isinstance(node, ast.IfExp):
        for part in (node.test, node.body, node.orelse):
            _check(part, text, names, used)
    elif isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            what = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
            raise FormulaError(f"unknown function {what!r} in \"{text}\": expected one of "
                               f"{', '.join(FUNCTIONS)}{did_you_mean(what, FUNCTIONS)}", offset)
        name = node.func.id
        arity = FUNCTIONS[name][0]
        takes = f"{arity} or more" if name in VARIADIC else str(arity)
        if node.keywords or any(isinstance(a, ast.Starred) for a in node.args):
            raise FormulaError(f"function {name!r} takes {takes} plain argument(s), "
                               f"found keywords or unpacking in \"{text}\"", offset)
        if len(node.args) != arity and not (name in VARIADIC and len(node.args) > arity):
            raise FormulaError(f"function {name!r} takes {takes} argument(s), found "
                               f"{len(node.args)} in \"{text}\"", offset)
        for arg in node.args:
            _check(arg, text, names, used)
    else:
        kind = {ast.Attribute: "attribute access", ast.Subscript: "indexing",
                ast.Lambda: "lambda"}.get(type(node), type(node).__name__)
        raise FormulaError(f"unsupported {kind} in \"{text}\": {_EXPECTED}", offset)


def _truth(value: Any) -> Any:
    return np.asarray(value) != 0


def _call(name: str, args: list[Any]) -> Any:
    function = FUNCTIONS[name][1]
    if name in VARIADIC:
        out = args[0]
        for arg in args[1:]:
            out = function(out, arg)
        return out
    return function(*args)


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
        if isinstance(node.op, ast.Not):
            return np.logical_not(_truth(inner)).astype(float)
        return -inner if isinstance(node.op, ast.USub) else +inner
    if isinstance(node, ast.Compare):
        left, out = _evaluate(node.left, values), True
        for op, right_node in zip(node.ops, node.comparators, strict=True):
            right = _evaluate(right_node, values)
            out = np.logical_and(out, _COMPARISONS[type(op)](left, right))
            left = right
        return np.asarray(out, dtype=float)
    if isinstance(node, ast.BoolOp):
        combine = np.logical_and if isinstance(node.op, ast.And) else np.logical_or
        parts = [_truth(_evaluate(v, values)) for v in node.values]
        out = parts[0]
        for part in parts[1:]:
            out = combine(out, part)
        return np.asarray(out, dtype=float)
    if isinstance(node, ast.IfExp):
        return _where(_evaluate(node.test, values), _evaluate(node.body, values),
                      _evaluate(node.orelse, values))
    assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
    return _call(node.func.id, [_evaluate(a, values) for a in node.args])


def _affine(node: ast.AST) -> tuple[float, dict[str, float]] | None:
    """(intercept, coefficients) of an affine sub-tree, or None: one walk, sub-expressions
    without names folded to numbers on the way."""
    if isinstance(node, ast.Constant):
        return float(node.value), {}  # type: ignore[arg-type]  # numbers only, checked by parsing
    if isinstance(node, ast.Name):
        return (CONSTANTS[node.id], {}) if node.id in CONSTANTS else (0.0, {node.id: 1.0})
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
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
            return float(_call(node.func.id, numbers)), {}
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
