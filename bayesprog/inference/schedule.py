"""What the dispatcher keeps per layout of question to schedule its questions among the
methods (:func:`bayesprog.inference.compute_posterior`): one object, :class:`Schedule`, held by
the :class:`~bayesprog.inference.plan.Layout`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Schedule:
    """The state of one layout's scheduling."""

    #: whether a question of this layout was asked (the first is answered without a plan)
    asked: bool = False
    #: when the layout's answer does not depend on the evidence's values: its one row of
    #: probabilities, the log of its normaliser, and the method that made it
    fixed: tuple[np.ndarray, float, str] | None = None
    #: the same, made by an exact method a question named, by the method's name
    fixed_by: dict[str, tuple[np.ndarray, float, str]] = field(default_factory=dict)
    #: the methods that apply, cheapest first, with their estimates and the batch size they
    #: were made for, by (registry version, order of magnitude of the batch)
    rankings: dict[Any, tuple[int, list[Any]]] = field(default_factory=dict)
    #: operations spent so far on questions of this layout (inf once a method's setup is
    #: paid): a method with a setup is chosen once as much was spent on the others (ski rental)
    spent: float = 0.0
    #: the method chosen for a batch size once no setup is left to weigh, by (registry
    #: version, batch size, memory limit)
    settled: dict[Any, Any] = field(default_factory=dict)
    #: a named method's estimate, and the batch size it was made for
    estimates: dict[Any, tuple[int, Any]] = field(default_factory=dict)
