"""Each parametric form against an independent reference (scipy.stats / numpy).

Every form is exercised through a small program ``P(M) P(X | M)`` (or a grid program for the
discrete ``gmm``): the posterior ``P(M | X=x)`` must be the normalised reference densities and
``log_evidence`` the log of ``sum_m P(m) density(x | m)``. Reference values are computed here,
never taken from bayesprog.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import stats
from scipy.special import logsumexp, softmax

import bayesprog
from bayesprog.errors import QuestionError

SETTINGS = settings(max_examples=40, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


def _load(doc: dict) -> bayesprog.Program:
    return bayesprog.loads(yaml.safe_dump(doc, sort_keys=False))


def _states(card: int) -> list[str]:
    return [f"m{i}" for i in range(card)]


def _keyed(values, card: int) -> dict:
    """A parameter table keyed by the states of M."""
    return {s: v for s, v in zip(_states(card), values, strict=True)}


def _ask(program, question, evidence=None, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return program.ask(question, evidence, **kw)


def _check_posterior(result, log_lik, log_prior):
    """``result`` must be softmax(log_prior + log_lik) with the matching log evidence."""
    joint = np.asarray(log_prior) + np.asarray(log_lik)
    expected = softmax(joint, axis=-1)
    assert np.all(np.isfinite(result.probabilities))
    np.testing.assert_allclose(result.probabilities, expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(result.log_evidence, logsumexp(joint, axis=-1),
                               rtol=1e-9, atol=1e-9)


# normal ------------------------------------------------------------------------------------------
@SETTINGS
@given(
    card=st.integers(2, 4),
    means=st.lists(st.floats(-3, 3), min_size=4, max_size=4),
    sigmas=st.lists(st.floats(0.05, 3), min_size=4, max_size=4),
    per_state_sigma=st.booleans(),
    xs=st.lists(st.floats(-5, 5), min_size=1, max_size=4),
)
def test_normal_against_scipy(card, means, sigmas, per_state_sigma, xs):
    means, sigmas = means[:card], (sigmas[:card] if per_state_sigma else [sigmas[0]] * card)
    program = _load({
        "bayesprog": 1,
        "variables": {"M": {"states": _states(card)}, "E": {"continuous": [-np.inf, np.inf]}},
        "decomposition": [
            {"term": "P(M)", "form": "uniform"},
            {"term": "P(E | M)", "form": "normal", "mean": _keyed(means, card),
             "sigma": _keyed(sigmas, card) if per_state_sigma else sigmas[0]},
        ],
    })
    log_prior = np.full(card, -np.log(card))
    for x in xs:
        ref = stats.norm.logpdf(x, loc=np.array(means), scale=np.array(sigmas))
        _check_posterior(_ask(program, "P(M | E)", {"E": x}), ref, log_prior)
    # all values at once, as a batch
    x = np.array(xs)
    ref = stats.norm.logpdf(x[:, None], loc=np.array(means), scale=np.array(sigmas))
    _check_posterior(_ask(program, "P(M | E)", {"E": x}), ref, log_prior)



@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), batch=st.integers(1, 4), x=st.floats(-3, 3))
def test_normal_with_runtime_mean_and_sigma(seed, batch, x):
    rng = np.random.default_rng(seed)
    mean = rng.uniform(-2, 2, size=(batch, 3))
    sigma = rng.uniform(0.1, 2, size=3)
    program = _load({
        "bayesprog": 1,
        "variables": {"M": {"states": _states(3)}, "E": {"continuous": [-np.inf, np.inf]}},
        "inputs": {"mu": {"shape": ["M"]}, "s": {"shape": ["M"]}},
        "decomposition": [
            {"term": "P(M)", "form": "uniform"},
            {"term": "P(E | M)", "form": "normal", "mean": {"input": "mu"},
             "sigma": {"input": "s"}},
        ],
    })
    result = _ask(program, "P(M | E)", {"E": x}, inputs={"mu": mean, "s": sigma})
    assert result.probabilities.shape == (batch, 3)
    ref = stats.norm.logpdf(x, loc=mean, scale=sigma)
    _check_posterior(result, ref, np.full(3, -np.log(3)))
    with pytest.raises(QuestionError):  # sigma must stay > 0 at question time too
        program.ask("P(M | E)", {"E": x}, inputs={"mu": mean, "s": -sigma})


def test_normal_fixed_in_question_text():
    program = _load({
        "bayesprog": 1,
        "variables": {"M": {"states": ["m0", "m1"]}, "E": {"continuous": [-np.inf, np.inf]}},
        "decomposition": [
            {"term": "P(M)", "form": "table", "table": [0.25, 0.75]},
            {"term": "P(E | M)", "form": "normal", "mean": {"m0": -0.5, "m1": 1.5}, "sigma": 0.7},
        ],
    })
    ref = stats.norm.logpdf(0.3, loc=[-0.5, 1.5], scale=0.7)
    _check_posterior(_ask(program, "P(M | E=0.3)"), ref, np.log([0.25, 0.75]))


# beta --------------------------------------------------------------------------------------------
def _beta_program(a, b):
    card = len(a)
    return _load({
        "bayesprog": 1,
        "variables": {"M": {"states": _states(card)}, "L": {"continuous": [0, 1]}},
        "decomposition": [
            {"term": "P(M)", "form": "uniform"},
            {"term": "P(L | M)", "form": "beta", "a": _keyed(a, card), "b": _keyed(b, card)},
        ],
    })


@SETTINGS
@given(
    card=st.integers(2, 4),
    a=st.lists(st.floats(0.2, 8), min_size=4, max_size=4),
    b=st.lists(st.floats(0.2, 8), min_size=4, max_size=4),
    xs=st.lists(st.floats(1e-6, 1 - 1e-6), min_size=1, max_size=4),
)
def test_beta_interior_against_scipy(card, a, b, xs):
    a, b = a[:card], b[:card]
    program = _beta_program(a, b)
    log_prior = np.full(card, -np.log(card))
    x = np.array(xs)
    ref = stats.beta.logpdf(x[:, None], np.array(a), np.array(b))
    _check_posterior(_ask(program, "P(M | L)", {"L": x}), ref, log_prior)


@SETTINGS
@given(
    card=st.integers(2, 4),
    at_zero=st.booleans(),
    ones=st.lists(st.booleans(), min_size=4, max_size=4),
    shape_big=st.lists(st.floats(1.0, 6), min_size=4, max_size=4),
    other=st.lists(st.floats(0.2, 6), min_size=4, max_size=4),
)
def test_beta_at_the_ends_of_its_support(card, at_zero, ones, shape_big, other):
    """x exactly 0 (1): a (b) = 1 gives the finite density b (a); a (b) > 1 gives 0; no NaN."""
    # the shape parameter that matters at this end: 1 for the first state, then 1 or >= 1
    edge = [1.0] + [1.0 if o else s for o, s in zip(ones[1:card], shape_big[1:card], strict=True)]
    rest = other[:card]
    a, b = (edge, rest) if at_zero else (rest, edge)
    x = 0.0 if at_zero else 1.0
    ref = stats.beta.logpdf(x, np.array(a), np.array(b))
    assert np.isfinite(ref[0])  # the reference itself: a = 1 at 0 (b = 1 at 1) is finite
    result = _ask(_beta_program(a, b), "P(M | L)", {"L": x})
    assert not np.any(np.isnan(result.probabilities))
    assert np.isfinite(result.log_evidence)
    _check_posterior(result, ref, np.full(card, -np.log(card)))


def test_beta_uniform_case_at_both_ends():
    # Beta(1, 1) is the uniform density 1 on [0, 1], also at 0 and 1; Beta(1, 3) at 0 is 3.
    program = _beta_program([1.0, 1.0], [1.0, 3.0])
    for x, lik in ((0.0, [1.0, 3.0]), (1.0, [1.0, 0.0])):
        result = _ask(program, "P(M | L)", {"L": x})
        expected = np.array(lik) / sum(lik)
        np.testing.assert_allclose(result.probabilities, expected, atol=1e-15)
        np.testing.assert_allclose(result.log_evidence, np.log(0.5 * sum(lik)), atol=1e-14)


# gmm, continuous child ---------------------------------------------------------------------------
def _mixture_logpdf(x, means, weights, sigma):
    """log sum_k w_k N(x; mean_k, sigma) for each row of means/weights (reference)."""
    x = np.asarray(x, dtype=float)[..., None, None]
    comp = stats.norm.logpdf(x, loc=means, scale=sigma)  # [..., M, K]
    with np.errstate(divide="ignore"):
        return logsumexp(comp + np.log(weights), axis=-1)


@SETTINGS
@given(
    card=st.integers(2, 3),
    k=st.integers(1, 3),
    seed=st.integers(0, 2**32 - 1),
    sigma=st.floats(0.1, 2),
    give_weights=st.booleans(),
    xs=st.lists(st.floats(-4, 4), min_size=1, max_size=3),
)
def test_gmm_continuous_child_against_scipy(card, k, seed, sigma, give_weights, xs):
    rng = np.random.default_rng(seed)
    means = rng.uniform(-3, 3, size=(card, k))
    weights = rng.dirichlet(np.ones(k), size=card) if give_weights else np.full((card, k), 1 / k)
    term = {"term": "P(E | M)", "form": "gmm", "means": _keyed(means.tolist(), card),
            "sigma": sigma}
    if give_weights:
        term["weights"] = _keyed(weights.tolist(), card)
    program = _load({
        "bayesprog": 1,
        "variables": {"M": {"states": _states(card)}, "E": {"continuous": [-np.inf, np.inf]}},
        "decomposition": [{"term": "P(M)", "form": "uniform"}, term],
    })
    x = np.array(xs)
    ref = _mixture_logpdf(x, means, weights, sigma)
    _check_posterior(_ask(program, "P(M | E)", {"E": x}), ref, np.full(card, -np.log(card)))


@SETTINGS
@given(
    k=st.integers(1, 3),
    seed=st.integers(0, 2**32 - 1),
    sigma=st.floats(0.05, 1),
    floor=st.floats(0.01, 0.9),
    low=st.floats(-3, 0),
    width=st.floats(0.5, 5),
    frac=st.lists(st.floats(0, 1), min_size=1, max_size=3),
)
def test_gmm_continuous_child_with_floor(k, seed, sigma, floor, low, width, frac):
    """value = (1 - floor) * mixture + floor / (high - low) on a bounded support."""
    rng = np.random.default_rng(seed)
    card = 3
    high = low + width
    means = rng.uniform(low, high, size=(card, k))
    weights = rng.dirichlet(np.ones(k))
    program = _load({
        "bayesprog": 1,
        "variables": {"M": {"states": _states(card)}, "E": {"continuous": [low, high]}},
        "decomposition": [
            {"term": "P(M)", "form": "table", "table": [0.5, 0.3, 0.2]},
            {"term": "P(E | M)", "form": "gmm", "means": _keyed(means.tolist(), card),
             "sigma": sigma, "weights": weights.tolist(), "floor": floor},
        ],
    })
    x = low + np.array(frac) * width
    x = np.clip(x, low, high)
    mix = np.exp(_mixture_logpdf(x, means, np.broadcast_to(weights, (card, k)), sigma))
    value = (1 - floor) * mix + floor / (high - low)
    _check_posterior(_ask(program, "P(M | E)", {"E": x}), np.log(value), np.log([0.5, 0.3, 0.2]))


def test_gmm_continuous_leaf_is_barren_when_unobserved():
    # a mixture of normals integrates to one over a real child: an unobserved leaf sums out
    program = _load({
        "bayesprog": 1,
        "variables": {"M": {"states": ["m0", "m1"]}, "E": {"continuous": [-np.inf, np.inf]}},
        "decomposition": [
            {"term": "P(M)", "form": "table", "table": [0.3, 0.7]},
            {"term": "P(E | M)", "form": "gmm", "means": {"m0": [0, 1], "m1": [2, 3]},
             "sigma": 0.5},
        ],
    })
    np.testing.assert_allclose(_ask(program, "P(M)").probabilities, [0.3, 0.7], atol=1e-15)


# gmm, discrete child over a grid parent ----------------------------------------------------------
def _grid_centres(shape, cell, origin):
    index = np.indices(shape).reshape(len(shape), -1).T  # row-major, as "i_j"
    return np.asarray(origin, dtype=float) + (index + 0.5) * cell


def _grid_gmm_value(centres, means, weights, sigma, floor, cell):
    """value[r, o] = (1-floor) * sum_k w_k N_D(c_o; mean_rk, sigma^2 I) + floor / area."""
    card, k, dim = means.shape
    mix = np.zeros((card, centres.shape[0]))
    for r in range(card):
        for j in range(k):
            mvn = stats.multivariate_normal(mean=means[r, j], cov=sigma**2 * np.eye(dim))
            mix[r] += weights[r, j] * mvn.pdf(centres)
    area = centres.shape[0] * cell**dim
    return (1 - floor) * mix + floor / area


@st.composite
def grid_gmm_cases(draw):
    rows, cols = draw(st.integers(1, 4)), draw(st.integers(2, 4))
    cell = draw(st.floats(0.05, 2))
    origin = draw(st.sampled_from([None, [0.0, 0.0], [-1.0, 0.5]]))
    card = draw(st.integers(2, 3))
    k = draw(st.integers(1, 3))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    lo = np.zeros(2) if origin is None else np.array(origin)
    hi = lo + np.array([rows, cols]) * cell
    means = rng.uniform(lo, hi, size=(card, k, 2))
    weights = rng.dirichlet(np.ones(k), size=card) if draw(st.booleans()) else None
    # sigma of the order of the cell, so the densities stay well above underflow
    sigma = cell * draw(st.floats(0.5, 3))
    floor = draw(st.sampled_from([0.0, 0.05, 0.1, 0.5]))
    return dict(shape=(rows, cols), cell=cell, origin=origin, card=card, k=k, means=means,
                weights=weights, sigma=sigma, floor=floor)


def _grid_program(case, means_as_input=False):
    grid = {"shape": list(case["shape"]), "cell": case["cell"]}
    if case["origin"] is not None:
        grid["origin"] = case["origin"]
    states = [f"r{i}" for i in range(case["card"])]
    term = {"term": "P(R | O)", "form": "gmm", "sigma": case["sigma"]}
    if means_as_input:
        term["means"] = {"input": "templates"}
    else:
        term["means"] = {s: m for s, m in zip(states, case["means"].tolist(), strict=True)}
    if case["weights"] is not None:
        term["weights"] = {s: w for s, w in zip(states, case["weights"].tolist(), strict=True)}
    if case["floor"]:
        term["floor"] = case["floor"]
    doc = {
        "bayesprog": 1,
        "variables": {"O": {"grid": grid}, "R": {"states": states}},
        "decomposition": [{"term": "P(O)", "form": "uniform"}, term],
    }
    if means_as_input:
        doc["inputs"] = {"templates": {"shape": ["R", "K", 2]}}
    return _load(doc)


def _case_value(case, means=None):
    origin = case["origin"] or [0.0, 0.0]
    centres = _grid_centres(case["shape"], case["cell"], origin)
    weights = case["weights"]
    if weights is None:
        weights = np.full((case["card"], case["k"]), 1 / case["k"])
    return _grid_gmm_value(centres, case["means"] if means is None else means, weights,
                           case["sigma"], case["floor"], case["cell"])


@SETTINGS
@given(case=grid_gmm_cases())
def test_gmm_grid_against_multivariate_normal(case):
    program = _grid_program(case)
    value = _case_value(case)  # [R, O]
    n = value.shape[1]
    log_prior = np.full(n, -np.log(n))
    for r in range(case["card"]):
        result = _ask(program, "P(O | R)", {"R": f"r{r}"})
        _check_posterior(result, np.log(value[r]), log_prior)
    # R unobserved: the potential is kept and summed over R (it is not normalised over R)
    _check_posterior(_ask(program, "P(O)"), np.log(value.sum(axis=0)), log_prior)
    # a cell given by name ("i_j") or by index: P(R | O=o) is the potential at o over R
    cols = case["shape"][1]
    for o in {0, value.shape[1] - 1, value.shape[1] // 2}:
        name = f"{o // cols}_{o % cols}"
        by_name = _ask(program, f"P(R | O={name})")
        by_index = _ask(program, "P(R | O)", {"O": o})
        ref = value[:, o] / value[:, o].sum()
        np.testing.assert_allclose(by_name.probabilities, ref, rtol=1e-9, atol=1e-14)
        np.testing.assert_allclose(by_index.probabilities, ref, rtol=1e-9, atol=1e-14)


@SETTINGS
@given(case=grid_gmm_cases(), seed=st.integers(0, 2**32 - 1))
def test_gmm_grid_with_runtime_input_means(case, seed):
    program = _grid_program(case, means_as_input=True)
    rng = np.random.default_rng(seed)
    lo = np.zeros(2) if case["origin"] is None else np.array(case["origin"])
    hi = lo + np.array(case["shape"]) * case["cell"]
    batch = rng.uniform(lo, hi, size=(3, case["card"], case["k"], 2))
    result = _ask(program, "P(O | R)", {"R": "r0"}, inputs={"templates": batch})
    assert result.probabilities.shape == (3, int(np.prod(case["shape"])))
    n = result.probabilities.shape[-1]
    for i in range(3):
        value = _case_value(case, batch[i])
        ref = np.log(value[0])
        joint = ref - np.log(n)
        np.testing.assert_allclose(result.probabilities[i], softmax(joint), rtol=1e-9,
                                   atol=1e-12)
        np.testing.assert_allclose(result.log_evidence[i], logsumexp(joint), rtol=1e-9)



@SETTINGS
@given(shape=st.tuples(st.integers(1, 4), st.integers(1, 4), st.integers(2, 4)),
       cell=st.floats(0.05, 2), k=st.integers(1, 3), seed=st.integers(0, 2**32 - 1),
       spread=st.floats(0.5, 3), floor=st.sampled_from([0.05, 0.5]))
def test_gmm_3d_grid_against_multivariate_normal(shape, cell, k, seed, spread, floor):
    """A volume of cells, the means given at run time [R, K, 3] (the shape cue of a 3-D
    workspace): scipy's trivariate Normal densities, mixed and floored."""
    rng = np.random.default_rng(seed)
    means = rng.uniform(0.0, np.array(shape) * cell, size=(2, k, 3))
    sigma = cell * spread
    program = _load({
        "bayesprog": 1,
        "variables": {"O": {"grid": {"shape": list(shape), "cell": cell}},
                      "R": {"states": ["r0", "r1"]}},
        "inputs": {"templates": {"shape": ["R", "K", "D"]}},
        "decomposition": [{"term": "P(O)", "form": "uniform"},
                          {"term": "P(R | O)", "form": "gmm", "sigma": sigma, "floor": floor,
                           "means": {"input": "templates"}}],
    })
    value = _grid_gmm_value(_grid_centres(shape, cell, [0.0, 0.0, 0.0]), means,
                            np.full((2, k), 1 / k), sigma, floor, cell)
    for r in range(2):
        result = program.posterior("P(O | R)", {"R": f"r{r}"}, inputs={"templates": means})
        np.testing.assert_allclose(result.probabilities, value[r] / value[r].sum(), rtol=1e-9)


def _two_template_grid(origin, cell, sigma, means):
    return _load({
        "bayesprog": 1,
        "variables": {"O": {"grid": {"shape": [4, 5], "cell": cell, "origin": origin}},
                      "R": {"states": ["r0", "r1"]}},
        "decomposition": [
            {"term": "P(O)", "form": "uniform"},
            {"term": "P(R | O)", "form": "gmm", "sigma": sigma,
             "means": {"r0": means[0].tolist(), "r1": means[1].tolist()}},
        ],
    })


def test_gmm_grid_far_from_the_origin():
    origin, cell, sigma = [1000.0, -2000.0], 0.01, 0.015
    means = np.array(origin) + np.array([[[1.0, 2.0]], [[3.0, 1.0]]]) * cell  # [R, K, 2]
    program = _two_template_grid(origin, cell, sigma, means)
    centres = _grid_centres((4, 5), cell, origin)
    value = _grid_gmm_value(centres, means, np.ones((2, 1)), sigma, 0.0, cell)
    result = _ask(program, "P(O | R=r0)")
    np.testing.assert_allclose(result.probabilities, value[0] / value[0].sum(), rtol=1e-9)


def test_gmm_grid_near_the_origin_is_exact():
    # the same grid and templates, shifted to the origin: the reference agrees to 1e-12
    origin, cell, sigma = [0.0, 0.0], 0.01, 0.015
    means = np.array([[[1.0, 2.0]], [[3.0, 1.0]]]) * cell
    program = _two_template_grid(origin, cell, sigma, means)
    value = _grid_gmm_value(_grid_centres((4, 5), cell, origin), means, np.ones((2, 1)),
                            sigma, 0.0, cell)
    result = _ask(program, "P(O | R=r0)")
    np.testing.assert_allclose(result.probabilities, value[0] / value[0].sum(), rtol=1e-12)


def test_gmm_grid_sigma_keyed_by_cell():
    sigmas = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0]
    names = [f"{i // 3}_{i % 3}" for i in range(6)]
    program = _load({
        "bayesprog": 1,
        "variables": {"O": {"grid": {"shape": [2, 3], "cell": 1.0}},
                      "R": {"states": ["r0", "r1"]}},
        "decomposition": [
            {"term": "P(O)", "form": "uniform"},
            {"term": "P(R | O)", "form": "gmm", "means": {"r0": [[0.5, 0.5]], "r1": [[1.5, 2.5]]},
             "sigma": dict(zip(names, sigmas, strict=True))},
        ],
    })
    centres = _grid_centres((2, 3), 1.0, [0.0, 0.0])
    value = np.array([stats.multivariate_normal([0.5, 0.5], s**2 * np.eye(2)).pdf(c)
                      for c, s in zip(centres, sigmas, strict=True)])
    result = _ask(program, "P(O | R=r0)")
    np.testing.assert_allclose(result.probabilities, value / value.sum(), rtol=1e-9)


# categorical / table -----------------------------------------------------------------------------
@SETTINGS
@given(
    ca=st.integers(2, 4), cb=st.integers(2, 4), cc=st.integers(2, 3),
    seed=st.integers(0, 2**32 - 1),
    mapping=st.booleans(),
)
def test_categorical_and_table_against_numpy(ca, cb, cc, seed, mapping):
    rng = np.random.default_rng(seed)
    pa = rng.dirichlet(np.ones(ca))
    pb = rng.dirichlet(np.ones(cb), size=ca)  # [A, B]
    pc = rng.dirichlet(np.ones(cc), size=(ca, cb))  # [A, B, C]
    sa = [f"a{i}" for i in range(ca)]
    sb = [f"b{i}" for i in range(cb)]
    sc = [f"c{i}" for i in range(cc)]
    if mapping:  # nested mappings, keyed by B first although the term lists A first
        table_c = {b: {a: dict(zip(sc, pc[i, j].tolist(), strict=True))
                       for i, a in enumerate(sa)} for j, b in enumerate(sb)}
        probs_b = {a: dict(zip(sb, pb[i].tolist(), strict=True)) for i, a in enumerate(sa)}
    else:
        table_c, probs_b = pc.tolist(), pb.tolist()
    program = _load({
        "bayesprog": 1,
        "variables": {"A": {"states": sa}, "B": {"states": sb}, "C": {"states": sc}},
        "decomposition": [
            {"term": "P(A)", "form": "categorical", "probabilities": pa.tolist()},
            {"term": "P(B | A)", "form": "categorical", "probabilities": probs_b},
            {"term": "P(C | A, B)", "form": "table", "table": table_c},
        ],
    })
    joint = pa[:, None, None] * pb[:, :, None] * pc  # [A, B, C]
    for c in range(cc):
        result = _ask(program, "P(A | C)", {"C": sc[c]})
        marg = joint[:, :, c].sum(axis=1)
        np.testing.assert_allclose(result.probabilities, marg / marg.sum(), rtol=1e-9, atol=1e-14)
        np.testing.assert_allclose(result.log_evidence, np.log(marg.sum()), rtol=1e-9)
    result = _ask(program, "P(B A | C=c0)")
    ref = joint[:, :, 0].T
    np.testing.assert_allclose(result.probabilities, ref / ref.sum(), rtol=1e-9, atol=1e-14)
    result = _ask(program, "P(C)")
    np.testing.assert_allclose(result.probabilities, joint.sum(axis=(0, 1)), rtol=1e-9,
                               atol=1e-14)


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), batch=st.integers(1, 4))
def test_categorical_with_runtime_probabilities(seed, batch):
    rng = np.random.default_rng(seed)
    pa = rng.dirichlet(np.ones(2))
    pb = rng.dirichlet(np.ones(3), size=(batch, 2))  # batch + [A, B]
    program = _load({
        "bayesprog": 1,
        "variables": {"A": {"states": ["a0", "a1"]}, "B": {"states": ["b0", "b1", "b2"]}},
        "inputs": {"pb": {"shape": ["A", 3]}},
        "decomposition": [
            {"term": "P(A)", "form": "table", "table": pa.tolist()},
            {"term": "P(B | A)", "form": "categorical", "probabilities": {"input": "pb"}},
        ],
    })
    result = _ask(program, "P(A | B=b2)", inputs={"pb": pb})
    joint = pa * pb[:, :, 2]
    np.testing.assert_allclose(result.probabilities, joint / joint.sum(-1, keepdims=True),
                               rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(result.log_evidence, np.log(joint.sum(-1)), rtol=1e-9)


# uniform -----------------------------------------------------------------------------------------
@SETTINGS
@given(ca=st.integers(2, 5), cb=st.integers(2, 4), seed=st.integers(0, 2**32 - 1))
def test_uniform_discrete_is_one_over_card(ca, cb, seed):
    rng = np.random.default_rng(seed)
    pb = rng.dirichlet(np.ones(cb), size=ca)
    sa, sb = [f"a{i}" for i in range(ca)], [f"b{i}" for i in range(cb)]
    program = _load({
        "bayesprog": 1,
        "variables": {"A": {"states": sa}, "B": {"states": sb}},
        "decomposition": [
            {"term": "P(A)", "form": "uniform"},
            {"term": "P(B | A)", "form": "table", "table": pb.tolist()},
        ],
    })
    for b in range(cb):
        result = _ask(program, "P(A | B)", {"B": b})
        np.testing.assert_allclose(result.probabilities, pb[:, b] / pb[:, b].sum(), rtol=1e-9)
        np.testing.assert_allclose(result.log_evidence, np.log(pb[:, b].sum() / ca), rtol=1e-9)
    np.testing.assert_allclose(_ask(program, "P(A)").probabilities, np.full(ca, 1 / ca),
                               rtol=1e-12)
    # a uniform child: P(B = b | A) = 1/cb whatever A, so the evidence is log(1/cb)
    flat = _load({
        "bayesprog": 1,
        "variables": {"A": {"states": sa}, "B": {"states": sb}},
        "decomposition": [
            {"term": "P(A)", "form": "table", "table": rng.dirichlet(np.ones(ca)).tolist()},
            {"term": "P(B | A)", "form": "uniform"},
        ],
    })
    result = _ask(flat, "P(B | A=a1)")
    np.testing.assert_allclose(result.probabilities, np.full(cb, 1 / cb), rtol=1e-12)
    result = _ask(flat, "P(A | B=b0)")
    np.testing.assert_allclose(np.exp(result.log_evidence), 1 / cb, rtol=1e-12)


@SETTINGS
@given(
    low=st.floats(-10, 10), width=st.floats(0.01, 100), frac=st.floats(0, 1),
    f=st.floats(-2, 2), seed=st.integers(0, 2**32 - 1),
)
def test_uniform_continuous_is_one_over_width(low, width, frac, f, seed):
    rng = np.random.default_rng(seed)
    high = low + width
    prior = rng.dirichlet(np.ones(3))
    mean = rng.uniform(-1, 1, size=3)
    program = _load({
        "bayesprog": 1,
        "variables": {
            "M": {"states": _states(3)},
            "U": {"continuous": [low, high]},
            "V": {"continuous": [-np.inf, np.inf]},
            "F": {"continuous": [-np.inf, np.inf]},
        },
        "decomposition": [
            {"term": "P(M)", "form": "table", "table": prior.tolist()},
            {"term": "P(U | M)", "form": "uniform"},
            {"term": "P(V | M)", "form": "uniform"},
            {"term": "P(F | M)", "form": "normal", "mean": _keyed(mean.tolist(), 3),
             "sigma": 0.5},
        ],
    })
    u = min(max(low + frac * width, low), high)
    ref = stats.norm.logpdf(f, loc=mean, scale=0.5)
    result = _ask(program, "P(M | U, F)", {"U": u, "F": f})
    np.testing.assert_allclose(result.probabilities, softmax(np.log(prior) + ref), rtol=1e-9,
                               atol=1e-14)
    # 1 / (high - low) on the closed support (scipy's uniform can put x == high just
    # outside [loc, loc + scale] by rounding, so the density is written out here)
    log_u = -np.log(high - low)
    np.testing.assert_allclose(result.log_evidence, log_u + logsumexp(np.log(prior) + ref),
                               rtol=1e-9, atol=1e-9)
    # an unbounded uniform is the constant 1: it changes neither posterior nor evidence
    result = _ask(program, "P(M | V, F)", {"V": 123.0, "F": f})
    np.testing.assert_allclose(result.log_evidence, logsumexp(np.log(prior) + ref), rtol=1e-9,
                               atol=1e-12)


def test_continuous_evidence_outside_support_is_refused():
    program = _beta_program([2.0, 3.0], [2.0, 1.0])
    with pytest.raises(QuestionError):
        program.ask("P(M | L)", {"L": 1.5})


def test_terms_set_when_loading_give_the_answers_of_the_edited_file():
    """``terms=`` is the file with those parameters written in: the posterior is scipy's."""
    doc = {"bayesprog": 1,
           "variables": {"M": {"states": _states(2)}, "X": {"continuous": [0, 1]}},
           "decomposition": [{"term": "P(M)", "form": "uniform"},
                             {"term": "P(X | M)", "form": "beta",
                              "a": _keyed([2.0, 5.0], 2), "b": 3.0}]}
    text = yaml.safe_dump(doc, sort_keys=False)
    a = {"m0": 1.5, "m1": 0.7}
    changed = bayesprog.loads(text, terms={"P(X|M)": {"a": a}})  # spelled as the parser reads it
    density = stats.beta.pdf(0.3, [1.5, 0.7], 3.0)
    np.testing.assert_allclose(changed.ask("P(M | X)", {"X": 0.3}).probabilities,
                               density / density.sum(), rtol=1e-12)
    original = stats.beta.pdf(0.3, [2.0, 5.0], 3.0)
    np.testing.assert_allclose(bayesprog.loads(text).ask("P(M | X)", {"X": 0.3}).probabilities,
                               original / original.sum(), rtol=1e-12)
    with pytest.raises(bayesprog.SpecError, match=r"<string>:\d+:\d+: no term 'P\(X\)'"):
        bayesprog.loads(text, terms={"P(X)": {"a": 1.0}})


# a sub-program over a field of errors, one per shape, whatever the shapes ---------------------
_SHAPES = """\
bayesprog: 1
variables:
  R: {states: [a, b]}
  L: {continuous: [0, 1], indexed_by: R}
decomposition:
  - {term: P(R), form: uniform}
  - {term: P(L | R), form: beta, a: 1.0, b: 4.5}
questions:
  shape: P(R | L)
"""

_CHOOSER = """\
bayesprog: 1
variables:
  R: {states: [a, b]}
  D: {states: [go, stay]}
inputs:
  errors: {shape: [R]}
decomposition:
  - {term: P(R), form: uniform}
  - {term: P(D | R), form: table, table: {a: {go: 0.9, stay: 0.1}, b: {go: 0.2, stay: 0.8}}}
soft_evidence:
  - {variable: R, form: program, program: shapes.yaml, question: shape,
     bind: {L: {input: errors}}}
"""


def test_a_field_of_errors_bound_from_an_input_over_shapes_set_when_loading(tmp_path):
    """The shapes R, set when the outer program is loaded, are set in the sub-program too; the
    sub-program's field L takes one error per shape from the outer input, and its answer
    P(R | L) weighs the outer program as soft evidence."""
    (tmp_path / "shapes.yaml").write_text(_SHAPES)
    (tmp_path / "chooser.yaml").write_text(_CHOOSER)
    states = ["disc", "ell", "square"]
    go = {"disc": 0.9, "ell": 0.4, "square": 0.2}
    program = bayesprog.load(tmp_path / "chooser.yaml", variables={"R": {"states": states}},
                             terms={"P(D | R)": {"table": {
                                 s: {"go": p, "stay": 1 - p} for s, p in go.items()}}})
    errors = np.array([[0.1, 0.5, 0.9], [0.7, 0.05, 0.3]])
    answer = program.ask("P(D)", inputs={"errors": errors})
    for row, e in enumerate(errors):
        # by hand: P(R = r | L) proportional to Beta(1, 4.5) at the error against r (the
        # others uniform), then P(D = go) = sum over r of P(r | L) P(go | r)
        shape = stats.beta(1.0, 4.5).pdf(e)
        shape /= shape.sum()
        assert answer.probabilities[row, 0] == pytest.approx(shape @ list(go.values()),
                                                             rel=1e-12)
    one = program.ask("P(D)", inputs={"errors": errors[1]})
    np.testing.assert_allclose(one.probabilities, answer.probabilities[1], rtol=1e-12)


def test_an_input_over_another_variable_is_not_bound_to_a_field(tmp_path):
    (tmp_path / "shapes.yaml").write_text(_SHAPES)
    text = _CHOOSER.replace("errors: {shape: [R]}", "errors: {shape: [D]}")
    (tmp_path / "chooser.yaml").write_text(text)
    with pytest.raises(bayesprog.SpecError, match="input 'errors' must not vary over variables, "
                       "except one of the term's own"):
        bayesprog.load(tmp_path / "chooser.yaml")


def test_a_replaced_variable_the_named_program_lacks_is_reported_by_the_term(tmp_path):
    (tmp_path / "shapes.yaml").write_text(_SHAPES)
    (tmp_path / "outer.yaml").write_text("""\
bayesprog: 1
variables:
  W: {states: [u, v]}
  R: {states: [a, b]}
  L: {continuous: [0, 1], indexed_by: R}
decomposition:
  - {term: P(W), form: uniform}
  - {term: P(R | W), form: program, program: shapes.yaml, question: shape,
     bind: {L: 0.5}}
  - {term: P(L | R), form: beta, a: 1, b: 2}
""")
    with pytest.raises(bayesprog.SpecError) as err:
        bayesprog.load(tmp_path / "outer.yaml", variables={"W": {"states": ["x", "y", "z"]}})
    text = str(err.value)
    assert "variable 'W' must have the same states in 'shapes.yaml'" in text
    assert "no variable 'W' to replace" not in text
