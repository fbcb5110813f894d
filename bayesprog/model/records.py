"""The provenance of a fit, as written under ``learned:`` in a fitted file (:class:`FitRecord`),
and of a discovered decomposition (:class:`StructureRecord`).

Plain dataclasses, so that learning and writing a fitted file never import pydantic: a record
of the common shape is read by :mod:`bayesprog.language.plain`, any other by pydantic, which
validates a dataclass field by field (``__pydantic_config__``: no unknown keys) and takes each
field's description from its metadata for the published schema.
"""

from __future__ import annotations

import dataclasses
from typing import Any

#: pydantic's configuration of both records, read when a document is validated by pydantic
_CONFIG = {"extra": "forbid", "strict": False}


def _field(description: str, default: Any = dataclasses.MISSING,
           default_factory: Any = dataclasses.MISSING) -> Any:
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory,
                                 metadata={"description": description})
    return dataclasses.field(default=default, metadata={"description": description})


@dataclasses.dataclass(kw_only=True)
class StructureRecord:
    """How a program's decomposition was discovered from data (``bayesprog discover``)."""

    __pydantic_config__ = _CONFIG

    method: str = _field("hc (hill climbing) or pc (the stable PC algorithm)")
    score: str | None = _field("hc: the score climbed (bic, bdeu, k2)", None)
    score_value: float | None = _field("hc: the discovered DAG's score", None)
    equivalent_sample_size: float | None = _field("bdeu: its prior's weight", None)
    test: str | None = _field("pc: the independence test (chi2, g)", None)
    significance: float | None = _field("pc: the level below which a test keeps an edge", None)
    max_conditioning: int | None = _field("pc: the largest conditioning set", None)
    tests: int | None = _field("pc: the independence tests run", None)
    iterations: int | None = _field("hc: the operations applied", None)
    restarts: int | None = _field("hc: the random restarts", None)
    seed: int | None = _field("hc: the seed of the restarts", None)
    families_scored: int | None = _field("hc: family scores computed (each once)", None)
    seconds: float = _field("the search's time")
    missing: str = _field("how missing values were used")
    constraints: dict[str, Any] = _field("forbidden and required arcs, tiers, the parents' "
                                         "limit, the start", default_factory=dict)
    oriented_by_choice: list[str] = _field(
        "pc: arcs whose direction the data left open, chosen without making a v-structure or "
        "a cycle", default_factory=list)
    discretised: dict[str, list[float]] = _field("columns binned by --discretise: their bins' "
                                                 "edges", default_factory=dict)
    warnings: list[str] = _field("arcs the data contradict in a way the search cannot see: "
                                 "into a variable that is a function of its other parents",
                                 default_factory=list)

    def as_data(self) -> dict[str, Any]:
        """The fields that say something (neither None nor empty), as written into a file."""
        return {k: v for k, v in dataclasses.asdict(self).items()
                if v is not None and v != {} and v != []}


@dataclasses.dataclass(kw_only=True)
class FitRecord:
    """The provenance of one fit, written into the fitted file; its statistics let a later fit
    continue with more data."""

    __pydantic_config__ = _CONFIG

    data: str = _field("the data file's name")
    sha256: str = _field("SHA-256 of the data file's bytes")
    rows: int = _field("rows in the data file")
    rows_used: int = _field("rows with a value for at least one learned term")
    log_likelihood: float = _field("log-likelihood of the rows used, fitted program")
    method: str = _field("maximum likelihood, or EM when values are missing")
    iterations: int = 1
    digits: int | None = _field(
        "significant digits the learned values are written with, when rounded (learn "
        "--rounded): as many as the rows behind them support (rounding moves a value by under "
        "a twentieth of 1/sqrt(rows_supporting)); a learned mean is written to a twentieth of "
        "its standard error instead. Absent: the values are written as fitted", None)
    columns: dict[str, str] = _field("the data's columns read as variables of other names "
                                     "(column: variable)", default_factory=dict)
    rows_supporting: int | None = _field(
        "the rows behind the learned values: these and those of the earlier fits this one "
        "continued from", None)
    rows_set_aside: int | None = _field(
        "bad rows of the data set aside (learn --on-bad-lines skip or warn): rows of more or "
        "fewer fields than the header, values that cannot be read for their variable; counted "
        "in rows, not in rows_used. Absent: bad rows were refused", None)
    terms: list[str] = _field("the terms learned", default_factory=list)
    statistics: dict[str, dict[str, Any]] = _field("per learned term, its sufficient "
                                                   "statistics", default_factory=dict)
    structure: StructureRecord | None = _field("when the decomposition itself was discovered "
                                               "from the data: how", None)
    ranges: dict[str, dict[str, list[float]]] = _field(
        "per real variable of a learned term, the least and greatest value its rows held: over "
        "every row ('*') and per state of each discrete parent ('M=steel'); what a value far "
        "outside is measured against", default_factory=dict)

    def __post_init__(self) -> None:
        # a statistic the loader read as an array (as it reads tables) is kept as lists, as
        # a fit makes it: records compare and write alike however they were read
        for named in self.statistics.values():
            for name, value in named.items():
                if hasattr(value, "tolist"):
                    named[name] = value.tolist()

    def as_data(self) -> dict[str, Any]:
        """The record as plain data, in the order of its fields (as written into a file; its
        structure's fields that say something); its statistics as they are, not copied (read
        them, do not change them)."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        if not self.ranges:  # a record of before ranges were kept reads as it was written
            del out["ranges"]
        if self.structure is not None:
            out["structure"] = self.structure.as_data()
        return out

    def replace(self, **changes: Any) -> FitRecord:
        """A copy with ``changes``."""
        return dataclasses.replace(self, **changes)
