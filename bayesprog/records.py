"""The provenance of a fit, as written under ``learned:`` in a fitted file (:class:`FitRecord`),
and of a discovered decomposition (:class:`StructureRecord`): pydantic models, the data types
of the model layer that only a learned program needs (imported with it, so that a program
without a ``learned:`` record never builds their validators).
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field


class StructureRecord(BaseModel):
    """How a program's decomposition was discovered from data (``bayesprog discover``)."""

    model_config = ConfigDict(extra="forbid", strict=False)

    method: str = Field(description="hc (hill climbing) or pc (the stable PC algorithm)")
    score: str | None = Field(None, description="hc: the score climbed (bic, bdeu, k2)")
    score_value: float | None = Field(None, description="hc: the discovered DAG's score")
    equivalent_sample_size: float | None = Field(None, description="bdeu: its prior's weight")
    test: str | None = Field(None, description="pc: the independence test (chi2, g)")
    significance: float | None = Field(None, description="pc: the level below which a test "
                                       "keeps an edge")
    max_conditioning: int | None = Field(None, description="pc: the largest conditioning set")
    tests: int | None = Field(None, description="pc: the independence tests run")
    iterations: int | None = Field(None, description="hc: the operations applied")
    restarts: int | None = Field(None, description="hc: the random restarts")
    seed: int | None = Field(None, description="hc: the seed of the restarts")
    families_scored: int | None = Field(None, description="hc: family scores computed (each "
                                        "once)")
    seconds: float = Field(description="the search's time")
    missing: str = Field(description="how missing values were used")
    constraints: dict[str, Any] = Field(default_factory=dict, description="forbidden and "
                                        "required arcs, tiers, the parents' limit, the start")
    oriented_by_choice: list[str] = Field(default_factory=list, description="pc: arcs whose "
                                          "direction the data left open, chosen without making "
                                          "a v-structure or a cycle")
    discretised: dict[str, list[float]] = Field(default_factory=dict, description="columns "
                                                "binned by --discretise: their bins' edges")
    warnings: list[str] = Field(default_factory=list, description="arcs the data contradict "
                                "in a way the search cannot see: into a variable that is a "
                                "function of its other parents")


class FitRecord(BaseModel):
    """The provenance of one fit, written into the fitted file; its statistics let a later fit
    continue with more data."""

    model_config = ConfigDict(extra="forbid", strict=False)

    data: str = Field(description="the data file's name")
    sha256: str = Field(description="SHA-256 of the data file's bytes")
    rows: int = Field(description="rows in the data file")
    rows_used: int = Field(description="rows with a value for at least one learned term")
    log_likelihood: float = Field(description="log-likelihood of the rows used, fitted program")
    method: str = Field(description="maximum likelihood, or EM when values are missing")
    iterations: int = 1
    digits: int | None = Field(
        None, description="significant digits the learned values are written with, when "
        "rounded (learn --rounded): as many as the rows behind them support (rounding moves a "
        "value by under a twentieth of 1/sqrt(rows_supporting)); a learned mean is written to "
        "a twentieth of its standard error instead. Absent: the values are written as fitted")
    columns: dict[str, str] = Field(
        default_factory=dict, description="the data's columns read as variables of other names "
        "(column: variable)")
    rows_supporting: int | None = Field(
        None, description="the rows behind the learned values: these and those of the earlier "
        "fits this one continued from")
    terms: list[str] = Field(default_factory=list, description="the terms learned")
    statistics: dict[str, dict[str, Any]] = Field(
        default_factory=dict, description="per learned term, its sufficient statistics")
    structure: StructureRecord | None = Field(
        None, description="when the decomposition itself was discovered from the data: how")
