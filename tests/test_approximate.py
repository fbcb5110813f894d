"""Beyond exact: sampling a program, likelihood weighting and loopy belief propagation, checked
against exact answers (ours, brute-force enumeration), scipy.stats and pyAgrum."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

import bayesprog
from bayesprog.cli import main
from bayesprog.errors import QuestionError
from bayesprog.limits import SizeError, set_limits

MODELS = Path(__file__).parents[1] / "models"
SPRINKLER = MODELS / "examples" / "sprinkler.yaml"

MIXED = """\
bayesprog: 1
variables:
  M: {states: [wood, silicone, plush]}
  C: {states: [c0, c1]}
  E: {continuous: [-.inf, .inf]}
  B: {continuous: [0, 1]}
  G: {continuous: [-5, 5]}
decomposition:
  - {term: P(M), form: table, table: [0.5, 0.3, 0.2]}
  - {term: P(C | M), form: table, table: {wood: [0.9, 0.1], silicone: [0.4, 0.6], plush: [0.2, 0.8]}}
  - {term: P(E | M), form: normal, mean: {wood: 0.5, silicone: 0.1, plush: -0.3}, sigma: 0.3}
  - {term: P(B | C), form: beta, a: {c0: 2, c1: 5}, b: 3}
  - {term: P(G | C), form: gmm, means: [-1, 2], sigma: 0.5, weights: {c0: [0.3, 0.7], c1: [0.9, 0.1]}, floor: 0.1}
"""


@pytest.fixture(scope="module")
def sprinkler():
    return bayesprog.load(SPRINKLER)


@pytest.fixture(scope="module")
def mixed():
    return bayesprog.loads(MIXED)


def binomial_ok(frequency: float, p: float, n: float, k: float = 4.5) -> bool:
    return abs(frequency - p) <= k * np.sqrt(max(p * (1 - p), 1e-12) / n) + 1e-12


# sampling ----------------------------------------------------------------------------------------
def test_forward_draws_follow_the_exact_joint(sprinkler):
    draws = sprinkler.sample(40000, rng=3)
    assert list(draws.columns) == ["Rain", "Sprinkler", "Grass"]
    exact = sprinkler.ask("P(Rain Sprinkler Grass)")
    for idx in np.ndindex(*exact.probabilities.shape):
        states = [exact.states[v][i] for v, i in zip(exact.variables, idx, strict=True)]
        hit = np.ones(len(draws), bool)
        for v, s in zip(exact.variables, states, strict=True):
            hit &= draws[v].to_numpy() == s
        assert binomial_ok(hit.mean(), exact.probabilities[idx], len(draws)), states


def test_continuous_draws_follow_their_densities(mixed):
    draws = mixed.sample(30000, rng=5)
    c0 = draws["C"].to_numpy() == "c0"
    # beta given C: scipy's distribution, by a Kolmogorov-Smirnov test
    assert stats.kstest(draws["B"][c0], stats.beta(2, 3).cdf).pvalue > 1e-3
    assert stats.kstest(draws["B"][~c0], stats.beta(5, 3).cdf).pvalue > 1e-3
    # normal given M
    wood = draws["M"].to_numpy() == "wood"
    assert stats.kstest(draws["E"][wood], stats.norm(0.5, 0.3).cdf).pvalue > 1e-3

    def mixture_cdf(x, weights):
        components = sum(w * stats.norm(m, 0.5).cdf(x) for w, m in zip(weights, (-1, 2),
                                                                          strict=True))
        return 0.9 * components + 0.1 * stats.uniform(-5, 10).cdf(x)

    assert stats.kstest(draws["G"][c0], lambda x: mixture_cdf(x, (0.3, 0.7))).pvalue > 1e-3
    assert stats.kstest(draws["G"][~c0], lambda x: mixture_cdf(x, (0.9, 0.1))).pvalue > 1e-3


@pytest.mark.parametrize("method", ["lw", "rejection"])
def test_conditioned_draws_follow_the_exact_posterior(sprinkler, method):
    draws = sprinkler.sample(40000, {"Grass": "wet"}, rng=2, method=method)
    exact = sprinkler.ask("P(Rain | Grass=wet)").probabilities[0]
    rain = (draws["Rain"] == "rain").to_numpy()
    if method == "lw":
        w = draws["weight"].to_numpy()
        assert np.isclose(w.sum(), 1.0)
        estimate, ess = float(w @ rain), 1 / float(w @ w)
    else:
        assert "weight" not in draws.columns
        estimate, ess = rain.mean(), len(draws)
    assert binomial_ok(estimate, exact, ess)


def test_draws_with_continuous_evidence_are_weighted_by_its_density(mixed):
    draws = mixed.sample(40000, {"E": 0.2, "B": 0.7}, rng=1)
    exact = mixed.ask("P(M C | E, B)", {"E": 0.2, "B": 0.7}).probabilities
    w = draws["weight"].to_numpy()
    ess = 1 / float(w @ w)
    for i, m in enumerate(("wood", "silicone", "plush")):
        estimate = float(w @ (draws["M"] == m).to_numpy())
        assert binomial_ok(estimate, exact[i].sum(), ess), m
    with pytest.raises(QuestionError, match="rejection sampling needs discrete evidence"):
        mixed.sample(10, {"E": 0.2}, method="rejection")


def test_the_same_seed_gives_the_same_draws(sprinkler):
    a = sprinkler.sample(500, {"Grass": "wet"}, rng=11)
    b = sprinkler.sample(500, {"Grass": "wet"}, rng=11)
    pd.testing.assert_frame_equal(a, b)
    assert not sprinkler.sample(500, rng=12).equals(sprinkler.sample(500, rng=11))


def test_cli_sample_writes_csv_and_parquet(tmp_path, capsys):
    for suffix in (".csv", ".parquet"):
        out = tmp_path / f"draws{suffix}"
        assert main(["sample", str(SPRINKLER), "-n", "300", "-o", str(out), "--seed", "4",
                     "--evidence", "Grass=wet"]) == 0
        frame = pd.read_csv(out) if suffix == ".csv" else pd.read_parquet(out)
        assert list(frame.columns) == ["Rain", "Sprinkler", "weight"]
        assert set(frame["Rain"]) <= {"rain", "dry"} and len(frame) == 300
    assert "300 draws of Rain, Sprinkler" in capsys.readouterr().out
    assert main(["sample", str(SPRINKLER), "-n", "0", "-o", str(tmp_path / "x.csv")]) == 2
    assert main(["sample", str(SPRINKLER), "-n", "5", "-o", str(tmp_path / "x.txt")]) == 2
    assert "expected a .csv or .parquet file" in capsys.readouterr().err


# likelihood weighting ------------------------------------------------------------------------------
def test_lw_agrees_with_exact_within_its_standard_errors(sprinkler, mixed):
    cases = [(sprinkler, "P(Rain Sprinkler | Grass)", {"Grass": ["wet", "dry"]}),
             (mixed, "P(M | E, G)", {"E": [0.2, -0.4, 0.6], "G": [1.5, -1.0, 0.0]}),
             (mixed, "P(C | B)", {"B": [0.1, 0.5, 0.9]})]
    for program, question, evidence in cases:
        exact = program.ask(question, evidence).probabilities
        answer = program.ask(question, evidence, method="lw", samples=20000, rng=7)
        assert answer.method == "lw" and answer.stderr.shape == exact.shape
        assert np.all(np.abs(answer.probabilities - exact) <= 4.5 * answer.stderr + 1e-9), question
        assert np.all(answer.ess > 100)


def test_lw_standard_errors_cover_the_exact_answer_as_often_as_they_say(sprinkler):
    exact = sprinkler.ask("P(Rain | Grass=wet)").probabilities[0]
    inside = []
    for seed in range(80):
        answer = sprinkler.ask("P(Rain | Grass=wet)", method="lw", samples=2000, rng=seed)
        inside.append(abs(answer.probabilities[0] - exact) <= 1.96 * answer.stderr[0])
    assert 0.85 <= np.mean(inside) <= 1.0  # nominal 95%


def test_lw_rows_do_not_depend_on_the_batch(sprinkler):
    seeds = [np.random.default_rng(s) for s in (5, 6)]
    both = sprinkler.ask("P(Rain | Grass)", {"Grass": ["wet", "dry"]}, method="lw",
                         samples=3000, rng=seeds)
    alone = sprinkler.ask("P(Rain | Grass)", {"Grass": ["dry"]}, method="lw", samples=3000,
                          rng=[np.random.default_rng(6)])
    np.testing.assert_array_equal(both.probabilities[1], alone.probabilities[0])


def test_lw_estimates_the_evidence(sprinkler):
    exact = sprinkler.ask("P(Rain | Grass=wet)")
    answer = sprinkler.ask("P(Rain | Grass=wet)", method="lw", samples=40000, rng=1)
    assert abs(np.exp(answer.log_evidence) - np.exp(exact.log_evidence)) < 0.01


def test_query_json_carries_the_error_estimate(capsys):
    assert main(["query", str(SPRINKLER), "why_wet", "--method", "lw", "--samples", "5000",
                 "--json"]) == 0
    answer = json.loads(capsys.readouterr().out)
    assert answer["method"] == "lw" and len(answer["stderr"]) == 2 and answer["ess"] > 1000
    assert main(["query", str(SPRINKLER), "why_wet", "--method", "lw"]) == 0
    assert "+- " in capsys.readouterr().out
    assert main(["query", str(SPRINKLER), "why_wet", "--samples", "0", "--method", "lw"]) == 2


# loopy belief propagation --------------------------------------------------------------------------
TREE = """\
bayesprog: 1
variables:
  A: {states: [a0, a1, a2]}
  B: {states: [b0, b1]}
  C: {states: [c0, c1]}
  D: {states: [d0, d1, d2]}
  E: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(A), form: table, table: [0.2, 0.5, 0.3]}
  - {term: P(B | A), form: table, table: [[0.9, 0.1], [0.3, 0.7], [0.5, 0.5]]}
  - {term: P(C | A), form: table, table: [[0.6, 0.4], [0.1, 0.9], [0.8, 0.2]]}
  - {term: P(D | C), form: table, table: [[0.1, 0.2, 0.7], [0.5, 0.25, 0.25]]}
  - {term: P(E | D), form: normal, mean: {d0: -1, d1: 0, d2: 1}, sigma: 0.7}
"""


def test_lbp_is_exact_on_a_tree():
    program = bayesprog.loads(TREE)
    evidence = {"B": ["b0", "b1", "b1"], "E": [0.3, -1.2, 2.0]}
    for question in ("P(A | B, E)", "P(D | B, E)", "P(C | B, E)", "P(C D | B, E)"):
        exact = program.ask(question, evidence).probabilities
        answer = program.ask(question, evidence, method="lbp")
        np.testing.assert_allclose(answer.probabilities, exact, atol=1e-10, err_msg=question)
        assert answer.method == "lbp" and answer.residual < 1e-9


def test_lbp_answers_one_variable_or_variables_that_share_a_term(sprinkler):
    program = bayesprog.loads(TREE)
    with pytest.raises(QuestionError, match="lbp answers the marginal of one variable"):
        program.ask("P(B D)", method="lbp")


def _grid(n: int, folder: Path, seed: int = 3) -> Path:
    """An n x n grid of binary variables, each with its up and left neighbours as parents,
    written as BIF by pyAgrum."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import pyagrum as gum
    gum.initRandom(seed)
    bn = gum.BayesNet("grid")
    for i in range(n):
        for j in range(n):
            bn.add(gum.LabelizedVariable(f"X{i}_{j}", "", 2))
    for i in range(n):
        for j in range(n):
            if i:
                bn.addArc(f"X{i - 1}_{j}", f"X{i}_{j}")
            if j:
                bn.addArc(f"X{i}_{j - 1}", f"X{i}_{j}")
    bn.generateCPTs()
    path = folder / f"grid{n}.bif"
    gum.saveBN(bn, str(path))
    return path


@pytest.fixture(scope="module")
def grid20(tmp_path_factory):
    folder = tmp_path_factory.mktemp("grid")
    bif = _grid(20, folder)
    assert main(["import", str(bif), "-o", str(folder / "grid20.yaml")]) == 0
    return bif, bayesprog.load(folder / "grid20.yaml")


def test_lbp_equals_pyagrums_on_the_20_by_20_grid(grid20):
    import pyagrum as gum

    bif, program = grid20
    bn = gum.loadBN(str(bif))
    evidence = {"X0_0": 1, "X19_19": 0, "X5_12": 1}
    engine = gum.LoopyBeliefPropagation(bn)
    engine.setEvidence(evidence)
    engine.makeInference()
    for target in ("X10_10", "X3_17", "X19_0"):
        answer = program.ask(f"P({target} | X0_0, X19_19, X5_12)",
                             {k: str(v) for k, v in evidence.items()}, method="lbp")
        np.testing.assert_allclose(answer.probabilities, engine.posterior(target).toarray(),
                                   atol=1e-6, err_msg=target)


def test_lw_agrees_with_pyagrums_sampling_on_the_20_by_20_grid(grid20):
    import pyagrum as gum

    bif, program = grid20
    gum.initRandom(1)
    bn = gum.loadBN(str(bif))
    engine = gum.ImportanceSampling(bn)
    engine.setEvidence({"X0_0": 1, "X19_19": 0})
    engine.setMaxTime(2)
    engine.setEpsilon(1e-9)
    engine.makeInference()
    theirs = engine.posterior("X10_10").toarray()
    their_se = np.sqrt(theirs[0] * theirs[1] / engine.nbrIterations())
    answer = program.ask("P(X10_10 | X0_0=1, X19_19=0)", method="lw", samples=20000, rng=3)
    combined = np.sqrt(answer.stderr[0] ** 2 + their_se**2)
    assert abs(answer.probabilities[0] - theirs[0]) < 4 * combined


def test_lw_and_lbp_agree_with_exact_on_a_12_by_12_grid(tmp_path):
    bif = _grid(12, tmp_path, seed=8)
    assert main(["import", str(bif), "-o", str(tmp_path / "grid12.yaml")]) == 0
    program = bayesprog.load(tmp_path / "grid12.yaml")
    question = "P(X6_6 | X0_0=1, X11_11=0)"
    exact = program.ask(question).probabilities
    lw = program.ask(question, method="lw", samples=20000, rng=2)
    assert np.all(np.abs(lw.probabilities - exact) <= 4.5 * lw.stderr)
    lbp = program.ask(question, method="lbp")
    assert np.abs(lbp.probabilities - exact).max() < 0.05  # loopy: close, not exact


def test_a_question_too_large_for_exact_names_the_approximate_methods(grid20):
    _, program = grid20
    try:
        set_limits(entries=10_000)
        with pytest.raises(SizeError, match=r"approximate method \(gibbs, lbp, lw\)"):
            program.ask("P(X10_10 | X0_0=1, X19_19=0)")
        answer = program.ask("P(X10_10 | X0_0=1, X19_19=0)", method="lbp")
        assert answer.probabilities.shape == (2,)
    finally:
        set_limits()


def test_an_unknown_method_is_a_question_error(sprinkler):
    with pytest.raises(QuestionError, match="method 'mcmc': expected one of"):
        sprinkler.ask("P(Rain)", method="mcmc")
