"""What every parametric form shares: declared parameters, their constraints, and evaluation.

A form turns one term ``P(X | parents)`` into a log-factor over the term's discrete variables.
Its parameters are declared as data (:class:`Param`), each with a :class:`Constraint`; the file
checker and the Python API check values against the same declarations.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import numpy as np

if TYPE_CHECKING:
    from bayesprog.vocabulary.variables import Discrete, Variable


@dataclass(frozen=True)
class InputRef:
    """A parameter given at question time by the runtime input ``name``."""

    name: str


@dataclass(frozen=True, eq=False)
class FormulaParam:
    """A parameter written as arithmetic of the term's parents (``mean: "2*X + 1"``): one
    formula per cell of a table keyed by discrete parents (``axes``; none for one formula).

    The formulas' variables are continuous parents (their values come from the evidence, or
    the Gaussian method treats them as unknowns) and discrete parents: numbers for a range (its
    integers), states named by integers and a discretised variable (its bins' midpoints), the
    index of the state for named states (which formulas only compare, see
    :meth:`~bayesprog.vocabulary.formula.Formula.with_states`)."""

    axes: tuple[str, ...]
    #: object array of :class:`~bayesprog.vocabulary.formula.Formula`, one axis per entry of ``axes``
    #: (then, with ``event``, one over the child's states)
    formulas: np.ndarray
    #: the formulas give the child's probabilities (its states on the last axis of
    #: ``formulas``, or, with ``child``, as the value of the child's name), normalised per
    #: configuration of the parents
    event: bool = False
    #: the child, when the formulas name it: each gives the weight of every child state
    child: str | None = None
    #: the text as written, where it differs from the formulas (a two-state child's one
    #: formula, its second state's probability)
    written: str = ""

    @property
    def names(self) -> tuple[str, ...]:
        """The parents and inputs the formulas name (not the child)."""
        seen: dict[str, None] = {}
        for f in self.formulas.flat:
            seen.update(dict.fromkeys(f.names))
        seen.pop(self.child, None)  # type: ignore[arg-type]
        return tuple(seen)

    def __str__(self) -> str:
        if self.written:
            return f'"{self.written}"'
        if not self.axes and (not self.event or self.child):
            return f'"{self.formulas.flat[0]}"'
        return "{" + ", ".join(f'"{f}"' for f in self.formulas.flat) + "}"

    def evaluate(self, variables: Mapping[str, Variable], known: Mapping[str, np.ndarray],
                 rows: int) -> tuple[tuple[str, ...], np.ndarray]:
        """``(axes, values)``: the formulas over the table's axes and the discrete variables
        they name (appended to ``axes``), for ``rows`` rows of the values ``known`` of the
        others (each ``[rows or 1]``); ``[rows, *axes]``, then the child's states with
        ``event``. Probabilities are not yet normalised (:meth:`normalised`)."""
        from bayesprog.vocabulary.variables import Discrete

        named = self.names + ((self.child,) if self.child else ())
        extra = tuple(n for n in named
                      if isinstance(variables.get(n), Discrete) and n not in self.axes)
        cards = [variables[a].card for a in extra]  # type: ignore[union-attr]
        values: dict[str, np.ndarray] = {}
        for name in named:
            var = variables.get(name)
            if isinstance(var, Discrete) and name in extra:
                shape = [1] * (1 + len(extra))
                shape[1 + extra.index(name)] = var.card
                values[name] = formula_values(var).reshape(shape)
            else:
                values[name] = np.asarray(known[name], float).reshape((-1,) + (1,) * len(extra))
        table = self.formulas
        out = np.empty((rows,) + table.shape + tuple(cards))
        for index in np.ndindex(*table.shape):
            formula = table.item(index)
            result = formula.evaluate({n: values[n] for n in formula.names})
            out[(slice(None),) + index] = np.broadcast_to(result, (rows, *cards))
        if self.child:  # the child's states last
            out = np.moveaxis(out, 1 + table.ndim + extra.index(self.child), -1)
            extra = tuple(n for n in extra if n != self.child)
        elif self.event:
            out = np.moveaxis(out, 1 + len(self.axes), -1)
        return self.axes + extra, out

    def normalised(self, axes: tuple[str, ...], values: np.ndarray,
                   variables: Mapping[str, Variable]) -> np.ndarray:
        """Probabilities ``values`` (from :meth:`evaluate`) normalised over the child's states;
        a ValueError names the first parent configuration whose values are negative, not
        finite, or all zero."""
        total = values.sum(axis=-1, keepdims=True)
        bad = ~(np.isfinite(values).all(-1) & (values >= 0).all(-1) & (total[..., 0] > 0))
        if bad.any():
            index = tuple(int(i) for i in np.argwhere(bad)[0])
            row = values[index]
            at = ", ".join(f"{a}={variables[a].states[i]}"  # type: ignore[union-attr]
                           for a, i in zip(axes, index[1:], strict=True))
            found = ", ".join(f"{v:.6g}" for v in row[:8]) + (", ..." if row.size > 8 else "")
            why = ("sum to 0" if np.isfinite(row).all() and (row >= 0).all()
                   else "are not all finite and >= 0")
            raise ValueError(f"the probabilities {self} {why}"
                             f"{' for ' + at if at else ''} (found [{found}]); expected "
                             "values >= 0 with a positive sum, normalised over the states")
        return values / total


def formula_values(var: Discrete) -> np.ndarray:
    """What a formula reads for each state of a discrete variable: its number (a range's
    integer, an integer-named state's, a bin's midpoint), else the state's index."""
    return np.asarray(var.values if var.values is not None else np.arange(var.card), float)


def is_binned(var: Any) -> bool:
    """A continuous variable answered on bins (``discretise:``)."""
    return getattr(var, "kind", None) == "bins"


@dataclass(frozen=True)
class Constraint:
    """A constraint on parameter values; ``ok`` tests an array (events on the trailing axis)."""

    text: str
    ok: Callable[[np.ndarray], bool]

    def __str__(self) -> str:
        return self.text


def _finite(a: np.ndarray) -> bool:
    return bool(np.isfinite(a).all())


def _simplex(a: np.ndarray) -> bool:
    a = np.asarray(a)
    return _finite(a) and bool((a >= 0).all()) and bool(
        (np.abs(a.sum(axis=-1) - 1.0) <= 1e-6).all())


real = Constraint("a finite real", _finite)
positive = Constraint("> 0", lambda a: _finite(a) and bool((np.asarray(a) > 0).all()))
nonnegative = Constraint(">= 0", lambda a: _finite(a) and bool((np.asarray(a) >= 0).all()))
unit_interval = Constraint("in [0, 1]", lambda a: _finite(a) and bool(
    ((np.asarray(a) >= 0) & (np.asarray(a) <= 1)).all()))
simplex = Constraint("non-negative and summing to 1", _simplex)


@dataclass(frozen=True)
class Param:
    """A declared parameter. ``event_ndim`` trailing dimensions belong to one distribution."""

    name: str
    constraint: Constraint
    event_ndim: int = 0
    default: Any = None
    doc: str = ""
    keyed_by_child_states: bool = False

    @property
    def required(self) -> bool:
        return self.default is None


@dataclass(frozen=True)
class ParamValue:
    """A parameter as an array: ``[batch] + [card(v) for v in axes] + event`` (batch if batched)."""

    axes: tuple[str, ...]
    array: np.ndarray
    batched: bool = False

    def aligned(self, axes: tuple[str, ...], event_ndim: int) -> np.ndarray:
        """The array with a leading batch axis (size 1 if unbatched) and one axis per ``axes``.

        Axes of ``axes`` that the parameter does not vary over get size 1, for broadcasting.
        """
        arr = self.array if self.batched else self.array[np.newaxis]
        own = list(self.axes)
        order = [own.index(a) + 1 for a in axes if a in own]
        event = list(range(1 + len(own), arr.ndim))
        arr = arr.transpose([0] + order + event)
        shape = [arr.shape[0]]
        it = iter(arr.shape[1 : 1 + len(order)])
        for a in axes:
            shape.append(next(it) if a in own else 1)
        return arr.reshape(shape + list(arr.shape[1 + len(order) :]))


@dataclass
class TermContext:
    """Everything a form needs to evaluate one term for one question."""

    child: Variable
    parents: tuple[Variable, ...]
    axes: tuple[str, ...]
    cards: tuple[int, ...]
    params: dict[str, ParamValue]
    value: ParamValue | None
    variables: Mapping[str, Variable]
    extra: dict[str, Any] = field(default_factory=dict)

    def param(self, name: str, event_ndim: int = 0) -> np.ndarray:
        return self.params[name].aligned(self.axes, event_ndim)

    def child_value(self) -> np.ndarray:
        assert self.value is not None
        return self.value.aligned(self.axes, 0)


# What an estimator needs (the estimators themselves: bayesprog.forms.estimators) ------------
Stats = dict[str, np.ndarray]
Params = dict[str, ParamValue]


class Term(Protocol):
    """What an estimator reads of the term it learns (a :class:`bayesprog.model.Term`): its
    child, its parents, their discrete axes and its label for messages."""

    @property
    def child(self) -> Variable: ...

    @property
    def parents(self) -> tuple[Variable, ...]: ...

    @property
    def axes(self) -> tuple[str, ...]: ...

    @property
    def label(self) -> str: ...


@dataclass(frozen=True)
class LearnOptions:
    """How a term is learned from data: Dirichlet pseudo-counts (tables), the candidate numbers
    of components (gmm, chosen by BIC when several), and parameters pooled across parent
    states. Which of them a form takes is its estimator's :attr:`Estimator.options`."""

    pseudo_counts: ParamValue | None = None
    components: tuple[int, ...] = ()
    shared: tuple[str, ...] = ()


class Estimator:
    """How one form is learned. ``learned`` names the parameters it sets, ``options`` the
    ``learn:`` options it takes (:class:`LearnOptions`), ``mixture`` whether it learns a
    mixture (whose EM iterates even on complete data, and whose number of components a fit
    may choose)."""

    learned: tuple[str, ...] = ()
    options: frozenset[str] = frozenset()
    mixture: bool = False

    def components(self, term: Term, params: Params) -> int:
        """The number of mixture components the parameters hold (1: no mixture)."""
        return 1

    def statistics(self, term: Term, x: np.ndarray, weights: np.ndarray, params: Params) -> Stats:
        """Statistics of a continuous child: ``x`` [n] values, ``weights`` [n, *parent cards]."""
        raise NotImplementedError

    def counts(self, term: Term, counts: np.ndarray) -> Stats:
        """Statistics of a discrete child from expected counts over ``term.axes``."""
        raise NotImplementedError

    def merge(self, a: Stats, b: Stats) -> Stats:
        return {k: a[k] + b[k] for k in a}

    def estimate(self, term: Term, stats: Stats, options: LearnOptions, params: Params) -> Params:
        raise NotImplementedError

    def free_parameters(self, term: Term, params: Params, options: LearnOptions) -> int:
        raise NotImplementedError

    def log_prior(self, term: Term, params: Params, options: LearnOptions) -> float:
        """The log prior density EM climbs with the likelihood (pseudo-counts), up to a constant."""
        return 0.0

    def check_statistics(self, stats: Stats, expected: Stats) -> str | None:
        """Why ``stats`` (read from a fitted file) cannot be added to ``expected``, or None."""
        if set(stats) != set(expected):
            return (f"statistics {sorted(stats)} where this form keeps {sorted(expected)}")
        for key, value in stats.items():
            if value.shape != expected[key].shape:
                return f"{key!r} has shape {value.shape}, expected {expected[key].shape}"
            if not np.all(np.isfinite(value)):
                return f"{key!r} holds a value that is not finite"
            if key in ("count", "counts", "sum_squared_deviations") and np.any(value < 0):
                return f"{key!r} holds a negative value"
        return None

    def initial(self, term: Term, x: np.ndarray, weights: np.ndarray, components: int,
                params: Params) -> Params:
        """Starting parameters when the file's cannot serve (gmm with another K)."""
        return params


class Form:
    """Base class of parametric forms. Subclasses declare ``name``, ``params`` and ``log_factor``.

    ``normalized`` says whether the term sums (or integrates) to one over the child for every
    parent configuration; unnormalized terms (potentials) are never pruned as barren.
    """

    name: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()
    child_kinds: ClassVar[tuple[str, ...]] = ("discrete", "continuous")
    normalized: ClassVar[bool] = True
    doc: ClassVar[str] = ""

    # What the form can do, declared as data: the engine, the learning and the display ask
    # these, never the form's name.
    #: how the notation writes it (``P(X | Y) = Normal(...)``); empty: the name capitalised
    title: ClassVar[str] = ""
    #: the parameter that is the child's mean, when the child is that mean plus Gaussian noise
    #: of standard deviation ``scale_param`` (or exactly that mean, ``scale_param`` None): the
    #: conditional linear-Gaussian algebra and the substitution of a deterministic term use it
    mean_param: ClassVar[str | None] = None
    scale_param: ClassVar[str | None] = None
    #: a location parameter and the spread of the values around it (``("mu", "sigma")``): a
    #: learned location is written to the precision its standard error allows, not to a number
    #: of significant digits (a mean of 1000.12 with a spread of 0.01 needs its decimals)
    location_scale: ClassVar[tuple[str, str] | None] = None
    #: a likelihood over a discrete variable's states may be given in this form (soft evidence)
    soft_evidence: ClassVar[bool] = False
    #: the term is another program's answer (loaded with the program, shown by its question)
    subprogram: ClassVar[bool] = False
    #: over a real child, its log density at each value reads that value alone (and literal
    #: parameters): a field whose values changed at a few cells since a layout's last question
    #: has its log densities computed again at those cells only
    #: (:mod:`bayesprog.inference.recurring`)
    pointwise: ClassVar[bool] = False
    #: :meth:`sample` is the quantile function at ``u[..., 0]`` (and :meth:`cdf` its inverse):
    #: a draw restricted to a bounded support takes ``u`` between the CDF at its bounds
    quantile_sample: ClassVar[bool] = False

    @property
    def display_name(self) -> str:
        return self.title or self.name.capitalize()

    @property
    def deterministic(self) -> bool:
        """The child is exactly ``mean_param`` (no noise): it is known once its parents are."""
        return self.mean_param is not None and self.scale_param is None

    def estimator(self, child: Variable) -> Estimator | None:
        """How terms of this form over ``child`` are learned from data (see
        :mod:`bayesprog.forms.estimators`), or None when there is nothing to learn."""
        return None

    def is_normalized(self, child: Variable) -> bool:
        """Whether this term sums (integrates) to one over ``child`` for every parent state."""
        return self.normalized

    def check(self, child: Variable, parents: tuple[Variable, ...]) -> list[str]:
        """Problems with the variables this term joins (messages without location)."""
        kind = "discrete" if child.is_discrete and not is_binned(child) else "continuous"
        if kind not in self.child_kinds:
            wanted = " or ".join(self.child_kinds)
            return [f"form {self.name!r} needs a {wanted} child, found {kind} {child.name!r}"]
        return []

    def check_params(self, params: Mapping[str, Any], child: Variable) -> list[tuple[str, str]]:
        """Problems between resolved parameters (literal ones are ``ParamValue``), as
        (parameter to point at, message) pairs."""
        return []

    def keyable(self, child: Variable, parents: tuple[Variable, ...]) -> list[Discrete]:
        """Discrete variables a parameter table may be keyed by (the parents by default)."""
        return [p for p in parents if p.is_discrete]  # type: ignore[misc]

    def event_ndim(self, param: Param, child: Variable) -> int:
        """The number of trailing event dimensions of ``param`` for this child."""
        return param.event_ndim

    def event_shape(self, param: Param, child: Variable) -> tuple[int, ...] | None:
        """The expected event shape of ``param`` when it is fixed by the variables, else None."""
        return None

    def log_factor(self, ctx: TermContext) -> np.ndarray:
        """Log values with shape ``[batch or 1] + [card or 1 for each of ctx.axes]``."""
        raise NotImplementedError

    def cdf(self, ctx: TermContext) -> np.ndarray | None:
        """``P(X <= x | parents)`` at ``ctx.child_value()``, shaped like :meth:`log_factor`,
        for a continuous child; None when the form has no closed-form CDF. A discretised
        child's bins take the differences of the CDF at their edges."""
        return None

    def sample(self, params: Mapping[str, np.ndarray], child: Variable,
               u: np.ndarray) -> np.ndarray:
        """Values of a continuous ``child``, one per draw, from the parameters at each draw
        (``params[k]``: ``draws + event``) and two independent uniforms per draw
        (``u[..., 0]``, ``u[..., 1]``), by inverse transform. Discrete children need no
        method: they are drawn from :meth:`log_factor`."""
        raise NotImplementedError(f"form {self.name!r} cannot draw a continuous child: give "
                                  f"{child.name} as evidence, or use a form that can")

    def draw(self, ctx: TermContext, u: np.ndarray) -> np.ndarray:
        """Values of a continuous child, one per draw, where sampling draws them: :meth:`sample`
        of the parameters at each draw (``ctx.params[k].array``: ``draws + event``) and of the
        uniforms ``u``. A form whose draws read more than its parameters (what it resolved with
        the term, ``ctx.extra``: the ``program`` form's sub-program) gives them here."""
        return self.sample({k: v.array for k, v in ctx.params.items()}, ctx.child, u)


_REGISTRY: dict[str, Form] = {}


def register_form(form: type[Form] | Form) -> type[Form] | Form:
    """Register a parametric form under its ``name`` (usable as a class decorator).

    >>> class Flat(Form):
    ...     name = "flat_example"
    ...     child_kinds = ("discrete",)
    ...     def log_factor(self, ctx):
    ...         return np.zeros((1,) + ctx.cards)
    >>> _ = register_form(Flat)
    >>> "flat_example" in available_forms()
    True
    """
    instance = form() if isinstance(form, type) else form
    if not instance.name:
        raise ValueError("a form needs a non-empty 'name'")
    _REGISTRY[instance.name] = instance
    return form


#: why a form an installed package declares could not be registered, by the form's name
_PLUGIN_PROBLEMS: dict[str, str] = {}


def get_form(name: str) -> Form | None:
    """The form registered as ``name``; a name that is not registered is looked for among the
    forms of installed packages (the ``bayesprog.forms`` entry points, read only then: see
    :mod:`bayesprog.forms.plugins`), and registered when found."""
    form = _REGISTRY.get(name)
    if form is None and name not in _PLUGIN_PROBLEMS:
        form = _plugin_form(name)
    return form


def available_forms() -> list[str]:
    """The registered forms (an installed package's form is registered at its first use)."""
    return sorted(_REGISTRY)


def unknown_form(name: str) -> str:
    """Why there is no form ``name`` (for a message that names it): the installed package
    that declares it cannot give it, or no form has that name, with the closest of the
    registered forms and the installed packages'."""
    if name in _PLUGIN_PROBLEMS:
        return _PLUGIN_PROBLEMS[name]
    from bayesprog.errors import did_you_mean
    from bayesprog.forms.plugins import installed

    names = sorted(set(_REGISTRY) | set(installed()))
    return (f"unknown form {name!r}{did_you_mean(name, names)} (expected one of "
            f"{', '.join(names)})")


def _plugin_form(name: str) -> Form | None:
    """The form of the installed package whose entry point is named ``name``, registered; None
    when there is none, or when it cannot be loaded (the reason kept for
    :func:`unknown_form`)."""
    from bayesprog.forms.plugins import installed

    plugin = installed().get(name)
    if plugin is None:
        return None
    try:
        found = plugin.load()
        form = found() if isinstance(found, type) and issubclass(found, Form) else found
    except Exception as exc:  # whatever the package raises: it must not take a program down
        _PLUGIN_PROBLEMS[name] = (f"form {name!r} comes from the {plugin}, which cannot be "
                                  f"loaded: {type(exc).__name__}: {exc}")
        return None
    if not isinstance(form, Form):
        _PLUGIN_PROBLEMS[name] = (f"form {name!r} comes from the {plugin}, which gives "
                                  f"{type(found).__name__} {found!r:.60}: expected a subclass "
                                  "of bayesprog.Form (or an instance of one)")
        return None
    if form.name != name:
        _PLUGIN_PROBLEMS[name] = (f"form {name!r} comes from the {plugin}, which gives the "
                                  f"form {form.name!r}: expected an entry point named after "
                                  f"its form ({form.name} = {plugin.value})")
        return None
    register_form(form)
    return form
