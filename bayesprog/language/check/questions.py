"""The checks of the questions and the ablations: a question's variables declared and its values
states or numbers in their support, a program conditioned on variables without a term asked
with their values, an ablation naming a term of the decomposition. :func:`question_problem`
checks a question asked from Python or the command line the same way."""

from __future__ import annotations

import math
from collections.abc import Collection

from bayesprog.errors import did_you_mean
from bayesprog.language.check.base import MAX_TERM_VARIABLES, Checker
from bayesprog.language.loader import Path as YPath
from bayesprog.limits import limit
from bayesprog.model import Term
from bayesprog.vocabulary.expressions import Expression, ExpressionError, parse_expression
from bayesprog.vocabulary.variables import Continuous, Discrete, Variable


class QuestionsCheck(Checker):
    """The ``questions:`` and ``ablate:`` sections."""

    def check_questions(self) -> dict[str, tuple[Expression, str, str]]:
        out: dict[str, tuple[Expression, str, str]] = {}
        for name in self.doc.questions:
            spec = self.doc.question(name)
            raw = self.doc.questions[name]
            path: YPath = ("questions", name) + (() if isinstance(raw, str) else ("ask",))
            try:
                expr = parse_expression(spec.ask)
            except ExpressionError as exc:
                self.error(path, f"question {name!r}: {exc}")
                continue
            problem = question_problem(expr, self.variables, self.conditioning)
            kind = "probability" if expr.event and spec.kind == "posterior" else spec.kind
            if not problem and expr.event and kind != "probability":
                problem = (f"{expr} asks the probability of an event, not a {kind} question "
                           "(leave out kind:, or ask P(searched | known) without values on "
                           "the left)")
            if problem:
                self.error(path, f"question {name!r}: {problem}")
                continue
            out[name] = (expr, kind, spec.description)
        return out

    def check_ablate(self, terms: list[Term]) -> list[Expression]:
        out = []
        for i, text in enumerate(self.doc.ablate):
            try:
                expr = parse_expression(text)
            except ExpressionError as exc:
                self.error(("ablate", i), f"ablate: {exc}")
                continue
            if not any(t.expression.key == expr.key for t in terms if not t.soft):
                known = ", ".join(str(t.expression) for t in terms if not t.soft)
                self.error(("ablate", i), f"ablate: no term {expr} in the decomposition "
                           f"(terms: {known})")
                continue
            out.append(expr)
        return out


def question_problem(expr: Expression, variables: dict[str, Variable],
                     conditioning: Collection[str] = ()) -> str | None:
    """Why ``expr`` cannot be asked of these variables (None if it can), of a program
    conditioned on the variables ``conditioning`` (which have no term)."""
    for name in expr.left + expr.right:
        if name not in variables:
            return (f"undeclared variable {name!r} in {expr}{did_you_mean(name, variables)} "
                    f"(declared: {', '.join(variables)})")
    if conditioning:
        problem = conditioning_problem(expr, conditioning)
        if problem:
            return problem
    for name in expr.left:
        var = variables[name]
        if isinstance(var, Continuous) and var.index is not None:
            return (f"cannot search the field {name!r} (one value per state of {var.index}): "
                    "fields are known or summed out")
    for name, text in expr.values.items():
        var = variables[name]
        if isinstance(var, Discrete):
            try:
                var.index_of(text)
            except KeyError:
                return (f"unknown state {text!r} of {name}{did_you_mean(text, var.states)} "
                        f"(expected one of {var.describe_states()})")
        elif var.index is None:
            try:
                value = float(text)
            except ValueError:
                return f"expected a number for {name}, found {text!r}"
            if not var.low <= value <= var.high:
                return (f"{name}={value} is outside its support [{var.low}, {var.high}]")
    searched = [v for name in expr.left if isinstance(v := variables[name], Discrete)]
    # a joint answer past the size limit is refused by the engine, with its estimate; one of
    # many variables of one state each would pass it and still not fit numpy's arrays
    if (len(searched) > MAX_TERM_VARIABLES and len(searched) == len(expr.left)
            and math.prod(v.card for v in searched) <= limit("entries")):
        return (f"{expr} searches {len(searched)} variables jointly; expected at most "
                f"{MAX_TERM_VARIABLES} (its answer has one axis per variable, and numpy's "
                "arrays take 32 axes, one of them for a batch)")
    return None


def conditioning_problem(expr: Expression, conditioning: Collection[str]) -> str | None:
    """Why ``expr`` cannot be asked of a program conditioned on ``conditioning`` (None if it
    can): a variable without a term has no distribution, so a question gives its value; it
    is neither searched nor summed out.

    >>> problem = conditioning_problem(parse_expression("P(X | Y=y0)"), ["U"])
    >>> problem.startswith("P(X | Y=y0) leaves U unknown, but U has no term"), problem[-23:]
    (True, 'expected P(X | Y=y0, U)')
    """
    searched = [n for n in conditioning if n in expr.left]
    unknown = [n for n in conditioning if n not in expr.left and n not in expr.right]
    if not searched and not unknown:
        return None
    names = searched + unknown
    listed = ", ".join(names)
    has = "have no term" if len(names) > 1 else "has no term"
    what = (f"searches {', '.join(searched)}" if searched else "") + (
        " and " if searched and unknown else "") + (
        f"leaves {', '.join(unknown)} unknown" if unknown else "")
    left = tuple(n for n in expr.left if n not in searched)
    fix = ""
    if left:
        given = Expression(left, expr.right + tuple(names), expr.values)
        fix = f": expected {given}"
    return (f"{expr} {what}, but {listed} {has} in the decomposition (the program is "
            f"conditioned on {'them' if len(names) > 1 else 'it'}), so every question gives "
            f"{'their values' if len(names) > 1 else 'its value'}{fix}")
