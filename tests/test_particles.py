"""A particle filter for steps that are not linear-Gaussian (``method="pf"``): seeded, with the
effective sample size of each step, checked against a filter on a fine grid."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.stats

import bayesprog
from bayesprog.cli import main

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
    with pytest.raises(bayesprog.QuestionError, match="filter questions"):
        program.ask("P(X | Y)", {"Y": YS}, kind="smooth", method="pf")
