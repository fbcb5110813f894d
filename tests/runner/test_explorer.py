"""The exploration loop: decisions asked of pi_tar, determinism, batching, ablations, pi_per."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

import bayesprog
from runner.attention.cues import saliency
from runner.attention.explorer import CONFIGURATIONS, Explorer
from runner.experiments.experiment import simulate
from runner.world.readings import paper_readings
from runner.world.scenario import load_scenario
from runner.world.sensor import material_normals

MODELS = Path(__file__).parents[2] / "models"


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(MODELS / "scenarios" / "paper.yaml")


def _explore(scenario, task, conf, runs, steps, seed=5):
    starts = np.array([[3, 4], [20, 30], [15, 15], [28, 58]])[:runs]
    return simulate(scenario, task, conf, starts, np.arange(runs), seed, steps)


def test_runner_choice_is_pi_tar_map_on_the_same_fields(scenario):
    explorer = Explorer(scenario, "T2", runs=3)
    explorer.reset(np.array([[10, 10], [12, 14], [20, 40]]), seed=9)
    rng = np.random.default_rng(0)
    cells = explorer.expected
    pi_tar = bayesprog.load(MODELS / "pi_tar.yaml")
    checked = 0
    for _ in range(12):
        # readings of silicone or wood, so that the runs meet perceived borders
        texture = np.where(rng.random(3) < 0.5, 0.12, 0.52) + 0.01 * rng.standard_normal(3)
        compliance = np.where(texture < 0.3, 0.35, 0.08) + 0.01 * rng.standard_normal(3)
        cells = explorer.step(cells, paper_readings(texture, compliance))
        d = explorer.last
        for run in range(3):
            inputs = {"errors": np.full(2, 0.5)}
            program = pi_tar.ablate("P(R | O)")
            if d.shape_ready[run]:
                inputs = {"templates": d.templates[run], "errors": d.shape_error[run]}
                program = pi_tar
            post = program.posterior("P(O | T, I, S, U)", {
                "T": "T2", "I": d.inhibition[run], "S": d.saliency[run],
                "U": d.uncertainty[run]}, inputs=inputs)
            p = post.probabilities
            np.testing.assert_allclose(p[d.next_cell[run]], p.max(), rtol=1e-12)
            checked += bool(d.shape_ready[run])
    assert checked >= 5  # the shape cue was part of most decisions


def test_same_seed_same_path_and_different_seed_differs(scenario):
    a = _explore(scenario, "T1", "full", 2, 15, seed=1)
    b = _explore(scenario, "T1", "full", 2, 15, seed=1)
    c = _explore(scenario, "T1", "full", 2, 15, seed=2)
    np.testing.assert_array_equal(a["paths"], b["paths"])
    np.testing.assert_array_equal(a["gamma"], b["gamma"])
    assert not np.array_equal(a["paths"], c["paths"])


def test_batched_runs_equal_runs_one_at_a_time(scenario):
    starts = np.array([[3, 4], [20, 30], [15, 15]])
    batched = simulate(scenario, "T2", "full", starts, np.arange(3), 11, 14)
    for r in range(3):
        alone = simulate(scenario, "T2", "full", starts[r : r + 1], np.array([r]), 11, 14)
        np.testing.assert_array_equal(alone["paths"][0], batched["paths"][r])
        np.testing.assert_allclose(alone["gamma"][0], batched["gamma"][r], rtol=1e-12)


def _uniform_variant(tmp_path: Path, term: str) -> bayesprog.Program:
    doc = yaml.safe_load((MODELS / "pi_tar.yaml").read_text())
    from bayesprog.vocabulary.expressions import parse_expression as parse

    hits = [t for t in doc["decomposition"] if parse(t["term"]).key == parse(term).key]
    assert len(hits) == 1
    hits[0].clear()
    hits[0].update({"term": term, "form": "uniform"})
    (tmp_path / "pi_obj.yaml").write_text((MODELS / "pi_obj.yaml").read_text())
    path = tmp_path / "pi_tar.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return bayesprog.load(path)


@pytest.mark.parametrize("configuration", [c for c in CONFIGURATIONS if c != "full"])
def test_each_ablation_is_the_program_with_that_term_uniform(scenario, tmp_path, configuration):
    (term,) = CONFIGURATIONS[configuration]
    explorer = Explorer(scenario, "T3", ablate=CONFIGURATIONS[configuration])
    rewritten = _uniform_variant(tmp_path, term)
    rng = np.random.default_rng(3)
    cells = 1800
    evidence = {"T": "T3", "I": rng.random((2, cells)), "S": rng.random((2, cells)),
                "U": rng.random((2, cells))}
    inputs = {"templates": rng.random((2, 2, 50, 2)) * 0.3,
              "errors": np.array([[0.1, 0.6], [0.7, 0.2]])}
    ours = explorer.target.posterior("P(O | T, I, S, U)", evidence, inputs=inputs)
    theirs = rewritten.posterior("P(O | T, I, S, U)", evidence, inputs=inputs)
    np.testing.assert_allclose(ours.probabilities, theirs.probabilities, rtol=1e-9, atol=1e-15)
    assert ours.ablated == (term,)
    full = bayesprog.load(MODELS / "pi_tar.yaml").posterior("P(O | T, I, S, U)", evidence,
                                                            inputs=inputs)
    assert not np.allclose(full.probabilities, ours.probabilities)


def test_pi_per_single_probe_recognition():
    """Single-probe MAP recognition over the 10 proxy materials, 10,000 probes each (seeded).

    False-failure budget: with the proxy's true rates (mean ~0.916; wood ~0.896 against plush
    ~0.913 and silicone ~0.954), 10,000 probes per material put the mean 40 standard errors above
    0.90 and wood's gap to plush about 4 standard errors: a fresh seed fails with probability
    below 1e-4.
    """
    program = bayesprog.load(MODELS / "pi_per.yaml")
    normals = material_normals(program)
    states = program.variables["M"].states
    rng = np.random.default_rng(20261122)
    n = 10_000
    rates = {}
    for m, name in enumerate(states):
        e = normals["E"][0][m] + normals["E"][1][m] * rng.standard_normal(n)
        c = normals["C"][0][m] + normals["C"][1][m] * rng.standard_normal(n)
        answer = program.map("material", {"E": e, "C": c}, rng=0)
        rates[name] = float(np.mean(answer.indices[:, 0] == m))
    assert np.mean(list(rates.values())) >= 0.90
    assert rates["wood"] < rates["plush"] and rates["wood"] < rates["silicone"]


def test_perception_is_recursive_bayes(scenario):
    """Two probes of one cell: the map holds prior x both likelihoods, normalised."""
    from scipy import stats

    explorer = Explorer(scenario, "T1")
    explorer.reset((4, 4), seed=0)
    flat = explorer.flat(np.array([[4, 4]]))
    readings = [(0.5, 0.1), (0.55, 0.05)]
    for e, c in readings:
        explorer.perceive(flat, paper_readings(np.array([e]), np.array([c])))
    normals = material_normals(explorer.perception)
    like = np.ones(10)
    for e, c in readings:
        like *= stats.norm(*normals["E"]).pdf(e) * stats.norm(*normals["C"]).pdf(c)
    np.testing.assert_allclose(explorer.posterior[0, flat[0]], like / like.sum(), rtol=1e-10)
    assert np.allclose(explorer.posterior[0, flat[0] + 1], 0.1)


def test_explorer_rejects_cells_outside_the_grid(scenario):
    explorer = Explorer(scenario, "T1")
    explorer.reset((0, 0))
    with pytest.raises(bayesprog.QuestionError, match="outside the 30 x 60 grid"):
        explorer.observe((30, 2), {"texture": 0.5, "compliance": 0.5})


def test_the_perceived_stimulus_kept_per_probe_is_the_one_read_from_the_map():
    """percept() is updated at the probed cell only; it equals the definition read from the
    whole perceptual map, after probes that change a cell's perceived material."""
    scenario = load_scenario(MODELS / "scenarios" / "paper.yaml")
    explorer = Explorer(scenario, "T3", runs=3)
    explorer.reset(np.array([[2, 2], [10, 30], [29, 59]]), seed=4)
    rng = np.random.default_rng(4)
    normals = material_normals(explorer.perception)
    ny = scenario.shape[1]
    compared = 0
    for _ in range(60):
        # probes packed in a corner of 6 x 6 cells (edges of the grid included), so that
        # neighbours are probed, cells probed again, and percepts flip
        cells = rng.integers(0, 6, 3) * ny + rng.integers(0, 6, 3)
        material = rng.integers(0, explorer.materials, 3)
        # a reading of that material, with noise: some probes flip a cell's percept
        texture = normals["E"][0][material] + rng.normal(0, 2, 3) * normals["E"][1][material]
        compliance = normals["C"][0][material] + rng.normal(0, 2, 3) * normals["C"][1][material]
        explorer.perceive(cells, paper_readings(texture, compliance))
        target, perceived = explorer.percept()
        p = explorer.posterior
        want_target = p[..., explorer.target_material] >= 0.5
        want_other = p[..., explorer.counter_materials].sum(-1) >= 0.5
        want = (explorer.visits > 0) & (want_target | want_other)
        assert np.array_equal(perceived.reshape(3, -1), want)
        assert np.array_equal((target & perceived).reshape(3, -1), want_target & want)
        # and the saliency kept around the probed cells is the one of the whole map
        _, s, _ = explorer.cue_fields()
        whole = saliency(target.astype(float), perceived).reshape(3, -1)
        whole[~np.any(np.isnan(whole) | (whole > 0), axis=1)] = np.nan  # the veto of a run
        np.testing.assert_array_equal(s, whole)
        compared += int(np.sum(s > 0))
    assert compared > 100  # the maps had salient cells to agree on


def test_the_path_kept_as_an_array_is_the_path_stacked(scenario):
    """The array of the path that the followed border reads, copied into its buffer a few
    steps at a time as the path grows past the buffer's size, is the whole path stacked,
    however often it is read, and a reset's new path replaces the old one."""
    explorer = Explorer(scenario, "T2", runs=2)
    rng = np.random.default_rng(3)
    for start in ([[1, 1], [5, 5]], [[7, 3], [0, 9]]):
        explorer.reset(np.array(start), seed=1)
        for step in range(150):
            explorer.path.append(rng.integers(0, len(explorer.centres), 2))
            if step % 7 == 0 or step > 120:
                np.testing.assert_array_equal(explorer.stacked_path(), np.stack(explorer.path))
        assert explorer.stacked_path().shape == (150, 2)
