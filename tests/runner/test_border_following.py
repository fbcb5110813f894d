"""The behaviour the saliency of the perceived stimulus must produce, on small workspaces.

* A walker started next to a border follows it with the full model and does not without S;
* the scenario's grid sets pi_tar's grid (no copy of pi_tar per grid size), and a scenario that
  does not fit pi_tar is refused when it is loaded, at FILE:LINE:COL.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import bayesprog
from runner.attention.explorer import Explorer
from runner.experiments.experiment import simulate
from runner.experiments.metrics import behaviour
from runner.world.readings import paper_readings
from runner.world.scenario import load_scenario

MODELS = (Path(__file__).parents[2] / "models").resolve()


def write(tmp_path: Path, grid=(20, 24), tasks="T2: silicone\n  T3: wood",
          templates=None, name="small.yaml",
          objects="  - {template: rectangle, material: silicone, at: [0.10, 0.12], "
                  "rotation: 15}") -> Path:
    templates = templates or (
        "  rectangle: [[-0.07, -0.05], [0.07, -0.05], [0.07, 0.05], [-0.07, 0.05]]\n"
        "  triangle: [[-0.09, -0.06], [0.09, -0.06], [0.0, 0.09]]")
    text = f"""\
scenario: 1
name: small
programs:
  perception: {MODELS / "pi_per.yaml"}
  shape: {MODELS / "pi_obj.yaml"}
  target: {MODELS / "pi_tar.yaml"}
grid: {{shape: [{grid[0]}, {grid[1]}], cell: 0.01}}
background: wood
templates:
{templates}
objects:
{objects}
tasks:
  {tasks}
"""
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_full_model_follows_a_border_that_a_walker_without_s_does_not(tmp_path):
    """Eight runs started on cells of the silicone border (T2), 40 steps: with S the walker stays
    near the border and probes a good part of it; without S it wanders off into the wood."""
    scenario = load_scenario(write(tmp_path))
    border = scenario.border("T2")
    cells = np.argwhere(border)
    starts = cells[np.linspace(0, len(cells) - 1, 8).astype(int)]
    result = {}
    for conf in ("full", "without_S"):
        paths = simulate(scenario, "T2", conf, starts, np.arange(8), seed=3,
                         iterations=40)["paths"]
        result[conf] = behaviour(paths, border)
    full, without_s = result["full"], result["without_S"]
    assert full["border_probed"] > 0.25, full
    assert full["border_probed"] > 1.5 * without_s["border_probed"], result
    assert full["enrichment"] > 1.5 * without_s["enrichment"], result


def test_the_scenario_grid_sets_pi_tar_grid(tmp_path):
    scenario = load_scenario(write(tmp_path, grid=(13, 9)))
    assert scenario.target.variables["O"].card == 13 * 9
    assert scenario.shape == (13, 9)
    paths = simulate(scenario, "T3", "full", np.array([[1, 1], [12, 8]]), np.arange(2), seed=1,
                     iterations=12)["paths"]
    assert paths.shape == (2, 12) and paths.min() >= 0 and paths.max() < 13 * 9


def test_pi_tar_takes_the_scenarios_tasks_whatever_their_names(tmp_path):
    path = write(tmp_path, tasks="T2: silicone\n  T4: wood")
    scenario = load_scenario(path)
    assert scenario.target.variables["T"].states == ("T2", "T4")
    explorer = Explorer(scenario, "T4")
    explorer.reset(start=[1, 1], seed=0)
    assert len(explorer.observe([1, 1], {"texture": 0.5, "compliance": 0.08})) == 2


def test_the_scenario_templates_are_the_shapes_of_pi_tar_and_pi_obj(tmp_path):
    """Any number of templates, polygons or curves: R of pi_tar and of pi_obj (its soft
    evidence) takes their names, and the explorer decides with all of them."""
    path = write(tmp_path, templates=(
        "  rectangle: [[-0.07, -0.05], [0.07, -0.05], [0.07, 0.05], [-0.07, 0.05]]\n"
        "  disc: {circle: 0.04}\n"
        "  oval: {ellipse: [0.06, 0.03], vertices: 64}\n"
        "  l_shape: [[-0.04, -0.05], [0.04, -0.05], [0.04, -0.02], [-0.01, -0.02], "
        "[-0.01, 0.05], [-0.04, 0.05]]"))
    scenario = load_scenario(path)
    names = ("rectangle", "disc", "oval", "l_shape")
    assert scenario.target.variables["R"].states == names
    assert scenario.load_shape().variables["R"].states == names
    oval = scenario.templates["oval"][0]
    assert oval.shape == (64, 2)
    x, y = oval[:, 0], oval[:, 1]  # shoelace area of the 64-gon inscribed in the ellipse
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    assert area == pytest.approx(32 * 0.06 * 0.03 * np.sin(2 * np.pi / 64), rel=1e-12)
    result = simulate(scenario, "T2", "full", np.array([[3, 3], [15, 20]]), np.arange(2), seed=1,
                      iterations=30)
    assert result["paths"].shape == (2, 30)


@pytest.mark.parametrize("template, expected", [
    ("{ellipse: [0.05, -0.01]}", "templates.oval: ellipse: expected two positive semi-axes"),
    ("{ellipse: [0.05]}", "ellipse: expected two positive semi-axes [a, b] (metres), found"),
    ("{ellipse: [0.05, 0.02], circle: 0.03}", "expected exactly one of 'ellipse: [a, b]'"),
    ("{square: 0.03}", "square"),
    ("{circle: -0.01}", "circle: expected a positive radius"),
    ("[[0, 0], [0.01, 0]]", "templates.oval: polygon: expected at least 3 points"),
])
def test_a_bad_curve_template_is_refused_at_its_place(tmp_path, template, expected):
    path = write(tmp_path, templates=(
        "  rectangle: [[-0.07, -0.05], [0.07, -0.05], [0.07, 0.05], [-0.07, 0.05]]\n"
        f"  oval: {template}"))
    with pytest.raises(bayesprog.SpecError) as err:
        load_scenario(path)
    line = path.read_text().splitlines().index(f"  oval: {template}") + 1
    assert f"{path}:{line}:" in str(err.value) and expected in str(err.value)


def test_a_saliency_that_vetoes_every_cell_is_left_out(tmp_path):
    """A small grid of wood probed everywhere (task T2, silicone): no cell has any saliency,
    so S is unobserved for every cell, and I and U choose. One cell read as silicone instead
    brings saliency back."""
    from runner.attention.explorer import Explorer

    # silicone laid out under one corner cell (a task's material must be in the layout); the
    # readings below are chosen by the test, whatever lies under the cells
    corner = "  - {polygon: [[0.03, 0.03], [0.04, 0.03], [0.04, 0.04], [0.03, 0.04]], " \
             "material: silicone}"
    scenario = load_scenario(write(tmp_path, grid=(4, 4), objects=corner))
    readings = {"wood": (0.52, 0.08), "silicone": (0.12, 0.35)}  # texture, compliance in pi_per
    fields = []
    for odd in (None, (3, 3)):
        explorer = Explorer(scenario, "T2")
        explorer.reset(start=(0, 0), seed=1)
        for ix in range(4):
            for iy in range(4):
                texture, compliance = readings["silicone" if (ix, iy) == odd else "wood"]
                explorer.perceive(explorer.flat(np.array([[ix, iy]])),
                                  paper_readings(texture, compliance))
        fields.append(explorer.cue_fields()[1][0])
    assert np.isnan(fields[0]).all()
    assert not np.isnan(fields[1]).all() and np.nanmax(fields[1]) > 0.5


def test_a_misperceived_cell_of_a_material_absent_from_the_workspace_is_no_discontinuity():
    """The task's discontinuity is between its material and the remaining materials of the
    workspace (the paper's Material_a and Material_b): a wood cell read as copper, which the
    workspace does not hold, says nothing about it; read as plush, it is a perceived edge."""
    from runner.attention.explorer import Explorer

    scenario = load_scenario(MODELS / "scenarios" / "paper.yaml")
    assert [scenario.materials[m] for m in scenario.counter_materials("T3")] == ["plush",
                                                                                  "silicone"]
    ex = Explorer(scenario, "T3")
    ex.reset(np.array([[2, 2]]), seed=[0])
    ny = scenario.shape[1]
    wood, copper, plush = (0.52, 0.08), (0.30, 0.04), (0.66, 0.62)
    row = [(2, y) for y in range(2, 9)]
    for (x, y), (e, c) in zip(row, [wood, wood, wood, copper, wood, wood, wood], strict=True):
        ex.perceive(np.array([x * ny + y]), paper_readings(np.array([e]), np.array([c])))
    target, perceived = ex.percept()
    assert perceived[0, 2, 5] == False  # noqa: E712 - probed, but neither side of the task
    assert target[0, 2, 4] and perceived[0, 2, 4]
    _, saliency, _ = ex.cue_fields()
    around = saliency[0].reshape(scenario.shape)[1:4, 4:7]
    assert not np.any(around > 0.5)  # no edge where the copper reading was
    ex.perceive(np.array([2 * ny + 5]), paper_readings(plush[0], plush[1]))
    ex.perceive(np.array([2 * ny + 5]), paper_readings(plush[0], plush[1]))
    target, perceived = ex.percept()
    assert perceived[0, 2, 5] and not target[0, 2, 5]
    _, saliency, _ = ex.cue_fields()
    assert np.nanmax(saliency[0].reshape(scenario.shape)[1:4, 4:7]) >= 0.5  # now an edge


@pytest.mark.parametrize("path", sorted((MODELS / "experiments").glob("*.yaml")),
                         ids=lambda p: p.stem)
def test_every_shipped_experiment_loads_and_each_task_has_a_border(path):
    from runner.experiments.experiment import load_experiment
    experiment = load_experiment(path)
    scenario = experiment.scenario
    materials = scenario.material_map
    for task in experiment.spec.tasks:
        border = scenario.border(task)
        assert border.any(), f"{path.name}: task {task} has no border"
        # a border cell is of the task's material and the task's material does not fill the grid
        assert (materials[border] == scenario.task_material(task)).all()
        assert (materials != scenario.task_material(task)).any()


def test_the_scenario_chooses_the_shape_matcher(tmp_path):
    path = write(tmp_path, templates=(
        "  rectangle: [[-0.07, -0.05], [0.07, -0.05], [0.07, 0.05], [-0.07, 0.05]]\n"
        "  disc: {circle: 0.04}\n"
        "shape_matcher: chamfer"))
    scenario = load_scenario(path)
    explorer = Explorer(scenario, "T2", runs=2)
    assert explorer.tracker.method == "chamfer"
    starts = np.array([[3, 3], [15, 20]])
    first = simulate(scenario, "T2", "full", starts, np.arange(2), seed=1, iterations=40,
                     explorer=explorer)
    again = simulate(scenario, "T2", "full", starts, np.arange(2), seed=1, iterations=40)
    np.testing.assert_array_equal(first["paths"], again["paths"])
