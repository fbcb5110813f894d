"""pi_per identified as in the paper: probes recorded from a sensor model that is not pi_per,
pi_per learned from them by `bayesprog learn`, the simulator drawing from the sensor model."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

import bayesprog
from bayesprog.cli import main
from runner.experiments.experiment import load_experiment, load_results, make_sensor, run_experiment
from runner.experiments.store import ResultStore
from runner.report.build import build_report, replay
from runner.world.scenario import load_scenario
from runner.world.sensor import SensorModel, SimulatedSensor, confusion, load_sensor_model
from runner.world.sensor import main as record_main

MODELS = Path(__file__).parents[2] / "models"
MATERIALS = bayesprog.load(MODELS / "pi_per.yaml").variables["M"].states


def test_the_shipped_probes_are_recorded_from_the_sensor_model_with_their_seed(tmp_path):
    out = tmp_path / "probes.csv"
    assert record_main([str(MODELS / "sensors" / "biotac_proxy.yaml"), "--perception",
                        str(MODELS / "pi_per.yaml"), "--per-material", "300", "--seed", "1",
                        "-o", str(out)]) == 0
    assert out.read_bytes() == (MODELS / "data" / "probes.csv").read_bytes()


def test_the_recording_command_keeps_its_address(tmp_path):
    """``python -m runner.sensor`` records as it always did (the sensors moved to runner.world)."""
    import subprocess
    import sys

    out = tmp_path / "probes.csv"
    done = subprocess.run([sys.executable, "-m", "runner.sensor",
                           str(MODELS / "sensors" / "biotac_proxy.yaml"), "--perception",
                           str(MODELS / "pi_per.yaml"), "--per-material", "300", "--seed", "1",
                           "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert out.read_bytes() == (MODELS / "data" / "probes.csv").read_bytes()
    refused = subprocess.run([sys.executable, "-m", "runner.sensor", "nowhere.yaml", "-o",
                              str(out)], capture_output=True, text=True, timeout=120)
    assert refused.returncode == 2 and refused.stderr.startswith("runner.sensor: ")
    assert "Traceback" not in refused.stderr


def test_the_shipped_identified_pi_per_is_learned_from_the_shipped_probes(tmp_path):
    out = tmp_path / "fitted.yaml"
    assert main(["learn", str(MODELS / "pi_per.yaml"), str(MODELS / "data" / "probes.csv"),
                 "-o", str(out), "--rounded"]) == 0  # shipped to the digits 3000 rows support
    shipped, fitted = bayesprog.load(MODELS / "pi_per_identified.yaml"), bayesprog.load(out)
    for term in ("P(E | M)", "P(C | M)"):
        for name in ("mean", "sigma"):
            np.testing.assert_allclose(shipped.term(term).params[name].array,
                                       fitted.term(term).params[name].array, rtol=1e-12)
    assert shipped.learned[-1].sha256 == fitted.learned[-1].sha256


def test_the_sensor_model_is_not_a_normal_of_one_spread():
    data = pd.read_csv(MODELS / "data" / "probes.csv")
    by = {m: g for m, g in data.groupby("M")}
    assert stats.skewtest(by["acrylic"]["E"]).pvalue < 1e-6  # skewed
    assert stats.skewtest(by["feather"]["C"]).statistic < 0  # skewed the other way
    r = stats.pearsonr(by["damp_sponge"]["E"], by["damp_sponge"]["C"])
    assert r.statistic > 0.2 and r.pvalue < 1e-4  # correlated features
    spreads = data.groupby("M")["E"].std()
    assert spreads.max() / spreads.min() > 2  # unequal spreads


def test_the_simulator_draws_from_the_sensor_model_never_from_pi_per():
    scenario = load_scenario(MODELS / "scenarios" / "paper_identified.yaml")
    seeds = [(1, r, 1) for r in range(5)]
    cells = np.arange(5) * 300
    hand = bayesprog.load(MODELS / "pi_per.yaml")
    a = make_sensor(scenario, seeds)
    b = make_sensor(scenario, seeds, perception=scenario.readings.with_program(hand))
    assert isinstance(a, SimulatedSensor) and isinstance(a.model, SensorModel)
    np.testing.assert_array_equal(a.probe(cells).values, b.probe(cells).values)
    model = load_sensor_model(MODELS / "sensors" / "biotac_proxy.yaml", MATERIALS)
    z = np.array([np.random.default_rng(s).standard_normal(6) for s in seeds])
    expected = model.draw(scenario.material_map.ravel()[cells], z[:, :4])
    drawn = make_sensor(scenario, seeds, perception=scenario.readings.with_program(hand))
    np.testing.assert_allclose(drawn.probe(cells).values, np.stack(expected, axis=1))


def test_wood_is_the_hardest_of_the_scenario_materials_for_the_identified_pi_per():
    model = load_sensor_model(MODELS / "sensors" / "biotac_proxy.yaml", MATERIALS)
    matrix = confusion(bayesprog.load(MODELS / "pi_per_identified.yaml"), model, 1000, 3)
    np.testing.assert_allclose(matrix.sum(1), 1.0)
    rate = dict(zip(MATERIALS, np.diag(matrix), strict=True))
    assert rate["wood"] < min(rate["plush"], rate["silicone"])
    assert np.diag(matrix).mean() > 0.85


def test_a_sensor_model_without_a_material_is_refused_at_its_place(tmp_path):
    text = (MODELS / "sensors" / "biotac_proxy.yaml").read_text()
    cut = text[: text.index("  wood:")]
    path = tmp_path / "partial.yaml"
    path.write_text(cut)
    with pytest.raises(bayesprog.SpecError, match=r"partial.yaml:\d+:\d+: no model for material"):
        load_sensor_model(path, MATERIALS)


def test_the_report_sets_the_findings_of_two_experiments_side_by_side(tmp_path):
    import yaml

    outs = []
    for name in ("paper", "paper_identified"):
        spec = {"experiment": 1, "name": name, "runner": "haptic",
                "scenario": str(MODELS / "scenarios" / f"{name}.yaml"), "tasks": ["T1", "T3"],
                "configurations": ["full", "without_S", "without_U"], "runs": 3,
                "iterations": 30, "seed": 3, "chunk": 3}
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(spec))
        run_experiment(load_experiment(path), tmp_path / name, progress=False)
        outs.append(tmp_path / name)
    # Fig. 11 replays a stored run: with a sensor model it must draw the same probes
    experiment = load_experiment(tmp_path / "paper_identified.yaml")
    stored = load_results(ResultStore(outs[1]), experiment.spec)["T3/full"]["paths"]
    for run in range(3):
        frames = list(replay(experiment, "T3", "full", run, 30))
        assert [f["cell"] for f in frames] == stored[run].tolist()
    build_report(outs[0], animation=False)
    text = (build_report(outs[1], animation=False, compare=outs[0]) / "report.md").read_text()
    assert "## The findings beside experiment paper" in text
    assert "| the paper | paper_identified | paper |" in text
    assert "learned from 3000 probes of `probes.csv`" in text
    assert "sensor model `biotac_proxy`" in text
