"""Replications of an experiment: each on its own sample drawn from (seed, replication), the
first one the experiment itself; the findings pooled over them (report/findings.json), with
the statistics checked against scipy and statsmodels."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from statsmodels.stats.multitest import multipletests

from bayesprog.cli import main
from runner.experiments.experiment import ExperimentSpec, load_experiment, run_experiment, units
from runner.experiments.loop import decision_seed, reading_seed, start_cell, start_cells
from runner.experiments.store import ResultStore
from runner.report.verdicts import (
    FINDINGS,
    Resampled,
    holm,
    judge_replications,
    keyed_findings,
    pooled,
    signed_rank_p,
    statistics_table,
)
from tests.runner.test_experiment import assert_same, write_experiment


# the samples --------------------------------------------------------------------------------
def test_replication_zero_draws_what_an_experiment_always_drew():
    old = np.random.default_rng([2024, 0xC0FFEE, 3])  # the key of an experiment's run 3
    expected = [old.integers(0, n) for n in (30, 60)]
    assert start_cell((30, 60), 2024, 3).tolist() == expected
    assert start_cell((30, 60), 2024, 3, replication=0).tolist() == expected
    assert decision_seed(2024, 3, 0) == (2024, 3, 0)
    assert reading_seed(2024, 3, 0) == (2024, 3, 1)


def test_each_replication_is_its_own_sample_drawn_from_the_seed_and_its_number():
    samples = [start_cells((30, 60), 100, 2024, q) for q in range(4)]
    for a in range(4):
        for b in range(a + 1, 4):
            assert (samples[a] != samples[b]).any(axis=1).mean() > 0.9
    # drawn from (seed, replication, run) alone: the number of runs does not change a run's
    assert start_cells((30, 60), 7, 2024, 2).tolist() == samples[2][:7].tolist()
    assert start_cells((30, 60), 100, 2024, 2).tolist() == samples[2].tolist()
    keys = {decision_seed(2024, 5, q) for q in range(5)} | {reading_seed(2024, 5, q)
                                                            for q in range(5)}
    assert len(keys) == 10
    # numpy pads a seed key with zeros: no replication's stream may repeat another's
    streams = [np.random.default_rng(k).random() for k in keys]
    assert len(set(streams)) == 10


def test_units_of_replication_zero_are_the_experiment_and_stored_where_it_stored_them(
        tmp_path):
    path = write_experiment(tmp_path)
    spec = load_experiment(path).spec
    three = load_experiment(path, replications=3).spec
    assert units(three)[:len(units(spec))] == units(spec)
    assert {u.replication for u in units(three)} == {0, 1, 2}
    assert [u.name for u in units(three) if u.replication == 0] == [u.name for u in units(spec)]
    assert all("replication_002/" in u.name for u in units(three) if u.replication == 2)


# the run --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def replicated(tmp_path_factory):
    """The small experiment without replications, and with three (run by the command)."""
    folder = tmp_path_factory.mktemp("replicated")
    path = write_experiment(folder, runs=3, iterations=8, tasks=["T1", "T2", "T3"],
                            configurations=["full", "without_S", "without_I"])
    once, thrice = folder / "once", folder / "thrice"
    assert main(["run", str(path), "--out", str(once), "-q", "--no-animation"]) == 0
    assert main(["run", str(path), "--out", str(thrice), "-q", "--no-animation",
                 "--replications", "3", "--workers", "2"]) == 0
    return path, once, thrice


def test_replication_zero_is_byte_identical_to_the_experiment(replicated):
    _, once, thrice = replicated
    assert (once / "report" / "statistics.json").read_bytes() == \
        (thrice / "report" / "statistics.json").read_bytes()
    for chunk in (once / "chunks").rglob("*.npz"):
        twin = thrice / chunk.relative_to(once)
        with np.load(chunk) as a, np.load(twin) as b:
            assert a.files == b.files
            for key in a.files:
                np.testing.assert_array_equal(a[key], b[key])
    assert json.loads((thrice / "experiment.json").read_text())["hash"] == \
        json.loads((once / "experiment.json").read_text())["hash"]


def test_replications_differ_and_findings_json_is_complete(replicated):
    _, once, thrice = replicated
    spec = load_experiment(replicated[0], replications=3).spec
    store = ResultStore(thrice)
    from runner.experiments.experiment import load_replications

    results = load_replications(store, spec)
    assert len(results) == 3
    assert not np.array_equal(results[0]["T1/full"]["paths"], results[1]["T1/full"]["paths"])
    found = json.loads((thrice / "report" / "findings.json").read_text())
    assert found["replications"] == 3
    assert [f["finding"] for f in found["findings"]] == ["S", "I", "T"]
    for f in found["findings"]:
        assert f["verdict"] in ("agrees", "differs")
        assert 0 <= f["agree"] <= f["of"] == 3
        assert 0.0 <= f["stability"] <= 1.0
        assert set(f["tasks"]) == {"T1", "T2", "T3"}
        for task in f["tasks"].values():
            lo, hi = task["ci95"]
            assert lo <= task["effect"] <= hi
            assert 0.0 <= task["p_holm"] <= 1.0
    single = json.loads((once / "report" / "findings.json").read_text())
    assert single["replications"] == 1 and all(f["of"] == 1 for f in single["findings"])
    report = (thrice / "report" / "report.md").read_text()
    assert "## Replications" in report and (thrice / "report" / "fig10_gamma_pooled.png").exists()
    assert "| stability |" in (once / "report" / "report.md").read_text()
    assert "## Replications" not in (once / "report" / "report.md").read_text()


def test_the_runs_table_holds_every_replication(replicated, tmp_path):
    import pandas as pd

    _, _, thrice = replicated
    assert main(["results", str(thrice), "-o", str(tmp_path / "runs.csv")]) == 0
    table = pd.read_csv(tmp_path / "runs.csv")
    assert sorted(table.replication.unique()) == [0, 1, 2]
    spec = load_experiment(replicated[0], replications=3).spec
    from runner.experiments.experiment import load_replications

    stored = load_replications(ResultStore(thrice), spec)[2]["T2/without_I"]
    rows = table[(table.task == "T2") & (table.configuration == "without_I")
                 & (table.replication == 2)]
    np.testing.assert_array_equal(rows["cell"].to_numpy(), stored["paths"].ravel())


def test_a_dask_cluster_gives_the_replications_the_same_numbers(replicated, tmp_path):
    from dask.distributed import LocalCluster

    from runner.experiments.experiment import load_replications

    path, _, thrice = replicated
    experiment = load_experiment(path, replications=3)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                      dashboard_address="127.0.0.1:0") as cluster:
        run_experiment(experiment, tmp_path / "out", scheduler=cluster.scheduler_address,
                       progress=False)
    for a, b in zip(load_replications(ResultStore(tmp_path / "out"), experiment.spec),
                    load_replications(ResultStore(thrice), experiment.spec), strict=True):
        assert_same(a, b)


def test_more_replications_in_a_folder_keep_the_ones_it_holds(replicated, tmp_path):
    path, once, _ = replicated
    import shutil

    out = tmp_path / "out"
    shutil.copytree(once, out)
    before = {p: p.stat().st_mtime_ns for p in (out / "chunks").rglob("*.npz")}
    assert main(["run", str(path), "--out", str(out), "-q", "--no-report",
                 "--replications", "2"]) == 0
    assert all(p.stat().st_mtime_ns == t for p, t in before.items())
    assert len(list((out / "chunks").rglob("*.npz"))) == 2 * len(before)
    assert json.loads((out / "experiment.json").read_text())["replications"] == 2


def test_replications_give_the_same_numbers_in_one_process(replicated, tmp_path):
    path, _, thrice = replicated
    experiment = load_experiment(path, replications=3)
    run_experiment(experiment, tmp_path / "out", progress=False)
    spec = experiment.spec
    from runner.experiments.experiment import load_replications

    for a, b in zip(load_replications(ResultStore(tmp_path / "out"), spec),
                    load_replications(ResultStore(thrice), spec), strict=True):
        assert_same(a, b)


@pytest.mark.parametrize("value", ["0", "-1", "2.5", "abc", ""])
def test_a_wrong_number_of_replications_is_refused_in_one_line(tmp_path, capsys, value):
    path = write_experiment(tmp_path)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), f"--replications={value}",
                 "--no-report"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--replications" in err, err
    assert not (tmp_path / "out").exists()


def test_an_experiment_file_may_ask_for_replications(tmp_path):
    path = write_experiment(tmp_path, replications=4)
    assert load_experiment(path).spec.replications == 4
    assert load_experiment(path, replications=2).spec.replications == 2
    bad = write_experiment(tmp_path, replications=0)
    with pytest.raises(Exception, match="replications"):
        load_experiment(bad)


# the statistics -------------------------------------------------------------------------------
def test_the_signed_rank_test_of_many_resamples_is_scipys():
    rng = np.random.default_rng(3)
    for _ in range(60):
        n = int(rng.integers(8, 150))
        d = np.round(rng.normal(rng.normal(0, 0.3), 1, size=n), int(rng.integers(0, 3)))
        d[rng.random(n) < 0.1] = 0.0  # zeros dropped, ties among the rest
        if not d.any():
            continue
        expected = stats.wilcoxon(d, method="approx").pvalue
        assert signed_rank_p(d[None])[0] == pytest.approx(expected, rel=1e-10, abs=1e-300)


def test_holm_of_many_rows_is_statsmodels():
    rng = np.random.default_rng(4)
    p = rng.random((12, 9)) ** 3  # (statsmodels collects garbage at every call)
    p[:, 3] = p[:, 1]  # ties
    for row, adjusted in zip(p, holm(p), strict=True):
        np.testing.assert_allclose(adjusted, multipletests(row, method="holm")[1], rtol=1e-12)


def _synthetic(runs: int, seed: int, effects: dict[str, float]) -> tuple[dict, ExperimentSpec]:
    """Gamma curves of paired runs: each configuration's the full model's scaled by 1 + effect
    and noise; the tasks' levels ordered T1 < T2 < T3 per border cell."""
    rng = np.random.default_rng(seed)
    spec = ExperimentSpec(name="synthetic", scenario="x.yaml", tasks=["T1", "T2", "T3"],
                          configurations=["full", *effects], runs=runs, iterations=5)
    results = {}
    for level, task in zip((1.0, 1.1, 1.6), spec.tasks, strict=True):
        base = level * rng.gamma(4.0, 1.0, size=(runs, 1)) * np.linspace(3, 1, 5)
        results[f"{task}/full"] = {"gamma": base}
        for conf, effect in effects.items():
            noise = rng.normal(1 + effect, 0.15, size=(runs, 1))
            results[f"{task}/{conf}"] = {"gamma": base * noise}
    return results, spec


@pytest.mark.parametrize("seed", range(6))
def test_the_resampled_rules_are_the_reports_rules_on_the_runs_themselves(seed):
    effects = [{"without_S": 0.3, "without_U": 0.08, "without_I": 0.02, "without_R": 0.0},
               {"without_S": 0.05, "without_U": 0.2, "without_I": 0.15, "without_R": -0.12},
               {"without_S": 0.2, "without_U": 0.04, "without_I": 0.11, "without_R": 0.01}]
    results, spec = _synthetic(80 + 10 * seed, seed, effects[seed % 3])
    borders = {"T1": 10, "T2": 10, "T3": 10}
    rows = statistics_table(results, spec, borders)
    expected = {key: verdict.startswith("agrees")
                for key, _, _, verdict in keyed_findings(rows, spec)}
    resampled = Resampled(results, spec, borders)
    got = resampled(np.arange(resampled.runs)[None, :])
    assert set(got) == set(expected) == {k for k, _ in FINDINGS}
    for key, agree in expected.items():
        assert bool(got[key][0][0]) == agree, key
    by = {(r["task"], r["configuration"]): r for r in rows}
    for t in spec.tasks:  # the effects are the table's
        assert got["U"][1][t][0] == pytest.approx(
            100 * (by[(t, "without_U")]["auc_mean"] / by[(t, "full")]["auc_mean"] - 1))
        assert got["T"][1][t][0] == pytest.approx(by[(t, "full")]["final_per_border_cell_mm"])


def test_pooled_findings_and_their_stability():
    effects = {"without_S": 0.3, "without_U": 0.1, "without_I": 0.02, "without_R": 0.0}
    reps = []
    for q in range(4):
        results, spec = _synthetic(60, 10 + q, effects)
        reps.append(results)
    borders = {"T1": 10, "T2": 10, "T3": 10}
    judged = judge_replications(reps, spec, borders, resamples=300)
    assert judged["replications"] == 4
    by = {f["finding"]: f for f in judged["findings"]}
    # clear effects: every verdict agrees, in every replication, and firmly
    for key in "SUIRT":
        assert by[key]["verdict"] == "agrees", by[key]
        assert by[key]["agree"] == 4
        assert by[key]["stability"] > 0.9
    together = pooled(reps)
    full = np.trapezoid(together["T1/full"]["gamma"], axis=1)
    s = np.trapezoid(together["T1/without_S"]["gamma"], axis=1)
    assert by["S"]["tasks"]["T1"]["effect"] == pytest.approx(100 * (s.mean() / full.mean() - 1))
    lo, hi = by["S"]["tasks"]["T1"]["ci95"]
    assert lo < 30 < hi and hi - lo < 15
    # the same seed, the same numbers
    assert judge_replications(reps, spec, borders, resamples=300) == judged


def test_a_verdict_at_its_threshold_is_not_stable():
    # removing U costs 5 %, the rule's threshold: the resamples fall on both sides
    results, spec = _synthetic(200, 1, {"without_U": 0.05})
    judged = judge_replications([results], spec, {"T1": 10, "T2": 10, "T3": 10},
                                resamples=400)
    u = next(f for f in judged["findings"] if f["finding"] == "U")
    assert 0.05 < u["stability"] < 0.95


def test_the_bundled_replicated_experiment_is_the_papers_ten_times():
    root = Path(__file__).parents[2] / "models" / "experiments"
    replicated = load_experiment(root / "paper_replicated.yaml").spec
    paper = load_experiment(root / "paper.yaml").spec
    assert replicated.replications == 10
    assert replicated.model_dump(exclude={"name", "description", "replications"}) == \
        paper.model_dump(exclude={"name", "description", "replications"})
    assert os.path.basename(replicated.scenario) == "paper.yaml"
