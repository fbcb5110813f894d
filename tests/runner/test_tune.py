"""``bayesprog tune``: a seeded search that resumes where it stopped, whose statistics are
scipy's and statsmodels', and whose tuned program loads and decides as the search evaluated it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import stats
from statsmodels.stats.multitest import multipletests

import bayesprog
from bayesprog.cli import main
from runner.experiments import tune as tune_module
from runner.experiments.tune import (
    PARAMETERS,
    area_over_distance,
    areas,
    evaluate,
    file_values,
    load_search,
    run_search,
    terms_of,
)
from runner.report.tuning import search_and_report
from runner.world.scenario import load_scenario

MODELS = Path(__file__).parents[2] / "models"


def write_search(folder: Path, **tune) -> Path:
    spec = {"experiment": 1, "name": "tiny", "runner": "haptic",
            "scenario": str(MODELS / "scenarios" / "small_grid.yaml"), "tasks": ["T1"],
            "configurations": ["full"], "runs": 4, "iterations": 25, "seed": 3,
            "tune": {"training": [str(MODELS / "scenarios" / "small_grid.yaml")],
                     "validation": [str(MODELS / "scenarios" / "corners.yaml")],
                     "trials": 4, "runs": 3, "validation_runs": 5, **tune}}
    path = folder / "tiny.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def fresh(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fresh")
    search = load_search(write_search(folder))
    return search_and_report(search, folder / "out", progress=False), folder / "out"


def test_the_hand_chosen_profiles_are_the_first_trial_and_the_best_is_no_worse(fresh):
    result, out = fresh
    first = result["trials"][0]
    assert first["objective"] == 1.0  # the file's own values, relative to themselves
    assert first["params"] == {p["name"]: p["hand"] for p in result["parameters"]}
    assert result["best_objective"] == min(t["objective"] for t in result["trials"])
    assert result["best_objective"] <= 1.0
    assert len({json.dumps(t["params"], sort_keys=True) for t in result["trials"]}) == 4
    for t in result["trials"]:  # every candidate inside the searched ranges
        for p in PARAMETERS:
            assert p.low <= t["params"][p.name] <= p.high


def test_a_search_continued_or_interrupted_ends_as_an_uninterrupted_one(fresh, tmp_path,
                                                                        monkeypatch):
    result, _ = fresh
    search = load_search(write_search(tmp_path))
    run_search(search, tmp_path / "out", trials=2, progress=False)  # then asked for more
    calls = {"n": 0}
    real = tune_module.evaluate

    def interrupted(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:  # Ctrl-C in the middle of the third trial
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(tune_module, "evaluate", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_search(search, tmp_path / "out", progress=False)
    monkeypatch.setattr(tune_module, "evaluate", real)
    resumed = run_search(search, tmp_path / "out", progress=False)
    assert resumed["trials"] == result["trials"]
    assert resumed["validation"] == result["validation"]


def test_the_same_seed_gives_the_same_search_whatever_the_workers(fresh, tmp_path):
    result, _ = fresh
    search = load_search(write_search(tmp_path))
    again = run_search(search, tmp_path / "out", workers=2, progress=False)
    assert again["trials"] == result["trials"]
    assert again["validation"] == result["validation"]
    search.spec.seed = 4  # another seed: other candidates after the hand-chosen first
    other = run_search(search, tmp_path / "seed4", trials=3, progress=False)
    assert other["trials"][1]["params"] != result["trials"][1]["params"]


def test_a_search_on_a_dask_cluster_is_the_local_one(fresh, tmp_path):
    """``--scheduler``: every candidate evaluated on the cluster's workers, the same journal,
    the same trials and validation as in one process."""
    from dask.distributed import LocalCluster

    result, _ = fresh
    search = load_search(write_search(tmp_path))
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                      dashboard_address="127.0.0.1:0") as cluster:
        on_dask = run_search(search, tmp_path / "out", scheduler=cluster.scheduler_address,
                             progress=False)
        assert main(["tune", str(write_search(tmp_path)), "--out", str(tmp_path / "cli"),
                     "--trials", "2", "--scheduler", cluster.scheduler_address, "-q"]) == 0
    assert on_dask["trials"] == result["trials"]
    assert on_dask["validation"] == result["validation"]
    assert (tmp_path / "out" / tune_module.JOURNAL).exists()
    written = json.loads((tmp_path / "cli" / "tune.json").read_text())
    assert written["trials"] == result["trials"][:2]


def test_dask_an_evaluation_whose_worker_died_is_run_again(fresh, tmp_path, monkeypatch):
    from types import SimpleNamespace

    from dask.distributed import LocalCluster
    from distributed.scheduler import KilledWorker

    result, _ = fresh
    real = tune_module._evaluate_at
    killed = tmp_path / "killed"  # a file: the cluster copies the function, and a list with it

    def dies_once(scenario_path, task, *rest):
        if not killed.exists():
            killed.write_text(task)
            raise KilledWorker(task, SimpleNamespace(address="tcp://gone:1"), 3)
        return real(scenario_path, task, *rest)

    monkeypatch.setattr(tune_module, "_evaluate_at", dies_once)
    search = load_search(write_search(tmp_path))
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address="127.0.0.1:0") as cluster:
        again = run_search(search, tmp_path / "out", scheduler=cluster.scheduler_address,
                           progress=False)
    assert killed.exists()
    assert again["trials"] == result["trials"]


def test_dask_a_scheduler_that_cannot_be_reached_is_reported(tmp_path, capsys):
    assert main(["tune", str(write_search(tmp_path)), "--out", str(tmp_path / "out"),
                 "--scheduler", "tcp://127.0.0.1:9", "-q"]) == 2
    err = capsys.readouterr().err
    assert "cannot reach a Dask scheduler" in err and "Traceback" not in err


def test_the_objective_is_the_mean_relative_area_under_gamma(fresh):
    result, out = fresh
    search = load_search(write_search(out.parent))
    best = result["trials"][result["best_trial"]]["params"]
    ratios = []
    for row, (scenario, task) in zip(result["training"], search.pairs("training"), strict=True):
        hand = np.trapezoid(evaluate(scenario, task, None, 3, 25, 3)["gamma"], axis=1)
        tuned = np.trapezoid(evaluate(scenario, task, best, 3, 25, 3)["gamma"], axis=1)
        assert row["auc_hand"] == pytest.approx(hand.mean(), rel=1e-12)
        ratios.append(tuned.mean() / hand.mean())
    assert result["best_objective"] == pytest.approx(np.mean(ratios), rel=1e-12)


def test_runs_are_the_same_whatever_the_chunk():
    scenario = load_scenario(MODELS / "scenarios" / "small_grid.yaml")
    values = file_values(scenario) | {"S.a": 8.0, "shape_weight": 0.2}
    whole = evaluate(scenario, "T2", values, 5, 20, 9, chunk=5)
    pieces = evaluate(scenario, "T2", values, 5, 20, 9, chunk=2)
    for key in ("gamma", "paths"):
        np.testing.assert_array_equal(whole[key], pieces[key])


def test_area_over_distance_is_the_integral_of_gamma_held_between_probes():
    rng = np.random.default_rng(5)
    gamma = np.sort(rng.uniform(0, 2, (4, 12)), axis=1)[:, ::-1]
    distance = np.cumsum(np.r_[0, *rng.uniform(0, 0.05, 11)] * np.ones((4, 1)), axis=1)
    distance[1] *= 3  # a run that overshoots the budget
    budget = 0.4
    fine = np.linspace(0, budget, 400_001)[:-1] + budget / 800_000  # midpoints
    expected = [gamma[i, np.searchsorted(distance[i], fine, side="right") - 1].sum()
                * budget / 400_000 for i in range(4)]
    np.testing.assert_allclose(area_over_distance(gamma, distance, budget), expected, rtol=1e-4)


def test_a_search_over_travel_compares_areas_within_the_hand_chosen_distance(tmp_path):
    search = load_search(write_search(tmp_path, objective="travel", trials=2))
    result = run_search(search, tmp_path / "out", progress=False)
    assert result["objective"] == "travel" and result["trials"][0]["objective"] == 1.0
    (scenario, task), row = search.pairs("training")[0], result["training"][0]
    hand = evaluate(scenario, task, None, 3, 25, 3)
    steps = np.linalg.norm(np.diff(scenario.centres[hand["paths"]], axis=1), axis=-1)
    budget = steps.sum(axis=1).mean()
    assert row["budget"] == pytest.approx(budget, rel=1e-12)
    distance = np.concatenate([np.zeros((3, 1)), np.cumsum(steps, axis=1)], axis=1)
    assert row["auc_hand"] == pytest.approx(
        area_over_distance(hand["gamma"], distance, budget).mean(), rel=1e-12)
    first = result["trials"][1]
    ratios = []
    for b, (scenario, task) in zip(result["training"], search.pairs("training"), strict=True):
        runs = evaluate(scenario, task, first["params"], 3, 25, 3)
        ratios.append(areas(scenario, runs, "travel", b["budget"]).mean() / b["auc_hand"])
    assert first["objective"] == pytest.approx(np.mean(ratios), rel=1e-12)


def test_validation_tests_are_scipys_wilcoxon_with_holms_correction(fresh):
    result, out = fresh
    search = load_search(write_search(out.parent))
    best = result["trials"][result["best_trial"]]["params"]
    ps = []
    for row, (scenario, task) in zip(result["validation"], search.pairs("validation"),
                                     strict=True):
        assert (row["scenario"], row["task"]) == (scenario.name, task)
        # validation streams: seed + 1
        hand = np.trapezoid(evaluate(scenario, task, None, 5, 25, 4)["gamma"], axis=1)
        tuned = np.trapezoid(evaluate(scenario, task, best, 5, 25, 4)["gamma"], axis=1)
        assert row["auc_hand"] == pytest.approx(hand.mean(), rel=1e-12)
        assert row["auc_tuned"] == pytest.approx(tuned.mean(), rel=1e-12)
        expected = 1.0 if np.allclose(hand, tuned) else stats.wilcoxon(tuned, hand).pvalue
        assert row["p"] == pytest.approx(expected, rel=1e-12)
        ps.append(expected)
    holm = multipletests(ps, method="holm")[1]
    np.testing.assert_allclose([r["p_holm"] for r in result["validation"]], holm, rtol=1e-12)


def test_the_tuned_program_loads_with_the_tuned_values_and_keeps_the_rest(fresh):
    result, out = fresh
    text = (out / "pi_tar.tuned.yaml").read_text()
    assert text.startswith("# Profiles tuned by bayesprog tune")
    assert "soft_evidence:" in text and "isotropic sigma" in text  # the rest as written
    tuned = bayesprog.load(out / "pi_tar.tuned.yaml")
    best = {p["name"]: p["tuned"] for p in result["parameters"]}
    terms = {t.label: t for t in tuned.terms}
    for label, params in terms_of(best).items():
        for key, value in params.items():
            assert float(terms[label].params[key].array) == pytest.approx(value, rel=1e-5)
    assert (out / "tune.png").stat().st_size > 10_000
    assert (out / "tune-visits.png").stat().st_size > 10_000
    md = (out / "tune.md").read_text()
    assert "**Verdict**" in md and "| corners | T1 | 5 |" in md
    row = result["validation"][0]
    scenario = load_scenario(MODELS / "scenarios" / "corners.yaml")
    paths = evaluate(scenario, "T1", best, 5, 25, 4)["paths"]
    border = scenario.border("T1").ravel()
    assert row["tuned_behaviour"]["precision"] == pytest.approx(border[paths].mean())


def test_terms_of_inverts_file_values():
    scenario = load_scenario(MODELS / "scenarios" / "small_grid.yaml")
    values = file_values(scenario)
    assert values["shape_weight"] == pytest.approx(0.5) and values["I.b"] == 2.5
    target = scenario.load_target(terms_of(values))
    assert [t.params.keys() for t in target.terms] == [t.params.keys()
                                                       for t in scenario.target.terms]


def test_a_search_that_must_keep_border_precision_picks_a_candidate_that_keeps_it(tmp_path):
    search = load_search(write_search(tmp_path, min_precision=1.0, trials=5))
    result = search_and_report(search, tmp_path / "out", progress=False)
    hand = [scenario.border(task).ravel()[evaluate(scenario, task, None, 3, 25, 3)["paths"]]
            .mean() for scenario, task in search.pairs("training")]
    for trial in result["trials"][:2]:
        kept = [scenario.border(task).ravel()[evaluate(scenario, task, trial["params"], 3, 25, 3)
                                              ["paths"]].mean()
                for scenario, task in search.pairs("training")]
        assert trial["precision"] == pytest.approx(np.mean(kept) / np.mean(hand), rel=1e-12)
    feasible = [t for t in result["trials"] if t["precision"] >= 1.0]
    assert result["best_objective"] == min(t["objective"] for t in feasible)
    assert result["trials"][result["best_trial"]]["precision"] >= 1.0
    assert "at least 1 times the hand-chosen" in (tmp_path / "out" / "tune.md").read_text()


def test_parameters_not_searched_keep_the_files_values(tmp_path):
    search = load_search(write_search(tmp_path, parameters=["S.a", "shape_weight"], trials=3))
    result = search_and_report(search, tmp_path / "out", progress=False)
    hand = {p["name"]: p["hand"] for p in result["parameters"]}
    for trial in result["trials"]:
        assert set(trial["params"]) == {"S.a", "shape_weight"}
    tuned = {p["name"]: p for p in result["parameters"]}
    assert [n for n, p in tuned.items() if not p["searched"]] == ["I.a", "I.b", "S.b", "U.a",
                                                                   "U.b"]
    assert all(tuned[n]["tuned"] == hand[n] for n in ("I.a", "I.b", "S.b", "U.a", "U.b"))
    scenario, task = search.pairs("training")[0]
    second = result["trials"][1]
    runs = evaluate(scenario, task, hand | second["params"], 3, 25, 3)
    ratios = [areas(s, evaluate(s, t, hand | second["params"], 3, 25, 3), "probes").mean()
              / b["auc_hand"] for b, (s, t) in zip(result["training"], search.pairs("training"),
                                                   strict=True)]
    assert runs["gamma"].shape == (3, 25)
    assert second["objective"] == pytest.approx(np.mean(ratios), rel=1e-12)
    assert "| I.a | inhibition profile, Beta a | 1 | 1 | not searched |" in (
        tmp_path / "out" / "tune.md").read_text()


@pytest.mark.parametrize("edit, expected", [
    (lambda spec: spec.pop("tune"), "tiny.yaml:1:1: no tune: section"),
    (lambda spec: spec["tune"]["validation"].append(spec["tune"]["training"][0]),
     "small_grid.yaml is already a training scenario"),
    (lambda spec: spec["tune"].update(validation=["nowhere.yaml"]),
     "tiny.yaml:16:5: validation scenario 'nowhere.yaml': no such file"),
    (lambda spec: spec["tune"].update(trials=0), "trials: Input should be greater than or equal"),
    (lambda spec: spec["tune"].update(runs=10**12), "tiny.yaml:18:9: 1,000,000,000,000 runs"),
    (lambda spec: spec["tune"].update(objective="speed"), "objective: Input should be 'probes'"),
    (lambda spec: spec["tune"].update(parameters=["S.a", "S.c"]),
     "tiny.yaml:22:5: unknown parameter 'S.c': expected one of I.a, I.b"),
])
def test_a_bad_search_is_refused_at_its_place(tmp_path, capsys, edit, expected):
    path = write_search(tmp_path)
    spec = yaml.safe_load(path.read_text())
    edit(spec)
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    assert main(["tune", str(path), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err


def test_a_search_where_no_candidate_keeps_the_precision_says_so(tmp_path, capsys):
    path = write_search(tmp_path, min_precision=10.0, trials=2)
    assert main(["tune", str(path), "--out", str(tmp_path / "out"), "-q"]) == 0
    assert "no trial kept min_precision 10" in capsys.readouterr().out
    result = json.loads((tmp_path / "out" / "tune.json").read_text())
    assert result["feasible"] is False and result["best_trial"] == 0
    assert "**No candidate kept it**" in (tmp_path / "out" / "tune.md").read_text()


@pytest.mark.parametrize("make, expected", [
    (lambda out: out.write_text("x"), "is a file, expected a folder"),
    (lambda out: (out.mkdir(), (out / "notes.txt").write_text("x")), "holds files but no search"),
])
def test_an_out_that_is_not_a_search_folder_is_refused(tmp_path, capsys, make, expected):
    path = write_search(tmp_path)
    make(tmp_path / "out")
    assert main(["tune", str(path), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err


def test_a_folder_of_another_search_is_refused(fresh, tmp_path, capsys):
    result, out = fresh
    path = write_search(tmp_path, runs=4)
    assert main(["tune", str(path), "--out", str(out), "-q"]) == 2
    assert "holds a search of other settings" in capsys.readouterr().err
