"""The engine against independent references.

* random small discrete programs (hypothesis) against brute-force enumeration of the joint in
  numpy, pgmpy's VariableElimination on ``to_bayesian_network`` and pyAgrum's LazyPropagation
  on a network built here from the same CPTs; MAP against the brute-force argmax;
* batched questions against one call per evidence set, with broadcasting;
* sub-programs (soft evidence from a ``program`` form, a ``program`` term) against joints
  multiplied by hand with numpy/scipy;
* ablation against the same program written with a uniform;
* log-space safety when every likelihood underflows in linear space;
* ``to_factor_graph`` against the posterior.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass
from functools import reduce
from pathlib import Path

import networkx as nx
import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy import stats
from scipy.special import logsumexp, softmax

import bayesprog
from bayesprog.errors import QuestionError, ZeroEvidenceError
from bayesprog.inference.relevance import requisite
from bayesprog.io.compile import to_bayesian_network, to_factor_graph

PROGRAMS = Path(__file__).parent / "programs"

with warnings.catch_warnings():
    # pgmpy warns about its deprecated modules when imported; pyagrum's SWIG module emits
    # DeprecationWarnings while it loads (and crashes when they are turned into errors).
    warnings.simplefilter("ignore")
    import pyagrum as gum
    from pgmpy.inference import BeliefPropagation, VariableElimination

SLOW_OK = [HealthCheck.too_slow, HealthCheck.data_too_large]


def _ask(program, question, evidence=None, **kw):
    """Ask with every warning an error (no RuntimeWarning from overflow, log(0), ...)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return program.ask(question, evidence, **kw)


def _loads(doc_or_text, base_dir=None) -> bayesprog.Program:
    text = doc_or_text if isinstance(doc_or_text, str) else yaml.safe_dump(doc_or_text,
                                                                           sort_keys=False)
    return bayesprog.loads(text, base_dir=base_dir)


# random discrete programs ------------------------------------------------------------------------
NAMES = ("A", "B", "C", "D", "E", "F")


@dataclass
class Net:
    """A random discrete Bayesian network and the YAML program that writes it."""

    order: list[str]  # a topological order
    states: dict[str, list[str]]
    range_low: dict[str, int]  # variables declared as integer ranges: their lowest value
    parents: dict[str, tuple[str, ...]]  # the order of the CPT axes
    cpts: dict[str, np.ndarray]  # axes: parents..., child
    doc: dict

    @property
    def cards(self) -> dict[str, int]:
        return {v: len(s) for v, s in self.states.items()}

    def program(self) -> bayesprog.Program:
        return _loads(self.doc)

    def joint(self) -> np.ndarray:
        """The full joint, axes in ``order``, by one einsum of all CPTs."""
        sym = {v: chr(ord("a") + i) for i, v in enumerate(self.order)}
        subs = ["".join(sym[p] for p in self.parents[v]) + sym[v] for v in self.order]
        eq = ",".join(subs) + "->" + "".join(sym[v] for v in self.order)
        return np.einsum(eq, *(self.cpts[v] for v in self.order))

    def unnormalised(self, searched, known: dict[str, int], soft=None) -> np.ndarray:
        """``P(searched, known)`` by brute-force enumeration, axes in ``searched`` order;
        ``soft`` maps variables to likelihood vectors multiplied into the joint."""
        joint = self.joint()
        for v, lik in (soft or {}).items():
            shape = [1] * len(self.order)
            shape[self.order.index(v)] = len(lik)
            joint = joint * np.reshape(lik, shape)
        sub = joint[tuple(known.get(v, slice(None)) for v in self.order)]
        remaining = [v for v in self.order if v not in known]
        summed = tuple(i for i, v in enumerate(remaining) if v not in searched)
        marg = sub.sum(axis=summed)
        kept = [v for v in remaining if v in searched]
        return np.transpose(marg, [kept.index(v) for v in searched])

    def requisite(self, searched, known, soft=()) -> set[str]:
        """The variables whose CPT ``P(searched | known)`` depends on, by d-separation
        (networkx): X's is requisite when a parameter node added as X's parent is not
        d-separated from the searched variables by the known ones (soft evidence: an observed
        child of its variable)."""
        graph = nx.DiGraph([(p, v) for v in self.order for p in self.parents[v]])
        graph.add_nodes_from(self.order)
        observed = set(known)
        for v in soft:
            graph.add_edge(v, f"soft {v}")
            observed.add(f"soft {v}")
        for v in self.order:
            graph.add_edge(f"theta {v}", v)
        return {v for v in self.order
                if not nx.is_d_separator(graph, {f"theta {v}"}, set(searched), observed)}

    def relevant_only(self, searched, known, soft=()) -> Net:
        """This network with every CPT that the question does not depend on made uniform:
        the same posterior wherever it exists, and one wherever the requisite part's does."""
        keep = self.requisite(searched, known, soft)
        cpts = {v: c if v in keep else np.full(c.shape, 1 / c.shape[-1])
                for v, c in self.cpts.items()}
        return Net(self.order, self.states, self.range_low, self.parents, cpts, self.doc)


@st.composite
def nets(draw, min_vars=2, max_vars=6, zeros=True):
    n = draw(st.integers(min_vars, max_vars))
    order = list(draw(st.permutations(NAMES))[:n])
    cards = {v: draw(st.integers(2, 3)) for v in order}
    ranged = draw(st.sampled_from([None, *order]))
    low = draw(st.sampled_from([-1, 0, 1, 5]))
    states = {v: ([str(low + i) for i in range(cards[v])] if v == ranged
                  else [f"{v.lower()}{i}" for i in range(cards[v])]) for v in order}
    parents = {v: tuple(draw(st.lists(st.sampled_from(order[:i]), unique=True, max_size=3)))
               if i else () for i, v in enumerate(order)}
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    with_zeros = zeros and draw(st.booleans())
    cpts, terms = {}, []
    for v in order:
        shape = tuple(cards[p] for p in parents[v]) + (cards[v],)
        form = draw(st.sampled_from(["table", "table", "categorical", "uniform"]))
        if form == "uniform":
            cpt = np.full(shape, 1.0 / cards[v])
        else:
            cpt = rng.dirichlet(np.ones(cards[v]), size=shape[:-1]).reshape(shape)
            if with_zeros:  # some impossible states, never a row's largest entry
                drop = (rng.random(shape) < 0.25) & (cpt < cpt.max(axis=-1, keepdims=True))
                cpt = np.where(drop, 0.0, cpt)
            cpt = cpt / cpt.sum(axis=-1, keepdims=True)
        cpts[v] = cpt
        written = list(draw(st.permutations(parents[v])))  # parent order in the term text
        term = {"term": f"P({v} | {', '.join(written)})" if written else f"P({v})",
                "form": form}
        if form != "uniform":
            key = "table" if form == "table" else "probabilities"
            if draw(st.booleans()):  # nested lists, in the written parent order
                perm = [parents[v].index(p) for p in written] + [len(written)]
                term[key] = np.transpose(cpt, perm).tolist()
            else:  # nested mappings keyed by state, nesting order of our choosing
                nesting = list(draw(st.permutations(parents[v])))
                child_map = draw(st.booleans())
                term[key] = _nested(cpt, parents[v], nesting, states, v, child_map, {})
        terms.append(term)
    terms = list(draw(st.permutations(terms)))  # the file need not be in topological order
    variables = {}
    for v in draw(st.permutations(order)):
        variables[v] = ({"range": [low, low + cards[v] - 1]} if v == ranged
                        else {"states": states[v]})
    doc = {"bayesprog": 1, "variables": variables, "decomposition": terms}
    return Net(order, states, {ranged: low} if ranged else {}, parents, cpts, doc)


def _nested(cpt, parents, nesting, states, child, child_map, fixed):
    if len(fixed) == len(nesting):
        row = cpt[tuple(fixed[p] for p in parents)].tolist()
        return dict(zip(states[child], row, strict=True)) if child_map else row
    var = nesting[len(fixed)]
    return {s: _nested(cpt, parents, nesting, states, child, child_map, {**fixed, var: i})
            for i, s in enumerate(states[var])}


@dataclass
class Query:
    searched: list[str]
    known: dict[str, int]  # state indices
    style: dict[str, str]  # inline (in the text), name, index (a value for ranges)

    def text(self, net: Net) -> str:
        right = [f"{v}={net.states[v][i]}" if self.style[v] == "inline" else v
                 for v, i in self.known.items()]
        return f"P({' '.join(self.searched)}" + (f" | {', '.join(right)})" if right else ")")

    def evidence(self, net: Net) -> dict:
        out = {}
        for v, i in self.known.items():
            if self.style[v] == "name":
                out[v] = net.states[v][i]
            elif self.style[v] == "index":
                out[v] = net.range_low[v] + i if v in net.range_low else i
        return out


@st.composite
def queries(draw, net: Net, min_known=0, max_searched=3, styles=("inline", "name", "index")):
    names = list(draw(st.permutations(net.order)))
    k = draw(st.integers(1, min(max_searched, len(names) - min_known)))
    searched, rest = names[:k], names[k:]
    known = rest[: draw(st.integers(min_known, len(rest)))]
    return Query(searched,
                 {v: draw(st.integers(0, net.cards[v] - 1)) for v in known},
                 {v: draw(st.sampled_from(styles)) for v in known})


def pgmpy_posterior(program, net: Net, q: Query) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        model = to_bayesian_network(program)
        evidence = {v: net.states[v][i] for v, i in q.known.items()}
        factor = VariableElimination(model).query(list(q.searched), evidence=evidence or None,
                                                  joint=True, show_progress=False)
    values = np.transpose(factor.values, [factor.variables.index(v) for v in q.searched])
    for axis, v in enumerate(q.searched):  # pgmpy's state order, mapped to ours by name
        values = np.take(values, [factor.state_names[v].index(s) for s in net.states[v]], axis)
    return values / values.sum()


def agrum_network(net: Net):
    """A pyAgrum BayesNet built from the CPTs (independently of bayesprog's compilation)."""
    bn = gum.BayesNet("reference")
    for v in net.order:
        bn.add(gum.LabelizedVariable(v, v, net.states[v]))
    for v in net.order:
        for p in net.parents[v]:
            bn.addArc(p, v)
    for v in net.order:
        cpt, parents = net.cpts[v], net.parents[v]
        if not parents:
            bn.cpt(v).fillWith(cpt.tolist())
            continue
        for combo in itertools.product(*(range(net.cards[p]) for p in parents)):
            # assignment by name: no reliance on pyAgrum's internal variable order
            bn.cpt(v)[dict(zip(parents, combo, strict=True))] = cpt[combo].tolist()
    return bn


def agrum_posterior(net: Net, q: Query) -> tuple[np.ndarray, float]:
    ie = gum.LazyPropagation(agrum_network(net))
    if q.known:
        ie.setEvidence(dict(q.known))
    target = set(q.searched)
    if len(target) > 1:
        ie.addJointTarget(target)
    ie.makeInference()
    pot = ie.posterior(q.searched[0]) if len(target) == 1 else ie.jointPosterior(target)
    out = np.empty([net.cards[v] for v in q.searched])
    for combo in np.ndindex(out.shape):
        out[combo] = pot[dict(zip(q.searched, (int(i) for i in combo), strict=True))]
    if not q.known:
        return out, 1.0
    # P(evidence) from an engine without targets: with a joint target declared, pyAgrum's
    # evidenceProbability() may cover only the part of the network around the target
    whole = gum.LazyPropagation(ie.BN())
    whole.setEvidence(dict(q.known))
    whole.makeInference()
    return out, whole.evidenceProbability()


def check_map(program, text, evidence, posterior: np.ndarray, net: Net, searched, seed):
    """MAP: the brute-force argmax (or one of the tied assignments), reproducible by seed."""
    result = _ask(program, text, evidence, kind="map", rng=seed)
    again = _ask(program, text, evidence, kind="map", rng=seed)
    assert isinstance(result, bayesprog.MapResult)
    np.testing.assert_array_equal(result.indices, again.indices)
    flat = posterior.ravel()
    best = flat.max()
    near = set(np.flatnonzero(flat >= best * (1 - 1e-9)).tolist())
    chosen = int(np.ravel_multi_index(tuple(result.indices), posterior.shape))
    if len(near) == 1:
        assert chosen == int(np.argmax(flat))
    else:
        assert chosen in near
    assert abs(float(result.probability) - flat[chosen]) <= 1e-9
    # the assignment in each variable's type: the integer of a range, else the state's name
    assert result.assignment == {
        v: int(net.states[v][int(i)]) if v in net.range_low else net.states[v][int(i)]
        for v, i in zip(searched, result.indices, strict=True)}


@settings(max_examples=70, deadline=None, suppress_health_check=SLOW_OK)
@given(data=st.data())
def test_random_programs_against_enumeration_pgmpy_and_pyagrum(data):
    net = data.draw(nets())
    q = data.draw(queries(net))
    program = net.program()
    text, evidence = q.text(net), q.evidence(net)
    # the engine answers from the terms the answer depends on (relevance reasoning): where
    # the evidence's probability is zero only through other terms, the answer exists
    p_evidence = net.unnormalised(q.searched, q.known).sum()
    marg = net.relevant_only(q.searched, q.known).unnormalised(q.searched, q.known)
    assert (marg.sum() == 0) <= (p_evidence == 0)
    if marg.sum() == 0:
        with pytest.raises(ZeroEvidenceError):
            program.ask(text, evidence)
        result = _ask(program, text, evidence, kind="map")
        assert bool(result.zero_evidence)
        assert int(result.ties) == marg.size  # a uniform choice among every assignment
        assert result.indices.shape == (len(q.searched),)
        assert all(0 <= int(i) < net.cards[v]
                   for v, i in zip(q.searched, result.indices, strict=True))
        return
    posterior = marg / marg.sum()

    result = _ask(program, text, evidence)
    assert result.variables == tuple(q.searched)
    assert result.probabilities.shape == marg.shape
    assert result.batch_shape == ()
    # (a) brute force
    np.testing.assert_allclose(result.probabilities, posterior, rtol=0, atol=1e-9)
    with np.errstate(divide="ignore"):
        np.testing.assert_allclose(result.log_evidence, np.log(p_evidence), rtol=1e-9,
                                   atol=1e-9)
    # the terms the engine planned with are the requisite ones
    planned = requisite(program, q.searched, q.known)
    assert planned == net.requisite(q.searched, q.known)
    if p_evidence > 0:
        # (b) pgmpy on the compiled network
        np.testing.assert_allclose(result.probabilities, pgmpy_posterior(program, net, q),
                                   rtol=0, atol=1e-9)
        # (c) pyAgrum on a network built independently from the same CPTs
        ref, ref_pe = agrum_posterior(net, q)
        np.testing.assert_allclose(result.probabilities, ref, rtol=0, atol=1e-9)
        np.testing.assert_allclose(np.exp(result.log_evidence), ref_pe, rtol=1e-9, atol=1e-12)
    # MAP
    check_map(program, text, evidence, posterior, net, q.searched, data.draw(st.integers(0, 99)))
    # with soft evidence (virtual evidence) on a random variable: brute force again
    soft_var = data.draw(st.sampled_from(net.order))
    lik = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1))).uniform(
        0.05, 1.0, size=net.cards[soft_var])
    assert requisite(program, q.searched, q.known, [soft_var]) == net.requisite(
        q.searched, q.known, [soft_var])
    whole = net.unnormalised(q.searched, q.known, {soft_var: lik})
    marg = net.relevant_only(q.searched, q.known, [soft_var]).unnormalised(
        q.searched, q.known, {soft_var: lik})
    assume(marg.sum() > 0)
    result = _ask(program, text, evidence, soft={soft_var: lik})
    np.testing.assert_allclose(result.probabilities, marg / marg.sum(), rtol=0, atol=1e-9)
    with np.errstate(divide="ignore"):
        np.testing.assert_allclose(result.log_evidence, np.log(whole.sum()), rtol=1e-9,
                                   atol=1e-9)


@settings(max_examples=30, deadline=None, suppress_health_check=SLOW_OK)
@given(data=st.data())
def test_factor_graph_product_is_the_posterior(data):
    net = data.draw(nets())
    q = data.draw(queries(net))
    marg = net.unnormalised(q.searched, q.known)
    assume(marg.sum() > 0)
    program = net.program()
    text, evidence = q.text(net), q.evidence(net)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        graph = to_factor_graph(program, text, evidence)
    factors = graph.get_factors()
    scope = set().union(*(f.variables for f in factors))
    assert scope.isdisjoint(q.known)  # observed variables are sliced away
    product = reduce(lambda a, b: a.product(b, inplace=False), factors)
    others = [v for v in product.variables if v not in q.searched]
    if others:
        product = product.marginalize(others, inplace=False)
    values = np.transpose(product.values, [product.variables.index(v) for v in q.searched])
    np.testing.assert_allclose(values / values.sum(), marg / marg.sum(), rtol=0, atol=1e-9)
    result = _ask(program, text, evidence)
    np.testing.assert_allclose(result.probabilities, values / values.sum(), rtol=0, atol=1e-9)
    # pgmpy's (exact, junction tree) belief propagation; it cannot take a graph made of
    # several components, and its messages are divided by each other (0 / 0 where a factor
    # holds zeros)
    if len(q.searched) == 1 and nx.is_connected(graph) and all(
            np.all(f.values > 0) for f in factors):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            bp = BeliefPropagation(graph).query(q.searched, show_progress=False)
        np.testing.assert_allclose(result.probabilities, bp.values, rtol=0, atol=1e-9)


def test_factor_graph_of_a_continuous_program():
    means_e, means_c, sigma = [0.1, 0.5, 0.9], [0.8, 0.2, 0.4], 0.15
    program = _loads({
        "bayesprog": 1,
        "variables": {"M": {"states": ["m0", "m1", "m2"]},
                      "E": {"continuous": [-np.inf, np.inf]},
                      "C": {"continuous": [-np.inf, np.inf]}},
        "decomposition": [
            {"term": "P(M)", "form": "table", "table": [0.2, 0.5, 0.3]},
            {"term": "P(E | M)", "form": "normal",
             "mean": dict(zip(["m0", "m1", "m2"], means_e, strict=True)), "sigma": sigma},
            {"term": "P(C | M)", "form": "normal",
             "mean": dict(zip(["m0", "m1", "m2"], means_c, strict=True)), "sigma": sigma},
        ],
    })
    evidence = {"E": 0.42, "C": 0.31}
    graph = to_factor_graph(program, "P(M | E, C)", evidence)
    product = reduce(lambda a, b: a.product(b, inplace=False), graph.get_factors())
    assert product.variables == ["M"]
    log_ref = (np.log([0.2, 0.5, 0.3]) + stats.norm.logpdf(0.42, means_e, sigma)
               + stats.norm.logpdf(0.31, means_c, sigma))
    np.testing.assert_allclose(product.values / product.values.sum(), softmax(log_ref),
                               rtol=1e-9)
    np.testing.assert_allclose(_ask(program, "P(M | E, C)", evidence).probabilities,
                               softmax(log_ref), rtol=1e-9)
    with pytest.raises(QuestionError):
        to_factor_graph(program, "P(M | E, C)", {"E": [0.1, 0.2], "C": 0.3})


# MAP ties --------------------------------------------------------------------------------------
TIES = {
    "bayesprog": 1,
    "variables": {"A": {"states": ["a0", "a1", "a2", "a3"]}, "B": {"states": ["b0", "b1"]}},
    "decomposition": [
        {"term": "P(A)", "form": "uniform"},
        {"term": "P(B | A)", "form": "table",
         "table": [[0.5, 0.5], [0.5, 0.5], [0.5, 0.5], [0.25, 0.75]]},
    ],
}


def test_map_ties_are_broken_among_the_tied_and_reproducibly():
    program = _loads(TIES)
    tied = {0, 1, 2}  # P(A | B=b0) is proportional to [.5, .5, .5, .25]
    choices = set()
    for seed in range(40):
        result = _ask(program, "P(A | B=b0)", kind="map", rng=seed)
        index = int(result.indices[0])
        assert index in tied
        assert int(result.ties) == 3
        np.testing.assert_allclose(result.probability, 0.5 / 1.75, rtol=1e-12)
        assert int(_ask(program, "P(A | B=b0)", kind="map", rng=seed).indices[0]) == index
        gen_a, gen_b = np.random.default_rng(seed), np.random.default_rng(seed)
        assert (int(_ask(program, "P(A | B=b0)", kind="map", rng=gen_a).indices[0])
                == int(_ask(program, "P(A | B=b0)", kind="map", rng=gen_b).indices[0]))
        choices.add(index)
    assert len(choices) > 1  # the tie is broken at random, not always the first
    default = _ask(program, "P(A | B=b0)", kind="map")
    assert int(default.indices[0]) == int(_ask(program, "P(A | B=b0)", kind="map",
                                               rng=0).indices[0])
    # no tie: the unique maximum, whatever the seed
    for seed in range(5):
        result = _ask(program, "P(A | B=b1)", kind="map", rng=seed)
        assert result.assignment == {"A": "a3"} and int(result.ties) == 1


def test_batched_map_with_one_generator_per_row_equals_single_calls():
    program = _loads(TIES)
    b = np.array(["b0", "b0", "b1", "b0", "b0", "b1"]).reshape(2, 3)
    seeds = [11, 12, 13, 14, 15, 16]
    batched = _ask(program, "P(A | B)", {"B": b}, kind="map",
                   rng=[np.random.default_rng(s) for s in seeds])
    assert batched.indices.shape == (2, 3, 1)
    for k, pos in enumerate(np.ndindex(2, 3)):
        single = _ask(program, "P(A | B)", {"B": b[pos]}, kind="map",
                      rng=np.random.default_rng(seeds[k]))
        np.testing.assert_array_equal(batched.indices[pos], single.indices)
        assert batched.ties[pos] == single.ties
    assert batched.assignment["A"].shape == (2, 3)
    with pytest.raises(QuestionError):
        program.ask("P(A | B)", {"B": b}, kind="map", rng=[1, 2])


def test_zero_evidence_in_a_sliced_factor_that_does_not_bear_on_the_answer():
    # A is independent of B: P(B | A=a0) is P(B), as relevance reasoning answers, while the
    # evidence's probability (a factor sliced down to the number 0) is exactly zero
    program = _loads({
        "bayesprog": 1,
        "variables": {"A": {"states": ["a0", "a1"]}, "B": {"states": ["b0", "b1"]}},
        "decomposition": [{"term": "P(A)", "form": "table", "table": [0.0, 1.0]},
                          {"term": "P(B)", "form": "table", "table": [0.3, 0.7]}],
    })
    answer = program.ask("P(B | A=a0)")
    np.testing.assert_allclose(answer.probabilities, [0.3, 0.7], atol=1e-15)
    assert answer.log_evidence == -np.inf
    assert program.ask("P(B | A)", {"A": ["a0", "a1"]}).log_evidence.tolist() == [
        -np.inf, 0.0]
    result = _ask(program, "P(B | A=a0)", kind="map")
    assert not bool(result.zero_evidence) and int(result.ties) == 1
    assert result.assignment["B"] == "b1"


def test_map_with_zero_evidence_from_a_child_is_a_uniform_choice():
    # the same situation when the zero sits in a factor that keeps an axis: uniform choice
    program = _loads({
        "bayesprog": 1,
        "variables": {"A": {"states": ["a0", "a1"]}, "B": {"states": ["b0", "b1"]}},
        "decomposition": [{"term": "P(A)", "form": "table", "table": [0.4, 0.6]},
                          {"term": "P(B | A)", "form": "table", "table": [[1, 0], [1, 0]]}],
    })
    with pytest.raises(ZeroEvidenceError):
        program.ask("P(A | B=b1)")
    result = _ask(program, "P(A | B=b1)", kind="map")
    assert bool(result.zero_evidence) and int(result.ties) == 2
    choices = {int(_ask(program, "P(A | B=b1)", kind="map", rng=s).indices[0])
               for s in range(20)}
    assert choices == {0, 1}


# batching --------------------------------------------------------------------------------------
def _batched_values(net: Net, v: str, idx: np.ndarray, style: str) -> np.ndarray:
    if style == "name":
        return np.asarray(net.states[v])[idx]
    return idx + net.range_low[v] if v in net.range_low else idx


@settings(max_examples=30, deadline=None, suppress_health_check=SLOW_OK)
@given(data=st.data())
def test_batched_equals_single_calls(data):
    net = data.draw(nets(zeros=False))
    q = data.draw(queries(net, min_known=1))
    shape = data.draw(st.sampled_from([(1,), (5,), (2, 3), (2, 1, 2)]))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    program = net.program()
    batched_vars = [v for v in q.known if q.style[v] != "inline"]
    assume(batched_vars)
    idx = {v: rng.integers(0, net.cards[v], size=shape) for v in batched_vars}
    evidence = {v: _batched_values(net, v, idx[v], q.style[v]) for v in batched_vars}
    text = q.text(net)
    result = _ask(program, text, evidence)
    cards = tuple(net.cards[v] for v in q.searched)
    assert result.probabilities.shape == shape + cards
    assert result.log_evidence.shape == shape
    assert result.batch_shape == shape
    seeds = rng.integers(0, 1000, size=int(np.prod(shape)))
    maps = _ask(program, text, evidence, kind="map", rng=[int(s) for s in seeds])
    for k, pos in enumerate(np.ndindex(shape)):
        single_ev = {v: evidence[v][pos] for v in batched_vars}
        single = _ask(program, text, single_ev)
        np.testing.assert_allclose(result.probabilities[pos], single.probabilities,
                                   rtol=0, atol=1e-12)
        np.testing.assert_allclose(result.log_evidence[pos], single.log_evidence,
                                   rtol=1e-12, atol=1e-12)
        known = {**q.known, **{v: int(idx[v][pos]) for v in batched_vars}}
        marg = net.unnormalised(q.searched, known)
        np.testing.assert_allclose(result.probabilities[pos], marg / marg.sum(), atol=1e-9)
        single_map = _ask(program, text, single_ev, kind="map", rng=int(seeds[k]))
        np.testing.assert_array_equal(maps.indices[pos], single_map.indices)


@settings(max_examples=25, deadline=None, suppress_health_check=SLOW_OK)
@given(data=st.data())
def test_broadcasting_batched_with_unbatched_evidence(data):
    net = data.draw(nets(min_vars=3, zeros=False))
    q = data.draw(queries(net, min_known=2, max_searched=2, styles=("name", "index")))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    program = net.program()
    text = q.text(net)
    first, second, *rest = list(q.known)
    fixed = {v: _batched_values(net, v, np.asarray(q.known[v]), q.style[v]) for v in rest}
    cases = [((2, 1), (3,), (2, 3)), ((), (4,), (4,)), ((3, 1), (1, 2), (3, 2))]
    for shape1, shape2, batch in cases:
        i1 = rng.integers(0, net.cards[first], size=shape1)
        i2 = rng.integers(0, net.cards[second], size=shape2)
        evidence = {first: _batched_values(net, first, i1, q.style[first]),
                    second: _batched_values(net, second, i2, q.style[second]), **fixed}
        result = _ask(program, text, evidence)
        assert result.batch_shape == batch
        b1, b2 = np.broadcast_arrays(evidence[first], evidence[second])
        b1 = np.broadcast_to(b1, batch)
        b2 = np.broadcast_to(b2, batch)
        for pos in np.ndindex(batch):
            single = _ask(program, text, {first: b1[pos], second: b2[pos], **fixed})
            np.testing.assert_allclose(result.probabilities[pos], single.probabilities,
                                       rtol=0, atol=1e-12)
            np.testing.assert_allclose(result.log_evidence[pos], single.log_evidence,
                                       rtol=1e-12, atol=1e-12)


def test_batched_continuous_evidence_and_soft_evidence():
    mean = [0.1, 0.5, 0.9]
    program = _loads({
        "bayesprog": 1,
        "variables": {"M": {"states": ["m0", "m1", "m2"]},
                      "E": {"continuous": [-np.inf, np.inf]},
                      "C": {"continuous": [0, 1]}},
        "decomposition": [
            {"term": "P(M)", "form": "uniform"},
            {"term": "P(E | M)", "form": "normal",
             "mean": dict(zip(["m0", "m1", "m2"], mean, strict=True)), "sigma": 0.2},
            {"term": "P(C | M)", "form": "beta", "a": {"m0": 2, "m1": 1, "m2": 0.5},
             "b": 1.5},
        ],
    })
    e = np.linspace(-0.2, 1.2, 6).reshape(2, 3)
    c = 0.35
    soft = np.array([[1.0, 0.5, 0.25], [0.2, 0.2, 1.0]])[:, None, :]  # batch (2, 1)
    result = _ask(program, "P(M | E, C)", {"E": e, "C": c}, soft={"M": soft})
    assert result.probabilities.shape == (2, 3, 3)
    for pos in np.ndindex(2, 3):
        single = _ask(program, "P(M | E, C)", {"E": e[pos], "C": c},
                      soft={"M": soft[pos[0], 0]})
        np.testing.assert_allclose(result.probabilities[pos], single.probabilities, atol=1e-12)
        log_ref = (np.log(soft[pos[0], 0]) + stats.norm.logpdf(e[pos], mean, 0.2)
                   + stats.beta.logpdf(c, [2, 1, 0.5], 1.5) - np.log(3))
        np.testing.assert_allclose(result.probabilities[pos], softmax(log_ref), rtol=1e-9)
        np.testing.assert_allclose(result.log_evidence[pos], logsumexp(log_ref), rtol=1e-9)



def test_batched_continuous_evidence_with_batched_discrete_parents():
    # P(E | M, K) is batched through E and sliced by a batched K: both batch paths at once
    mean = np.array([[-1.0, 0.5], [0.0, 2.0], [1.0, -0.5]])  # [M, K]
    sigma = np.array([0.3, 0.9])  # [K]
    pk_m = np.array([[0.2, 0.8], [0.5, 0.5], [0.9, 0.1]])  # [M, K]
    program = _loads({
        "bayesprog": 1,
        "variables": {"M": {"states": ["m0", "m1", "m2"]}, "K": {"states": ["k0", "k1"]},
                      "E": {"continuous": [-np.inf, np.inf]}},
        "decomposition": [
            {"term": "P(M)", "form": "uniform"},
            {"term": "P(K | M)", "form": "table", "table": pk_m.tolist()},
            {"term": "P(E | M, K)", "form": "normal",
             "mean": {m: dict(zip(["k0", "k1"], row, strict=True))
                      for m, row in zip(["m0", "m1", "m2"], mean.tolist(), strict=True)},
             "sigma": {"k0": 0.3, "k1": 0.9}},
        ],
    })
    e = np.array([-1.1, 0.4, 2.2, 0.0, 1.3])
    k = np.array([0, 1, 1, 0, 1])
    result = _ask(program, "P(M | E, K)", {"E": e, "K": k})
    for row in range(5):
        log_ref = (np.log(pk_m[:, k[row]]) - np.log(3)
                   + stats.norm.logpdf(e[row], mean[:, k[row]], sigma[k[row]]))
        np.testing.assert_allclose(result.probabilities[row], softmax(log_ref), rtol=1e-9)
        np.testing.assert_allclose(result.log_evidence[row], logsumexp(log_ref), rtol=1e-9)
        single = _ask(program, "P(M | E, K)", {"E": e[row], "K": int(k[row])})
        np.testing.assert_allclose(result.probabilities[row], single.probabilities,
                                   rtol=0, atol=1e-12)
    # E batched (2, 1) against K batched (5,): a (2, 5) batch
    result = _ask(program, "P(M | E, K)", {"E": e[:2, None], "K": k})
    assert result.batch_shape == (2, 5)
    for i, j in np.ndindex(2, 5):
        log_ref = (np.log(pk_m[:, k[j]]) - np.log(3)
                   + stats.norm.logpdf(e[i], mean[:, k[j]], sigma[k[j]]))
        np.testing.assert_allclose(result.probabilities[i, j], softmax(log_ref), rtol=1e-9)


# sub-programs ----------------------------------------------------------------------------------
TAR_YAML = (PROGRAMS / "tar.yaml").read_text(encoding="utf-8")

OBJ_YAML = (PROGRAMS / "obj.yaml").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def tar_program(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tar")
    (folder / "tar.yaml").write_text(TAR_YAML)
    (folder / "obj.yaml").write_text(OBJ_YAML)
    return bayesprog.load(folder / "tar.yaml")


def tar_reference(t: int, i_field, s_field, templates, l1, l2) -> np.ndarray:
    """log P(O=o, T=t, I, S | soft evidence on R) for every cell o, multiplied by hand."""
    # the sub-program: P(R | L1, L2) with a uniform P(R)
    log_r = (stats.beta.logpdf(l1, [1, 1], [4.5, 1]) + stats.beta.logpdf(l2, 1, [1, 4.5])
             + np.log(0.5))
    soft = softmax(log_r)
    # the grid: 4 x 5 cells of side 0.01, row-major, centres at (i + .5, j + .5) * cell
    cell, floor = 0.01, 0.1
    centres = np.array([((i + 0.5) * cell, (j + 0.5) * cell)
                        for i in range(4) for j in range(5)])
    area = 20 * cell**2
    gmm = np.zeros((2, 20))
    k = templates.shape[1]
    for r in range(2):
        for j in range(k):
            gmm[r] += stats.multivariate_normal(templates[r, j], 0.015**2 * np.eye(2)).pdf(
                centres) / k
    gmm = (1 - floor) * gmm + floor / area
    likelihood_o = soft @ gmm  # sum_r P_gmm(r | o) soft(r)
    a_s = [3.0, 2.0][t]
    return (np.log(1 / 20) + np.log(1 / 2) + stats.beta.logpdf(i_field, 1, 2.5)
            + stats.beta.logpdf(s_field, a_s, 1) + np.log(likelihood_o))


@settings(max_examples=15, deadline=None, suppress_health_check=SLOW_OK)
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(1, 3), t=st.integers(0, 1))
def test_soft_evidence_from_a_sub_program_equals_the_hand_joint(tar_program, seed, k, t):
    rng = np.random.default_rng(seed)
    templates = rng.uniform(0, 0.05, size=(2, k, 2))
    i_field, s_field = rng.uniform(0.01, 0.99, size=(2, 20))
    l1, l2 = rng.uniform(0.01, 0.99, size=2)
    log_ref = tar_reference(t, i_field, s_field, templates, l1, l2)
    evidence = {"T": ["T1", "T2"][t], "I": i_field, "S": s_field}
    inputs = {"templates": templates, "l1": l1, "l2": l2}
    result = _ask(tar_program, "P(O | T, I, S)", evidence, inputs=inputs)
    np.testing.assert_allclose(result.probabilities, softmax(log_ref), rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(result.log_evidence, logsumexp(log_ref), rtol=1e-9)
    best = _ask(tar_program, "next", evidence, inputs=inputs)
    assert isinstance(best, bayesprog.MapResult)
    assert int(best.indices[0]) == int(np.argmax(log_ref))
    # a grid's MAP is its cell's indices
    assert best.assignment["O"] == (int(np.argmax(log_ref) // 5), int(np.argmax(log_ref) % 5))


def test_soft_evidence_sub_program_batched(tar_program):
    rng = np.random.default_rng(7)
    templates = rng.uniform(0, 0.05, size=(2, 2, 2))
    i_field = rng.uniform(0.01, 0.99, size=(3, 20))
    s_field = rng.uniform(0.01, 0.99, size=20)
    t = np.array(["T1", "T2", "T1"])
    l1 = np.array([0.1, 0.5, 0.9])
    result = _ask(tar_program, "P(O | T, I, S)", {"T": t, "I": i_field, "S": s_field},
                  inputs={"templates": templates, "l1": l1, "l2": 0.3})
    assert result.probabilities.shape == (3, 20)
    for row in range(3):
        log_ref = tar_reference([0, 1, 0][row], i_field[row], s_field, templates, l1[row], 0.3)
        np.testing.assert_allclose(result.probabilities[row], softmax(log_ref), rtol=1e-9,
                                   atol=1e-15)
        np.testing.assert_allclose(result.log_evidence[row], logsumexp(log_ref), rtol=1e-9)


SUB_YAML = """\
bayesprog: 1
variables:
  X: {states: [x0, x1, x2]}
  K: {states: [k0, k1]}
  Z: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(K), form: table, table: [0.6, 0.4]}
  - {term: P(X | K), form: table, table: {k0: [0.7, 0.2, 0.1], k1: [0.1, 0.3, 0.6]}}
  - {term: P(Z | X), form: normal, mean: {x0: -1.0, x1: 0.0, x2: 1.5}, sigma: 0.8}
questions:
  given_z: P(X | K, Z)
"""

OUTER_YAML = """\
bayesprog: 1
variables:
  X: {states: [x0, x1, x2]}
  K: {states: [k0, k1]}
  W: {states: [w0, w1]}
inputs:
  z: {}
decomposition:
  - {term: P(K), form: table, table: [0.25, 0.75]}
  - {term: P(X | K), form: program, program: sub.yaml, question: given_z, bind: {Z: {input: z}}}
  - {term: P(W | X), form: table, table: {x0: [0.9, 0.1], x1: [0.5, 0.5], x2: [0.2, 0.8]}}
"""

SUB_PX_K = np.array([[0.7, 0.2, 0.1], [0.1, 0.3, 0.6]])  # [K, X]
SUB_MEAN, SUB_SIGMA = np.array([-1.0, 0.0, 1.5]), 0.8
OUTER_PK = np.array([0.25, 0.75])
OUTER_PW_X = np.array([[0.9, 0.1], [0.5, 0.5], [0.2, 0.8]])  # [X, W]


def outer_joint(z: float) -> np.ndarray:
    """P(K, X, W) with P(X | K) = P_sub(X | K, Z=z), by hand; axes K, X, W."""
    sub = SUB_PX_K * stats.norm.pdf(z, SUB_MEAN, SUB_SIGMA)
    sub = sub / sub.sum(axis=1, keepdims=True)
    return OUTER_PK[:, None, None] * sub[:, :, None] * OUTER_PW_X[None, :, :]


@pytest.fixture(scope="module")
def sub_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sub")
    (folder / "sub.yaml").write_text(SUB_YAML)
    (folder / "outer.yaml").write_text(OUTER_YAML)
    (folder / "outer_literal.yaml").write_text(
        OUTER_YAML.replace("bind: {Z: {input: z}}", "bind: {Z: 0.3}").replace(
            "inputs:\n  z: {}\n", ""))
    return folder


def test_program_term_equals_the_hand_joint(sub_dir):
    program = bayesprog.load(sub_dir / "outer.yaml")
    for z in (-1.2, 0.3, 2.0):
        joint = outer_joint(z)
        inputs = {"z": z}
        result = _ask(program, "P(K | W=w1)", inputs=inputs)
        ref = joint[:, :, 1].sum(axis=1)
        np.testing.assert_allclose(result.probabilities, ref / ref.sum(), rtol=1e-9)
        np.testing.assert_allclose(result.log_evidence, np.log(ref.sum()), rtol=1e-9)
        result = _ask(program, "P(X | W)", {"W": "w0"}, inputs=inputs)
        ref = joint[:, :, 0].sum(axis=0)
        np.testing.assert_allclose(result.probabilities, ref / ref.sum(), rtol=1e-9)
        result = _ask(program, "P(X K)", inputs=inputs)
        np.testing.assert_allclose(result.probabilities, joint.sum(axis=2).T, rtol=1e-9)
        result = _ask(program, "P(K | X=x2)", inputs=inputs)
        ref = joint[:, 2, :].sum(axis=1)
        np.testing.assert_allclose(result.probabilities, ref / ref.sum(), rtol=1e-9)
        best = _ask(program, "P(X K | W=w1)", inputs=inputs, kind="map")
        ref = joint[:, :, 1].T
        assert tuple(best.indices) == np.unravel_index(np.argmax(ref), ref.shape)
    # the runtime input batched: one row per value of z
    zs = np.array([-1.2, 0.3, 2.0, 0.0])
    result = _ask(program, "P(K | W=w1)", inputs={"z": zs})
    assert result.probabilities.shape == (4, 2)
    for row, z in enumerate(zs):
        ref = outer_joint(z)[:, :, 1].sum(axis=1)
        np.testing.assert_allclose(result.probabilities[row], ref / ref.sum(), rtol=1e-9)
        np.testing.assert_allclose(result.log_evidence[row], np.log(ref.sum()), rtol=1e-9)
    # a literal bind
    literal = bayesprog.load(sub_dir / "outer_literal.yaml")
    joint = outer_joint(0.3)
    result = _ask(literal, "P(K | W=w0)")
    ref = joint[:, :, 0].sum(axis=1)
    np.testing.assert_allclose(result.probabilities, ref / ref.sum(), rtol=1e-9)



def test_program_term_with_two_parents_in_another_order(tmp_path):
    rng = np.random.default_rng(5)
    table = rng.dirichlet(np.ones(2), size=(2, 3))  # P_sub(X | K, J): [K, J, X]
    (tmp_path / "sub.yaml").write_text(yaml.safe_dump({
        "bayesprog": 1,
        "variables": {"X": {"states": ["x0", "x1"]}, "K": {"states": ["k0", "k1"]},
                      "J": {"states": ["j0", "j1", "j2"]}},
        "decomposition": [
            {"term": "P(K)", "form": "uniform"},
            {"term": "P(J)", "form": "table", "table": [0.1, 0.3, 0.6]},
            {"term": "P(X | K, J)", "form": "table", "table": table.tolist()},
        ],
    }, sort_keys=False))
    pk, pj = np.array([0.35, 0.65]), np.array([0.5, 0.2, 0.3])
    (tmp_path / "outer.yaml").write_text(yaml.safe_dump({
        "bayesprog": 1,
        "variables": {"X": {"states": ["x0", "x1"]}, "K": {"states": ["k0", "k1"]},
                      "J": {"states": ["j0", "j1", "j2"]}},
        "decomposition": [
            {"term": "P(K)", "form": "table", "table": pk.tolist()},
            {"term": "P(J)", "form": "table", "table": pj.tolist()},
            {"term": "P(X | J, K)", "form": "program", "program": "sub.yaml",
             "question": "P(X | K, J)"},
        ],
    }, sort_keys=False))
    program = bayesprog.load(tmp_path / "outer.yaml")
    joint = pk[:, None, None] * pj[None, :, None] * table  # [K, J, X]
    for x in range(2):
        result = _ask(program, "P(K J | X)", {"X": x})
        ref = joint[:, :, x]
        np.testing.assert_allclose(result.probabilities, ref / ref.sum(), rtol=1e-12)
        np.testing.assert_allclose(result.log_evidence, np.log(ref.sum()), rtol=1e-12)
    result = _ask(program, "P(X | J=j2, K=k0)")
    np.testing.assert_allclose(result.probabilities, table[0, 2], rtol=1e-12)
    # batched evidence on the term's parents
    k, j = np.array(["k0", "k1", "k1", "k0"]), np.array([2, 0, 1, 1])
    result = _ask(program, "P(X | K, J)", {"K": k, "J": j})
    for row in range(4):
        np.testing.assert_allclose(result.probabilities[row],
                                   table[int(k[row][1]), j[row]], rtol=1e-12)

def test_program_term_with_a_range_parent(tmp_path):
    (tmp_path / "sub.yaml").write_text(
        "bayesprog: 1\n"
        "variables:\n  X: {states: [x0, x1]}\n  K: {range: [1, 3]}\n"
        "decomposition:\n"
        "  - {term: P(K), form: uniform}\n"
        "  - {term: P(X | K), form: table, table: [[0.9, 0.1], [0.5, 0.5], [0.2, 0.8]]}\n")
    (tmp_path / "outer.yaml").write_text(
        "bayesprog: 1\n"
        "variables:\n  X: {states: [x0, x1]}\n  K: {range: [1, 3]}\n"
        "decomposition:\n"
        "  - {term: P(K), form: table, table: [0.2, 0.3, 0.5]}\n"
        "  - {term: P(X | K), form: program, program: sub.yaml, question: 'P(X | K)'}\n")
    program = bayesprog.load(tmp_path / "outer.yaml")
    ref = np.array([0.2, 0.3, 0.5]) * np.array([0.1, 0.5, 0.8])
    result = _ask(program, "P(K | X=x1)")
    np.testing.assert_allclose(result.probabilities, ref / ref.sum(), rtol=1e-12)


def test_soft_evidence_categorical_input_and_keyword():
    pa = np.array([0.2, 0.5, 0.3])
    pb = np.array([[0.9, 0.1], [0.4, 0.6], [0.3, 0.7]])
    doc = {
        "bayesprog": 1,
        "variables": {"A": {"states": ["a0", "a1", "a2"]}, "B": {"states": ["b0", "b1"]}},
        "inputs": {"lik": {"shape": [3]}},
        "decomposition": [
            {"term": "P(A)", "form": "table", "table": pa.tolist()},
            {"term": "P(B | A)", "form": "table", "table": pb.tolist()},
        ],
        "soft_evidence": [{"variable": "A", "form": "categorical",
                           "probabilities": {"input": "lik"}}],
    }
    program = _loads(doc)
    lik = np.array([[0.1, 0.3, 0.6], [0.6, 0.3, 0.1]])
    result = _ask(program, "P(A | B=b1)", inputs={"lik": lik})
    ref = pa * pb[:, 1] * lik
    np.testing.assert_allclose(result.probabilities, ref / ref.sum(-1, keepdims=True),
                               rtol=1e-12)
    np.testing.assert_allclose(result.log_evidence, np.log(ref.sum(-1)), rtol=1e-12)
    # the same likelihoods given at question time instead
    plain = _loads({k: v for k, v in doc.items() if k not in ("inputs", "soft_evidence")})
    result = _ask(plain, "P(A | B=b1)", soft={"A": lik})
    np.testing.assert_allclose(result.probabilities, ref / ref.sum(-1, keepdims=True),
                               rtol=1e-12)
    # soft evidence on a descendant that is not asked about still counts
    result = _ask(plain, "P(A)", soft={"B": [0.0, 1.0]})
    ref = pa * pb[:, 1]
    np.testing.assert_allclose(result.probabilities, ref / ref.sum(), rtol=1e-12)


# ablation --------------------------------------------------------------------------------------
PA = [0.3, 0.7]
PB_A = [[0.7, 0.2, 0.1], [0.1, 0.3, 0.6]]
PC_B = [[0.9, 0.1], [0.4, 0.6], [0.2, 0.8]]
PD_AB = [[[0.5, 0.5], [0.9, 0.1], [0.2, 0.8]], [[0.3, 0.7], [0.6, 0.4], [0.99, 0.01]]]
E_MEAN = [-1.0, 0.0, 2.0]


def _ablation_doc(b_uniform=False, e_uniform=False, ablate=None):
    b_term = ({"term": "P(B | A)", "form": "uniform"} if b_uniform
              else {"term": "P(B | A)", "form": "table", "table": PB_A})
    e_term = ({"term": "P(E | B)", "form": "uniform"} if e_uniform
              else {"term": "P(E | B)", "form": "normal",
                    "mean": dict(zip(["b0", "b1", "b2"], E_MEAN, strict=True)), "sigma": 0.7})
    doc = {
        "bayesprog": 1,
        "variables": {"A": {"states": ["a0", "a1"]}, "B": {"states": ["b0", "b1", "b2"]},
                      "C": {"states": ["c0", "c1"]}, "D": {"states": ["d0", "d1"]},
                      "E": {"continuous": [-np.inf, np.inf]}},
        "decomposition": [
            {"term": "P(A)", "form": "table", "table": PA},
            b_term,
            {"term": "P(C | B)", "form": "table", "table": PC_B},
            {"term": "P(D | A, B)", "form": "table", "table": PD_AB},
            e_term,
        ],
    }
    if ablate:
        doc["ablate"] = ablate
    return doc


ABLATION_QUESTIONS = [
    ("P(A | B=b1)", {}),
    ("P(B | A=a0)", {}),
    ("P(A | C=c0)", {}),
    ("P(B C | D=d1)", {}),
    ("P(A | D, C)", {"D": "d0", "C": "c1"}),
    ("P(A B | E)", {"E": 0.4}),
    ("P(D)", {}),
]


def _ablation_joint(b_uniform):
    """P(A, B, C, D) by hand, axes A, B, C, D."""
    pb = np.full((2, 3), 1 / 3) if b_uniform else np.array(PB_A)
    return (np.array(PA)[:, None, None, None] * pb[:, :, None, None]
            * np.array(PC_B)[None, :, :, None] * np.array(PD_AB)[:, :, None, :])


def test_ablate_equals_the_program_written_with_a_uniform():
    program = _loads(_ablation_doc())
    for question, evidence in ABLATION_QUESTIONS:  # fill the original's caches first
        _ask(program, question, evidence)
    ablated = program.ablate("P(B|A)")
    written = _loads(_ablation_doc(b_uniform=True))
    assert ablated.ablated == ("P(B | A)",)
    assert program.ablated == ()
    for question, evidence in ABLATION_QUESTIONS:
        got = _ask(ablated, question, evidence)
        want = _ask(written, question, evidence)
        np.testing.assert_allclose(got.probabilities, want.probabilities, rtol=1e-12,
                                   atol=1e-15)
        np.testing.assert_allclose(got.log_evidence, want.log_evidence, rtol=1e-12)
        assert got.ablated == ("P(B | A)",)
    # against the hand joint with a uniform P(B | A), and the original left untouched
    for b_uniform, prog in ((True, ablated), (False, program)):
        joint = _ablation_joint(b_uniform)
        ref = joint[:, 1].sum(axis=(1, 2))
        np.testing.assert_allclose(_ask(prog, "P(A | B=b1)").probabilities, ref / ref.sum(),
                                   rtol=1e-12)
        ref = joint[:, :, :, 1].sum(axis=0)  # B, C
        np.testing.assert_allclose(_ask(prog, "P(B C | D=d1)").probabilities, ref / ref.sum(),
                                   rtol=1e-12)
        log_b = np.log(joint.sum(axis=(0, 2, 3))) + stats.norm.logpdf(0.4, E_MEAN, 0.7)
        result = _ask(prog, "P(B | E)", {"E": 0.4})
        np.testing.assert_allclose(result.probabilities, softmax(log_b), rtol=1e-12)
        np.testing.assert_allclose(result.log_evidence, logsumexp(log_b), rtol=1e-12)
    # MAP records the ablation too
    best = _ask(ablated, "P(B | A=a0)", kind="map")
    assert best.ablated == ("P(B | A)",)


def test_ablate_in_the_file_equals_the_python_call():
    in_file = _loads(_ablation_doc(ablate=["P(B | A)"]))
    by_call = _loads(_ablation_doc()).ablate("P(B | A)")
    assert in_file.ablated == by_call.ablated == ("P(B | A)",)
    for question, evidence in ABLATION_QUESTIONS:
        got = _ask(in_file, question, evidence)
        want = _ask(by_call, question, evidence)
        np.testing.assert_allclose(got.probabilities, want.probabilities, rtol=1e-12,
                                   atol=1e-15)
        np.testing.assert_allclose(got.log_evidence, want.log_evidence, rtol=1e-12)


def test_ablate_several_terms_and_a_continuous_one():
    program = _loads(_ablation_doc())
    twice = program.ablate("P(B | A)").ablate(["P(B | A)", "P(D | B, A)"])
    assert twice.ablated == ("P(B | A)", "P(D | A, B)")
    joint = _ablation_joint(True)
    joint = joint.sum(axis=3, keepdims=True) * 0.5  # P(D | A, B) uniform
    ref = joint[:, :, :, 0].sum(axis=(1, 2))
    np.testing.assert_allclose(_ask(twice, "P(A | D=d0)").probabilities, ref / ref.sum(),
                               rtol=1e-12)
    # a continuous child on an unbounded support: the uniform is the constant 1
    no_e = program.ablate("P(E | B)")
    written = _loads(_ablation_doc(e_uniform=True))
    for value in (-3.0, 0.4, 5.0):
        got = _ask(no_e, "P(A B | E)", {"E": value})
        want = _ask(written, "P(A B | E)", {"E": value})
        np.testing.assert_allclose(got.probabilities, want.probabilities, rtol=1e-12)
        ref = _ablation_joint(False).sum(axis=(2, 3))
        np.testing.assert_allclose(got.probabilities, ref, rtol=1e-12)
    with pytest.raises(QuestionError):
        program.ablate("P(C | A)")
    # the compiled network of an ablated program is the ablated one
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        discrete = _loads({**_ablation_doc(), "variables": {
            k: v for k, v in _ablation_doc()["variables"].items() if k != "E"},
            "decomposition": _ablation_doc()["decomposition"][:4]}).ablate("P(B | A)")
        factor = VariableElimination(to_bayesian_network(discrete)).query(
            ["A"], evidence={"B": "b1"}, joint=True, show_progress=False)
    np.testing.assert_allclose(factor.values, PA, rtol=1e-12)
    np.testing.assert_allclose(_ask(discrete, "P(A | B=b1)").probabilities, PA, rtol=1e-12)


# log-space safety ------------------------------------------------------------------------------
def _tiny_program(means_e, means_f, sigma):
    states = [f"m{i}" for i in range(len(means_e))]
    return _loads({
        "bayesprog": 1,
        "variables": {"M": {"states": states},
                      "E": {"continuous": [-np.inf, np.inf]},
                      "F": {"continuous": [-np.inf, np.inf]}},
        "decomposition": [
            {"term": "P(M)", "form": "uniform"},
            {"term": "P(E | M)", "form": "normal",
             "mean": dict(zip(states, means_e, strict=True)), "sigma": sigma},
            {"term": "P(F | M)", "form": "normal",
             "mean": dict(zip(states, means_f, strict=True)), "sigma": sigma},
        ],
    })


@settings(max_examples=30, deadline=None, suppress_health_check=SLOW_OK)
@given(
    seed=st.integers(0, 2**32 - 1),
    card=st.integers(2, 4),
    shift_e=st.floats(1.0, 3.0),
    shift_f=st.floats(-3.0, -1.0),
)
def test_underflowing_likelihoods_stay_exact_in_log_space(seed, card, shift_e, shift_f):
    rng = np.random.default_rng(seed)
    means_e = rng.uniform(-1, 1, size=card)
    means_f = rng.uniform(-1, 1, size=card)
    sigma = 1e-3
    program = _tiny_program(means_e.tolist(), means_f.tolist(), sigma)
    e = float(means_e.max() + shift_e)  # >= 1 away from every mean
    f = float(means_f.min() + shift_f)
    # in linear space every density is exactly 0
    assert np.all(stats.norm.pdf(e, means_e, sigma) == 0)
    assert np.all(stats.norm.pdf(f, means_f, sigma) == 0)
    for question, evidence, log_lik in (
        ("P(M | E)", {"E": e}, stats.norm.logpdf(e, means_e, sigma)),
        ("P(M | E, F)", {"E": e, "F": f},
         stats.norm.logpdf(e, means_e, sigma) + stats.norm.logpdf(f, means_f, sigma)),
    ):
        result = _ask(program, question, evidence)
        log_joint = log_lik - np.log(card)
        assert np.all(np.isfinite(result.probabilities))
        assert np.isfinite(result.log_evidence)
        np.testing.assert_allclose(result.probabilities, softmax(log_joint), rtol=1e-6,
                                   atol=1e-12)
        np.testing.assert_allclose(result.log_evidence, logsumexp(log_joint), rtol=1e-12)


def test_underflow_in_some_rows_of_a_batch():
    # row 0: E favours m0, F favours m1, each by ~5e5 nats: the scaled product underflows to 0
    # for every state; row 1: E and F both favour m1, nothing underflows.
    means_e, means_f, sigma = [0.0, 1.0, 2.0], [1.0, 0.0, 2.0], 1e-3
    program = _tiny_program(means_e, means_f, sigma)
    e = np.array([0.0002, 1.0004])
    f = np.array([0.0003, 0.0001])
    result = _ask(program, "P(M | E, F)", {"E": e, "F": f})
    for row in range(2):
        log_joint = (stats.norm.logpdf(e[row], means_e, sigma)
                     + stats.norm.logpdf(f[row], means_f, sigma) - np.log(3))
        np.testing.assert_allclose(result.probabilities[row], softmax(log_joint), rtol=1e-6,
                                   atol=1e-12)
        np.testing.assert_allclose(result.log_evidence[row], logsumexp(log_joint), rtol=1e-12)
    best = _ask(program, "P(M | E, F)", {"E": e, "F": f}, kind="map")
    assert best.indices[:, 0].tolist() == [0, 1]



@pytest.mark.parametrize("gap", [300.0, 340.0, 355.0, 365.0, 370.0, 372.0])
def test_partially_underflowing_contraction_is_exact(gap):
    # three fields, each favouring one state of M by ~gap nats: after each factor is scaled
    # by its maximum, every state's product is ~exp(-2 gap); at gap 370 a subnormal double
    # with a few bits of precision, which must not leak into the posterior
    gaps = gap + np.array([[-gap, 0.0, 0.3], [-0.2, -gap, 0.0], [0.3, -0.2, -gap]])
    means = np.sqrt(2 * gaps)  # N(0; mean, 1) is exp(-gap) times N(0; 0, 1)
    states = ["m0", "m1", "m2"]
    doc = {"bayesprog": 1, "variables": {"M": {"states": states}},
           "decomposition": [{"term": "P(M)", "form": "uniform"}]}
    for i in range(3):
        doc["variables"][f"E{i}"] = {"continuous": [-np.inf, np.inf]}
        doc["decomposition"].append({"term": f"P(E{i} | M)", "form": "normal",
                                     "mean": dict(zip(states, means[i].tolist(), strict=True)),
                                     "sigma": 1.0})
    program = _loads(doc)
    log_joint = sum(stats.norm.logpdf(0.0, means[i], 1.0) for i in range(3)) - np.log(3)
    if gap >= 365:
        assert np.exp(log_joint).max() < np.finfo(float).tiny  # subnormal in linear space
    result = _ask(program, "P(M | E0, E1, E2)", {"E0": 0.0, "E1": 0.0, "E2": 0.0})
    np.testing.assert_allclose(result.probabilities, softmax(log_joint), rtol=1e-9)
    np.testing.assert_allclose(result.log_evidence, logsumexp(log_joint), rtol=1e-12)


@pytest.mark.parametrize("exponent", [50, 90, 100, 103, 110, 150])
def test_tiny_discrete_probabilities_stay_exact(exponent):
    """Three observed children, each of probability ~10^-exponent: P(evidence) ranges from
    normal doubles through subnormals (~1e-300 .. 1e-320) to exact underflow (1e-450)."""
    tiny = 10.0 ** -exponent
    rows = np.array([[1.0, 2.0, 0.5], [3.0, 1.0, 0.25], [0.7, 1.5, 2.5]]) * tiny  # [C_i, M]
    prior = np.array([0.5, 0.3, 0.2])
    states = ["m0", "m1", "m2"]
    doc = {"bayesprog": 1,
           "variables": {"M": {"states": states}},
           "decomposition": [{"term": "P(M)", "form": "table", "table": prior.tolist()}]}
    for i in range(3):
        doc["variables"][f"C{i}"] = {"states": [f"c{i}_rare", f"c{i}_usual"]}
        doc["decomposition"].append({
            "term": f"P(C{i} | M)", "form": "table",
            "table": {m: [float(rows[i, j]), 1.0 - float(rows[i, j])]
                      for j, m in enumerate(states)}})
    program = _loads(doc)
    log_joint = np.log(prior) + np.log(rows).sum(axis=0)
    question = "P(M | C0=c0_rare, C1=c1_rare, C2=c2_rare)"
    result = _ask(program, question)
    np.testing.assert_allclose(result.probabilities, softmax(log_joint), rtol=1e-12)
    np.testing.assert_allclose(result.log_evidence, logsumexp(log_joint), rtol=1e-12)
    # the same through a batch that mixes rare and usual observations
    c0 = np.array(["c0_rare", "c0_usual", "c0_rare"])
    batched = _ask(program, "P(M | C0, C1=c1_rare, C2=c2_rare)", {"C0": c0})
    for row, name in enumerate(c0):
        lik0 = rows[0] if name == "c0_rare" else 1.0 - rows[0]
        log_ref = np.log(prior) + np.log(lik0) + np.log(rows[1:]).sum(axis=0)
        np.testing.assert_allclose(batched.probabilities[row], softmax(log_ref), rtol=1e-12)
        np.testing.assert_allclose(batched.log_evidence[row], logsumexp(log_ref), rtol=1e-12)


def test_grid_with_many_fields_multiplying_small_values():
    rows, cols, n_fields, sigma = 3, 4, 8, 0.01
    n = rows * cols
    rng = np.random.default_rng(3)
    means = rng.uniform(0, 1, size=(n_fields, n))
    # field k sits on its mean at cell 3k mod n and 0.5 away elsewhere: every cell is
    # 0.5 / 0.01 = 50 sigmas away in most fields, exp(-1250) per field in linear space
    values = means + 0.5
    for k in range(n_fields):
        values[k, (3 * k) % n] = means[k, (3 * k) % n] + 0.002 * k
    variables = {"O": {"grid": {"shape": [rows, cols], "cell": 1.0}},
                 "T": {"states": ["t0", "t1"]}}
    terms = [{"term": "P(O)", "form": "uniform"},
             {"term": "P(T)", "form": "table", "table": [0.4, 0.6]}]
    for k in range(n_fields):
        variables[f"F{k}"] = {"continuous": [-np.inf, np.inf], "indexed_by": "O"}
        terms.append({"term": f"P(F{k} | O)", "form": "normal", "mean": means[k].tolist(),
                      "sigma": sigma})
    variables["G"] = {"continuous": [0, 1], "indexed_by": "O"}
    terms.append({"term": "P(G | O, T)", "form": "beta", "a": {"t0": 30, "t1": 0.5},
                  "b": {"t0": 0.5, "t1": 30}})
    program = _loads({"bayesprog": 1, "variables": variables, "decomposition": terms})
    g = rng.uniform(0.05, 0.95, size=n)
    evidence = {f"F{k}": values[k] for k in range(n_fields)} | {"G": g}
    known = ", ".join(evidence)
    log_fields = stats.norm.logpdf(values, means, sigma).sum(axis=0)  # [O]
    assert np.all(np.exp(log_fields) == 0)  # the product underflows in linear space
    for t in range(2):
        log_joint = (log_fields + stats.beta.logpdf(g, [30, 0.5][t], [0.5, 30][t])
                     - np.log(n) + np.log([0.4, 0.6][t]))
        result = _ask(program, f"P(O | T=t{t}, {known})", evidence)
        assert np.all(np.isfinite(result.probabilities))
        np.testing.assert_allclose(result.probabilities, softmax(log_joint), rtol=1e-6,
                                   atol=1e-12)
        np.testing.assert_allclose(result.log_evidence, logsumexp(log_joint), rtol=1e-12)
        best = _ask(program, f"P(O | T=t{t}, {known})", evidence, kind="map")
        assert int(best.indices[0]) == int(np.argmax(log_joint))
    # T searched too: a joint over 2 x 12 states, still exact
    result = _ask(program, f"P(T O | {known})", evidence)
    log_joint = np.stack([log_fields + stats.beta.logpdf(g, [30, 0.5][t], [0.5, 30][t])
                          + np.log([0.4, 0.6][t]) for t in range(2)]) - np.log(n)
    np.testing.assert_allclose(result.probabilities, softmax(log_joint, axis=None), rtol=1e-6,
                               atol=1e-12)
    np.testing.assert_allclose(result.log_evidence, logsumexp(log_joint), rtol=1e-12)


# the probability of an event --------------------------------------------------------------------


@settings(max_examples=50, deadline=None, suppress_health_check=SLOW_OK)
@given(data=st.data())
def test_the_probability_of_an_event_against_enumeration_and_pgmpy(data):
    net = data.draw(nets())
    q = data.draw(queries(net, styles=("inline", "name")))
    event = {v: data.draw(st.integers(0, net.cards[v] - 1)) for v in q.searched}
    program = net.program()
    left = ", ".join(f"{v}={net.states[v][i]}" for v, i in event.items())
    right = [f"{v}={net.states[v][i]}" if q.style[v] == "inline" else v for v, i in q.known.items()]
    text = f"P({left}" + (f" | {', '.join(right)})" if right else ")")
    known = net.unnormalised([], q.known).sum()
    both = net.unnormalised(list(event), q.known)[tuple(event.values())]
    if known == 0:
        with pytest.raises(ZeroEvidenceError, match="probability zero"):
            program.probability(text, q.evidence(net))
        return
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", "divide by zero", RuntimeWarning)
        result = program.probability(text, q.evidence(net))
    assert result.batch_shape == () and result.variables == tuple(event)
    assert abs(float(result) - both / known) <= 1e-9  # brute force
    # pgmpy: the joint of the event's variables given the known ones, read at the event
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        factor = VariableElimination(to_bayesian_network(program)).query(
            list(event), evidence={v: net.states[v][i] for v, i in q.known.items()} or None,
            joint=True, show_progress=False)
    cell = tuple(factor.state_names[v].index(net.states[v][event[v]]) for v in factor.variables)
    assert abs(float(result) - factor.values[cell] / factor.values.sum()) <= 1e-9


ASIA = (PROGRAMS / "asia.yaml").read_text(encoding="utf-8")


def _pgmpy_probability(program, event: dict, known: dict) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        engine = VariableElimination(to_bayesian_network(program))
        factor = engine.query(list(event), evidence=known or None, joint=True,
                              show_progress=False)
    cell = tuple(factor.state_names[v].index(event[v]) for v in factor.variables)
    return float(factor.values[cell] / factor.values.sum())


def test_the_probability_of_evidence_of_asia_from_the_command_line_matches_pgmpy(tmp_path,
                                                                                 capsys):
    import json

    from bayesprog.cli import main

    path = tmp_path / "asia.yaml"
    path.write_text(ASIA)
    program = bayesprog.load(path)
    for text, event, known in [
            ("P(smoke=yes, dysp=yes)", {"smoke": "yes", "dysp": "yes"}, {}),
            ("P(xray=yes, dysp=no | asia=yes)", {"xray": "yes", "dysp": "no"}, {"asia": "yes"}),
            ("P(lung=yes | smoke=no, xray=yes)", {"lung": "yes"}, {"smoke": "no", "xray": "yes"})]:
        assert main(["query", str(path), text, "--json"]) == 0
        answer = json.loads(capsys.readouterr().out)
        reference = _pgmpy_probability(program, event, known)
        assert answer["kind"] == "probability" and answer["question"] == text
        assert abs(answer["probability"] - reference) <= 1e-9, text
        assert answer["log_probability"] == pytest.approx(np.log(reference), abs=1e-9)
        assert main(["query", str(path), text]) == 0
        assert f"probability {reference:.6g}" in capsys.readouterr().out
    # the probability of evidence is the log_evidence of any question on that evidence
    evidence = program.ask("P(asia | smoke=yes, dysp=yes)").log_evidence
    assert program.probability("P(smoke=yes, dysp=yes)").log_probability == pytest.approx(
        float(evidence), abs=1e-12)
    # a batch of events at once, the event's values given as evidence
    batch = program.probability("P(smoke dysp)", {"smoke": ["yes", "no"], "dysp": "yes"})
    assert batch.batch_shape == (2,)
    for row, smoke in enumerate(["yes", "no"]):
        assert abs(batch.probability[row]
                   - _pgmpy_probability(program, {"smoke": smoke, "dysp": "yes"}, {})) <= 1e-9
    # an impossible event has probability 0 (log -inf); impossible known values are refused
    assert float(program.probability("P(either=no | tub=yes)")) == 0.0
    with pytest.raises(ZeroEvidenceError, match="probability zero"):
        program.probability("P(xray=yes | tub=yes, either=no)")


@pytest.mark.parametrize("text, message", [
    ("P(smoke=yes, dysp)", "dysp without a value beside smoke"),
    ("P(smoke=yes dysp=yes)", "separate the variables of an event by commas"),
    ("P(smoke=maybe)", "unknown state 'maybe' of smoke"),
    ("P(smok=yes)", "undeclared variable 'smok'"),
])
def test_a_malformed_event_is_refused_with_its_fix(tmp_path, capsys, text, message):
    from bayesprog.cli import main

    path = tmp_path / "asia.yaml"
    path.write_text(ASIA)
    assert main(["query", str(path), text]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert main(["query", str(path), "P(smoke=yes)", "--map"]) == 2
    assert "asks the probability of an event, not a map question" in capsys.readouterr().err


def test_an_event_that_fixes_a_real_variable_has_a_density():
    program = _loads("""
bayesprog: 1
variables:
  M: {states: [wood, silicone]}
  E: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(M), form: table, table: [0.3, 0.7]}
  - {term: P(E | M), form: normal, mean: {wood: 0.5, silicone: 0.1}, sigma: 0.1}
""")
    given = program.probability("P(E=0.45 | M=wood)")
    assert given.density and float(given) == pytest.approx(stats.norm.pdf(0.45, 0.5, 0.1),
                                                           rel=1e-12)
    marginal = program.probability("P(E=0.45)")
    assert float(marginal) == pytest.approx(0.3 * stats.norm.pdf(0.45, 0.5, 0.1)
                                            + 0.7 * stats.norm.pdf(0.45, 0.1, 0.1), rel=1e-12)
    assert marginal.to_json()["density"] == pytest.approx(float(marginal))
    # a discrete event given a real value is a probability, Bayes' rule on the same numbers
    wood = program.probability("P(M=wood | E=0.45)")
    assert not wood.density and float(wood) == pytest.approx(
        0.3 * stats.norm.pdf(0.45, 0.5, 0.1) / float(marginal), rel=1e-12)
