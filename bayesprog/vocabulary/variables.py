"""Variables of a Bayesian program: discrete (named states, integer ranges, grids) and continuous."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True, eq=False)
class Discrete:
    """A discrete variable. ``coords`` (one row per state) is set for grids, ``values`` for
    ranges (the integers) and for discretised continuous variables (``kind="bins"``: the bins'
    midpoints, with their ``edges``)."""

    name: str
    states: tuple[str, ...]
    values: np.ndarray | None = None
    coords: np.ndarray | None = None
    grid_shape: tuple[int, ...] | None = None
    cell: float | None = None
    description: str = ""
    kind: str = "states"
    #: bin edges of a discretised continuous variable (``card + 1``), and its support
    edges: np.ndarray | None = None
    support: tuple[float, float] | None = None

    @property
    def card(self) -> int:
        return len(self.states)

    @property
    def typed_states(self) -> tuple[Any, ...]:
        """The states as values of the variable's type: integers for a range, the cell's
        indices (ix, iy, ...) for a grid, names else (computed once)."""
        cache = self.__dict__.get("_typed_cache")
        if cache is None:
            if self.kind == "range" and self.values is not None:
                cache = tuple(int(v) for v in self.values)
            elif self.kind == "bins" and self.values is not None:
                cache = tuple(float(v) for v in self.values)
            elif self.kind == "grid":
                cache = tuple(tuple(int(i) for i in s.split("_")) for s in self.states)
            else:
                cache = self.states
            object.__setattr__(self, "_typed_cache", cache)
        return cache

    @property
    def is_discrete(self) -> bool:
        return True

    def index_of(self, value: object) -> int:
        """The index of a state given by name, by integer value (ranges) or else by index.

        >>> g = grid_variable("O", (2, 3))
        >>> g.index_of("1_2"), g.index_of(5), g.index_of("5")
        (5, 5, 5)
        """
        if self.edges is not None and not isinstance(value, (bool, np.bool_)):
            return self._bin_of(value)
        if isinstance(value, (str, np.str_)):
            text = str(value).strip()
            if text in self._lookup:
                return self._lookup[text]
            if _is_int(text):  # an integer value of a range, or the index of a state
                return self.index_of(int(text))
            raise KeyError(text)
        if isinstance(value, (bool, np.bool_)):
            raise KeyError(value)
        if isinstance(value, (int, np.integer)):
            if self.values is not None:
                hits = np.flatnonzero(self.values == int(value))
                if hits.size:
                    return int(hits[0])
                raise KeyError(value)
            if 0 <= int(value) < self.card:
                return int(value)
            raise KeyError(value)
        raise KeyError(value)

    def _bin_of(self, value: object) -> int:
        """The bin of a number (a bin's name is also accepted) within the support."""
        assert self.edges is not None and self.support is not None
        if isinstance(value, (str, np.str_)) and str(value).strip() in self._lookup:
            return self._lookup[str(value).strip()]
        try:
            x = float(value)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise KeyError(value) from None
        low, high = self.support
        if not low <= x <= high:
            raise KeyError(value)
        inner = self.edges[1:-1]
        return int(np.searchsorted(inner, x, side="right"))

    def describe_states(self, limit: int = 6) -> str:
        shown = ", ".join(self.states[:limit])
        return shown + (f", ... ({self.card} states)" if self.card > limit else "")

    @property
    def _lookup(self) -> dict[str, int]:
        cache = self.__dict__.get("_lookup_cache")
        if cache is None:
            cache = {s: i for i, s in enumerate(self.states)}
            object.__setattr__(self, "_lookup_cache", cache)
        return cache


@dataclass(frozen=True, eq=False)
class Continuous:
    """A real variable on ``[low, high]``; with ``index`` it is a field: one value per index state."""

    name: str
    low: float = -np.inf
    high: float = np.inf
    index: str | None = None
    description: str = ""
    kind: str = field(default="continuous")

    @property
    def is_discrete(self) -> bool:
        return False

    @property
    def width(self) -> float:
        return float(self.high - self.low)


Variable = Discrete | Continuous


def discrete(var: Variable) -> Discrete:
    """``var`` as a discrete variable, for code that has established that it is one."""
    if not isinstance(var, Discrete):
        raise TypeError(f"{var.name} is continuous where a discrete variable is expected")
    return var


def _is_int(text: str) -> bool:
    try:
        int(text)
    except ValueError:
        return False
    return True


def grid_variable(
    name: str,
    shape: tuple[int, ...],
    cell: float = 1.0,
    origin: tuple[float, ...] | None = None,
    description: str = "",
) -> Discrete:
    """A grid of cells in row-major order; state ``"i_j"`` has centre ``origin + (i+.5, j+.5)*cell``.

    >>> g = grid_variable("O", (2, 3), cell=0.5)
    >>> g.states[:4], g.coords[4].tolist()
    (('0_0', '0_1', '0_2', '1_0'), [0.75, 0.75])
    """
    origin_arr = np.zeros(len(shape)) if origin is None else np.asarray(origin, float)
    index = np.indices(shape).reshape(len(shape), -1).T
    coords = origin_arr + (index + 0.5) * cell
    states = tuple("_".join(str(i) for i in row) for row in index)
    return Discrete(
        name,
        states,
        coords=coords,
        grid_shape=tuple(shape),
        cell=cell,
        description=description,
        kind="grid",
    )


def binned_variable(name: str, edges: np.ndarray, support: tuple[float, float],
                    description: str = "") -> Discrete:
    """A continuous variable answered on bins: one state per interval ``[e_i, e_i+1)``, its
    value the interval's midpoint; the first and last bins also take the tails of the support.

    >>> x = binned_variable("X", np.array([0.0, 1.0, 3.0]), (0.0, 3.0))
    >>> x.states, x.typed_states, x.index_of(2.5), x.index_of("1.0")
    (('[0, 1)', '[1, 3]'), (0.5, 2.0), 1, 1)
    """
    edges = np.asarray(edges, float)
    states = tuple(f"[{_number(a)}, {_number(b)}{']' if i == len(edges) - 2 else ')'}"
                   for i, (a, b) in enumerate(zip(edges[:-1], edges[1:], strict=True)))
    return Discrete(name, states, values=(edges[:-1] + edges[1:]) / 2, description=description,
                    kind="bins", edges=edges, support=(float(support[0]), float(support[1])))


def _number(x: float) -> str:
    return f"{x:.6g}"
