"""Structure learning: the scores and tests against pgmpy's, hill climbing and PC against
pgmpy's searches, recovery of known networks, missing values, constraints, the discovered
program as a file, and the evidence of a program against brute-force integration."""

from __future__ import annotations

import hashlib
import itertools
import json
import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import bayesprog
from bayesprog.cli import main
from bayesprog.learning.structure import (
    Constraints,
    Scores,
    ci_test,
    hill_climb,
    pc_skeleton,
)
from bayesprog.program.discovery import StructureWarning, code_data


def _sample(name: str, rows: int, seed: int = 1) -> tuple[pd.DataFrame, object]:
    from pgmpy.sampling import BayesianModelSampling
    from pgmpy.utils import get_example_model

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = get_example_model(name)
        frame = BayesianModelSampling(model).forward_sample(size=rows, seed=seed,
                                                            show_progress=False)
    return frame.astype(str), model


@pytest.fixture(scope="module")
def asia():
    return _sample("asia", 4000)


@pytest.fixture(scope="module")
def child():
    return _sample("child", 5000)


def _coded(frame: pd.DataFrame):
    coded = code_data(frame)
    return coded, list(coded.names)


def run(capsys, *args) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


# scores and tests against pgmpy --------------------------------------------------------------

@pytest.mark.parametrize("score", ["bic", "bdeu", "k2"])
def test_family_and_dag_scores_equal_pgmpys(child, score):
    from pgmpy.estimators import BIC, K2, BDeu

    frame, model = child
    coded, names = _coded(frame)
    ours = Scores(coded.codes, coded.card, score, ess=5.0)
    theirs = {"bic": BIC(frame), "bdeu": BDeu(frame, equivalent_sample_size=5.0),
              "k2": K2(frame)}[score]
    rng = np.random.default_rng(3)
    for _ in range(25):
        child_index = int(rng.integers(len(names)))
        others = [i for i in range(len(names)) if i != child_index]
        parents = tuple(sorted(int(i) for i in rng.choice(others, int(rng.integers(0, 4)),
                                                          replace=False)))
        expected = theirs.local_score(names[child_index], [names[p] for p in parents])
        assert ours.local(child_index, parents) == pytest.approx(expected, rel=1e-12, abs=1e-9)
    parents = [[names.index(p) for p in model.get_parents(v)] for v in names]
    assert ours.total(parents) == pytest.approx(theirs.score(model), rel=1e-12, abs=1e-9)


def test_the_k2_closed_form_differs_from_pgmpys_k2_only_by_absent_configurations(child):
    """pgmpy's K2 counts every parent configuration in the prior's term and only those with
    rows in the counts' term: ``log Gamma(r)`` more per configuration without rows. The
    closed form (the evidence, checked against integration below) adds nothing for them."""
    from math import lgamma

    from bayesprog.learning.structure import K2_EXACT

    frame, _ = child
    coded, names = _coded(frame)
    pgmpy_like = Scores(coded.codes, coded.card, "k2")
    exact = Scores(coded.codes, coded.card, K2_EXACT)
    found_absent = False
    for c, p1, p2 in itertools.islice(itertools.permutations(range(len(names)), 3), 300):
        parents = tuple(sorted((p1, p2)))
        absent = int((pgmpy_like.counts(c, parents).sum(axis=1) == 0).sum())
        found_absent |= absent > 0
        assert pgmpy_like.local(c, parents) - exact.local(c, parents) == pytest.approx(
            absent * lgamma(int(coded.card[c])), abs=1e-9)
    assert found_absent


@pytest.mark.parametrize("test", ["chi2", "g"])
def test_independence_tests_equal_pgmpys(child, test):
    from pgmpy.estimators.CITests import chi_square, g_sq

    frame, _ = child
    coded, names = _coded(frame)
    reference = {"chi2": chi_square, "g": g_sq}[test]
    rng = np.random.default_rng(4)
    for _ in range(25):
        x, y = (int(i) for i in rng.choice(len(names), 2, replace=False))
        rest = [i for i in range(len(names)) if i not in (x, y)]
        given = [int(i) for i in rng.choice(rest, int(rng.integers(0, 3)), replace=False)]
        statistic, dof, p = ci_test(coded.codes, coded.card, x, y, given, test)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            expected = reference(names[x], names[y], [names[g] for g in given], frame,
                                 boolean=False)
        assert statistic == pytest.approx(expected[0], rel=1e-9, abs=1e-9)
        assert dof == expected[2]
        assert p == pytest.approx(expected[1], rel=1e-6, abs=1e-12)


# the searches against pgmpy's ---------------------------------------------------------------

@pytest.mark.parametrize("name", ["asia", "child"])
def test_hill_climbing_scores_at_least_as_well_as_pgmpys(name, asia, child):
    from pgmpy.estimators import BIC, HillClimbSearch

    frame, _ = asia if name == "asia" else child
    coded, names = _coded(frame)
    scores = Scores(coded.codes, coded.card, "bic")
    ours = hill_climb(scores, Constraints(len(names)))
    # each family's score was computed once, and the search applied operations
    assert ours.iterations > 0 and ours.families_scored == len(scores.cache)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        theirs = HillClimbSearch(frame).estimate(scoring_method=BIC(frame), show_progress=False)
    their_parents = [[names.index(p) for p in theirs.predecessors(v)] for v in names]
    assert ours.score >= scores.total(their_parents) - 1e-6
    # and by pgmpy's own scorer
    assert _pgmpy_bic(frame, names, ours.parents) >= _pgmpy_bic(frame, names, their_parents) - 1e-6


def _pgmpy_bic(frame: pd.DataFrame, names: list[str], parents) -> float:
    from pgmpy.estimators import BIC
    from pgmpy.models import DiscreteBayesianNetwork

    model = DiscreteBayesianNetwork()
    model.add_nodes_from(names)
    model.add_edges_from((names[u], names[v]) for v, ps in enumerate(parents) for u in ps)
    return float(BIC(frame).score(model))


def test_discovery_scores_at_least_as_well_as_pyagrums_greedy_search(child):
    """pyAgrum's BNLearner (greedy hill climbing on BIC, a negligible smoothing prior for the
    parent configurations the data never show), its DAG scored by pgmpy's BIC as ours."""
    gum = pytest.importorskip("pyagrum")
    frame, _ = child
    learner = gum.BNLearner(frame)
    learner.useGreedyHillClimbing()
    learner.useScoreBIC()
    learner.useSmoothingPrior(1e-6)
    bn = learner.learnBN()
    names = list(frame.columns)
    theirs = [[names.index(bn.variable(p).name()) for p in bn.parents(bn.idFromName(v))]
              for v in names]
    found = bayesprog.discover(frame)
    ours = [[names.index(p) for p in found.parents[v]] for v in names]
    assert _pgmpy_bic(frame, names, ours) >= _pgmpy_bic(frame, names, theirs) - 1e-6


@pytest.mark.parametrize("name, rows", [("asia", 4000), ("survey", 3000), ("cancer", 2000)])
def test_pc_skeleton_equals_pgmpys_on_the_same_data_and_test(name, rows):
    from pgmpy.estimators import PC

    frame, _ = _sample(name, rows)
    coded, names = _coded(frame)
    ours = pc_skeleton(coded.codes, coded.card, Constraints(len(names)), test="chi2",
                       significance=0.01)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        skeleton, _ = PC(frame).build_skeleton(ci_test="chi_square", significance_level=0.01,
                                               show_progress=False)
    our_edges = {frozenset((names[u], names[v])) for u in range(len(names))
                 for v in ours.adjacent[u]}
    assert our_edges == {frozenset(e) for e in skeleton.edges()}


def _skeleton_errors(parents: dict[str, list[str]], model) -> tuple[int, int]:
    found = {frozenset((c, p)) for c, ps in parents.items() for p in ps}
    true = {frozenset(e) for e in model.edges()}
    return len(found - true), len(true - found)


def test_known_networks_are_recovered_with_few_skeleton_errors(child):
    frame, model = child
    for method in ("hc", "pc"):
        found = bayesprog.discover(frame, method=method)
        extra, missing = _skeleton_errors(found.parents, model)
        # child has 25 arcs; the errors, reported here, stay few
        print(f"child, {method}: {extra} extra and {missing} missing edges of 25")
        assert extra + missing <= 6, (method, extra, missing)


# the discovered program --------------------------------------------------------------------

def test_a_discovered_program_validates_answers_and_is_relearned(tmp_path, asia, capsys):
    frame, _ = asia
    frame.iloc[:3000].to_csv(tmp_path / "asia.csv", index=False)
    frame.iloc[3000:].to_csv(tmp_path / "more.csv", index=False)
    code, out, err = run(capsys, "discover", tmp_path / "asia.csv", "-o", tmp_path / "asia.yaml")
    assert code == 0, err
    assert "wrote" in out and "arcs" in out
    assert run(capsys, "validate", tmp_path / "asia.yaml")[0] == 0
    text = (tmp_path / "asia.yaml").read_text()
    record = bayesprog.load(tmp_path / "asia.yaml").learned[0]
    assert record.structure is not None and record.structure.method == "hc"
    assert record.structure.score == "bic" and record.structure.iterations > 0
    assert record.structure.missing == "none"

    assert record.sha256 == hashlib.sha256((tmp_path / "asia.csv").read_bytes()).hexdigest()
    assert "structure:" in text
    code, out, _ = run(capsys, "query", tmp_path / "asia.yaml", "P(lung | smoke=yes)", "--json")
    assert code == 0
    answer = json.loads(out)["probabilities"]
    smokers = frame.iloc[:3000][frame.iloc[:3000]["smoke"] == "yes"]
    assert answer[1] == pytest.approx((smokers["lung"] == "yes").mean(), abs=0.02)
    code, _, err = run(capsys, "learn", tmp_path / "asia.yaml", tmp_path / "more.csv", "-o",
                       tmp_path / "more.yaml")
    assert code == 0, err
    assert len(bayesprog.load(tmp_path / "more.yaml").learned) == 2


def test_the_written_record_is_the_search_record(asia, monkeypatch):
    """The fit's record, the search's in it, is written with the fitted values in place: the
    file reads back as the record (constraints, lists, numbers), and so does the round trip's
    writing of it, where the text cannot be written in place."""
    frame, _ = asia
    found = bayesprog.discover(frame, forbid=["lung->either"], require=["asia->dysp"],
                               tiers=[["asia", "smoke"]], max_parents=3)
    assert bayesprog.loads(found.text).learned[-1] == found.record
    assert found.record.structure.constraints["max_parents"] == 3
    assert "    structure: {method: hc," in found.text  # written in place
    monkeypatch.setattr("bayesprog.learning.inplace.splice", lambda *args: None)
    again = bayesprog.discover(frame, forbid=["lung->either"], require=["asia->dysp"],
                               tiers=[["asia", "smoke"]], max_parents=3)
    assert bayesprog.loads(again.text).learned[-1] == again.record
    assert "    structure:\n      method: hc\n" in again.text  # by the round trip
    assert again.parents == found.parents


def test_the_tables_are_the_posterior_mean_under_the_prior_written(asia):
    frame, _ = asia
    with warnings.catch_warnings():  # an arc into either, a function of tub and lung
        warnings.simplefilter("ignore", StructureWarning)
        found = bayesprog.discover(frame, method="hc", score="bdeu", equivalent_sample_size=4)
    program = found.program
    for term in program.terms:
        if term.parents:
            continue
        name = term.child.name
        states = program.variables[name].states
        counts = np.array([(frame[name] == s).sum() for s in states], dtype=float)
        expected = (counts + 4 / len(states)) / (counts.sum() + 4)
        np.testing.assert_allclose(program.table(str(term.expression)).to_numpy().ravel(),
                                   expected, rtol=1e-3)


def test_missing_values_are_used_per_family_and_said(asia):
    frame, _ = asia
    holed = frame.copy()
    rng = np.random.default_rng(5)
    for column in ("smoke", "xray"):
        holed.loc[rng.random(len(holed)) < 0.2, column] = None
    coded = code_data(holed)
    names = coded.names
    scores = Scores(coded.codes, coded.card, "bic")
    from pgmpy.estimators import BIC

    x, p = names.index("xray"), names.index("smoke")
    available = holed[["xray", "smoke"]].dropna()
    expected = BIC(available).local_score("xray", ["smoke"])
    assert scores.local(x, (p,)) == pytest.approx(expected, rel=1e-12)
    found = bayesprog.discover(holed, method="hc")
    assert "available-case" in found.record.structure.missing
    assert str((holed.isna().any(axis=1)).sum()) in found.record.structure.missing
    assert found.record.method.startswith("EM")



@pytest.mark.parametrize("text", [
    "A,B,C\nyes,1.50,x\nno,2,\nyes, 1.50,y\n,2,x\nno,10,y\n",  # blanks, numbers as written
    "A,B\n\"a,1\",u\nb,v\n\"a,1\",v\nb,u\n",  # quoted: read by the csv module
    "A\tB\nx\t1\ny\t2\nx\t2\n",  # tab-separated
])
def test_a_csv_file_is_coded_as_its_rows_read_by_the_csv_module(tmp_path, text):
    from bayesprog.learning.data import read_frame

    path = tmp_path / ("d.tsv" if "\t" in text else "d.csv")
    path.write_text(text)
    coded, frame = code_data(path, columns={"A": "first"}), read_frame(path)[0]
    expected = code_data(frame, columns={"A": "first"})  # the cells as the csv module reads them
    assert coded.names == expected.names == ["first", *frame.columns[1:]]
    assert coded.states == expected.states
    np.testing.assert_array_equal(coded.codes, expected.codes)
    assert coded.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()
    assert coded.source == str(path)

def _frames() -> dict[str, pd.DataFrame]:
    rng = np.random.default_rng(3)
    n = 60
    return {
        "str": pd.DataFrame({"a": rng.choice(["x", "y", "z"], n),
                             "b": rng.choice(["p", "q"], n)}).astype(str),
        "object with nulls": pd.DataFrame({"a": pd.Series(["x", None, "y", np.nan, "x"] * 12,
                                                          dtype=object)}),
        "str with nulls and blanks": pd.DataFrame({"a": pd.Series(["x", None, "y", "", "é"] * 12,
                                                                  dtype="str")}),
        "string, python storage": pd.DataFrame({"a": pd.Series(
            ["x", None, "y", "x"] * 15, dtype=pd.StringDtype("python"))}),
        "object, pd.NA and numpy's nan": pd.DataFrame({"a": pd.Series(
            ["x", pd.NA, "y", np.float64("nan")] * 15, dtype=object)}),
        "integers": pd.DataFrame({"a": rng.integers(0, 3, n), "b": rng.integers(-2, 2, n)}),
        "floats, nan and -0": pd.DataFrame({"a": [0.0, -0.0, 1.0, np.nan] * 15}),
        "booleans": pd.DataFrame({"a": rng.random(n) < 0.5, "b": rng.choice(["u", "v"], n)}),
        "True, 1, 1.0 and '1'": pd.DataFrame({"a": pd.Series([True, 1, 1.0, "1", None] * 12,
                                                             dtype=object)}),
        "Python integers as objects": pd.DataFrame({"a": pd.Series(
            rng.integers(-1, 3, n).tolist(), dtype=object)}),
        "numpy integers as objects": pd.DataFrame({"a": pd.Series(
            list(rng.integers(0, 3, n)), dtype=object)}),
        "Python booleans as objects": pd.DataFrame({"a": pd.Series(
            (rng.random(n) < 0.5).tolist(), dtype=object)}),
        "integers and None as objects": pd.DataFrame({"a": pd.Series(
            [1, None, 2, 1, 3] * 12, dtype=object)}),
        "categorical": pd.DataFrame({"a": pd.Categorical(rng.choice(["u", "v"], n)),
                                     "b": rng.choice(["x", "y"], n)}),
        "shuffled index": pd.DataFrame({"a": rng.choice(["x", "y"], n),
                                        "b": rng.integers(0, 3, n)}, index=rng.permutation(n)),
    }


@pytest.mark.parametrize("name", list(_frames()))
def test_a_frames_hash_read_from_its_codes_is_pandas_hash_of_the_frame(name):
    """A data frame's columns are coded once and its SHA-256 read from the codes (each string
    hashed once): the digest of pandas' hash of the whole frame, as learning records it."""
    from bayesprog.learning.data import read_frame

    frame = _frames()[name]
    expected = hashlib.sha256(pd.util.hash_pandas_object(frame, index=False).to_numpy()
                              .tobytes()).hexdigest()
    assert read_frame(frame).sha256 == expected
    coded = code_data(frame)
    assert coded.sha256 == expected
    assert coded.source == "<data frame>"
    # the rows as their states' names, made when read
    for j, column in enumerate(coded.names):
        names = np.array([*coded.states[j], None], dtype=object)[coded.codes[:, j]]
        assert coded.frame[column].astype(object).where(coded.frame[column].notna(),
                                                        None).tolist() == names.tolist()


@pytest.mark.parametrize("name", list(_frames()))
def test_a_frames_columns_are_coded_as_they_are_read_value_by_value(name, monkeypatch):
    """Pandas codes a column of one kind of value (strings, integers, booleans) at once; the
    states and the rows' codes are those of reading it value by value, each value's text a
    state (``True``, ``1`` and ``1.0`` two of them: ``true`` and ``1``)."""
    import bayesprog.program.discovery as discovery

    frame = _frames()[name]
    coded = code_data(frame)
    if frame.iloc[:, 0].dtype == object and "True, 1" not in name:
        assert discovery._distinct(frame.iloc[:, 0])[0].max() < 10  # coded, not row by row
    monkeypatch.setattr(discovery, "_distinct", lambda values: (
        np.arange(len(values)), list(values.to_numpy(dtype=object))))
    slow = code_data(frame)
    assert coded.states == slow.states
    np.testing.assert_array_equal(coded.codes, slow.codes)


def _random_dag(n: int, arcs: int, rng: np.random.Generator) -> list[list[int]]:
    order = rng.permutation(n)
    parents: list[list[int]] = [[] for _ in range(n)]
    while sum(map(len, parents)) < arcs:
        a, b = sorted(int(i) for i in rng.choice(n, 2, replace=False))
        u, v = int(order[a]), int(order[b])
        if u not in parents[v]:
            parents[v].append(u)
    return parents


@pytest.mark.parametrize("score", ["bic", "bdeu", "k2"])
def test_move_gains_equal_pgmpys_scores_recomputed(child, score):
    """The change of score of each move that the climb reads (kept up to date, counted as bit
    sets or row by row) against pgmpy's family scores computed from scratch."""
    from pgmpy.estimators import BIC, K2, BDeu

    frame, model = child
    coded, names = _coded(frame)
    n = len(names)
    theirs = {"bic": BIC(frame), "bdeu": BDeu(frame, equivalent_sample_size=5.0),
              "k2": K2(frame)}[score]
    rng = np.random.default_rng(11)
    graphs = [[[] for _ in names], [[names.index(p) for p in model.get_parents(v)] for v in names],
              _random_dag(n, 30, rng)]
    scores = Scores(coded.codes, coded.card, score, ess=5.0)
    for parents in graphs if score == "bic" else graphs[1:2]:
        gain = scores.gains(parents)
        for _ in range(25):
            u, v = (int(i) for i in rng.choice(n, 2, replace=False))
            family = set(parents[v]) ^ {u}
            expected = (theirs.local_score(names[v], [names[p] for p in sorted(family)])
                        - theirs.local_score(names[v], [names[p] for p in parents[v]]))
            assert gain[u, v] == pytest.approx(expected, rel=1e-9, abs=1e-7), (u, v)
        assert np.all(np.diag(gain) == 0)


def test_move_gains_with_missing_values_are_counted_alike_both_ways(asia, monkeypatch):
    """Rows missing a value: each family is scored on the rows where all its variables are
    observed, whether its counts come from bit sets or from the distinct rows (the bit sets
    turned off), and as pgmpy scores those rows."""
    from pgmpy.estimators import BIC

    from bayesprog.learning import _score_kernels as kernels

    frame, _ = asia
    holed = frame.copy()
    rng = np.random.default_rng(6)
    for column in ("smoke", "xray", "lung"):
        holed.loc[rng.random(len(holed)) < 0.15, column] = None
    coded, names = _coded(holed)
    n = len(names)
    by_bits = Scores(coded.codes, coded.card)
    monkeypatch.setattr(kernels, "BITS_LIMIT", 0)
    by_rows = Scores(coded.codes, coded.card)
    assert by_bits._data[3].shape[1] > 0 and by_rows._data[3].shape[1] == 0
    for parents in ([[] for _ in names], _random_dag(n, 12, rng)):
        gain = by_bits.gains(parents)
        np.testing.assert_allclose(gain, by_rows.gains(parents), rtol=1e-12, atol=1e-9)
        for v in range(n):
            u = int(rng.choice([i for i in range(n) if i != v]))
            family = sorted(set(parents[v]) ^ {u})

            def pgmpy(ps: list[int], v: int = v) -> float:
                columns = [names[v], *(names[p] for p in ps)]
                return BIC(holed[columns].dropna()).local_score(names[v], columns[1:])

            assert gain[u, v] == pytest.approx(pgmpy(family) - pgmpy(list(parents[v])),
                                               rel=1e-9, abs=1e-7)


def test_the_climb_stops_where_no_move_gains(child):
    """From the graph hill climbing returns (no tabu steps past the optimum, no restarts), no
    addition, deletion or reversal that keeps the graph acyclic raises the score by epsilon."""
    import networkx as nx

    frame, _ = child
    coded, names = _coded(frame)
    n = len(names)
    scores = Scores(coded.codes, coded.card)
    found = hill_climb(scores, Constraints(n), restarts=0, patience=0)
    parents = [list(ps) for ps in found.parents]
    assert found.score == pytest.approx(scores.total(parents), abs=1e-6)
    gain = scores.gains(parents)
    graph = nx.DiGraph([(u, v) for v, ps in enumerate(parents) for u in ps])
    graph.add_nodes_from(range(n))
    for u, v in itertools.permutations(range(n), 2):
        if u in parents[v]:
            assert gain[u, v] < 1e-4  # deletion
            graph.remove_edge(u, v)
            if not nx.has_path(graph, u, v):  # reversal
                assert gain[u, v] + gain[v, u] < 1e-4
            graph.add_edge(u, v)
        elif v not in parents[u] and not nx.has_path(graph, v, u):
            assert gain[u, v] < 1e-4  # addition


def test_many_variables_and_many_states_are_scored_as_counted():
    """Past 64 variables a family's key takes more words; past 127 states the rows are kept as
    int32: the scores still equal those of the counts, and the climb's its families' sum."""
    rng = np.random.default_rng(8)
    codes = rng.integers(0, 2, size=(300, 70))
    codes[:, 1] = np.where(rng.random(300) < 0.9, codes[:, 0], 1 - codes[:, 0])  # dependent
    codes[:, 69] = rng.integers(0, 200, 300)
    codes[rng.random(300) < 0.05, 68] = -1
    card = [2] * 69 + [200]
    scores = Scores(codes, card)
    found = hill_climb(scores, Constraints(70), restarts=1)
    assert found.score == pytest.approx(scores.total(found.parents), abs=1e-9)
    assert 0 in found.parents[1] or 1 in found.parents[0]
    for (child, parents), value in itertools.islice(scores.cache.items(), 40):
        counts = scores.counts(child, parents).astype(float)
        totals = counts.sum(axis=1, keepdims=True)
        safe = np.where(counts > 0, counts, 1.0)
        ll = float(np.sum(counts * np.log(safe / np.where(totals > 0, totals, 1.0))))
        q, r = counts.shape
        assert value == pytest.approx(ll - 0.5 * np.log(counts.sum()) * q * (r - 1), rel=1e-12)
    for parents in [(69,), (68, 69), (3, 68)]:
        assert Scores(codes, card).local(0, parents) == pytest.approx(
            scores.local(0, parents), rel=1e-12)


def test_distinct_rows_and_their_numbers_are_the_data():
    from bayesprog.learning._score_kernels import distinct_rows

    rng = np.random.default_rng(2)
    codes = rng.integers(-1, 3, size=(500, 4)).astype(np.int8)
    rows, weights = distinct_rows(codes)
    assert weights.sum() == 500 and len({tuple(r) for r in rows.T}) == rows.shape[1]
    found = {tuple(r): int(w) for r, w in zip(rows.T, weights, strict=True)}
    unique, counts = np.unique(codes, axis=0, return_counts=True)
    assert found == {tuple(r): int(c) for r, c in zip(unique, counts, strict=True)}


def test_discovery_is_the_same_for_the_same_seed(asia):
    frame, _ = asia
    first = bayesprog.discover(frame, seed=4, restarts=3)
    assert bayesprog.discover(frame, seed=4, restarts=3).parents == first.parents


def test_restarts_are_seeded_and_never_worse(child):
    frame, _ = child
    coded, names = _coded(frame)
    plain = hill_climb(Scores(coded.codes, coded.card), Constraints(len(names)), restarts=0)
    once = hill_climb(Scores(coded.codes, coded.card), Constraints(len(names)), restarts=2,
                      seed=7)
    again = hill_climb(Scores(coded.codes, coded.card), Constraints(len(names)), restarts=2,
                       seed=7)
    assert once.parents == again.parents and once.score == again.score
    assert once.score >= plain.score - 1e-9


# constraints -------------------------------------------------------------------------------

def test_constraints_are_kept(asia, tmp_path):
    frame, _ = asia
    free = bayesprog.discover(frame)
    arc = next((p, c) for c, ps in free.parents.items() for p in ps)
    forbidden = bayesprog.discover(frame, forbid=[f"{arc[0]}->{arc[1]}"])
    assert arc[0] not in forbidden.parents[arc[1]]
    required = bayesprog.discover(frame, require=["asia->dysp"])
    assert "asia" in required.parents["dysp"]
    (tmp_path / "tiers.txt").write_text("dysp, xray\nasia smoke\n")
    tiered = bayesprog.discover(frame, tiers=tmp_path / "tiers.txt")
    early = {"dysp", "xray"}
    for c, ps in tiered.parents.items():
        if c in early:
            assert set(ps) <= early, (c, ps)
    capped = bayesprog.discover(frame, max_parents=1)
    assert max(len(ps) for ps in capped.parents.values()) <= 1
    for method in ("hc", "pc"):
        found = bayesprog.discover(frame, method=method, require=["asia->dysp"],
                                   forbid=["lung->either"])
        assert "asia" in found.parents["dysp"] and "lung" not in found.parents["either"]


def test_hill_climbing_starts_from_a_program(asia, tmp_path):
    frame, _ = asia
    found = bayesprog.discover(frame)
    found.save(tmp_path / "found.yaml")
    again = bayesprog.discover(frame, start=tmp_path / "found.yaml", restarts=0)
    # from the graph found, the search only looks past it: no worse, in a few steps
    assert again.record.structure.score_value >= found.record.structure.score_value - 1e-6
    assert again.record.structure.iterations < found.record.structure.iterations
    arc = next(f"{p}->{c}" for c, ps in found.parents.items() for p in ps)
    with pytest.raises(bayesprog.BayesprogError, match=f"the arc {arc.replace('->', ' -> ')} "
                       "is required .or in the starting program. and forbidden"):
        bayesprog.discover(frame, start=tmp_path / "found.yaml", forbid=[arc])
    assert again.record.structure.constraints["start"].endswith("found.yaml")


@pytest.mark.parametrize("args, said", [
    (["--forbid", "asia->tub", "--require", "asia->tub"], "both forbidden"),
    (["--require", "asia->tub", "--require", "tub->either", "--require", "either->asia"],
     "make a cycle"),
    (["--require", "nowhere->tub"], "no variable 'nowhere'"),
    (["--forbid", "asia"], "expected an arc A->B"),
    (["--method", "pc", "--max-parents", "2"], "applies to hill climbing"),
    (["--significance", "1.5", "--method", "pc"], "--significance"),
    (["--discretise", "1"], "--discretise"),
    (["--forbid", "asia-"], "quote the arc"),
    (["--method", "pc", "--score", "bdeu"], "--score applies to hill climbing"),
])
def test_contradictory_or_bad_constraints_are_user_errors(asia, tmp_path, capsys, args, said):
    frame, _ = asia
    frame.to_csv(tmp_path / "asia.csv", index=False)
    code, out, err = run(capsys, "discover", tmp_path / "asia.csv", "-o", tmp_path / "x.yaml",
                         *args)
    assert code == 2 and not out and said in err and "Traceback" not in err
    assert not (tmp_path / "x.yaml").exists()


def test_a_family_beyond_the_size_limit_is_refused_before_the_search(tmp_path, capsys):
    rng = np.random.default_rng(0)
    frame = pd.DataFrame({f"V{i}": rng.choice(["a", "b"], 50) for i in range(24)})
    frame.to_csv(tmp_path / "wide.csv", index=False)
    requires = [x for i in range(1, 24) for x in ("--require", f"V{i}->V0")]
    code, out, err = run(capsys, "discover", tmp_path / "wide.csv", "-o", tmp_path / "x.yaml",
                         *requires)
    assert code == 2 and "family of V0" in err and "16,777,216 cells" in err


def test_tiers_against_a_required_arc_are_refused(asia, tmp_path):
    frame, _ = asia
    with pytest.raises(bayesprog.BayesprogError, match="forbidden"):
        bayesprog.discover(frame, tiers=[["dysp"], ["asia"]], require=["asia->dysp"])


# bad data ----------------------------------------------------------------------------------

@pytest.mark.parametrize("column, said", [
    (["a"] * 30, "holds one value"),
    ([f"id{i}" for i in range(30)], "a different value in each"),
    ([None] * 30, "no value"),
])
def test_columns_that_cannot_be_variables_are_refused(tmp_path, capsys, column, said):
    rng = np.random.default_rng(0)
    frame = pd.DataFrame({"A": rng.choice(["x", "y"], 30), "B": rng.choice(["u", "v"], 30),
                          "Bad": column})
    frame.to_csv(tmp_path / "d.csv", index=False)
    code, out, err = run(capsys, "discover", tmp_path / "d.csv", "-o", tmp_path / "x.yaml")
    assert code == 2 and "'Bad'" in err and said in err and "Traceback" not in err


def test_a_column_of_many_numbers_asks_to_be_binned():
    rng = np.random.default_rng(3)
    frame = pd.DataFrame({"T": np.round(rng.normal(20, 5, 400), 1),
                          "R": rng.choice(["dry", "wet"], 400)})
    with pytest.raises(bayesprog.BayesprogError, match="different numbers.*--discretise"):
        bayesprog.discover(frame)
    assert len(bayesprog.discover(frame, discretise=4).program.variables["T"].states) == 4


def test_bundled_data_is_found_by_its_name(tmp_path, capsys):
    code, out, err = run(capsys, "discover", "probes", "-o", tmp_path / "p.yaml",
                         "--discretise", "3")
    assert code == 0, err
    assert bayesprog.load(tmp_path / "p.yaml").learned[0].data.endswith("probes.csv")


def test_a_hidden_variable_is_refused_clearly(tmp_path, asia):
    frame, _ = asia
    (tmp_path / "start.yaml").write_text(
        "bayesprog: 1\nvariables: {H: {states: [h0, h1]}, asia: {states: ['no', 'yes']}}\n"
        "decomposition:\n  - {term: P(H), form: table, table: [0.5, 0.5]}\n"
        "  - {term: P(asia | H), form: table, table: [0.5, 0.5]}\n")
    with pytest.raises(bayesprog.BayesprogError, match="hidden variable is out of scope"):
        bayesprog.discover(frame, start=tmp_path / "start.yaml")


def test_numbers_are_states_as_written_or_binned():
    rng = np.random.default_rng(1)
    x = rng.normal(size=400)
    frame = pd.DataFrame({"N": rng.choice([1, 2, 10], 400), "X": x,
                          "Y": np.where(x + rng.normal(scale=0.3, size=400) > 0, "hi", "lo")})
    with pytest.raises(bayesprog.BayesprogError, match="different value in each"):
        bayesprog.discover(frame)
    found = bayesprog.discover(frame, discretise=3)
    assert found.program.variables["N"].states == ("1", "2", "10")  # by value, as written
    assert len(found.program.variables["X"].states) == 3
    assert found.program.variables["X"].states[0].startswith("[")
    edges = found.record.structure.discretised["X"]
    assert edges[0] == pytest.approx(x.min()) and edges[-1] == pytest.approx(x.max())
    assert "X" in found.parents["Y"] or "Y" in found.parents["X"]


# evidence ----------------------------------------------------------------------------------

_TWO = """
bayesprog: 1
variables: {A: {states: [a0, a1]}, B: {states: [b0, b1]}}
decomposition:
  - {term: P(A), form: table, table: [0.5, 0.5]}
  - {term: P(B | A), form: table, table: [0.5, 0.5]}
"""


@pytest.mark.parametrize("score, ess", [("k2", 1.0), ("bdeu", 4.0), ("bdeu", 8.0)])
def test_the_closed_form_evidence_equals_brute_force_integration(score, ess):
    data = {"A": ["a0", "a0", "a1", "a1", "a1", "a0", "a1"],
            "B": ["b0", "b1", "b1", "b1", "b0", "b0", "b1"]}
    program = bayesprog.loads(_TWO)
    found = program.evidence(data, score=score, equivalent_sample_size=ess)
    assert found.method.startswith("exact")
    # Dirichlet (Beta) priors on P(A), P(B | a0), P(B | a1), of integer shapes here; the
    # likelihood times the priors integrated over the three parameters at once, on a tensor
    # grid of Gauss-Legendre nodes (exact for these polynomials of degree < 2 x 24)
    if score == "k2":
        prior_a = prior_b = (1.0, 1.0)
    else:
        prior_a, prior_b = (ess / 2, ess / 2), (ess / 4, ess / 4)
    import scipy.special
    import scipy.stats

    nodes, weights = scipy.special.roots_legendre(24)
    t, w = (nodes + 1) / 2, weights / 2
    ta, t0, t1 = np.meshgrid(t, t, t, indexing="ij")
    like = np.ones_like(ta)
    for a, b in zip(data["A"], data["B"], strict=True):
        theta = t0 if a == "a0" else t1
        like *= (ta if a == "a0" else 1 - ta) * (theta if b == "b0" else 1 - theta)
    density = (scipy.stats.beta.pdf(ta, *prior_a) * scipy.stats.beta.pdf(t0, *prior_b)
               * scipy.stats.beta.pdf(t1, *prior_b))
    value = np.einsum("i,j,k,ijk->", w, w, w, like * density)
    assert found.log_evidence == pytest.approx(np.log(value), abs=1e-9)


def test_the_true_structure_has_the_most_evidence(tmp_path, capsys):
    frame, model = _sample("asia", 3000, seed=2)
    frame.to_csv(tmp_path / "asia.csv", index=False)
    names = list(frame.columns)
    states = {n: sorted(frame[n].unique()) for n in names}

    def program(parents: dict[str, list[str]], file: str) -> None:
        lines = ["bayesprog: 1", "variables:"]
        lines += [f"  {n}: {{states: {json.dumps(states[n])}}}" for n in names]
        lines.append("decomposition:")
        for n in names:
            ps = parents.get(n, [])
            term = f"P({n} | {', '.join(ps)})" if ps else f"P({n})"
            lines.append(f"  - {{term: '{term}', form: table, table: [0.5, 0.5]}}")
        (tmp_path / file).write_text("\n".join(lines) + "\n")

    program({n: list(model.get_parents(n)) for n in names}, "true.yaml")
    program({}, "empty.yaml")
    program({n: names[:i] for i, n in enumerate(names)}, "complete.yaml")
    code, out, err = run(capsys, "compare", tmp_path / "empty.yaml", tmp_path / "complete.yaml",
                         tmp_path / "true.yaml", tmp_path / "asia.csv", "--json")
    assert code == 0, err
    rows = json.loads(out)
    assert rows[0]["program"].endswith("true.yaml")
    assert rows[0]["log_bayes_factor"] == 0 and all(r["log_bayes_factor"] < -10 for r in rows[1:])
    assert {tuple(sorted(r)) for r in rows} == {("log_bayes_factor", "log_evidence", "method",
                                                 "path", "program", "rows")}
    code, out, _ = run(capsys, "compare", tmp_path / "true.yaml", tmp_path / "asia.csv")
    assert code == 0 and "log evidence" in out and "exact: BDeu" in out


def test_evidence_of_a_program_with_real_variables_is_bic_and_says_so():
    program = bayesprog.loads("""
bayesprog: 1
variables: {M: {states: [m0, m1]}, E: {continuous: [-.inf, .inf]}}
decomposition:
  - {term: P(M), form: table, table: [0.5, 0.5]}
  - {term: P(E | M), form: normal, mean: 0.0, sigma: 1.0}
""")
    rng = np.random.default_rng(2)
    m = rng.choice(["m0", "m1"], 200)
    e = np.where(m == "m0", 0.0, 2.0) + rng.normal(size=200)
    found = program.evidence({"M": list(m), "E": list(e)})
    assert found.method.startswith("BIC")
    fitted = program.fit({"M": list(m), "E": list(e)})
    free = 1 + 4  # P(M): one probability; P(E | M): a mean and a sigma per state
    assert found.log_evidence == pytest.approx(fitted.log_likelihood
                                               - 0.5 * np.log(200) * free, rel=1e-12)


def test_discovery_on_a_dict_of_columns_is_deterministic():
    rng = np.random.default_rng(9)
    a = rng.choice(["x", "y"], 500)
    b = np.where(rng.random(500) < 0.9, a, np.where(a == "x", "y", "x"))
    data = {"A": list(a), "B": list(b), "C": list(rng.choice(["p", "q"], 500))}
    first = bayesprog.discover(data)

    def timeless(text: str) -> str:  # the record's search time is the clock's, not the data's
        return re.sub(r"\bseconds: [0-9.e+-]+", "seconds: _", text)

    assert timeless(first.text) == timeless(bayesprog.discover(data).text)
    assert "seconds:" in first.text
    assert sorted(itertools.chain.from_iterable(first.parents.values())) in (["A"], ["B"])


# what the search cannot see: a deterministic variable ------------------------------------------

def test_pc_says_when_arcs_contradict_a_deterministic_table(tmp_path, capsys):
    """In asia, either = tub OR lung: given tub and lung it tells nothing more, so PC finds
    xray and dysp independent given them and makes them parents of either. The arcs into a
    variable that the data show to be a function of its other parents are said, and
    forbidding them gives the true families."""
    asia = bayesprog.load(Path(__file__).parent / "programs" / "asia.yaml")
    frame = asia.sample(20_000, rng=3)
    with pytest.warns(StructureWarning) as caught:
        found = bayesprog.discover(frame, method="pc")
    assert sorted(found.parents["either"]) == ["dysp", "lung", "tub", "xray"]
    said = [str(w.message) for w in caught]
    assert len(said) == 1 and said[0].startswith("either is a function of tub, lung in the data")
    assert "the arcs xray -> either, dysp -> either contradict" in said[0]
    assert "--forbid xray->either" in said[0]
    assert found.record.structure.warnings == said  # and in the file's record
    assert "warnings:" in found.text
    # the command line says it on stderr and still writes the program
    frame.to_csv(tmp_path / "asia.csv", index=False)
    code, out, err = run(capsys, "discover", tmp_path / "asia.csv", "--method", "pc", "-o",
                         tmp_path / "pc.yaml")
    assert code == 0 and (tmp_path / "pc.yaml").is_file()
    assert err.startswith("bayesprog: warning: either is a function of")
    # forbidding the arcs it names gives either its own parents, and no warning
    arcs = [f"{p}->either" for p in found.parents["either"] if p not in ("tub", "lung")]
    with warnings.catch_warnings():
        warnings.simplefilter("error", StructureWarning)
        fixed = bayesprog.discover(frame, method="pc", forbid=arcs)
    assert sorted(fixed.parents["either"]) == ["lung", "tub"]
    assert fixed.record.structure.warnings == []


def test_a_function_of_chance_in_few_rows_is_not_said_to_be_deterministic():
    from bayesprog.program.discovery import determined_by

    rng = np.random.default_rng(4)
    codes = rng.integers(0, 3, size=(12, 4))  # 12 rows, 9 configurations of two columns
    assert determined_by(codes, 0, [1, 2]) is None
    xor = rng.integers(0, 2, size=(400, 4))  # column 0 is column 1 xor column 2
    xor[:, 0] = xor[:, 1] ^ xor[:, 2]
    assert determined_by(xor, 0, [1, 2, 3]) == [1, 2]  # the smallest set, a proper subset
    assert determined_by(xor, 0, [1, 3]) is None
