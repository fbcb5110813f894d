"""The report's perception section shows the recordings a scenario learns from: the figure
drawn, the readings it draws (not the cell nor a press's raw figures), one figure per file, the
copy stored with the results rather than the file as edited since."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from runner.report.build import (
    NOT_READINGS,
    RECORDINGS_FIGURES,
    recording_columns,
    recordings_section,
)
from runner.robot.presses import RAW_COLUMNS
from runner.world.scenario import load_scenario

MODELS = Path(__file__).parents[2] / "models"

SCENARIO = """\
scenario: 1
name: recorded
programs:
  perception: {{recordings: {perception}}}
  shape: {models}/pi_obj.yaml
  target: {models}/pi_tar.yaml
grid: {{shape: [20, 30], cell: 0.01}}
background: cork
templates:
  square: [[-0.04, -0.04], [0.04, -0.04], [0.04, 0.04], [-0.04, 0.04]]
objects:
  - {{template: square, material: steel, at: [0.08, 0.08], rotation: 10}}
tasks:
  follow_steel: steel
{sensor}"""


def presses(path: Path, seed: int, empty: int = 0) -> pd.DataFrame:
    """A lab's presses as `bayesprog record --physics` writes them: the material, the two
    readings, the cell and the raw figures; ``empty`` texture cells left empty."""
    rng = np.random.default_rng(seed)
    material = np.repeat(["cork", "felt", "steel"], 40)
    frame = pd.DataFrame({
        "material": material,
        "texture": rng.normal(np.repeat([0.5, 0.65, 0.13], 40), 0.05),
        "compliance": rng.normal(np.repeat([0.08, 0.6, 0.35], 40), 0.05),
        "ix": rng.integers(0, 20, material.size), "iy": rng.integers(0, 30, material.size),
        "force_n": rng.normal(1, 0.01, material.size),
        "depth_m": rng.normal(1e-3, 1e-4, material.size)})
    frame.loc[rng.choice(material.size, empty, replace=False), "texture"] = None
    frame.to_csv(path, index=False)
    return frame


def scenario_at(tmp_path: Path, perception: str, sensor: str | None = None):
    text = SCENARIO.format(models=MODELS, perception=perception,
                           sensor=f"sensor:\n  recordings: {sensor}\n" if sensor else "")
    path = tmp_path / "scenario.yaml"
    path.write_text(text)
    return load_scenario(path)


def test_the_readings_are_drawn_beside_the_recognition_table(tmp_path):
    presses(tmp_path / "presses.csv", seed=1, empty=3)
    folder = tmp_path / "report"
    folder.mkdir()
    lines = recordings_section(scenario_at(tmp_path, "presses.csv"), folder)
    assert lines[:2] == ["", "![Recordings presses.csv](recordings.png)"]
    caption = lines[3]
    assert "`presses.csv` that pi_per is learned from: 120 presses (cork 40, felt 40, " \
           "steel 40)" in caption
    assert "every pair of the readings texture, compliance," in caption
    assert "Missing readings, each left out of the pairs it is in: texture 3." in caption
    assert (folder / "recordings.png").read_bytes()[:4] == b"\x89PNG"
    assert not (folder / "recordings_2.png").exists()


def test_the_readings_are_the_columns_but_the_cell_and_the_raw_figures(tmp_path):
    frame = presses(tmp_path / "p.csv", seed=2)
    assert recording_columns(list(frame.columns[1:])) == ["texture", "compliance"]
    frame = frame.assign(pdc=1.0, iz=0, electrode="x")
    assert recording_columns(list(frame.columns[1:])) == ["texture", "compliance", "pdc",
                                                          "electrode"]
    # every raw figure a physics press records is known not to be a reading
    assert set(RAW_COLUMNS.values()) <= set(NOT_READINGS)


def test_a_file_learned_from_and_fitted_to_is_drawn_once_two_files_twice(tmp_path):
    presses(tmp_path / "a.csv", seed=3)
    presses(tmp_path / "b.csv", seed=4)
    folder = tmp_path / "report"
    folder.mkdir()
    lines = recordings_section(scenario_at(tmp_path, "a.csv", "a.csv"), folder)
    assert sum(line.startswith("![") for line in lines) == 1
    assert "that pi_per is learned from and the simulated sensor is fitted to" in lines[3]
    lines = recordings_section(scenario_at(tmp_path, "a.csv", "b.csv"), folder)
    assert [line for line in lines if line.startswith("![")] == [
        "![Recordings a.csv](recordings.png)", "![Recordings b.csv](recordings_2.png)"]
    assert all((folder / png).is_file() for png in RECORDINGS_FIGURES)
    # a scenario without recordings: no lines, and an earlier report's figures gone
    assert recordings_section(load_scenario(MODELS / "scenarios" / "paper.yaml"), folder) == []
    assert not any((folder / png).exists() for png in RECORDINGS_FIGURES)


def test_the_readings_a_perception_names_are_the_ones_drawn(tmp_path):
    presses(tmp_path / "presses.csv", seed=5)
    folder = tmp_path / "report"
    folder.mkdir()
    lines = recordings_section(scenario_at(tmp_path, "presses.csv"), folder,
                               readings=["compliance"])
    assert "every pair of the readings compliance," in lines[3]


def test_the_copy_stored_with_the_results_is_drawn(tmp_path):
    stored = presses(tmp_path / "presses.csv", seed=6)
    text = (tmp_path / "presses.csv").read_text()
    scenario = scenario_at(tmp_path, "presses.csv")
    out = tmp_path / "out"
    (out / "report").mkdir(parents=True)
    path = scenario.recordings_paths()["perception_recordings"]
    (out / "experiment.json").write_text(json.dumps({
        "experiment": {}, "start_cells": [], "hash": "0",
        "files": {"perception_recordings": {"path": str(path), "text": text}}}))
    stored.iloc[:30].to_csv(tmp_path / "presses.csv", index=False)  # edited since the run
    lines = recordings_section(scenario, out / "report")
    assert "120 presses (cork 40, felt 40, steel 40)" in lines[3]


def test_a_reading_the_recordings_lack_is_named(tmp_path):
    from bayesprog import BayesprogError

    presses(tmp_path / "presses.csv", seed=7)
    folder = tmp_path / "report"
    folder.mkdir()
    with pytest.raises(BayesprogError, match="presses.csv: no column 'nope'"):
        recordings_section(scenario_at(tmp_path, "presses.csv"), folder, readings=["nope"])
