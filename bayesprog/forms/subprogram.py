"""The ``program`` form: another program's answer used as a term (a sub-program).

``P(X | Y) = P_sub(X | Y, bound...)``: the sub-program is asked its question for every state of
the term's parents at once (the parents become batch axes of the sub-question), in the same call
as the outer question. Used under ``soft_evidence:``, the answer ``P_sub(X | ...)`` multiplies
the outer program as a likelihood over ``X``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bayesprog.errors import ProgramCycleError, SpecError, did_you_mean
from bayesprog.expressions import ExpressionError, parse_expression
from bayesprog.files import reference_problem
from bayesprog.forms.base import Form, InputRef, ParamValue, TermContext, register_form


def _fills_field(sub: Any, name: str, decl: Any, term: Any) -> bool:
    """Whether input ``decl``, bound to ``name`` of the sub-program, gives one value per state of
    a variable of the term (so the same states there) to a field of ``sub`` indexed by it."""
    field = sub.variables.get(name)
    own = {term.child.name, *(p.name for p in term.parents)}
    return (len(decl.axes) == 1 and not decl.event and decl.axes[0] in own
            and field is not None and getattr(field, "index", None) == decl.axes[0])


@register_form
class ProgramForm(Form):
    """A term whose distribution is a question of another program file.

    Parameters: ``program`` (a path relative to this file), ``question`` (a question name of
    that program, or ``P(X | ...)``), ``bind`` (values or ``{input: NAME}`` for the
    sub-question's known variables that are not parents of the term, and for its inputs).
    """

    name = "program"
    child_kinds = ("discrete",)
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
        for var in (term.child,) + tuple(term.parents):
            other = sub.variables.get(var.name)
            if other is None or not other.is_discrete or other.states != var.states:
                problems.append(f"variable {var.name!r} must have the same states in "
                                f"{raw['program']!r}")
            elif var is not term.child and var.name not in expr.right:
                problems.append(f"parent {var.name!r} must be known in the sub-question {expr}")
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
            if name not in expr.right and name not in sub.inputs:
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
            else:
                term.params[f"bind:{name}"] = ParamValue((), np.asarray(value))
        for message in problems:
            checker.error(path, f"{what}: {message}")
        term.extra.update(program=sub, question=expr, source=raw["program"])
        return len(checker.problems) - before

    def log_factor(self, ctx: TermContext) -> np.ndarray:
        sub = ctx.extra["program"]  # a Program: asked like any other
        expr = ctx.extra["question"]
        parents = ctx.axes[1:]
        lead = 1 + len(parents)
        evidence: dict[str, Any] = {}
        inputs: dict[str, Any] = {}
        for i, name in enumerate(parents):
            shape = [1] * lead
            states = ctx.variables[name].states  # type: ignore[union-attr]
            shape[1 + i] = len(states)
            # by name: an integer would read as a value for a range variable
            evidence[name] = np.asarray(states).reshape(shape)
        for key, value in ctx.params.items():
            name = key.removeprefix("bind:")
            arr = value.array if value.batched else value.array[np.newaxis]
            trailing = arr.shape[1:]
            arr = arr.reshape(arr.shape[:1] + (1,) * len(parents) + trailing)
            if arr.dtype.kind in "US" or arr.dtype == object:
                arr = arr.astype(str)
            (inputs if name in sub.inputs else evidence)[name] = arr
        answer = sub.ask(expr, evidence=evidence, inputs=inputs)
        probs = answer.probabilities.reshape((-1,) + answer.probabilities.shape[-1 - len(parents):])
        with np.errstate(divide="ignore"):
            return np.moveaxis(np.log(probs), -1, 1)
