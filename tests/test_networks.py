"""bnlearn networks imported from the BIF files shipped with pgmpy, asked the same questions as
pgmpy's VariableElimination and pyAgrum's LazyPropagation.

pyAgrum's network is built here from the parsed CPDs, not by pyAgrum's BIF reader, which rounds
the numbers (differences of ~1e-8) and so could not be compared to 1e-9.
"""

from __future__ import annotations

import gzip
import warnings
from pathlib import Path

import numpy as np
import pyagrum as gum
import pytest

import bayesprog
from bayesprog.cli import main
from bayesprog.io import network_to_document, read_network

EXAMPLES = Path(__import__("pgmpy").__file__).parent / "utils" / "example_models"
# Every bnlearn network of pgmpy's wheel up to hepar2's size (70 nodes), but mildew and barley,
# whose CPTs (547,158 and 130,180 numbers) make pgmpy's BIF reader alone take several seconds.
NETWORKS = ["asia", "cancer", "earthquake", "sachs", "survey", "alarm", "child", "insurance",
            "water", "hailfinder", "hepar2"]
SMALL = ["asia", "cancer", "earthquake", "survey"]


class Network:
    def __init__(self, name: str, tmp: Path):
        self.name = name
        self.bif = tmp / f"{name}.bif"
        self.bif.write_text(gzip.open(EXAMPLES / f"{name}.bif.gz", "rt").read())
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.model = read_network(self.bif)
        doc = network_to_document(self.model, name)
        import yaml

        self.yaml = tmp / f"{name}.yaml"
        self.yaml.write_text(yaml.safe_dump(doc, sort_keys=False))
        self.program = bayesprog.load(self.yaml)
        self.cpds = {c.variable: c for c in self.model.get_cpds()}
        for cpd in self.cpds.values():  # the importer renormalises rows rounded in the file
            cpd.normalize(inplace=True)

    def agrum(self) -> gum.BayesNet:
        bn = gum.BayesNet(self.name)
        for var, cpd in self.cpds.items():
            bn.add(gum.LabelizedVariable(var, var, [str(x) for x in cpd.state_names[var]]))
        for var, cpd in self.cpds.items():
            for parent in cpd.variables[1:]:
                bn.addArc(parent, var)
        for var, cpd in self.cpds.items():
            parents = cpd.variables[1:]
            values = np.asarray(cpd.values, dtype=float)
            for index in np.ndindex(*values.shape[1:]):
                where = {p: str(cpd.state_names[p][i]) for p, i in zip(parents, index, strict=True)}
                bn.cpt(var)[where] = values[(slice(None),) + index].tolist()
        return bn

    def sample(self, rng: np.random.Generator) -> dict[str, str]:
        """Forward sampling from the CPDs (so the evidence has positive probability)."""
        import networkx as nx

        graph = nx.DiGraph(list(self.model.edges()))
        graph.add_nodes_from(self.model.nodes())
        values: dict[str, str] = {}
        for var in nx.topological_sort(graph):
            cpd = self.cpds[var]
            parents = cpd.variables[1:]
            index = tuple(cpd.state_names[p].index(values[p]) for p in parents)
            probs = cpd.values[(slice(None),) + index]
            values[var] = cpd.state_names[var][rng.choice(len(probs), p=probs / probs.sum())]
        return values


@pytest.fixture(scope="module")
def networks(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("networks")
    return {name: Network(name, tmp) for name in NETWORKS}


def _questions(net: Network, seed: int, n: int):
    rng = np.random.default_rng(seed)
    names = list(net.program.variables)
    out = []
    for _ in range(n):
        world = net.sample(rng)
        k = int(rng.integers(1, min(6, len(names) - 1) + 1))
        chosen = rng.choice(len(names), size=k + 1, replace=False)
        target, observed = names[chosen[0]], [names[i] for i in chosen[1:]]
        out.append((target, {v: world[v] for v in observed}))
    return out


@pytest.mark.parametrize("name", NETWORKS)
def test_posteriors_equal_pgmpy_and_pyagrum(networks, name):
    from pgmpy.inference import VariableElimination

    net = networks[name]
    ve = VariableElimination(net.model)
    bn = net.agrum()
    lazy = gum.LazyPropagation(bn)
    for target, evidence in _questions(net, seed=hash(name) % 2**32, n=4):
        ours = net.program.posterior(f"P({target} | {', '.join(evidence)})", evidence)
        states = ours.states[target]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref = ve.query([target], evidence=evidence, show_progress=False)
        pg = np.array([ref.values[ref.state_names[target].index(s)] for s in states])
        lazy.setEvidence(evidence)
        lazy.makeInference()
        post = lazy.posterior(target)
        labels = list(bn.variable(target).labels())
        ag = np.array([post[labels.index(s)] for s in states])
        np.testing.assert_allclose(ours.probabilities, pg, rtol=0, atol=1e-9)
        np.testing.assert_allclose(ours.probabilities, ag, rtol=0, atol=1e-9)
        lazy.eraseAllEvidence()


@pytest.mark.parametrize("name", ["alarm", "child", "insurance", "hailfinder", "hepar2"])
def test_a_first_question_equals_the_planned_contraction(networks, name):
    """A question asked first of a fresh program is answered by elimination, nothing planned;
    the planned contraction (the method named) gives the same posterior and evidence
    probability to 1e-12."""
    net = networks[name]
    for target, evidence in _questions(net, seed=11, n=5):
        question = f"P({target} | {', '.join(evidence)})"
        program = bayesprog.load(net.yaml)
        first = program.posterior(question, evidence)
        assert not program.inference_cache.plans._paths
        planned = program.posterior(question, evidence, method="contraction")
        np.testing.assert_allclose(first.probabilities, planned.probabilities, rtol=1e-12,
                                   atol=1e-15)
        np.testing.assert_allclose(first.log_evidence, planned.log_evidence, rtol=1e-12)


@pytest.mark.parametrize("name", ["alarm", "child", "hepar2"])
def test_batched_equals_single(networks, name):
    """Evidence sets that share the question go in one call and give the single answers."""
    net = networks[name]
    rng = np.random.default_rng(7)
    names = list(net.program.variables)
    observed = [names[i] for i in rng.choice(len(names), size=4, replace=False)]
    target = next(v for v in names if v not in observed)
    worlds = [net.sample(rng) for _ in range(25)]
    batch = {v: np.array([w[v] for w in worlds]) for v in observed}
    question = f"P({target} | {', '.join(observed)})"
    try:
        batched = net.program.posterior(question, batch)
    except bayesprog.ZeroEvidenceError:  # pragma: no cover - sampled evidence has p > 0
        pytest.fail("sampled evidence cannot have probability zero")
    for i, world in enumerate(worlds):
        single = net.program.posterior(question, {v: world[v] for v in observed})
        np.testing.assert_allclose(batched.probabilities[i], single.probabilities, atol=1e-12)


@pytest.mark.parametrize("name", SMALL)
def test_map_equals_brute_force(networks, name):
    net = networks[name]
    program = net.program
    names = list(program.variables)
    cards = [program.variables[v].card for v in names]
    joint = np.ones(cards)
    for var in names:
        cpd = net.cpds[var]
        order = [var] + list(cpd.variables[1:])
        values = np.asarray(cpd.values)
        # reorder states to ours, then broadcast into the joint's axes
        for axis, v in enumerate(order):
            perm = [cpd.state_names[v].index(s) for s in program.variables[v].states]
            values = np.take(values, perm, axis=axis)
        perm_axes = [order.index(v) for v in names if v in order]
        values = values.transpose(perm_axes)
        shape = [program.variables[v].card if v in order else 1 for v in names]
        joint = joint * values.reshape(shape)
    rng = np.random.default_rng(3)
    for _ in range(5):
        world = net.sample(rng)
        searched = list(rng.choice(names, size=2, replace=False))
        known = [v for v in names if v not in searched][: int(rng.integers(0, 3))]
        sliced = joint
        for v in known:
            idx = program.variables[v].states.index(world[v])
            sel = [slice(None)] * len(names)
            sel[names.index(v)] = slice(idx, idx + 1)
            sliced = sliced[tuple(sel)]
        others = tuple(i for i, v in enumerate(names) if v not in searched)
        table = sliced.sum(axis=others)
        order = sorted(searched, key=names.index)
        table = np.transpose(table, [order.index(v) for v in searched])
        best = np.unravel_index(np.argmax(table), table.shape)
        ties = int(np.sum(table >= table.max() * (1 - 1e-12)))
        question = f"P({' '.join(searched)} | {', '.join(known)})" if known \
            else f"P({' '.join(searched)})"
        answer = program.map(question, {v: world[v] for v in known}, rng=0)
        if ties == 1:
            assert tuple(answer.indices) == tuple(int(i) for i in best)
        np.testing.assert_allclose(answer.probability, table.max() / table.sum(), atol=1e-12)


def test_import_export_round_trip(networks, tmp_path):
    """BIF -> YAML -> BIF -> YAML keeps variables, states, parent order and every CPT."""
    net = networks["child"]
    assert main(["export", str(net.yaml), "-o", str(tmp_path / "child.bif")]) == 0
    assert main(["import", str(tmp_path / "child.bif"), "-o", str(tmp_path / "again.yaml")]) == 0
    again = bayesprog.load(tmp_path / "again.yaml")
    first = net.program
    assert set(again.variables) == set(first.variables)
    for name, var in first.variables.items():
        assert again.variables[name].states == var.states
        a, b = first.term_of(name), again.term_of(name)
        assert [p.name for p in a.parents] == [p.name for p in b.parents]
        # equal to the last bits (renormalising rows divides by sums within 1 ulp of 1)
        np.testing.assert_allclose(a.params["table"].array, b.params["table"].array,
                                   rtol=1e-14, atol=0)


def test_imported_program_answers_on_the_command_line(networks, capsys):
    net = networks["asia"]
    assert main(["query", str(net.yaml), "P(lung | smoke=yes, xray=yes)", "--json"]) == 0
    out = capsys.readouterr().out
    import json

    data = json.loads(out)
    assert data["variables"] == ["lung"] and abs(sum(data["probabilities"]) - 1) < 1e-12


@pytest.mark.parametrize("content, words", [
    ("network x {\n}\nvariable A {\n type discrete [ 2 ] { a, b };\n}\n", "no CPD for A"),
    ("network x {\n variable A { type discrete [ 2 ] { a, b }; }\n", "bad.bif"),
    ("", "cannot parse as BIF"),
])
def test_malformed_network_files(tmp_path, capsys, content, words):
    bad = tmp_path / "bad.bif"
    bad.write_text(content)
    assert main(["import", str(bad), "-o", str(tmp_path / "bad.yaml")]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err


def test_unsupported_network_format(tmp_path, capsys):
    other = tmp_path / "net.dsc"
    other.write_text("x")
    assert main(["import", str(other), "-o", str(tmp_path / "x.yaml")]) == 2
    assert "unsupported network format" in capsys.readouterr().err


def _rare_leaves(net: Network) -> dict[str, str]:
    """Every leaf of the network observed in its least likely state: evidence under which
    likelihood weighting's draws, which ignore it, nearly all weigh nothing."""
    import networkx as nx

    graph = nx.DiGraph(list(net.model.edges()))
    leaves = sorted(v for v in graph.nodes if graph.out_degree(v) == 0)
    return {v: net.program.variables[v].states[
        int(np.argmin(net.program.ask(f"P({v})").probabilities))] for v in leaves}


def test_gibbs_sampling_answers_unlikely_evidence_as_exact_and_as_pyagrum(networks):
    net = networks["child"]
    evidence = _rare_leaves(net)
    question = f"P(Disease | {', '.join(evidence)})"
    exact = net.program.ask(question, evidence).probabilities
    weighted = net.program.ask(question, evidence, method="lw", samples=20_000)
    assert float(weighted.ess) < 0.01 * 20_000  # likelihood weighting starves here
    gibbs = net.program.ask(question, evidence, method="gibbs", samples=20_000, burn_in=1_000,
                            rng=4)
    assert gibbs.method == "gibbs" and np.isnan(gibbs.log_evidence)
    assert gibbs.evidence == "not estimated by Gibbs sampling"
    assert np.all(np.abs(gibbs.probabilities - exact) <= 4 * gibbs.stderr + 0.005)
    assert float(gibbs.ess) > 20 * float(weighted.ess)
    gum.initRandom(1)  # pyAgrum's chain seeded (0 would seed it from the clock)
    engine = gum.GibbsSampling(net.agrum())
    engine.setEvidence(evidence)
    engine.setEpsilon(1e-3)
    engine.setMaxTime(20)
    engine.makeInference()
    theirs = np.asarray(engine.posterior("Disease").toarray())
    assert np.all(np.abs(gibbs.probabilities - theirs) < 0.04)
    assert np.all(np.abs(theirs - exact) < 0.04)


def test_gibbs_sampling_is_seeded_per_row_whatever_the_batch(networks):
    program = networks["cancer"].program
    rows = {"Xray": np.array(["positive", "negative", "positive"]),
            "Dyspnoea": np.array(["True", "True", "False"])}
    question = "P(Cancer | Xray, Dyspnoea)"
    batch = program.ask(question, rows, method="gibbs", samples=4_000, burn_in=200, rng=9)
    again = program.ask(question, rows, method="gibbs", samples=4_000, burn_in=200, rng=9)
    np.testing.assert_array_equal(batch.probabilities, again.probabilities)
    # each row's chain has its own generator: a row asked alone is the same row
    alone = program.ask(question, {k: v[:1] for k, v in rows.items()}, method="gibbs",
                        samples=4_000, burn_in=200, rng=9)
    np.testing.assert_array_equal(alone.probabilities[0], batch.probabilities[0])
    exact = program.ask(question, rows).probabilities
    assert np.all(np.abs(batch.probabilities - exact) <= 4 * batch.stderr + 0.01)
    with pytest.raises(bayesprog.BayesprogError, match="thin"):
        program.ask(question, rows, method="gibbs", thin=0)


@pytest.mark.parametrize("name", ["asia", "alarm", "child", "insurance", "hailfinder"])
def test_questions_asked_again_equal_the_full_path_and_pyagrum(networks, name):
    """A question asked again, one evidence set at a time by state name, takes the warm path
    (its settled method read directly); each answer equals the full path's (the same evidence
    given as a batch of one row) to 1e-12, its evidence probability to 1e-9, and pyAgrum's
    posterior to 1e-9: by default, with the contraction named, and with tables switched off.
    The questions include targets d-separated from some or all of their evidence."""
    from bayesprog.inference import quick
    from bayesprog.inference.methods import table as table_method

    net = networks[name]
    lazy = gum.LazyPropagation(net.agrum())
    rng = np.random.default_rng(5)
    names = list(net.program.variables)
    worlds = [net.sample(rng) for _ in range(12)]
    warm = 0
    for mode in ("default", "contraction", "no tables"):
        limit = table_method.TABLE_LIMIT
        table_method.TABLE_LIMIT = 0 if mode == "no tables" else limit
        try:
            program = bayesprog.load(net.yaml)
            method = "contraction" if mode == "contraction" else None
            for k in (1, 2, 4):
                chosen = rng.choice(len(names), size=k + 1, replace=False)
                target, observed = names[chosen[0]], [names[i] for i in chosen[1:]]
                question = f"P({target} | {', '.join(observed)})"
                for world in worlds:
                    evidence = {v: world[v] for v in observed}
                    ours = program.posterior(question, evidence, method=method)
                    full = program.posterior(question, {v: [s] for v, s in evidence.items()},
                                             method=method)
                    np.testing.assert_allclose(ours.probabilities, full.probabilities[0],
                                               rtol=1e-12, atol=1e-15)
                    np.testing.assert_allclose(ours.log_evidence, full.log_evidence[0],
                                               rtol=1e-9)
                    if method:
                        assert ours.method == full.method == method
                    lazy.setEvidence(evidence)
                    lazy.makeInference()
                    post = lazy.posterior(target)
                    labels = [post.variable(0).label(i)
                              for i in range(post.variable(0).domainSize())]
                    reference = [post[labels.index(s)] for s in ours.states[target]]
                    np.testing.assert_allclose(ours.probabilities, reference, atol=1e-9)
                    lazy.eraseAllEvidence()
                key = (question, "posterior", method, tuple(observed))
                warm += quick.answer(program, key, evidence) is not None
        finally:
            table_method.TABLE_LIMIT = limit
    assert warm >= 7  # (a layout still weighing a compiled table takes the full path)
