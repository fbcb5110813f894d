"""A sub-program whose child is real (``form: program`` over a continuous variable): the term is
the other program's answer, a density, read at the child's value, integrated over its bins,
drawn from. Every answer is checked against the same model worked out by hand with
scipy.stats (closed forms of Gaussians and their mixtures)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

import bayesprog
from bayesprog.errors import QuestionError, SpecError
from bayesprog.inference.density import Density

#: a linear-Gaussian program with a discrete S: Z | S ~ N(mu_S, 1), X | Z ~ N(2 Z + 1, 0.5),
#: so X | S ~ N(2 mu_S + 1, sqrt(4 + 0.25))
LINEAR = """\
bayesprog: 1
name: linear
variables:
  S: {states: [a, b]}
  Z: {continuous: [-.inf, .inf]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: uniform}
  - {term: P(Z | S), form: normal, mean: {a: 0.0, b: 3.0}, sigma: 1.0}
  - {term: P(X | Z), form: normal, mean: "2*Z + 1", sigma: 0.5}
questions:
  x_given_s: P(X | S)
"""
LINEAR_MEAN, LINEAR_SD = np.array([1.0, 7.0]), np.sqrt(4.25)

#: a mixture: X | H = sum_k P(k | H) N(mu_k, s_k)
MIXTURE = """\
bayesprog: 1
name: mixture
variables:
  H: {states: [h0, h1]}
  K: {states: [k1, k2, k3]}
  X: {continuous: [-10, 10]}
decomposition:
  - {term: P(H), form: uniform}
  - {term: P(K | H), form: table, table: {h0: [0.2, 0.5, 0.3], h1: [0.6, 0.1, 0.3]}}
  - term: P(X | K)
    form: normal
    mean: {k1: -2.0, k2: 0.5, k3: 4.0}
    sigma: {k1: 0.7, k2: 1.2, k3: 0.4}
questions:
  x_given_h: P(X | H)
  x: P(X)
"""
WEIGHTS = np.array([[0.2, 0.5, 0.3], [0.6, 0.1, 0.3]])
MEANS, SDS = np.array([-2.0, 0.5, 4.0]), np.array([0.7, 1.2, 0.4])

#: X | S, G ~ N(G, 1.5) for S = a, N(2 G + 3, 1.5) for S = b, with G a real known variable
GAIN = """\
bayesprog: 1
name: gain
variables:
  S: {states: [a, b]}
  G: {continuous: [-.inf, .inf]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: uniform}
  - {term: P(G), form: normal, mean: 0, sigma: 1}
  - {term: "P(X | S, G)", form: normal, mean: {a: "G", b: "2*G + 3"}, sigma: 1.5}
questions:
  x: P(X | S, G)
"""


def _mixture_pdf(x: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """sum_k w_k N(x; mu_k, s_k) at ``x`` [..., 1] for weights [..., K]."""
    return (weights * stats.norm.pdf(x, MEANS, SDS)).sum(-1)


def _write(folder, **files):
    for name, text in files.items():
        (folder / f"{name}.yaml").write_text(text)


def _load(folder, text, **files):
    _write(folder, **files)
    (folder / "caller.yaml").write_text(text)
    return bayesprog.load(folder / "caller.yaml")


def _posterior(joint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised rows of ``joint`` and the log of their sums."""
    total = joint.sum(-1, keepdims=True)
    return joint / total, np.log(total[..., 0])


# the term read at the value of its child ------------------------------------------------------
def test_a_linear_gaussian_answer_is_the_density_of_a_term_over_a_discrete_parent(tmp_path):
    caller = _load(tmp_path, """\
bayesprog: 1
variables:
  S: {states: [a, b]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: table, table: [0.3, 0.7]}
  - {term: P(X | S), form: program, program: linear.yaml, question: x_given_s}
""", linear=LINEAR)
    x = np.array([0.5, 4.0, 7.0, -30.0])
    answer = caller.ask("P(S | X)", {"X": x})
    joint = np.array([0.3, 0.7]) * stats.norm.pdf(x[:, None], LINEAR_MEAN, LINEAR_SD)
    probabilities, log_evidence = _posterior(joint)
    np.testing.assert_allclose(answer.probabilities, probabilities, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, log_evidence, rtol=1e-12)
    # the sub-program's own answer, asked directly, is the same density
    direct = bayesprog.load(tmp_path / "linear.yaml").ask("x_given_s", {"S": ["a", "b"]})
    np.testing.assert_allclose(direct.mean("X"), LINEAR_MEAN, rtol=1e-12)


def test_a_known_variable_of_the_sub_question_bound_to_a_batched_input_or_a_literal(tmp_path):
    _write(tmp_path, gain=GAIN)
    term = "{term: P(X | S), form: program, program: gain.yaml, question: x, bind: {G: %s}}"
    head = ("bayesprog: 1\nvariables:\n  S: {states: [a, b]}\n  X: {continuous: [-.inf, .inf]}"
            "\ninputs:\n  g: {}\ndecomposition:\n  - {term: P(S), form: table, table: [0.4, "
            "0.6]}\n  - ")
    g, x = np.array([0.0, 1.0, -2.0]), np.array([0.5, 4.0, 1.0])
    by_input = bayesprog.loads(head + term % "{input: g}", str(tmp_path / "a.yaml"), tmp_path)
    answer = by_input.ask("P(S | X)", {"X": x}, inputs={"g": g})
    joint = np.stack([0.4 * stats.norm.pdf(x, g, 1.5), 0.6 * stats.norm.pdf(x, 2 * g + 3, 1.5)],
                     -1)
    probabilities, log_evidence = _posterior(joint)
    np.testing.assert_allclose(answer.probabilities, probabilities, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, log_evidence, rtol=1e-12)
    literal = bayesprog.loads(head + term % "1.0", str(tmp_path / "b.yaml"), tmp_path)
    answer = literal.ask("P(S | X)", {"X": x})
    joint = np.stack([0.4 * stats.norm.pdf(x, 1.0, 1.5), 0.6 * stats.norm.pdf(x, 5.0, 1.5)], -1)
    np.testing.assert_allclose(answer.probabilities, _posterior(joint)[0], rtol=0, atol=1e-12)


def test_an_observed_discrete_parent_in_a_batch_reads_its_own_row_of_the_answer(tmp_path):
    caller = _load(tmp_path, """\
bayesprog: 1
variables:
  S: {states: [a, b]}
  D: {states: [d0, d1]}
  X: {continuous: [-.inf, .inf]}
  Y: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: table, table: [0.3, 0.7]}
  - {term: P(D), form: table, table: [0.5, 0.5]}
  - {term: P(X | S), form: program, program: linear.yaml, question: x_given_s}
  - {term: "P(Y | X, D)", form: normal, mean: {d0: "X", d1: "X + 2"}, sigma: 0.5}
""", linear=LINEAR)
    s, x, y = np.array(["b", "a", "b"]), np.array([6.0, 0.0, 8.0]), np.array([6.5, 2.5, 8.0])
    answer = caller.ask("P(D | S, X, Y)", {"S": s, "X": x, "Y": y})
    mean = np.where(s == "a", LINEAR_MEAN[0], LINEAR_MEAN[1])
    prior = np.where(s == "a", 0.3, 0.7) * stats.norm.pdf(x, mean, LINEAR_SD)
    joint = 0.5 * stats.norm.pdf(y[:, None], x[:, None] + [0.0, 2.0], 0.5)
    probabilities, log_evidence = _posterior(joint)
    np.testing.assert_allclose(answer.probabilities, probabilities, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, log_evidence + np.log(prior), rtol=1e-12)


def test_a_real_parent_passes_its_value_to_the_sub_question(tmp_path):
    caller = _load(tmp_path, """\
bayesprog: 1
variables:
  S: {states: [a, b]}
  G: {continuous: [-.inf, .inf]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: table, table: [0.4, 0.6]}
  - {term: P(G), form: normal, mean: 1, sigma: 2}
  - {term: "P(X | S, G)", form: program, program: gain.yaml, question: x}
""", gain=GAIN)
    g, x = np.array([0.0, 1.0, -2.0]), np.array([0.5, 4.0, 1.0])
    answer = caller.ask("P(S | X, G)", {"X": x, "G": g})
    joint = np.stack([0.4 * stats.norm.pdf(x, g, 1.5), 0.6 * stats.norm.pdf(x, 2 * g + 3, 1.5)],
                     -1)
    probabilities, log_evidence = _posterior(joint)
    np.testing.assert_allclose(answer.probabilities, probabilities, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, log_evidence + stats.norm.logpdf(g, 1, 2),
                               rtol=1e-12)


def test_a_discretised_parent_passes_its_bins_midpoint_to_a_real_variable_there(tmp_path):
    caller = _load(tmp_path, """\
bayesprog: 1
variables:
  S: {states: [a, b]}
  G: {continuous: [-2, 4], discretise: {bins: [-2, 0, 2, 4]}}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: table, table: [0.4, 0.6]}
  - {term: P(G), form: uniform}
  - {term: "P(X | S, G)", form: program, program: gain.yaml, question: x}
""", gain=GAIN)
    x = np.array([0.5, 4.0])
    answer = caller.ask("P(S | X, G)", {"X": x, "G": [0.7, -1.5]})
    g = np.array([1.0, -1.0])  # the midpoints of [0, 2) and [-2, 0)
    joint = np.stack([0.4 * stats.norm.pdf(x, g, 1.5), 0.6 * stats.norm.pdf(x, 2 * g + 3, 1.5)],
                     -1)
    np.testing.assert_allclose(answer.probabilities, _posterior(joint)[0], rtol=0, atol=1e-12)
    # G unknown: the three bins, equally likely, each passing its midpoint
    mids = np.array([-1.0, 1.0, 3.0])
    joint = np.array([0.4 * stats.norm.pdf(0.5, mids, 1.5).mean(),
                      0.6 * stats.norm.pdf(0.5, 2 * mids + 3, 1.5).mean()])
    np.testing.assert_allclose(caller.ask("P(S | X=0.5)").probabilities, _posterior(joint)[0],
                               rtol=0, atol=1e-12)


def test_an_unknown_real_parent_is_summed_out_on_the_grid(tmp_path):
    caller = _load(tmp_path, """\
bayesprog: 1
variables:
  S: {states: [a, b]}
  G: {continuous: [-10, 10]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: table, table: [0.4, 0.6]}
  - {term: P(G), form: normal, mean: 1, sigma: 2}
  - {term: "P(X | S, G)", form: program, program: gain.yaml, question: x}
""", gain=GAIN)
    answer = caller.ask("P(S | X=1.0)")
    assert answer.method == "grid"
    # G ~ N(1, 2), its mass beyond [-10, 10] (3.4e-6) left out: X | S=a ~ N(1, sqrt(4 +
    # 2.25)), X | S=b ~ N(5, sqrt(16 + 2.25))
    joint = np.array([0.4 * stats.norm.pdf(1.0, 1.0, np.sqrt(6.25)),
                      0.6 * stats.norm.pdf(1.0, 5.0, np.sqrt(18.25))])
    error = np.abs(answer.probabilities - _posterior(joint)[0])
    assert np.all(error <= answer.error), (error, answer.error)
    assert np.all(error < 1e-4)


def test_a_mixture_answer_is_the_term_and_the_evidence_is_the_mixture_density(tmp_path):
    caller = _load(tmp_path, """\
bayesprog: 1
variables:
  H: {states: [h0, h1]}
  X: {continuous: [-10, 10]}
decomposition:
  - {term: P(H), form: table, table: [0.25, 0.75]}
  - {term: P(X | H), form: program, program: mixture.yaml, question: x_given_h}
""", mixture=MIXTURE)
    x = np.array([0.5, 4.0, -2.0, 9.0])
    answer = caller.ask("P(H | X)", {"X": x})
    joint = np.array([0.25, 0.75]) * _mixture_pdf(x[:, None, None], WEIGHTS)
    probabilities, log_evidence = _posterior(joint)
    np.testing.assert_allclose(answer.probabilities, probabilities, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, log_evidence, rtol=1e-12)


def test_a_term_without_parents_takes_the_sub_programs_marginal_density(tmp_path):
    caller = _load(tmp_path, """\
bayesprog: 1
variables:
  X: {continuous: [-10, 10]}
  D: {states: [d0, d1]}
  Y: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(X), form: program, program: mixture.yaml, question: x}
  - {term: P(D), form: table, table: [0.9, 0.1]}
  - {term: "P(Y | X, D)", form: normal, mean: {d0: "X", d1: "X + 2"}, sigma: 0.5}
""", mixture=MIXTURE)
    x, y = np.array([0.5, 4.0, -2.0]), np.array([1.0, 6.5, -2.2])
    answer = caller.ask("P(D | X, Y)", {"X": x, "Y": y})
    joint = np.array([0.9, 0.1]) * stats.norm.pdf(y[:, None], x[:, None] + [0.0, 2.0], 0.5)
    probabilities, log_evidence = _posterior(joint)
    # the sub-program's P(X): its prior over H is uniform, so the weights are the rows' mean
    marginal = _mixture_pdf(x[:, None], WEIGHTS.mean(0))
    np.testing.assert_allclose(answer.probabilities, probabilities, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, log_evidence + np.log(marginal),
                               rtol=1e-12)


def test_a_value_far_in_a_tail_keeps_its_log_density(tmp_path):
    """Where every component's density underflows, the term keeps its logarithm: the
    posterior is that of the nearest component, not 0/0."""
    caller = _load(tmp_path, """\
bayesprog: 1
variables:
  S: {states: [a, b]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: table, table: [0.3, 0.7]}
  - {term: P(X | S), form: program, program: linear.yaml, question: x_given_s}
""", linear=LINEAR)
    answer = caller.ask("P(S | X=200)")
    log_joint = np.log([0.3, 0.7]) + stats.norm.logpdf(200.0, LINEAR_MEAN, LINEAR_SD)
    assert np.all(stats.norm.pdf(200.0, LINEAR_MEAN, LINEAR_SD) == 0)  # (the density itself)
    expected = np.exp(log_joint - np.logaddexp.reduce(log_joint))
    np.testing.assert_allclose(answer.probabilities, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, np.logaddexp.reduce(log_joint), rtol=1e-12)


# bins: a discretised child, and the grid method ------------------------------------------------
def test_a_discretised_child_takes_the_probability_of_each_bin_from_the_sub_programs_cdf(
        tmp_path):
    caller = _load(tmp_path, """\
bayesprog: 1
variables:
  S: {states: [a, b]}
  X: {continuous: [-.inf, .inf], discretise: {bins: [-1, 1, 3, 5]}}
  F: {states: ["on", "off"]}
decomposition:
  - {term: P(S), form: table, table: [0.3, 0.7]}
  - {term: P(X | S), form: program, program: linear.yaml, question: x_given_s}
  - term: P(F | X)
    form: table
    table: {"[-1, 1)": [0.1, 0.9], "[1, 3)": [0.5, 0.5], "[3, 5]": [0.9, 0.1]}
""", linear=LINEAR)
    edges = np.array([-np.inf, 1.0, 3.0, np.inf])  # the outer bins take the tails
    bins = np.diff(stats.norm.cdf(edges[:, None], LINEAR_MEAN, LINEAR_SD), axis=0).T  # [S, X]
    answer = caller.ask("P(X | S)", {"S": ["a", "b"]})
    np.testing.assert_allclose(answer.probabilities, bins, rtol=0, atol=1e-12)
    on = np.array([0.1, 0.5, 0.9])
    joint = np.array([0.3, 0.7]) * (bins @ on)
    np.testing.assert_allclose(caller.ask("P(S | F=on)").probabilities, _posterior(joint)[0],
                               rtol=0, atol=1e-12)


MIXTURE_CALLER = """\
bayesprog: 1
variables:
  H: {states: [h0, h1]}
  X: {continuous: [-10, 10]}
  Y: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(H), form: table, table: [0.25, 0.75]}
  - {term: P(X | H), form: program, program: mixture.yaml, question: x_given_h}
  - {term: P(Y | X), form: normal, mean: "X + 1", sigma: 0.5}
"""


def _unknown_x_posterior(y: float) -> np.ndarray:
    """P(H | Y=y) with X summed out: each component convolved with the noise of Y (the tails
    beyond [-10, 10] are below 1e-40 of the mass)."""
    likelihood = (WEIGHTS * stats.norm.pdf(y, MEANS + 1, np.sqrt(SDS**2 + 0.25))).sum(-1)
    return _posterior(np.array([0.25, 0.75]) * likelihood)[0]


def test_the_grid_method_answers_an_unknown_real_child_within_its_error(tmp_path):
    caller = _load(tmp_path, MIXTURE_CALLER, mixture=MIXTURE)
    answer = caller.ask("P(H | Y=2.0)", method="grid")
    expected = _unknown_x_posterior(2.0)
    error = np.abs(answer.probabilities - expected)
    # the answer on 256 bins is closer than its estimated error (the change from 128 bins)
    assert np.all(error <= answer.error), (error, answer.error)
    assert np.all(error < 1e-3)


def test_the_gaussian_method_names_the_term_and_the_methods_that_use_it(tmp_path):
    caller = _load(tmp_path, MIXTURE_CALLER, mixture=MIXTURE)
    with pytest.raises(QuestionError) as caught:
        caller.ask("P(H | Y=2.0)", method="gaussian")
    message = str(caught.value)
    assert "P(X | H) is another program's answer" in message
    assert "grid method" in message and "'lw'" in message


# draws -----------------------------------------------------------------------------------------
def test_likelihood_weighting_draws_an_unknown_child_from_the_sub_program(tmp_path):
    caller = _load(tmp_path, MIXTURE_CALLER, mixture=MIXTURE)
    answer = caller.ask("P(H | Y=2.0)", method="lw", samples=40_000, rng=3)
    # a fixed seed; the answer is within 5 standard errors (a false failure once in 1.7
    # million seeds)
    error = np.abs(answer.probabilities - _unknown_x_posterior(2.0))
    assert np.all(error <= 5 * answer.stderr), (error, answer.stderr)


def test_forward_draws_follow_the_sub_programs_mixture(tmp_path):
    caller = _load(tmp_path, MIXTURE_CALLER, mixture=MIXTURE)
    draws = caller.sample(4000, rng=11)
    for h, weights in zip(("h0", "h1"), WEIGHTS, strict=True):
        x = draws.X[draws.H == h].to_numpy()

        def cdf(v, weights=weights):
            return (weights * stats.norm.cdf(np.asarray(v)[:, None], MEANS, SDS)).sum(-1)

        # a fixed seed; Kolmogorov-Smirnov at 1e-3 (a false failure once in a thousand seeds)
        assert stats.kstest(x, cdf).pvalue > 1e-3
    assert abs((draws.H == "h0").mean() - 0.25) < 4 * np.sqrt(0.25 * 0.75 / 4000)


def test_draws_inside_a_bounded_support_follow_the_truncated_answer(tmp_path):
    """The sub-program answers N(1, sqrt(4.25)) for S = a, untruncated; a child declared on
    [0, 2] (there and here) is drawn from that density renormalised on [0, 2]."""
    bounded = LINEAR.replace("X: {continuous: [-.inf, .inf]}", "X: {continuous: [0, 2]}")
    caller = _load(tmp_path, """\
bayesprog: 1
variables:
  S: {states: [a, b]}
  X: {continuous: [0, 2]}
decomposition:
  - {term: P(S), form: table, table: [1.0, 0.0]}
  - {term: P(X | S), form: program, program: linear.yaml, question: x_given_s}
""", linear=bounded)
    x = caller.sample(3000, rng=5).X.to_numpy()
    assert x.min() >= 0 and x.max() <= 2
    low, high = (np.array([0.0, 2.0]) - 1.0) / LINEAR_SD
    truncated = stats.truncnorm(low, high, loc=1.0, scale=LINEAR_SD)
    # a fixed seed; Kolmogorov-Smirnov at 1e-3 (a false failure once in a thousand seeds)
    assert stats.kstest(x, truncated.cdf).pvalue > 1e-3


def test_a_real_parent_drawn_passes_each_draw_to_the_sub_question(tmp_path):
    caller = _load(tmp_path, """\
bayesprog: 1
variables:
  S: {states: [a, b]}
  G: {continuous: [-.inf, .inf]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: table, table: [0.4, 0.6]}
  - {term: P(G), form: normal, mean: 1, sigma: 2}
  - {term: "P(X | S, G)", form: program, program: gain.yaml, question: x}
""", gain=GAIN)
    draws = caller.sample(4000, rng=2)
    # X - G | S=a ~ N(0, 1.5) and X - 2 G | S=b ~ N(3, 1.5), whatever G was drawn
    a, b = draws[draws.S == "a"], draws[draws.S == "b"]
    # a fixed seed; Kolmogorov-Smirnov at 1e-3 (a false failure once in a thousand seeds)
    assert stats.kstest((a.X - a.G).to_numpy(), stats.norm(0, 1.5).cdf).pvalue > 1e-3
    assert stats.kstest((b.X - 2 * b.G).to_numpy(), stats.norm(3, 1.5).cdf).pvalue > 1e-3
    assert stats.kstest(draws.G.to_numpy(), stats.norm(1, 2).cdf).pvalue > 1e-3


def test_a_child_whose_term_binds_a_field_is_read_but_not_drawn(tmp_path):
    """An input of one value per state of the parent V, bound to a field of the sub-program
    over V: the term reads the sub-program's answer at a known X; a draw of X, which would
    take the field's value at the drawn V alone, is refused."""
    caller = _load(tmp_path, """\
bayesprog: 1
variables:
  V: {states: [v1, v2]}
  X: {continuous: [-.inf, .inf]}
inputs:
  errors: {shape: [V]}
decomposition:
  - {term: P(V), form: table, table: [0.4, 0.6]}
  - term: P(X | V)
    form: program
    program: field.yaml
    question: "P(X | V, L)"
    bind: {L: {input: errors}}
""", field="""\
bayesprog: 1
variables:
  V: {states: [v1, v2]}
  L: {continuous: [0, 1], indexed_by: V}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(V), form: uniform}
  - {term: P(L | V), form: beta, a: 1, b: 3}
  - {term: P(X | V), form: normal, mean: {v1: 0.0, v2: 2.0}, sigma: 1.0}
""")
    answer = caller.ask("P(V | X=1.5)", inputs={"errors": [0.2, 0.4]})
    joint = np.array([0.4, 0.6]) * stats.norm.pdf(1.5, [0.0, 2.0], 1.0)
    np.testing.assert_allclose(answer.probabilities, _posterior(joint)[0], rtol=0, atol=1e-12)
    with pytest.raises(QuestionError, match="X cannot be drawn from field.yaml: the term binds "
                       "the input 'errors', one value per state, to a field of it; give X as "
                       "evidence"):
        caller.sample(3, inputs={"errors": [0.2, 0.4]})


def test_the_command_line_answers_with_a_sub_programs_density(tmp_path, capsys):
    from bayesprog.cli import main

    _load(tmp_path, """\
bayesprog: 1
variables:
  S: {states: [a, b]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: table, table: [0.3, 0.7]}
  - {term: P(X | S), form: program, program: linear.yaml, question: x_given_s}
""", linear=LINEAR)
    assert main(["query", str(tmp_path / "caller.yaml"), "P(S | X=4.5)", "--json"]) == 0
    answer = json.loads(capsys.readouterr().out)
    joint = np.array([0.3, 0.7]) * stats.norm.pdf(4.5, LINEAR_MEAN, LINEAR_SD)
    np.testing.assert_allclose(answer["probabilities"], _posterior(joint)[0], rtol=1e-12)
    assert main(["query", str(tmp_path / "caller.yaml"), "P(X | S=a)"]) == 2
    assert "P(X | S) is another program's answer" in capsys.readouterr().err


# the file's problems ---------------------------------------------------------------------------
@pytest.mark.parametrize(("declared", "found"), [
    ("S2: {states: [a, b]}", "found it discrete"),
    ("S2: {continuous: [0, 1]}", "found it on [0, 1]"),
])
def test_a_real_child_needs_a_real_variable_of_the_same_support_there(tmp_path, declared, found):
    sub = LINEAR.replace("X: {continuous: [-.inf, .inf]}", declared.replace("S2", "X"))
    sub = sub.replace("  - {term: P(X | Z), form: normal, mean: \"2*Z + 1\", sigma: 0.5}\n",
                      "  - {term: P(X), form: uniform}\n")
    with pytest.raises(SpecError) as caught:
        _load(tmp_path, """\
bayesprog: 1
variables:
  S: {states: [a, b]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: uniform}
  - {term: P(X | S), form: program, program: linear.yaml, question: x_given_s}
""", linear=sub)
    text = str(caught.value)
    assert "caller.yaml:7:" in text
    assert "variable 'X' is real here: expected it real on [-inf, inf] in 'linear.yaml'" in text
    assert found in text


def test_binding_a_parent_of_the_term_is_refused(tmp_path):
    with pytest.raises(SpecError) as caught:
        _load(tmp_path, """\
bayesprog: 1
variables:
  S: {states: [a, b]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(S), form: uniform}
  - {term: P(X | S), form: program, program: linear.yaml, question: x_given_s, bind: {S: a}}
""", linear=LINEAR)
    assert ("caller.yaml:7:5: term P(X | S): program: bind: 'S' is a parent of the term: the "
            "sub-question takes its value from this program's S") in str(caught.value)


def test_a_real_parent_needs_a_real_variable_there(tmp_path):
    with pytest.raises(SpecError) as caught:
        _load(tmp_path, """\
bayesprog: 1
variables:
  Z: {continuous: [-.inf, .inf]}
  X: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(Z), form: normal, mean: 0, sigma: 1}
  - {term: P(X | Z), form: program, program: gain.yaml, question: "P(X | S, G)"}
""", gain=GAIN.replace("S: {states: [a, b]}", "S: {states: [a, b]}\n  Z: {states: [z]}")
                .replace("  - {term: P(S), form: uniform}", "  - {term: P(S), form: uniform}\n"
                         "  - {term: P(Z), form: uniform}"))
    assert "variable 'Z' is real here: expected it real in 'gain.yaml' too" in str(
        caught.value)


# the density read one point per row ------------------------------------------------------------
def test_a_mixtures_log_density_cdf_and_quantile_at_a_point_per_row():
    weights = np.array([[0.2, 0.5, 0.3], [1.0, 0.0, 0.0]])
    density = Density("P(X | H)", ("X",), (2,), np.zeros(2), weights=weights,
                      means=np.broadcast_to(MEANS[:, None], (2, 3, 1)).copy(),
                      covariances=np.broadcast_to((SDS**2)[:, None, None], (2, 3, 1, 1)).copy())
    rows = np.array([0, 1, 0, 1, 1])
    x = np.array([0.3, -2.5, 4.1, 3.0, -40.0])
    with np.errstate(divide="ignore"):
        expected = np.log((weights[rows] * stats.norm.pdf(x[:, None], MEANS, SDS)).sum(-1))
    expected[-1] = stats.norm.logpdf(-40.0, -2.0, 0.7)  # (where the density underflows)
    np.testing.assert_allclose(density.log_pdf_at("X", x, rows), expected, rtol=1e-12)
    cdf = (weights[rows] * stats.norm.cdf(x[:, None], MEANS, SDS)).sum(-1)
    np.testing.assert_allclose(density.cdf_at("X", x, rows), cdf, rtol=1e-12, atol=1e-300)
    q = np.array([0.01, 0.5, 0.9, 0.999, 0.3])
    found = density.quantile_at("X", q, rows)
    np.testing.assert_allclose(found[[1, 3, 4]], stats.norm.ppf(q[[1, 3, 4]], -2.0, 0.7),
                               rtol=1e-12)
    np.testing.assert_allclose(density.cdf_at("X", found, rows), q, rtol=1e-12)


def test_bins_log_density_cdf_and_quantile_at_a_point_per_row():
    edges = np.array([0.0, 1.0, 3.0, 4.0])
    masses = np.array([[0.25, 0.5, 0.25], [0.5, 0.0, 0.5]])
    density = Density("P(X | H)", ("X",), (2,), np.zeros(2), edges={"X": edges}, masses=masses)
    rows = np.array([0, 0, 1, 1, 0])
    x = np.array([0.5, 2.0, 2.0, 3.5, 5.0])
    with np.errstate(divide="ignore"):
        expected = np.log([0.25, 0.25, 0.0, 0.5, 0.0])  # mass / width, nothing outside
    np.testing.assert_array_equal(density.log_pdf_at("X", x, rows), expected)
    np.testing.assert_allclose(density.cdf_at("X", x, rows), [0.125, 0.5, 0.5, 0.75, 1.0],
                               rtol=1e-15)
    q = np.array([0.125, 0.5, 0.5, 0.75, 1.0])
    # row 1's empty bin holds no quantile: 0.5 is the end of its first bin
    np.testing.assert_allclose(density.quantile_at("X", q, rows), [0.5, 2.0, 1.0, 3.5, 4.0],
                               rtol=1e-15)
