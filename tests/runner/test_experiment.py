"""Experiments: stored per chunk, resumable, identical across executors and chunkings; the
report and its statistics."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from bayesprog.cli import main
from runner.experiments import experiment as experiment_module
from runner.experiments.experiment import load_experiment, load_results, run_experiment, units
from runner.experiments.store import ResultStore, StoreError
from runner.report.build import area_under, paired_test

MODELS = Path(__file__).parents[2] / "models"


def write_experiment(folder: Path, **changes) -> Path:
    spec = {"experiment": 1, "name": "small", "runner": "haptic",
            "scenario": str(MODELS / "scenarios" / "paper.yaml"), "tasks": ["T1", "T3"],
            "configurations": ["full", "without_S"], "runs": 4, "iterations": 6, "seed": 7,
            "chunk": 2}
    spec.update(changes)
    path = folder / f"small_{len(list(folder.glob('small_*.yaml')))}.yaml"
    import yaml

    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def results_of(out: Path) -> dict:
    store = ResultStore(out)
    spec = load_experiment(store.manifest()["files"]["experiment"]["path"]).spec
    return load_results(store, spec)


def assert_same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        for field in ("gamma", "paths", "runs"):
            np.testing.assert_array_equal(a[key][field], b[key][field], err_msg=f"{key} {field}")


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    folder = tmp_path_factory.mktemp("reference")
    path = write_experiment(folder)
    run_experiment(load_experiment(path), folder / "out", progress=False)
    return folder / "out", results_of(folder / "out")


def test_chunk_size_does_not_change_the_numbers(reference, tmp_path):
    for chunk in (1, 3, 4):
        path = write_experiment(tmp_path, chunk=chunk)
        run_experiment(load_experiment(path), tmp_path / f"out{chunk}", progress=False)
        assert_same(results_of(tmp_path / f"out{chunk}"), reference[1])


def test_local_processes_give_the_same_numbers(reference, tmp_path):
    path = write_experiment(tmp_path)
    run_experiment(load_experiment(path), tmp_path / "out", workers=2, progress=False)
    assert_same(results_of(tmp_path / "out"), reference[1])


def test_dask_cluster_gives_the_same_numbers(reference, tmp_path):
    from dask.distributed import LocalCluster

    path = write_experiment(tmp_path)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                      dashboard_address="127.0.0.1:0") as cluster:
        run_experiment(load_experiment(path), tmp_path / "out", scheduler=cluster.scheduler_address,
                       progress=False)
    assert_same(results_of(tmp_path / "out"), reference[1])


def test_interruption_loses_only_the_chunk_in_flight_and_resume_completes(reference, tmp_path,
                                                                           monkeypatch):
    path = write_experiment(tmp_path)
    experiment = load_experiment(path)
    calls = []
    real = experiment_module.compute_unit

    def interrupted(experiment_path, unit, *rest):
        calls.append(unit)
        if len(calls) == 4:
            raise KeyboardInterrupt  # Ctrl-C while the 4th chunk is computed
        return real(experiment_path, unit, *rest)

    monkeypatch.setattr(experiment_module, "compute_unit", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_experiment(experiment, tmp_path / "out", progress=False)
    store = ResultStore(tmp_path / "out")
    all_units = units(experiment.spec)
    assert [store.done(u) for u in all_units] == [True] * 3 + [False] * (len(all_units) - 3)
    assert not list((tmp_path / "out").rglob("*.tmp"))  # no partial file left behind
    monkeypatch.setattr(experiment_module, "compute_unit", real)
    before = {u: store.path(u).stat().st_mtime_ns for u in all_units[:3]}
    run_experiment(experiment, tmp_path / "out", progress=False)
    assert {u: store.path(u).stat().st_mtime_ns for u in all_units[:3]} == before  # skipped
    assert_same(results_of(tmp_path / "out"), reference[1])


def test_a_finished_experiment_run_twice_gives_identical_numbers(reference, tmp_path, capsys):
    path = write_experiment(tmp_path)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-report", "-q"]) == 0
    assert main(["run", str(path), "--out", str(out), "--no-report", "-q"]) == 0
    assert_same(results_of(out), reference[1])


def test_a_changed_configuration_is_refused(tmp_path, capsys):
    out = tmp_path / "out"
    first = write_experiment(tmp_path)
    assert main(["run", str(first), "--out", str(out), "--no-report", "-q"]) == 0
    changed = write_experiment(tmp_path, iterations=7)
    assert main(["run", str(changed), "--out", str(out), "--no-report", "-q"]) == 2
    err = capsys.readouterr().err
    assert "another configuration" in err and "Traceback" not in err
    with pytest.raises(StoreError):
        run_experiment(load_experiment(changed), out, progress=False)


def test_manifest_records_seed_starts_programs_and_hash(reference):
    manifest = json.loads((reference[0] / "experiment.json").read_text())
    assert manifest["experiment"]["seed"] == 7
    assert len(manifest["start_cells"]) == 4
    assert set(manifest["files"]) == {"experiment", "scenario", "perception", "shape", "target"}
    assert "P(O | T, I, S, U)" in manifest["files"]["target"]["text"]
    assert len(manifest["hash"]) == 16


def test_same_start_cells_for_every_configuration(reference):
    results = reference[1]
    starts = {key: r["paths"][:, 0].tolist() for key, r in results.items()}
    assert len({tuple(v) for v in starts.values()}) == 1


def test_report_builds_every_figure(reference, capsys):
    out = reference[0]
    assert main(["report", str(out)]) == 0
    folder = out / "report"
    for name in ("fig9_visits.png", "fig10_gamma.png", "fig11_decision.png",
                 "fig11_decision.mp4", "report.md", "report.html", "statistics.json"):
        assert (folder / name).stat().st_size > 0, name
    assert (folder / "fig9_visits.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (folder / "fig11_decision.mp4").read_bytes()[4:8] == b"ftyp"  # an MP4 container
    assert (folder / "fig11_decision.mp4").stat().st_size < 5e6
    text = (folder / "report.md").read_text()
    assert "Removing S degrades the most" in text and "| T3 | without_S |" in text
    page = (folder / "report.html").read_text()
    # the HTML carries what the Markdown carries: every table row, figure and the video
    for line in text.splitlines():
        if line.startswith("| T3 | without_S |"):
            assert all(cell.strip() in page for cell in line.split("|") if cell.strip())
    for name in ("fig9_visits.png", "fig10_gamma.png", "fig11_decision.png",
                 "fig11_decision.mp4"):
        assert f'src="{name}"' in page


def test_report_html_shows_its_figures_in_a_browser(reference, screenshot):
    assert main(["report", str(reference[0]), "--no-animation"]) == 0
    pixels = screenshot(reference[0] / "report" / "report.html", 1300, 4000)
    # the figures are drawn: many coloured pixels (text and tables alone are grey)
    colourful = (pixels.max(axis=-1) - pixels.min(axis=-1)) > 0.25
    assert colourful.mean() > 0.05
    # the heat maps of Fig. 9 ('hot': red with little blue) among them
    red = (pixels[..., 0] > 0.6) & (pixels[..., 2] < 0.2)
    assert red.sum() > 2000


def test_p_values_are_holm_adjusted_over_the_experiment(reference):
    from statsmodels.stats.multitest import multipletests

    from runner.report.build import statistics_table

    results = reference[1]
    spec = load_experiment(ResultStore(reference[0]).manifest()["files"]["experiment"]["path"]).spec
    rows = statistics_table(results, spec, {t: 10 for t in spec.tasks})
    tested = [r for r in rows if "p_auc" in r]
    expected = multipletests([r["p_auc"] for r in tested], method="holm")[1]
    np.testing.assert_allclose([r["p_auc_holm"] for r in tested], expected)
    assert all(r["p_auc_holm"] >= r["p_auc"] for r in tested)


def test_report_of_a_folder_without_results(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "not an experiment's output folder" in capsys.readouterr().err


def test_statistics_against_scipy():
    rng = np.random.default_rng(0)
    gamma = rng.random((12, 30))
    from runner.experiments.experiment import mean_sem

    mean, sem = mean_sem(gamma)
    np.testing.assert_allclose(mean, gamma.mean(axis=0))
    np.testing.assert_allclose(sem, stats.sem(gamma, axis=0))
    np.testing.assert_allclose(area_under(gamma), [np.trapezoid(g) for g in gamma])
    a, b = rng.random(20), rng.random(20) + 0.2
    assert paired_test(a, b) == pytest.approx(stats.wilcoxon(a, b).pvalue)
    assert paired_test(a, a) == 1.0


def test_ctrl_c_with_worker_processes_stops_at_once_and_resumes(tmp_path):
    """A real SIGINT to `bayesprog run --workers 2`: exit 130 promptly, chunks kept, resume."""
    import shutil
    import signal
    import subprocess
    import sys
    import time

    # enough work (32 chunks, a few seconds on two cores) that the interrupt lands while chunks
    # remain
    path = write_experiment(tmp_path, runs=8, chunk=1, iterations=40)
    out = tmp_path / "out"
    script = Path(sys.executable).with_name("bayesprog")
    command = [str(script), "run", str(path), "--out", str(out), "--workers", "2", "-q",
               "--no-report"]
    for _attempt in range(3):
        process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 120
        while not list(out.glob("chunks/*/*/*.npz")) and time.monotonic() < deadline:
            time.sleep(0.05)
        running = process.poll() is None
        before = len(list(out.glob("chunks/*/*/*.npz")))
        process.send_signal(signal.SIGINT)
        sent = time.monotonic()
        _, err = process.communicate(timeout=60)
        finished = process.returncode == 0 and len(list(out.glob("chunks/*/*/*.npz"))) == 32
        if running and before < 32 and not finished:
            break  # the signal reached a run with chunks left: it must stop it
        # a loaded machine kept this test from the run until it had ended (or kept the signal
        # from it until its last chunks were done): nothing to stop; a run that never stops
        # fails below, after the last attempt
        shutil.rmtree(out)
    assert running and before < 32, "the run always ended before the test could interrupt it"
    assert time.monotonic() - sent < 10
    assert process.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    kept = list(out.glob("chunks/*/*/*.npz"))
    assert 1 <= len(kept) < 32
    assert not list(out.rglob("*.tmp"))
    assert subprocess.run(command, capture_output=True, text=True).returncode == 0
    reference = tmp_path / "reference"
    run_experiment(load_experiment(path), reference, progress=False)
    assert_same(results_of(out), results_of(reference))


def test_the_runs_table_holds_every_probe_with_its_cues(reference, tmp_path, capsys):
    import pandas as pd

    from runner.report.build import replay

    out, results = reference
    assert main(["results", str(out), "-o", str(tmp_path / "runs.parquet")]) == 0
    table = pd.read_parquet(tmp_path / "runs.parquet")
    experiment = load_experiment(ResultStore(out).manifest()["files"]["experiment"]["path"])
    spec = experiment.spec
    assert len(table) == len(spec.tasks) * len(spec.configurations) * spec.runs * spec.iterations
    rows = table[(table.task == "T3") & (table.configuration == "full")]
    stored = results["T3/full"]
    np.testing.assert_array_equal(rows["cell"].to_numpy(), stored["paths"].ravel())
    # the cell as explore names it, [ix, iy]: the flat index is ix * ny + iy
    ny = experiment.scenario.shape[1]
    np.testing.assert_array_equal(rows["ix"] * ny + rows["iy"], rows["cell"])
    assert "iz" not in table.columns and (rows["iy"] < ny).all()
    np.testing.assert_array_equal(rows["gamma_m"].to_numpy(), stored["gamma"].ravel())
    assert rows[rows.step == 0][["inhibition", "saliency", "uncertainty"]].isna().all().all()
    # the cues at a probed cell are those of the decision that chose it (a replay agrees)
    frames = list(replay(experiment, "T3", "full", 1, spec.iterations))
    run = rows[rows.run == 1].set_index("step")
    for k, frame in enumerate(frames[:-1]):
        chosen = frame["next"]
        assert run.loc[k + 1, "cell"] == chosen
        for key, column in (("I", "inhibition"), ("S", "saliency"), ("U", "uncertainty")):
            np.testing.assert_equal(run.loc[k + 1, column], frame[key][chosen])
    assert main(["results", str(out), "-o", str(tmp_path / "runs.csv")]) == 0
    assert len(pd.read_csv(tmp_path / "runs.csv")) == len(table)
    assert main(["results", str(out), "-o", str(tmp_path / "runs.xlsx")]) == 2


def test_a_report_draws_what_was_stored_from_any_folder(tmp_path, monkeypatch, capsys):
    path = write_experiment(tmp_path, configurations=["without_S"], iterations=1)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-report", "-q"]) == 0
    stored = json.loads((out / "experiment.json").read_text())["start_cells"]
    # the experiment file edited afterwards, the report asked from another folder
    path.write_text(path.read_text().replace("seed: 7", "seed: 99"))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    from runner.experiments.experiment import stored_experiment

    assert stored_experiment(out).start_cells().tolist() == stored
    assert main(["report", str(out), "--no-animation"]) == 0  # no full model, one iteration
    rows = json.loads((out / "report" / "statistics.json").read_text())  # strict JSON
    assert {r["configuration"] for r in rows} == {"without_S"}
    (elsewhere / "runs.csv").mkdir()
    assert main(["results", str(out), "-o", str(elsewhere / "runs.csv")]) == 2  # a folder
    assert "cannot write" in capsys.readouterr().err


def _verdicts(areas: dict[str, dict[str, np.ndarray]]) -> tuple[dict[str, str], list[dict]]:
    """The report's verdicts and statistics on made-up results: per task and configuration,
    the per-run areas under a constant Gamma(k) of two steps (the area is the value itself)."""
    from runner.experiments.experiment import ExperimentSpec
    from runner.report.build import findings, statistics_table

    configurations = ["full", "without_R", "without_S", "without_I", "without_U"]
    spec = ExperimentSpec(name="made_up", scenario="none.yaml", tasks=list(areas),
                          configurations=configurations, runs=60, iterations=2)
    results = {f"{t}/{c}": {"gamma": np.repeat(areas[t][c][:, None], 2, axis=1)}
               for t in areas for c in configurations}
    rows = statistics_table(results, spec, {t: 10 for t in areas})
    return {text.split()[1]: verdict for text, _, verdict in findings(rows, spec)}, rows


def _task(s_shift: float, u_shift: float, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    full = rng.uniform(8.0, 12.0, 60)
    noise = lambda: rng.normal(0.0, 0.05, 60)  # noqa: E731
    return {"full": full, "without_R": full + noise(), "without_I": full + 0.02 + noise(),
            "without_S": full + s_shift + rng.normal(0.0, 0.8, 60),
            "without_U": full + u_shift + rng.normal(0.0, 0.8, 60)}


def test_removing_s_is_the_worst_unless_another_ablation_is_distinguishably_worse():
    def s_row(rows: list[dict], task: str) -> dict:
        return next(r for r in rows if (r["task"], r["configuration"]) == (task, "without_S"))

    # S the worst in every task: agrees
    verdicts, rows = _verdicts({t: _task(3.0, 1.0, i) for i, t in enumerate(("T1", "T2", "T3"))})
    assert verdicts["S"] == "agrees" and s_row(rows, "T3")["runner_up"] == "without_U"
    # in T3 removing U is worse by a margin the runs cannot tell from chance: still agrees
    close = {"T1": _task(3.0, 1.0, 0), "T2": _task(3.0, 1.0, 1), "T3": _task(2.0, 1.0, 2)}
    spread = np.random.default_rng(3).normal(0.0, 0.8, 60)
    close["T3"]["without_U"] = close["T3"]["without_S"] + spread - spread.mean() + 0.05
    verdicts, rows = _verdicts(close)
    row = s_row(rows, "T3")
    assert row["runner_up_auc"] > row["auc_mean"] and row["p_runner_up_holm"] >= 0.01
    assert verdicts["S"] == "agrees"
    # in T3 removing U is clearly worse: differs
    far = {"T1": _task(3.0, 1.0, 0), "T2": _task(3.0, 1.0, 1), "T3": _task(1.0, 3.0, 2)}
    verdicts, rows = _verdicts(far)
    assert s_row(rows, "T3")["p_runner_up_holm"] < 0.01 and verdicts["S"] == "differs"
    # removing S not significant in one task: differs, however it ranks
    flat = {"T1": _task(3.0, 1.0, 0), "T2": _task(3.0, 1.0, 1), "T3": _task(0.0, -0.5, 2)}
    assert _verdicts(flat)[0]["S"] == "differs"
