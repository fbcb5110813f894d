"""The per-cell cues of pi_tar (runner/attention/cues.py) against independent computations.

* U, eq. (11): scipy.stats.entropy / log(10);
* S, eq. (12): scipy.ndimage.sobel (``mode="nearest"``: edges replicated) and hand-made grids;
* I, eq. (10): a direct numpy Beta kernel whose maximum is found numerically by
  scipy.optimize.minimize_scalar (not from the closed-form mode).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import ndimage, optimize, stats

from runner.attention.cues import inhibition, saliency, uncertainty

MATERIALS = 10
ALPHA, BETA = 1.01, 9.0  # design.md section 4
FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# --- U, eq. (11) -------------------------------------------------------------------------------


def test_uncertainty_uniform_is_one_and_one_hot_is_zero():
    uniform = np.full(MATERIALS, 1.0 / MATERIALS)
    one_hot = np.eye(MATERIALS)  # ten posteriors, each certain of one material
    assert uncertainty(uniform) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_array_equal(uncertainty(one_hot), np.zeros(MATERIALS))


@pytest.mark.parametrize(
    "posterior",
    [
        [0.5, 0.5] + [0.0] * 8,
        [0.9] + [0.1 / 9] * 9,
        [0.7, 0.2, 0.1] + [0.0] * 7,
        list(np.arange(1, 11) / 55.0),
    ],
)
def test_uncertainty_matches_scipy_entropy(posterior):
    p = np.asarray(posterior)
    assert p.sum() == pytest.approx(1.0)
    expected = stats.entropy(p) / np.log(MATERIALS)
    assert uncertainty(p) == pytest.approx(expected, abs=1e-12)


def test_uncertainty_two_equal_materials_by_hand():
    # H = log 2 nats, so U = log 2 / log 10 = log10(2)
    p = np.array([0.5, 0.5] + [0.0] * 8)
    assert uncertainty(p) == pytest.approx(np.log10(2.0), abs=1e-12)


@FAST
@given(seed=st.integers(0, 2**32 - 1), runs=st.integers(1, 3), cells=st.integers(1, 6),
       concentration=st.floats(0.05, 5.0))
def test_uncertainty_batched_matches_scipy(seed, runs, cells, concentration):
    rng = np.random.default_rng(seed)
    post = rng.dirichlet(np.full(MATERIALS, concentration), size=(runs, cells))
    u = uncertainty(post)
    assert u.shape == (runs, cells)
    expected = stats.entropy(post, axis=-1) / np.log(MATERIALS)
    np.testing.assert_allclose(u, expected, atol=1e-12)
    assert np.all((u >= 0) & (u <= 1))


# --- S, eq. (12) -------------------------------------------------------------------------------


def reference_saliency(d: np.ndarray) -> np.ndarray:
    """max(|s_x|, |s_y|) / 4 with scipy's Sobel, s_x along the first grid axis (ix)."""
    sx = ndimage.sobel(d, axis=0, mode="nearest")
    sy = ndimage.sobel(d, axis=1, mode="nearest")
    return np.maximum(np.abs(sx), np.abs(sy)) / 4.0


def test_saliency_step_along_x():
    """A 0/1 step between ix = 2 and ix = 3 (an edge parallel to the y axis)."""
    d = np.zeros((8, 6))
    d[3:, :] = 1.0
    expected = np.zeros((8, 6))
    expected[2:4, :] = 1.0  # both cells beside the step, in every row, grid edges included
    np.testing.assert_allclose(saliency(d), expected, atol=1e-12)
    np.testing.assert_allclose(saliency(d), reference_saliency(d), atol=1e-12)


def test_saliency_step_along_y():
    """A 0/1 step between iy = 3 and iy = 4 (an edge parallel to the x axis), 1 on the low side."""
    d = np.zeros((5, 9))
    d[:, :4] = 1.0
    expected = np.zeros((5, 9))
    expected[:, 3:5] = 1.0
    np.testing.assert_allclose(saliency(d), expected, atol=1e-12)
    np.testing.assert_allclose(saliency(d), reference_saliency(d), atol=1e-12)


def test_saliency_single_peak_by_hand():
    """One cell at 1: the 4-neighbours see a centre weight 2 (S = 1/2), the diagonal neighbours
    a corner weight 1 (S = 1/4), the peak itself and everything further away 0."""
    d = np.zeros((7, 7))
    d[3, 3] = 1.0
    expected = np.zeros((7, 7))
    for ix, iy in ((2, 3), (4, 3), (3, 2), (3, 4)):
        expected[ix, iy] = 0.5
    for ix, iy in ((2, 2), (2, 4), (4, 2), (4, 4)):
        expected[ix, iy] = 0.25
    np.testing.assert_allclose(saliency(d), expected, atol=1e-12)


def test_saliency_batched_over_runs():
    rng = np.random.default_rng(1)
    d = rng.random((3, 6, 4))
    s = saliency(d)
    assert s.shape == d.shape
    for r in range(3):  # scipy on each 2-D slice (a 3-D scipy Sobel would smooth across runs)
        np.testing.assert_allclose(s[r, 1:-1, 1:-1], reference_saliency(d[r])[1:-1, 1:-1],
                                   atol=1e-12)
        np.testing.assert_allclose(s[r], saliency(d[r]), atol=1e-12)


@FAST
@given(d=arrays(np.float64, st.tuples(st.integers(2, 9), st.integers(2, 9)),
                elements=st.floats(0.0, 1.0)))
def test_saliency_in_unit_interval_and_matches_scipy_inside(d):
    """Every cell perceived: the standard Sobel / 4 away from the grid's edge (at the edge the
    cells outside count as unperceived, and each line's weights are renormalised)."""
    s = saliency(d)
    assert s.shape == d.shape
    assert np.all((s >= 0.0) & (s <= 1.0))
    np.testing.assert_allclose(s[1:-1, 1:-1], reference_saliency(d)[1:-1, 1:-1], atol=1e-12)


def test_saliency_in_3d_matches_scipy_inside():
    d = np.random.default_rng(3).random((5, 6, 7))
    reference = np.max([np.abs(ndimage.sobel(d, axis=a, mode="nearest")) for a in range(3)],
                       axis=0) / 16.0  # 16: the (1, 2, 1) x (1, 2, 1) weights of one side
    np.testing.assert_allclose(saliency(d, dims=3)[1:-1, 1:-1, 1:-1],
                               reference[1:-1, 1:-1, 1:-1], atol=1e-12)


# --- S of a partly probed map: what has been perceived, not where ----------------------------


def _brute_line_sobel(d, probed, ix, iy):
    """Eq. (12) at one cell from its definition, by loops: per axis, the (1, 2, 1)-weighted mean
    of the probed cells of each of the three lines, a missing side replaced by the centre."""
    nx, ny = d.shape
    best, compared_any = 0.0, False
    for axis in (0, 1):
        means = {}
        for offset in (-1, 0, 1):
            num = den = 0.0
            for along, w in ((-1, 1.0), (0, 2.0), (1, 1.0)):
                cx, cy = (ix + offset, iy + along) if axis == 0 else (ix + along, iy + offset)
                if 0 <= cx < nx and 0 <= cy < ny and probed[cx, cy]:
                    num, den = num + w * d[cx, cy], den + w
            if den:
                means[offset] = num / den
        if len(means) >= 2:
            hi, lo = means.get(1, means.get(0)), means.get(-1, means.get(0))
            best, compared_any = max(best, abs(hi - lo)), True
    if compared_any:
        return best
    near = probed[max(ix - 1, 0): ix + 2, max(iy - 1, 0): iy + 2].any()
    return np.nan if near else 0.0


@FAST
@given(seed=st.integers(0, 2**32 - 1), nx=st.integers(1, 7), ny=st.integers(1, 7),
       share=st.floats(0.0, 1.0))
def test_saliency_of_a_partly_probed_map_matches_its_definition(seed, nx, ny, share):
    rng = np.random.default_rng(seed)
    d = rng.random((nx, ny))
    probed = rng.random((nx, ny)) < share
    expected = np.array([[_brute_line_sobel(d, probed, i, j) for j in range(ny)]
                         for i in range(nx)])
    np.testing.assert_allclose(saliency(d, probed), expected, atol=1e-12)  # compiled kernel
    np.testing.assert_allclose(saliency(d, probed, kernel=False), expected, atol=1e-12)


def test_the_frontier_of_what_was_probed_is_not_salient():
    """Probed cells all perceived as the target (d = 1), the rest at the prior 0.1: the standard
    Sobel of that map marks the edge of the probed block; the perceived saliency does not."""
    d = np.full((10, 10), 0.1)
    probed = np.zeros((10, 10), bool)
    probed[2:6, 3:7] = True
    d[probed] = 1.0
    assert reference_saliency(d).max() == pytest.approx(0.9)  # the frontier, full strength
    s = saliency(d, probed)
    assert np.nanmax(s) == 0.0
    # far from anything probed the map is the uniform prior: no edge there
    assert s[9, 0] == 0.0 and s[0, 9] == 0.0
    # next to the block there is nothing to compare across the frontier: not observed
    assert np.isnan(s[1, 4]) or s[1, 4] == 0.0


def test_a_perceived_border_and_its_continuation_are_salient():
    """Target cells (d = 1) probed at ix = 3 and other cells (d = 0) at ix = 4, rows 0..4: the
    unprobed cells of row 5 that continue the border are as salient as the border itself."""
    d = np.full((8, 10), 0.1)
    probed = np.zeros((8, 10), bool)
    probed[3:5, 0:5] = True
    d[3, 0:5], d[4, 0:5] = 1.0, 0.0
    s = saliency(d, probed)
    np.testing.assert_allclose(s[3:5, 0:6], 1.0)
    # beside the probed strip, away from the border, nothing is compared or nothing differs
    assert np.isnan(s[1, 2]) or s[1, 2] == 0.0
    assert s[3, 8] == 0.0  # nothing probed around it


# --- I, eq. (10) -------------------------------------------------------------------------------


def kernel(d):
    return d ** (ALPHA - 1) * (1 - d) ** (BETA - 1)


def max_kernel() -> float:
    res = optimize.minimize_scalar(lambda x: -kernel(x), bounds=(0.0, 1.0), method="bounded",
                                   options={"xatol": 1e-12})
    return -res.fun


def reference_inhibition(centres, last, diagonal):
    d = np.linalg.norm(centres[None, :, :] - last[:, None, :], axis=-1) / diagonal
    return 1.0 - kernel(np.clip(d, 0.0, 1.0)) / max_kernel()


def paper_grid(nx=30, ny=60, cell=0.01):
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    centres = (np.stack([ix.ravel(), iy.ravel()], axis=1) + 0.5) * cell
    return centres, float(np.hypot(nx * cell, ny * cell))


def test_inhibition_matches_direct_beta_kernel_on_the_paper_grid():
    centres, diagonal = paper_grid()
    last = centres[[0, 5 * 60 + 7, 29 * 60 + 59, 15 * 60 + 30]]
    i = inhibition(centres, last, diagonal)
    assert i.shape == (4, len(centres))
    np.testing.assert_allclose(i, reference_inhibition(centres, last, diagonal), atol=1e-9)
    assert np.all((i >= 0.0) & (i <= 1.0))


def test_inhibition_is_exactly_one_at_the_current_cell():
    centres, diagonal = paper_grid()
    flat = np.array([0, 123, 1799, 900])
    i = inhibition(centres, centres[flat], diagonal)
    assert np.all(i[np.arange(4), flat] == 1.0)
    # and strictly below 1 at every other cell of the grid
    others = np.ones_like(i, dtype=bool)
    others[np.arange(4), flat] = False
    assert np.all(i[others] < 1.0)


def test_inhibition_minimum_near_the_mode():
    # probe positions on a fine line through the last probed cell, d from 0 to 1 of the diagonal
    diagonal = 0.5
    d = np.linspace(0.0, 1.0, 200_001)
    centres = np.stack([d * diagonal, np.zeros_like(d)], axis=1)
    i = inhibition(centres, np.zeros((1, 2)), diagonal)[0]
    mode = (ALPHA - 1) / (ALPHA + BETA - 2)
    k = int(np.argmin(i))
    assert abs(d[k] - mode) <= 2e-5
    assert i[k] == pytest.approx(0.0, abs=1e-6)
    assert i[0] == 1.0 and i[-1] == pytest.approx(1.0, abs=1e-12)  # f(0) = f(1) = 0
    # falls to the minimum, then rises back towards 1
    assert np.all(np.diff(i[: k + 1]) <= 1e-12)
    assert np.all(np.diff(i[k:]) >= -1e-12)
    np.testing.assert_allclose(i, reference_inhibition(centres, np.zeros((1, 2)), diagonal)[0],
                               atol=1e-9)


@FAST
@given(seed=st.integers(0, 2**32 - 1), runs=st.integers(1, 4), n=st.integers(1, 40))
def test_inhibition_random_points_match_reference(seed, runs, n):
    rng = np.random.default_rng(seed)
    diagonal = float(np.hypot(0.3, 0.6))
    centres = rng.uniform([0, 0], [0.3, 0.6], (n, 2))
    last = rng.uniform([0, 0], [0.3, 0.6], (runs, 2))
    i = inhibition(centres, last, diagonal)
    assert np.all((i >= 0.0) & (i <= 1.0))
    np.testing.assert_allclose(i, reference_inhibition(centres, last, diagonal), atol=1e-9)


def test_a_perceived_map_smaller_than_the_batch_is_broadcast():
    """One mask for every run: the compiled kernel and the array version read it alike."""
    rng = np.random.default_rng(5)
    d = (rng.random((3, 6, 7)) < 0.5).astype(float)
    probed = rng.random((6, 7)) < 0.5
    expected = np.stack([saliency(d[r], probed) for r in range(3)])
    np.testing.assert_allclose(saliency(d, probed), expected, atol=1e-12)
    np.testing.assert_allclose(saliency(d, probed, kernel=False), expected, atol=1e-12)


def test_nan_at_a_perceived_cell_is_refused_and_ignored_elsewhere():
    d = np.zeros((4, 4))
    probed = np.zeros((4, 4), bool)
    probed[1, 1:3] = True
    d[0, 0] = np.nan  # not perceived: never read
    for kernel in (True, False):
        assert not np.isnan(saliency(d, probed, kernel=kernel)[1, 1])
    d[1, 1] = np.nan
    with pytest.raises(ValueError, match="perceived"):
        saliency(d, probed)


def test_the_explorers_inhibition_lookup_is_the_direct_formula():
    """The explorer reads I from a table of offsets (a window per run): the same numbers."""
    from runner.attention.explorer import Explorer
    from runner.world.scenario import load_scenario

    scenario = load_scenario(Path(__file__).parents[2] / "models" / "scenarios" / "paper.yaml")
    explorer = Explorer(scenario, "T1", runs=5)
    last = np.array([0, 61, 1799, 59, 1740])  # corners and an inner cell
    direct = inhibition(scenario.centres, scenario.centres[last], explorer.diagonal)
    np.testing.assert_allclose(explorer.inhibition_at(last), direct, atol=1e-12)
