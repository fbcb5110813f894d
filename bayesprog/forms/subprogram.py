"""The ``program`` form: another program's answer used as a term (a sub-program).

``P(X | Y) = P_sub(X | Y, bound...)``: the sub-program is asked its question for every state of
the term's parents at once (the parents become batch axes of the sub-question), in the same call
as the outer question. Used under ``soft_evidence:``, the answer ``P_sub(X | ...)`` multiplies
the outer program as a likelihood over ``X``.

A real child ``X`` takes the sub-program's density (a Gaussian or a mixture of Gaussians, or
bins): its log at the value of ``X`` where ``X`` is known, its CDF at the edges of the bins of
a discretised ``X`` (and of the grid method's), its quantile function where ``X`` is drawn.
A real parent passes its value (a discretised one, its bin's midpoint) to the sub-question.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bayesprog.errors import ProgramCycleError, QuestionError, SpecError, did_you_mean
from bayesprog.forms.base import (
    Form,
    FormulaParam,
    InputRef,
    ParamValue,
    TermContext,
    is_binned,
    register_form,
)
from bayesprog.support.files import reference_problem
from bayesprog.vocabulary.expressions import ExpressionError, parse_expression
from bayesprog.vocabulary.formula import FormulaError, parse_formula


def _fills_field(sub: Any, name: str, decl: Any, term: Any) -> bool:
    """Whether input ``decl``, bound to ``name`` of the sub-program, gives one value per state of
    a variable of the term (so the same states there) to a field of ``sub`` indexed by it."""
    field = sub.variables.get(name)
    own = {term.child.name, *(p.name for p in term.parents)}
    return (len(decl.axes) == 1 and not decl.event and decl.axes[0] in own
            and field is not None and getattr(field, "index", None) == decl.axes[0])


def _is_real(var: Any) -> bool:
    """A real variable that is not a field (discretised or not)."""
    return var is not None and getattr(var, "index", None) is None and (
        not var.is_discrete or is_binned(var))


def _support(var: Any) -> tuple[float, float]:
    return tuple(var.support) if is_binned(var) else (var.low, var.high)


def _child_problem(child: Any, other: Any, source: str) -> str | None:
    """Why the sub-program's variable ``other`` cannot give the term's child its distribution:
    the same states for a discrete child, a real variable of the same support for a real one
    (discretised here or not: the bins take their probability from its density)."""
    if not _is_real(child):
        if getattr(child, "index", None) is not None:
            return (f"{child.name!r} is a field (one value per state of {child.index}): "
                    "expected a discrete or a real child")
        if other is None or not other.is_discrete or other.states != child.states:
            return f"variable {child.name!r} must have the same states in {source!r}"
        return None
    low, high = _support(child)
    if _is_real(other) and not is_binned(other) and _support(other) == (low, high):
        return None
    found = ("not declared" if other is None else
             "discretised" if is_binned(other) else
             "discrete" if other.is_discrete else
             "a field" if not _is_real(other) else
             f"on [{other.low:g}, {other.high:g}]")
    here = "discretised" if is_binned(child) else "real"
    return (f"variable {child.name!r} is {here} here: expected it real on [{low:g}, {high:g}] "
            f"in {source!r} too (its density is the term's), found it {found}")


def _parent_value(var: Any, other: Any, source: str) -> ParamValue | FormulaParam | str:
    """What the term passes to the sub-question's known variable ``var``: its states (a
    discrete parent of the same states there), or its value (a real parent, real there too;
    a discretised parent passes its bin's midpoint), as a parameter over the term's own axes;
    else why it cannot."""
    if (var.is_discrete and other is not None and other.is_discrete
            and other.states == var.states):
        # by name: an integer would read as a value for a range variable
        return ParamValue((var.name,), np.asarray(var.states))
    if _is_real(var) and _is_real(other) and not is_binned(other):
        try:
            formula = parse_formula(var.name, names=[var.name])
        except FormulaError as exc:
            return f"parent {var.name!r} cannot pass its value to {source!r}: {exc}"
        table = np.empty((), dtype=object)
        table[()] = formula
        return FormulaParam((), table)
    if not var.is_discrete:
        return f"variable {var.name!r} is real here: expected it real in {source!r} too"
    if is_binned(var):
        return (f"variable {var.name!r} must have the same bins in {source!r}, or be real "
                "there")
    return f"variable {var.name!r} must have the same states in {source!r}"


@register_form
class ProgramForm(Form):
    """A term whose distribution is a question of another program file.

    Parameters: ``program`` (a path relative to this file), ``question`` (a question name of
    that program, or ``P(X | ...)``), ``bind`` (values or ``{input: NAME}`` for the
    sub-question's known variables that are not parents of the term, and for its inputs).
    """

    name = "program"
    child_kinds = ("discrete", "continuous")
    soft_evidence = True
    subprogram = True

    def resolve(self, term: Any, raw: dict[str, Any], checker: Any, path: tuple) -> int:
        before = len(checker.problems)
        what = f"term {term.label}: program"
        for key in raw:
            if key not in ("program", "question", "bind"):
                checker.error(path + (key,), f"{what}: unknown parameter {key!r}: expected "
                              "program, question, bind", at_key=True)
        if not isinstance(raw.get("program"), str) or not isinstance(raw.get("question"), str):
            checker.error(path, f"{what}: expected 'program: FILE' and 'question: NAME or "
                          "P(X | ...)'")
            return len(checker.problems) - before
        file = Path(raw["program"])
        file = file if file.is_absolute() else checker.base_dir / file
        if checker.load_program is None:
            checker.error(path + ("program",), f"{what}: sub-programs cannot be loaded here")
            return len(checker.problems) - before
        problem = reference_problem(file, "program", raw["program"])
        if problem:
            checker.error(path + ("program",), f"{what} {raw['program']!r}: {problem}")
            return len(checker.problems) - before
        try:
            sub = checker.load_program(file, tuple(v.name for v in (term.child,
                                                                    *term.parents)))
        except ProgramCycleError as exc:
            checker.error(path + ("program",), f"{what} {raw['program']!r}: programs that name "
                          f"each other in a circle ({exc}): expected a program that does not "
                          "lead back to this one")
            return len(checker.problems) - before
        except SpecError as exc:
            checker.error(path + ("program",), f"{what} {raw['program']!r} has "
                          f"{len(exc.diagnostics)} problem(s), listed with its own file")
            checker.problems.extend(exc.diagnostics)
            return len(checker.problems) - before
        except OSError as exc:
            checker.error(path + ("program",), f"{what}: cannot read {raw['program']!r}: "
                          f"{exc.strerror or exc}")
            return len(checker.problems) - before
        question = raw["question"]
        if question in sub.questions:
            expr = sub.questions[question].expression
        else:
            try:
                expr = parse_expression(question)
            except ExpressionError as exc:
                named = ", ".join(sub.questions) or "none"
                if "(" not in question:  # a name: misspelt, or not one of the other file's
                    checker.error(path + ("question",), f"{what}: {question!r} is not a "
                                  f"question of {raw['program']!r}"
                                  f"{did_you_mean(question, sub.questions)} (its questions: "
                                  f"{named}); expected one of them, or P({term.child.name} | "
                                  "...)")
                else:
                    checker.error(path + ("question",), f"{what}: {question!r} is neither a "
                                  f"question of {raw['program']!r} ({named}) nor an "
                                  f"expression: {exc}")
                return len(checker.problems) - before
        problems = []
        if expr.left != (term.child.name,):
            problems.append(f"the sub-question {expr} must search exactly "
                            f"{term.child.name!r}")
        child_problem = _child_problem(term.child, sub.variables.get(term.child.name),
                                       raw["program"])
        if child_problem:
            problems.append(child_problem)
        for var in term.parents:
            value = _parent_value(var, sub.variables.get(var.name), raw["program"])
            if isinstance(value, str):
                problems.append(value)
            elif var.name not in expr.right:
                problems.append(f"parent {var.name!r} must be known in the sub-question {expr}")
            else:
                term.params[f"parent:{var.name}"] = value
        bind = raw.get("bind") or {}
        if not isinstance(bind, dict):
            problems.append("bind: expected a mapping NAME: value or NAME: {input: INPUT}")
            bind = {}
        parents = {p.name for p in term.parents}
        needed = [n for n in expr.right if n not in parents and n not in expr.values]
        for name in needed:
            if name not in bind:
                problems.append(f"the sub-question's known variable {name!r} needs a value in "
                                "bind")
        for name, value in bind.items():
            if name in parents:
                problems.append(f"bind: {name!r} is a parent of the term: the sub-question "
                                f"takes its value from this program's {name}")
            elif name not in expr.right and name not in sub.inputs:
                problems.append(f"bind: {name!r} is neither a known variable of {expr} nor an "
                                f"input of {raw['program']!r}")
            elif isinstance(value, dict) and set(value) == {"input"}:
                decl = checker.inputs.get(value["input"])
                if decl is None:
                    problems.append(f"bind: unknown input {value['input']!r}")
                elif decl.axes and not _fills_field(sub, name, decl, term):
                    problems.append(f"bind: input {value['input']!r} must not vary over "
                                    "variables, except one of the term's own, bound to a "
                                    f"field of {raw['program']!r} indexed by it")
                else:
                    term.params[f"bind:{name}"] = InputRef(value["input"])
                    if decl.axes:
                        term.extra.setdefault("fields", []).append(value["input"])
            else:
                term.params[f"bind:{name}"] = ParamValue((), np.asarray(value))
        for message in problems:
            checker.error(path, f"{what}: {message}")
        term.extra.update(program=sub, question=expr, source=raw["program"])
        return len(checker.problems) - before

    def log_factor(self, ctx: TermContext) -> np.ndarray:
        answer, parents = self._answer(ctx)
        if not _is_real(ctx.child):
            probs = answer.probabilities
            probs = probs.reshape((-1,) + probs.shape[probs.ndim - 1 - len(parents):])
            with np.errstate(divide="ignore"):
                return np.moveaxis(np.log(probs), -1, 1)
        x, rows = np.broadcast_arrays(ctx.child_value(), _rows(answer, len(parents)))
        return answer.log_pdf_at(ctx.child.name, x, rows)

    def cdf(self, ctx: TermContext) -> np.ndarray:
        """The sub-program's CDF at the child's values (the edges of its bins)."""
        answer, parents = self._answer(ctx)
        rows = _rows(answer, len(parents))
        if len(parents) < len(ctx.axes):  # a discretised child: its own axis, after the batch's
            rows = rows[:, np.newaxis]
        x, rows = np.broadcast_arrays(ctx.child_value(), rows)
        return answer.cdf_at(ctx.child.name, x, rows)

    def draw(self, ctx: TermContext, u: np.ndarray) -> np.ndarray:
        """The sub-program asked once for every draw (its parents' states and values, and the
        bound values, at that draw), each value its answer's quantile at ``u[..., 0]``, taken
        between the CDF at the bounds of a bounded support."""
        child = ctx.child
        fields = ctx.extra.get("fields")
        if fields:
            raise QuestionError(f"{child.name} cannot be drawn from {ctx.extra['source']}: "
                                f"the term binds the input {fields[0]!r}, one value per state, "
                                f"to a field of it; give {child.name} as evidence")
        draws = u.shape[:-1]
        size = int(np.prod(draws))
        params = {k: ParamValue((), v.array.reshape((size,) + v.array.shape[len(draws):]),
                                True) for k, v in ctx.params.items()}
        answer, _ = self._answer(TermContext(child, (), (), (), params, None, ctx.variables,
                                             ctx.extra))
        rows = np.broadcast_to(_rows(answer, 0).reshape(-1), (size,))
        low, high = child.low, child.high  # type: ignore[union-attr]
        below = answer.cdf_at(child.name, np.full(size, low), rows) if np.isfinite(low) \
            else np.zeros(size)
        inside = (answer.cdf_at(child.name, np.full(size, high), rows) if np.isfinite(high)
                  else np.ones(size)) - below
        if not np.all(inside > 0):
            raise QuestionError(f"{ctx.extra['source']}: {ctx.extra['question']} puts no "
                                f"probability inside the support [{low:g}, {high:g}] of "
                                f"{child.name} at some of its draws: it cannot be drawn there")
        values = answer.quantile_at(child.name, below + u.reshape(size, -1)[:, 0] * inside, rows)
        return np.clip(values, low, high).reshape(draws)

    def _answer(self, ctx: TermContext) -> tuple[Any, tuple[str, ...]]:
        """The sub-program's answer for every state of the term's discrete parents (batch axes
        after the question's: ``[batch or 1] + cards``), and those parents."""
        sub = ctx.extra["program"]  # a Program: asked like any other
        own = bool(ctx.axes) and ctx.axes[0] == ctx.child.name
        parents = ctx.axes[1:] if own else ctx.axes
        evidence: dict[str, Any] = {}
        inputs: dict[str, Any] = {}
        for key, value in ctx.params.items():
            kind, _, name = key.partition(":")
            if kind == "parent":
                arr = value.aligned(parents, 0)
            else:  # bound values and inputs: their own shape after the batch and the parents
                arr = value.array if value.batched else value.array[np.newaxis]
                arr = arr.reshape(arr.shape[:1] + (1,) * len(parents) + arr.shape[1:])
            if arr.dtype.kind in "US" or arr.dtype == object:
                arr = arr.astype(str)
            (inputs if name in sub.inputs else evidence)[name] = arr
        return sub.ask(ctx.extra["question"], evidence=evidence, inputs=inputs), parents


def _rows(answer: Any, parents: int) -> np.ndarray:
    """The flat row of ``answer`` at each place of its batch, ``[batch or 1]`` then the last
    ``parents`` axes of the batch (the term's discrete parents)."""
    rows = np.arange(int(np.prod(answer.batch_shape))).reshape(answer.batch_shape)
    return rows.reshape((-1,) + rows.shape[rows.ndim - parents:])
