"""Volumes of cells (3-D workspaces): solids, their material map and border, the 3-D Sobel of a
partly probed map, 3-D inhibition, 3-D ICP, and the loop, the experiment and the report on a
volume. Checked against loops over the definitions, scipy and brute-force geometry."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

import bayesprog
from runner.attention.cues import inhibition, saliency
from runner.attention.explorer import Explorer
from runner.attention.shape import _kabsch, match3d
from runner.experiments.experiment import load_experiment, run_experiment, simulate, start_cells
from runner.report.build import build_report
from runner.world.readings import paper_readings
from runner.world.scenario import load_scenario
from runner.world.sensor import material_normals
from runner.world.solids import SolidSpec, farthest_points

MODELS = Path(__file__).parents[2] / "models"


@pytest.fixture(scope="module")
def volume():
    return load_scenario(MODELS / "scenarios" / "volume.yaml")


def _small_volume(folder: Path, **changes) -> Path:
    """A small volume (10 x 12 x 8 cells of 1.5 cm) with a plush box and a silicone sphere."""
    doc = {
        "scenario": 1, "name": "small_volume",
        "programs": {k: str(MODELS / f) for k, f in
                     (("perception", "pi_per.yaml"), ("shape", "pi_obj.yaml"),
                      ("target", "pi_tar.yaml"))},
        "grid": {"shape": [10, 12, 8], "cell": 0.015},
        "background": "wood",
        "templates": {"box": {"box": [0.06, 0.045, 0.045]}, "ball": {"sphere": 0.03}},
        "template_points": 30,
        "objects": [{"template": "box", "material": "plush", "at": [0.045, 0.05, 0.06],
                     "rotation": 30},
                    {"template": "ball", "material": "silicone", "at": [0.1, 0.13, 0.06]}],
        "tasks": {"T1": "plush", "T2": "silicone", "T3": "wood"},
    }
    doc.update(changes)
    path = folder / "small_volume.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


# --- solids and the material map --------------------------------------------------------------


def test_material_map_of_a_volume_is_the_solids_by_their_definition(volume):
    """Each cell centre tested against the solids' equations, the box turned by hand."""
    m = volume.material_map
    assert m.shape == (20, 24, 12)
    plush, silicone, wood = (volume.materials.index(n) for n in ("plush", "silicone", "wood"))
    for (i, j, k) in itertools.product(range(20), range(24), range(12)):
        c = (np.array([i, j, k]) + 0.5) * 0.01
        t = np.deg2rad(20)
        d = c - [0.06, 0.07, 0.06]
        local = [np.cos(t) * d[0] + np.sin(t) * d[1], -np.sin(t) * d[0] + np.cos(t) * d[1], d[2]]
        in_box = all(abs(v) <= h for v, h in zip(local, (0.04, 0.03, 0.025), strict=True))
        e = c - [0.135, 0.165, 0.06]
        in_ellipsoid = (e[0] / 0.045) ** 2 + (e[1] / 0.035) ** 2 + (e[2] / 0.035) ** 2 <= 1
        expected = silicone if in_ellipsoid else plush if in_box else wood
        assert m[i, j, k] == expected, (i, j, k)


def test_border_of_a_volume_is_six_adjacency(volume):
    m = volume.material_map
    for task in ("T1", "T2", "T3"):
        material = volume.task_material(task)
        expected = np.zeros(m.shape, bool)
        for idx in zip(*np.nonzero(m == material), strict=True):
            for axis, step in itertools.product(range(3), (-1, 1)):
                other = list(idx)
                other[axis] += step
                if 0 <= other[axis] < m.shape[axis] and m[tuple(other)] != material:
                    expected[idx] = True
        np.testing.assert_array_equal(volume.border(task), expected)
        assert expected.sum() > 50


@pytest.mark.parametrize("solid, on_surface", [
    (SolidSpec(box=[0.08, 0.06, 0.04]),
     lambda p: np.isclose(np.max(np.abs(p) / [0.04, 0.03, 0.02], axis=1), 1.0)),
    (SolidSpec(ellipsoid=[0.05, 0.03, 0.02]),
     lambda p: np.isclose((p**2 / np.array([0.05, 0.03, 0.02]) ** 2).sum(axis=1), 1.0)),
    (SolidSpec(sphere=0.03), lambda p: np.isclose(np.linalg.norm(p, axis=1), 0.03)),
])
def test_surface_points_lie_on_the_surface_and_spread_evenly(solid, on_surface):
    pts = solid.surface(120)
    assert pts.shape == (120, 3)
    assert on_surface(pts).all()
    # farther apart than the same number drawn at random from a dense sample of the surface
    dense = solid.surface(1200)
    random = dense[np.random.default_rng(0).choice(len(dense), 120, replace=False)]

    def closest(p):
        d = np.linalg.norm(p[:, None] - p[None], axis=-1)
        return (d + np.eye(len(p)) * 1e9).min()

    assert closest(pts) > 1.5 * closest(random)


def test_prism_surface_is_its_walls_and_caps():
    triangle = [[-0.05, -0.04], [0.05, -0.04], [0.0, 0.05]]
    solid = SolidSpec(prism={"polygon": triangle, "height": 0.04})
    pts = solid.surface(150)
    on_cap = np.isclose(np.abs(pts[:, 2]), 0.02)
    poly = np.array(triangle)
    # a wall point lies on one of the three edges (distance to the edge's line 0, within it)
    a, b = poly, np.roll(poly, -1, axis=0)
    t = np.clip(((pts[:, None, :2] - a) * (b - a)).sum(-1) / ((b - a) ** 2).sum(-1), 0, 1)
    edge = np.linalg.norm(pts[:, None, :2] - (a + t[..., None] * (b - a)), axis=-1).min(axis=1)
    assert (on_cap | (edge < 1e-12)).all()
    assert on_cap.any() and (~on_cap).any()
    assert solid.inside(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.03], [0.04, 0.04, 0.0]])
                        ).tolist() == [True, False, False]


def test_farthest_points_pick_the_farthest_each_time():
    rng = np.random.default_rng(1)
    points = rng.random((200, 3))
    chosen = farthest_points(points, 12)
    for n in range(1, 12):
        d = np.linalg.norm(points[:, None] - chosen[None, :n], axis=-1).min(axis=1)
        assert np.linalg.norm(chosen[n] - chosen[:n], axis=-1).min() == pytest.approx(d.max())


# --- scenario errors ---------------------------------------------------------------------------


@pytest.mark.parametrize("changes, message", [
    ({"templates": {"box": [[0, 0], [0.1, 0], [0, 0.1]]}},
     r"small_volume.yaml:\d+:\d+: template 'box': a 3-D grid takes solids"),
    ({"objects": [{"template": "box", "material": "plush", "at": [0.05, 0.05]}]},
     r"small_volume.yaml:\d+:\d+: expected 3 coordinates on a 3-D grid, found 2"),
    ({"objects": [{"polygon": [[0, 0], [0.1, 0], [0, 0.1]], "material": "plush"}]},
     r"small_volume.yaml:\d+:\d+: a 3-D grid takes objects placed from solid templates"),
    ({"templates": {"box": {"box": [0.06, 0.045]}}},
     r"small_volume.yaml:\d+:\d+: .*box: expected three positive lengths"),
    ({"templates": {"box": {"box": [0.06, 0.045, 0.04], "sphere": 0.02}}},
     r"small_volume.yaml:\d+:\d+: .*expected exactly one of"),
    ({"grid": {"shape": [10, 12, 8, 2], "cell": 0.01}},
     r"small_volume.yaml:\d+:\d+: grid.shape: expected at most 3 items, found 4: "),
    ({"templates": {"box": {"prism": {"polygon": [[0, 0], [0, 0], [0, 0]], "height": 0.04}},
                    "ball": {"sphere": 0.03}}},
     r"small_volume.yaml:\d+:\d+: .*prism polygon: expected a simple polygon enclosing an area"),
    ({"templates": {"box": {"prism": {"polygon": [[0, 0], [0.05, 0], [0, 0.05]],
                                      "height": float("inf")}}, "ball": {"sphere": 0.03}}},
     r"small_volume.yaml:\d+:\d+: .*finite number"),
    ({"template_points": 2000}, r"small_volume.yaml:\d+:\d+: .*less than or equal to 1500"),
    ({"objects": [{"template": "box", "material": "plush", "at": [1.0, 1.0, 1.0]}],
      "tasks": {"T1": "plush", "T3": "wood"}},
     r"small_volume.yaml:\d+:\d+: this object \(plush\) holds no cell's centre"),
    ({"templates": {"box": {"cube": [0.06, 0.045, 0.045]}, "ball": {"spere": 0.03}}},
     r"small_volume.yaml:\d+:\d+: unknown key 'cube': expected box, circle, ellipse, "
     r"ellipsoid, prism, sphere or vertices\n"),
    ({"templates": {"box": {"box": [0.06, 0.045, 0.045]}, "ball": {"spere": 0.03}}},
     r"small_volume.yaml:\d+:\d+: unknown key 'spere': .* \(did you mean 'sphere'\?\)"),
    ({"shape_matcher": "chamfer"},
     r"small_volume.yaml:\d+:\d+: shape matcher 'chamfer' registers 2-D outlines"),
])
def test_volume_scenario_errors_name_file_line_and_column(tmp_path, changes, message):
    with pytest.raises(bayesprog.SpecError, match=message):
        load_scenario(_small_volume(tmp_path, **changes))


def test_a_solid_template_on_a_surface_is_refused(tmp_path):
    path = _small_volume(tmp_path, grid={"shape": [10, 12], "cell": 0.015}, objects=[])
    with pytest.raises(bayesprog.SpecError, match=r"template 'box': a 2-D grid takes outlines"):
        load_scenario(path)


# --- cues in 3-D -------------------------------------------------------------------------------


def _brute_saliency_3d(d, probed, cell):
    """Eq. (12) at one cell of a volume by loops: along each axis, the (1, 2, 1) x (1, 2, 1)
    weighted mean of the probed cells of each of the three planes across it, a missing side
    replaced by the centre plane; NaN when nothing is compared but a probed cell is near."""
    shape = d.shape
    best, compared_any, near = 0.0, False, False
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        means = {}
        for offset in (-1, 0, 1):
            num = den = 0.0
            for (u, wu), (v, wv) in itertools.product(((-1, 1), (0, 2), (1, 1)), repeat=2):
                c = list(cell)
                c[axis] += offset
                c[others[0]] += u
                c[others[1]] += v
                if all(0 <= c[a] < shape[a] for a in range(3)) and probed[tuple(c)]:
                    num += wu * wv * d[tuple(c)]
                    den += wu * wv
                    near = True
            if den:
                means[offset] = num / den
        if len(means) >= 2:
            compared_any = True
            hi = means.get(1, means.get(0))
            lo = means.get(-1, means.get(0))
            best = max(best, abs(hi - lo))
    return min(best, 1.0) if compared_any else (np.nan if near else 0.0)


def test_partly_probed_3d_saliency_against_its_definition():
    rng = np.random.default_rng(4)
    d = (rng.random((5, 6, 4)) < 0.4).astype(float)
    probed = rng.random(d.shape) < 0.35
    s = saliency(d, probed, dims=3)
    for cell in itertools.product(*map(range, d.shape)):
        np.testing.assert_allclose(s[cell], _brute_saliency_3d(d, probed, cell), atol=1e-12,
                                   err_msg=str(cell))


def test_explorer_cues_in_a_volume(volume):
    """I is eq. (10) with the 3-D distance, S the 3-D Sobel of the perceived map (a run where
    nothing is salient anywhere learns nothing from it: NaN), and cells index row-major."""
    explorer = Explorer(volume, "T1", runs=2)
    explorer.reset(np.array([[3, 4, 5], [15, 20, 2]]), seed=1)
    means = material_normals(explorer.perception)
    plush, wood = volume.materials.index("plush"), volume.materials.index("wood")
    cells = explorer.expected
    for step in range(8):  # plush then wood: a perceived change of material
        m = plush if step < 4 else wood
        reading = [np.full(2, means[f][0][m]) for f in ("E", "C")]
        cells = explorer.step(cells, paper_readings(*reading))
    d = explorer.last
    last = explorer.centres[explorer.path[-1]]
    np.testing.assert_allclose(d.inhibition, inhibition(explorer.centres, last,
                                                        np.linalg.norm([0.2, 0.24, 0.12])),
                               atol=1e-12)
    target, perceived = explorer.percept()
    expected = saliency(target.astype(float), perceived, dims=3).reshape(2, -1)
    expected[~np.any(np.isnan(expected) | (expected > 0), axis=1)] = np.nan
    assert (expected > 0).any()
    np.testing.assert_allclose(d.saliency, expected, atol=1e-12)
    assert explorer.cell(explorer.flat(np.array([[19, 23, 11]]))).tolist() == [[19, 23, 11]]
    assert explorer.flat(np.array([[1, 2, 3]]))[0] == (1 * 24 + 2) * 12 + 3
    with pytest.raises(bayesprog.QuestionError, match="outside the 20 x 24 x 12 grid"):
        explorer.flat(np.array([[3, 4, 12]]))
    with pytest.raises(bayesprog.QuestionError, match="expected cells of 3 coordinates"):
        explorer.flat(np.array([[3, 4]]))
    for start in ([1, 2], [[1, 2], [3, 4], [5, 6]]):
        with pytest.raises(bayesprog.QuestionError, match="expected a start cell of 3 coord"):
            explorer.reset(start)


# --- 3-D ICP -----------------------------------------------------------------------------------


def test_kabsch_against_scipy_align_vectors():
    rng = np.random.default_rng(2)
    source = rng.normal(size=(12, 3))
    target = source @ Rotation.random(random_state=3).as_matrix().T + [0.1, -0.2, 0.3] \
        + 0.01 * rng.normal(size=(12, 3))
    rot, shift = _kabsch(source[None], target[None], np.ones((1, 12, 1)))
    reference, _ = Rotation.align_vectors(target - target.mean(0), source - source.mean(0))
    np.testing.assert_allclose(rot[0], reference.as_matrix(), atol=1e-10)
    np.testing.assert_allclose(shift[0], target.mean(0) - reference.apply(source.mean(0)),
                               atol=1e-10)


def test_icp_3d_recovers_a_moved_solid():
    """Points of each solid's surface, turned (about z and a little off it) and shifted: ICP
    brings its own template onto them within the resolution of the surface sample it pairs
    with (points about 3 mm apart here; a fit stops where no pair changes, within
    half that), and the other template stays clearly farther."""
    from scipy.spatial import cKDTree

    solids = [SolidSpec(box=[0.08, 0.06, 0.05]), SolidSpec(ellipsoid=[0.045, 0.035, 0.03])]
    surfaces = [s.surface(1500) for s in solids]
    surfaces = [s - s.mean(axis=0) for s in surfaces]
    spacing = [np.sort(cKDTree(s).query(s, 2)[0][:, 1]).mean() for s in surfaces]
    assert 0.002 < min(spacing) and max(spacing) < 0.005
    points = np.stack([farthest_points(s, 40) for s in surfaces])
    rng = np.random.default_rng(5)
    for t, surface in enumerate(surfaces):
        turn = Rotation.from_euler("zx", [50 + 90 * t, 4], degrees=True).as_matrix()
        shift = np.array([0.1, 0.12, 0.06])
        moved = surface @ turn.T + shift
        path = moved[rng.choice(len(surface), 60, replace=False)][None]
        reg = match3d(path, surfaces, points, rotations=8, iterations=40)
        assert reg.distance[0, t] < spacing[t] / 2
        assert reg.distance[0, 1 - t] > 2 * reg.distance[0, t] + 1e-3
        assert reg.error[0, t] < reg.error[0, 1 - t]
        # the registered template points lie on the moved solid (its symmetries allowed)
        assert cKDTree(moved).query(reg.points[0, t])[0].max() < spacing[t]


def test_nearest_grid_finds_the_k_d_trees_nearest_sample():
    """The grid's exact lookup is the tree's nearest sample (index and distance) for points
    on, near, far from and outside the grid; its approximate one is within half a cell's
    diagonal of it."""
    from scipy.spatial import cKDTree

    from runner.attention.shape import NearestGrid

    for solid in (SolidSpec(box=[0.08, 0.06, 0.05]), SolidSpec(ellipsoid=[0.045, 0.035, 0.03])):
        surface = solid.surface(1500)
        surface = surface - surface.mean(axis=0)
        tree = cKDTree(surface)
        grid = NearestGrid(tree, surface)
        rng = np.random.default_rng(1)
        for scale in (0.001, 0.005, 0.02, 0.1, 0.5):
            points = surface[rng.integers(0, len(surface), 3000)] \
                + rng.normal(scale=scale, size=(3000, 3))
            distance, index = grid.query(points)
            reference, nearest = tree.query(points)
            np.testing.assert_array_equal(distance, reference)
            np.testing.assert_array_equal(index, nearest)
            rough, _ = grid.query(points, approximate=True)
            inside = np.all((points >= grid.low) & (points < grid.low + grid.shape * grid.cell),
                            axis=1)
            assert np.all(rough[inside] <= reference[inside] + np.sqrt(3) * grid.cell + 1e-12)


def test_compiled_icp_3d_recovers_a_moved_solid_as_the_tree_does():
    """With the grids, the compiled ICP (screened approximately, then exact) brings each solid's
    own template onto its moved surface as the k-d tree's ICP does (within the sample's
    resolution), the other template staying clearly farther."""
    from scipy.spatial import cKDTree

    from runner.attention.shape import NearestGrid

    solids = [SolidSpec(box=[0.08, 0.06, 0.05]), SolidSpec(ellipsoid=[0.045, 0.035, 0.03])]
    surfaces = [s.surface(1500) for s in solids]
    surfaces = [s - s.mean(axis=0) for s in surfaces]
    trees = [cKDTree(s) for s in surfaces]
    grids = [NearestGrid(tree, s) for tree, s in zip(trees, surfaces, strict=True)]
    spacing = [np.sort(tree.query(s, 2)[0][:, 1]).mean() for tree, s in zip(trees, surfaces,
                                                                              strict=True)]
    points = np.stack([farthest_points(s, 40) for s in surfaces])
    rng = np.random.default_rng(5)
    for t, surface in enumerate(surfaces):
        turn = Rotation.from_euler("zx", [50 + 90 * t, 4], degrees=True).as_matrix()
        moved = surface @ turn.T + np.array([0.1, 0.12, 0.06])
        path = moved[rng.choice(len(surface), 60, replace=False)][None]
        compiled = match3d(path, surfaces, points, rotations=8, iterations=40, trees=trees,
                           grids=grids)
        tree = match3d(path, surfaces, points, rotations=8, iterations=40, trees=trees)
        assert compiled.distance[0, t] < spacing[t] / 2
        assert compiled.distance[0, t] == pytest.approx(tree.distance[0, t], abs=spacing[t] / 2)
        assert compiled.distance[0, 1 - t] > 2 * compiled.distance[0, t] + 1e-3
        assert cKDTree(moved).query(compiled.points[0, t])[0].max() < spacing[t]
        # a warm start alone (no screening) pairs exactly: the tree's fit, to rounding
        warm = (compiled.angle, compiled.shift)
        again = match3d(path, surfaces, points, rotations=0, iterations=8, warm=warm,
                        trees=trees, grids=grids)
        by_tree = match3d(path, surfaces, points, rotations=0, iterations=8, warm=warm,
                          trees=trees)
        np.testing.assert_allclose(again.distance, by_tree.distance, rtol=1e-9)
        np.testing.assert_allclose(again.shift, by_tree.shift, atol=1e-9)


# --- the loop, the experiment and the report on a volume --------------------------------------


def test_batched_runs_in_a_volume_equal_runs_one_at_a_time(tmp_path):
    scenario = load_scenario(_small_volume(tmp_path))
    starts = start_cells(scenario.shape, 3, 4)
    batched = simulate(scenario, "T1", "full", starts, np.arange(3), 11, 30)
    for r in range(3):
        alone = simulate(scenario, "T1", "full", starts[r : r + 1], np.array([r]), 11, 30)
        np.testing.assert_array_equal(alone["paths"][0], batched["paths"][r])
    again = simulate(scenario, "T1", "full", starts, np.arange(3), 11, 30)
    np.testing.assert_array_equal(again["paths"], batched["paths"])


def test_experiment_and_report_on_a_volume(tmp_path, capsys):
    scenario = _small_volume(tmp_path)
    spec = {"experiment": 1, "name": "small_volume", "runner": "haptic",
            "scenario": str(scenario), "tasks": ["T1", "T2"],
            "configurations": ["full", "without_S"], "runs": 4, "iterations": 25, "seed": 3,
            "chunk": 2}
    path = tmp_path / "experiment.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    run_experiment(load_experiment(path), tmp_path / "out", progress=False)
    folder = build_report(tmp_path / "out")
    for name in ("fig9_visits.png", "fig9_slices.png", "fig10_gamma.png", "fig11_decision.png"):
        assert (folder / name).stat().st_size > 10_000, name
    import imageio_ffmpeg

    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(folder / "fig11_decision.mp4"))
    assert frames == 24  # every step of the run replayed (25 iterations: 24 decisions)
    rows = json.loads((folder / "statistics.json").read_text())
    assert {(r["task"], r["configuration"]) for r in rows} == {
        (t, c) for t in ("T1", "T2") for c in ("full", "without_S")}
    assert all(np.isfinite(r["final_mean"]) and r["final_mean"] > 0 for r in rows)
    from runner.report.tables import runs_table

    table = runs_table(tmp_path / "out")
    probed = load_scenario(scenario).centres[table["cell"].to_numpy()] * 100
    np.testing.assert_allclose(table[["x_cm", "y_cm", "z_cm"]].to_numpy(), probed)
    assert "fig9_slices.png" in (folder / "report.md").read_text()


def test_robot_session_in_a_volume(volume):
    """``explore --stdio`` in a volume: cells [ix, iy, iz] in and out, the maps nested
    [ix][iy][iz] as the explorer's own fields, a two-coordinate cell refused."""
    import io

    from runner.robot.stdio import serve

    explorer = Explorer(volume, "T1")
    means = material_normals(explorer.perception)
    plush = volume.materials.index("plush")
    line = {"cell": [5, 6, 5], "texture": float(means["E"][0][plush]),
            "compliance": float(means["C"][0][plush]), "maps": True}
    lines = [json.dumps(line), json.dumps({**line, "cell": [5, 6], "maps": False})]
    out = io.StringIO()
    serve(explorer, io.StringIO("\n".join(lines) + "\n"), out, seed=3)
    first, second = (json.loads(x) for x in out.getvalue().splitlines())
    assert len(first["next"]) == 3 and all(0 <= i < n for i, n in
                                           zip(first["next"], volume.shape, strict=True))
    assert first["probed"]["material"] == "plush"
    inhibition_map = np.array(first["maps"]["inhibition"], float)
    assert inhibition_map.shape == volume.shape
    np.testing.assert_allclose(inhibition_map.ravel(), explorer.last.inhibition[0])
    assert "expected 'cell' as 3 integers [ix, iy, iz], found [5, 6]" in second["error"]


def test_a_volume_too_large_for_a_chunk_is_refused_before_anything_is_allocated(tmp_path, capsys):
    from bayesprog.cli import main

    scenario = _small_volume(tmp_path, grid={"shape": [150, 100, 100], "cell": 0.0015})
    path = tmp_path / "experiment.yaml"
    path.write_text(yaml.safe_dump({"experiment": 1, "name": "big", "runner": "haptic",
                                    "scenario": str(scenario), "tasks": ["T1"], "runs": 10, "chunk": 10,
                                    "configurations": ["full"], "iterations": 5},
                                   sort_keys=False))
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "experiment.yaml:" in err and "a chunk of 10 runs on the 150 x 100 x 100 grid needs" \
        in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()



def test_tune_on_volumes_draws_them_from_above(tmp_path, capsys):
    """`bayesprog tune` with volumes for training and validation: the search runs and its
    figures draw the validation volume seen from above."""
    from bayesprog.cli import main

    spec = {"experiment": 1, "name": "tune_volume", "runner": "haptic",
            "scenario": str(MODELS / "scenarios" / "volume.yaml"), "tasks": ["T1"],
            "configurations": ["full"], "runs": 4, "iterations": 15, "seed": 1, "chunk": 4,
            "tune": {"training": [str(MODELS / "scenarios" / "volume.yaml")],
                     "validation": [str(MODELS / "scenarios" / "volume_prisms.yaml")],
                     "trials": 2, "runs": 2, "validation_runs": 2}}
    path = tmp_path / "tune.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    assert main(["tune", str(path), "--out", str(tmp_path / "out"), "-q"]) == 0
    result = json.loads((tmp_path / "out" / "tune.json").read_text())
    assert {row["scenario"] for row in result["validation"]} == {"volume_prisms"}
    visits = np.asarray(result["validation"][0]["hand_visits"])
    assert visits.size == 26 * 18 * 10 and visits.sum() == 2 * 15
    for name in ("tune.png", "tune-visits.png"):
        assert (tmp_path / "out" / name).stat().st_size > 5_000


def test_a_solid_past_the_volumes_edge_is_clipped_with_a_warning_at_its_line(tmp_path):
    inside = load_scenario(_small_volume(tmp_path))
    assert inside.warnings == []
    path = _small_volume(tmp_path, objects=[
        {"template": "box", "material": "plush", "at": [0.01, 0.05, 0.06]},
        {"template": "ball", "material": "silicone", "at": [0.1, 0.13, 0.06]}])
    scenario = load_scenario(path)
    assert len(scenario.warnings) == 1
    warning = str(scenario.warnings[0])
    assert "small_volume.yaml:" in warning and "warning: object 1 (plush) reaches past" in warning
    assert "surface points are outside; it is clipped to the grid" in warning


@pytest.mark.parametrize("growth, expected", [(None, [20, 30, 40, 50, 60]),
                                              (1.5, [18, 27, 41, 62])])
def test_full_searches_at_multiples_or_as_the_set_grows(growth, expected, monkeypatch):
    """On a surface a run's full search is made again at each multiple of restart_every
    points; in a volume (growth) once its set has grown by the factor since the last."""
    from runner.attention.shape import Registration, ShapeTracker

    tracker = ShapeTracker(np.zeros((1, 4, 2)), np.zeros((1, 3, 2)), growth=growth)
    searched = []

    def fake(path, counts, runs, *, rotations, iterations, warm=True):
        if rotations:
            searched.append(int(counts[runs][0]))
        n = len(runs)
        return Registration(error=np.full((n, 1), 0.1), distance=np.full((n, 1), 0.01),
                            points=np.zeros((n, 1, 3, 2)), angle=np.zeros((n, 1)),
                            shift=np.zeros((n, 1, 2)))

    monkeypatch.setattr(tracker, "_match", fake)
    path = np.zeros((1, 64, 2))
    for count in range(10, 65):
        tracker.update(path, np.array([count]))
    assert [c for c in searched if c > tracker.short] == expected
