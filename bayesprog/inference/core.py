"""What every inference method shares: the log-factor, and the per-program cache of compiled
pieces (contraction expressions, evidence-free factors, compiled tables)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import opt_einsum


@dataclass
class Factor:
    """A log-factor over ``axes``: ``log`` is ``[B] + cards`` if ``batched``, else ``cards``."""

    axes: tuple[str, ...]
    log: np.ndarray
    batched: bool


class Plans:
    """A cache of opt_einsum contraction expressions keyed by the operands' layout."""

    def __init__(self) -> None:
        self._cache: dict[Any, Any] = {}

    def get(self, operands: list[Factor], output: tuple[str, ...], batched_out: bool) -> Any:
        # the batch size is left out of the key: a plan serves every batch size (opt_einsum
        # checks ranks, not sizes), so batches that vary from call to call are not replanned
        key = (tuple((f.axes, f.batched, f.log.shape[f.batched:]) for f in operands), output,
               batched_out)
        expr = self._cache.get(key)
        if expr is None:
            names = sorted({a for f in operands for a in f.axes} | set(output))
            sym = {n: opt_einsum.get_symbol(i + 1) for i, n in enumerate(names)}
            batch = opt_einsum.get_symbol(0)
            terms = [(batch if f.batched else "") + "".join(sym[a] for a in f.axes)
                     for f in operands]
            out = (batch if batched_out else "") + "".join(sym[a] for a in output)
            eq = ",".join(terms) + "->" + out
            expr = opt_einsum.contract_expression(eq, *(f.log.shape for f in operands))
            self._cache[key] = expr
        return expr


@dataclass
class InferenceCache:
    """Compiled pieces a program keeps between questions (its terms never change: an ablation
    is a new program with a cache of its own)."""

    plans: Plans = field(default_factory=Plans)
    #: factors of terms that depend on no evidence nor input, by id of the term
    static_factors: dict[int, Factor] = field(default_factory=dict)
    #: compiled tables of the table method, by (searched, observed)
    tables: dict[Any, Any] = field(default_factory=dict)
    #: the methods that apply to a layout of question, cheapest first, with their estimates
    #: and the batch size they were made for
    rankings: dict[Any, tuple[int, list[Any]]] = field(default_factory=dict)
    #: a named method's estimate for a layout of question, and the batch size it was made for
    estimates: dict[Any, tuple[int, Any]] = field(default_factory=dict)
    #: programs derived from this one for a method (its real variables on bins, ...)
    derived: dict[Any, Any] = field(default_factory=dict)
