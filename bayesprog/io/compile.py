"""Compilation targets besides the engine: pgmpy models for export, drawing and cross-checking.

pgmpy is imported lazily (importing it is slow) and is never on the hot path.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from bayesprog.errors import QuestionError
from bayesprog.forms import InputRef
from bayesprog.inference.binding import Bound, bind
from bayesprog.inference.factors import relevant_terms, slice_factor, term_factor
from bayesprog.program import Program
from bayesprog.vocabulary.expressions import Question
from bayesprog.vocabulary.variables import discrete


def to_bayesian_network(program: Program) -> Any:
    """A pgmpy ``DiscreteBayesianNetwork`` with one ``TabularCPD`` per term.

    Needs a discrete program whose terms have literal parameters (tables, categoricals,
    uniforms); otherwise use :func:`to_factor_graph` with the evidence bound.
    """
    from pgmpy.factors.discrete import TabularCPD
    from pgmpy.models import DiscreteBayesianNetwork

    if not program.is_discrete:
        raise QuestionError(f"{program.name} has continuous variables: a Bayesian network (and so BIF, XMLBIF or "
                            "UAI export) needs a discrete program")
    if program.conditioning:
        raise QuestionError(f"{', '.join(program.conditioning)} has no term in {program.name} "
                            "(the program is conditioned on it): a Bayesian network (and so BIF, "
                            "XMLBIF or UAI export) gives every variable a table")
    model = DiscreteBayesianNetwork()
    model.add_nodes_from(program.variables)
    cpds = []
    bound = Bound(())  # no evidence, no inputs: the literal tables as they are
    for term in program.active_terms:
        if term.soft:
            raise QuestionError("soft evidence has no place in a Bayesian network")
        if any(isinstance(v, InputRef) for v in term.params.values()):
            raise QuestionError(f"term {term.label} takes a runtime input: a Bayesian network (and so "
                                "BIF, XMLBIF or UAI export) needs literal tables")
        factor = term_factor(program, term, bound)
        values = np.exp(factor.log)  # axes: child, parents
        child = discrete(term.child)
        parents = [p.name for p in term.parents]
        cards = [discrete(program.variables[p]).card for p in parents]
        model.add_edges_from((p, child.name) for p in parents)
        cpds.append(TabularCPD(
            child.name, child.card, values.reshape(child.card, -1),
            evidence=parents or None, evidence_card=cards or None,
            state_names={v: list(discrete(program.variables[v]).states)
                         for v in [child.name] + parents},
        ))
    model.add_cpds(*cpds)
    model.check_model()
    return model


def to_factor_graph(
    program: Program,
    question: str | Question,
    evidence: Mapping[str, Any] | None = None,
    inputs: Mapping[str, Any] | None = None,
) -> Any:
    """A pgmpy ``FactorGraph`` of the question's factors with unbatched evidence bound in.

    Observed discrete variables are sliced away, continuous values become likelihood factors,
    so the factor graph's product is proportional to ``P(unobserved, evidence)``.
    """
    from pgmpy.factors.discrete import DiscreteFactor
    from pgmpy.models import FactorGraph

    q = program.question(question)
    bound = bind(program, q, evidence, inputs, None)
    if bound.batch_shape:
        raise QuestionError("to_factor_graph takes one evidence set, not a batch")
    graph = FactorGraph()
    # pgmpy merges equal factors into one node, so factors over the same variables are
    # multiplied together first.
    merged: dict[frozenset[str], Any] = {}
    for term in relevant_terms(program, q.expression.left, [*bound.discrete, *bound.continuous]):
        f = slice_factor(term_factor(program, term, bound), bound)
        if not f.axes:
            continue
        factor = DiscreteFactor(list(f.axes), list(f.log.shape), np.exp(f.log),
                                state_names={a: list(discrete(program.variables[a]).states)
                                             for a in f.axes})
        key = frozenset(f.axes)
        merged[key] = merged[key] * factor if key in merged else factor
    for factor in merged.values():
        graph.add_nodes_from(factor.variables)
        graph.add_factors(factor)
        graph.add_edges_from((a, factor) for a in factor.variables)
    graph.check_model()
    return graph
