"""Physics probes (MuJoCo): a press indents a surface by Hooke's law, a stroke on a rigid flat
surface slides at its friction coefficient, roughness reads as texture, probes are seeded per
(run, step) whatever the batch; `bayesprog record --physics` writes what a lab writes and a
simple classifier tells the materials apart from one press; `robot --physics` closes the loop;
a missing extra is one line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

import bayesprog
from bayesprog.cli import main
from runner.experiments.loop import make_sensor, reading_seed, start_cell
from runner.world.physics import (
    MaterialPhysics,
    PhysicsSensor,
    ProbeSpec,
    Scene,
    default_materials,
    features,
    press_cells,
)
from runner.world.scenario import load_scenario

ROOT = Path(__file__).parents[2]
MODELS = ROOT / "models"
QUIET = ProbeSpec(jitter=0.0, noise_force=0.0, noise_depth=0.0)


def uniform(material: MaterialPhysics, spec: ProbeSpec = QUIET, shape=(5, 5)) -> Scene:
    """A surface of one material, every cell alike."""
    flat = material.model_copy(update={"variation": 0.0})
    return Scene(np.zeros(shape, int), 0.01, ("m",), {"m": flat}, spec)


@pytest.mark.parametrize("stiffness", [250.0, 3000.0, 20000.0])
@pytest.mark.parametrize("force", [0.5, 2.0])
def test_a_press_indents_the_surface_by_force_over_stiffness(stiffness, force):
    damping = 2 * np.sqrt(stiffness * 0.2)
    scene = uniform(MaterialPhysics(stiffness=stiffness, damping=damping, friction=0.5,
                                    roughness=0.0), QUIET.model_copy(update={"force": force,
                                                                             "press": 0.6}))
    probe = scene.probe(12, np.random.default_rng(0))
    assert probe.force == pytest.approx(force, rel=0.01)
    assert probe.depth == pytest.approx(force / stiffness, rel=0.03)  # Hooke's law
    assert probe.compliance == pytest.approx(force / stiffness / force / 0.004, rel=0.03)


@pytest.mark.parametrize("friction", [0.3, 0.5])
def test_a_stroke_on_a_rigid_flat_surface_slides_at_its_friction_coefficient(friction):
    scene = uniform(MaterialPhysics(stiffness=1e5, damping=280, friction=friction,
                                    roughness=0.0))
    probe = scene.probe(12, np.random.default_rng(0))
    assert probe.friction_ratio == pytest.approx(friction, rel=0.05)
    assert probe.tangential_sd < 0.01  # a flat surface: no fluctuation to speak of


def test_a_rougher_surface_reads_rougher():
    sds, textures = [], []
    for roughness in (0.0, 5e-5, 3e-4):
        scene = uniform(MaterialPhysics(stiffness=1e5, damping=280, friction=0.5,
                                        roughness=roughness), ProbeSpec())
        probes = [scene.probe(c, np.random.default_rng([1, c])) for c in range(25)]
        sds.append(np.mean([p.tangential_sd for p in probes]))
        textures.append(np.mean([p.texture for p in probes]))
    assert sds[0] < sds[1] < sds[2] and textures[0] < textures[1] < textures[2]


def test_features_of_known_traces():
    """A press that meets the surface at 6 mm and settles 1 mm below at 2 N (the force rising
    linearly with the depth), then a stroke whose tangential force is 0.6 N plus a sine of
    amplitude 0.1 N: depth, force, friction ratio, fluctuation (the sine's standard deviation,
    a / sqrt 2) and the two features."""
    spec = ProbeSpec(compliance_scale=0.004, texture_scale=0.2, friction_weight=0.2)
    press, stroke = 200, 400
    descent = np.linspace(0.0065, 0.005, 61)  # 0.5 mm in the air, then 1 mm into the surface
    height = np.concatenate([descent, np.full(press - 61, 0.005), np.full(stroke, 0.005)])
    normal = np.clip(2000 * (0.006 - height), 0, None)
    t = np.arange(stroke)
    tangential = np.concatenate([np.zeros(press), 0.6 + 0.1 * np.sin(2 * np.pi * t / 20)])
    texture, compliance, raw = features(normal, tangential, height, press, spec)
    assert raw["force"] == pytest.approx(2.0)
    assert raw["depth"] == pytest.approx(0.001, rel=1e-9)
    assert raw["friction_ratio"] == pytest.approx(0.3, rel=1e-3)
    # (the straight line taken out absorbs a little of the sine: 0.1 % here)
    assert raw["tangential_sd"] == pytest.approx(0.1 / np.sqrt(2), rel=5e-3)
    assert compliance == pytest.approx(0.001 / 2.0 / 0.004, rel=1e-9)
    assert texture == pytest.approx(raw["tangential_sd"] / 2.0 / 0.2 + 0.2 * raw["friction_ratio"],
                                    rel=1e-12)


@pytest.fixture(scope="module")
def paper_physics():
    return load_scenario(MODELS / "scenarios" / "paper_physics.yaml")


def test_probes_are_seeded_by_run_and_step_whatever_the_batch(paper_physics):
    scene = paper_physics.physics_scene()
    cells = [np.array([400, 1250]), np.array([401, 1251])]
    together = PhysicsSensor(scene, [(5, 0), (5, 1)])
    alone = [PhysicsSensor(scene, [(5, r)]) for r in (0, 1)]
    for step in cells:
        both = together.probe(step)
        apart = [alone[r].probe(step[r:r + 1]) for r in (0, 1)]
        np.testing.assert_array_equal(both.values, np.concatenate([a.values for a in apart]))
    again = PhysicsSensor(scene, [(5, 0), (5, 1)])
    np.testing.assert_array_equal(again.probe(cells[0]).values, PhysicsSensor(
        scene, [(5, 0), (5, 1)]).probe(cells[0]).values)


def test_every_shipped_layouts_material_has_physical_properties():
    known = default_materials()
    laid = set()
    for path in (MODELS / "scenarios").glob("*.yaml"):
        spec = yaml.safe_load(path.read_text())
        laid |= {spec["background"], *(o["material"] for o in spec.get("objects", []))}
    assert laid <= set(known), laid - set(known)
    assert known["wood"].stiffness > 10 * known["silicone"].stiffness > 10 * known["plush"].stiffness
    assert all(m.why for m in known.values())


def test_recorded_presses_tell_the_materials_apart_from_one_press(tmp_path):
    from sklearn.discriminant_analysis import QuadraticDiscriminantAnalysis

    files = {}
    for seed in (3, 4):
        files[seed] = tmp_path / f"presses{seed}.csv"
        assert main(["record", "paper", "--physics", "--presses", "40", "--seed", str(seed),
                     "-o", str(files[seed]), "-q"]) == 0
    train, test = (pd.read_csv(files[s]) for s in (3, 4))
    assert list(train.columns[:5]) == ["material", "texture", "compliance", "ix", "iy"]
    assert {"force_n", "depth_m", "friction_ratio", "tangential_sd_n"} <= set(train.columns)
    assert train["material"].value_counts().to_dict() == {"plush": 40, "silicone": 40,
                                                          "wood": 40}
    paper = load_scenario(MODELS / "scenarios" / "paper.yaml")
    truth = paper.material_map[train["ix"], train["iy"]]
    assert [paper.materials[m] for m in truth] == train["material"].tolist()
    means = train.groupby("material")["compliance"].mean()
    assert means.idxmin() == "wood"
    features_ = ["texture", "compliance"]
    classifier = QuadraticDiscriminantAnalysis(reg_param=0.1).fit(train[features_],
                                                                  train["material"])
    assert (classifier.predict(test[features_]) == test["material"]).mean() >= 0.9
    # the file feeds a scenario's perception as a lab's recordings do
    text = (MODELS / "scenarios" / "paper.yaml").read_text().replace(
        "perception: ../pi_per.yaml", f"perception: {{recordings: {files[3]}}}")
    scenario_file = MODELS / "scenarios" / f"_physics_test_{tmp_path.name}.yaml"
    try:
        scenario_file.write_text(text)
        learned = load_scenario(scenario_file).perception
    finally:
        scenario_file.unlink()
    assert learned.variables["M"].states == ("plush", "silicone", "wood")
    mean = learned.term("P(C | M)").params["mean"].array
    np.testing.assert_allclose(mean, train.groupby("material")["compliance"].mean(), rtol=1e-9)


def test_the_shipped_presses_and_the_pi_per_learned_from_them(tmp_path):
    out = tmp_path / "presses.csv"
    assert main(["record", "paper", "--physics", "--presses", "50", "--seed", "1", "-o",
                 str(out), "-q"]) == 0
    fresh, shipped = pd.read_csv(out), pd.read_csv(MODELS / "data" / "physics_presses.csv")
    assert fresh["material"].tolist() == shipped["material"].tolist()
    for column in shipped.columns[1:]:
        np.testing.assert_allclose(fresh[column], shipped[column], rtol=1e-4, atol=1e-6)
    program = bayesprog.load(MODELS / "pi_per_physics.yaml")
    for term, column in (("P(E | M)", "texture"), ("P(C | M)", "compliance")):
        np.testing.assert_allclose(program.term(term).params["mean"].array,
                                   shipped.groupby("material")[column].mean(), rtol=1e-9)


def test_the_closed_loop_with_a_simulated_fingertip(capsys, paper_physics):
    assert main(["robot", "paper_physics", "--physics", "--task", "T2", "--steps", "30",
                 "--seed", "0", "--json"]) == 0
    outcome = json.loads(capsys.readouterr().out)
    assert set(outcome) == {"gamma_m", "border_cells", "path_m", "steps", "probes"}
    assert outcome["steps"] == len(outcome["probes"]) == 30
    assert outcome["border_cells"] == int(paper_physics.border("T2").sum())
    cells = [tuple(p["cell"]) for p in outcome["probes"]]
    assert cells[0] == tuple(start_cell(paper_physics.shape, 0, 0))
    for probe, cell in zip(outcome["probes"], cells, strict=True):
        material = paper_physics.materials[paper_physics.material_map[cell]]
        assert probe["material"] == material
        assert set(probe) == {"cell", "readings", "material"}
        assert set(probe["readings"]) == {"texture", "compliance"}
    centres = (np.array(cells) + 0.5) * paper_physics.cell
    assert outcome["path_m"] == pytest.approx(np.linalg.norm(np.diff(centres, axis=0),
                                                             axis=1).sum())
    probed = np.array([np.ravel_multi_index(c, paper_physics.shape) for c in cells])
    border = paper_physics.centres[paper_physics.border("T2").ravel()]
    nearest = np.linalg.norm(border[:, None] - paper_physics.centres[probed][None], axis=-1)
    assert outcome["gamma_m"] == pytest.approx(nearest.min(axis=1).sum())
    # the first reading is the physics sensor's for that run's first probe
    sensor = make_sensor(paper_physics, [reading_seed(0, 0)])
    first = sensor.probe(probed[:1])
    assert outcome["probes"][0]["readings"]["texture"] == first["texture"][0]


@pytest.mark.parametrize("command", [
    ["record", "paper", "--physics", "-o", "{tmp}/x.csv"],
    ["robot", "paper", "--physics"],
    ["run", "paper_physics", "--out", "{tmp}/out"],
])
def test_without_mujoco_physics_exits_2_in_one_line(command, tmp_path):
    code = ("import sys; sys.modules['mujoco'] = None; from bayesprog.cli import main; "
            "sys.exit(main(sys.argv[1:]))")
    args = [a.format(tmp=tmp_path) for a in command]
    done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=300)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and 'pip install "bayesprog[physics]"' in done.stderr


def test_importing_the_packages_never_imports_mujoco():
    code = ("import sys, bayesprog, runner, runner.plugin, runner.world.scenario, "
            "runner.world.physics, runner.experiments.loop, runner.robot.closed, "
            "runner.robot.presses; print('mujoco' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert done.stdout.strip() == "False", done.stderr


@pytest.mark.parametrize("edit, expected", [
    (lambda s: s.update(physics={"granite": {"stiffness": 1e5}}), "unknown material 'granite'"),
    (lambda s: s["sensor"].update(model="../sensors/biotac_proxy.yaml"),
     "expected one source of readings, found model and physics"),
    (lambda s: s.update(physics={"wood": {"friction": -1}}), "friction"),
    (lambda s: s["sensor"]["physics"].update(force=0), "force"),
])
def test_a_bad_physics_section_is_refused_at_its_place(tmp_path, capsys, edit, expected):
    spec = yaml.safe_load((MODELS / "scenarios" / "paper_physics.yaml").read_text())
    edit(spec)
    path = MODELS / "scenarios" / f"_bad_physics_{tmp_path.name}.yaml"
    try:
        path.write_text(yaml.safe_dump(spec, sort_keys=False))
        assert main(["validate", str(path)]) == 2
    finally:
        path.unlink()
    err = capsys.readouterr().err
    assert expected in err and f"{path.name}:" in err and "Traceback" not in err


def test_a_material_without_defaults_needs_all_its_properties(tmp_path, capsys):
    spec = yaml.safe_load((MODELS / "scenarios" / "paper_physics.yaml").read_text())
    spec["physics"] = {"plush": {"stiffness": 200}}  # the others from the defaults
    path = MODELS / "scenarios" / f"_physics_{tmp_path.name}.yaml"
    try:
        path.write_text(yaml.safe_dump(spec, sort_keys=False))
        plush = load_scenario(path).physics["plush"]
        assert plush.stiffness == 200 and plush.friction == default_materials()["plush"].friction
    finally:
        path.unlink()
    perception = (MODELS / "pi_per.yaml").read_text().replace("acrylic", "basalt")
    (tmp_path / "pi_per.yaml").write_text(perception)
    spec["programs"] = {"perception": str(tmp_path / "pi_per.yaml"),
                        "shape": str(MODELS / "pi_obj.yaml"),
                        "target": str(MODELS / "pi_tar.yaml")}
    spec["physics"] = {"basalt": {"stiffness": 1e5, "friction": 0.6}}
    path = tmp_path / "basalt.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    assert main(["validate", str(path)]) == 2
    assert "basalt has no bundled physical properties: give damping, roughness too" in \
        capsys.readouterr().err


def test_press_cells_land_on_their_material_and_repeat_with_their_seed(paper_physics):
    first = press_cells(paper_physics.material_map, 30, 9)
    assert [m for m, _ in first] == sorted(set(paper_physics.material_map.ravel().tolist()))
    for m, cells in first:
        assert (paper_physics.material_map.ravel()[cells] == m).all()
    again = press_cells(paper_physics.material_map, 30, 9)
    assert all((a[1] == b[1]).all() for a, b in zip(first, again, strict=True))
