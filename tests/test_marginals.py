"""Every marginal in one pass (``Program.marginals``, ``query --marginals``): the junction
tree's posteriors against brute-force enumeration, against pyAgrum's LazyPropagation on bnlearn
networks, and against one question per variable; batches, soft evidence, errors."""

from __future__ import annotations

import gzip
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

import bayesprog
from bayesprog.cli import main
from bayesprog.errors import QuestionError, ZeroEvidenceError
from bayesprog.io import dump_document, import_network


def _random_network(seed: int, size: int = 8) -> tuple[bayesprog.Program, dict]:
    """A random DAG over ``size`` variables of 2 to 4 states (up to three parents, so loops
    in the moral graph), as a program and as tables for enumeration."""
    rng = np.random.default_rng(seed)
    cards = {f"V{i}": int(rng.integers(2, 5)) for i in range(size)}
    names = list(cards)
    parents = {n: sorted(rng.choice(names[:i], size=min(i, int(rng.integers(0, 4))),
                                    replace=False).tolist()) for i, n in enumerate(names)}
    doc = {"bayesprog": 1, "variables": {n: {"states": [f"s{j}" for j in range(c)]}
                                         for n, c in cards.items()}, "decomposition": []}
    tables = {}
    for n in names:
        shape = tuple(cards[p] for p in parents[n])
        table = rng.dirichlet(np.ones(cards[n]) * 0.7, size=shape)
        tables[n] = (parents[n], table)
        term = f"P({n} | {', '.join(parents[n])})" if parents[n] else f"P({n})"
        doc["decomposition"].append({"term": term, "form": "table", "table": table.tolist()})
    return bayesprog.loads(dump_document(doc)), {"cards": cards, "tables": tables}


def _enumerate(net: dict, evidence: dict[str, int]) -> tuple[dict[str, np.ndarray], float]:
    cards, tables = net["cards"], net["tables"]
    names = list(cards)
    joint = np.ones([cards[n] for n in names])
    for n, (parents, table) in tables.items():
        axes = [names.index(p) for p in parents] + [names.index(n)]
        shape = [1] * len(names)
        for a, c in zip(axes, table.shape, strict=True):
            shape[a] = c
        order = np.argsort(axes)
        joint = joint * table.transpose(order).reshape(shape)
    index = tuple(evidence.get(n, slice(None)) for n in names)
    kept = joint[index]
    free = [n for n in names if n not in evidence]
    total = kept.sum()
    out = {}
    for i, n in enumerate(free):
        out[n] = kept.sum(axis=tuple(j for j in range(len(free)) if j != i)) / total
    return out, float(np.log(total))


@pytest.mark.parametrize("seed", range(6))
def test_every_marginal_is_the_enumerated_one(seed):
    program, net = _random_network(seed)
    rng = np.random.default_rng(100 + seed)
    names = list(net["cards"])
    for observed_count in (0, 1, 3):
        observed = rng.choice(names, size=observed_count, replace=False).tolist()
        evidence = {n: int(rng.integers(net["cards"][n])) for n in observed}
        found = program.marginals(evidence)
        expected, log_z = _enumerate(net, evidence)
        assert set(found) == set(expected)
        for name, answer in found.items():
            assert np.allclose(answer.probabilities, expected[name], rtol=0, atol=1e-12)
            assert answer.log_evidence == pytest.approx(log_z, abs=1e-10)


def test_a_batch_is_answered_as_its_rows_one_by_one():
    program, net = _random_network(7, size=10)
    rng = np.random.default_rng(3)
    rows = {"V2": rng.integers(net["cards"]["V2"], size=6),
            "V7": rng.integers(net["cards"]["V7"], size=6)}
    batch = program.marginals(rows)
    for r in range(6):
        one = program.marginals({k: int(v[r]) for k, v in rows.items()})
        for name, answer in one.items():
            assert batch[name].probabilities.shape == (6, net["cards"][name])
            assert np.allclose(batch[name].probabilities[r], answer.probabilities, atol=1e-13)
            assert batch[name].log_evidence[r] == pytest.approx(float(answer.log_evidence))


def test_soft_evidence_and_a_subset_of_variables_as_single_questions_give_them():
    program, net = _random_network(11, size=9)
    soft = {"V4": np.linspace(0.2, 1.0, net["cards"]["V4"])}
    found = program.marginals({"V8": 1}, variables=["V0", "V3"], soft=soft)
    assert list(found) == ["V0", "V3"]
    for name in found:
        single = program.posterior(f"P({name} | V8)", {"V8": 1}, soft=soft)
        assert np.allclose(found[name].probabilities, single.probabilities, atol=1e-13)


@pytest.mark.parametrize("call, message", [
    (lambda p: p.marginals({"V0": 0}, variables=["V0"]), "V0 is observed"),
    (lambda p: p.marginals({}, variables=["W"]), "unknown variable 'W'"),
    (lambda p: p.marginals({"W": 0}), "evidence for unknown variable 'W'"),
])
def test_a_wrong_request_is_refused_in_words(call, message):
    program, _ = _random_network(0)
    with pytest.raises(QuestionError, match=message):
        call(program)


def test_impossible_evidence_is_refused_as_by_a_question():
    program = bayesprog.loads(
        "bayesprog: 1\nvariables: {A: {states: [a0, a1]}, B: {states: [b0, b1]}, "
        "C: {states: [c0, c1]}}\ndecomposition:\n  - {term: P(A), form: table, table: [1, 0]}\n"
        "  - {term: P(B | A), form: table, table: [[1, 0], [0.5, 0.5]]}\n"
        "  - {term: P(C | B), form: table, table: [[0.5, 0.5], [0.5, 0.5]]}\n")
    with pytest.raises(ZeroEvidenceError):
        program.marginals({"B": "b1"})


def test_a_real_variable_observed_is_a_likelihood_and_one_unobserved_is_refused():
    text = ("bayesprog: 1\nvariables:\n  A: {states: [a0, a1]}\n  X: {continuous: [-.inf, .inf]}\n"
            "  B: {states: [b0, b1]}\ndecomposition:\n"
            "  - {term: P(A), form: table, table: [0.3, 0.7]}\n"
            "  - {term: P(X | A), form: normal, mean: {a0: -1.0, a1: 1.0}, sigma: 1.0}\n"
            "  - {term: P(B | A), form: table, table: [[0.9, 0.1], [0.2, 0.8]]}\n")
    program = bayesprog.loads(text)
    found = program.marginals({"X": 0.4})
    for name in ("A", "B"):
        single = program.posterior(f"P({name} | X)", {"X": 0.4})
        assert np.allclose(found[name].probabilities, single.probabilities, atol=1e-13)
    with pytest.raises(QuestionError, match="X is real"):
        program.marginals({}, variables=["A", "X"])


def _example(name: str, tmp_path: Path) -> tuple[Path, Path]:
    import pgmpy

    source = Path(pgmpy.__file__).parent / "utils" / "example_models" / f"{name}.bif.gz"
    bif = tmp_path / f"{name}.bif"
    bif.write_bytes(gzip.decompress(source.read_bytes()))
    return bif, import_network(bif, tmp_path / f"{name}.yaml")


@pytest.mark.parametrize("name", ["asia", "alarm", "insurance"])
def test_every_marginal_of_a_bnlearn_network_is_pyagrums(name, tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import pyagrum as gum

    bif, path = _example(name, tmp_path)
    program = bayesprog.load(path)
    bn = gum.loadBN(str(bif))
    # pyAgrum reads a BIF's numbers as single-precision floats (0.9 -> 0.89999998): its tables
    # are set to the program's, to compare the inference alone
    for term in yaml.safe_load(path.read_text())["decomposition"]:
        child, _, given = term["term"][2:-1].partition(" | ")
        parents = given.split(", ") if given else []
        table = np.asarray(term["table"], dtype=float)
        order = list(reversed(bn.cpt(child).names))  # the axes of pyAgrum's array
        axes = parents + [child]
        bn.cpt(child).fillWith(table.transpose([axes.index(n) for n in order]).ravel().tolist())
    gum.initRandom(5)
    generator = gum.BNDatabaseGenerator(bn)
    generator.drawSamples(3)
    rows = generator.to_pandas()
    rng = np.random.default_rng(5)
    names = list(program.variables)
    inference = gum.LazyPropagation(bn)
    for r in range(3):
        observed = rng.choice(names, size=min(5, len(names) - 1), replace=False).tolist()
        evidence = {n: str(rows.iloc[r][n]) for n in observed}
        found = program.marginals(evidence)
        inference.eraseAllEvidence()
        inference.setEvidence(evidence)
        inference.makeInference()
        worst = max(float(np.abs(found[v].probabilities
                                 - inference.posterior(v).toarray()).max()) for v in found)
        assert worst < 1e-9
        assert set(found) == set(names) - set(observed)
        any_answer = next(iter(found.values()))
        assert float(any_answer.log_evidence) == pytest.approx(
            np.log(inference.evidenceProbability()), abs=1e-9)


def test_query_marginals_prints_every_posterior(tmp_path, capsys):
    _, path = _example("asia", tmp_path)
    assert main(["query", str(path), "--marginals", "--evidence", "smoke=yes",
                 "--evidence", "xray=yes", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["evidence"] == ["smoke", "xray"]
    assert set(printed["marginals"]) == {"asia", "tub", "lung", "bronc", "either", "dysp"}
    program = bayesprog.load(path)
    lung = program.posterior("P(lung | smoke=yes, xray=yes)")
    assert printed["marginals"]["lung"]["probabilities"] == pytest.approx(
        lung.probabilities.tolist(), abs=1e-12)
    assert printed["log_evidence"] == pytest.approx(float(lung.log_evidence), abs=1e-12)
    assert main(["query", str(path), "--marginals", "--evidence", "smoke=yes"]) == 0
    table = capsys.readouterr().out
    assert all(f"P({n} | smoke)" in table for n in ("asia", "lung", "dysp"))


@pytest.mark.parametrize("argv, message", [
    (["P(lung)", "--marginals"], "--marginals: expected no question"),
    (["--marginals", "--map"], "--marginals and --map"),
    ([], "expected a question"),
])
def test_query_marginals_refuses_what_does_not_go_with_it(tmp_path, capsys, argv, message):
    _, path = _example("asia", tmp_path)
    assert main(["query", str(path), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_the_same_layout_keeps_its_tree():
    program, _ = _random_network(2, size=10)
    program.marginals({"V1": 0})
    trees = [k for k in program.inference_cache.layouts if k[0] == "junction"]
    program.marginals({"V1": 1})
    assert [k for k in program.inference_cache.layouts if k[0] == "junction"] == trees
    assert len(trees) == 1


def test_questions_observing_other_variables_share_one_tree_and_stay_exact():
    """The tree does not depend on what is observed: a session of questions, each observing
    other variables (batched too), builds it once, and every answer is the enumerated one."""
    program, net = _random_network(4, size=9)
    rng = np.random.default_rng(9)
    names = list(net["cards"])
    for count in (2, 0, 4, 1, 3):
        observed = rng.choice(names, size=count, replace=False).tolist()
        evidence = {n: int(rng.integers(net["cards"][n])) for n in observed}
        found = program.marginals(evidence)
        expected, log_z = _enumerate(net, evidence)
        for name, answer in found.items():
            assert np.allclose(answer.probabilities, expected[name], rtol=0, atol=1e-12)
            assert answer.log_evidence == pytest.approx(log_z, abs=1e-10)
    batch = {"V2": [0, 1, 1], "V5": [1, 0, 1]}
    found = program.marginals(batch)
    for row in range(3):
        expected, log_z = _enumerate(net, {n: v[row] for n, v in batch.items()})
        for name, answer in found.items():
            assert np.allclose(answer.probabilities[row], expected[name], rtol=0, atol=1e-12)
            assert float(answer.log_evidence[row]) == pytest.approx(log_z, abs=1e-10)
    assert len([k for k in program.inference_cache.layouts if k[0] == "junction"]) == 1


def _grid(size: int, seed: int = 0) -> bayesprog.Program:
    """A square grid of two-state variables, each cell's parents its upper and left cells."""
    rng = np.random.default_rng(seed)
    doc = {"bayesprog": 1, "variables": {}, "decomposition": []}
    for i in range(size):
        for j in range(size):
            name = f"X{i}_{j}"
            doc["variables"][name] = {"states": ["a", "b"]}
            parents = ([f"X{i - 1}_{j}"] if i else []) + ([f"X{i}_{j - 1}"] if j else [])
            table = rng.dirichlet([1.0, 1.0], size=(2,) * len(parents))
            doc["decomposition"].append({
                "term": f"P({name} | {', '.join(parents)})" if parents else f"P({name})",
                "form": "table", "table": table.tolist()})
    return bayesprog.loads(dump_document(doc))


def test_evidence_that_splits_the_graph_is_answered_on_the_smaller_tree(monkeypatch):
    """Every other column of a grid observed: the factors sliced at the evidence make a far
    smaller tree than the whole ones (even one within the limits when the whole one is not),
    and that one answers, as single questions do."""
    from bayesprog.inference import junction
    from bayesprog.limits import set_limits

    program = _grid(8)
    evidence = {f"X{i}_{j}": "ab"[(i + j) % 2] for i in range(8) for j in range(1, 8, 2)}
    asked = ["X2_0", "X5_4", "X7_6"]
    monkeypatch.setattr(junction, "WHOLE_TREE", 100)
    found = program.marginals(evidence, variables=asked)
    given = ", ".join(evidence)
    for name in asked:
        single = program.posterior(f"P({name} | {given})", evidence)
        assert np.allclose(found[name].probabilities, single.probabilities, rtol=0, atol=1e-12)
    chosen = [v for k, v in program.inference_cache.layouts.items() if k[0] == "junction sliced"]
    whole = [v for k, v in program.inference_cache.layouts.items() if k[0] == "junction"]
    assert len(chosen) == 1 and chosen[0] is not whole[0]
    assert chosen[0].entries * 2 < whole[0].entries

    fresh = _grid(8)
    set_limits(entries=2_000)  # the whole factors' tree is past it, the sliced one is not
    try:
        again = fresh.marginals(evidence, variables=asked)
    finally:
        set_limits()
    for name in asked:
        assert np.allclose(again[name].probabilities, found[name].probabilities, atol=1e-12)


def test_no_rows_of_evidence_give_answers_of_no_rows_and_change_nothing_kept():
    program, net = _random_network(3, size=6)
    before = program.marginals({"V2": 1})
    empty = program.marginals({"V2": np.array([], dtype=int)})
    assert all(a.probabilities.shape == (0, net["cards"][n]) for n, a in empty.items())
    after = program.marginals({"V2": 1})
    for name, answer in after.items():
        assert answer.log_evidence == before[name].log_evidence
        assert np.array_equal(answer.probabilities, before[name].probabilities)


def test_a_tree_far_past_the_limit_is_refused_in_words():
    from bayesprog.limits import SizeError, set_limits

    program = _grid(10)
    set_limits(entries=500)  # the elimination stops past 4 x 500 entries
    try:
        with pytest.raises(SizeError, match="junction tree of 99 variables needs more than "
                           "2,000 entries, more than the limit of 500"):
            program.marginals({"X0_1": "a"})
    finally:
        set_limits()
