"""What a question answers: a posterior, or a MAP assignment chosen from one.

MAP is the joint argmax of the searched variables after summing out the others; ties are broken
by a seeded generator (one per batch row, when given), never by index order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bayesprog.errors import ArgumentError, QuestionError, ZeroEvidenceError, short_repr
from bayesprog.inference.density import Density, per_row
from bayesprog.support import rich

#: Relative tolerance under which two probabilities count as tied for MAP.
TIE_RTOL = 1e-12


class Deferred:
    """A dataclass field that may be given as a function of no arguments, called at its first
    read (a value the answer can give but seldom needs); ``shaped``: the value read is one
    number per row, shaped as the answer's batch (:func:`~bayesprog.inference.density.per_row`)."""

    def __init__(self, name: str, shaped: bool = False) -> None:
        self.name, self.slot, self.shaped = name, "_" + name, shaped

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        if obj is None:
            return self
        value = obj.__dict__[self.slot]
        if callable(value):
            value = value()
            if self.shaped:
                value = per_row(value, obj.batch_shape)
            obj.__dict__[self.slot] = value
        return value

    def __set__(self, obj: Any, value: Any) -> None:
        obj.__dict__[self.slot] = value


@dataclass
class Posterior:
    """``P(searched | evidence)``: ``probabilities`` has shape ``batch + cards of variables``.

    ``states`` gives each variable's states as values of its type, as ``to_json`` and a MAP
    give them (integers for a range, ``(ix, iy)`` for a grid's cells, names else); ``names``
    the same states as the text shown in tables.

    ``log_evidence`` is the log-probability of the evidence per row; where the question left
    out evidence that does not bear on its answer, it is computed at its first read."""

    question: str
    variables: tuple[str, ...]
    names: dict[str, tuple[str, ...]]
    probabilities: np.ndarray
    log_evidence: np.ndarray
    batch_shape: tuple[int, ...]
    ablated: tuple[str, ...] = ()
    #: the states as values of each variable's type (integers for a range); names by default
    #: (read them as ``states``)
    values: dict[str, tuple[Any, ...]] | None = None
    #: the inference method that answered (``table``, ``contraction``: exact; ``lbp``, ``lw``)
    method: str = ""
    #: approximate answers: the standard error of each probability (``lw``, ``gibbs``), the
    #: effective sample size per row (``lw``, ``gibbs``), the sweeps made and the last change
    #: of a message (``lbp``)
    stderr: np.ndarray | None = None
    ess: np.ndarray | None = None
    iterations: int | None = None
    residual: float | None = None
    #: how ``log_evidence`` was computed when it is not exact (``lbp``: "Bethe approximation")
    evidence: str | None = None
    #: an estimated bound of each probability's error, not a standard error (``grid``: the
    #: change from half its bins), and the bins of each unknown real variable
    error: np.ndarray | None = None
    resolution: dict[str, int] = field(default_factory=dict)
    #: what the +- of an approximate answer is: ``"stderr"`` (``stderr``), ``"bound"``
    #: (``error``); None when it has none
    uncertainty: str | None = None
    #: a question over steps whose steps an approximate method answered: that method (its
    #: answer gives no error estimate)
    steps_method: str = ""
    #: the rows without an answer (the evidence that bears on it has probability zero), when
    #: ``log_evidence`` is not computed yet; None: the rows where it is -inf
    impossible: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        given = self.__dict__["_log_evidence"]
        if not callable(given):  # (computed at its first read: shaped then)
            self.__dict__["_log_evidence"] = per_row(given, self.batch_shape)

    def _repr_html_(self) -> str | None:
        return rich.html("posterior", self)

    def __getstate__(self) -> dict[str, Any]:
        # a pickled answer carries its evidence's probability, not the way to compute it
        self.log_evidence  # noqa: B018  (computed where it was deferred)
        return dict(self.__dict__)

    @property
    def states(self) -> dict[str, tuple[Any, ...]]:
        """Each searched variable's states, as values of its type."""
        return {v: self.typed(v) for v in self.variables}

    def typed(self, variable: str) -> tuple[Any, ...]:
        return (self.values or {}).get(variable, self.names[variable])

    def to_json(self) -> dict[str, Any]:
        return {
            "question": self.question,
            "variables": list(self.variables),
            "states": {v: list(self.typed(v)) for v in self.variables},
            "probabilities": self.probabilities.tolist(),
            "log_evidence": _floats(self.log_evidence),
            "ablated": list(self.ablated),
            **self._method_json(),
        }

    def _method_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"method": self.method} if self.method else {}
        if self.uncertainty is not None:
            out["uncertainty"] = self.uncertainty
        if self.stderr is not None:
            out["stderr"] = self.stderr.tolist()
        if self.error is not None:
            out["error"] = self.error.tolist()
        if self.resolution:
            out["bins"] = dict(self.resolution)
        if self.steps_method:
            out["steps_method"] = self.steps_method
        if self.ess is not None:
            out["ess"] = self.ess.tolist()
        if self.iterations is not None:
            out["iterations"] = self.iterations
            out["residual"] = self.residual
        if self.evidence is not None:
            out["log_evidence_method"] = self.evidence
        return out


Posterior.log_evidence = Deferred("log_evidence", shaped=True)  # type: ignore[assignment]


@dataclass
class MapResult:
    """The joint argmax of the searched variables (others summed out), ties broken by an RNG.

    ``indices`` has shape ``batch + (len(variables),)``; ``probability`` is the posterior
    probability of the chosen assignment; ``ties`` counts the assignments that shared the maximum.

    ``kind`` is ``"sequence"`` for the most likely sequence of a program over time steps: then
    ``indices`` has time as its first axis, and ``probability``, ``ties`` and ``zero_evidence``
    are one per sequence (the batch shape), ``probability`` that of the whole sequence and
    ``ties`` the number of sequences as probable (drawn among as a MAP's tied assignments).
    """

    question: str
    variables: tuple[str, ...]
    names: dict[str, tuple[str, ...]]
    indices: np.ndarray
    probability: np.ndarray
    ties: np.ndarray
    zero_evidence: np.ndarray
    posterior: Posterior
    ablated: tuple[str, ...] = ()
    kind: str = "map"

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The rows of evidence: one assignment each (one sequence each, for a sequence)."""
        return tuple(self.probability.shape)

    @property
    def log_evidence(self) -> np.ndarray:
        """The log-probability of the evidence per row; for a sequence, of all its steps'
        evidence, ``log P(y_1..T)`` (the posterior's are per step, ``log P(y_t | y_1..t-1)``)."""
        if self.kind == "sequence":
            return per_row(np.sum(self.posterior.log_evidence, axis=0), self.batch_shape)
        return self.posterior.log_evidence

    @property
    def steps(self) -> int | None:
        """The number of steps of a sequence (None for a MAP question)."""
        return int(self.indices.shape[0]) if self.kind == "sequence" else None

    @property
    def states(self) -> dict[str, tuple[Any, ...]]:
        """Each searched variable's states, as values of its type (as in ``assignment``)."""
        return self.posterior.states

    @property
    def assignment(self) -> dict[str, Any]:
        """The argmax as values of each variable's type: state names, integers for a range
        (arrays when batched)."""
        out = {}
        for i, var in enumerate(self.variables):
            typed = self.posterior.typed(var)
            if all(isinstance(v, (int, float)) for v in typed):  # a range, bins: numbers
                values = np.asarray(typed)
            else:
                values = np.empty(len(self.names[var]), dtype=object)
                for j, value in enumerate(typed):
                    values[j] = value  # one object per state (a grid cell is a tuple)
            chosen = values[self.indices[..., i]]
            out[var] = chosen if self.indices.ndim > 1 else chosen.item() if hasattr(
                chosen, "item") else chosen
        return out

    def _repr_html_(self) -> str | None:
        return rich.html("map", self)

    def to_json(self) -> dict[str, Any]:
        assignment = self.assignment
        out = {
            "question": self.question,
            "map": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in assignment.items()},
            "probability": self.probability.tolist(),
            "ties": self.ties.tolist(),
            "zero_evidence": self.zero_evidence.tolist(),
            "log_evidence": _floats(self.log_evidence),
            "ablated": list(self.ablated),
            **self.posterior._method_json(),
        }
        if self.kind == "sequence":  # one path per sequence: its probability, its ties
            out["method"] = "sequence"
            out["log_evidence_per_step"] = _floats(self.posterior.log_evidence)
        return out


def _floats(values: np.ndarray) -> Any:
    """Numbers for JSON: -inf (evidence of probability zero) as None."""
    array = np.asarray(values, float)
    out = np.where(np.isfinite(array), array, np.nan).tolist()
    if isinstance(out, float):
        return None if np.isnan(out) else out
    return _nested_none(out)


def _nested_none(values: list) -> list:
    return [_nested_none(v) if isinstance(v, list) else (None if v != v else v) for v in values]


def seed_of(rng: Any) -> int:
    """``rng`` as a seed, checked: an integer >= 0."""
    if isinstance(rng, (bool, np.bool_)) or not isinstance(rng, (int, np.integer)):
        raise ArgumentError(f"rng: expected a seed (an integer >= 0), a "
                            "numpy.random.Generator, or one of them per batch row; found "
                            f"{type(rng).__name__} {short_repr(rng)}")
    if rng < 0:
        raise QuestionError(f"rng: expected a seed >= 0, found {rng}")
    return int(rng)


def generator_of(rng: Any) -> np.random.Generator:
    """A generator from ``rng``: a ``numpy.random.Generator``, or a seed (an integer >= 0)."""
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(seed_of(rng))


def row_generators(rng: Any, rows: int) -> list[np.random.Generator]:
    """One generator per batch row: ``rng`` shared by the rows (a seed or a generator; None is
    seed 0), or a sequence of one per row."""
    if isinstance(rng, Sequence) and not isinstance(rng, (str, bytes)):
        if len(rng) != rows:
            raise QuestionError(f"expected one generator per batch row ({rows}), got {len(rng)}")
        return [generator_of(r) for r in rng]
    return [generator_of(0 if rng is None else rng)] * rows


def choose_map(posterior: Posterior, question: str, rng: Any, ablated: tuple[str, ...]) -> MapResult:
    """Joint argmax per batch row; ties (relative 1e-12) broken uniformly by ``rng``.

    ``rng`` is a ``numpy.random.Generator`` (or a seed) shared by the rows, or a sequence of one
    generator per row: then a row's choice does not depend on the rest of the batch.
    """
    shape = posterior.batch_shape
    cards = posterior.probabilities.shape[len(shape) :]
    flat = posterior.probabilities.reshape((-1, int(np.prod(cards))))
    rows = flat.shape[0]
    gens = row_generators(rng, rows)
    best = flat.max(axis=1)
    tied = flat >= (best * (1 - TIE_RTOL))[:, None]
    counts = tied.sum(axis=1)
    choice = flat.argmax(axis=1)
    for row in np.flatnonzero(counts > 1):
        candidates = np.flatnonzero(tied[row])
        choice[row] = candidates[gens[row].integers(candidates.size)]
    indices = np.stack(np.unravel_index(choice, cards), axis=-1).reshape(shape + (len(cards),))
    zero = impossible_rows(posterior)
    return MapResult(
        question=question,
        variables=posterior.variables,
        names=posterior.names,
        indices=indices,
        probability=flat[np.arange(rows), choice].reshape(shape),
        ties=counts.reshape(shape),
        zero_evidence=np.asarray(zero).reshape(shape),
        posterior=posterior,
        ablated=ablated,
    )


def impossible_rows(posterior: Posterior | Density) -> np.ndarray:
    """Where the answer does not exist: the evidence that bears on it has probability zero."""
    known = getattr(posterior, "impossible", None)
    return known if known is not None else np.asarray(posterior.log_evidence) == -np.inf


def zero_rows_message(posterior: Posterior | Density) -> str:
    zero = np.argwhere(impossible_rows(posterior))
    where = ", ".join(str(tuple(int(i) for i in row)) for row in zero[:5]) if posterior.batch_shape else ""
    return (f"the evidence has probability zero under the program for {posterior.question}"
            + (f" (batch rows {where}{', ...' if len(zero) > 5 else ''})" if where else "")
            + ": no posterior exists; check the evidence or use a MAP question")


def check_zero(posterior: Posterior | Density) -> None:
    known = getattr(posterior, "impossible", None)
    if known is None:  # NaN in log_evidence: a method that estimates no evidence
        known = np.asarray(posterior.log_evidence) == -np.inf
    if known.any() if known.ndim else known:  # (one row: its truth, without a reduction)
        raise ZeroEvidenceError(zero_rows_message(posterior))
