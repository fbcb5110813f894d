"""The checks of the variables and the runtime inputs: each variable built from its
declaration (states, range, grid, continuous, discretised), a field indexed by a discrete
variable, an input's dimensions."""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any

import numpy as np

from bayesprog.language.check.base import Checker
from bayesprog.model import InputDecl
from bayesprog.vocabulary.variables import (
    Continuous,
    Discrete,
    Variable,
    binned_variable,
    grid_variable,
)

if TYPE_CHECKING:  # (pydantic's models are built only for a file the plain reader leaves)
    from bayesprog.language.document import InputSpec
    from bayesprog.language.plain import PlainInput


def build_variable(name: str, spec: Any) -> Variable:
    if spec.states is not None:
        states = tuple(spec.states)
        # states named by integers (1, 2, 3): an integer in evidence or data is a name, not
        # an index, as for a range
        numbers = [int(s) for s in states if re.fullmatch(r"-?[0-9]+", s) and str(int(s)) == s]
        values = np.array(numbers) if len(numbers) == len(states) else None
        return Discrete(name, states, values=values, description=spec.description)
    if spec.range is not None:
        low, high = spec.range
        values = np.arange(low, high + 1)
        return Discrete(
            name, tuple(str(v) for v in values), values=values, description=spec.description,
            kind="range",
        )
    if spec.grid is not None:
        g = spec.grid
        return grid_variable(name, tuple(g.shape), g.cell, g.origin, spec.description)
    low, high = spec.continuous
    if spec.discretise is not None:
        return binned_variable(name, np.asarray(spec.discretise.edges(spec.continuous)),
                               (low, high), spec.description)
    return Continuous(name, float(low), float(high), spec.indexed_by, spec.description)


class VariablesCheck(Checker):
    """The ``variables:`` and ``inputs:`` sections."""

    def check_variables(self) -> None:
        for name, spec in self.doc.variables.items():
            self.variables[name] = build_variable(name, spec)
        for name, var in self.variables.items():
            if isinstance(var, Continuous) and var.index is not None:
                index = self.variables.get(var.index)
                if index is None or not index.is_discrete:
                    self.error(
                        ("variables", name, "indexed_by"),
                        f"variable {name!r} is indexed_by {var.index!r}: expected a declared "
                        f"discrete variable, found {'nothing' if index is None else 'a continuous one'}",
                    )

    def check_inputs(self) -> None:
        for name, spec in self.doc.inputs.items():
            self.inputs[name] = self.input_decl(name, spec)

    def input_decl(self, name: str, spec: InputSpec | PlainInput) -> InputDecl:
        axes: list[str] = []
        event: list[int | str] = []
        for i, dim in enumerate(spec.shape):
            if isinstance(dim, str) and dim in self.variables:
                if not self.variables[dim].is_discrete:
                    self.error(
                        ("inputs", name, "shape", i),
                        f"input {name!r}: dimension {dim!r} names a continuous variable; "
                        "expected a discrete variable, an integer or a free symbol",
                    )
                elif event:
                    self.error(
                        ("inputs", name, "shape", i),
                        f"input {name!r}: variable dimensions must come first, "
                        f"found {dim!r} after {event}",
                    )
                else:
                    axes.append(dim)
            elif isinstance(dim, int) and dim < 1:
                self.error(("inputs", name, "shape", i), f"expected a size >= 1, found {dim}")
            else:
                event.append(dim)
        return InputDecl(name, tuple(axes), tuple(event), spec.description)
