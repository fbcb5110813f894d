"""Real variables beyond observed leaves: linear-Gaussian and conditional linear-Gaussian terms
answered exactly, deterministic terms, formulas as parameters, questions on real variables,
discretised variables; checked against closed forms, pgmpy and numerical integration."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import integrate, stats

import bayesprog
from bayesprog.cli import main
from bayesprog.errors import QuestionError, SpecError
from bayesprog.learning.data import DataError

EXAMPLES = Path(__file__).parents[1] / "models" / "examples"


def program(body: str) -> bayesprog.Program:
    return bayesprog.loads("bayesprog: 1\n" + body)


def gaussian_condition(mean, cov, observed, values):
    """The closed form: the Gaussian of the others given ``observed`` = ``values``."""
    o = np.asarray(observed)
    rest = np.array([i for i in range(len(mean)) if i not in observed])
    gain = cov[np.ix_(rest, o)] @ np.linalg.inv(cov[np.ix_(o, o)])
    m = mean[rest] + gain @ (np.asarray(values) - mean[o])
    c = cov[np.ix_(rest, rest)] - gain @ cov[np.ix_(o, rest)]
    return m, c, stats.multivariate_normal(mean[o], cov[np.ix_(o, o)]).logpdf(values)


# linear-Gaussian programs -----------------------------------------------------------------------
def test_sensor_fusion_matches_pgmpy_linear_gaussian_network():
    from pgmpy.factors.continuous import LinearGaussianCPD
    from pgmpy.models import LinearGaussianBayesianNetwork

    p = bayesprog.load(EXAMPLES / "sensor_fusion.yaml")
    evidence = {"GE": 1.0, "GN": 0.5, "B": 0.4, "Fault": "ok"}
    d = p.ask("P(East North | GE, GN, B, Fault)", evidence)
    assert d.method == "gaussian"
    net = LinearGaussianBayesianNetwork([("East", "GE"), ("North", "GN"), ("East", "B"), ("North", "B")])
    net.add_cpds(LinearGaussianCPD("East", [0.0], 2.0), LinearGaussianCPD("North", [0.0], 2.0),
                 LinearGaussianCPD("GE", [0.0, 1.0], 0.3, ["East"]),
                 LinearGaussianCPD("GN", [0.0, 1.0], 0.3, ["North"]),
                 LinearGaussianCPD("B", [0.0, 0.8, -0.6], 0.1, ["East", "North"]))
    mean, cov = net.to_joint_gaussian()
    import networkx as nx

    order = list(nx.topological_sort(net))  # the order of to_joint_gaussian
    idx = [order.index(v) for v in ("East", "North", "GE", "GN", "B")]
    mean, cov = mean[idx], cov[np.ix_(idx, idx)]
    m, c, loglik = gaussian_condition(mean, cov, [2, 3, 4], [1.0, 0.5, 0.4])
    np.testing.assert_allclose([d.mean("East"), d.mean("North")], m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(d.covariance(), c, rtol=0, atol=1e-12)
    np.testing.assert_allclose(d.log_evidence, loglik + np.log(0.9), rtol=0, atol=1e-10)
    np.testing.assert_allclose(d.sd("East"), np.sqrt(c[0, 0]), atol=1e-12)


def test_posterior_and_density_each_ask_their_kind_and_name_the_other():
    """``Program.posterior`` answers a table; a question on real variables is asked with
    ``Program.density`` (and ``posterior`` says so, instead of failing an assertion)."""
    p = bayesprog.load(EXAMPLES / "sensor_fusion.yaml")
    reading = {"GE": 1.0, "GN": 0.5, "B": 2.6}
    with pytest.raises(QuestionError, match=r"searches real variables \(East\).*"
                       r"program\.density"):
        p.posterior("P(East | GE, GN, B)", reading)
    density = p.density("P(East | GE, GN, B)", reading)
    assert density.mean("East") == pytest.approx(
        float(p.ask("P(East | GE, GN, B)", reading).mean("East")), abs=1e-15)
    with pytest.raises(QuestionError, match=r"program\.posterior"):
        p.density("P(Fault | GE, GN, B)", reading)
    with pytest.raises(QuestionError, match=r"program\.ask"):
        p.posterior("P(Fault East | GE, GN, B)", reading)
    assert p.posterior("P(Fault | GE, GN, B)", reading).probabilities.shape == (2,)


def test_conditional_linear_gaussian_is_the_mixture_over_the_discrete_cause():
    p = bayesprog.load(EXAMPLES / "sensor_fusion.yaml")
    reading = {"GE": 1.0, "GN": 0.5, "B": 2.6}
    prior = np.diag([4.0, 4.0])
    h = np.array([[1.0, 0], [0, 1.0], [0.8, -0.6]])
    noise = np.diag([0.09, 0.09, 0.01])
    z = np.array([1.0, 0.5, 2.6])
    weights, means, covs = [], [], []
    for offset, p_fault in ((0.0, 0.9), (2.0, 0.1)):
        shift = np.array([0, 0, offset])
        weights.append(p_fault * stats.multivariate_normal(shift, h @ prior @ h.T + noise).pdf(z))
        info = np.linalg.inv(prior) + h.T @ np.linalg.inv(noise) @ h
        covs.append(np.linalg.inv(info))
        means.append(covs[-1] @ h.T @ np.linalg.inv(noise) @ (z - shift))
    w = np.array(weights) / sum(weights)
    fault = p.ask("P(Fault | GE, GN, B)", reading)
    np.testing.assert_allclose(fault.probabilities, w, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fault.log_evidence, np.log(sum(weights)), atol=1e-10)
    d = p.ask("P(East North | GE, GN, B)", reading)
    mix_mean = w @ np.array(means)
    np.testing.assert_allclose([d.mean("East"), d.mean("North")], mix_mean, atol=1e-12)
    second = sum(wi * (c + np.outer(m, m)) for wi, m, c in zip(w, means, covs, strict=True))
    np.testing.assert_allclose(d.covariance(), second - np.outer(mix_mean, mix_mean), atol=1e-12)
    # the marginal density is the mixture's, its quantiles invert its CDF
    x = np.linspace(-2, 3, 7)
    by_hand = sum(wi * stats.norm(m[0], np.sqrt(c[0, 0])).pdf(x)
                  for wi, m, c in zip(w, means, covs, strict=True))
    np.testing.assert_allclose(d.pdf("East", x), by_hand, rtol=1e-10)
    for q in (0.05, 0.5, 0.9):
        xq = d.quantile("East", q)
        cdf = sum(wi * stats.norm(m[0], np.sqrt(c[0, 0])).cdf(xq)
                  for wi, m, c in zip(w, means, covs, strict=True))
        assert abs(cdf - q) < 1e-12


def test_kalman_filter_and_smoother_match_the_recursions():
    p = bayesprog.load(EXAMPLES / "kalman.yaml")
    z = [1.2, 1.9, 3.4]
    m, v = 0.0, 1.0
    for reading in z:  # predict, then update: the textbook recursion
        m, v = m + 1.0, v + 0.25
        gain = v / (v + 0.64)
        m, v = m + gain * (reading - m), (1 - gain) * v
    d = p.ask("filter")
    np.testing.assert_allclose([d.mean("X3"), d.sd("X3") ** 2], [m, v], rtol=0, atol=1e-12)
    assert d.map("X3") == pytest.approx(m, abs=1e-12)
    np.testing.assert_allclose(d.quantile("X3", [0.1, 0.5, 0.9]),
                               stats.norm(m, np.sqrt(v)).ppf([0.1, 0.5, 0.9]), atol=1e-9)
    # the smoother, from the joint Gaussian of the whole chain
    a = np.zeros((7, 7))  # order X0 X1 X2 X3 Z1 Z2 Z3
    for t in (1, 2, 3):
        a[t, t - 1] = 1.0
        a[3 + t, t] = 1.0
    b = np.array([0, 1, 1, 1, 0, 0, 0.0])
    s = np.array([1, 0.25, 0.25, 0.25, 0.64, 0.64, 0.64])
    inv = np.linalg.inv(np.eye(7) - a)
    mean, cov = inv @ b, inv @ np.diag(s) @ inv.T
    cm, cc, _ = gaussian_condition(mean, cov, [4, 5, 6], z)
    smooth = p.ask("smooth")
    np.testing.assert_allclose([smooth.mean("X1"), smooth.sd("X1")],
                               [cm[1], np.sqrt(cc[1, 1])], atol=1e-12)


def test_batched_evidence_gives_each_row_its_answer():
    p = bayesprog.load(EXAMPLES / "kalman.yaml")
    z3 = np.array([3.4, 2.0, 5.0])
    batch = p.ask("P(X3 | Z1, Z2, Z3)", {"Z1": 1.2, "Z2": 1.9, "Z3": z3})
    assert batch.mean("X3").shape == (3,)
    for i, value in enumerate(z3):
        one = p.ask("P(X3 | Z1, Z2, Z3)", {"Z1": 1.2, "Z2": 1.9, "Z3": float(value)})
        assert batch.mean("X3")[i] == pytest.approx(float(one.mean("X3")), abs=1e-12)


def test_linear_deterministic_term_is_exact():
    p = program("""
variables:
  X0: {continuous: [-.inf, .inf]}
  U: {continuous: [-.inf, .inf]}
  X1: {continuous: [-.inf, .inf]}
  Z: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(X0), form: normal, mean: 2, sigma: 1}
  - {term: P(U), form: normal, mean: 0, sigma: 10}
  - {term: "P(X1 | X0, U)", form: dirac, value: "X0 + U"}
  - {term: P(Z | X1), form: normal, mean: "X1", sigma: 0.5}
""")
    d = p.ask("P(X1 | U, Z)", {"U": 1.5, "Z": 4.0})
    # X1 = X0 + 1.5 ~ N(3.5, 1), read with noise 0.5
    v = 1 / (1 + 1 / 0.25)
    assert float(d.mean("X1")) == pytest.approx(v * (3.5 + 4.0 / 0.25), abs=1e-12)
    assert float(d.sd("X1")) == pytest.approx(np.sqrt(v), abs=1e-12)
    with pytest.raises(QuestionError, match="deterministic"):
        p.ask("P(X0 | X1=1.0)")


def test_a_formula_of_known_parents_needs_no_gaussian_method():
    p = program("""
variables:
  M: {states: [a, b]}
  X: {continuous: [-.inf, .inf]}
  W: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(M), form: table, table: [0.3, 0.7]}
  - {term: P(X), form: normal, mean: 0, sigma: 1}
  - {term: "P(W | M, X)", form: normal, mean: {a: "2*X + 1", b: "-X"}, sigma: 0.5}
""")
    post = p.ask("P(M | X, W)", {"X": 0.7, "W": 1.1})
    assert post.method in ("contraction", "table")
    like = np.array([0.3 * stats.norm(2 * 0.7 + 1, 0.5).pdf(1.1),
                     0.7 * stats.norm(-0.7, 0.5).pdf(1.1)])
    np.testing.assert_allclose(post.probabilities, like / like.sum(), atol=1e-12)
    # X unknown: the same question by Gaussian algebra, against numerical integration
    d = p.ask("P(M | W)", {"W": 1.1})
    assert d.method == "gaussian"
    marg = [0.3 * integrate.quad(lambda x: stats.norm.pdf(x) * stats.norm(2 * x + 1, 0.5).pdf(
        1.1), -10, 10, epsabs=1e-13)[0], 0.7 * integrate.quad(
        lambda x: stats.norm.pdf(x) * stats.norm(-x, 0.5).pdf(1.1), -10, 10, epsabs=1e-13)[0]]
    np.testing.assert_allclose(d.probabilities, np.array(marg) / sum(marg), atol=1e-10)


def test_mixture_map_is_the_highest_mode():
    p = program("""
variables:
  C: {states: [left, right]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(C), form: table, table: [0.4, 0.6]}
  - {term: P(X | C), form: normal, mean: {left: -2, right: 3}, sigma: {left: 0.5, right: 2}}
""")
    d = p.ask("P(X)")
    x = np.linspace(-6, 8, 200_001)
    dens = 0.4 * stats.norm(-2, 0.5).pdf(x) + 0.6 * stats.norm(3, 2).pdf(x)
    assert float(d.map("X")) == pytest.approx(x[dens.argmax()], abs=1e-4)
    np.testing.assert_allclose(d.pdf("X", x[::1000]), dens[::1000], rtol=1e-12)


# non-linear programs: a grid with an error estimate --------------------------------------------
def test_deterministic_range_on_a_grid_against_quadrature():
    p = bayesprog.load(EXAMPLES / "range_beacon.yaml")
    d = p.ask("where")
    assert d.method == "grid" and d.resolution == {"X": 256}

    def like(x):
        return stats.norm(np.sqrt(x**2 + 9), 0.5).pdf(5.0)

    z = integrate.quad(like, 0, 10, points=[4.0], epsabs=1e-13)[0]
    mean = integrate.quad(lambda x: x * like(x), 0, 10, points=[4.0], epsabs=1e-13)[0] / z
    second = integrate.quad(lambda x: x * x * like(x), 0, 10, points=[4.0])[0] / z
    sd = np.sqrt(second - mean**2)
    for stat, exact in (("mean", mean), ("sd", sd)):
        found = float(getattr(d, stat)("X"))
        estimated = float(d.error[stat]["X"])
        # the estimate is of the right size: the true error is below it and not far below
        assert abs(found - exact) <= estimated + 1e-9, (stat, found, exact, estimated)
        assert estimated < 0.05
    assert float(d.mean("X")) == pytest.approx(mean, abs=0.01)


def test_grid_answers_a_bounded_gaussian_program_close_to_the_exact_one():
    body = """
variables:
  X: {continuous: [-8, 8]}
  Z: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(X), form: normal, mean: 0, sigma: 1}
  - {term: P(Z | X), form: normal, mean: "X", sigma: 0.5}
"""
    p = program(body)
    exact = p.ask("P(X | Z=1)")
    grid = p.ask("P(X | Z=1)", method="grid", bins=200)
    assert exact.method == "gaussian" and grid.method == "grid"
    for stat in ("mean", "sd"):
        assert abs(float(getattr(grid, stat)("X")) - float(getattr(exact, stat)("X"))) \
            <= float(grid.error[stat]["X"]) + 1e-9


def test_unbounded_non_gaussian_program_is_refused_with_the_reason():
    p = program("""
variables:
  X: {continuous: [-.inf, .inf]}
  Z: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(X), form: normal, mean: 0, sigma: 1}
  - {term: P(Z | X), form: normal, mean: "X**2", sigma: 0.5}
""")
    with pytest.raises(QuestionError) as err:
        p.ask("P(X | Z=1)")
    assert "not affine" in str(err.value) and "unbounded support" in str(err.value)


def test_a_formula_may_use_runtime_inputs():
    """mean: "gain*X + offset" with gain and offset given per question (batched): the
    coefficient of X is known once gain is, so the answer is still exact Gaussian algebra."""
    p = program("""
variables:
  X: {continuous: [-.inf, .inf]}
  Z: {continuous: [-.inf, .inf]}
inputs:
  gain: {}
  offset: {}
decomposition:
  - {term: P(X), form: normal, mean: 1, sigma: 2}
  - {term: P(Z | X), form: normal, mean: "gain*X + offset", sigma: 0.5}
""")
    gain, offset, z = np.array([0.5, 2.0, -1.0]), np.array([0.0, 1.0, 3.0]), 2.0
    d = p.ask("P(X | Z)", {"Z": z}, inputs={"gain": gain, "offset": offset})
    assert d.method == "gaussian"
    for r in range(3):  # Z = g X + o + noise: the closed form per row
        m, c, loglik = gaussian_condition(
            np.array([1.0, gain[r] * 1.0 + offset[r]]),
            np.array([[4.0, 4.0 * gain[r]], [4.0 * gain[r], 4.0 * gain[r] ** 2 + 0.25]]),
            [1], [z])
        assert float(d.mean("X")[r]) == pytest.approx(m[0], abs=1e-12)
        assert float(d.sd("X")[r]) == pytest.approx(np.sqrt(c[0, 0]), abs=1e-12)
        assert float(d.log_evidence[r]) == pytest.approx(loglik, abs=1e-10)
    # drawn: Z follows its formula with the inputs of the draw
    draws = p.sample(4000, inputs={"gain": 2.0, "offset": 1.0}, rng=2)
    assert stats.kstest((draws["Z"] - 2 * draws["X"] - 1) / 0.5, stats.norm.cdf).pvalue > 1e-3
    with pytest.raises(QuestionError, match="missing input 'gain'"):
        p.ask("P(X | Z=1)", inputs={"offset": 0.0})


def test_a_formula_refuses_an_input_with_a_shape(tmp_path):
    path = tmp_path / "shaped.yaml"
    path.write_text("""bayesprog: 1
variables:
  X: {continuous: [-.inf, .inf]}
  Z: {continuous: [-.inf, .inf]}
inputs:
  gains: {shape: [3]}
decomposition:
  - {term: P(X), form: normal, mean: 0, sigma: 1}
  - {term: P(Z | X), form: normal, mean: "gains*X", sigma: 1}
""")
    with pytest.raises(SpecError) as err:
        bayesprog.load(path)
    (diag,) = err.value.diagnostics
    assert (diag.line, diag.column) == (9, 42)
    assert "a formula takes scalar inputs" in diag.message


# discretised variables --------------------------------------------------------------------------
def test_discretised_variable_bins_take_the_integral_and_may_have_discrete_children():
    p = program("""
variables:
  T: {continuous: [-.inf, .inf], discretise: {bins: [10, 15, 20, 25]}}
  Fan: {states: ["on", "off"]}
decomposition:
  - {term: P(T), form: normal, mean: 18, sigma: 4}
  - term: P(Fan | T)
    form: table
    table: {"[10, 15)": [0.1, 0.9], "[15, 20)": [0.5, 0.5], "[20, 25]": [0.9, 0.1]}
""")
    prior = p.ask("P(T)")
    cdf = stats.norm(18, 4).cdf([15, 20])
    np.testing.assert_allclose(prior.probabilities, [cdf[0], cdf[1] - cdf[0], 1 - cdf[1]],
                               atol=1e-15)
    post = p.ask("P(T | Fan=on)")
    like = np.array([0.1, 0.5, 0.9]) * prior.probabilities
    np.testing.assert_allclose(post.probabilities, like / like.sum(), atol=1e-15)
    # a reading is the bin that holds it
    assert p.ask("P(Fan | T)", {"T": 21.3}).probabilities[0] == pytest.approx(0.9)


def test_a_discretised_program_exports_to_pgmpy_with_the_same_answers():
    from pgmpy.inference import VariableElimination

    from bayesprog.io.compile import to_bayesian_network

    p = program("""
variables:
  T: {continuous: [-.inf, .inf], discretise: {bins: [10, 15, 20, 25]}}
  K: {range: [0, 2]}
  Fan: {states: ["on", "off"]}
decomposition:
  - {term: P(K), form: table, table: [0.2, 0.5, 0.3]}
  - {term: P(T | K), form: normal, mean: "16 + 2*K", sigma: 4}
  - term: P(Fan | T)
    form: table
    table: {"[10, 15)": [0.1, 0.9], "[15, 20)": [0.5, 0.5], "[20, 25]": [0.9, 0.1]}
""")
    net = to_bayesian_network(p)
    ve = VariableElimination(net).query(["K"], evidence={"Fan": "on"})
    np.testing.assert_allclose(p.ask("P(K | Fan=on)").probabilities, ve.values, atol=1e-12)
    # the bins of T given K are differences of the normal CDF at the edges
    cdf = stats.norm(16 + 2 * 2, 4).cdf([15, 20])
    np.testing.assert_allclose(p.ask("P(T | K=2)").probabilities,
                               [cdf[0], cdf[1] - cdf[0], 1 - cdf[1]], atol=1e-15)


# drawing and learning ---------------------------------------------------------------------------
def test_forward_draws_follow_the_formulas_of_drawn_parents():
    p = bayesprog.load(EXAMPLES / "range_beacon.yaml")
    d = p.sample(4000, rng=3)
    np.testing.assert_allclose(d["D"], np.sqrt(d["X"] ** 2 + 9), rtol=1e-14)
    assert stats.kstest(d["X"], stats.uniform(0, 10).cdf).pvalue > 1e-3
    residual = (d["R"] - d["D"]) / 0.5
    assert stats.kstest(residual, stats.norm.cdf).pvalue > 1e-3
    again = p.sample(4000, rng=3)
    np.testing.assert_array_equal(again["R"], d["R"])


BOUNDED = """
variables:
  A: {states: [a0, a1]}
  X: {continuous: [0, 1]}
  L: {continuous: [0.5, 4]}
  G: {continuous: [0, 1]}
decomposition:
  - {term: P(A), form: table, table: [0.4, 0.6]}
  - {term: P(X | A), form: normal, mean: {a0: 0.1, a1: 0.8}, sigma: 0.4}
  - {term: P(L | A), form: lognormal, mu: {a0: 0.0, a1: 1.0}, sigma: 1.0}
  - {term: P(G | A), form: gmm, weights: [0.5, 0.5], means: [[-0.2, 0.5], [0.4, 1.3]], sigma: 0.3}
"""


def test_sample_draws_a_bounded_real_variable_inside_its_support_from_the_truncated_term(
        tmp_path, capsys):
    """A Normal child of a variable declared on [0, 1] put a quarter of its draws outside it;
    each real variable is now drawn from its term truncated to its support (checked against
    scipy.stats.truncnorm, and the log-normal's truncated CDF; a false failure at 1e-3 per
    Kolmogorov-Smirnov test, seeded)."""
    p = program(BOUNDED)
    draws = p.sample(20_000, rng=11)
    for name, (low, high) in {"X": (0, 1), "L": (0.5, 4), "G": (0, 1)}.items():
        assert draws[name].between(low, high).all(), name
    for state, mean in (("a0", 0.1), ("a1", 0.8)):
        x = draws.loc[draws["A"] == state, "X"]
        truncated = stats.truncnorm((0 - mean) / 0.4, (1 - mean) / 0.4, loc=mean, scale=0.4)
        assert stats.kstest(x, truncated.cdf).pvalue > 1e-3
    for state, mu in (("a0", 0.0), ("a1", 1.0)):
        x = draws.loc[draws["A"] == state, "L"]
        law = stats.lognorm(1.0, scale=np.exp(mu))
        low, high = law.cdf(0.5), law.cdf(4)
        assert stats.kstest(x, lambda v, law=law, low=low, high=high:
                            (law.cdf(v) - low) / (high - low)).pvalue > 1e-3
    # a mixture has no quantile function: its values outside are drawn again (a truncation)
    g = draws.loc[draws["A"] == "a0", "G"]
    mixture = [stats.norm(-0.2, 0.3), stats.norm(0.5, 0.3)]
    inside = sum(0.5 * (c.cdf(1) - c.cdf(0)) for c in mixture)
    assert stats.kstest(g, lambda v: sum(0.5 * (c.cdf(v) - c.cdf(0)) for c in mixture)
                        / inside).pvalue > 1e-3
    # the parents keep their own law, and the command line writes the same draws
    assert abs((draws["A"] == "a1").mean() - 0.6) < 4 * np.sqrt(0.24 / 20_000)
    (tmp_path / "bounded.yaml").write_text("bayesprog: 1\n" + BOUNDED)
    assert main(["sample", str(tmp_path / "bounded.yaml"), "-n", "500", "--seed", "4", "-o",
                 str(tmp_path / "d.csv")]) == 0
    written = pd.read_csv(tmp_path / "d.csv")
    assert written["X"].between(0, 1).all() and written["L"].between(0.5, 4).all()


def test_a_term_with_no_probability_inside_a_support_is_refused_with_its_name():
    far = program(BOUNDED.replace("mean: {a0: 0.1, a1: 0.8}", "mean: {a0: 0.1, a1: 90}"))
    with pytest.raises(QuestionError, match=r"term P\(X \| A\) puts no probability inside "
                       r"the support \[0, 1\] of X"):
        far.sample(100, rng=1)
    mixture = program(BOUNDED.replace("means: [[-0.2, 0.5], [0.4, 1.3]]",
                                      "means: [[-50, -40], [0.4, 1.3]]"))
    with pytest.raises(QuestionError, match=r"term P\(G \| A\) puts little or no probability"):
        mixture.sample(100, rng=1)


def test_likelihood_weighting_draws_the_unknown_real_parents():
    p = bayesprog.load(EXAMPLES / "sensor_fusion.yaml")
    reading = {"GE": 1.0, "GN": 0.5, "B": 2.6}
    exact = p.ask("P(Fault | GE, GN, B)", reading)
    lw = p.ask("P(Fault | GE, GN, B)", reading, method="lw", samples=40_000, rng=5)
    assert lw.method == "lw"
    assert np.all(np.abs(lw.probabilities - exact.probabilities) < 4 * lw.stderr + 1e-9)
    # weighted draws of North against the exact posterior mean
    draws = p.sample(40_000, evidence=reading, rng=5)
    w = draws["weight"] / draws["weight"].sum()
    mean = float((w * draws["North"]).sum())
    sd = float(np.sqrt((w * (draws["North"] - mean) ** 2).sum()))
    exact_north = p.ask("P(North | GE, GN, B)", reading)
    assert abs(mean - float(exact_north.mean("North"))) < 5 * sd / np.sqrt(1 / (w**2).sum())
    with pytest.raises(QuestionError, match="North is real: likelihood weighting"):
        p.ask("P(North | GE, GN, B)", reading, method="lw")


def test_likelihood_weighting_answers_when_no_exact_method_does():
    p = program("""
variables:
  S: {states: [near, far]}
  X: {continuous: [-.inf, .inf]}
  Z: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: table, table: [0.5, 0.5]}
  - {term: P(X | S), form: normal, mean: {near: 1, far: 4}, sigma: 1}
  - {term: P(Z | X), form: normal, mean: "X**2", sigma: 1}
""")
    answer = p.ask("P(S | Z=2)", rng=1, samples=20_000)
    assert answer.method == "lw"  # not Gaussian (X**2), unbounded X (no grid)
    # by quadrature: P(S, Z=2) = int N(x; m_S, 1) N(2; x^2, 1) dx
    joint = [integrate.quad(lambda x, m=m: stats.norm.pdf(x, m) * stats.norm.pdf(2, x * x),
                            -10, 10, points=[0, 1.4])[0] for m in (1, 4)]
    truth = np.array(joint) / sum(joint)
    assert np.all(np.abs(answer.probabilities - truth) < 4 * answer.stderr + 1e-6)


def test_terms_with_formulas_are_kept_when_fitting_the_others():
    p = bayesprog.load(EXAMPLES / "sensor_fusion.yaml")
    data = p.sample(5000, rng=1)
    with pytest.raises(DataError, match="'mean' is a formula of its parents"):
        p.fit(data)
    formulas = ("P(GE | East)", "P(GN | North)", "P(B | East, North, Fault)")
    fitted = p.fit(data, freeze=formulas)
    params = fitted.estimate.params
    assert params["P(East)"]["mean"].array == pytest.approx(data["East"].mean())
    assert set(params) == {"P(East)", "P(North)", "P(Fault)"}
    # without the Fault column, EM reads the fault from the residual of B, through the
    # frozen formula term: the counts of the draws
    hidden = p.fit(data.drop(columns=["Fault"]),
                   freeze=formulas + ("P(East)", "P(North)"))
    share = float((data["Fault"] == "offset").mean())
    assert hidden.estimate.params["P(Fault)"]["table"].array[1] == pytest.approx(share, abs=2e-3)
    # a real parent missing in some row cannot be integrated out here: said so
    data.loc[3, "East"] = np.nan
    with pytest.raises(DataError, match="uses East in its 'mean'"):
        p.fit(data, freeze=formulas)


def test_a_data_column_of_a_discretised_variable_holds_numbers():
    p = program("""
variables:
  T: {continuous: [-.inf, .inf], discretise: {bins: [10, 15, 20, 25]}}
  Fan: {states: ["on", "off"]}
decomposition:
  - {term: P(T), form: normal, mean: 18, sigma: 4, learn: false}
  - {term: P(Fan | T), form: table, table: [0.5, 0.5]}
""")
    data = {"T": [12.0, 16.0, 21.0, 22.0, "[10, 15)", 30.0], "Fan": ["off", "on", "on", "on",
                                                                      "off", "off"]}
    fitted = p.fit(data).estimate.params["P(Fan | T)"]["table"].array
    # 30 is in the last bin (the outer bins take the tails)
    np.testing.assert_array_equal(fitted, [[0, 1], [1, 0], [2 / 3, 1 / 3]])
    with pytest.raises(DataError, match="'hot' is neither a number"):
        p.fit({"T": ["hot"], "Fan": ["on"]})


# errors at their place --------------------------------------------------------------------------
@pytest.mark.parametrize("mean, message, column", [
    ('"2*X +"', "syntax", None),  # where Python's parser puts it: inside the quotes
    ('"2*Q"', "unknown name 'Q'", 12 + 1 + 2),  # at Q
    ('"__import__(1)"', "function", 12 + 1),  # at the call
    ('"M + X"', "M has named states", 12 + 1),  # at M, which may only be compared
])
def test_a_bad_formula_is_reported_at_its_place(tmp_path, mean, message, column):
    path = tmp_path / "bad.yaml"
    path.write_text(f"""bayesprog: 1
variables:
  M: {{states: [a, b]}}
  X: {{continuous: [-.inf, .inf]}}
  W: {{continuous: [-.inf, .inf]}}
decomposition:
  - {{term: P(M), form: table, table: [0.5, 0.5]}}
  - {{term: P(X), form: normal, mean: 0, sigma: 1}}
  - {{term: "P(W | X, M)", form: normal, sigma: 1,
     mean: {mean}}}
""")
    with pytest.raises(SpecError) as err:
        bayesprog.load(path)
    (diag,) = err.value.diagnostics
    assert diag.line == 10
    if column is None:
        assert 12 < diag.column <= 12 + len(mean)
    else:
        assert diag.column == column
    assert message.lower() in diag.message.lower()


def test_a_real_parent_that_no_parameter_uses_is_refused(tmp_path):
    with pytest.raises(SpecError, match="parent 'X' is real-valued.*discretise"):
        program("""
variables:
  X: {continuous: [-.inf, .inf]}
  A: {states: [a, b]}
decomposition:
  - {term: P(X), form: normal, mean: 0, sigma: 1}
  - {term: P(A | X), form: table, table: [0.5, 0.5]}
""")


def test_a_question_on_both_kinds_is_the_discrete_answer_times_the_real_one():
    p = bayesprog.load(EXAMPLES / "sensor_fusion.yaml")
    joint = p.ask("P(East Fault | GE=1)")
    np.testing.assert_allclose(joint.weights, p.ask("P(Fault | GE=1)").probabilities,
                               atol=1e-12)
    for i, state in enumerate(p.variables["Fault"].states):
        given = p.ask(f"P(East | Fault={state}, GE=1)")
        assert joint.mean("East")[i] == pytest.approx(float(given.mean("East")), abs=1e-12)
        assert joint.sd("East")[i] == pytest.approx(float(given.sd("East")), abs=1e-12)


# the command line -------------------------------------------------------------------------------
def test_query_json_gives_mean_sd_quantiles_map(capsys):
    assert main(["query", str(EXAMPLES / "kalman.yaml"), "filter", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) >= {"mean", "sd", "quantiles", "map"}
    p = bayesprog.load(EXAMPLES / "kalman.yaml")
    d = p.ask("filter")
    assert out["mean"]["X3"] == pytest.approx(float(d.mean("X3")), abs=1e-12)
    assert out["quantiles"]["X3"]["0.5"] == pytest.approx(float(d.mean("X3")), abs=1e-9)


def test_query_prints_a_readable_summary_and_plots(capsys, tmp_path):
    plot = tmp_path / "density.png"
    assert main(["query", str(EXAMPLES / "range_beacon.yaml"), "where", "--plot",
                 str(plot)]) == 0
    out = capsys.readouterr().out
    assert "mean" in out and "sd" in out and "MAP" in out and "grid" in out
    assert plot.stat().st_size > 1000
