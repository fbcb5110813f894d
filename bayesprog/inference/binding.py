"""Binding a question's evidence, inputs and soft evidence to arrays with one flat batch axis.

Values arrive with any leading batch shape; they are checked against the variables and inputs
they are given for (states, supports, declared shapes), broadcast together, and flattened, so
that every method sees one batch axis of ``Bound.size`` rows.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bayesprog.errors import QuestionError, did_you_mean, expect_mapping, short_repr
from bayesprog.forms import ParamValue
from bayesprog.inference.protocol import ProgramLike
from bayesprog.vocabulary.expressions import Question
from bayesprog.vocabulary.variables import Continuous, Discrete, discrete


@dataclass
class Bound:
    """Evidence, inputs and soft evidence bound to flat batch arrays."""

    batch_shape: tuple[int, ...]
    discrete: dict[str, np.ndarray | int] = field(default_factory=dict)
    continuous: dict[str, ParamValue] = field(default_factory=dict)
    inputs: dict[str, ParamValue] = field(default_factory=dict)
    soft: dict[str, ParamValue] = field(default_factory=dict)
    #: terms made uniform on some rows, by their text (``str(term.expression)``): where
    #: (``[size]`` booleans, some of them True)
    ablated: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def size(self) -> int:
        return math.prod(self.batch_shape)  # (1 for no batch; read often: no numpy call)

    def rows(self, start: int, stop: int) -> Bound:
        """Rows ``start`` to ``stop`` of the flat batch (values without a batch axis kept)."""
        return self._picked(slice(start, stop), min(stop, self.size) - start)

    def take(self, rows: np.ndarray) -> Bound:
        """The rows ``rows`` (flat indices, in their order) of the flat batch, as a batch of
        their own (values without a batch axis kept)."""
        return self._picked(np.asarray(rows, dtype=np.intp), len(rows))

    def _picked(self, index: slice | np.ndarray, size: int) -> Bound:
        def cut(value: ParamValue) -> ParamValue:
            return ParamValue(value.axes, value.array[index], True) if value.batched \
                else value

        ablated = {k: v[index] for k, v in self.ablated.items()}
        return Bound(
            (size,),
            {k: v[index] if isinstance(v, np.ndarray) else v
             for k, v in self.discrete.items()},
            {k: cut(v) for k, v in self.continuous.items()},
            {k: cut(v) for k, v in self.inputs.items()},
            {k: cut(v) for k, v in self.soft.items()},
            {k: v for k, v in ablated.items() if v.any()})


def _flatten(arr: np.ndarray, own: tuple[int, ...], batch_shape: tuple[int, ...],
             trailing: int) -> tuple[np.ndarray, bool]:
    """Broadcast ``arr`` (batch ``own`` + trailing dims) to the common batch, flattened to one axis."""
    if not own:
        return arr, False
    tail = arr.shape[arr.ndim - trailing :] if trailing else ()
    full = arr if arr.shape == batch_shape + tail else np.broadcast_to(arr, batch_shape + tail)
    return full.reshape((-1,) + tail), True


def bind(
    program: ProgramLike,
    question: Question,
    evidence: Mapping[str, Any] | None,
    inputs: Mapping[str, Any] | None,
    soft: Mapping[str, Any] | None,
    ablate: Mapping[str, Any] | None = None,
) -> Bound:
    """``evidence``, ``inputs`` and ``soft`` evidence checked and flattened to one batch
    axis; ``ablate``: the rows on which terms (by their text, as ``str(term.expression)``)
    are made uniform, booleans that broadcast with the rest (a term ablated on no row is left
    out)."""
    expr = question.expression
    if not inputs and not soft and not ablate:
        named = _named_states(program, expr, evidence)
        if named is not None:
            return named
    variables = program.variables
    evidence = expect_mapping(evidence, "evidence", "variable names to values")
    inputs = expect_mapping(inputs, "inputs", "input names to arrays")
    soft = expect_mapping(soft, "soft", "variable names to likelihood vectors")
    values: dict[str, Any] = dict(expr.values)
    for name, value in evidence.items():
        if name not in variables:
            raise QuestionError(f"evidence for unknown variable {name!r}"
                                f"{did_you_mean(name, variables)} (declared: "
                                f"{', '.join(variables)})")
        if name not in expr.right:
            raise QuestionError(f"evidence for {name!r}, which is not known in {expr}"
                                f"{did_you_mean(name, expr.right)} (expected evidence for "
                                f"{', '.join(expr.right) or 'no variable'})")
        if name in expr.values:
            raise QuestionError(f"{name} is fixed to {expr.values[name]!r} by the question "
                                "and given again as evidence")
        values[name] = value
    missing = [n for n in expr.right if n not in values]
    if missing:
        raise QuestionError(f"missing evidence for {', '.join(missing)} in {expr}")

    staged: list[tuple[str, str, np.ndarray, tuple[int, ...], int]] = []
    for name, value in values.items():
        var = variables[name]
        if isinstance(var, Discrete):
            idx = _state_indices(var, value)
            staged.append(("discrete", name, idx, idx.shape, 0))
        else:
            arr = _continuous_values(var, value, variables)
            trailing = 1 if var.index is not None else 0
            staged.append(("continuous", name, arr, arr.shape[: arr.ndim - trailing], trailing))
    for name, value in inputs.items():
        decl = program.inputs.get(name)
        if decl is None:
            raise QuestionError(f"unknown input {name!r}{did_you_mean(name, program.inputs)} "
                                f"(declared inputs: {', '.join(program.inputs) or 'none'})")
        arr = _input_array(program, decl, value)
        staged.append(("input", name, arr, arr.shape[: arr.ndim - decl.ndim], decl.ndim))
    for name, value in soft.items():
        soft_var = variables.get(name)
        if not isinstance(soft_var, Discrete):
            raise QuestionError(f"soft evidence needs a declared discrete variable, found {name!r}"
                                + did_you_mean(name, [n for n, v in variables.items()
                                                      if isinstance(v, Discrete)]))
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise QuestionError(f"soft evidence on {name}: expected {soft_var.card} non-negative "
                                f"likelihoods (numbers), found {short_repr(value)}") from None
        if arr.ndim < 1 or arr.shape[-1] != soft_var.card or np.any(arr < 0) or not np.all(np.isfinite(arr)):
            raise QuestionError(f"soft evidence on {name}: expected {soft_var.card} non-negative "
                                f"likelihoods (one per state), found shape {arr.shape}")
        staged.append(("soft", name, arr, arr.shape[:-1], 1))
    for name, value in (ablate or {}).items():
        arr = np.asarray(value)
        if arr.dtype != np.bool_:
            raise QuestionError(f"ablate {name}: expected booleans (True on the rows where the "
                                f"term is uniform), found {short_repr(value)}")
        staged.append(("ablated", name, arr, arr.shape, 0))
    try:
        batch_shape = tuple(np.broadcast_shapes(*(s[3] for s in staged))) if staged else ()
    except ValueError:
        shapes = ", ".join(f"{s[1]}: {s[3]}" for s in staged)
        raise QuestionError(f"batch shapes do not broadcast together ({shapes})") from None
    bound = Bound(batch_shape)
    for kind, name, arr, own, trailing in staged:
        flat, batched = _flatten(arr, own, batch_shape, trailing)
        if kind == "discrete":
            bound.discrete[name] = flat if batched else int(flat)
        elif kind == "continuous":
            var = variables[name]
            axes = (var.index,) if var.index else ()  # type: ignore[union-attr]
            bound.continuous[name] = ParamValue(axes, flat, batched)
        elif kind == "input":
            bound.inputs[name] = ParamValue(program.inputs[name].axes, flat, batched)
        elif kind == "ablated":
            rows = np.broadcast_to(flat, (bound.size,))
            if rows.any():
                bound.ablated[name] = rows
        else:
            bound.soft[name] = ParamValue((name,), flat, batched)
    return bound


def _named_states(program: ProgramLike, expr: Any, evidence: Any) -> Bound | None:
    """The common case in one pass: each known variable discrete and given one state by name
    (in the evidence or the question's text). None for anything else, which :func:`bind`
    checks and explains."""
    if evidence is None:
        evidence = {}
    elif type(evidence) is not dict:
        return None
    right, fixed = expr.right, expr.values
    if len(evidence) + len(fixed) != len(right):
        return None
    lookups = _state_lookups(program)
    found: dict[str, np.ndarray | int] = {}
    for values in (evidence, fixed) if fixed else (evidence,):
        for name, value in values.items():
            lookup = lookups.get(name)
            if lookup is None:
                var = program.variables.get(name)
                if not isinstance(var, Discrete):
                    return None
                lookup = lookups[name] = var._lookup
            if type(value) is not str or name in found or name not in right:
                return None
            index = lookup.get(value)
            if index is None:
                return None
            found[name] = index
    return Bound((), found)


def _state_lookups(program: ProgramLike) -> dict[str, dict[str, int]]:
    """Each discrete variable's states by name, as far as made (kept with the program's
    compiled pieces)."""
    cache = program.inference_cache
    if cache.state_lookups is None:
        cache.state_lookups = {}  # filled as variables are asked about
    return cache.state_lookups


def _cell_indices(var: Discrete, value: Any) -> Any:
    """A grid's cells given as ``(ix, iy, ...)`` tuples, as answers give them (a tuple, or
    lists of tuples for a batch), as their indices; None for anything else."""
    dims = len(var.grid_shape or ())
    if isinstance(value, tuple):
        if len(value) != dims or not all(isinstance(i, (int, np.integer)) for i in value):
            return None
        name = "_".join(str(int(i)) for i in value)
        if name not in var._lookup:
            raise QuestionError(f"unknown cell {value} of {var.name} (its grid is "
                                f"{' x '.join(map(str, var.grid_shape or ()))})")
        return var._lookup[name]
    if isinstance(value, list) and value and _cell_indices(var, value[0]) is not None:
        out = [_cell_indices(var, v) for v in value]
        if any(v is None for v in out):
            raise QuestionError(f"evidence for {var.name}: expected cells (ix, iy, ...) "
                                "throughout, found a mixture of cells and other values")
        return out
    return None


def _state_indices(var: Discrete, value: Any) -> np.ndarray:
    if isinstance(value, str) and value in var._lookup:  # one state by name: the common case
        return np.asarray(var._lookup[value], dtype=np.intp)
    if var.kind == "grid" and isinstance(value, (tuple, list)):
        cells = _cell_indices(var, value)
        if cells is not None:
            return np.asarray(cells, dtype=np.intp)
    arr = np.asarray(value)
    if arr.size == 0:  # no rows: no values to read, whatever numpy made their type
        return np.zeros(arr.shape, dtype=np.intp)
    if var.edges is not None and arr.dtype.kind in "iuf":  # a discretised variable: a reading
        assert var.support is not None
        low, high = var.support
        outside = ~((arr >= low) & (arr <= high))
        if np.any(outside):
            raise QuestionError(f"evidence for {var.name}: {arr[outside].ravel()[0]} is outside "
                                f"its support [{low}, {high}]")
        return np.searchsorted(var.edges[1:-1], arr, side="right").astype(np.intp)
    if arr.dtype.kind in "iu":
        if var.values is not None:
            lookup = {int(v): i for i, v in enumerate(var.values)}
            bad = [v for v in np.unique(arr) if int(v) not in lookup]
            if bad:
                raise QuestionError(f"unknown value {bad[0]} of {var.name} (expected "
                                    f"{var.values[0]}..{var.values[-1]})")
            return np.vectorize(lookup.__getitem__, otypes=[np.intp])(arr) if arr.size else arr
        # (a few values, the common case of one evidence set, checked without reductions)
        beyond = any(not 0 <= v < var.card for v in arr.ravel().tolist()) \
            if arr.size <= 16 else bool(arr.min() < 0 or arr.max() >= var.card)
        if beyond:
            bad = arr[(arr < 0) | (arr >= var.card)].ravel()[0]
            raise QuestionError(f"state index {bad} of {var.name} is out of range "
                                f"(0..{var.card - 1})")
        return arr.astype(np.intp, copy=False)
    if arr.dtype.kind in "USO":
        names, inverse = np.unique(arr.astype(str), return_inverse=True)
        codes = np.empty(len(names), dtype=np.intp)
        for i, item in enumerate(names):
            try:
                codes[i] = var.index_of(str(item))
            except KeyError:
                raise QuestionError(f"unknown state {str(item)!r} of {var.name}"
                                    f"{did_you_mean(str(item), var.states)} (expected one "
                                    f"of {var.describe_states()})") from None
        return codes[inverse].reshape(arr.shape)
    raise QuestionError(f"evidence for {var.name}: expected state names or indices, "
                        f"found {arr.dtype} values")


def _continuous_values(var: Continuous, value: Any, variables: Mapping) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise QuestionError(f"evidence for {var.name}: expected numbers, found {value!r}") from None
    if var.index is not None:
        card = variables[var.index].card
        if arr.ndim < 1 or arr.shape[-1] != card:
            raise QuestionError(f"evidence for field {var.name}: expected a last dimension of "
                                f"{card} (one value per state of {var.index}), found shape "
                                f"{arr.shape}")
    if not arr.size:
        return arr
    # one pass for the usual case: the smallest and largest values inside the support (NaN,
    # a field's missing value, is skipped by fmin/fmax unless every value is NaN)
    low, high = np.fmin.reduce(arr, axis=None), np.fmax.reduce(arr, axis=None)
    if var.index is not None and low >= var.low and high <= var.high and np.isfinite(low) \
            and np.isfinite(high):
        return arr
    missing = np.isnan(arr)
    if missing.any() and var.index is None:
        raise QuestionError(f"evidence for {var.name}: expected numbers, found NaN (a variable "
                            "that is not observed is left out of the evidence)")
    if not np.all(np.isfinite(arr[~missing])) and np.isfinite(var.width):
        raise QuestionError(f"evidence for {var.name}: expected finite values")
    with np.errstate(invalid="ignore"):
        outside = (arr < var.low) | (arr > var.high)
    if np.any(outside):
        raise QuestionError(f"evidence {var.name}={arr[outside].ravel()[0]:g} is outside its "
                            f"support [{var.low:g}, {var.high:g}]")
    return arr


def _input_array(program: ProgramLike, decl: Any, value: Any) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise QuestionError(f"input {decl.name!r}: expected an array of numbers") from None
    want: list[int | str] = [discrete(program.variables[a]).card for a in decl.axes] + list(decl.event)
    declared = list(decl.axes) + list(decl.event)
    ok = arr.ndim >= len(want)
    symbols: dict[str, int] = {}
    if ok:
        for w, got in zip(want, arr.shape[arr.ndim - len(want) :], strict=False):
            if isinstance(w, int):
                ok &= w == got
            else:
                ok &= symbols.setdefault(w, got) == got
    if not ok:
        raise QuestionError(f"input {decl.name!r}: expected trailing shape {declared} "
                            f"(= {[w if isinstance(w, int) else '?' for w in want]}), found "
                            f"{list(arr.shape)}")
    if not np.all(np.isfinite(arr)):
        raise QuestionError(f"input {decl.name!r}: expected finite values")
    return arr
