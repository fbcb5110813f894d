"""The dispatcher (see :mod:`bayesprog.inference`): a question's answer by the method it
names, the layout's one answer when it does not depend on the evidence's values, the method
settled for its batch size, or the cheapest that the layout's ranking finds."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from bayesprog.errors import QuestionError
from bayesprog.inference.answers import MapResult, Posterior, check_zero, choose_map
from bayesprog.inference.binding import Bound, bind
from bayesprog.inference.cost import ranked, refined, unanswerable, why_not
from bayesprog.inference.density import Density
from bayesprog.inference.methods import (
    Cost,
    Method,
    base,
    registered_methods,
    registry_version,
)
from bayesprog.inference.methods.base import (
    PER_CALL,
    PER_FACTOR,
    first_answerers,
    own_methods_only,
)
from bayesprog.inference.plan import QuestionPlan
from bayesprog.inference.protocol import ProgramLike
from bayesprog.limits import check_size, limit
from bayesprog.vocabulary.expressions import Expression, Question
from bayesprog.vocabulary.variables import Discrete


def compute_posterior(program: ProgramLike, question: Question, bound: Bound,
                      method: str | None = None,
                      options: Mapping[str, Any] | None = None) -> Posterior | Density:
    """The posterior of ``question`` for bound evidence (a density when it searches real
    variables): by ``method`` when it is named; else the layout's answer when it does not
    depend on the evidence's values, its first question's answer with nothing planned, the
    method settled for this batch size, or the cheapest that the ranking finds (exact, or
    approximate with its error where no exact method applies)."""
    plan = QuestionPlan(program, question, bound, dict(options) if options else {})
    schedule = plan.layout.schedule
    if method is not None:
        return named(plan, method)
    if schedule.fixed is not None:
        return _constant(plan, schedule.fixed)
    if not schedule.asked and own_methods_only():  # (a method of one's own is ranked at once)
        answer = _first(plan)
        if answer is not None:
            return answer
    settled = schedule.settled.get((registry_version(), bound.size, limit("entries")))
    if settled is not None:  # no setup was left to weigh for this batch size
        answer = settled.posterior(plan)
        if answer is not None:
            answer.method = answer.method or settled.name
            return with_evidence(plan, answer, settled.exact)
    return _ranked(plan)


def named(plan: QuestionPlan, method: str) -> Posterior | Density:
    """The answer of the method the question names; an exact method's answer to a layout
    whose answer does not depend on the evidence's values is kept, and given again."""
    schedule = plan.layout.schedule
    schedule.asked = True  # its method prepares what the layout's later questions use
    fixed = schedule.fixed_by.get(method)
    if fixed is not None:
        return _constant(plan, fixed)
    answer = _by(method, plan)
    exact = registered_methods()[method].exact
    if exact and plan.layout.constant and isinstance(answer, Posterior):
        schedule.fixed_by[method] = _first_row(plan, answer)
    return with_evidence(plan, answer, exact)


def _first_row(plan: QuestionPlan, answer: Posterior) -> tuple[np.ndarray, float, str]:
    """A layout's one answer, from ``answer`` (before its evidence is deferred): its first
    row of probabilities ``[1] + cards``, the log of its normaliser, and its method."""
    first = answer.probabilities.reshape((plan.bound.size,) + plan.layout.cards)[:1]
    return first.copy(), float(answer.log_evidence.flat[0]), answer.method


def _constant(plan: QuestionPlan, fixed: tuple[np.ndarray, float, str]
              ) -> Posterior | Density:
    """The layout's one answer, when it is the same whatever the evidence's values."""
    size = plan.bound.size
    row, normaliser, name = fixed
    if size == 1:
        rows, logs = row.copy(), np.array([normaliser])
    else:
        rows, logs = np.repeat(row, size, axis=0), np.full(size, normaliser)
    return with_evidence(plan, base.answer(plan, rows, logs, method=name))


def _first(plan: QuestionPlan) -> Posterior | Density | None:
    """A layout's first question, answered by a method that needs no plan for it (the
    contraction's elimination); asked only while every registered method is the package's
    own (the cost model must weigh one from outside from the first question on)."""
    schedule = plan.layout.schedule
    schedule.asked = True
    for method in first_answerers():
        direct = method.first_question(plan)
        if direct is None:
            continue
        rows, logs, operations = direct
        # what it spent counts towards a compiled table's setup (ski rental, _ranked)
        schedule.spent += operations + PER_CALL + PER_FACTOR * len(plan.terms)
        if plan.layout.constant:
            schedule.fixed = (rows.copy(), float(logs[0]), method.name)
        return with_evidence(plan, base.answer(plan, rows, logs, method=method.name))
    return None


def _ranked(plan: QuestionPlan) -> Posterior | Density:
    """The cheapest method of the layout's ranking for this batch that answers."""
    layout, schedule, bound = plan.layout, plan.layout.schedule, plan.bound
    size, version, cap = bound.size, registry_version(), limit("entries")
    # the ranking depends on which variables are searched and known, not on their values, and
    # on the batch size only through its order of magnitude
    found = schedule.rankings.get((version, size.bit_length()))
    if found is None:
        methods = ranked(plan, quick=True)
        if not methods:
            raise QuestionError(unanswerable(plan))
        found = schedule.rankings[(version, size.bit_length())] = (size, methods)
    ranked_size, methods = found
    # a method with a setup (a table compiled once) is chosen once the questions of this
    # layout have spent as much on the others as the setup costs: never more than twice the
    # cost of the better choice in hindsight (ski rental)
    spent = schedule.spent
    fitting = _fitting(methods, ranked_size, size, cap, spent)
    floors = [c.setup for _, c in methods if c.floor]
    if floors and (not fitting or fitting[0][1].floor or spent >= min(floors)):
        # a quick estimate's bound could decide: the full estimates, once per ranking
        methods = refined(plan, methods)
        schedule.rankings[(version, size.bit_length())] = (ranked_size, methods)
        fitting = _fitting(methods, ranked_size, size, cap, spent)
    if not fitting:
        method_, cost = methods[0]
        per_row = cost.memory / ranked_size
        if size > 1 and per_row <= cap and not plan.latent:
            # the batch does not fit at once, but its rows do: answered in slices
            return _in_slices(plan.program, plan.question, bound, plan.options,
                              max(int(cap // per_row), 1))
        approximate = ", ".join(name for name, m in registered_methods().items()
                                if not m.exact and m.estimate(plan) is not None)
        check_size(cost.memory / ranked_size * size,
                   f"{plan.question.expression} (by {method_.name}, the exact method that "
                   "needs least)", hint=f"; or ask an approximate method ({approximate}): "
                   "method=... in Python, --method on the command line" if approximate else "")
    for method_, cost in fitting:
        answer = method_.posterior(plan)
        if answer is not None:
            answer.method = answer.method or method_.name
            if method_ is fitting[0][0] and spent >= max(c.setup for _, c in fitting):
                # no setup left to weigh: this choice is the one for every later batch of
                # this size
                schedule.settled[(version, size, cap)] = method_
            schedule.spent = (math.inf if cost.setup else
                              spent + cost.operations / ranked_size * size + cost.fixed)
            if layout.constant and isinstance(answer, Posterior):
                schedule.fixed = _first_row(plan, answer)
            return with_evidence(plan, answer, method_.exact)
    raise RuntimeError(f"no inference method answered {plan.question.expression}")


def _fitting(methods: list[tuple[Method, Cost]], ranked_size: int, size: int, cap: float,
             spent: float) -> list[tuple[Method, Cost]]:
    """The ranked ``methods`` (estimated for ``ranked_size`` rows) whose memory for ``size``
    rows is within ``cap``, cheapest first once ``spent`` is deducted from their setups."""
    fitting = [(m, c) for m, c in methods if c.memory / ranked_size * size <= cap]
    fitting.sort(key=lambda mc: mc[1].operations / ranked_size * size + mc[1].fixed
                 + max(mc[1].setup - spent, 0.0))
    return fitting


def _in_slices(program: ProgramLike, question: Question, bound: Bound,
               options: Mapping[str, Any] | None, rows: int) -> Posterior:
    """The answer to a batch too large to contract at once, asked ``rows`` rows at a time
    and put together (each slice within the memory limit)."""
    parts: list[Posterior] = []
    for start in range(0, bound.size, rows):
        part = compute_posterior(program, question, bound.rows(start, start + rows),
                                 options=options)
        assert isinstance(part, Posterior)  # the question has no unknown real variable
        parts.append(part)
    shape = bound.batch_shape

    def log_evidence() -> np.ndarray:
        return np.concatenate([part.log_evidence for part in parts]).reshape(shape)

    impossible = [part.log_evidence == -np.inf if part.impossible is None else part.impossible
                  for part in parts]
    cards = parts[0].probabilities.shape[1:]
    return dataclasses.replace(
        parts[0], batch_shape=shape, log_evidence=log_evidence,  # type: ignore[arg-type]
        probabilities=np.concatenate([part.probabilities for part in parts]).reshape(
            shape + cards),
        impossible=np.concatenate(impossible).reshape(shape))


def with_evidence(plan: QuestionPlan, answer: Posterior | Density,
                   exact: bool = True) -> Posterior | Density:
    """``answer`` with the log-probability of all its evidence: where the plan left out
    evidence that does not bear on the answer, its normaliser is not that probability, which
    is then computed at the first read of ``log_evidence`` (by the same method when it is
    approximate, else by the cheapest exact one)."""
    if not plan.layout.pruned or not isinstance(answer, Posterior):
        return answer
    normaliser = answer.log_evidence
    impossible = normaliser == -np.inf
    if not exact and np.isnan(normaliser).all():  # lbp: it estimates no evidence
        return answer
    answer.impossible = impossible
    answer.log_evidence = deferred_evidence(
        plan.program, plan.question.expression, plan.bound, None if exact else answer.method,
        plan.options)
    return answer


def deferred_evidence(program: ProgramLike, expression: Expression, bound: Bound,
                      method: str | None, options: Mapping[str, Any]) -> Any:
    """A function of no arguments computing the log-probability of all the evidence of
    ``expression`` (by ``method``, else by the cheapest exact one)."""

    def log_evidence() -> np.ndarray:
        question = Question(Expression((), expression.right, expression.values))
        return compute_posterior(program, question, bound, method, options).log_evidence

    return log_evidence


def _by(name: str, plan: QuestionPlan) -> Posterior | Density:
    """The answer of the method ``name``, which the question asks for (its estimate kept per
    layout of question, like a ranking)."""
    methods = registered_methods()
    method = methods.get(name)
    if method is None:
        raise QuestionError(f"method {name!r}: expected one of {', '.join(methods)}")
    estimates = plan.layout.schedule.estimates
    options = tuple(sorted((k, v) for k, v in plan.options.items() if k != "rng"))
    key = (name, options, registry_version(), plan.bound.size.bit_length())
    found = estimates.get(key)
    if found is None:
        cost = None if (plan.latent and not method.continuous) or (
            plan.bound.ablated and not method.ablates_rows) else method.estimate(plan)
        found = estimates[key] = (plan.bound.size, cost)
    size, cost = found
    if cost is not None:
        cost = Cost(cost.operations / size * plan.bound.size, cost.memory / size * plan.bound.size)
    if cost is None:
        why = why_not(method, plan) or (f"{', '.join(plan.latent)} unknown and continuous"
                                        if plan.latent and not method.continuous else None)
        raise QuestionError(f"method {name!r} does not answer {plan.question.expression}"
                            + (f": {why}" if why else " (see the methods in the language "
                               "reference)"))
    check_size(cost.memory, f"{plan.question.expression} (by {name})")
    answer = method.posterior(plan)
    if answer is None:
        raise QuestionError(f"method {name!r} cannot answer every row of "
                            f"{plan.question.expression} (probabilities below its precision): "
                            "use method='contraction'")
    answer.method = answer.method or name
    return answer


def _empty_answer(program: ProgramLike, question: Question,
                  batch: tuple[int, ...]) -> Posterior | Density:
    """The answer to a batch of no rows: its arrays shaped ``batch + ...``, nothing computed."""
    searched = question.expression.left
    variables = [v for name in searched if isinstance(v := program.variables[name], Discrete)]
    if len(variables) < len(searched):
        d = len(searched)
        return Density(str(question.expression), tuple(searched), batch,
                       np.zeros(batch), program.ablated, weights=np.zeros((0, 1)),
                       means=np.zeros((0, 1, d)), covariances=np.zeros((0, 1, d, d)))
    cards = tuple(v.card for v in variables)
    return Posterior(
        question=str(question.expression),
        variables=tuple(searched),
        names={v.name: v.states for v in variables},
        probabilities=np.zeros(batch + cards),
        log_evidence=np.zeros(batch),
        batch_shape=batch,
        ablated=program.ablated,
        values={v.name: v.typed_states for v in variables},
    )


def ask(
    program: ProgramLike,
    question: Question,
    evidence: Mapping[str, Any] | None = None,
    inputs: Mapping[str, Any] | None = None,
    soft: Mapping[str, Any] | None = None,
    rng: Any = None,
    method: str | None = None,
    options: Mapping[str, Any] | None = None,
    ablate: Mapping[str, Any] | None = None,
) -> Posterior | MapResult | Density:
    """Answer ``question`` (posterior or MAP, by its kind) for batched evidence; ``ablate``:
    terms (by their text) made uniform on the rows where it is True (see :func:`bind`)."""
    bound = bind(program, question, evidence, inputs, soft, ablate)
    if bound.batch_shape and bound.size == 0:  # an empty batch: empty answers of its shape
        posterior = _empty_answer(program, question, bound.batch_shape)
    else:
        posterior = compute_posterior(program, question, bound, method,
                                      dict(options or {}, rng=rng))
    if isinstance(posterior, Density):  # its MAP is among its summaries
        check_zero(posterior)
        return posterior
    if question.kind == "map":
        return choose_map(posterior, str(question.expression), 0 if rng is None else rng,
                          program.ablated)
    check_zero(posterior)
    return posterior
