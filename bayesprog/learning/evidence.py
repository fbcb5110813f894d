"""A program's evidence of a data set (its log marginal likelihood), and programs compared by
it: exact for discrete programs of tables under Dirichlet priors (the BDeu or K2 closed form),
the BIC approximation otherwise."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from bayesprog.errors import BayesprogError
from bayesprog.forms.estimators import TableEstimator
from bayesprog.learning.structure import K2_EXACT, Scores, StructureError


@dataclass
class Evidence:
    """A program's log marginal likelihood of a data set, and how it was computed."""

    log_evidence: float
    method: str
    rows: int


def evidence(program: Any, data: Any, *, score: str = "bdeu",
             equivalent_sample_size: float = 1.0,
             columns: Mapping[str, str] | None = None) -> Evidence:
    """``log P(data | program's structure)``: for a program whose terms are all tables over
    discrete variables, with complete data, the closed form under Dirichlet priors on its
    tables (``"bdeu"`` with ``equivalent_sample_size``, or ``"k2"``, uniform counts of 1);
    otherwise (real variables, other forms, missing values) the BIC approximation, the
    fitted log-likelihood less ``log(rows)/2`` per free parameter, and the method says so."""
    from bayesprog.learning.data import load_data
    from bayesprog.vocabulary.variables import Discrete

    if score not in ("bdeu", "k2"):
        raise StructureError(f"score {score!r}: expected bdeu or k2")
    coded = load_data(data, program.variables, columns)
    discrete = all(isinstance(v, Discrete) and v.kind != "bins"
                   for v in program.variables.values())
    # terms whose parameters are tables of counts (what a Dirichlet prior is conjugate to)
    tables = all(isinstance(t.form.estimator(t.child), TableEstimator) for t in program.terms)
    complete = (set(coded.discrete) == set(program.variables) and
                all((c >= 0).all() for c in coded.discrete.values()))
    if discrete and tables and complete:
        names = list(program.variables)
        codes = np.stack([coded.discrete[n] for n in names], axis=1)
        card = [program.variables[n].card for n in names]
        scores = Scores(codes, card, K2_EXACT if score == "k2" else score,
                        equivalent_sample_size)
        index = {n: i for i, n in enumerate(names)}
        total = 0.0
        for term in program.terms:
            ps = tuple(sorted(index[p.name] for p in term.parents))
            total += scores.local(index[term.child.name], ps)
        what = (f"exact: BDeu closed form (equivalent sample size {equivalent_sample_size:g})"
                if score == "bdeu" else "exact: K2 closed form")
        return Evidence(total, what, coded.rows)
    fit = program.fit(data, columns=columns)
    learned = set(fit.record.terms)
    free = sum(_free_parameters(t) for t in fit.program.terms if t.label in learned)
    rows = fit.record.rows_used
    reasons = ("real variables" if not discrete else "forms other than tables"
               if not tables else "missing values")
    return Evidence(fit.log_likelihood - 0.5 * math.log(max(rows, 1)) * free,
                    f"BIC approximation ({reasons}): fitted log-likelihood less "
                    f"log(rows)/2 x {free} parameters", rows)


def _free_parameters(term: Any) -> int:
    count = 0
    for param in term.form.params:
        value = term.params.get(param.name)
        array = getattr(value, "array", None)
        if array is None:
            continue
        size = int(np.size(array))
        if param.event_ndim and array.ndim:
            size -= size // array.shape[-1]  # a simplex row has one value less than its length
        count += size
    return count


def compare(programs: Sequence[Any], data: Any, *, score: str = "bdeu",
            equivalent_sample_size: float = 1.0,
            names: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Each program's evidence of ``data`` and its Bayes factor against the best (as a natural
    log: 0 for the best, negative for the others), best first; ``names`` label the programs
    (by default their names, or files)."""
    if not programs:
        raise BayesprogError("compare: expected at least one program")
    found = [evidence(p, data, score=score, equivalent_sample_size=equivalent_sample_size)
             for p in programs]
    best = max(e.log_evidence for e in found)
    rows: list[dict[str, Any]] = []
    for i, (program, e) in enumerate(zip(programs, found, strict=True)):
        label = names[i] if names is not None else (program.name or str(program.path))
        rows.append({"program": label, "path": str(program.path),
                     "log_evidence": e.log_evidence, "log_bayes_factor": e.log_evidence - best,
                     "method": e.method, "rows": e.rows})
    return sorted(rows, key=lambda r: -r["log_evidence"])
