"""The log-normal form (bayesprog/forms/lognormal.py), a form added as one class: its density,
CDF, draws and maximum-likelihood fit against scipy.stats.lognorm."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import stats
from scipy.special import logsumexp, softmax

import bayesprog

PROGRAM = """\
bayesprog: 1
variables:
  Q: {states: [fine, medium, coarse]}
  D: {continuous: [0, .inf]}
decomposition:
  - {term: P(Q), form: uniform}
  - {term: P(D | Q), form: lognormal, mu: {fine: MU0, medium: MU1, coarse: MU2}, sigma: SIGMA}
"""


def program(mus, sigma) -> bayesprog.Program:
    text = PROGRAM.replace("SIGMA", repr(float(sigma)))
    for i, mu in enumerate(mus):
        text = text.replace(f"MU{i}", repr(float(mu)))
    return bayesprog.loads(text)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mus=st.lists(st.floats(-2, 2), min_size=3, max_size=3), sigma=st.floats(0.1, 2),
       xs=st.lists(st.floats(1e-3, 20), min_size=1, max_size=5))
def test_the_density_is_scipys(mus, sigma, xs):
    x = np.array(xs)
    answer = program(mus, sigma).ask("P(Q | D)", {"D": x})
    log_lik = stats.lognorm.logpdf(x[:, None], s=sigma, scale=np.exp(np.array(mus)))
    np.testing.assert_allclose(answer.probabilities, softmax(log_lik, axis=-1), rtol=1e-9,
                               atol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, logsumexp(log_lik, axis=-1) - np.log(3),
                               rtol=1e-9, atol=1e-9)


def test_no_mass_at_or_below_zero():
    p = program([0.0, 0.5, 1.0], 0.5)
    with pytest.raises(bayesprog.ZeroEvidenceError):
        p.ask("P(Q | D)", {"D": 0.0})


def test_the_bins_of_a_discretised_child_take_scipys_cdf():
    p = bayesprog.loads("""\
bayesprog: 1
variables:
  D: {continuous: [0, .inf], discretise: {bins: [0, 0.5, 1, 2, 1000]}}
decomposition:
  - {term: P(D), form: lognormal, mu: 0.2, sigma: 0.7}
""")
    cdf = stats.lognorm(s=0.7, scale=np.exp(0.2)).cdf([0.5, 1, 2, 1000])
    np.testing.assert_allclose(p.ask("P(D)").probabilities,
                               np.diff(np.r_[0.0, cdf]) / cdf[-1], rtol=1e-12, atol=1e-15)


def test_draws_follow_scipys_distribution():
    draws = program([-1.0, 0.3, 1.5], 0.6).sample(4000, rng=7)
    for i, state in enumerate(["fine", "medium", "coarse"]):
        d = draws.loc[draws["Q"] == state, "D"].to_numpy()
        test = stats.kstest(d, stats.lognorm(s=0.6, scale=np.exp([-1.0, 0.3, 1.5][i])).cdf)
        assert test.pvalue > 1e-3  # a false failure once in a thousand seeds


def test_the_fit_is_scipys_maximum_likelihood():
    rng = np.random.default_rng(11)
    truth = {"fine": (-1.0, 0.3), "medium": (0.2, 0.5), "coarse": (1.1, 0.8)}
    frame = pd.concat([pd.DataFrame({"Q": state, "D": rng.lognormal(mu, s, 400)})
                       for state, (mu, s) in truth.items()], ignore_index=True)
    fit = program([0.0, 0.0, 0.0], 1.0).fit(frame)
    params = fit.program.term("P(D | Q)").params
    for i, state in enumerate(truth):
        x = frame.loc[frame["Q"] == state, "D"].to_numpy()
        s, _, scale = stats.lognorm.fit(x, floc=0)
        assert params["mu"].array[i] == pytest.approx(np.log(scale), rel=1e-9, abs=1e-12)
        assert params["sigma"].array[i] == pytest.approx(s, rel=1e-6)


def test_shared_sigma_pools_the_logs():
    rng = np.random.default_rng(2)
    frame = pd.DataFrame({"Q": ["fine"] * 300 + ["coarse"] * 300,
                          "D": np.r_[rng.lognormal(-1, 0.4, 300), rng.lognormal(1, 0.4, 300)]})
    fit = bayesprog.loads("""\
bayesprog: 1
variables:
  Q: {states: [fine, coarse]}
  D: {continuous: [0, .inf]}
decomposition:
  - {term: P(Q), form: uniform}
  - term: P(D | Q)
    form: lognormal
    mu: {fine: 0.0, coarse: 0.0}
    sigma: 1.0
    learn: {shared: [sigma]}
""").fit(frame)
    sigma = fit.program.term("P(D | Q)").params["sigma"].array
    logs, groups = np.log(frame["D"].to_numpy()), frame["Q"].to_numpy()
    pooled = np.sqrt(sum(((logs[groups == g] - logs[groups == g].mean()) ** 2).sum()
                         for g in ("fine", "coarse")) / len(logs))
    assert float(np.asarray(sigma)) == pytest.approx(pooled, rel=1e-9)


def test_a_value_at_or_below_zero_cannot_be_learned():
    # (a negative value is refused by the data's support check before any estimator reads it)
    frame = pd.DataFrame({"Q": ["fine", "coarse", "medium"], "D": [0.5, 0.0, 2.0]})
    with pytest.raises(bayesprog.BayesprogError, match="a log-normal variable is > 0"):
        program([0.0, 0.0, 0.0], 1.0).fit(frame)


def test_it_declares_what_it_can_do():
    from bayesprog.forms import get_form
    from bayesprog.views.show import render
    from bayesprog.vocabulary.variables import Continuous

    form = get_form("lognormal")
    assert form is not None and form.display_name == "LogNormal"
    estimator = form.estimator(Continuous("D", 0.0))
    assert estimator is not None and estimator.learned == ("mu", "sigma")
    assert estimator.options == frozenset({"shared"}) and not estimator.mixture
    assert form.mean_param is None  # not linear-Gaussian: the Gaussian method refuses it
    assert "LogNormal(mu = " in render(program([0, 1, 2], 0.5))
