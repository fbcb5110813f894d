"""Particles for steps that are not linear-Gaussian (``method="pf"``): a filter and a smoother
(forward filtering, backward smoothing), seeded, with the effective sample size of each step,
checked against a filter and a smoother on a fine grid, and against the Kalman filter and the
Rauch-Tung-Striebel smoother on a linear program; the smoother's memory grows as the number of
particles, its answer the same whatever its blocks, and what would not fit the limit is
refused with its cost."""

from __future__ import annotations

import json
import re
import tracemalloc

import numpy as np
import pytest
import scipy.stats

import bayesprog
from bayesprog.cli import main
from bayesprog.limits import SizeError, set_limits
from bayesprog.program import dynamic

BEND = """\
bayesprog: 1
name: bend
variables:
  X_before: {continuous: [-.inf, .inf]}
  X: {continuous: [-.inf, .inf]}
  Y: {continuous: [-.inf, .inf]}
time:
  previous: {X_before: X}
decomposition:
  - {term: P(X_before), form: normal, mean: 0.0, sigma: 1.0}
  - {term: P(X | X_before), form: normal, mean: "2*sin(X_before) + 0.5", sigma: 0.5}
  - {term: P(Y | X), form: normal, mean: "X", sigma: 0.4}
questions:
  track: {ask: P(X | Y), kind: filter}
"""

YS = [1.0, 2.1, 0.3, -0.4, 1.7]


def _grid_filter(ys: list[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The same filter on 3,001 points of [-6, 8]: means, sds and log p(y_t | y_<t)."""
    x = np.linspace(-6, 8, 3001)
    dx = x[1] - x[0]
    belief = scipy.stats.norm.pdf(x, 0.0, 1.0)
    move = scipy.stats.norm.pdf(x[None, :], 2 * np.sin(x[:, None]) + 0.5, 0.5)  # before, after
    means, sds, logs = [], [], []
    for y in ys:
        predicted = belief @ move * dx
        joint = predicted * scipy.stats.norm.pdf(y, x, 0.4)
        evidence = joint.sum() * dx
        belief = joint / evidence
        mean = (x * belief).sum() * dx
        means.append(mean)
        sds.append(np.sqrt(((x - mean) ** 2 * belief).sum() * dx))
        logs.append(np.log(evidence))
    return np.array(means), np.array(sds), np.array(logs)


def test_the_particle_filter_agrees_with_a_fine_grid_filter():
    program = bayesprog.loads(BEND)
    answer = program.ask("track", {"Y": YS}, method="pf", samples=20_000, rng=3)
    means, sds, logs = _grid_filter(YS)
    assert answer.method == "pf" and answer.ess.shape == (len(YS),)
    assert np.all((answer.ess > 100) & (answer.ess <= 20_000))
    error = np.asarray(answer.sd("X")) / np.sqrt(answer.ess)
    assert np.all(np.abs(answer.mean("X") - means) < 5 * error + 0.01)
    np.testing.assert_allclose(answer.sd("X"), sds, atol=0.03)
    # the estimate of p(y_t | y_<t) has a relative error of about 1/sqrt(ess)
    assert np.all(np.abs(answer.log_evidence - logs) < 4 / np.sqrt(answer.ess) + 0.01)


def test_the_particle_filter_is_seeded():
    program = bayesprog.loads(BEND)
    one = program.ask("track", {"Y": YS}, method="pf", samples=500, rng=7)
    two = program.ask("track", {"Y": YS}, method="pf", samples=500, rng=7)
    other = program.ask("track", {"Y": YS}, method="pf", samples=500, rng=8)
    np.testing.assert_array_equal(one.mean("X"), two.mean("X"))
    assert not np.array_equal(one.mean("X"), other.mean("X"))
    # a batch of sequences: the first is the sequence asked alone
    batch = program.ask("track", {"Y": np.array([YS, YS[::-1]]).T}, method="pf",
                        samples=500, rng=7)
    np.testing.assert_array_equal(batch.mean("X")[:, 0], one.mean("X"))


def test_the_command_line_and_what_a_particle_filter_does_not_answer(tmp_path, capsys):
    (tmp_path / "bend.yaml").write_text(BEND)
    code = main(["query", str(tmp_path / "bend.yaml"), "track", "--evidence", "Y=1.0,2.1",
                 "--method", "pf", "--samples", "2000", "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["mean"]["X"]) == 2 and len(out["ess"]) == 2 and out["method"] == "pf"
    program = bayesprog.loads(BEND)
    with pytest.raises(bayesprog.QuestionError, match="method='pf'"):
        program.ask("track", {"Y": YS})  # not linear: the Kalman filter says to ask pf
    with pytest.raises(bayesprog.QuestionError, match="filter and smooth questions"):
        program.ask("P(X | Y)", {"Y": YS}, kind="sequence", method="pf")


# the particle smoother (forward filtering, backward smoothing) ----------------------------------

def _grid_smoother(ys: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """The smoother of BEND on 3,001 points of [-6, 8], by the forward and the backward
    recursions: smoothed means and sds."""
    x = np.linspace(-6, 8, 3001)
    dx = x[1] - x[0]
    move = scipy.stats.norm.pdf(x[None, :], 2 * np.sin(x[:, None]) + 0.5, 0.5)  # before, after
    belief, filtered, predicted = scipy.stats.norm.pdf(x, 0.0, 1.0), [], []
    for y in ys:
        prior = belief @ move * dx
        belief = prior * scipy.stats.norm.pdf(y, x, 0.4)
        belief /= belief.sum() * dx
        predicted.append(prior)
        filtered.append(belief)
    smoothed = [filtered[-1]]
    for t in range(len(ys) - 2, -1, -1):
        ratio = np.where(predicted[t + 1] > 0, smoothed[0] / predicted[t + 1], 0.0)
        s = filtered[t] * (move @ ratio * dx)
        smoothed.insert(0, s / (s.sum() * dx))
    means = np.array([(x * s).sum() * dx for s in smoothed])
    sds = np.array([np.sqrt(((x - m) ** 2 * s).sum() * dx) for s, m in zip(smoothed, means,
                                                                          strict=True)])
    return means, sds


#: independent particle systems, asked at once as a batch of the same sequence (each sequence
#: of a batch draws from its own streams): their spread is the Monte Carlo error
REPLICATIONS = 8


def _replicated(program: bayesprog.Program, ys: list[float], samples: int, seed: int):
    """The smoother run REPLICATIONS times: each step's mean over the runs, its standard error
    from their spread, and the mean sd."""
    answer = program.ask("P(X | Y)", {"Y": np.tile(ys, (REPLICATIONS, 1)).T}, kind="smooth",
                         method="pf", samples=samples, rng=seed)
    means, sds = np.asarray(answer.mean("X")), np.asarray(answer.sd("X"))  # [steps, runs]
    error = means.std(axis=1, ddof=1) / np.sqrt(REPLICATIONS)
    return answer, means.mean(axis=1), error, sds.mean(axis=1)


def test_the_particle_smoother_agrees_with_a_fine_grid_smoother():
    """Within its Monte Carlo error, estimated from the spread of independent runs: each
    smoothed mean within 5 standard errors of the grid's (Student's t with 7 degrees of
    freedom: a false failure about one in 600 per step, seeded), the sds within 0.03."""
    program = bayesprog.loads(BEND)
    answer, mean, error, sd = _replicated(program, YS, 800, 3)
    grid_means, grid_sds = _grid_smoother(YS)
    filtered, _, _ = _grid_filter(YS)
    assert answer.method == "pf-smooth" and answer.ess.shape == (len(YS), REPLICATIONS)
    assert np.all((answer.ess >= 1) & (answer.ess <= 800))  # 1 / sum of squared weights
    assert np.all(np.abs(mean - grid_means) < 5 * error), (mean, grid_means, error)
    np.testing.assert_allclose(sd, grid_sds, atol=0.03)
    # smoothing moved the earlier steps (by far more than its error), not the last one
    assert np.all((np.abs(grid_means - filtered) > 10 * error)[:-1])
    last = program.ask("P(X | Y)", {"Y": np.tile(YS, (REPLICATIONS, 1)).T}, kind="filter",
                       method="pf", samples=800, rng=3)
    np.testing.assert_array_equal(answer.mean("X")[-1], last.mean("X")[-1])


CART = """\
bayesprog: 1
variables:
  X_before: {continuous: [-.inf, .inf]}
  X: {continuous: [-.inf, .inf]}
  Y: {continuous: [-.inf, .inf]}
time:
  previous: {X_before: X}
decomposition:
  - {term: P(X_before), form: normal, mean: 0.0, sigma: 1.0}
  - {term: P(X | X_before), form: normal, mean: "0.9*X_before + 0.5", sigma: 0.3}
  - {term: P(Y | X), form: normal, mean: "2*X", sigma: 0.5}
"""


def test_the_particle_smoother_agrees_with_rts_on_a_linear_program(tmp_path, capsys):
    program = bayesprog.loads(CART)
    ys = [1.0, 2.1, 2.9, 1.7]
    exact = program.ask("P(X | Y)", {"Y": ys}, kind="smooth")
    assert exact.method == "kalman-rts"
    _, mean, error, sd = _replicated(program, ys, 600, 5)
    assert np.all(np.abs(mean - exact.mean("X")) < 5 * error), (mean, exact.mean("X"), error)
    np.testing.assert_allclose(sd, exact.sd("X"), atol=0.02)
    # the command line: --over-time smooth --method pf, with each step's ess
    (tmp_path / "cart.yaml").write_text(CART)
    assert main(["query", str(tmp_path / "cart.yaml"), "P(X | Y)", "--over-time", "smooth",
                 "--method", "pf", "--samples", "500", "--evidence", "Y=1.0,2.1,2.9",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["method"] == "pf-smooth" and len(out["ess"]) == 3 and out["density"] == "gaussian"
    assert main(["query", str(tmp_path / "cart.yaml"), "P(X | Y)", "--over-time", "smooth",
                 "--method", "pf", "--samples", "500", "--evidence", "Y=1.0,2.1,2.9"]) == 0
    text = capsys.readouterr().out
    assert "particle smoother" in text and "step 3" in text and "effective sample size" in text


def test_the_particle_smoother_is_seeded_whatever_the_batching():
    program = bayesprog.loads(BEND)
    one = program.ask("P(X | Y)", {"Y": YS}, kind="smooth", method="pf", samples=300, rng=7)
    two = program.ask("P(X | Y)", {"Y": YS}, kind="smooth", method="pf", samples=300, rng=7)
    np.testing.assert_array_equal(one.mean("X"), two.mean("X"))
    batch = program.ask("P(X | Y)", {"Y": np.array([YS, YS[::-1]]).T}, kind="smooth",
                        method="pf", samples=300, rng=7)
    np.testing.assert_array_equal(batch.mean("X")[:, 0], one.mean("X"))
    np.testing.assert_array_equal(batch.ess[:, 0], one.ess)
    reversed_alone = program.ask("P(X | Y)", {"Y": YS[::-1]}, kind="smooth", method="pf",
                                 samples=300, rng=7)
    assert not np.array_equal(batch.mean("X")[:, 1], one.mean("X"))
    assert reversed_alone.mean("X").shape == (len(YS),)


# the smoother's memory: n pairs' densities at a time, never the n x n matrix -------------------

def test_the_particle_smoother_agrees_with_rts_under_a_limit_below_its_n_squared_pairs():
    """2,000 particles, the entries limit (3,000,000) below the 4,000,000 pairs of one
    sequence's step: each smoothed mean within 5 standard errors of the Rauch-Tung-Striebel
    smoother's, the error from the spread of 8 independent runs (Student's t with 7 degrees of
    freedom: a false failure about one in 600 per step, seeded)."""
    program = bayesprog.loads(CART)
    ys = [1.0, 2.1, 2.9, 1.7]
    exact = program.ask("P(X | Y)", {"Y": ys}, kind="smooth")
    assert exact.method == "kalman-rts"
    try:
        set_limits(entries=3_000_000)
        answer, mean, error, sd = _replicated(program, ys, 2_000, 11)
    finally:
        set_limits()
    assert answer.method == "pf-smooth"
    assert np.all(np.abs(mean - exact.mean("X")) < 5 * error), (mean, exact.mean("X"), error)
    np.testing.assert_allclose(sd, exact.sd("X"), atol=0.01)


def test_the_particle_smoother_needs_memory_in_n_not_n_squared():
    """3,000 particles: one n x n matrix of float64 is 72 MB; the smoother's whole run, its
    filter included, allocates less than a quarter of that at its peak (numpy's arrays are
    traced), under a limit a fifteenth of n^2 that shrinks its blocks, and answers as it does
    with the default limit, bit for bit."""
    program = bayesprog.loads(CART)
    ys, n = [1.0, 2.1, 2.9], 3_000
    free = program.ask("P(X | Y)", {"Y": ys}, kind="smooth", method="pf", samples=n, rng=4)
    try:
        set_limits(entries=600_000)
        tracemalloc.start()
        low = program.ask("P(X | Y)", {"Y": ys}, kind="smooth", method="pf", samples=n, rng=4)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
        set_limits()
    assert peak < 8 * n * n / 4, f"{peak / 2**20:.1f} MB"
    np.testing.assert_array_equal(low.mean("X"), free.mean("X"))
    np.testing.assert_array_equal(low.sd("X"), free.sd("X"))
    np.testing.assert_array_equal(low.ess, free.ess)


#: a step whose transition's noise switches with a discrete variable the engine sums out
SWITCHING = """\
bayesprog: 1
variables:
  X_before: {continuous: [-.inf, .inf]}
  X: {continuous: [-.inf, .inf]}
  S: {states: [calm, jump]}
  Y: {continuous: [-.inf, .inf]}
time:
  previous: {X_before: X}
decomposition:
  - {term: P(X_before), form: normal, mean: 0.0, sigma: 1.0}
  - {term: P(S), form: table, table: [0.8, 0.2]}
  - {term: "P(X | X_before, S)", form: normal, mean: "0.9*X_before + 0.5",
     sigma: {calm: 0.3, jump: 1.0}}
  - {term: P(Y | X), form: normal, mean: "2*X", sigma: 0.5}
"""


@pytest.mark.parametrize("text", [BEND, SWITCHING], ids=["bend", "switching"])
@pytest.mark.parametrize("pairs", [1, 7 * 300, 300 * 300])
def test_the_particle_smoothers_blocks_do_not_change_its_answer(monkeypatch, text, pairs):
    """One particle after per block, seven (the last block short: 300 = 42 * 7 + 6), or all of
    them at once: the same answer, bit for bit, on two sequences of a non-linear step and of a
    step with a variable summed out."""
    program = bayesprog.loads(text)
    evidence = {"Y": np.array([YS, YS[::-1]]).T}
    usual = program.ask("P(X | Y)", evidence, kind="smooth", method="pf", samples=300, rng=2)
    monkeypatch.setattr(dynamic, "PAIRS_PER_BLOCK", pairs)
    blocked = program.ask("P(X | Y)", evidence, kind="smooth", method="pf", samples=300, rng=2)
    np.testing.assert_array_equal(blocked.mean("X"), usual.mean("X"))
    np.testing.assert_array_equal(blocked.sd("X"), usual.sd("X"))
    np.testing.assert_array_equal(blocked.ess, usual.ess)


def test_particles_past_the_limit_are_refused_with_their_cost(tmp_path, capsys):
    """Refused before anything is drawn, with the entries they need: at least every step's
    particles and weights, kept for the backward pass; a million particles past the default
    limit (800 MB), on the command line too (status 2, no traceback)."""
    program = bayesprog.loads(CART)
    ys = [1.0, 2.1, 2.9, 1.7]
    try:
        set_limits(entries=1_000_000)
        with pytest.raises(SizeError) as refused:
            program.ask("P(X | Y)", {"Y": ys}, kind="smooth", method="pf", samples=20_000)
    finally:
        set_limits()
    message = str(refused.value)
    found = re.fullmatch(r"a particle smoother of 20,000 particles x 1 sequence x 4 steps "
                         r"needs ([\d,]+) entries, more than the limit of 1,000,000 \(raise it "
                         r"with the environment variable BAYESPROG_MAX_ENTRIES\); or ask fewer "
                         r"particles \(samples=\.\.\. in Python, --samples on the command "
                         r"line\), or fewer sequences or steps at once",
                         message)
    assert found, message
    assert int(found[1].replace(",", "")) >= 20_000 * 4 * 2
    with pytest.raises(SizeError, match="a particle filter of 1,000,000 particles x 3 sequences"):
        program.ask("P(X | Y)", {"Y": np.tile(ys, (3, 1)).T}, kind="filter", method="pf",
                    samples=1_000_000)
    (tmp_path / "cart.yaml").write_text(CART)
    assert main(["query", str(tmp_path / "cart.yaml"), "P(X | Y)", "--over-time", "smooth",
                 "--method", "pf", "--samples", "1000000", "--evidence", "Y=1.0,2.1"]) == 2
    err = capsys.readouterr().err
    assert "a particle smoother of 1,000,000 particles x 1 sequence x 2 steps needs" in err
    assert "Traceback" not in err
