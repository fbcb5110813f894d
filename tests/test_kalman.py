"""Programs over time with real states: a linear-Gaussian step is filtered (Kalman) and smoothed
(Rauch-Tung-Striebel) exactly, one or several real states jointly, checked against the
recursions written by hand and the joint Gaussian of all the observations."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.stats

import bayesprog
from bayesprog.cli import main

CART = """\
bayesprog: 1
name: cart
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
questions:
  track: {ask: P(X | Y), kind: filter}
"""

#: position and velocity, observed with noise on the position
MOVING = """\
bayesprog: 1
name: moving
variables:
  P_before: {continuous: [-.inf, .inf]}
  V_before: {continuous: [-.inf, .inf]}
  P: {continuous: [-.inf, .inf]}
  V: {continuous: [-.inf, .inf]}
  Z: {continuous: [-.inf, .inf]}
time:
  previous: {P_before: P, V_before: V}
decomposition:
  - {term: P(P_before), form: normal, mean: 0.0, sigma: 2.0}
  - {term: P(V_before | P_before), form: normal, mean: "0.25*P_before + 1", sigma: 0.5}
  - {term: P(V | V_before), form: normal, mean: "0.95*V_before", sigma: 0.2}
  - {term: "P(P | P_before, V)", form: normal, mean: "P_before + V", sigma: 0.1}
  - {term: P(Z | P), form: normal, mean: "P", sigma: 0.7}
"""


def _kalman(a, b, q, h, d, r, m0, p0, ys):
    """The textbook filter and RTS smoother: x' = a x + b + N(0, q), y = h x + d + N(0, r)."""
    m, p = m0, p0
    fm, fp, pm, pp = [], [], [], []
    for y in ys:
        mp, ppred = a @ m + b, a @ p @ a.T + q
        s = h @ ppred @ h.T + r
        k = ppred @ h.T @ np.linalg.inv(s)
        m, p = mp + k @ (y - h @ mp - d), (np.eye(len(m)) - k @ h) @ ppred
        fm.append(m), fp.append(p), pm.append(mp), pp.append(ppred)
    sm, sp = [fm[-1]], [fp[-1]]
    for t in range(len(ys) - 2, -1, -1):
        j = fp[t] @ a.T @ np.linalg.inv(pp[t + 1])
        sm.insert(0, fm[t] + j @ (sm[0] - pm[t + 1]))
        sp.insert(0, fp[t] + j @ (sp[0] - pp[t + 1]) @ j.T)
    return np.array(fm), np.array(fp), np.array(sm), np.array(sp)


def test_one_real_state_equals_the_recursions_for_a_batch_of_sequences():
    program = bayesprog.loads(CART)
    ys = np.array([[1.0, 0.2], [2.1, 0.1], [2.9, -0.4], [3.3, 0.0]])  # time, batch
    filtered = program.ask("track", {"Y": ys})
    smoothed = program.ask("P(X | Y)", {"Y": ys}, kind="smooth")
    assert filtered.batch_shape == (4, 2) and filtered.method == "kalman"
    for k in range(2):
        fm, fp, sm, sp = _kalman(np.array([[0.9]]), np.array([0.5]), np.array([[0.09]]),
                                 np.array([[2.0]]), np.zeros(1), np.array([[0.25]]),
                                 np.zeros(1), np.eye(1), ys[:, k, None])
        np.testing.assert_allclose(filtered.mean("X")[:, k], fm[:, 0], atol=1e-12)
        np.testing.assert_allclose(filtered.sd("X")[:, k], np.sqrt(fp[:, 0, 0]), atol=1e-12)
        np.testing.assert_allclose(smoothed.mean("X")[:, k], sm[:, 0], atol=1e-12)
        np.testing.assert_allclose(smoothed.sd("X")[:, k], np.sqrt(sp[:, 0, 0]), atol=1e-12)


def _joint_of_observations(steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of (y_1..y_T) of CART, built from the unrolled linear model."""
    # x_t = 0.9^t x_0 + sum 0.9^(t-s) (0.5 + e_s); y_t = 2 x_t + v_t
    mean_x, cov_x = np.zeros(steps), np.zeros((steps, steps))
    for t in range(1, steps + 1):
        mean_x[t - 1] = sum(0.9 ** (t - s) * 0.5 for s in range(1, t + 1))
        for u in range(1, steps + 1):
            cov_x[t - 1, u - 1] = 0.9 ** (t + u) * 1.0 + sum(
                0.9 ** (t - s) * 0.9 ** (u - s) * 0.09 for s in range(1, min(t, u) + 1))
    return 2 * mean_x, 4 * cov_x + 0.25 * np.eye(steps)


def test_the_evidence_of_the_steps_is_the_joint_gaussian_of_the_observations():
    program = bayesprog.loads(CART)
    ys = np.array([1.0, 2.1, 2.9, 3.3, 2.5])
    answer = program.ask("track", {"Y": ys})
    mean, cov = _joint_of_observations(len(ys))
    expected = scipy.stats.multivariate_normal(mean, cov).logpdf(ys)
    assert answer.log_evidence.sum() == pytest.approx(expected, abs=1e-10)


def test_several_real_states_jointly_with_their_covariance():
    program = bayesprog.loads(MOVING)
    zs = np.array([1.2, 2.0, 3.5, 4.1, 5.6, 6.0])
    filtered = program.ask("P(P V | Z)", {"Z": zs}, kind="filter")
    smoothed = program.ask("P(V P | Z)", {"Z": zs}, kind="smooth")
    # the state x = (P, V): V' = 0.95 V + N(0, .04); P' = P + V' + N(0, .01)
    a = np.array([[1.0, 0.95], [0.0, 0.95]])
    q = np.array([[0.04 + 0.01, 0.04], [0.04, 0.04]])
    b = np.zeros(2)
    h, d, r = np.array([[1.0, 0.0]]), np.zeros(1), np.array([[0.49]])
    m0 = np.array([0.0, 1.0])
    p0 = np.array([[4.0, 1.0], [1.0, 0.25 + 0.25]])  # V = 0.25 P + 1 + N(0, .25)
    fm, fp, sm, sp = _kalman(a, b, q, h, d, r, m0, p0, zs[:, None])
    np.testing.assert_allclose(filtered.means[:, 0], fm, atol=1e-10)
    np.testing.assert_allclose(filtered.covariances[:, 0], fp, atol=1e-10)
    np.testing.assert_allclose(smoothed.means[:, 0], sm[:, ::-1], atol=1e-10)
    np.testing.assert_allclose(smoothed.covariances[:, 0], sp[:, ::-1, ::-1], atol=1e-10)


def test_the_json_gives_per_step_means_and_sds(tmp_path, capsys):
    (tmp_path / "cart.yaml").write_text(CART)
    assert main(["query", str(tmp_path / "cart.yaml"), "P(X | Y)", "--over-time", "smooth",
                 "--evidence", "Y=1.0,2.1,2.9", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["mean"]["X"]) == 3 and len(out["sd"]["X"]) == 3
    assert out["method"] == "kalman-rts"
    assert out["mean"]["X"][-1] == pytest.approx(1.438938436932419, abs=1e-12)
    assert out["density"] == "gaussian"  # one Gaussian per step, not a mixture
    assert main(["query", str(tmp_path / "cart.yaml"), "P(X | Y)", "--over-time", "filter",
                 "--evidence", "Y=1.0,2.1,2.9", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["density"] == "gaussian"


def test_a_density_says_how_it_is_held():
    """``kind`` (``density`` in --json): one Gaussian, a mixture over a discrete variable
    summed out, or bins."""
    mixed = bayesprog.loads("""\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  X: {continuous: [-.inf, .inf]}
  Y: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(A), form: table, table: [0.3, 0.7]}
  - {term: P(X | A), form: normal, mean: {a0: -1, a1: 1}, sigma: 1}
  - {term: P(Y | X), form: normal, mean: X, sigma: 0.5}
""")
    assert mixed.density("P(X | Y)", {"Y": 0.2}).to_json()["density"] == "gaussian mixture"
    assert mixed.density("P(X | Y, A)", {"Y": 0.2, "A": "a0"}).kind == "gaussian"
    bounded = bayesprog.loads("""\
bayesprog: 1
variables:
  X: {continuous: [-5, 5]}
  Y: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(X), form: normal, mean: 0, sigma: 1}
  - {term: P(Y | X), form: normal, mean: X, sigma: 0.5}
""")
    assert bounded.density("P(X | Y)", {"Y": 1.0}, method="grid").kind == "bins"
    cart = bayesprog.loads(CART)
    assert cart.ask("track", {"Y": [1.0, 2.0]}).kind == "gaussian"


@pytest.mark.parametrize("change, said", [
    ('mean: "0.9*X_before + 0.5"', 'mean: "sin(X_before)"'),
    ("kind: filter", "kind: sequence"),
])
def test_what_the_kalman_filter_cannot_answer_is_said(change, said):
    program = bayesprog.loads(CART.replace(change, said))
    with pytest.raises(bayesprog.QuestionError) as info:
        program.ask("track", {"Y": [1.0, 2.0]})
    assert ("linear-Gaussian" in str(info.value)) or ("smoothed means" in str(info.value))


def test_a_real_and_a_discrete_state_together_are_refused_at_the_time_section():
    text = MOVING.replace("V_before: {continuous: [-.inf, .inf]}",
                          "V_before: {states: [slow, fast]}")
    with pytest.raises(bayesprog.SpecError, match="one kind"):
        bayesprog.loads(text)
