"""Identification: parameters learned from data, checked against independent estimators
(scipy.stats, scikit-learn, pgmpy, a direct maximisation of the observed-data likelihood), the
fitted file's round trip, continuing a fit, and the errors bad data get."""

from __future__ import annotations

import hashlib
import itertools
import logging
import math
import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import optimize, stats

import bayesprog
from bayesprog.cli import main
from bayesprog.learning import DataError, render_fitted

NORMAL = """\
bayesprog: 1
name: sensor
# a comment the fitted file must keep
variables:
  M: {states: [wood, silk, felt]}
  E: {continuous: [-.inf, .inf], description: texture}
decomposition:
  - term: P(M)
    form: table
    table: [0.2, 0.3, 0.5]   # the prior, to be learned
  - term: P(E | M)
    form: normal
    mean: 0.0
    sigma: 1.0
"""


def normal_data(seed: int, n: int = 300) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    m = rng.choice(["wood", "silk", "felt"], size=n, p=[0.5, 0.3, 0.2])
    mu = {"wood": 0.2, "silk": 0.5, "felt": 0.9}
    sd = {"wood": 0.05, "silk": 0.1, "felt": 0.2}
    e = np.array([rng.normal(mu[k], sd[k]) for k in m])
    return pd.DataFrame({"M": m, "E": e})


def test_tables_and_normals_by_maximum_likelihood_match_pgmpy_and_scipy():
    program = bayesprog.loads(NORMAL)
    data = normal_data(0)
    fit = program.fit(data)
    table = fit.program.term("P(M)").params["table"].array
    freq = data["M"].value_counts(normalize=True)
    np.testing.assert_allclose(table, [freq["wood"], freq["silk"], freq["felt"]], rtol=1e-12)
    term = fit.program.term("P(E | M)")
    for i, state in enumerate(["wood", "silk", "felt"]):
        loc, scale = stats.norm.fit(data.loc[data["M"] == state, "E"])
        assert term.params["mean"].array[i] == pytest.approx(loc, rel=1e-12)
        assert term.params["sigma"].array[i] == pytest.approx(scale, rel=1e-10)
    assert fit.record.method == "maximum likelihood"
    expected = sum(np.log(table[["wood", "silk", "felt"].index(m)])
                   + stats.norm.logpdf(e, term.params["mean"].array[["wood", "silk", "felt"].index(m)],
                                       term.params["sigma"].array[["wood", "silk", "felt"].index(m)])
                   for m, e in zip(data["M"], data["E"], strict=True))
    assert fit.log_likelihood == pytest.approx(expected, rel=1e-12)


def _pgmpy_network(cpds):
    from pgmpy.models import DiscreteBayesianNetwork

    model = DiscreteBayesianNetwork([("A", "B"), ("A", "C")])
    model.add_cpds(*cpds)
    return model


DISCRETE = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  B: {states: [b0, b1, b2]}
  C: {states: [c0, c1]}
decomposition:
  - {term: P(A), form: table, table: [0.6, 0.4]}
  - term: P(B | A)
    form: table
    table: {a0: [0.5, 0.3, 0.2], a1: [0.1, 0.3, 0.6]}
  - term: P(C | A)
    form: table
    table: {a0: [0.7, 0.3], a1: [0.2, 0.8]}
"""


def discrete_data(seed: int, n: int = 400) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    a = rng.random(n) < 0.35
    b = np.where(a, rng.choice(3, n, p=[0.1, 0.2, 0.7]), rng.choice(3, n, p=[0.6, 0.3, 0.1]))
    c = np.where(a, rng.random(n) < 0.9, rng.random(n) < 0.15).astype(int)
    return pd.DataFrame({"A": np.where(a, "a1", "a0"), "B": [f"b{i}" for i in b],
                         "C": [f"c{i}" for i in c]})


def test_dirichlet_pseudo_counts_match_pgmpy_bayesian_estimator():
    from pgmpy.estimators import BayesianEstimator

    text = DISCRETE.replace("table: {a0: [0.5, 0.3, 0.2], a1: [0.1, 0.3, 0.6]}",
                            "table: {a0: [0.5, 0.3, 0.2], a1: [0.1, 0.3, 0.6]}\n"
                            "    learn: {pseudo_counts: {a0: [1, 2, 3], a1: [0.5, 0.5, 4]}}")
    data = discrete_data(1, n=60)
    fit = bayesprog.loads(text).fit(data)
    model = _pgmpy_network([])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        logging.disable(logging.WARNING)
        try:
            cpd = BayesianEstimator(model, data).estimate_cpd(
                "B", prior_type="dirichlet", pseudo_counts=[[1, 0.5], [2, 0.5], [3, 4]])
        finally:
            logging.disable(logging.NOTSET)
    ours = fit.program.term("P(B | A)").params["table"].array  # [A, B]
    ref = cpd.get_values()  # [B, A] in pgmpy's state order
    order_b = [cpd.state_names["B"].index(s) for s in ("b0", "b1", "b2")]
    order_a = [cpd.state_names["A"].index(s) for s in ("a0", "a1")]
    np.testing.assert_allclose(ours, ref[np.ix_(order_b, order_a)].T, rtol=1e-12)


def test_em_with_a_hidden_variable_matches_pgmpy():
    from pgmpy.estimators import ExpectationMaximization
    from pgmpy.factors.discrete import TabularCPD

    data = discrete_data(2, n=2000).drop(columns="A")  # A is hidden: no column
    program = bayesprog.loads(DISCRETE)
    fit = program.fit(data, max_iter=2000, tol=1e-14)
    assert fit.record.method == "EM" and fit.converged
    names = {"A": ["a0", "a1"], "B": ["b0", "b1", "b2"], "C": ["c0", "c1"]}
    init = {
        "A": TabularCPD("A", 2, [[0.6], [0.4]], state_names={"A": names["A"]}),
        "B": TabularCPD("B", 3, [[0.5, 0.1], [0.3, 0.3], [0.2, 0.6]], evidence=["A"],
                        evidence_card=[2], state_names={"B": names["B"], "A": names["A"]}),
        "C": TabularCPD("C", 2, [[0.7, 0.2], [0.3, 0.8]], evidence=["A"], evidence_card=[2],
                        state_names={"C": names["C"], "A": names["A"]}),
    }
    model = _pgmpy_network([])
    model.add_node("A")
    model.latents = {"A"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        logging.disable(logging.WARNING)
        try:
            cpds = ExpectationMaximization(model, data).get_parameters(
                latent_card={"A": 2}, init_cpds=init, max_iter=2000, atol=1e-12,
                show_progress=False)
        finally:
            logging.disable(logging.NOTSET)
    by = {c.variable: c for c in cpds}
    ours, theirs = {}, {}
    for var, term in (("B", "P(B | A)"), ("C", "P(C | A)")):
        cpd = by[var]
        ref = cpd.get_values()
        rows = [cpd.state_names[var].index(s) for s in names[var]]
        theirs[var] = ref[np.ix_(rows, _latent_order(cpd.state_names["A"]))].T  # [A, var]
        ours[var] = fit.program.term(term).params["table"].array
        np.testing.assert_allclose(ours[var], theirs[var], atol=1e-5)
    theirs["A"] = by["A"].get_values()[_latent_order(by["A"].state_names["A"]), 0]
    ours["A"] = fit.program.term("P(A)").params["table"].array
    np.testing.assert_allclose(ours["A"], theirs["A"], atol=1e-5)

    def log_likelihood(p):  # rows of (B, C), A summed out
        b = data["B"].str[1].astype(int).to_numpy()
        c = data["C"].str[1].astype(int).to_numpy()
        return np.log((p["A"][None, :] * p["B"][:, b].T * p["C"][:, c].T).sum(1)).sum()

    assert fit.log_likelihood == pytest.approx(log_likelihood(ours), rel=1e-12)
    assert fit.log_likelihood >= log_likelihood(theirs) - 1e-9  # at least as far up as pgmpy


def _latent_order(states: list) -> list[int]:
    """pgmpy names a latent variable's states 0, 1, ... in the order of its initial CPD."""
    return [states.index(s) if s in states else states.index(i) for i, s in enumerate(["a0", "a1"])]


def _observed_log_likelihood(theta: np.ndarray, data: pd.DataFrame) -> float:
    """Log-likelihood of rows that may miss A, for P(A) P(B | A): by enumeration."""
    pa = np.array([1 - theta[0], theta[0]])
    pb = np.array([[1 - theta[1], theta[1]], [1 - theta[2], theta[2]]])  # [A, B]
    total = 0.0
    for a, b in zip(data["A"], data["B"], strict=True):
        bi = int(b[1])
        if isinstance(a, str):
            total += np.log(pa[int(a[1])] * pb[int(a[1]), bi])
        else:
            total += np.log(pa @ pb[:, bi])
    return total


def test_em_with_partly_missing_values_maximises_the_observed_likelihood():
    text = """\
bayesprog: 1
variables: {A: {states: [a0, a1]}, B: {states: [b0, b1]}}
decomposition:
  - {term: P(A), form: table, table: [0.5, 0.5]}
  - {term: P(B | A), form: table, table: [[0.6, 0.4], [0.3, 0.7]]}
"""
    rng = np.random.default_rng(3)
    a = rng.random(200) < 0.3
    b = np.where(a, rng.random(200) < 0.8, rng.random(200) < 0.2)
    frame = pd.DataFrame({"A": np.where(a, "a1", "a0"), "B": np.where(b, "b1", "b0")})
    frame.loc[rng.random(200) < 0.4, "A"] = None
    fit = bayesprog.loads(text).fit(frame, max_iter=5000, tol=1e-15)
    theta = np.array([fit.program.term("P(A)").params["table"].array[1],
                      *fit.program.term("P(B | A)").params["table"].array[:, 1]])
    best = optimize.minimize(lambda t: -_observed_log_likelihood(t, frame), x0=[0.5, 0.4, 0.6],
                             bounds=[(1e-6, 1 - 1e-6)] * 3, method="L-BFGS-B",
                             options={"ftol": 1e-15, "gtol": 1e-10})
    np.testing.assert_allclose(theta, best.x, atol=2e-4)
    assert fit.log_likelihood == pytest.approx(_observed_log_likelihood(theta, frame), rel=1e-10)
    assert fit.log_likelihood >= -best.fun - 1e-8


BETA = """\
bayesprog: 1
variables: {T: {states: [t1, t2]}, S: {continuous: [0, 1]}}
decomposition:
  - {term: P(T), form: table, table: [0.5, 0.5], learn: false}
  - {term: P(S | T), form: beta, a: 1, b: 1}
"""


def test_beta_by_maximum_likelihood_matches_scipy_fit():
    rng = np.random.default_rng(4)
    frame = pd.DataFrame({"T": ["t1"] * 300 + ["t2"] * 200,
                          "S": np.r_[rng.beta(3, 1, 300), rng.beta(0.7, 2.5, 200)]})
    fit = bayesprog.loads(BETA).fit(frame)
    params = fit.program.term("P(S | T)").params
    for i, state in enumerate(["t1", "t2"]):
        x = frame.loc[frame["T"] == state, "S"].to_numpy()
        a, b, _, _ = stats.beta.fit(x, floc=0, fscale=1)
        ours = params["a"].array[i], params["b"].array[i]
        assert ours == pytest.approx((a, b), rel=2e-3)
        assert stats.beta.logpdf(x, *ours).sum() >= stats.beta.logpdf(x, a, b).sum() - 1e-9
    np.testing.assert_array_equal(fit.program.term("P(T)").params["table"].array, [0.5, 0.5])


GMM = """\
bayesprog: 1
variables: {X: {continuous: [-.inf, .inf]}}
decomposition:
  - term: P(X)
    form: gmm
    means: [0.0, 1.0]
    sigma: 1.0
    weights: [0.5, 0.5]
    learn: {components: COMPONENTS}
"""


def gmm_data(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.r_[rng.normal(-2, 0.5, 300), rng.normal(1, 0.5, 200), rng.normal(3, 0.5, 250)]


def test_gmm_by_em_matches_scikit_learn():
    from sklearn.mixture import GaussianMixture

    x = gmm_data(5)
    fit = bayesprog.loads(GMM.replace("COMPONENTS", "3")).fit({"X": x}, max_iter=5000, tol=1e-14)
    params = fit.program.term("P(X)").params
    # the same deterministic start: means at the quantiles (i + 1/2)/3, sigma spread / 3
    q = np.quantile(x, [1 / 6, 1 / 2, 5 / 6])
    ref = GaussianMixture(3, covariance_type="tied", reg_covar=0, tol=1e-14, max_iter=5000,
                          means_init=q[:, None], weights_init=np.full(3, 1 / 3),
                          precisions_init=np.array([[9 / x.var()]])).fit(x[:, None])
    order = np.argsort(ref.means_[:, 0])
    np.testing.assert_allclose(np.sort(params["means"].array), ref.means_[order, 0], atol=1e-5)
    np.testing.assert_allclose(params["weights"].array[np.argsort(params["means"].array)],
                               ref.weights_[order], atol=1e-5)
    assert float(params["sigma"].array) == pytest.approx(np.sqrt(ref.covariances_[0, 0]), rel=1e-5)
    assert fit.log_likelihood == pytest.approx(ref.score(x[:, None]) * len(x), rel=1e-8)


def test_gmm_components_chosen_by_bic_as_scikit_learn_would():
    from sklearn.mixture import GaussianMixture

    x = gmm_data(6)
    fit = bayesprog.loads(GMM.replace("COMPONENTS", "[1, 2, 3, 4]")).fit({"X": x})
    chosen = len(fit.program.term("P(X)").params["means"].array)
    bics = [GaussianMixture(k, covariance_type="tied", n_init=3, random_state=0)
            .fit(x[:, None]).bic(x[:, None]) for k in (1, 2, 3, 4)]
    assert chosen == 1 + int(np.argmin(bics)) == 3
    assert "3 components by BIC" in fit.record.method


def test_fitted_file_keeps_comments_and_layout_and_records_provenance(tmp_path):
    source = tmp_path / "sensor.yaml"
    source.write_text(NORMAL)
    data = tmp_path / "probes.csv"
    normal_data(7).to_csv(data, index=False)
    out = tmp_path / "fitted.yaml"
    assert main(["learn", str(source), str(data), "-o", str(out)]) == 0
    text = out.read_text()
    assert "# a comment the fitted file must keep" in text
    assert "# the prior, to be learned" in text
    assert text.index("name: sensor") < text.index("variables:") < text.index("decomposition:")
    fitted = bayesprog.load(out)
    direct = bayesprog.loads(NORMAL).fit(data)
    record = fitted.learned[-1]
    assert record.digits is None and "digits:" not in text  # written as fitted
    for term in ("P(M)", "P(E | M)"):
        for name, value in direct.program.term(term).params.items():  # 15 digits
            np.testing.assert_allclose(fitted.term(term).params[name].array, value.array,
                                       rtol=1e-14, atol=0)
    rounded = tmp_path / "rounded.yaml"
    assert main(["learn", str(source), str(data), "-o", str(rounded), "--rounded"]) == 0
    shortened = bayesprog.load(rounded)
    assert shortened.learned[-1].digits == 4  # 300 rows: a relative standard error near 0.06
    for name, value in direct.program.term("P(M)").params.items():
        written = shortened.term("P(M)").params[name].array
        # each value to 4 significant digits; a distribution's largest entry takes the rest
        np.testing.assert_allclose(written, value.array, rtol=2 * 0.5e-3, atol=0)
        assert not np.array_equal(written, value.array)  # rounded, as the record says
    assert record.sha256 == hashlib.sha256(data.read_bytes()).hexdigest()
    assert record.rows == record.rows_used == 300 and record.data == "probes.csv"
    assert record.log_likelihood == pytest.approx(direct.log_likelihood, rel=1e-12)
    assert record.terms == ["P(M)", "P(E | M)"]


ASIA = (Path(__file__).parent / "programs" / "asia.yaml").read_text(encoding="utf-8")
ASIA_ARCS = [("asia", "tub"), ("smoke", "lung"), ("smoke", "bronc"), ("tub", "either"),
             ("lung", "either"), ("either", "xray"), ("bronc", "dysp"), ("either", "dysp")]


def test_keyed_tables_naming_their_parents_are_learned_and_written_back_as_pgmpy_counts(
        tmp_path, capsys):
    from pgmpy.models import DiscreteBayesianNetwork
    from pgmpy.parameter_estimator import DiscreteMLE

    source = tmp_path / "asia.yaml"
    source.write_text(ASIA)
    data = bayesprog.loads(ASIA).sample(20_000, rng=5)
    csv = tmp_path / "data.csv"
    data.to_csv(csv, index=False)
    out = tmp_path / "fitted.yaml"
    assert main(["learn", str(source), str(csv), "-o", str(out)]) == 0
    assert "values written as fitted" in capsys.readouterr().out
    text = out.read_text()
    # the keys name their variable again, in the author's order of the levels
    assert "tub=yes: {lung=yes: [" in text and "tub=no: {lung=yes: [" in text
    assert "either=yes: {bronc=yes: {dysp=yes: " in text
    assert "# keys name their variable" in text
    fitted = bayesprog.load(out)
    network = DiscreteBayesianNetwork(ASIA_ARCS)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        logging.disable(logging.WARNING)
        try:
            estimator = DiscreteMLE().fit(network, data.astype(str))
            cpds = estimator.parameters_
        finally:
            logging.disable(logging.NOTSET)
    assert len(cpds) == 8
    for cpd in cpds:
        child, parents = cpd.variable, cpd.variables[1:]
        term = f"P({child} | {', '.join(parents)})" if parents else f"P({child})"
        ours = fitted.table(term)  # parent states by child states, read from the file
        reference = cpd.get_values()  # [child, parents...] in pgmpy's state order
        for r, states in enumerate(itertools.product(*(cpd.state_names[p] for p in parents))):
            row = ours.loc[states if len(states) > 1 else states[0]] if parents else ours.iloc[0]
            for c, state in enumerate(cpd.state_names[child]):
                assert abs(row[state] - reference[c, r]) <= 1e-9, (term, states, state)
    # Program.fit then Fit.save writes the same file; --rounded keeps the names too
    bayesprog.load(source).fit(csv).save(tmp_path / "again.yaml")
    assert (tmp_path / "again.yaml").read_text() == text
    assert main(["learn", str(source), str(csv), "-o", str(tmp_path / "r.yaml"), "--rounded"]) == 0
    assert "tub=yes: {lung=yes: [" in (tmp_path / "r.yaml").read_text()


def test_a_parameter_written_once_for_every_parent_state_is_learned_into_keys_naming_them():
    text = ASIA.replace("  dysp: {states: [yes, no]}", "  dysp: {states: [yes, no]}\n"
                        "  cough: {continuous: [-.inf, .inf]}")
    text += "  - {term: 'P(cough | bronc, either)', form: normal, mean: 0, sigma: 1}\n"
    program = bayesprog.loads(text, "asia.yaml")
    data = bayesprog.loads(ASIA).sample(3000, rng=2)
    mean = {("yes", "yes"): 2.0, ("yes", "no"): 1.0, ("no", "yes"): 0.5, ("no", "no"): 0.0}
    noise = np.random.default_rng(3).normal(0, 0.3, len(data))
    data["cough"] = [mean[b, e] for b, e in zip(data["bronc"], data["either"], strict=True)] + noise
    fit = program.fit(data)
    written = render_fitted(text, fit.estimate.params, fit.program.variables, fit.record)
    # bronc and either have the same states: plain keys (yes, no) would not load
    assert "bronc=yes:" in written and "either=yes:" in written
    again = bayesprog.loads(written)
    for name in ("mean", "sigma"):
        np.testing.assert_allclose(again.term("P(cough | bronc, either)").params[name].array,
                                   fit.program.term("P(cough | bronc, either)").params[name].array,
                                   rtol=1e-14)


def test_learning_continues_from_a_fitted_file_with_more_data(tmp_path):
    source = tmp_path / "sensor.yaml"
    source.write_text(NORMAL)
    first, second = normal_data(8, 200), normal_data(9, 150)
    bayesprog.load(source).fit(first).save(tmp_path / "first.yaml")
    more = bayesprog.load(tmp_path / "first.yaml").fit(second)
    both = bayesprog.loads(NORMAL).fit(pd.concat([first, second]))
    for term in ("P(M)", "P(E | M)"):
        for name, value in both.program.term(term).params.items():
            np.testing.assert_allclose(more.program.term(term).params[name].array, value.array,
                                       rtol=1e-9)
    assert "continued" in more.record.method
    more.save(tmp_path / "second.yaml", source=tmp_path / "first.yaml")
    assert len(bayesprog.load(tmp_path / "second.yaml").learned) == 2


def test_frozen_terms_keep_their_values():
    text = NORMAL.replace("    table: [0.2, 0.3, 0.5]   # the prior, to be learned",
                          "    table: [0.2, 0.3, 0.5]\n    learn: false")
    fit = bayesprog.loads(text).fit(normal_data(10))
    np.testing.assert_array_equal(fit.program.term("P(M)").params["table"].array, [0.2, 0.3, 0.5])
    fit = bayesprog.loads(NORMAL).fit(normal_data(10), freeze=["P(E|M)"])
    assert float(fit.program.term("P(E | M)").params["mean"].array) == 0.0
    assert fit.record.terms == ["P(M)"]


def test_missing_continuous_values_leave_their_rows_out_of_that_term_only():
    frame = normal_data(11)
    frame.loc[::3, "E"] = np.nan
    fit = bayesprog.loads(NORMAL).fit(frame)
    kept = frame.dropna()
    loc, _ = stats.norm.fit(kept.loc[kept["M"] == "silk", "E"])
    assert fit.program.term("P(E | M)").params["mean"].array[1] == pytest.approx(loc, rel=1e-12)
    counts = frame["M"].value_counts(normalize=True)
    assert fit.program.term("P(M)").params["table"].array[0] == pytest.approx(counts["wood"])


def test_parquet_data(tmp_path):
    path = tmp_path / "probes.parquet"
    normal_data(12).to_parquet(path)
    fit = bayesprog.loads(NORMAL).fit(path)
    assert fit.record.rows == 300 and fit.record.data == "probes.parquet"


@pytest.mark.parametrize("csv, message", [
    ("M,E\nwood,0.1\nwod,0.2\n", "row 2 (line 3), column 'M': unknown state 'wod' of M"),
    ("M,E\nwood,0.1\nsilk,high\n", "row 2 (line 3), column 'E': expected a number for continuous E"),
    ("M,E,Z\nwood,0.1,1\n", "column 'Z' (column 3): the program has no variable 'Z'"),
    ("M,E\nwood,0.1\nwood,0.3\nsilk,0.2\nfelt,0.4\nfelt,0.5\n",
     "too few rows for P(E | M): (M=silk) has fewer than 2 rows"),
    ("M,E\nwood,0.1\nwood,0.1\nsilk,0.2\nsilk,0.3\nfelt,0.4\nfelt,0.5\n",
     "zero variance ((M=wood) has one repeated value)"),
])
def test_bad_data_is_refused_with_its_place_and_nothing_written(tmp_path, capsys, csv, message):
    source = tmp_path / "sensor.yaml"
    source.write_text(NORMAL)
    data = tmp_path / "probes.csv"
    data.write_text(csv)
    out = tmp_path / "fitted.yaml"
    assert main(["learn", str(source), str(data), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and "probes.csv" in err and "Traceback" not in err
    assert not out.exists()
    with pytest.raises(DataError, match="probes.csv"):
        bayesprog.load(source).fit(data)


def test_bad_learn_options_are_refused_at_their_place():
    text = NORMAL.replace("    sigma: 1.0", "    sigma: 1.0\n    learn: {pseudo_counts: 1, shared: [sd]}")
    with pytest.raises(bayesprog.SpecError) as err:
        bayesprog.loads(text, "sensor.yaml")
    lines = str(err.value).splitlines()
    assert any(line.startswith("sensor.yaml:15:") and "pseudo_counts are for forms categorical and table" in line
               for line in lines)
    assert any("shared names 'sd'" in line for line in lines)


# --- regressions: each found by trying to break the learner ---------------------------------------

def test_state_names_a_yaml_reader_would_misread_are_written_quoted(tmp_path):
    source = tmp_path / "switch.yaml"
    source.write_text("""\
bayesprog: 1
variables:
  R: {states: ["yes", "no"]}
  S: {states: ["on", "off", "007"]}
decomposition:
  - {term: P(R), form: table, table: [0.5, 0.5]}
  - term: P(S | R)
    form: table
    table: [[0.3, 0.3, 0.4], [0.3, 0.3, 0.4]]   # one row per state of R
""")
    data = tmp_path / "switch.csv"
    data.write_text("R,S\nyes,on\nyes,007\nno,off\nno,off\n")
    out = tmp_path / "fitted.yaml"
    assert main(["learn", str(source), str(data), "-o", str(out)]) == 0
    text = out.read_text()
    assert "# one row per state of R" in text  # the nested lists were updated in place
    fitted = bayesprog.load(out)
    np.testing.assert_allclose(fitted.term("P(S | R)").params["table"].array,
                               [[0.5, 0, 0.5], [0, 1, 0]])


def test_a_state_named_like_a_missing_value_is_a_state(tmp_path):
    program = bayesprog.loads("""\
bayesprog: 1
variables: {Region: {states: ["NA", "EU", "None"]}}
decomposition: [{term: P(Region), form: table, table: [0.2, 0.3, 0.5]}]
""")
    data = tmp_path / "regions.csv"
    data.write_text("Region\nNA\nNA\nNA\nEU\nNone\n\n")
    fit = program.fit(data)
    np.testing.assert_allclose(fit.program.term("P(Region)").params["table"].array, [0.6, 0.2, 0.2])
    assert fit.record.rows_used == 5


def test_a_row_with_more_fields_than_the_header_is_refused(tmp_path):
    data = tmp_path / "shifted.csv"
    data.write_text("M,E\nwood,0.1,7\nwood,0.3\n")
    with pytest.raises(DataError, match=r"row 1 \(line 2\): 3 fields, expected 2"):
        bayesprog.loads(NORMAL).fit(data)


def test_shared_sigma_and_a_shared_mean_are_maximum_likelihood():
    data = normal_data(20)
    text = NORMAL.replace("    sigma: 1.0", "    sigma: 1.0\n    learn: {shared: [sigma]}")
    params = bayesprog.loads(text).fit(data).program.term("P(E | M)").params
    groups = [data.loc[data["M"] == m, "E"].to_numpy() for m in ("wood", "silk", "felt")]
    pooled = sum(((g - g.mean()) ** 2).sum() for g in groups) / len(data)
    assert float(params["sigma"].array) == pytest.approx(np.sqrt(pooled), rel=1e-12)
    text = NORMAL.replace("    sigma: 1.0", "    sigma: 1.0\n    learn: {shared: [mean]}")
    params = bayesprog.loads(text).fit(data).program.term("P(E | M)").params

    def negative_log_likelihood(theta):  # one mean, a log-sigma per state
        return -sum(stats.norm.logpdf(g, theta[0], np.exp(t)).sum()
                    for g, t in zip(groups, theta[1:], strict=True))

    best = optimize.minimize(negative_log_likelihood, [0.5, -2, -2, -2], method="Nelder-Mead",
                             options={"xatol": 1e-10, "fatol": 1e-12, "maxiter": 20000})
    assert float(params["mean"].array) == pytest.approx(best.x[0], abs=1e-5)
    np.testing.assert_allclose(params["sigma"].array, np.exp(best.x[1:]), rtol=1e-4)


def test_values_far_from_zero_keep_their_precision():
    rng = np.random.default_rng(21)
    frame = pd.DataFrame({"M": ["wood"] * 50 + ["silk"] * 50 + ["felt"] * 50,
                          "E": 1.7e9 + rng.normal(0, 10, 150)})
    params = bayesprog.loads(NORMAL).fit(frame).program.term("P(E | M)").params
    for i in range(3):
        _, scale = stats.norm.fit(frame["E"].to_numpy()[50 * i: 50 * (i + 1)] - 1.7e9)
        assert params["sigma"].array[i] == pytest.approx(scale, rel=1e-6)


def test_complete_data_needs_no_starting_values_and_continuing_after_a_zero_works(tmp_path):
    source = tmp_path / "d.yaml"
    source.write_text(DISCRETE.replace("{a0: [0.5, 0.3, 0.2], a1: [0.1, 0.3, 0.6]}",
                                       "{a0: [1.0, 0.0, 0.0], a1: [0.0, 0.0, 1.0]}"))
    first = tmp_path / "first.csv"
    first.write_text("A,B,C\na0,b0,c0\na0,b0,c1\na1,b2,c1\na1,b2,c0\n")
    assert main(["learn", str(source), str(first), "-o", str(tmp_path / "f1.yaml")]) == 0
    more = tmp_path / "more.csv"
    more.write_text("A,B,C\na1,b0,c1\na0,b1,c0\n")  # cases the first fit gave probability 0
    assert main(["learn", str(tmp_path / "f1.yaml"), str(more), "-o", str(tmp_path / "f2.yaml"),
                 "--rounded"]) == 0
    table = bayesprog.load(tmp_path / "f2.yaml").term("P(B | A)").params["table"].array
    # six rows support 3 significant digits; each row still sums to one exactly as written
    np.testing.assert_array_equal(table, [[0.667, 0.333, 0], [0.333, 0, 0.667]])
    assert main(["learn", str(tmp_path / "f2.yaml"), str(more), "-o", str(tmp_path / "f3.yaml")]) == 2


def test_em_with_pseudo_counts_climbs_the_posterior_to_its_fixed_point():
    text = DISCRETE.replace("    table: {a0: [0.7, 0.3], a1: [0.2, 0.8]}",
                            "    table: {a0: [0.7, 0.3], a1: [0.2, 0.8]}\n"
                            "    learn: {pseudo_counts: 1}")
    data = discrete_data(22, n=300).drop(columns="A")
    program = bayesprog.loads(text)
    fit = program.fit(data, max_iter=5000, tol=1e-13)
    longer = program.fit(data, max_iter=20000, tol=0.0)
    for term in ("P(A)", "P(B | A)", "P(C | A)"):
        np.testing.assert_allclose(fit.program.term(term).params["table"].array,
                                   longer.program.term(term).params["table"].array, atol=1e-5)
    assert fit.converged and fit.record.iterations > 2


def test_variables_unrelated_to_the_data_are_not_enumerated():
    names = [f"Z{i}" for i in range(30)]  # 2^30 joint states if they were summed over
    declared = "".join(f"  {n}: {{states: [z0, z1]}}\n" for n in names)
    terms = "".join(f"  - {{term: P({n}), form: table, table: [0.5, 0.5], learn: false}}\n"
                    for n in names)
    text = NORMAL.replace("decomposition:\n", declared + "decomposition:\n") + terms
    fit = bayesprog.loads(text).fit(normal_data(23))
    assert fit.record.method == "maximum likelihood"
    direct = bayesprog.loads(NORMAL).fit(normal_data(23))
    assert fit.log_likelihood == pytest.approx(direct.log_likelihood, rel=1e-12)


def test_components_are_refused_beyond_one_per_value_and_bic_skips_what_cannot_be_fitted():
    x = gmm_data(24)[:60]
    with pytest.raises(DataError, match="200000 components for 60 values"):
        bayesprog.loads(GMM.replace("COMPONENTS", "200000")).fit({"X": x})
    fit = bayesprog.loads(GMM.replace("COMPONENTS", "[1, 2, 3, 200]")).fit({"X": x})
    assert "could not be fitted" in fit.record.method


def test_the_same_data_twice_is_refused_and_each_term_continues_from_its_own_last_fit(tmp_path):
    source = tmp_path / "sensor.yaml"
    source.write_text(NORMAL)
    parts = [normal_data(s, 120) for s in (25, 26, 27)]
    files = []
    for i, part in enumerate(parts):
        files.append(tmp_path / f"c{i}.csv")
        part.to_csv(files[-1], index=False)
    bayesprog.load(source).fit(files[0]).save(tmp_path / "f1.yaml")
    with pytest.raises(DataError, match="already learned"):
        bayesprog.load(tmp_path / "f1.yaml").fit(files[0])
    bayesprog.load(tmp_path / "f1.yaml").fit(files[1], freeze=["P(E | M)"]).save(
        tmp_path / "f2.yaml")
    last = bayesprog.load(tmp_path / "f2.yaml").fit(files[2])
    expected = bayesprog.loads(NORMAL).fit(pd.concat([parts[0], parts[2]]))
    np.testing.assert_allclose(last.program.term("P(E | M)").params["mean"].array,
                               expected.program.term("P(E | M)").params["mean"].array, rtol=1e-12)


def test_edited_statistics_are_refused_with_a_message(tmp_path):
    source = tmp_path / "sensor.yaml"
    source.write_text(NORMAL)
    bayesprog.load(source).fit(normal_data(28)).save(tmp_path / "f1.yaml")
    text = (tmp_path / "f1.yaml").read_text()
    start = text.index("count: [", text.index("P(E | M):\n", text.index("statistics:")))
    end = text.index("]", start)
    for bad, message in (("count: abc", "not an array of numbers"),
                         ("count: [1.0, -2.0, 3.0]", "negative"),
                         ("count: [1.0, 2.0]", "shape")):
        (tmp_path / "bad.yaml").write_text(text[:start] + bad + text[end + 1:])
        with pytest.raises(DataError, match=message):
            bayesprog.load(tmp_path / "bad.yaml").fit(normal_data(29))


def test_columns_of_other_names_are_read_as_the_variables_they_are_mapped_to(tmp_path, capsys):
    source = tmp_path / "sensor.yaml"
    source.write_text(NORMAL)
    data = normal_data(7)
    named = tmp_path / "named.csv"
    data.to_csv(named, index=False)
    other = tmp_path / "other.csv"
    data.rename(columns={"M": "material", "E": "texture"}).to_csv(other, index=False)
    assert main(["learn", str(source), str(named), "-o", str(tmp_path / "a.yaml")]) == 0
    assert main(["learn", str(source), str(other), "-o", str(tmp_path / "b.yaml"),
                 "--column", "material=M", "--column", "texture=E"]) == 0
    a, b = bayesprog.load(tmp_path / "a.yaml"), bayesprog.load(tmp_path / "b.yaml")
    for term in ("P(M)", "P(E | M)"):
        for name, value in a.term(term).params.items():
            np.testing.assert_array_equal(b.term(term).params[name].array, value.array)
    assert b.learned[-1].columns == {"material": "M", "texture": "E"}
    capsys.readouterr()
    for args, expected in ((["--column", "mat=M"], "no column 'mat' to read as M"),
                           (["--column", "material=X"], "the program has no variable 'X'"),
                           (["--column", "material"], "expected COLUMN=VARIABLE"),
                           ([], "the program has no variable 'material'")):
        assert main(["learn", str(source), str(other), "-o", str(tmp_path / "c.yaml"),
                     *args]) == 2
        err = capsys.readouterr().err
        assert expected in err and "Traceback" not in err, err


def test_a_variable_takes_the_states_of_its_data_and_is_learned_anew(tmp_path, capsys):
    source = tmp_path / "sensor.yaml"
    source.write_text(NORMAL)
    data = normal_data(11).replace({"M": {"wood": "cork", "silk": "steel", "felt": "foam"}})
    csv = tmp_path / "lab.csv"
    data.rename(columns={"M": "material"}).to_csv(csv, index=False)
    out = tmp_path / "lab.yaml"
    assert main(["learn", str(source), str(csv), "-o", str(out), "--column", "material=M",
                 "--states-from-data", "M"]) == 0
    lab = bayesprog.load(out)
    assert lab.variables["M"].states == ("cork", "foam", "steel")  # sorted, as written
    assert "# a comment the fitted file must keep" in out.read_text()
    # as a program declaring those states, fitted to the same data (values to their digits)
    declared = bayesprog.loads(NORMAL.replace("[wood, silk, felt]", "[cork, foam, steel]"))
    direct = declared.fit(data)
    for term in ("P(M)", "P(E | M)"):
        for name, value in direct.program.term(term).params.items():
            np.testing.assert_allclose(lab.term(term).params[name].array, value.array,
                                       rtol=2e-3, atol=1e-4)
    counts = data["M"].value_counts(normalize=True)
    np.testing.assert_allclose(lab.term("P(M)").params["table"].array,
                               [counts["cork"], counts["foam"], counts["steel"]], atol=1e-3)
    # a term over M that keeps its values cannot follow the new states
    capsys.readouterr()
    assert main(["learn", str(source), str(csv), "-o", str(tmp_path / "x.yaml"), "--column",
                 "material=M", "--states-from-data", "M", "--freeze", "P(M)"]) == 2
    assert "P(M) keeps its values" in capsys.readouterr().err


# --- bnlearn networks: pgmpy's tables, the plain CSV reader and the in-place writer ----------

EXAMPLES = Path(__import__("pgmpy").__file__).parent / "utils" / "example_models"


def _imported(tmp_path: Path, name: str, pseudo_counts: float | None) -> Path:
    """``bayesprog import`` of pgmpy's bnlearn network, its tables given pseudo-counts."""
    path = tmp_path / f"{name}.yaml"
    assert main(["import", str(EXAMPLES / f"{name}.bif.gz"), "-o", str(path)]) == 0
    if pseudo_counts is not None:
        text = path.read_text()
        learned = re.sub(r"(?m)^(\s*)form: table$",
                         rf"\1form: table\n\1learn: {{pseudo_counts: {pseudo_counts}}}", text)
        assert learned.count("pseudo_counts") == text.count("form: table")
        path.write_text(learned)
    return path


def _sampled(name: str, rows: int, seed: int = 1) -> pd.DataFrame:
    from pgmpy.sampling import BayesianModelSampling
    from pgmpy.utils import get_example_model

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = get_example_model(name)
        return BayesianModelSampling(model).forward_sample(size=rows, seed=seed,
                                                           show_progress=False).astype(str)


@pytest.mark.parametrize("name, rows, pseudo_counts", [
    ("asia", 10_000, None), ("asia", 10_000, 1.0), ("alarm", 10_000, None),
    ("alarm", 10_000, 0.5)])
def test_bnlearn_tables_equal_pgmpy_with_and_without_pseudo_counts(tmp_path, name, rows,
                                                                   pseudo_counts):
    """Maximum likelihood against pgmpy's DiscreteMLE, and the posterior mean under uniform
    Dirichlet pseudo-counts against its DiscreteBayesianEstimator, to 1e-12. Without
    pseudo-counts a table with a parent configuration no row shows is undefined (ours says
    so): those terms are frozen, the others compared."""
    from pgmpy.models import DiscreteBayesianNetwork
    from pgmpy.parameter_estimator import DiscreteBayesianEstimator, DiscreteMLE

    program = bayesprog.load(_imported(tmp_path, name, pseudo_counts))
    frame = _sampled(name, rows)
    csv = tmp_path / f"{name}.csv"
    frame.to_csv(csv, index=False)
    states = {n: list(v.states) for n, v in program.variables.items()}
    freeze = []
    if pseudo_counts is None:
        for term in program.terms:
            parents = [p.name for p in term.parents]
            seen = len(frame.groupby(parents).size()) if parents else 1
            if seen < math.prod(len(states[p]) for p in parents):
                freeze.append(str(term.expression))
        assert len(freeze) < len(program.terms) // 2
    fit = program.fit(csv, freeze=freeze)
    again = program.fit(frame, freeze=freeze)  # a data frame: the same counts
    network = DiscreteBayesianNetwork([(p.name, t.child.name) for t in program.terms
                                       for p in t.parents])
    network.add_nodes_from(program.variables)
    estimator = (DiscreteMLE(state_names=states) if pseudo_counts is None else
                 DiscreteBayesianEstimator(prior_type="dirichlet", pseudo_counts=pseudo_counts,
                                           state_names=states))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        logging.disable(logging.WARNING)
        try:
            cpds = {c.variable: c for c in estimator.fit(network, frame).parameters_}
        finally:
            logging.disable(logging.NOTSET)
    compared = 0
    for term in fit.program.terms:
        label = str(term.expression)
        if label in freeze:
            continue
        cpd = cpds[term.child.name]
        parents = [p.name for p in term.parents]
        # pgmpy's [child, *evidence] in its state order, to ours: [*parents, child]
        reference = np.transpose(np.asarray(cpd.values),
                                 [cpd.variables.index(p) for p in parents] + [0])
        for axis, var in enumerate([*parents, term.child.name]):
            reference = np.take(reference, [cpd.state_names[var].index(s) for s in states[var]],
                                axis=axis)
        ours = term.params["table"].array
        np.testing.assert_allclose(ours, reference, rtol=0, atol=1e-12, err_msg=label)
        np.testing.assert_array_equal(again.program.term(label).params["table"].array, ours)
        compared += 1
    assert compared == len(program.terms) - len(freeze)
    assert fit.record.log_likelihood == pytest.approx(again.record.log_likelihood, rel=1e-12)


def _csv_cases(rng: np.random.Generator) -> list[tuple[str, str]]:
    """CSV texts with what a plain reader could get wrong: long and non-ASCII values, a value
    first met late, empty cells, spaces after the delimiter, CRLF, a BOM, no final newline."""
    cases = []
    for case in range(12):
        names = ["short", "longer_than_eight", "a_value_longer_than_sixteen_bytes_x", "ünï"]
        states = {"A": ["y", "n"], "B": ["state_one", "state_two", "state_three"],
                  "C": [names[2] + str(i) for i in range(3)], "D": ["é", "日本", "ü" * 9]}
        rows = int(rng.choice([0, 1, 7, 1500, 2500]))
        lines = [", ".join(states) if case % 3 == 0 else ",".join(states)]
        for r in range(rows):
            cells = [rng.choice(v) if rng.random() > 0.05 else "" for v in states.values()]
            if case % 4 == 1 and r == rows - 1:
                cells[1] = "state_four"  # not among the first rows' values
            if case % 5 == 2:
                cells = [" " + c for c in cells]
            cells.append(repr(float(rng.normal())) if rng.random() > 0.1 else "")
            lines.append(",".join(str(c) for c in cells))
        lines[0] += ",X" if case % 3 else ", X"
        newline = "\r\n" if case % 2 else "\n"
        text = ("\ufeff" if case == 5 else "") + newline.join(lines)
        cases.append((text + (newline if case % 6 else ""), f"case{case}"))
    return cases


def test_plain_csv_reading_equals_the_csv_module(tmp_path, monkeypatch):
    """The numpy reader of plain CSV files codes every file as the csv module's reading does,
    errors included (the row and the value named), its columns coded one after the other or
    side by side on threads, or read ahead on a thread of its own."""
    import bayesprog.learning.data as data_module
    import bayesprog.learning.plain_csv as plain_module
    from bayesprog.learning.plain_csv import ReadAhead, read_plain_csv

    long = ", ".join(f"a_value_longer_than_sixteen_bytes_x{i}" for i in range(3))
    program = bayesprog.loads(f"""\
bayesprog: 1
variables:
  A: {{states: [y, n]}}
  B: {{states: [state_one, state_two, state_three]}}
  C: {{states: [{long}]}}
  D: {{states: [é, 日本, üüüüüüüüü]}}
  X: {{continuous: [-.inf, .inf]}}
decomposition:
  - {{term: P(A), form: table, table: [0.5, 0.5]}}
  - {{term: P(B), form: table, table: [0.3, 0.3, 0.4]}}
  - {{term: P(C), form: table, table: [0.3, 0.3, 0.4]}}
  - {{term: P(D), form: table, table: [0.3, 0.3, 0.4]}}
  - {{term: P(X), form: normal, mean: 0, sigma: 1}}
""")

    def read(path: Path | ReadAhead) -> tuple:
        try:
            data = data_module.load_data(path, program.variables)
        except DataError as exc:
            return ("error", str(exc))
        return (data.rows, {k: v.tolist() for k, v in data.discrete.items()},
                {k: np.nan_to_num(v, nan=-1e300).tolist() for k, v in data.continuous.items()})

    for text, name in _csv_cases(np.random.default_rng(4)):
        path = tmp_path / f"{name}.csv"
        path.write_bytes(text.encode("utf-8"))
        assert read_plain_csv(path.read_bytes(), ",") is not None, name  # the fast way is taken
        fast = read(path)
        assert read(ReadAhead(path)) == fast, name
        with monkeypatch.context() as patch:
            patch.setattr(plain_module, "read_plain_csv", lambda raw, sep, padded=False: None)
            assert read(path) == fast, name
            assert read(ReadAhead(path)) == fast, name  # not plain: read by the csv module
        with monkeypatch.context() as patch:  # its columns coded on several threads
            patch.setattr(plain_module, "THREADED_FIELDS", 0)
            patch.setattr(plain_module.os, "cpu_count", lambda: 3)
            assert read(path) == fast, name


def test_a_file_read_ahead_fails_as_the_file_read_then(tmp_path, monkeypatch):
    """Data read ahead on a thread give the fit and the errors the path gives: a missing
    file, a folder, a file that is not CSV, one with a bad value (its row named); what the
    thread raised is raised where the data are used."""
    import bayesprog.learning.plain_csv as plain_module
    from bayesprog.learning.plain_csv import ReadAhead

    program = bayesprog.loads("""\
bayesprog: 1
variables: {A: {states: [y, n]}, B: {states: [y, n]}}
decomposition:
  - {term: P(A), form: table, table: [0.5, 0.5]}
  - {term: P(B | A), form: table, table: [[0.5, 0.5], [0.5, 0.5]]}
""")
    good = tmp_path / "good.csv"
    good.write_text("A,B\ny,n\nn,n\ny,y\n")
    bad = tmp_path / "bad.csv"
    bad.write_text("A,B\ny,n\nmaybe,n\n")
    json_file = tmp_path / "d.json"
    json_file.write_text("{}")

    def outcome(source):
        try:
            fit = program.fit(source)
        except DataError as exc:
            return "error", str(exc)
        return fit.program.term("P(B | A)").params["table"].array.tolist(), fit.record.sha256

    for path in (good, bad, tmp_path / "missing.csv", tmp_path, json_file):
        assert outcome(ReadAhead(path)) == outcome(path), path
    assert outcome(ReadAhead(bad))[1] == f"{bad}: row 2 (line 3), column 'A': unknown state " \
        "'maybe' of A: expected one of y, n (on_bad_lines=\"skip\" sets bad rows aside)"

    def broken(path, threads):
        raise MemoryError("no room")

    monkeypatch.setattr(plain_module, "read_file", broken)
    with pytest.raises(MemoryError, match="no room"):
        program.fit(ReadAhead(good))


def test_numbers_are_replaced_where_they_stand_past_wide_characters(tmp_path, monkeypatch):
    """The writer finds each number as the loader reads the file: tables of numbers in the
    text (one on several lines, one after a word on its line), small ones and single numbers as
    YAML nodes, after comments in characters of several bytes and line ends other than a
    newline; what it writes loads as the round trip's file does."""
    import bayesprog.learning.inplace as inplace

    text = """\
# Modèle: 材料 et capteur (résumé ✓)
bayesprog: 1
variables:
  M: {states: [bois, soie, métal]}   # é, 日本
  S: {states: [lisse, rugueux]}
  E: {continuous: [-.inf, .inf]}
decomposition:
  - term: P(M)   # a priori: « uniforme »
    table: [0.3333333333333333, 0.3333333333333333, 0.3333333333333334]
  - {term: P(S | M), form: table, table: [[0.5, 0.5],
                                          [0.25, 0.75], [0.9, 0.1]]}
  - term: P(E | M)  # ✓ ✓
    form: normal
    mean: [0.0, 1.0, 2.0]   # bois, soie, métal
    sigma: [1.0, 1.0, 1.0]
"""
    text = text.replace("  - term: P(M)   # a priori", "  - form: table\n    term: P(M)   # a priori")
    # characters the YAML parser takes for line ends, which a text editor may not
    text = text.replace("bayesprog: 1\n", 'bayesprog: 1\ndescription: "Mesures\u2028du capteur'
                        '\x85(deux lignes)"\n')
    source = tmp_path / "capteur.yaml"
    source.write_text(text, encoding="utf-8")
    rng = np.random.default_rng(3)
    m = rng.choice(["bois", "soie", "métal"], 300, p=[0.2, 0.3, 0.5])
    rows = {"M": m.tolist(), "S": rng.choice(["lisse", "rugueux"], 300).tolist(),
            "E": (rng.normal(size=300) + (m == "soie")).tolist()}
    program = bayesprog.load(source)
    found = {}

    def keep(*args):
        found["spliced"] = spliced = splice(*args)
        return spliced

    splice = inplace.splice
    with monkeypatch.context() as patch:
        patch.setattr(inplace, "splice", keep)
        in_place = program.fit(rows).text()
    assert found["spliced"] is not None  # written in place, not by the round trip
    with monkeypatch.context() as patch:
        patch.setattr(inplace, "splice", lambda *args: None)
        round_trip = program.fit(rows).text()
    # every character but the numbers (and the record after them) as written
    assert re.sub(r"[-+.e0-9]+", "#", in_place.split("\n# Fits that set")[0]) == re.sub(
        r"[-+.e0-9]+", "#", text)
    ours, reference = bayesprog.loads(in_place), bayesprog.loads(round_trip)
    for term in reference.terms:
        for name, value in term.params.items():
            np.testing.assert_array_equal(ours.term(str(term.expression)).params[name].array,
                                          value.array)
    assert ours.term("P(S | M)").params["table"].array[2].tolist() != [0.9, 0.1]


def test_numbers_are_written_one_by_one_as_a_single_number_is():
    """The writer of many numbers at once (a table's, a statistic's rows) writes each as
    ``number`` does, the values that are not finite and the shortest round trips included."""
    from bayesprog.learning.inplace import _flow, _rows, number, numbers

    rng = np.random.default_rng(3)
    values = np.concatenate([rng.random(50), rng.normal(size=20) * 10.0 ** rng.integers(
        -30, 30, size=20), [0.0, -0.0, 1.0, 0.1, 1e16, 1e-5, 1 / 3, np.nan, np.inf, -np.inf]])
    one_by_one = [number(float(x)) for x in values]
    assert numbers(values) == one_by_one
    assert numbers(values.reshape(8, 10).tolist()) == one_by_one
    assert numbers(values[:50]) == [repr(float(x)) for x in values[:50]]
    assert _flow(values.tolist()) == "[" + ", ".join(one_by_one) + "]"
    assert _flow([1, 2.5, None]) == "[1, 2.5, null]"  # not all floats: item by item
    rows = values.reshape(2, 4, 10)
    written = _rows(rows.tolist(), 3, 0).replace("\n", "").replace(" ", "")
    assert written == _flow(rows.tolist()).replace(" ", "")


def test_tables_written_in_place_equal_the_round_trip_and_keep_the_file(tmp_path, monkeypatch):
    """A file of nested lists gets its numbers replaced where they stand (a comment inside a
    table stays); the values, and the record appended then continued, equal ruamel's round
    trip's."""
    import bayesprog.learning.inplace as inplace

    source = _imported(tmp_path, "asia", 1.0)
    lines = source.read_text().split("\n")
    first_table = next(i for i, line in enumerate(lines) if "table:" in line)
    lines[first_table] += "  # learned"  # a comment on a table's line, whatever its layout
    text = "\n".join(lines)
    source.write_text(text)
    frame = _sampled("asia", 3000)
    csvs = []
    for i, part in enumerate((frame[:2000], frame[2000:])):
        csvs.append(tmp_path / f"part{i}.csv")
        part.to_csv(csvs[-1], index=False)
    written = {}
    for way in ("in place", "round trip"):
        with monkeypatch.context() as patch:
            if way == "round trip":
                patch.setattr(inplace, "splice", lambda *args: None)
            first = tmp_path / f"first {way}.yaml"
            bayesprog.load(source).fit(csvs[0]).save(first)
            second = tmp_path / f"second {way}.yaml"
            bayesprog.load(first).fit(csvs[1]).save(second)
            written[way] = (first.read_text(), bayesprog.load(second))
    first, fitted = written["in place"]
    # outside the numbers and the record, the file as it was
    assert first.split("\n# Fits that set")[0].count("\n") == text.count("\n")
    assert first.split("\n")[first_table].endswith("  # learned")
    assert re.sub(r"[-+.e0-9]+", "#", first.split("\n# Fits that set")[0]) == re.sub(
        r"[-+.e0-9]+", "#", text.rstrip("\n") + "\n")
    reference = written["round trip"][1]
    for term in reference.terms:
        np.testing.assert_array_equal(fitted.term(str(term.expression)).params["table"].array,
                                      term.params["table"].array)
    assert [r.as_data() for r in fitted.learned] == [r.as_data() for r in reference.learned]
    assert len(fitted.learned) == 2 and fitted.learned[-1].rows_supporting == 3000
