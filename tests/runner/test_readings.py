"""A lab's own readings: perceived through whatever variables its pi_per declares (checked
against scipy.stats), missing ones summed out, drawn by simulated sensors seeded per run,
recorded, logged and checked at their line before anything runs."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

import bayesprog
from bayesprog.cli import main
from runner.attention.explorer import Explorer
from runner.experiments.log import SessionLog
from runner.experiments.loop import make_sensor
from runner.robot.recording import Recorder
from runner.robot.stdio import serve
from runner.world.readings import Perception, ReadingError, Readings
from runner.world.scenario import load_scenario

ROOT = Path(__file__).parents[2]
MODELS = ROOT / "models"
TRUTH = MODELS / "fingertip" / "fingertip_sensor.yaml"
FINGERTIP = MODELS / "scenarios" / "fingertip.yaml"


@pytest.fixture(scope="module")
def truth() -> Perception:
    return Perception(bayesprog.load(TRUTH))


@pytest.fixture(scope="module")
def fingertip():
    return load_scenario(FINGERTIP)


@pytest.fixture(scope="module")
def world():
    """The example's world: probes drawn from its true program, whose features depend on
    each other (no sensor: the perception program is drawn from)."""
    return load_scenario(MODELS / "scenarios" / "fingertip_truth.yaml")


def by_hand(pdc: float, pac: float | None, tdc: float | None, slip: str | None) -> np.ndarray:
    """P(M | the readings given) of models/fingertip/fingertip_sensor.yaml, by scipy.stats: pac_rms
    depends on pdc; electrode_var (left out) is summed out with its own Normal."""
    means = {"pine": (31.0, 3.0, -1.2, 0.25, 0.9, 0.3), "steel": (36.0, 2.5, -2.3, 0.2, 3.4, 0.4),
             "felt": (12.0, 3.5, -1.6, 0.3, 0.5, 0.25), "rubber": (21.0, 3.0, -2.0, 0.25, 1.3, 0.35)}
    slips = {"pine": 0.3, "steel": 0.6, "felt": 0.1, "rubber": 0.05}
    out = []
    for m, (mp, sp, a, sa, mt, st) in means.items():
        p = stats.norm(mp, sp).pdf(pdc)
        if pac is not None:
            p *= stats.norm(a + 0.02 * pdc, sa).pdf(pac)
        if tdc is not None:
            p *= stats.norm(mt, st).pdf(tdc)
        if slip is not None:
            p *= slips[m] if slip == "slip" else 1 - slips[m]
        out.append(p)
    out = np.array(out)
    return out / out.sum()


def test_features_that_depend_on_each_other_and_a_discrete_one_are_perceived_exactly(truth):
    assert truth.names == ("pdc", "pac_rms", "tdc", "electrode_var", "slip")
    assert truth.reading("slip").discrete and not truth.naive_normals
    nan = math.nan
    readings = Readings(truth.names, [[30.0, -0.6, 1.0, nan, 1], [25.0, nan, nan, nan, 0],
                                      [14.0, -1.4, 0.6, nan, nan]])
    got = truth.posterior(readings)
    expected = [by_hand(30.0, -0.6, 1.0, "slip"), by_hand(25.0, None, None, "stick"),
                by_hand(14.0, -1.4, 0.6, None)]
    np.testing.assert_allclose(got, expected, rtol=1e-10)


def test_a_probe_without_any_reading_is_refused(truth):
    with pytest.raises(ReadingError, match="nothing to perceive"):
        truth.posterior(Readings(truth.names, np.full((1, 5), np.nan)))


def test_readings_as_sent_name_states_and_refuse_what_is_not_a_reading(truth):
    r = truth.readings_of({"pdc": 20, "slip": "stick", "tdc": None})
    assert r.missing_names() == ["pac_rms", "tdc", "electrode_var"] and r["slip"][0] == 0.0
    assert truth.readings_of({"pdc": 20, "slip": 1})["slip"][0] == 1.0
    with pytest.raises(ReadingError, match="state 'slipped' is not one of stick, slip: did you "
                                           "mean 'slip'"):
        truth.readings_of({"slip": "slipped"})
    with pytest.raises(ReadingError, match="unknown reading.*'tcd'.*did you mean 'tdc'"):
        truth.readings_of({"tcd": 1.0})
    with pytest.raises(ReadingError, match="pdc: expected a number"):
        truth.readings_of({"pdc": "high"})


@pytest.mark.parametrize("which", ["world", "fingertip"])
def test_a_simulated_sensor_is_seeded_per_run_whatever_the_batch(which, request):
    scenario = request.getfixturevalue(which)  # drawn from the program; resampled recordings
    seeds = [(3, r, 1) for r in range(6)]
    cells = np.array([5, 100, 300, 400, 600, 700])
    together = make_sensor(scenario, seeds).probe(cells)
    for r in range(6):
        alone = make_sensor(scenario, seeds[r:r + 1]).probe(cells[r:r + 1])
        np.testing.assert_array_equal(alone.values, together.values[r:r + 1])
    again = make_sensor(scenario, seeds).probe(cells)
    np.testing.assert_array_equal(again.values, together.values)


def test_draws_of_the_program_follow_it_given_the_material(world):
    material = world.material_map.ravel()
    steel = np.flatnonzero(material == world.materials.index("steel"))[:1]
    sensor = make_sensor(world, [(1, r, 1) for r in range(3000)])
    drawn = sensor.probe(np.repeat(steel, 3000))
    assert stats.kstest(drawn["pdc"], stats.norm(36.0, 2.5).cdf).pvalue > 1e-3
    slope = np.polyfit(drawn["pdc"], drawn["pac_rms"], 1)[0]
    assert slope == pytest.approx(0.02, abs=0.01)  # the dependence is drawn, not dropped
    assert np.mean(drawn["slip"] == 1) == pytest.approx(0.6, abs=0.04)


def test_resampled_probes_are_rows_of_the_cells_material(fingertip):
    frame = pd.read_csv(MODELS / "data" / "fingertip_presses.csv")
    sensor = make_sensor(fingertip, [(2, r, 1) for r in range(50)])
    material = fingertip.material_map.ravel()
    cells = np.arange(0, 50 * 17, 17)
    drawn = sensor.probe(cells)
    for r, cell in enumerate(cells):
        rows = frame[frame["material"] == fingertip.materials[material[cell]]]
        assert np.isclose(rows["pdc"].to_numpy(), drawn["pdc"][r]).any()
        row = rows[np.isclose(rows["pdc"].to_numpy(), drawn["pdc"][r])].iloc[0]
        assert row["tdc"] == pytest.approx(drawn["tdc"][r])
        assert ["stick", "slip"][int(drawn["slip"][r])] == row["slip"]


def test_the_learned_program_keeps_the_observed_ranges_and_warns_only_outside_them(fingertip):
    frame = pd.read_csv(MODELS / "data" / "fingertip_presses.csv")
    record = fingertip.perception.learned[-1]
    for reading in ("pdc", "tdc"):
        assert record.ranges[reading]["*"] == [frame[reading].min(), frame[reading].max()]
        for m, rows in frame.groupby("material"):
            assert record.ranges[reading][f"M={m}"] == [rows[reading].min(), rows[reading].max()]
    perception = fingertip.readings
    readings = Readings.of(perception.names, {
        n: frame[n].map({"stick": 0, "slip": 1}) if n == "slip" else frame[n]
        for n in perception.names})
    assert not any(perception.range_warnings(readings, r) for r in range(len(frame)))
    far = perception.readings_of({"pdc": 500.0, "tdc": 1.0})
    assert "pdc 500 is outside [" in perception.range_warnings(far)[0]
    assert perception.far_warning(far).startswith("pdc 500 is ")  # in pdc's own units
    assert "tdc" not in perception.far_warning(far)


STDIO = [{"cell": [2, 2], "readings": {"pdc": 31.0, "pac_rms": -0.6, "tdc": 0.9,
                                       "electrode_var": 0.28, "slip": "stick"}},
         {"cell": [3, 2], "readings": {"pdc": 30.0, "tdc": None, "slip": "slip"}},
         {"cell": [3, 3], "pdc": 29.0, "pac_rms": float("nan")}]


def test_a_session_with_missing_and_discrete_readings_leaves_a_log_that_learns(tmp_path,
                                                                                fingertip):
    lines = "".join(json.dumps(line) + "\n" for line in STDIO)
    log = SessionLog(tmp_path / "session.csv")
    out = io.StringIO()
    assert serve(Explorer(fingertip, "follow_steel"), io.StringIO(lines), out, log=log) == 3
    log.close()
    replies = [json.loads(line) for line in out.getvalue().splitlines()]
    assert "missing" not in replies[0]
    assert replies[1]["missing"] == ["pac_rms", "tdc", "electrode_var"]
    assert replies[2]["missing"] == ["pac_rms", "tdc", "electrode_var", "slip"]
    table = pd.read_csv(tmp_path / "session.csv")
    assert list(table["step"]) == [0, 1, 2] and list(table["slip"].fillna("")) == [
        "stick", "slip", ""]
    assert table["tdc"].isna().tolist() == [False, True, True]
    assert list(table["material"]) == ["pine"] * 3
    assert list(table["decided"]) == [r["probed"]["material"] for r in replies]
    assert [[a, b] for a, b in zip(table["next_ix"], table["next_iy"], strict=True)] == [
        r["next"] for r in replies]
    meta = json.loads((tmp_path / "session.json").read_text())
    assert meta["task"] == "follow_steel" and meta["readings"] == list(fingertip.readings.names)


def test_recording_a_labs_sensor_over_stdio_writes_recordings_that_learn(tmp_path, fingertip):
    recorder = Recorder(fingertip, tmp_path / "presses.csv")
    rng = np.random.default_rng(5)
    lines = []
    for material, (pdc, tdc) in {"steel": (36, 3.4), "felt": (12, 0.5)}.items():
        for _ in range(20):
            lines.append(json.dumps({"material": material, "readings": {
                "pdc": pdc + rng.normal(), "pac_rms": -1.5 + 0.1 * rng.normal(),
                "tdc": tdc + 0.1 * rng.normal(), "electrode_var": 0.3 + 0.01 * rng.normal(),
                "slip": ["stick", "slip"][int(rng.integers(2))]}}))
    lines += [json.dumps({"cell": [0, 0], "pdc": 30.0}),  # pine in the layout
              json.dumps({"cell": [0, 0], "material": "felt", "pdc": 30.0}),
              json.dumps({"material": "steel"})]
    replies = [recorder.answer(line) for line in lines]
    recorder.close()
    assert replies[39] == {"recorded": 40, "material": "felt"}
    assert replies[40] == {"recorded": 41, "material": "pine"}
    assert "not felt: expected the two to agree" in replies[41]["error"]
    assert "nothing recorded" in replies[42]["error"]
    table = pd.read_csv(tmp_path / "presses.csv")
    assert list(table.columns) == ["material", *fingertip.readings.names, "ix", "iy"]
    assert len(table) == 41 and table.iloc[40]["ix"] == 0 and np.isnan(table.iloc[0]["ix"])
    steel = table[table["material"] == "steel"]
    program = bayesprog.load(MODELS / "fingertip" / "fingertip_per.yaml")
    labelled = table[table["material"] != "pine"]  # one press of pine: too few to learn
    fitted = program.fit(labelled[["material", *fingertip.readings.names]].rename(
        columns={"material": "M"}), states_from_data=["M"]).program
    mean = fitted.term("P(pdc | M)").params["mean"].array  # type: ignore[union-attr]
    states = fitted.variables["M"].states  # type: ignore[union-attr]
    assert mean[list(states).index("steel")] == pytest.approx(steel["pdc"].mean())


def write_scenario(tmp_path: Path, old: str, new: str) -> Path:
    text = FINGERTIP.read_text().replace("../", f"{MODELS}/").replace(old, new)
    assert text != FINGERTIP.read_text().replace("../", f"{MODELS}/"), old
    path = tmp_path / "lab.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("old, new, expected", [
    ("readings: [pdc, pac_rms, tdc, electrode_var, slip]",
     "readings: [pdc, pac_rms, tcd, electrode_var, slip]",
     "lab.yaml:14:15: perception program 'fingertip_per': fingertip_per declares no variable "
     "'tcd' for the reading 'tcd': did you mean 'tdc'?"),
    ("    material: M\n", "    material: m\n",
     "lab.yaml:13:15: perception program 'fingertip_per': fingertip_per declares no material "
     "variable 'm': did you mean 'M'?"),
    ("  resample: ../data/fingertip_presses.csv", "  model: ../sensors/biotac_proxy.yaml",
     "a sensor model gives the readings texture, compliance (the paper's), but the perception "
     "program reads pdc, pac_rms, tdc, electrode_var, slip"),
    ("  resample: ../data/fingertip_presses.csv",
     "  physics: {readings: {pdc: pressure, tcd: temperature_drop}}",
     "reading 'tcd': the perception program reads no such reading: did you mean 'tdc'?"),
    ("  resample: ../data/fingertip_presses.csv", "  physics: {readings: {slip: friction_ratio}}",
     "reading 'slip' is discrete (states stick, slip): the fingertip's features are numbers"),
])
def test_what_a_lab_gets_wrong_is_refused_at_its_line_before_anything_runs(
        tmp_path, capsys, old, new, expected):
    path = write_scenario(tmp_path, old.replace("../", f"{MODELS}/"),
                          new.replace("../", f"{MODELS}/"))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err, err


def test_a_resampled_file_without_a_readings_column_is_refused_at_its_line(tmp_path, capsys):
    frame = pd.read_csv(MODELS / "data" / "fingertip_presses.csv").drop(columns=["tdc"])
    frame.to_csv(tmp_path / "short.csv", index=False)
    path = write_scenario(tmp_path, f"resample: {MODELS}/data/fingertip_presses.csv",
                          f"resample: {tmp_path}/short.csv")
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    line = path.read_text().splitlines().index(f"  resample: {tmp_path}/short.csv") + 1
    assert f"lab.yaml:{line}:13: recordings" in err and "no column 'tdc'" in err, err


def test_a_labs_experiment_runs_through_its_own_readings(tmp_path):
    experiment = tmp_path / "exp.yaml"
    experiment.write_text(f"experiment: 1\nname: lab\nrunner: haptic\nscenario: {FINGERTIP}\n"
                          "tasks: [follow_felt]\nconfigurations: [full, without_S]\n"
                          "runs: 3\niterations: 12\nseed: 4\n")
    assert main(["run", str(experiment), "--out", str(tmp_path / "out"), "-q",
                 "--no-report"]) == 0
    assert main(["results", str(tmp_path / "out"), "-o", str(tmp_path / "runs.csv")]) == 0
    table = pd.read_csv(tmp_path / "runs.csv")
    assert set(table["configuration"]) == {"full", "without_S"}
    # every probe's readings, by name, are rows of the recordings of the cell's material
    scenario = load_scenario(FINGERTIP)
    presses = pd.read_csv(MODELS / "data" / "fingertip_presses.csv")
    assert list(table.columns[-5:]) == list(scenario.readings.names)
    assert set(table["slip"]) <= {"stick", "slip"}
    truth = scenario.material_map.ravel()[table["cell"]]
    for (pdc, tdc), m in zip(table[["pdc", "tdc"]].to_numpy(), truth, strict=True):
        rows = presses[presses["material"] == scenario.materials[m]]
        assert np.isclose(rows["pdc"], pdc).any() and np.isclose(rows["tdc"], tdc).any()


def test_a_bad_row_of_the_recordings_is_refused_at_its_line_or_set_aside_when_asked(
        tmp_path, capsys):
    lines = (MODELS / "data" / "fingertip_presses.csv").read_text().splitlines()
    lines[7] = lines[7] + ",extra"  # line 8: a field too many
    lines[12] = lines[12].replace("stick", "stuck").replace("slip,", "stuck,")  # line 13
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    path = write_scenario(tmp_path, f"recordings: {MODELS}/data/fingertip_presses.csv",
                          f"recordings: {tmp_path}/bad.csv")
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "line 8" in err and "fields" in err and "on_bad_lines: skip" in err, err
    text = path.read_text().replace("    material: M\n", "    material: M\n    on_bad_lines: skip\n")
    path.write_text(text)
    scenario = load_scenario(path)
    warned = " ".join(str(w) for w in scenario.warnings)
    assert "2 bad row(s) set aside" in warned and "line 8" in warned and "line 13" in warned
    assert "'stuck'" in warned and "did you mean" in warned
    assert scenario.perception.learned[-1].rows_set_aside == 2
    assert scenario.perception.learned[-1].rows_used == len(lines) - 1 - 2


def test_a_session_log_learns_pi_per_again(tmp_path, fingertip):
    sensor = make_sensor(fingertip, [(9, 0, 1)])
    explorer = Explorer(fingertip, "follow_felt")
    log = SessionLog(tmp_path / "log.csv")
    from runner.robot.session import Session, probe_line

    session = Session(explorer, seed=3, log=log)
    cell = [4, 4]
    for _ in range(60):
        flat = int(np.ravel_multi_index(tuple(cell), fingertip.shape))
        reply = session.answer(json.dumps(probe_line(cell, sensor.probe(np.array([flat])),
                                                     perception=fingertip.readings)))
        cell = reply["next"]
    log.close()
    out = tmp_path / "relearned.yaml"
    assert main(["learn", str(MODELS / "fingertip" / "fingertip_per.yaml"), str(tmp_path / "log.csv"),
                 "--column", "material=M", "--states-from-data", "M", "--ignore-other-columns",
                 "-o", str(out)]) == 0
    relearned = bayesprog.load(out)
    table = pd.read_csv(tmp_path / "log.csv")
    states = list(relearned.variables["M"].states)  # type: ignore[union-attr]
    assert states == sorted(set(table["material"]))
    mean = relearned.term("P(tdc | M)").params["mean"].array  # type: ignore[union-attr]
    for m, rows in table.groupby("material"):
        assert mean[states.index(m)] == pytest.approx(rows["tdc"].mean(), rel=1e-12)
    assert main(["learn", str(MODELS / "fingertip" / "fingertip_per.yaml"), str(tmp_path / "log.csv"),
                 "--column", "material=M", "--states-from-data", "M", "-o",
                 str(tmp_path / "refused.yaml")]) == 2  # its cells are no variable's


def test_the_paper_readings_under_other_names_read_a_tab_separated_file_with_a_bom(tmp_path):
    """A lab's program names its material and features its own way; its recordings are a
    spreadsheet's export: tab-separated, with a byte-order mark."""
    program = (MODELS / "pi_per.yaml").read_text().replace("  M:\n", "  Mat:\n").replace(
        "  E: {", "  T: {").replace("  C: {", "  K: {").replace("| M)", "| Mat)").replace(
        "P(E |", "P(T |").replace("P(C |", "P(K |").replace("P(M)", "P(Mat)").replace(
        "P(M | E, C)", "P(Mat | T, K)")
    (tmp_path / "lab_per.yaml").write_text(program)
    frame = pd.read_csv(MODELS / "data" / "lab_recordings.csv")
    (tmp_path / "lab.tsv").write_text("\ufeff" + frame.to_csv(sep="\t", index=False))
    scenario = (MODELS / "scenarios" / "lab_recorded.yaml").read_text().replace(
        "../pi_obj.yaml", str(MODELS / "pi_obj.yaml")).replace(
        "../pi_tar.yaml", str(MODELS / "pi_tar.yaml")).replace(
        "perception: {recordings: ../data/lab_recordings.csv}",
        "perception: {recordings: lab.tsv, program: lab_per.yaml, material: Mat, "
        "readings: {texture: T, compliance: K}}").replace(
        "recordings: ../data/lab_recordings.csv", "recordings: lab.tsv")
    (tmp_path / "lab.yaml").write_text(scenario)
    lab = load_scenario(tmp_path / "lab.yaml")
    assert lab.readings.names == ("texture", "compliance") and lab.readings.material == "Mat"
    mean = lab.perception.term("P(T | Mat)").params["mean"].array  # type: ignore[union-attr]
    states = list(lab.perception.variables["Mat"].states)  # type: ignore[union-attr]
    for m, rows in frame.groupby("material"):
        assert mean[states.index(m)] == pytest.approx(rows["texture"].mean(), rel=1e-12)
    assert lab.sensor_model is not None and lab.sensor_model.materials == tuple(states)


def test_ranges_cover_every_data_set_a_continued_fit_learned_from(tmp_path):
    frame = pd.read_csv(MODELS / "data" / "fingertip_presses.csv")
    columns = ["material", *load_scenario(FINGERTIP).readings.names]
    first, second = frame.iloc[::2][columns], frame.iloc[1::2][columns]
    first.to_csv(tmp_path / "a.csv", index=False)
    second.to_csv(tmp_path / "b.csv", index=False)
    once = bayesprog.load(MODELS / "fingertip" / "fingertip_per.yaml").fit(
        str(tmp_path / "a.csv"), columns={"material": "M"}, states_from_data=["M"]).program
    twice = once.fit(str(tmp_path / "b.csv"), columns={"material": "M"}).program
    ranges = Perception(twice).ranges["pdc"]
    assert ranges["*"] == (frame["pdc"].min(), frame["pdc"].max())
    for m, rows in frame.groupby("material"):
        assert ranges[m] == (rows["pdc"].min(), rows["pdc"].max())


def test_validate_refuses_two_readings_of_one_variable(tmp_path, capsys):
    path = write_scenario(tmp_path, "readings: [pdc, pac_rms, tdc, electrode_var, slip]",
                          "readings: {a: pdc, b: pdc}")
    assert main(["validate", str(path)]) == 2
    assert "readings 'a' and 'b' are both the variable 'pdc'" in capsys.readouterr().err


def test_a_fingertip_that_gives_some_readings_leaves_the_others_missing(tmp_path):
    path = write_scenario(tmp_path, f"  resample: {MODELS}/data/fingertip_presses.csv",
                          "  physics: {readings: {pdc: pressure, tdc: temperature_drop}}")
    scenario = load_scenario(path)
    warned = " ".join(str(w) for w in scenario.warnings)
    assert "the fingertip gives no pac_rms, electrode_var, slip" in warned
    sensor = make_sensor(scenario, [(0, 0, 1)])
    readings = sensor.probe(np.array([5]))
    assert readings.names == ("pdc", "tdc")
    explorer = Explorer(scenario, "follow_felt")
    explorer.reset(start=[0, 5], seed=0)
    explorer.step(np.array([5]), readings)  # the others summed out
    by_hand = scenario.readings.program.ask(
        "P(M | pdc, tdc)", {"pdc": readings["pdc"], "tdc": readings["tdc"]}).probabilities
    np.testing.assert_allclose(explorer.posterior[0, 5], by_hand[0], rtol=1e-12)


MIXTURE = """\
bayesprog: 1
name: mixture_per
variables:
  M: {states: [felt, pine, rubber, steel]}
  pdc: {continuous: [-.inf, .inf]}
  tdc: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(M), form: uniform}
  - term: P(pdc | M)
    form: gmm
    means: {felt: [10.0, 14.0], pine: [28.0, 33.0], rubber: [19.0, 23.0], steel: [34.0, 38.0]}
    sigma: 2.0
    learn: {components: 2}
  - {term: P(tdc | M), form: normal, mean: 1.0, sigma: 1.0}
"""


def test_a_mixture_per_material_learned_from_the_recordings_is_perceived_exactly(tmp_path):
    (tmp_path / "mixture.yaml").write_text(MIXTURE)
    path = write_scenario(tmp_path, "    program: ../fingertip/fingertip_per.yaml".replace(
        "../", f"{MODELS}/"), f"    program: {tmp_path}/mixture.yaml")
    path.write_text(path.read_text().replace(
        "readings: [pdc, pac_rms, tdc, electrode_var, slip]", "readings: [pdc, tdc]"))
    scenario = load_scenario(path)
    assert scenario.readings.names == ("pdc", "tdc") and not scenario.readings.naive_normals
    program = scenario.perception
    mix = program.term("P(pdc | M)").params
    means, sigma, weights = (np.asarray(mix[k].array) for k in ("means", "sigma", "weights"))  # type: ignore[union-attr]
    normal = program.term("P(tdc | M)").params
    mu, sd = (np.asarray(normal[k].array) for k in ("mean", "sigma"))  # type: ignore[union-attr]
    explorer = Explorer(scenario, "follow_rubber")
    explorer.reset(start=[0, 0], seed=0)
    explorer.observe([0, 0], {"pdc": 20.0, "tdc": 1.2})
    density = (weights * stats.norm(means, sigma[:, None]).pdf(20.0)).sum(axis=1)
    density *= stats.norm(mu, sd).pdf(1.2)
    np.testing.assert_allclose(explorer.posterior[0, 0], density / density.sum(), rtol=1e-10)
