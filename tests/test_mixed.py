"""Questions that search discrete and real variables together: the joint as per-state weights
and conditional densities, and its MAP, against the closed form and a brute-force grid."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.stats

import bayesprog
from bayesprog.cli import main

MIX = """\
bayesprog: 1
variables:
  C: {states: [a, b]}
  X: {continuous: [-.inf, .inf]}
  Y: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(C), form: table, table: [0.3, 0.7]}
  - {term: P(X | C), form: normal, mean: {a: 0.0, b: 2.0}, sigma: {a: 1.0, b: 0.5}}
  - {term: P(Y | X), form: normal, mean: "X", sigma: 0.8}
"""

PI, MU, S, R = np.array([0.3, 0.7]), np.array([0.0, 2.0]), np.array([1.0, 0.5]), 0.8


def _closed(y: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    w = PI * scipy.stats.norm.pdf(y, MU, np.sqrt(S**2 + R**2))
    precision = 1 / S**2 + 1 / R**2
    return w / w.sum(), (MU / S**2 + y / R**2) / precision, np.sqrt(1 / precision)


def test_the_joint_equals_the_closed_form_for_a_batch():
    program = bayesprog.loads(MIX)
    ys = np.array([1.5, -1.0, 2.6])
    joint = program.ask("P(C X | Y)", {"Y": ys})
    assert joint.batch_shape == (3,)
    for k, y in enumerate(ys):
        w, m, sd = _closed(y)
        np.testing.assert_allclose(joint.weights[k], w, atol=1e-12)
        np.testing.assert_allclose(joint.mean("X")[k], m, atol=1e-12)
        np.testing.assert_allclose(joint.sd("X")[k], sd, atol=1e-12)
        # the MAP: within each state the density peaks at its mean, w / sqrt(2 pi var)
        peaks = w / np.sqrt(2 * np.pi * sd**2)
        best = int(np.argmax(peaks))
        found = joint.map()
        assert found["C"][k] == "ab"[best]
        assert found["X"][k] == pytest.approx(m[best], abs=1e-12)
        assert found["density"][k] == pytest.approx(peaks[best], rel=1e-12)
        # and a brute-force search of the joint density on a fine grid agrees
        x = np.linspace(-4, 5, 90001)
        like = scipy.stats.norm.pdf(y, x, R)
        dens = np.stack([PI[c] * scipy.stats.norm.pdf(x, MU[c], S[c]) * like for c in (0, 1)])
        c, i = np.unravel_index(np.argmax(dens), dens.shape)
        assert c == best and x[i] == pytest.approx(m[best], abs=1e-3)


def test_two_real_variables_jointly_given_each_state():
    program = bayesprog.loads(MIX.replace(
        "  Y: {continuous: [-.inf, .inf]}", "  Z: {continuous: [-.inf, .inf]}\n"
        "  Y: {continuous: [-.inf, .inf]}").replace(
        '  - {term: P(Y | X), form: normal, mean: "X", sigma: 0.8}',
        '  - {term: P(Z | X), form: normal, mean: "0.5*X + 1", sigma: 0.3}\n'
        '  - {term: P(Y | Z), form: normal, mean: "Z", sigma: 0.8}'))
    joint = program.ask("P(X C Z | Y=1.2)")
    assert joint.discrete == ("C",) and joint.real == ("X", "Z")
    for c in (0, 1):
        # (X, Z, Y) given C: jointly Gaussian; condition on Y = 1.2 by hand
        mean = np.array([MU[c], 0.5 * MU[c] + 1, 0.5 * MU[c] + 1])
        vx = S[c] ** 2
        vz = 0.25 * vx + 0.09
        cov = np.array([[vx, 0.5 * vx, 0.5 * vx], [0.5 * vx, vz, vz], [0.5 * vx, vz, vz + 0.64]])
        gain = cov[:2, 2] / cov[2, 2]
        cond_mean = mean[:2] + gain * (1.2 - mean[2])
        cond_cov = cov[:2, :2] - np.outer(gain, cov[2, :2])
        np.testing.assert_allclose([joint.mean("X")[c], joint.mean("Z")[c]], cond_mean,
                                   atol=1e-12)
        np.testing.assert_allclose([joint.sd("X")[c], joint.sd("Z")[c]],
                                   np.sqrt(np.diag(cond_cov)), atol=1e-12)
    marginal = [PI[c] * scipy.stats.norm.pdf(1.2, 0.5 * MU[c] + 1,
                                             np.sqrt(0.25 * S[c]**2 + 0.09 + 0.64))
                for c in (0, 1)]
    np.testing.assert_allclose(joint.weights, np.array(marginal) / sum(marginal), atol=1e-12)


def test_the_command_line_prints_and_writes_the_joint(tmp_path, capsys):
    (tmp_path / "mix.yaml").write_text(MIX)
    assert main(["query", str(tmp_path / "mix.yaml"), "P(C X | Y=1.5)", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    w, m, _ = _closed(1.5)
    np.testing.assert_allclose(out["weights"], w, atol=1e-12)
    np.testing.assert_allclose(out["mean"]["X"], m, atol=1e-12)
    assert out["map"]["C"] == "b" and out["method"] == "mixed"
    assert main(["query", str(tmp_path / "mix.yaml"), "P(C X | Y=1.5)"]) == 0
    text = capsys.readouterr().out
    assert "discrete and real together" in text and "MAP: C=b" in text
