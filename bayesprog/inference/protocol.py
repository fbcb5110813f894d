"""What inference needs of a program (the program layer builds on inference, not the reverse)."""

from __future__ import annotations

from typing import Protocol

from bayesprog.inference.core import InferenceCache
from bayesprog.model import InputDecl, Term
from bayesprog.vocabulary.variables import Variable


class ProgramLike(Protocol):
    """A checked program: its variables, inputs, terms (ablations applied) and cache."""

    name: str
    variables: dict[str, Variable]
    inputs: dict[str, InputDecl]
    ablated: tuple[str, ...]
    inference_cache: InferenceCache

    @property
    def active_terms(self) -> list[Term]: ...

    @property
    def conditioning(self) -> tuple[str, ...]:
        """The variables without a term, which every question gives."""
        ...

    def ancestors(self, name: str) -> set[str]: ...
