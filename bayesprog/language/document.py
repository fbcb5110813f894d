"""The structure of a program file (format version 1), as pydantic models.

Only the shape of the document is checked here; what refers to what (variables in terms,
states in tables, parameter constraints) is checked by :mod:`bayesprog.language.check`.
"""

from __future__ import annotations

import difflib
import math
import typing
from collections import Counter
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar, get_args, get_origin

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    WithJsonSchema,
    field_validator,
    model_validator,
)

from bayesprog.errors import Diagnostic, SpecError, short_repr
from bayesprog.language.loader import Located, load_yaml
from bayesprog.language.plain import check_states, name_of_number
from bayesprog.model.records import FitRecord
from bayesprog.support.files import KINDS

FORMAT_VERSION = 1
M = TypeVar("M", bound=BaseModel)


#: Axes of a grid variable (numpy arrays have at most 32 dimensions, and a question may add
#: a batch axis).
MAX_AXES = 16


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=False)


class GridSpec(_Strict):
    shape: list[int] = Field(min_length=1, description="number of cells along each axis")
    cell: float = Field(1.0, gt=0, description="side of a cell, in the unit of the coordinates")
    origin: list[float] | None = Field(None, description="corner of the grid (default zeros)")

    @model_validator(mode="after")
    def _positive(self) -> GridSpec:
        if any(n < 1 for n in self.shape):
            raise ValueError(f"grid shape must have sizes >= 1, got {self.shape}")
        if len(self.shape) > MAX_AXES:
            raise ValueError(f"expected at most {MAX_AXES} axes, found {len(self.shape)}")
        check_states(math.prod(self.shape), f"a grid of {' x '.join(map(str, self.shape))}")
        if self.origin is not None and len(self.origin) != len(self.shape):
            raise ValueError(
                f"origin must have {len(self.shape)} coordinates (one per axis), "
                f"got {len(self.origin)}"
            )
        return self


class DiscretiseSpec(_Strict):
    """Bins of a discretised continuous variable: a number of equal bins over a bounded
    support, or the bin edges (increasing; the outer bins also take the tails)."""

    bins: int | list[float] = Field(description="a number of equal bins (>= 2) or the edges")

    def check_support(self, support: list[float]) -> None:
        low, high = support
        if isinstance(self.bins, int):
            if not 2 <= self.bins <= MAX_BINS:
                raise ValueError(f"expected between 2 and {MAX_BINS:,} bins, found {self.bins}")
            if not (math.isfinite(low) and math.isfinite(high)):
                raise ValueError(f"equal bins need a bounded support, found [{low}, {high}]: "
                                 "give the edges (bins: [e0, e1, ...])")
            return
        edges = self.bins
        if not 3 <= len(edges) <= MAX_BINS + 1:
            raise ValueError(f"expected between 3 and {MAX_BINS + 1:,} edges, found {len(edges)}")
        if not all(math.isfinite(e) for e in edges) or any(
                b <= a for a, b in zip(edges, edges[1:], strict=False)):
            raise ValueError(f"expected finite, increasing bin edges, found {edges}")
        if edges[0] < low or edges[-1] > high:
            raise ValueError(f"expected edges inside the support [{low}, {high}], found "
                             f"[{edges[0]}, {edges[-1]}]")

    def edges(self, support: list[float]) -> list[float]:
        if isinstance(self.bins, int):
            low, high = support
            return [low + (high - low) * i / self.bins for i in range(self.bins + 1)]
        return list(self.bins)


#: The most bins a discretised variable may have (a discrete variable of that many states).
MAX_BINS = 100_000


class VariableSpec(_Strict):
    """Exactly one of ``states``, ``range``, ``grid`` or ``continuous``."""

    states: Annotated[list[str], WithJsonSchema(
        {"type": "array", "items": {"type": ["string", "number"]}})] | None = Field(
        None, description="named states of a discrete variable (a number is a name, as written)")
    range: list[int] | None = Field(
        None, min_length=2, max_length=2, description="inclusive integer range [low, high]"
    )
    grid: GridSpec | None = Field(None, description="a grid of cells whose states carry coordinates")
    continuous: list[float] | None = Field(
        None, min_length=2, max_length=2, description="support [low, high] of a real variable"
    )
    indexed_by: str | None = Field(
        None, description="a continuous field: one value per state of this discrete variable"
    )
    discretise: DiscretiseSpec | None = Field(
        None, description="answer a continuous variable on bins (it may then have discrete "
        "children): its term gives each bin the probability of the interval"
    )
    description: str = ""

    @field_validator("states", mode="before")
    @classmethod
    def _numbers_are_names(cls, value: Any) -> Any:
        # a state is a name: an unquoted number (states: [1, 2, 3]) names it as written
        if isinstance(value, list):
            return [name_of_number(v) for v in value]
        return value

    @model_validator(mode="after")
    def _one_kind(self) -> VariableSpec:
        kinds = [k for k in ("states", "range", "grid", "continuous") if getattr(self, k) is not None]
        if len(kinds) != 1:
            found = ", ".join(kinds) if kinds else "none"
            raise ValueError(
                f"expected exactly one of states, range, grid, continuous; found {found}"
            )
        if self.indexed_by is not None and self.continuous is None:
            raise ValueError("indexed_by is only for continuous variables")
        if self.states is not None:
            if not self.states:
                raise ValueError("expected at least one state, found none")
            dups = sorted(s for s, n in Counter(self.states).items() if n > 1)
            if dups:
                raise ValueError(f"expected distinct state names, found {dups} twice")
        if self.range is not None and self.range[0] > self.range[1]:
            raise ValueError(f"expected range [low, high] with low <= high, got {self.range}")
        if self.range is not None:
            check_states(self.range[1] - self.range[0] + 1, f"the range {self.range}")
        if self.continuous is not None and not self.continuous[0] < self.continuous[1]:
            raise ValueError(f"expected support [low, high] with low < high, got {self.continuous}")
        if self.discretise is not None:
            if self.continuous is None or self.indexed_by is not None:
                raise ValueError("discretise is for a continuous variable (not a field)")
            self.discretise.check_support(self.continuous)
        return self


class InputSpec(_Strict):
    """A named runtime array bound when a question is asked."""

    shape: list[int | str] = Field(
        default_factory=list,
        description="trailing shape: a discrete variable's name (one axis over its states), "
        "an integer, or a free symbol; leading extra dimensions are batch dimensions",
    )
    description: str = ""


class _WithParameters(BaseModel):
    """A form and its parameters, which sit beside ``form`` (checked by the form itself)."""

    model_config = ConfigDict(extra="allow")

    @property
    def parameters(self) -> dict[str, Any]:
        return dict(self.model_extra or {})


class LearnSpec(_Strict):
    """How a term's parameters are learned from data (``bayesprog learn``, ``Program.fit``)."""

    pseudo_counts: Any = Field(
        None, description="table and categorical: Dirichlet pseudo-counts, one number or a "
        "table laid out like the term's (the estimate is the posterior mean)")
    components: int | list[int] | None = Field(
        None, description="gmm: the number of components, or several to choose from by BIC")
    shared: list[str] = Field(
        default_factory=list, description="parameters kept equal across parent states "
        "(pooled); the others are learned per parent state")


class TermSpec(_WithParameters):
    """``P(X | parents)`` with a form."""

    term: str = Field(description="P(X | parents)")
    form: str = Field(description="name of a registered parametric form")
    description: str = ""
    learn: bool | LearnSpec = Field(
        True, description="false keeps the term as written when the program is learned; a "
        "mapping gives learning options")


class SoftEvidenceSpec(_WithParameters):
    """A likelihood over the states of ``variable`` (virtual evidence), given by a form."""

    variable: str = Field(description="the discrete variable the likelihood is over")
    form: str = Field(description="categorical (a vector or an input) or program")
    description: str = ""


class QuestionSpec(_Strict):
    ask: str = Field(description="P(searched | known)")
    kind: Literal["posterior", "map", "filter", "smooth", "sequence", "probability"] = Field(
        "posterior", description="posterior, map, or over a sequence of steps (a program with "
        "time:): filter, smooth, sequence (the most likely sequence); probability: of an "
        "event, P(A=a, B=b | C=c) (the kind of a question with values on its left)")
    description: str = ""


class TimeSpec(_Strict):
    """A program that repeats per time step: its decomposition is one step."""

    previous: dict[str, str] = Field(
        min_length=1, description="{PREVIOUS: STATE, ...}: each variable PREVIOUS is the state "
        "variable STATE one step earlier (one pair per discrete state variable); the terms of "
        "the PREVIOUS variables are the belief before the first step")


class Document(_Strict):
    bayesprog: Literal[1] = Field(description="format version")
    name: str | None = None
    description: str = ""
    variables: dict[str, VariableSpec] = Field(min_length=1)
    inputs: dict[str, InputSpec] = Field(default_factory=dict)
    decomposition: list[TermSpec] = Field(min_length=1)
    soft_evidence: list[SoftEvidenceSpec] = Field(default_factory=list)
    questions: dict[str, QuestionSpec | str] = Field(default_factory=dict)
    time: TimeSpec | None = Field(None, description="the decomposition is one time step")
    ablate: list[str] = Field(default_factory=list)
    learned: list[FitRecord] = Field(default_factory=list, description="fits that set the "
                                     "parameters, oldest first")

    @field_validator("bayesprog", mode="before")
    @classmethod
    def _version_is_an_integer(cls, value: Any) -> Any:
        if isinstance(value, bool):
            raise ValueError(f"unsupported format version: expected 'bayesprog: 1', found {value}")
        return value

    def question(self, name: str) -> QuestionSpec:
        q = self.questions[name]
        return QuestionSpec(ask=q, kind="posterior") if isinstance(q, str) else q


#: pydantic's names for the branches of a union, left out of the paths in messages (a branch
#: tagged ``<name>`` by a discriminator is left out too)
_UNION_TAGS = {"QuestionSpec", "str"}


def validate_located(located: Located, model: type[M]) -> tuple[M | None, list[Diagnostic]]:
    """Validate loaded data against a pydantic model; problems located by line and column."""
    try:
        return model.model_validate(located.data), []
    except ValidationError as exc:
        out: list[Diagnostic] = []
        seen: set[tuple[int, int]] = set()
        for err in exc.errors():
            raw_loc = tuple(err["loc"])
            if "str" in raw_loc and not isinstance(err.get("input"), str):
                continue  # the string shorthand of a union did not apply: the other branch speaks
            loc = tuple(p for p in raw_loc if not (isinstance(p, str) and (
                p in _UNION_TAGS or (p.startswith("<") and p.endswith(">")))))
            msg = err["msg"].removeprefix("Value error, ")
            at_key = False
            if err["type"] == "missing":
                msg = f"missing required key {loc[-1]!r}"
                loc = loc[:-1]
            elif err["type"] == "extra_forbidden":
                msg = f"unknown key {loc[-1]!r}"
                if ")" in str(loc[-1]):
                    msg += " (inside a flow mapping {...}, quote text that contains a comma)"
                else:
                    msg += _expected_keys(model, raw_loc[:-1], str(loc[-1]))
                at_key = True
            elif err["type"] == "literal_error" and loc == ("bayesprog",):
                msg = f"unsupported format version: expected 'bayesprog: 1', found {err['input']!r}"
            elif err["type"] == "value_error":
                msg = f"{'.'.join(map(str, loc))}: {msg}"
            elif err["type"] in ("too_long", "too_short") and "actual_length" in err.get("ctx", {}):
                ctx = err["ctx"]
                bound = ("at most", ctx.get("max_length")) if err["type"] == "too_long" else \
                    ("at least", ctx.get("min_length"))
                kind = "entries" if ctx.get("field_type") == "Dictionary" else "items"
                msg = (f"{'.'.join(map(str, loc))}: expected {bound[0]} {bound[1]} {kind}, found "
                       f"{ctx['actual_length']}: {short_repr(err.get('input'))}")
            else:
                msg = f"{'.'.join(map(str, loc))}: {msg}, found {short_repr(err.get('input'))}"
            d = located.diagnostic(loc, msg, at_key=at_key)
            if (d.line, d.column) not in seen:
                seen.add((d.line, d.column))
                out.append(d)
        return None, out


def _expected_keys(model: type[BaseModel], where: tuple, key: str) -> str:
    """What the mapping at ``where`` (pydantic's location, union tags included) takes: ":
    expected a, b or c" and the nearest spelling of ``key`` among them; "" when unknown."""
    types: list[Any] = [model]
    for part in where:
        if isinstance(part, str) and (part in _UNION_TAGS or (part.startswith("<")
                                                              and part.endswith(">"))):
            continue  # a branch of a union: its members stay in view
        types = [t for member in types for t in _inside(member, part)]
    keys = sorted({name for member in types for leaf in _leaves(member)
                   if isinstance(leaf, type) and issubclass(leaf, BaseModel)
                   for name in leaf.model_fields})
    if not keys:
        return ""
    near = difflib.get_close_matches(key, keys, n=1, cutoff=0.6)
    listed = ", ".join(keys[:-1]) + f" or {keys[-1]}" if len(keys) > 1 else keys[0]
    return f": expected {listed}" + (f" (did you mean {near[0]!r}?)" if near else "")


def _leaves(annotation: Any) -> list[Any]:
    """The types an annotation may hold: the members of a union, without ``Annotated``."""
    origin = get_origin(annotation)
    if origin is typing.Annotated:
        return _leaves(get_args(annotation)[0])
    if origin is typing.Union or str(origin) == "<class 'types.UnionType'>":
        return [leaf for arg in get_args(annotation) for leaf in _leaves(arg)]
    return [annotation]


def _inside(annotation: Any, part: Any) -> list[Any]:
    """The annotations found at ``part`` (a key or an index) of a value of ``annotation``."""
    out = []
    for leaf in _leaves(annotation):
        origin = get_origin(leaf)
        if isinstance(leaf, type) and issubclass(leaf, BaseModel):
            if isinstance(part, str) and part in leaf.model_fields:
                out.append(leaf.model_fields[part].annotation)
        elif origin in (list, tuple) and isinstance(part, int) and get_args(leaf):
            out.append(get_args(leaf)[0])
        elif origin is dict and isinstance(part, str) and len(get_args(leaf)) == 2:
            out.append(get_args(leaf)[1])
    return out


def load_document(path: Path, model: type[M]) -> tuple[Located, M]:
    """Read a YAML file strictly into ``model``; raises :class:`SpecError` with every problem
    (``OSError`` when the file cannot be read: check it first with ``reference_problem``)."""
    kind = next((KINDS[k] for k in model.model_fields if k in KINDS), "document")
    located, problems = load_yaml(path.read_text(encoding="utf-8"), str(path), kind)
    if problems:
        raise SpecError(problems)
    spec, problems = validate_located(located, model)
    if spec is None:
        raise SpecError(problems)
    return located, spec
