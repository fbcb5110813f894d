"""Every approximate answer names its method and says what its +- is, in the text output and in
``--json``: a standard error (likelihood weighting, Gibbs sampling), an estimated bound of its
error (the grid, never called a standard error), or none (loopy belief propagation, the
particle filter and smoother, estimates shown without a +-)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate, stats

import bayesprog
from bayesprog.cli import main

EXAMPLES = Path(__file__).parents[1] / "models" / "examples"
SPRINKLER = str(EXAMPLES / "sprinkler.yaml")
UMBRELLA = str(EXAMPLES / "umbrella.yaml")

# a discrete question whose unknown real variable is not linear-Gaussian: answered on a grid
BUMPY = """\
bayesprog: 1
name: bumpy
variables:
  D: {states: [near, far]}
  X: {continuous: [0, 1]}
  Y: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(D), form: table, table: [0.4, 0.6]}
  - {term: P(X | D), form: beta, a: {near: 2.0, far: 5.0}, b: 3.0}
  - {term: P(Y | X), form: normal, mean: "sin(6*X)", sigma: 0.5}
"""

CART = """\
bayesprog: 1
name: cart
variables:
  X_before: {continuous: [-.inf, .inf]}
  X: {continuous: [-.inf, .inf]}
  Y: {continuous: [-.inf, .inf]}
time:
  previous: {X_before: X}
decomposition:
  - {term: P(X_before), form: normal, mean: 0.0, sigma: 1.0}
  - {term: P(X | X_before), form: normal, mean: "0.9*X_before + 0.5", sigma: 0.3}
  - {term: P(Y | X), form: normal, mean: "2*X", sigma: 0.5}
"""


def query(capsys, *args: str) -> tuple[str, dict]:
    """The text output and the ``--json`` output of ``bayesprog query ARGS``."""
    assert main(["query", *args]) == 0
    text = capsys.readouterr().out
    assert main(["query", *args, "--json"]) == 0
    return text, json.loads(capsys.readouterr().out)


@pytest.fixture
def bumpy(tmp_path) -> str:
    path = tmp_path / "bumpy.yaml"
    path.write_text(BUMPY)
    return str(path)


@pytest.fixture
def cart(tmp_path) -> str:
    path = tmp_path / "cart.yaml"
    path.write_text(CART)
    return str(path)


@pytest.mark.parametrize(("method", "header"), [
    ("lw", "(likelihood weighting: +- one standard error)"),
    ("gibbs", "(Gibbs sampling: +- one standard error, from batch means)"),
])
def test_sampling_answers_give_standard_errors(capsys, method, header):
    text, data = query(capsys, SPRINKLER, "P(Rain | Grass=wet)", "--method", method,
                       "--samples", "3000", "--seed", "2")
    first = text.splitlines()[0]
    assert first == f"P(Rain | Grass=wet)   {header}"
    stderr = data["stderr"]
    for row, error in zip(text.splitlines()[2:4], stderr, strict=True):
        assert row.endswith(f"+- {error:.2g}")
    assert data["method"] == method and data["uncertainty"] == "stderr"
    assert "error" not in data
    # the standard error is that of the estimate: the exact answer within 4.5 of them
    exact = bayesprog.load(SPRINKLER).ask("P(Rain | Grass=wet)").probabilities
    assert np.all(np.abs(np.array(data["probabilities"]) - exact) <= 4.5 * np.array(stderr)
                  + (0.01 if method == "gibbs" else 0))


def exact_bumpy(y: float) -> np.ndarray:
    """P(D | Y=y) by numerical integration over X."""
    prior, a = np.array([0.4, 0.6]), (2.0, 5.0)
    joint = np.array([p * integrate.quad(lambda x, a=ai: stats.beta(a, 3.0).pdf(x)
                                         * stats.norm(np.sin(6 * x), 0.5).pdf(y), 0, 1,
                                         epsabs=1e-13)[0]
                      for p, ai in zip(prior, a, strict=True)])
    return joint / joint.sum()


def test_a_grid_answer_gives_a_bound_not_a_standard_error(capsys, bumpy):
    text, data = query(capsys, bumpy, "P(D | Y=0.3)", "--bins", "16")
    assert text.splitlines()[0] == (
        "P(D | Y=0.3)   (on a grid of 32 bins for X: +- an estimated bound of the "
        "discretisation error, the change from 16 bins)")
    assert data["method"] == "grid" and data["uncertainty"] == "bound"
    assert "stderr" not in data and data["bins"] == {"X": 32}
    error = np.array(data["error"])
    for row, e in zip(text.splitlines()[2:4], error, strict=True):
        assert row.endswith(f"+- {e:.2g}")
    # a bound: the error of the answer against numerical integration is within it
    assert np.all(np.abs(np.array(data["probabilities"]) - exact_bumpy(0.3)) <= error)
    answer = bayesprog.load(bumpy).ask("P(D | Y=0.3)", bins=16)
    assert answer.stderr is None and answer.uncertainty == "bound"
    np.testing.assert_array_equal(answer.error, error)


def test_a_grid_density_gives_its_bound_in_json(capsys):
    text, data = query(capsys, str(EXAMPLES / "range_beacon.yaml"), "where")
    assert "on a grid of 256 bins for X: +- an estimated bound of the discretisation error, " \
           "the change from 128 bins" in text.splitlines()[0]
    assert data["method"] == "grid" and data["uncertainty"] == "bound" and "error" in data
    assert "stderr" not in data


def test_loopy_belief_propagation_says_it_has_no_error_estimate(capsys):
    text, data = query(capsys, SPRINKLER, "P(Rain | Grass=wet)", "--method", "lbp")
    assert text.splitlines()[0].startswith("P(Rain | Grass=wet)   (loopy belief propagation: ")
    assert text.splitlines()[0].endswith("; no error estimate)")
    assert "+-" not in text
    assert data["method"] == "lbp" and "uncertainty" not in data and "stderr" not in data


@pytest.mark.parametrize(("kind", "method", "header"), [
    ("filter", "pf", "(particle filter: the particles' moments, no error estimate)"),
    ("smooth", "pf-smooth",
     "(particle smoother (FFBSm): the particles' moments, no error estimate)"),
])
def test_particle_answers_name_their_method(capsys, cart, kind, method, header):
    text, data = query(capsys, cart, "P(X | Y)", "--over-time", kind, "--method", "pf",
                       "--samples", "300", "--evidence", "Y=1.0,2.1")
    assert text.splitlines()[0].endswith(header)
    assert data["method"] == method and "uncertainty" not in data and "stderr" not in data


def test_exact_answers_say_nothing_of_an_error(capsys, cart):
    text, data = query(capsys, SPRINKLER, "P(Rain | Grass=wet)")
    assert text.splitlines()[0] == "P(Rain | Grass=wet)" and "+-" not in text
    assert "uncertainty" not in data and "stderr" not in data and "error" not in data
    text, data = query(capsys, cart, "P(X | Y)", "--over-time", "filter", "--evidence",
                       "Y=1.0,2.1")
    assert text.splitlines()[0].endswith("(exact, Kalman filter)")
    assert "uncertainty" not in data


def test_a_map_of_an_approximate_posterior_gives_its_standard_error(capsys):
    text, data = query(capsys, SPRINKLER, "P(Rain | Grass=wet)", "--map", "--method", "lw",
                       "--samples", "3000")
    assert text.splitlines()[0] == ("MAP of P(Rain | Grass=wet)   (likelihood weighting: +- "
                                    "one standard error)")
    chosen = ["rain", "dry"].index(data["map"]["Rain"])
    assert text.splitlines()[1].endswith(f"+- {data['stderr'][chosen]:.2g}")
    assert data["uncertainty"] == "stderr"


def test_estimates_without_an_error_say_so(capsys, bumpy):
    text, data = query(capsys, SPRINKLER, "P(Rain=rain | Grass=wet)", "--method", "lw",
                       "--samples", "3000")
    assert text.splitlines()[0] == ("P(Rain=rain | Grass=wet)   (likelihood weighting: an "
                                    "estimate, no error given)")
    assert data["method"] == "lw"
    text, data = query(capsys, bumpy, "P(D X | Y=0.3)", "--bins", "16")
    assert text.splitlines()[0] == ("P(D X | Y=0.3)   (discrete and real together; D: on a "
                                    "grid, X: on a grid, no error given)")
    assert data["method"] == "mixed" and data["methods"] == {"discrete": "grid", "real": "grid"}
    text, data = query(capsys, UMBRELLA, "today", "--evidence", "Umbrella=yes,no", "--method",
                       "lw", "--samples", "500")
    assert text.splitlines()[0].endswith("(each step by likelihood weighting: no error "
                                         "estimate)")
    assert data["method"] == "filter" and data["steps_method"] == "lw"
    text, data = query(capsys, UMBRELLA, "most_likely", "--evidence", "Umbrella=yes,no",
                       "--method", "lw", "--samples", "500")
    assert text.splitlines()[0].endswith("(each step by likelihood weighting: no error "
                                         "estimate)")
    assert data["method"] == "sequence" and data["steps_method"] == "lw"


def test_the_most_likely_sequence_refuses_a_method_that_estimates_no_evidence(capsys):
    assert main(["query", UMBRELLA, "most_likely", "--evidence", "Umbrella=yes,no",
                 "--method", "gibbs", "--samples", "300"]) == 2
    err = capsys.readouterr().err
    assert "method 'gibbs' does not estimate the probability of evidence, which the most " \
           "likely sequence needs" in err
