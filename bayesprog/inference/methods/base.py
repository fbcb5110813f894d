"""The interface every inference method implements, and the registry the cost model picks from.

A method says whether it applies to a question and at what estimated cost (:meth:`estimate`),
and answers it (:meth:`posterior`). A new method is one module with one class registered by
:func:`register_method`, and its tests in one file.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from bayesprog.inference.answers import Posterior
from bayesprog.inference.density import Density
from bayesprog.inference.plan import Layout, QuestionPlan


@dataclass(frozen=True)
class Cost:
    """A method's estimate for one question over its whole batch: arithmetic operations and
    the largest array it allocates (entries); ``fixed``: operations a call costs whatever its
    batch size (the handling of each factor, in ``PER_FACTOR`` units); ``setup``: operations
    paid once for every later question of the same layout (a compiled table), not per call;
    ``floor``: a quick estimate, whose ``setup`` and ``memory`` are lower bounds (the method's
    :meth:`~Method.estimate` gives the full one)."""

    operations: float
    memory: float
    fixed: float = 0.0
    setup: float = 0.0
    floor: bool = False


#: What handling one factor costs a call (binding, slicing, rescaling, one step of the
#: contraction: about 20 microseconds), in arithmetic operations (about 1e9 per second on the
#: benchmark's machine), so that a cost model in operations also ranks small questions, whose
#: time this overhead dominates.
PER_FACTOR = 2e4
#: What an exact method's call costs besides its factors (binding the evidence, the layout's
#: lookups, the answer: about 12 microseconds, measured by benchmarks/engine.py).
PER_CALL = 1.4e4
#: What a factor prepared once per layout (a term that reads no evidence value) costs a
#: contraction's call beyond its operations: an index into its table and one einsum step
#: (about 2.4 microseconds, fitted over the bnlearn networks and grids of 6 x 6 to 16 x 16 in
#: benchmarks/engine.py, with ``PER_CALL`` and one rate for the operations).
PER_PREPARED = 3e3


class Method:
    """One way of answering questions. Subclasses set ``name`` and implement both methods."""

    name: ClassVar[str] = ""
    #: how an answer names the method (the text output's header): ``name`` when empty
    title: ClassVar[str] = ""
    #: whether the answers are exact (else they carry an error estimate)
    exact: ClassVar[bool] = True
    #: what the +- of an approximate answer is: ``"stderr"``, a standard error (sampling);
    #: ``"bound"``, an estimated bound of its error (a discretisation); None: none is given
    uncertainty: ClassVar[str | None] = None
    #: whether it answers questions with unknown continuous variables (searched ones, or
    #: parents of a relevant term); the discrete methods do not
    continuous: ClassVar[bool] = False
    #: an approximate method the cost model may choose on its own when no exact method
    #: applies (its answers state their error)
    fallback: ClassVar[bool] = False
    #: it answers some first questions of a layout with nothing planned (:meth:`first_question`)
    answers_first: ClassVar[bool] = False
    #: it answers questions that make a term uniform on some rows of their batch
    #: (``ask(..., ablate=...)``): it builds every term's factor for the question's own rows
    #: (:func:`~bayesprog.inference.factors.term_factor`)
    ablates_rows: ClassVar[bool] = False

    def why_not(self, plan: QuestionPlan) -> str | None:
        """Why this method does not answer ``plan`` (None: it does, or has nothing to say)."""
        return None

    def estimate(self, plan: QuestionPlan) -> Cost | None:
        """The cost of answering ``plan``, or None when this method does not apply to it."""
        raise NotImplementedError

    def quick_estimate(self, plan: QuestionPlan) -> Cost | None:
        """:meth:`estimate`, or where that takes long (a path search for a setup that may
        never be paid), a quicker one with lower bounds marked ``floor``: the cost model asks
        for the full estimate only when the bound could make this method the choice."""
        return self.estimate(plan)

    def first_question(self, plan: QuestionPlan) -> tuple[np.ndarray, np.ndarray, int] | None:
        """A layout's first question answered without planning the layout: the normalised
        table ``[1] + cards``, the log normaliser ``[1]`` and the operations it took; None
        when this question needs the planned path (the default)."""
        return None

    def prepared_row(self, layout: Layout, values: dict[str, int]
                     ) -> tuple[np.ndarray, float] | None:
        """One row of evidence (a state index per observed variable) answered from what
        ``layout`` has prepared, as :meth:`posterior` answers it: the probabilities over the
        searched variables (a new array) and the log normaliser; None when the row needs
        :meth:`posterior` (the default)."""
        return None

    def posterior(self, plan: QuestionPlan) -> Posterior | Density | None:
        """The answer (a density when the searched variables are real), or None when some rows
        need another method (the next cheapest)."""
        raise NotImplementedError

    def describe(self, answer: Any) -> str:
        """How an approximate ``answer`` was made and what its +- is, as the text output says
        it after the question: the method's title, then the meaning of the +-."""
        return (self.title or self.name) + {
            "stderr": ": +- one standard error",
            "bound": ": +- an estimated bound of its error"}.get(self.uncertainty or "", "")


def method_named(name: str) -> Method | None:
    """The registered method called ``name``; None for the other answers (the recursions of
    questions over steps, a particle filter)."""
    return registered_methods().get(name)


def answer(plan: QuestionPlan, probabilities: np.ndarray, log_evidence: np.ndarray,
           **extra: Any) -> Posterior:
    """The posterior of ``plan``'s question from flat rows (``[rows] + cards`` and ``[rows]``),
    shaped to the question's batch; ``extra``: the method's own fields (``method``,
    ``stderr`` shaped like the probabilities, ...)."""
    shape = plan.bound.batch_shape
    cards = plan.layout.cards
    if "stderr" in extra:
        extra["stderr"] = extra["stderr"].reshape(shape + cards)
    if "ess" in extra:
        extra["ess"] = extra["ess"].reshape(shape)
    states, values = plan.layout.named_states
    return Posterior(
        question=str(plan.question.expression),
        variables=plan.searched,
        names=dict(states),
        values=dict(values),
        probabilities=probabilities.reshape(shape + cards),
        log_evidence=np.asarray(log_evidence).reshape(shape),
        batch_shape=shape,
        ablated=plan.program.ablated,
        **extra,
    )


_METHODS: dict[str, Method] = {}
_VERSION = [0]

#: The package's own methods, one module each of :mod:`bayesprog.inference.methods`, in the
#: order they register (the cost model's order among equal costs). They are imported when the
#: registry is first read, not with the package: a layout's first question, answered by the
#: contraction with nothing planned, loads the contraction's module alone.
BUILTIN = ("contraction", "gaussian", "gibbs", "grid", "lbp", "lw", "table")
_PACKAGE = "bayesprog.inference.methods"
_LOADED: set[str] = set()


def _load(*names: str) -> None:
    """Import the package's own method modules ``names`` (each registers its method)."""
    from importlib import import_module

    for name in names:
        if name not in _LOADED:
            _LOADED.add(name)
            import_module(f"{_PACKAGE}.{name}")


def _builtin(cls: type) -> bool:
    return cls.__module__.startswith(_PACKAGE + ".") and \
        cls.__module__.rpartition(".")[2] in BUILTIN


def register_method(cls: type[Method]) -> type[Method]:
    """Class decorator: make a method available to the cost model under ``cls.name``."""
    if not cls.name:
        raise ValueError(f"{cls.__name__} needs a name")
    if not _builtin(cls):
        _load(*BUILTIN)  # the package's own come first, as they always have
    _METHODS[cls.name] = cls()
    _VERSION[0] += 1
    return cls


def registry_version() -> int:
    """A number that changes whenever a method is registered (rankings kept before are stale)."""
    _load(*BUILTIN)
    return _VERSION[0]


def registered_methods() -> dict[str, Method]:
    """The registered methods by name, in registration order."""
    _load(*BUILTIN)
    return dict(_METHODS)


def own_methods_only() -> bool:
    """Whether every registered method is one of this package's (no method registered from
    outside it, which the cost model must weigh from a layout's first question)."""
    return all(_builtin(type(m)) for m in _METHODS.values())


def first_answerers() -> list[Method]:
    """The registered methods that answer a layout's first question with nothing planned."""
    _load(*(name for name in BUILTIN if name in FIRST))
    return [m for m in _METHODS.values() if m.answers_first]


#: the package's own methods that answer a layout's first question (``answers_first``)
FIRST = ("contraction",)
