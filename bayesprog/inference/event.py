"""The probability of an event: ``P(A=a, B=b | C=c)``, a number per row of evidence.

It is a ratio of two probabilities of evidence, each the normaliser of a question that searches
nothing: ``log P(A=a, B=b | C=c) = log P(A=a, B=b, C=c) - log P(C=c)``. Both are answered by
the engine as any question is (the requisite terms, the cheapest exact method), so the answer
is exact wherever the engine's are; where the event fixes a real variable it is a density.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from bayesprog.errors import QuestionError, ZeroEvidenceError
from bayesprog.inference.answers import _floats
from bayesprog.inference.binding import bind
from bayesprog.inference.density import per_row
from bayesprog.inference.dispatch import compute_posterior
from bayesprog.inference.protocol import ProgramLike
from bayesprog.vocabulary.expressions import Expression, Question
from bayesprog.vocabulary.variables import Discrete


@dataclass
class Probability:
    """``P(A=a, B=b | C=c)``: the probability of the event on the left given the known
    values, per batch row (``probability`` has the batch shape; a density where the event
    fixes a real variable: ``density`` is then True).

    ``log_evidence`` is the log-probability of the known values alone (zero when nothing is
    known), the denominator of the ratio."""

    question: str
    variables: tuple[str, ...]
    probability: np.ndarray
    log_probability: np.ndarray
    log_evidence: np.ndarray
    batch_shape: tuple[int, ...]
    density: bool = False
    ablated: tuple[str, ...] = ()
    method: str = ""

    def __post_init__(self) -> None:
        self.log_evidence = per_row(self.log_evidence, self.batch_shape)

    def __float__(self) -> float:
        if self.probability.size != 1:
            raise TypeError(f"a batch of {self.probability.size} probabilities is not one "
                            "number: read .probability")
        return float(self.probability.reshape(-1)[0])

    def to_json(self) -> dict[str, Any]:
        return {
            "question": self.question,
            "kind": "probability",
            "variables": list(self.variables),
            "density" if self.density else "probability": self.probability.tolist(),
            "log_probability": _floats(self.log_probability),
            "log_evidence": _floats(self.log_evidence),
            "ablated": list(self.ablated),
            **({"method": self.method} if self.method else {}),
        }


def probability(program: ProgramLike, question: Question, evidence: Mapping[str, Any] | None,
                inputs: Mapping[str, Any] | None, soft: Mapping[str, Any] | None,
                method: str | None, options: Mapping[str, Any]) -> Probability:
    """The probability of the event of ``question`` (its left, with the values written there
    or given in ``evidence``) given its known values (its right), per batch row."""
    expr = question.expression
    evidence = dict(evidence or {})
    event = expr.left
    given = {n: evidence.pop(n) for n in event if n in evidence}
    missing = [n for n in event if n not in expr.values and n not in given]
    if missing:
        raise QuestionError(f"the probability of an event needs a value for each of its "
                            f"variables: {', '.join(missing)} has none in {expr} (write "
                            f"{missing[0]}=VALUE there, or give it as evidence)")
    known_values = {n: v for n, v in expr.values.items() if n not in event}
    joint = Question(Expression((), (*expr.right, *event), dict(expr.values)))
    log_joint, used = _log_evidence(program, joint, {**evidence, **given}, inputs, soft,
                                    method, options)
    if expr.right or soft:
        known = Question(Expression((), expr.right, known_values))
        log_known, _ = _log_evidence(program, known, evidence, inputs, soft, method, options)
    else:
        log_known = np.zeros(())
    log_joint, log_known = np.broadcast_arrays(log_joint, log_known)
    impossible = np.isneginf(log_known)
    if impossible.any():
        rows = [str(tuple(int(i) for i in r)) for r in np.argwhere(impossible)[:5]]
        where = f" (batch rows {', '.join(rows)})" if impossible.ndim else ""
        raise ZeroEvidenceError(f"the known values of {expr} have probability zero under the "
                                f"program{where}: the probability given them does not exist")
    with np.errstate(invalid="ignore"):
        log_p = np.where(np.isneginf(log_joint), -np.inf, log_joint - log_known)
    real = any(not isinstance(program.variables[n], Discrete) for n in event)
    return Probability(str(expr), tuple(event), np.exp(log_p), log_p, np.array(log_known),
                       tuple(log_p.shape), real, program.ablated, used)


def _log_evidence(program: ProgramLike, question: Question, evidence: Mapping[str, Any],
                  inputs: Mapping[str, Any] | None, soft: Mapping[str, Any] | None,
                  method: str | None, options: Mapping[str, Any]) -> tuple[np.ndarray, str]:
    """The log-probability of the evidence of ``question`` per row, and the method that
    computed it."""
    bound = bind(program, question, evidence, inputs, soft)
    if bound.batch_shape and bound.size == 0:
        return np.zeros(bound.batch_shape), ""
    answer = compute_posterior(program, question, bound, method, options)
    log_evidence = np.asarray(answer.log_evidence, float).reshape(bound.batch_shape)
    if np.isnan(log_evidence).any():
        raise QuestionError(f"method {answer.method!r} does not estimate the probability of "
                            f"evidence, which {question.expression} needs: leave out the "
                            "method (an exact one answers) or use lw")
    return log_evidence, answer.method
