"""Another lab's scenario: tasks named as the lab names them, every mistake caught at its line
before anything runs, and a report that says when its runs were too few to tell."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from bayesprog.cli import main
from runner.attention.explorer import Explorer
from runner.experiments.experiment import ExperimentSpec
from runner.experiments.metrics import area_under
from runner.report.build import ALPHA, POWER, findings, statistics_table
from runner.world.scenario import load_scenario

MODELS = Path(__file__).parents[2] / "models"

LAB = """\
scenario: 1
name: lab
programs:
  perception: {models}/pi_per.yaml
  shape: {models}/pi_obj.yaml
  target: {models}/pi_tar.yaml
grid: {{shape: [20, 20], cell: 0.01}}
background: wood
templates:
  square: [[-0.04, -0.04], [0.04, -0.04], [0.04, 0.04], [-0.04, 0.04]]
objects:
  - {{template: square, material: copper, at: [0.06, 0.06]}}
  - {{template: square, material: silicone, at: {second}}}
tasks:
  follow_copper: copper
  follow_silicone: silicone
  edge_of_wood: wood
  around_the_copper_again: copper
"""


def lab(tmp_path: Path, second: str = "[0.14, 0.12]", extra: str = "") -> Path:
    path = tmp_path / "lab.yaml"
    path.write_text(LAB.format(models=MODELS, second=second) + extra)
    return path


def test_a_scenario_names_its_tasks_and_as_many_as_it_needs(tmp_path):
    scenario = load_scenario(lab(tmp_path))
    names = ["follow_copper", "follow_silicone", "edge_of_wood", "around_the_copper_again"]
    assert scenario.target.variables["T"].states == tuple(names)
    explorer = Explorer(scenario, "follow_silicone")
    explorer.reset(start=[2, 2], seed=0)
    nxt = explorer.observe([2, 2], {"texture": 0.13, "compliance": 0.35})  # a silicone-like reading
    assert len(nxt) == 2 and explorer.task == "follow_silicone"


def test_an_experiment_runs_with_the_labs_task_names(tmp_path, capsys):
    scenario = lab(tmp_path)
    experiment = tmp_path / "exp.yaml"
    experiment.write_text(f"experiment: 1\nname: lab\nrunner: haptic\nscenario: {scenario}\n"
                          "tasks: [follow_copper, edge_of_wood]\nconfigurations: [full]\n"
                          "runs: 2\niterations: 5\nseed: 1\n")
    assert main(["run", str(experiment), "--out", str(tmp_path / "out"), "-q", "--no-report"]) == 0
    assert main(["results", str(tmp_path / "out"), "-o", str(tmp_path / "runs.csv")]) == 0
    import pandas as pd

    table = pd.read_csv(tmp_path / "runs.csv")
    assert set(table["task"]) == {"follow_copper", "edge_of_wood"}


def test_a_task_whose_material_is_not_laid_out_is_refused_at_its_line(tmp_path, capsys):
    path = lab(tmp_path, extra="  plush_border: plush\n")
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    line = path.read_text().splitlines().index("  plush_border: plush") + 1
    assert f"lab.yaml:{line}:17: task 'plush_border' follows the border of 'plush'" in err
    assert "expected one of copper, silicone, wood" in err and "Traceback" not in err


def test_an_object_past_the_grids_edge_is_clipped_with_a_warning_at_its_line(tmp_path, capsys):
    path = lab(tmp_path, second="[0.18, 0.12]")
    assert main(["validate", str(path)]) == 0
    out, err = capsys.readouterr()
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if "0.18" in text)
    assert f"lab.yaml:{line}:5: warning: object 2 (silicone) reaches past the edge" in err
    assert "lab.yaml: ok (scenario)" in out
    scenario = load_scenario(path)
    inside = scenario.object_cells()[1][1].reshape(scenario.shape)
    assert inside[19].any() and inside.sum() < 64  # clipped: fewer than its 8 x 8 cells


# the report says when the runs were too few -----------------------------------------------

def _results(spread: float, shift: float, runs: int, seed: int = 0) -> dict:
    """Synthetic stored results of one task: the full model, and without S and U whose areas
    under Gamma differ from the full model's by ``shift`` (relative) plus noise."""
    rng = np.random.default_rng(seed)
    steps = 11
    full = np.tile(np.linspace(2.0, 1.0, steps), (runs, 1))
    out = {"T1/full": {"gamma": full, "paths": np.zeros((runs, steps), int)}}
    for conf in ("without_S", "without_U"):
        noise = rng.normal(shift, spread, size=(runs, 1))
        out[f"T1/{conf}"] = {"gamma": full * (1 + noise), "paths": np.zeros((runs, steps), int)}
    return out


def _spec(runs: int) -> ExperimentSpec:
    return ExperimentSpec(name="x", runner="haptic", scenario="s.yaml", tasks=["T1"],
                          configurations=["full", "without_S", "without_U"], runs=runs,
                          iterations=11, seed=0)


def test_the_smallest_detectable_change_follows_the_paired_differences():
    runs = 40
    results = _results(spread=0.2, shift=0.02, runs=runs)
    rows = statistics_table(results, _spec(runs), {"T1": 10})
    z = stats.norm.ppf(1 - ALPHA / 2 / 2) + stats.norm.ppf(POWER)  # two tests in the column
    for row in rows[1:]:
        full = area_under(results["T1/full"]["gamma"])
        diff = area_under(results[f"T1/{row['configuration']}"]["gamma"]) - full
        expected = z * np.std(diff, ddof=1) / math.sqrt(runs) / np.mean(full)
        assert row["detectable_auc"] == pytest.approx(expected, rel=1e-12)
        needed = math.ceil((z * np.std(diff, ddof=1) / (0.05 * np.mean(full))) ** 2)
        assert row["runs_for_smallest"] == needed
    json.dumps(rows)


def test_verdicts_the_runs_could_not_settle_say_so_and_others_do_not():
    few = findings(statistics_table(_results(0.3, 0.08, runs=8), _spec(8), {"T1": 10}), _spec(8))
    verdicts = {text.split()[1]: verdict for text, _, verdict in few}
    assert "runs too few to tell" in verdicts["S"] and "runs too few to tell" in verdicts["U"]
    many = findings(statistics_table(_results(0.01, 0.08, runs=60), _spec(60), {"T1": 10}),
                    _spec(60))
    assert not any("too few" in verdict for _, _, verdict in many)


# a lab's recordings ---------------------------------------------------------------------------

RECORDED = """\
scenario: 1
name: recorded
programs:
  perception: {{recordings: recordings.csv}}
  shape: {models}/pi_obj.yaml
  target: {models}/pi_tar.yaml
grid: {{shape: [20, 30], cell: 0.01}}
background: cork
templates:
  square: [[-0.04, -0.04], [0.04, -0.04], [0.04, 0.04], [-0.04, 0.04]]
objects:
  - {{template: square, material: steel, at: [0.08, 0.08], rotation: 10}}
  - {{template: square, material: felt, at: [0.1, 0.21]}}
tasks:
  follow_steel: steel
  follow_felt: felt
sensor:
  recordings: recordings.csv
"""
OURS = {"wood": "cork", "plush": "felt", "silicone": "steel"}


def recorded(tmp_path: Path, edit: tuple[str, str] = ("", "")) -> Path:
    import pandas as pd

    probes = pd.read_csv(MODELS / "data" / "probes.csv")
    probes = probes[probes.M.isin(list(OURS))].replace({"M": OURS})
    probes.rename(columns={"M": "material", "E": "texture", "C": "compliance"}).to_csv(
        tmp_path / "recordings.csv", index=False)
    path = tmp_path / "recorded.yaml"
    text = RECORDED.format(models=MODELS)
    assert not edit[0] or edit[0] in text
    path.write_text(text.replace(*edit) if edit[0] else text)
    return path


def test_a_scenario_learns_its_perception_from_its_recordings(tmp_path, capsys):
    scenario = load_scenario(recorded(tmp_path))
    assert scenario.materials == ("cork", "felt", "steel")
    # as bayesprog learn would write it, with the lab's columns and materials
    assert main(["learn", str(MODELS / "pi_per.yaml"), str(tmp_path / "recordings.csv"), "-o",
                 str(tmp_path / "per.yaml"), "--column", "material=M", "--column", "texture=E",
                 "--column", "compliance=C", "--states-from-data", "M"]) == 0
    import bayesprog

    learned = bayesprog.load(tmp_path / "per.yaml")
    for term in ("P(E | M)", "P(C | M)"):
        for name in ("mean", "sigma"):
            np.testing.assert_allclose(scenario.perception.term(term).params[name].array,
                                       learned.term(term).params[name].array, rtol=1e-3)
    assert scenario.perception.learned[-1].data == "recordings.csv"


def test_the_sensor_fitted_to_the_recordings_draws_like_them(tmp_path):
    import pandas as pd

    scenario = load_scenario(recorded(tmp_path))
    data = pd.read_csv(tmp_path / "recordings.csv")
    model = scenario.sensor_model
    assert model is not None
    for i, material in enumerate(scenario.materials):
        rows = data[data.material == material]
        z = np.random.default_rng(i).standard_normal((4000, 4))
        texture, compliance = model.draw(np.full(4000, i), z)
        for drawn, column in ((texture, "texture"), (compliance, "compliance")):
            x = rows[column].to_numpy()
            # each feature: scipy's maximum-likelihood skew-normal, and draws the data agree with
            shape, loc, scale = stats.skewnorm.fit(x)
            spec = getattr(model.spec.materials[material], column)
            assert (spec.skew, spec.loc, spec.scale) == pytest.approx((shape, loc, scale))
            assert stats.ks_2samp(x, drawn).pvalue > 0.001, (material, column)
        rank = stats.spearmanr(rows.texture, rows.compliance).statistic
        assert stats.spearmanr(texture, compliance).statistic == pytest.approx(rank, abs=0.08)


def test_a_sensor_model_is_recovered_from_its_own_recordings():
    from runner.world.sensor import SensorModel, load_sensor_model

    truth = load_sensor_model(MODELS / "sensors" / "biotac_proxy.yaml")
    import pandas as pd

    frame = pd.DataFrame(truth.record(3000, seed=3))
    fitted = SensorModel.from_recordings(frame, truth.materials)
    for material in ("wood", "plush", "feather"):
        a, b = truth.spec.materials[material], fitted.spec.materials[material]
        for feature in ("texture", "compliance"):
            x, y = getattr(a, feature), getattr(b, feature)
            # a skew-normal's mean and spread (its three parameters trade off one another)
            assert stats.skewnorm(y.skew, y.loc, y.scale).mean() == pytest.approx(
                stats.skewnorm(x.skew, x.loc, x.scale).mean(), abs=0.05 * x.scale)
            assert stats.skewnorm(y.skew, y.loc, y.scale).std() == pytest.approx(
                stats.skewnorm(x.skew, x.loc, x.scale).std(), rel=0.05)
    # and the two readings go together as they do (the correlation of the symmetric parts is
    # poorly determined where both features are strongly skewed; what they draw is not)
    for i, material in enumerate(truth.materials):
        z = np.random.default_rng(i).standard_normal((6000, 4))
        drawn = [stats.spearmanr(*m.draw(np.full(6000, i), z)).statistic for m in (truth, fitted)]
        assert drawn[1] == pytest.approx(drawn[0], abs=0.06), material


@pytest.mark.parametrize("edit, expected", [
    (("perception: {recordings: recordings.csv}", "perception: {recordings: none.csv}"),
     "recorded.yaml:4:28: recordings 'none.csv': no such file"),
    (("perception: {recordings: recordings.csv}",
      "perception: {recordings: recordings.csv, readings: {texture: E, roughness: C}}"),
     "recorded.yaml:4:28: recordings 'recordings.csv': no column 'roughness' (for C)"),
    (("background: cork", "background: oak"), "unknown material 'oak': expected one of cork, "
                                              "felt, steel"),
])
def test_a_labs_recordings_are_checked_at_their_line(tmp_path, capsys, edit, expected):
    path = recorded(tmp_path, edit)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err, err


def test_an_experiment_runs_on_a_labs_recordings_and_reports_where_they_came_from(tmp_path):
    path = recorded(tmp_path)
    experiment = tmp_path / "exp.yaml"
    experiment.write_text(f"experiment: 1\nname: lab\nrunner: haptic\nscenario: {path}\n"
                          "tasks: [follow_steel]\nconfigurations: [full, without_S]\nruns: 3\n"
                          "iterations: 8\nseed: 1\n")
    assert main(["run", str(experiment), "--out", str(tmp_path / "out"), "-q",
                 "--no-animation"]) == 0
    report = (tmp_path / "out" / "report" / "report.md").read_text()
    assert "learned from 900 probes of `recordings.csv`" in report
    assert "sensor model `fitted to recordings.csv`" in report
    # the recordings drawn in the perception section, after the recognition table
    perception = report.split("## Perception", 1)[1].split("\n## ", 1)[0]
    assert perception.index("| material in the scenario |") \
        < perception.index("![Recordings recordings.csv](recordings.png)")
    assert (tmp_path / "out" / "report" / "recordings.png").is_file()
    manifest = json.loads((tmp_path / "out" / "experiment.json").read_text())
    assert {"perception_recordings", "sensor_recordings"} <= set(manifest["files"])


def test_the_shipped_lab_example_is_checked_whole(capsys):
    files = [MODELS / "scenarios" / "lab_recorded.yaml", MODELS / "experiments" / "lab_recorded.yaml"]
    assert main(["validate", *map(str, files)]) == 0
    scenario = load_scenario(files[0])
    assert scenario.materials == ("cork", "felt", "steel") and scenario.warnings == []
    assert list(scenario.spec.tasks) == ["follow_steel", "follow_felt"]


def test_the_notebook_speaks_the_labs_task_names(tmp_path):
    from runner.report.notebook import Results, step_view

    path = recorded(tmp_path)
    experiment = tmp_path / "exp.yaml"
    experiment.write_text(f"experiment: 1\nname: lab\nrunner: haptic\nscenario: {path}\n"
                          "tasks: [follow_felt]\nconfigurations: [full, without_S]\nruns: 2\n"
                          "iterations: 6\nseed: 1\n")
    assert main(["run", str(experiment), "--out", str(tmp_path / "out"), "-q", "--no-report"]) == 0
    results = Results(tmp_path / "out")
    assert set(results.table()["task"]) == {"follow_felt"}
    view = step_view(tmp_path / "out", task="follow_felt", steps=3)
    assert "follow_felt" in view._repr_html_()
    with pytest.raises(Exception, match="expected one of follow_steel, follow_felt"):
        step_view(tmp_path / "out", task="T1", steps=3)
