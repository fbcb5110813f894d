"""bnlearn's linear-Gaussian networks (the JSON files pgmpy ships) imported as programs, asked
questions and written back.

The reference is the joint Gaussian of the linear structural equations, computed here from the
JSON alone: ``x = b0 + B x + e``, ``e ~ N(0, D)``, so ``mean = (I - B)^-1 b0`` and
``Sigma = (I - B)^-1 D (I - B)^-T``; a question's answer is then Gaussian conditioning, by
scipy's solvers. (pgmpy's ``to_joint_gaussian`` rounds both to 8 decimals, so it serves as a
looser second check.)
"""

from __future__ import annotations

import importlib.util
import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy import linalg, stats

import bayesprog
from bayesprog.cli import main
from bayesprog.io.gaussian import formula_names

EXAMPLES = Path(importlib.util.find_spec("pgmpy").origin).parent / "utils" / "example_models"
NETWORKS = ["ecoli70", "magic-niab", "magic-irri", "arth150"]


class Reference:
    """The joint Gaussian of a JSON network, from its numbers alone."""

    def __init__(self, data: dict):
        self.nodes = list(data["nodes"])
        at = {v: i for i, v in enumerate(self.nodes)}
        n = len(self.nodes)
        weights, intercept, noise = np.zeros((n, n)), np.zeros(n), np.zeros(n)
        for v, cpd in data["cpds"].items():
            intercept[at[v]] = cpd["coefficients"]["(Intercept)"][0]
            noise[at[v]] = cpd["variance"][0]  # a variance (pgmpy: std = sqrt(variance[0]))
            for p in cpd["parents"]:
                weights[at[v], at[p]] = cpd["coefficients"][p][0]
        solve = linalg.solve(np.eye(n) - weights, np.eye(n))
        self.mean = solve @ intercept
        self.cov = solve @ np.diag(noise) @ solve.T
        self.at = at

    def condition(self, targets: list[str], evidence: dict[str, float]):
        """The targets' conditional mean and covariance, and log p(evidence)."""
        t = [self.at[v] for v in targets]
        o = [self.at[v] for v in evidence]
        x = np.array(list(evidence.values()))
        s_oo = self.cov[np.ix_(o, o)]
        gain = linalg.solve(s_oo, self.cov[np.ix_(o, t)], assume_a="pos")
        mean = self.mean[t] + gain.T @ (x - self.mean[o])
        cov = self.cov[np.ix_(t, t)] - self.cov[np.ix_(t, o)] @ gain
        return mean, cov, stats.multivariate_normal(self.mean[o], s_oo).logpdf(x)

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        return rng.multivariate_normal(self.mean, self.cov, size=size)


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    """Each network imported through the command line: (program, names, reference, json)."""
    out = {}
    folder = tmp_path_factory.mktemp("gaussian")
    for name in NETWORKS:
        target = folder / f"{name}.yaml"
        assert main(["import", str(EXAMPLES / f"{name}.json"), "-o", str(target)]) == 0
        data = json.loads((EXAMPLES / f"{name}.json").read_text())
        out[name] = (bayesprog.load(target), formula_names(data["nodes"]), Reference(data), data)
    return out


@pytest.mark.parametrize("name", NETWORKS)
def test_import_keeps_every_node_and_number(imported, name):
    program, names, _, data = imported[name]
    assert list(program.variables) == [names[v] for v in data["nodes"]]
    for node, cpd in data["cpds"].items():
        term = program.term_of(names[node])
        assert [p.name for p in term.parents] == [names[p] for p in cpd["parents"]]
        assert float(term.params["sigma"].array) == math.sqrt(cpd["variance"][0])
        if names[node] != node:
            assert program.variables[names[node]].description.startswith(f"named {node!r}")


@pytest.mark.parametrize("name", NETWORKS)
def test_answers_equal_the_joint_gaussian(imported, name):
    """A few targets given a few observed variables, with evidence drawn from the network
    (seeded): mean, sd, covariance and log-evidence to 1e-8."""
    program, names, ref, _ = imported[name]
    rng = np.random.default_rng(sum(map(ord, name)))
    worst = 0.0
    for observed_count, target_count in [(1, 1), (3, 1), (5, 2), (8, 3)]:
        picked = rng.choice(len(ref.nodes), observed_count + target_count, replace=False)
        targets = [ref.nodes[i] for i in picked[:target_count]]
        observed = [ref.nodes[i] for i in picked[target_count:]]
        for draw in ref.sample(rng, 3):
            evidence = {v: float(draw[ref.at[v]]) for v in observed}
            mean, cov, log_evidence = ref.condition(targets, evidence)
            answer = program.ask(f"P({' '.join(names[v] for v in targets)} | "
                                 f"{', '.join(names[v] for v in observed)})",
                                 {names[v]: x for v, x in evidence.items()})
            assert answer.method == "gaussian"
            got = np.array([float(answer.mean(names[v])) for v in targets])
            sds = np.array([float(answer.sd(names[v])) for v in targets])
            np.testing.assert_allclose(got, mean, rtol=0, atol=1e-8)
            np.testing.assert_allclose(sds, np.sqrt(np.diag(cov)), rtol=0, atol=1e-8)
            np.testing.assert_allclose(answer.covariance(), cov, rtol=0, atol=1e-8)
            np.testing.assert_allclose(answer.log_evidence, log_evidence, rtol=0, atol=1e-8)
            worst = max(worst, float(np.abs(got - mean).max()))
    assert worst < 1e-8


@pytest.mark.parametrize("name", ["ecoli70", "arth150"])
def test_batched_evidence_equals_one_row_at_a_time(imported, name):
    program, names, ref, _ = imported[name]
    rng = np.random.default_rng(7)
    picked = rng.choice(len(ref.nodes), 5, replace=False)
    target, observed = ref.nodes[picked[0]], [ref.nodes[i] for i in picked[1:]]
    draws = ref.sample(rng, 6)
    question = f"P({names[target]} | {', '.join(names[v] for v in observed)})"
    batch = program.ask(question, {names[v]: draws[:, ref.at[v]] for v in observed})
    for row, draw in enumerate(draws):
        mean, cov, _ = ref.condition([target], {v: float(draw[ref.at[v]]) for v in observed})
        assert float(batch.mean(names[target])[row]) == pytest.approx(mean[0], abs=1e-8)
        assert float(batch.sd(names[target])[row]) == pytest.approx(math.sqrt(cov[0, 0]),
                                                                    abs=1e-8)


def test_a_question_without_evidence_is_the_marginal(imported):
    program, names, ref, _ = imported["magic-irri"]
    node = ref.nodes[0]
    answer = program.ask(f"P({names[node]})")
    assert float(answer.mean(names[node])) == pytest.approx(ref.mean[0], abs=1e-8)
    assert float(answer.sd(names[node])) == pytest.approx(math.sqrt(ref.cov[0, 0]), abs=1e-8)


def test_pgmpy_predicts_the_same_means(imported):
    """pgmpy's LinearGaussianBayesianNetwork.predict_probability on the same file (its joint
    rounded to 8 decimals, hence the looser tolerance)."""
    import pandas as pd

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from pgmpy.models import LinearGaussianBayesianNetwork

        model = LinearGaussianBayesianNetwork.load(str(EXAMPLES / "ecoli70.json"))
    program, names, ref, _ = imported["ecoli70"]
    observed = ["asnA", "cspG", "eutG", "fixC"]
    draw = ref.sample(np.random.default_rng(3), 1)[0]
    evidence = {v: float(draw[ref.at[v]]) for v in observed}
    missing, means, _ = model.predict_probability(pd.DataFrame([evidence]))
    for target in ("lacZ", "yceP", "aceB"):
        answer = program.ask(f"P({target} | {', '.join(observed)})", evidence)
        assert float(answer.mean(target)) == pytest.approx(means[0, missing.index(target)],
                                                           abs=1e-6)


@pytest.mark.parametrize("name", NETWORKS)
def test_export_gives_back_the_file(imported, name, tmp_path):
    """import -> export: the same nodes, arcs and numbers (each float's repr), here the same
    bytes."""
    program, *_ = imported[name]
    out = tmp_path / f"{name}.json"
    assert main(["export", str(program.path), "-o", str(out)]) == 0
    original = json.loads((EXAMPLES / f"{name}.json").read_text())
    again = json.loads(out.read_text())
    assert again == original  # floats compared exactly
    assert out.read_text() == (EXAMPLES / f"{name}.json").read_text()


def test_round_trip_of_full_precision_numbers(tmp_path):
    """Coefficients of 17 digits come back to the bit; so do variances of up to 15 digits,
    longer ones within a few units of the last place (the program keeps sigma = sqrt(v))."""
    rng = np.random.default_rng(11)
    nodes = ["a", "b.c", "2d", "e"]
    parents = {"a": [], "b.c": ["a"], "2d": ["a", "b.c"], "e": ["2d"]}
    cpds = {}
    for i, v in enumerate(nodes):
        variance = float(rng.uniform(0.01, 5)) if i % 2 else float(f"{rng.uniform(0.01, 5):.15g}")
        cpds[v] = {"coefficients": {"(Intercept)": [float(rng.normal())],
                                    **{p: [float(rng.normal())] for p in parents[v]}},
                   "variance": [variance], "parents": parents[v]}
    arcs = [[p, v] for v in nodes for p in parents[v]]
    (tmp_path / "net.json").write_text(json.dumps({"nodes": nodes, "arcs": arcs, "cpds": cpds}))
    assert main(["import", str(tmp_path / "net.json"), "-o", str(tmp_path / "net.yaml")]) == 0
    assert main(["export", str(tmp_path / "net.yaml"), "-o", str(tmp_path / "back.json")]) == 0
    back = json.loads((tmp_path / "back.json").read_text())
    assert back["nodes"] == nodes and sorted(back["arcs"]) == sorted(arcs)
    for i, v in enumerate(nodes):
        assert back["cpds"][v]["coefficients"] == cpds[v]["coefficients"]
        assert back["cpds"][v]["parents"] == cpds[v]["parents"]
        got, want = back["cpds"][v]["variance"][0], cpds[v]["variance"][0]
        assert got == want if i % 2 == 0 else abs(got - want) <= 4 * math.ulp(want)


NETWORK = {"nodes": ["A", "B"], "arcs": [["A", "B"]],
           "cpds": {"A": {"coefficients": {"(Intercept)": [0.5]}, "variance": [1.0],
                          "parents": []},
                    "B": {"coefficients": {"(Intercept)": [0.1], "A": [2.0]},
                          "variance": [0.25], "parents": ["A"]}}}


def _edited(change) -> str:
    data = json.loads(json.dumps(NETWORK))
    change(data)
    return json.dumps(data)


@pytest.mark.parametrize("text, words", [
    ("nodes: [A, B]\n", ["not JSON", "line 1, column 1", "nodes, arcs and cpds"]),
    ("[1, 2]", ["expected a JSON object", "found a list"]),
    (_edited(lambda d: d.pop("cpds")), ["missing key 'cpds'", "expected nodes, arcs and cpds"]),
    (_edited(lambda d: d["cpds"]["B"].pop("variance")), ["cpds['B']", "missing 'variance'"]),
    (_edited(lambda d: d["cpds"]["A"].update(variance=[-0.5])),
     ["cpds['A'].variance", "expected a number > 0", "found -0.5"]),
    (_edited(lambda d: d["cpds"]["B"]["coefficients"].update(Z=[1.0])),
     ["cpds['B'].coefficients", "'Z' is not a node"]),
    (_edited(lambda d: d["cpds"]["B"].update(parents=["A", "Q"])),
     ["cpds['B'].parents", "'Q' is not a node"]),
    (_edited(lambda d: (d["arcs"].append(["B", "A"]),
                        d["cpds"]["A"].update(parents=["B"]),
                        d["cpds"]["A"]["coefficients"].update(B=[1.0]))),
     ["a cycle: ", "A -> B -> A", "expected a directed acyclic graph"]),
    (_edited(lambda d: d["cpds"]["B"]["coefficients"].pop("A")),
     ["cpds['B'].coefficients: no 'A'"]),
    (_edited(lambda d: d["arcs"].clear()), ["arcs has no A -> B"]),
    (_edited(lambda d: d["cpds"]["A"]["coefficients"].update({"(Intercept)": ["x"]})),
     ["expected a finite number", 'found "x"']),
    ('{"nodes": ["A"], "nodes": ["B"], "arcs": [], "cpds": {}}', ["'nodes' is given twice"]),
    ('{"nodes": ["A"], "arcs": [], "cpds": {"A": {"coefficients": {"(Intercept)": [NaN]}, '
     '"variance": [1], "parents": []}}}', ["NaN is not a JSON number"]),
])
def test_bad_files_are_refused_in_one_line(tmp_path, capsys, text, words):
    bad = tmp_path / "bad.json"
    bad.write_text(text)
    assert main(["import", str(bad), "-o", str(tmp_path / "bad.yaml")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1 and str(bad) in err, err
    for word in words:
        assert word in err, err
    assert not (tmp_path / "bad.yaml").exists()


def test_every_problem_of_a_file_is_reported(tmp_path, capsys):
    def change(d):
        d["cpds"]["A"]["variance"] = [-1]
        d["cpds"]["B"]["coefficients"]["Z"] = [1.0]

    bad = tmp_path / "bad.json"
    bad.write_text(_edited(change))
    assert main(["import", str(bad), "-o", str(tmp_path / "bad.yaml")]) == 2
    err = capsys.readouterr().err
    assert "cpds['A'].variance" in err and "'Z' is not a node" in err


def test_a_huge_file_is_refused_before_it_is_parsed(tmp_path, capsys, monkeypatch):
    from bayesprog.io import gaussian

    monkeypatch.setattr(gaussian, "MAX_BYTES", 1000)
    big = tmp_path / "big.json"
    big.write_text(json.dumps(NETWORK) + " " * 2000)
    assert main(["import", str(big), "-o", str(tmp_path / "big.yaml")]) == 2
    err = capsys.readouterr().err
    assert "big.json" in err and "more than" in err and "Traceback" not in err


def test_a_missing_file_and_a_gzipped_one(tmp_path, capsys):
    import gzip

    assert main(["import", str(tmp_path / "none.json"), "-o", str(tmp_path / "x.yaml")]) == 2
    assert "no such file" in capsys.readouterr().err
    packed = tmp_path / "net.json.gz"
    with gzip.open(packed, "wt") as f:
        f.write(json.dumps(NETWORK))
    assert main(["import", str(packed), "-o", str(tmp_path / "net.yaml")]) == 0
    program = bayesprog.load(tmp_path / "net.yaml")
    # B = 0.1 + 2 A + e: E[B] = 1.1, and given B = 1.1 + 2, E[A] = 0.5 + 2*4/(4 + 0.25)
    answer = program.ask("P(A | B)", {"B": 3.1})
    assert float(answer.mean("A")) == pytest.approx(0.5 + 2 * 2.0 / 4.25, abs=1e-12)


def test_export_refuses_a_program_that_is_not_linear_gaussian(tmp_path, capsys):
    program = tmp_path / "p.yaml"
    program.write_text("""bayesprog: 1
variables:
  A: {continuous: [-.inf, .inf]}
  B: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(A), form: normal, mean: 0, sigma: 1}
  - {term: P(B | A), form: normal, mean: "A**2", sigma: 1}
""")
    assert main(["export", str(program), "-o", str(tmp_path / "p.json")]) == 2
    err = capsys.readouterr().err
    assert "is not affine" in err and "Traceback" not in err


def test_the_layouts_algebra_equals_the_general_gaussian_path(imported, monkeypatch):
    """What a linear-Gaussian layout keeps between questions (LinearLayout) gives the answers
    of the general Gaussian algebra, which rebuilds everything at each question: joint
    questions, batches, log-evidence."""
    from bayesprog.inference.methods import gaussian

    program, names, ref, _ = imported["magic-niab"]
    rng = np.random.default_rng(5)
    picked = rng.choice(len(ref.nodes), 6, replace=False)
    targets, observed = [ref.nodes[i] for i in picked[:2]], [ref.nodes[i] for i in picked[2:]]
    draws = ref.sample(rng, 4)
    question = (f"P({' '.join(names[v] for v in targets)} | "
                f"{', '.join(names[v] for v in observed)})")
    evidence = {names[v]: draws[:, ref.at[v]] for v in observed}
    fast = program.ask(question, evidence)
    assert any("gaussian linear" in layout.prepared and layout.prepared["gaussian linear"]
               for layout in program.inference_cache.layouts.values())
    monkeypatch.setattr(gaussian.LinearLayout, "_make", classmethod(lambda cls, plan, block: None))
    general = bayesprog.load(program.path).ask(question, evidence)
    np.testing.assert_allclose(fast.covariance(), general.covariance(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.log_evidence, general.log_evidence, rtol=0, atol=1e-10)
    for v in targets:
        np.testing.assert_allclose(fast.mean(names[v]), general.mean(names[v]), rtol=0,
                                   atol=1e-12)


@pytest.mark.parametrize("text, affine", [
    ("2*X + 1 - (Y - 3)/4", True), ("X*Y", False), ("exp(0)*X", True), ("X/0", False),
    ("-X + pi*Y", True), ("2**3*X", True), ("X**2", False), ("sqrt(X)", False),
    ("(X + Y)*3 - Y*3", True), ("gain*X", False), ("1/X", False), ("X/2/4", True),
    ("+X - -Y", True), ("hypot(3, 4)*X + e", True), ("minimum(X, 1)", False),
    ("1e308*10*X", False), ("-(2*X - Y)/5 + 1.5e-3", True)])
def test_the_affine_form_of_a_formula_gives_its_values(text, affine):
    from bayesprog.vocabulary.formula import parse_formula

    formula = parse_formula(text)
    found = formula.affine()
    assert (found is not None) == affine
    if found is None:
        return
    intercept, coefficients = found
    assert set(coefficients) == set(formula.names)
    rng = np.random.default_rng(len(text))
    for _ in range(3):
        values = {name: float(rng.normal()) for name in formula.names}
        expected = float(formula.evaluate(values))
        assert intercept + sum(c * values[n] for n, c in coefficients.items()) == \
            pytest.approx(expected, rel=1e-12, abs=1e-12)
