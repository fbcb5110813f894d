"""Gamma (eq. 16), ground-truth borders and the polygon helpers of runner/world/scenario.py.

Gamma is checked against ``gamma_brute_force`` and against scipy's ``cdist``; borders against
sets of cells drawn by hand on a tiny scenario written here.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.distance import cdist

from runner.experiments.metrics import BorderDistance, behaviour, gamma_brute_force
from runner.world.scenario import inside, load_scenario, outline_points

MODELS = Path(__file__).parents[2] / "models"


def grid_centres(nx: int, ny: int, cell: float) -> np.ndarray:
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    return (np.stack([ix.ravel(), iy.ravel()], axis=1) + 0.5) * cell


@functools.cache
def paper():
    return load_scenario(MODELS / "scenarios" / "paper.yaml")


# --- Gamma -------------------------------------------------------------------------------------


@st.composite
def gamma_cases(draw):
    nx, ny = draw(st.integers(1, 7)), draw(st.integers(1, 7))
    cell = draw(st.sampled_from([0.01, 0.02, 1.0]))
    n = nx * ny
    border = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    runs = draw(st.integers(1, 3))
    steps = draw(st.integers(1, 12))
    probes = np.array(draw(st.lists(st.lists(st.integers(0, n - 1), min_size=runs, max_size=runs),
                                    min_size=steps, max_size=steps)))  # [steps, runs]
    return grid_centres(nx, ny, cell), border, probes


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=gamma_cases())
def test_gamma_incremental_equals_recomputation(case):
    centres, border, probes = case
    runs = probes.shape[1]
    g = BorderDistance(centres, border, runs=runs)
    for k in range(len(probes)):
        got = g.probe(probes[k])
        assert got.shape == (runs,)
        for r in range(runs):
            probed = probes[: k + 1, r]
            if border.any():
                expected = cdist(centres[border], centres[probed]).min(axis=1).sum()
            else:
                expected = 0.0
            assert got[r] == pytest.approx(expected, abs=1e-12)
            assert got[r] == pytest.approx(gamma_brute_force(centres, border, list(probed)),
                                           abs=1e-12)
        np.testing.assert_array_equal(g.gamma(), got)


def test_gamma_by_hand_on_a_line():
    # cells at x = 0, 1, 2, 3, 4 (cell 1 m, one row); border cells 0 and 4
    centres = grid_centres(5, 1, 1.0)
    border = np.array([True, False, False, False, True])
    g = BorderDistance(centres, border, runs=2)
    np.testing.assert_allclose(g.probe(np.array([2, 0])), [2.0 + 2.0, 0.0 + 4.0])
    np.testing.assert_allclose(g.probe(np.array([3, 4])), [2.0 + 1.0, 0.0 + 0.0])
    # probing the same cell again changes nothing; Gamma never increases
    np.testing.assert_allclose(g.probe(np.array([3, 4])), [3.0, 0.0])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(1, 30))
def test_gamma_on_the_paper_grid_random_probes(seed, k):
    """Gamma of the paper's T2 border for random probes, against cdist."""
    scenario = paper()
    border = scenario.border("T2").ravel()
    rng = np.random.default_rng(seed)
    probes = rng.integers(0, len(scenario.centres), size=k)
    g = BorderDistance(scenario.centres, border, runs=1)
    for j, p in enumerate(probes):
        got = g.probe(np.array([p]))[0]
        expected = cdist(scenario.centres[border], scenario.centres[probes[: j + 1]]).min(1).sum()
        assert got == pytest.approx(expected, rel=1e-12)


# --- a hand-drawn scenario ---------------------------------------------------------------------


def write_scenario(tmp_path: Path, square: list[list[float]]) -> Path:
    text = f"""\
scenario: 1
name: tiny
programs:
  perception: {(MODELS / "pi_per.yaml").resolve()}
  shape: {(MODELS / "pi_obj.yaml").resolve()}
  target: {(MODELS / "pi_tar.yaml").resolve()}
grid: {{shape: [6, 5], cell: 0.01}}
background: wood
templates:
  rectangle: [[-0.01, -0.01], [0.01, -0.01], [0.01, 0.01], [-0.01, 0.01]]
  triangle: [[-0.01, -0.01], [0.01, -0.01], [0.0, 0.01]]
objects:
  - {{polygon: {square}, material: silicone}}
tasks:
  T1: silicone
  T2: wood
"""
    path = tmp_path / "tiny.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def cells_of(mask: np.ndarray) -> set[tuple[int, int]]:
    return {(int(ix), int(iy)) for ix, iy in zip(*np.nonzero(mask), strict=True)}


# The square covers the cell centres ix in {2, 3}, iy in {1, 2} (1 cm cells, centres at +0.5 cm).
INTERIOR = [[0.02, 0.01], [0.04, 0.01], [0.04, 0.03], [0.02, 0.03]]
INTERIOR_SILICONE = {(2, 1), (2, 2), (3, 1), (3, 2)}
# every silicone cell touches wood; the wood cells touching silicone are the 8 around the square
INTERIOR_BORDERS = {
    "T1": INTERIOR_SILICONE,
    "T2": {(1, 1), (1, 2), (4, 1), (4, 2), (2, 0), (3, 0), (2, 3), (3, 3)},
}
# The same square in the corner: cells ix in {0, 1}, iy in {0, 1}. Cell (0, 0) only touches
# silicone and the edge of the grid, which is not another material: it is not a border cell.
CORNER = [[0.0, 0.0], [0.02, 0.0], [0.02, 0.02], [0.0, 0.02]]
CORNER_SILICONE = {(0, 0), (0, 1), (1, 0), (1, 1)}
CORNER_BORDERS = {
    "T1": {(0, 1), (1, 0), (1, 1)},
    "T2": {(2, 0), (2, 1), (0, 2), (1, 2)},
}


@pytest.mark.parametrize(
    ("square", "silicone", "borders"),
    [(INTERIOR, INTERIOR_SILICONE, INTERIOR_BORDERS), (CORNER, CORNER_SILICONE, CORNER_BORDERS)],
    ids=["interior", "corner"],
)
def test_border_of_a_hand_drawn_scenario(tmp_path, square, silicone, borders):
    scenario = load_scenario(write_scenario(tmp_path, square))
    assert scenario.shape == (6, 5)
    wood, sil = scenario.materials.index("wood"), scenario.materials.index("silicone")
    expected_map = np.full((6, 5), wood)
    for ix, iy in silicone:
        expected_map[ix, iy] = sil
    np.testing.assert_array_equal(scenario.material_map, expected_map)
    for task, cells in borders.items():
        mask = scenario.border(task)
        assert mask.shape == (6, 5)
        assert cells_of(mask) == cells, task


def test_gamma_on_the_hand_drawn_scenario(tmp_path):
    scenario = load_scenario(write_scenario(tmp_path, INTERIOR))
    border = scenario.border("T1")
    g = BorderDistance(scenario.centres, border, runs=1)
    # probe cell (2, 1): distances to (2, 1), (2, 2), (3, 1), (3, 2) are 0, 1, 1, sqrt 2 cells
    got = g.probe(np.array([2 * 5 + 1]))[0]
    assert got == pytest.approx(0.01 * (0 + 1 + 1 + np.sqrt(2)))
    # then (3, 2): every border cell within one cell, two of them probed
    got = g.probe(np.array([3 * 5 + 2]))[0]
    assert got == pytest.approx(0.01 * (0 + 1 + 1 + 0))


def test_paper_scenario_materials_and_borders():
    scenario = paper()
    m = scenario.material_map
    assert m.shape == (30, 60)
    names = scenario.materials
    assert names[m[15, 17]] == "silicone"  # the rectangle's centre (0.15, 0.17)
    assert names[m[15, 43]] == "plush"  # the triangle placed at (0.15, 0.43)
    assert names[m[0, 0]] == "wood" and names[m[29, 59]] == "wood"
    for task in ("T1", "T2", "T3"):
        target = scenario.task_material(task)
        expected = set()
        for ix in range(30):
            for iy in range(60):
                if m[ix, iy] != target:
                    continue
                neighbours = [(ix + dx, iy + dy) for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1))]
                if any(m[x, y] != target for x, y in neighbours if 0 <= x < 30 and 0 <= y < 60):
                    expected.add((ix, iy))
        assert expected, task
        assert cells_of(scenario.border(task)) == expected, task


# --- inside / outline_points -------------------------------------------------------------------


def test_inside_square_and_orientation():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    pts = np.array([[0.5, 0.5], [0.1, 0.9], [1.5, 0.5], [-0.2, 0.5], [0.5, 1.2], [0.5, -0.01]])
    expected = [True, True, False, False, False, False]
    assert inside(pts, square).tolist() == expected
    assert inside(pts, square[::-1]).tolist() == expected  # clockwise gives the same


def test_inside_concave_polygon():
    # an L: the unit square [0, 2]^2 minus the top-right quarter [1, 2]^2
    ell = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float)
    pts = np.array([[0.5, 0.5], [1.5, 0.5], [0.5, 1.5], [1.5, 1.5], [2.5, 0.5], [0.5, 2.5]])
    assert inside(pts, ell).tolist() == [True, True, True, False, False, False]


def test_outline_points_square_by_hand():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    expected = [[0, 0], [0.5, 0], [1, 0], [1, 0.5], [1, 1], [0.5, 1], [0, 1], [0, 0.5]]
    np.testing.assert_allclose(outline_points(square, 8), expected, atol=1e-12)


def test_outline_points_triangle_by_hand():
    # a 3-4-5 triangle, perimeter 12: one point per unit of arc length, starting at vertex 0
    tri = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]])
    expected = [[0, 0], [1, 0], [2, 0], [3, 0], [4, 0], [4, 1], [4, 2], [4, 3],
                [3.2, 2.4], [2.4, 1.8], [1.6, 1.2], [0.8, 0.6]]
    np.testing.assert_allclose(outline_points(tri, 12), expected, atol=1e-12)


def test_paper_templates_are_centred_outline_points():
    scenario = paper()
    for name, (poly, pts) in scenario.templates.items():
        assert pts.shape == (50, 2), name
        np.testing.assert_allclose(pts.mean(axis=0), 0.0, atol=1e-12)
        # the centred polygon is the YAML polygon shifted by the same vector as the points
        raw = np.asarray(scenario.spec.templates[name], float)
        np.testing.assert_allclose(poly - poly[0], raw - raw[0], atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), runs=st.integers(1, 4), steps=st.integers(2, 30))
def test_behaviour_metrics_by_brute_force(seed, runs, steps):
    """Recall, precision, first reach and path length, counted probe by probe."""
    rng = np.random.default_rng(seed)
    nx, ny, cell = 5, 7, 0.01
    border = rng.random((nx, ny)) < 0.3
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    centres = (np.stack([ix.ravel(), iy.ravel()], axis=1) + 0.5) * cell
    paths = rng.integers(0, nx * ny, (runs, steps))
    got = behaviour(paths, border, centres)
    flat = border.ravel()
    on = [[bool(flat[c]) for c in run] for run in paths]
    assert got["precision"] == pytest.approx(sum(map(sum, on)) / (runs * steps))
    if flat.any():
        recall = [len({c for c in run if flat[c]}) / flat.sum() for run in paths]
        assert got["border_probed"] == pytest.approx(np.mean(recall))
    firsts = [row.index(True) for row in on if any(row)]
    assert got["reached"] == pytest.approx(len(firsts) / runs)
    if firsts:
        assert got["reach_step"] == pytest.approx(np.median(firsts))
    lengths = [sum(float(np.hypot(*(centres[b] - centres[a])))
                   for a, b in zip(run[:-1], run[1:], strict=True)) for run in paths]
    assert got["path_length"] == pytest.approx(np.mean(lengths))


def test_the_search_and_the_following_add_up_to_the_area_under_gamma():
    from runner.experiments.metrics import area_under, phase_areas

    rng = np.random.default_rng(5)
    gamma = rng.random((40, 12))
    paths = rng.integers(0, 20, size=(40, 12))
    border = np.zeros(20, bool)
    border[[4, 11]] = True
    search, follow = phase_areas(gamma, paths, border)
    np.testing.assert_allclose(search + follow, area_under(gamma), rtol=1e-12)
    for run in range(40):  # each part by itself: the trapezoids up to, and from, the first reach
        hits = np.flatnonzero(border[paths[run]])
        first = hits[0] if hits.size else 11
        assert search[run] == pytest.approx(np.trapezoid(gamma[run, :first + 1]))
        assert follow[run] == pytest.approx(np.trapezoid(gamma[run, first:]) if hits.size else 0.0)
