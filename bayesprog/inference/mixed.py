"""Questions that search discrete and real variables together: ``P(C X | Y=1.5)``.

The answer is the joint as a mixture: for each configuration of the searched discrete
variables, its probability given the evidence (a question on the discrete variables) and the
density of the real ones given that configuration and the evidence (one question on the real
variables, the configurations a batch axis in front). Its MAP is the configuration and value
where the joint density is highest: for a Gaussian conditional, at its mean, with the density
``w / sqrt((2 pi)^d |Sigma|)``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bayesprog.errors import QuestionError
from bayesprog.inference.answers import Posterior
from bayesprog.inference.density import Density, per_row
from bayesprog.support import rich
from bayesprog.vocabulary.expressions import Expression, Question

#: the most configurations of the searched discrete variables a mixed question answers
MAX_CONFIGURATIONS = 4096


@dataclass
class Joint:
    """``P(discrete real | evidence)``: the discrete configurations' ``weights`` (``batch +
    cards``) and the real variables' density given each (``conditional``, batch ``[K] +
    batch``, the K configurations flat in the order of ``weights``)."""

    question: str
    discrete: tuple[str, ...]
    real: tuple[str, ...]
    names: dict[str, tuple[str, ...]]
    weights: np.ndarray
    conditional: Density
    log_evidence: np.ndarray
    batch_shape: tuple[int, ...]
    ablated: tuple[str, ...] = ()
    #: the methods that answered the discrete variables (``"discrete"``: their weights) and
    #: the real ones given them (``"real"``)
    methods: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.log_evidence = per_row(self.log_evidence, self.batch_shape)

    @property
    def variables(self) -> tuple[str, ...]:
        return self.discrete + self.real

    @property
    def cards(self) -> tuple[int, ...]:
        return tuple(len(self.names[v]) for v in self.discrete)

    def _per_configuration(self, values: np.ndarray) -> np.ndarray:
        """``[K] + batch`` to ``batch + cards``."""
        moved = np.moveaxis(np.asarray(values, float).reshape((-1,) + self.batch_shape), 0, -1)
        return moved.reshape(self.batch_shape + self.cards)

    def mean(self, variable: str) -> np.ndarray:
        """The mean of a real variable given each discrete configuration (``batch + cards``)."""
        return self._per_configuration(self.conditional.mean(variable))

    def sd(self, variable: str) -> np.ndarray:
        return self._per_configuration(self.conditional.sd(variable))

    def map(self) -> dict[str, Any]:
        """The most probable configuration and value: ``{variable: value}`` (arrays over the
        batch), and ``"density"``, the joint density there."""
        peak = self._peaks()  # [K] + batch: the highest joint density within each configuration
        weights = np.moveaxis(self.weights.reshape(self.batch_shape + (-1,)), -1, 0)
        with np.errstate(divide="ignore"):
            score = np.log(weights) + peak
        best = np.argmax(score, axis=0)  # batch
        out: dict[str, Any] = {}
        index = np.unravel_index(best, self.cards)
        for v, i in zip(self.discrete, index, strict=True):
            out[v] = np.asarray(self.names[v], dtype=object)[i]
        for v in self.real:
            values = np.asarray(self._mode(v)).reshape((-1,) + self.batch_shape)
            out[v] = np.take_along_axis(values, best[None], 0)[0]
        out["density"] = np.exp(np.take_along_axis(score, best[None], 0)[0])
        return out

    def _mode(self, variable: str) -> np.ndarray:
        c = self.conditional
        if c.weights is not None and c.weights.shape[1] == 1:
            assert c.means is not None
            return c.means[:, 0, c.variables.index(variable)]
        return np.asarray(c.map(variable))

    def _peaks(self) -> np.ndarray:
        """Each configuration's highest log-density of the real variables, ``[K] + batch``."""
        c = self.conditional
        if c.weights is not None and c.weights.shape[1] == 1:
            assert c.covariances is not None
            _, logdet = np.linalg.slogdet(c.covariances[:, 0])
            d = len(c.variables)
            return (-0.5 * (d * np.log(2 * np.pi) + logdet)).reshape((-1,) + self.batch_shape)
        if len(self.real) != 1:
            raise QuestionError("the MAP of several real variables whose density given the "
                                "discrete ones is itself a mixture is not available: ask "
                                "for one real variable")
        v = self.real[0]
        mode = np.asarray(c.map(v)).reshape(-1)
        dens = np.asarray(c.pdf(v, mode[:, None])).reshape(-1, mode.size)
        rows = np.arange(mode.size)
        with np.errstate(divide="ignore"):
            return np.log(dens[rows, rows]).reshape((-1,) + self.batch_shape)

    def to_json(self) -> dict[str, Any]:
        best = self.map()
        return {
            "question": self.question,
            "discrete": list(self.discrete),
            "real": list(self.real),
            "states": {v: list(self.names[v]) for v in self.discrete},
            "weights": self.weights.tolist(),
            "mean": {v: self.mean(v).tolist() for v in self.real},
            "sd": {v: self.sd(v).tolist() for v in self.real},
            "map": {k: np.asarray(best[k]).tolist() for k in self.variables},
            "map_density": np.asarray(best["density"]).tolist(),
            "log_evidence": np.asarray(self.log_evidence).tolist(),
            "ablated": list(self.ablated),
            "method": "mixed",
            "methods": dict(self.methods),
        }

    def _repr_html_(self) -> str | None:
        return rich.html("joint", self)


def mixed(program: Any, question: Question, evidence: Mapping[str, Any] | None,
          inputs: Mapping[str, Any] | None, soft: Mapping[str, Any] | None,
          method: str | None, options: Mapping[str, Any]) -> Joint:
    """The answer of a question that searches discrete and real variables (see the module)."""
    expr = question.expression
    discrete = tuple(v for v in expr.left if program.variables[v].is_discrete)
    real = tuple(v for v in expr.left if not program.variables[v].is_discrete)
    cards = [program.variables[v].card for v in discrete]
    size = int(np.prod(cards))
    if size > MAX_CONFIGURATIONS:
        raise QuestionError(f"{expr}: the searched discrete variables have {size:,} "
                            f"configurations, more than the {MAX_CONFIGURATIONS:,} a mixed "
                            "question answers")
    evidence = dict(evidence or {})
    weights = program.ask(Question(Expression(discrete, expr.right, dict(expr.values))),
                          evidence, inputs=inputs, soft=soft, method=method,
                          samples=options.get("samples"), bins=options.get("bins"))
    assert isinstance(weights, Posterior)
    batch = weights.batch_shape
    shape = (size, *batch)
    index = np.unravel_index(np.arange(size), cards)
    given: dict[str, Any] = {}
    for v, i in zip(discrete, index, strict=True):
        given[v] = np.broadcast_to(np.asarray(i).reshape((size,) + (1,) * len(batch)), shape)
    for name, value in evidence.items():
        array = np.asarray(value)
        if array.ndim < len(batch):  # batch axes broadcast from the right
            array = array.reshape((1,) * (len(batch) - array.ndim) + array.shape)
        given[name] = array[np.newaxis]  # the configurations' axis in front
    conditional = program.ask(
        Question(Expression(real, discrete + tuple(expr.right), dict(expr.values))), given,
        inputs=inputs, soft=soft, method=method, samples=options.get("samples"),
        bins=options.get("bins"))
    if not isinstance(conditional, Density):
        raise QuestionError(f"{expr}: expected a density of {', '.join(real)}")
    return Joint(f"{expr}", discrete, real,
                 {v: program.variables[v].states for v in discrete},
                 weights.probabilities, conditional, weights.log_evidence, batch,
                 program.ablated, {"discrete": weights.method, "real": conditional.method})
