"""Conditioning-only variables: a variable the decomposition gives no term (a control, a known
input) makes the program a conditional one, ``P(X Y | U)``. Every question gives it, and it adds
nothing to the evidence's probability. The answers are checked against sums written here with
numpy, densities from scipy.stats, and the recursions of a corridor filter and a Kalman filter
written by hand."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pandas as pd
import pytest
import scipy.stats

import bayesprog
from bayesprog.cli import main
from bayesprog.errors import QuestionError, SpecError
from bayesprog.learning.data import DataError
from bayesprog.views.show import render
from bayesprog.vocabulary.expressions import parse_expression

#: P(X) and P(Y | X, U), drawn once: [x], [x, u, y]
_RNG = np.random.default_rng(20240611)
PX = _RNG.dirichlet([2.0, 2.0])
PY = _RNG.dirichlet([1.0, 1.0], size=(2, 3))
X_STATES, U_STATES, Y_STATES = ["x0", "x1"], ["u0", "u1", "u2"], ["y0", "y1"]

COMMANDED = f"""\
bayesprog: 1
name: commanded
variables:
  X: {{states: [x0, x1]}}
  U: {{states: [u0, u1, u2]}}
  Y: {{states: [y0, y1]}}
decomposition:
  - {{term: P(X), form: table, table: {json.dumps(PX.tolist())}}}
  - term: P(Y | X, U)
    form: table
    table: {json.dumps(PY.tolist())}
"""


def _hand(y: int, u: int) -> tuple[np.ndarray, float]:
    """P(X | Y=y, U=u) and log P(Y=y | U=u), by the sum over X."""
    joint = PX * PY[:, u, y]
    return joint / joint.sum(), float(np.log(joint.sum()))


@pytest.fixture(scope="module")
def commanded() -> bayesprog.Program:
    return bayesprog.loads(COMMANDED)


# answers -------------------------------------------------------------------------------------
# (loopy belief propagation is exact on this tree)
@pytest.mark.parametrize("method", [None, "table", "contraction", "lbp"])
def test_the_posterior_and_log_evidence_are_given_the_command_without_a_prior(commanded, method):
    pairs = list(itertools.product(range(2), range(3)))
    evidence = {"Y": [Y_STATES[y] for y, _ in pairs], "U": [U_STATES[u] for _, u in pairs]}
    for _ in range(2):  # the second time by the method the layout settled on
        answer = commanded.ask("P(X | Y, U)", evidence, method=method)
        for row, (y, u) in enumerate(pairs):
            posterior, log_evidence = _hand(y, u)
            np.testing.assert_allclose(answer.probabilities[row], posterior, rtol=0, atol=1e-12)
            assert abs(answer.log_evidence[row] - log_evidence) < 1e-12


def test_a_question_written_with_its_values_asked_once_and_again(commanded):
    posterior, log_evidence = _hand(1, 2)
    for _ in range(3):  # the first question's path, the full path, the warm path
        answer = commanded.ask("P(X | Y=y1, U=u2)")
        np.testing.assert_allclose(answer.probabilities, posterior, rtol=0, atol=1e-12)
        assert abs(float(answer.log_evidence) - log_evidence) < 1e-12
        answer = commanded.ask("P(X | Y, U)", {"Y": "y1", "U": "u2"})
        np.testing.assert_allclose(answer.probabilities, posterior, rtol=0, atol=1e-12)
        assert abs(float(answer.log_evidence) - log_evidence) < 1e-12


def test_several_commands_at_once_broadcast_with_the_evidence(commanded):
    commands = np.array([["u0", "u1", "u2"], ["u2", "u2", "u0"]])
    answer = commanded.ask("P(X | Y, U)", {"Y": "y0", "U": commands})
    assert answer.probabilities.shape == (2, 3, 2)
    for i, j in np.ndindex(2, 3):
        posterior, log_evidence = _hand(0, U_STATES.index(commands[i, j]))
        np.testing.assert_allclose(answer.probabilities[i, j], posterior, rtol=0, atol=1e-12)
        assert abs(answer.log_evidence[i, j] - log_evidence) < 1e-12


def test_a_prior_on_the_command_would_add_its_log_probability(commanded):
    """The program with a uniform P(U) answers the same posterior, and its log-evidence is
    lower by log 3 in every row: the offset the conditional program does not have."""
    with_prior = bayesprog.loads(COMMANDED.replace(
        "decomposition:\n", "decomposition:\n  - {term: P(U), form: uniform}\n"))
    evidence = {"Y": ["y0", "y1", "y1"], "U": ["u0", "u1", "u2"]}
    conditional = commanded.ask("P(X | Y, U)", evidence)
    joint = with_prior.ask("P(X | Y, U)", evidence)
    np.testing.assert_allclose(conditional.probabilities, joint.probabilities, atol=1e-12)
    np.testing.assert_allclose(joint.log_evidence - conditional.log_evidence,
                               np.full(3, np.log(1 / 3)), rtol=0, atol=1e-12)
    assert with_prior.conditioning == () and commanded.conditioning == ("U",)


def test_what_the_command_alone_says(commanded):
    # nothing but the command known: the prior of X, and the probability of no evidence, 1
    answer = commanded.ask("P(X | U=u1)")
    np.testing.assert_allclose(answer.probabilities, PX, rtol=0, atol=1e-12)
    assert float(answer.log_evidence) == 0.0
    # the probability of an event given the command
    event = commanded.probability("P(Y=y0 | U)", {"U": ["u0", "u1", "u2"]})
    np.testing.assert_allclose(event.probability, PX @ PY[:, :, 0], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(event.log_evidence, np.zeros(3))


def test_evidence_the_answer_does_not_need_still_counts_in_the_log_evidence():
    """A reading Z of the command alone is screened off from X by U: the posterior is
    answered without its term, and its probability is still in the log-evidence."""
    pz = np.array([[0.6, 0.4], [0.25, 0.75], [0.1, 0.9]])  # [u, z]
    program = bayesprog.loads(COMMANDED.replace("  Y: {states: [y0, y1]}\n",
                                                "  Y: {states: [y0, y1]}\n  Z: {range: [0, 1]}\n")
                              + f"  - {{term: P(Z | U), form: table, table: {pz.tolist()}}}\n")
    answer = program.ask("P(X | Y, U, Z)", {"Y": ["y0", "y1", "y1"], "U": ["u0", "u2", "u1"],
                                            "Z": [1, 0, 1]})
    for row, (y, u, z) in enumerate([(0, 0, 1), (1, 2, 0), (1, 1, 1)]):
        posterior, log_evidence = _hand(y, u)
        np.testing.assert_allclose(answer.probabilities[row], posterior, rtol=0, atol=1e-12)
        assert abs(answer.log_evidence[row] - (log_evidence + np.log(pz[u, z]))) < 1e-12


@pytest.mark.parametrize("method", ["lw", "gibbs"])
def test_the_sampling_methods_given_the_command(commanded, method):
    """Each probability within 5 of its standard errors of the sum by hand (seeded: a false
    failure below one in a million per number for a normal error)."""
    answer = commanded.ask("P(X | Y, U)", {"Y": ["y0", "y1", "y1"], "U": ["u1", "u2", "u0"]},
                           method=method, samples=20_000, rng=2)
    for row, (y, u) in enumerate([(0, 1), (1, 2), (1, 0)]):
        posterior, _ = _hand(y, u)
        assert np.all(np.abs(answer.probabilities[row] - posterior)
                      < 5 * answer.stderr[row]), (row, answer.probabilities[row], posterior)


def test_all_marginals_in_one_pass_given_the_command(commanded):
    found = commanded.marginals({"Y": ["y0", "y1"], "U": ["u2", "u0"]})
    assert list(found) == ["X"]
    for row, (y, u) in enumerate([(0, 2), (1, 0)]):
        posterior, log_evidence = _hand(y, u)
        np.testing.assert_allclose(found["X"].probabilities[row], posterior, atol=1e-12)
        assert abs(found["X"].log_evidence[row] - log_evidence) < 1e-12


#: X ~ N(1, 2^2), Y | X, U ~ N(X + U, 0.5^2), with no term for the real command U
STEERED = """\
bayesprog: 1
name: steered
variables:
  X: {continuous: [-.inf, .inf]}
  U: {continuous: [-.inf, .inf]}
  Y: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(X), form: normal, mean: 1.0, sigma: 2.0}
  - {term: "P(Y | X, U)", form: normal, mean: "X + U", sigma: 0.5}
"""


@pytest.mark.parametrize("method", [None, "gaussian"])
def test_a_real_command_in_a_linear_gaussian_program(method):
    program = bayesprog.loads(STEERED)
    y, u = np.array([1.0, 2.0, -0.5]), np.array([0.5, -1.0, 3.0])
    answer = program.ask("P(X | Y, U)", {"Y": y, "U": u}, method=method)
    assert answer.method == "gaussian"
    precision = 1 / 2.0**2 + 1 / 0.5**2
    mean = (1.0 / 2.0**2 + (y - u) / 0.5**2) / precision
    np.testing.assert_allclose(answer.mean("X"), mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.sd("X"), np.full(3, precision**-0.5), rtol=0, atol=1e-12)
    evidence = scipy.stats.norm.logpdf(y, 1.0 + u, np.hypot(2.0, 0.5))
    np.testing.assert_allclose(answer.log_evidence, evidence, rtol=0, atol=1e-12)
    # the density of Y at a point, given the command
    event = program.probability("P(Y=1.5 | U=0.25)")
    assert event.density
    density = scipy.stats.norm.logpdf(1.5, 1.25, np.hypot(2.0, 0.5))
    assert abs(float(event.log_probability) - density) < 1e-12


#: a discrete cause C, and a real reading Y whose mean is a formula of the real command U
READ = """\
bayesprog: 1
name: read
variables:
  C: {states: [a, b]}
  U: {continuous: [-.inf, .inf]}
  Y: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(C), form: table, table: [0.3, 0.7]}
  - {term: "P(Y | C, U)", form: normal, mean: {a: "U", b: "2*U + 1"}, sigma: 0.5}
"""


@pytest.mark.parametrize("method", [None, "contraction"])
def test_a_real_command_read_pointwise_by_the_exact_discrete_methods(method):
    program = bayesprog.loads(READ)
    y, u = np.array([1.0, 2.0, 0.2]), np.array([0.5, 0.8, -1.0])
    answer = program.ask("P(C | Y, U)", {"Y": y, "U": u}, method=method)
    likelihood = np.stack([scipy.stats.norm.pdf(y, u, 0.5),
                           scipy.stats.norm.pdf(y, 2 * u + 1, 0.5)], axis=-1)
    joint = np.array([0.3, 0.7]) * likelihood
    np.testing.assert_allclose(answer.probabilities, joint / joint.sum(-1, keepdims=True),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, np.log(joint.sum(-1)), rtol=0, atol=1e-12)


# programs over time -----------------------------------------------------------------------------
#: a corridor of five cells; the command moves one cell (0.8) or leaves the robot where it is;
#: a door sensor reads the cell
CELLS = 5
MOVE = np.zeros((CELLS, 3, CELLS))  # [before, command, after]
for _cell, (_u, _step) in itertools.product(range(CELLS), enumerate([-1, 0, 1])):
    MOVE[_cell, _u, min(max(_cell + _step, 0), CELLS - 1)] += 0.8
    MOVE[_cell, _u, _cell] += 0.2
SEES = np.array([[0.9, 0.1], [0.1, 0.9], [0.2, 0.8], [0.85, 0.15], [0.1, 0.9]])  # [cell, D]
START = np.array([0.4, 0.3, 0.1, 0.1, 0.1])
COMMANDS, DOORS = ["left", "stay", "right"], ["door", "wall"]

CORRIDOR = f"""\
bayesprog: 1
name: corridor
variables:
  X_before: {{range: [0, {CELLS - 1}]}}
  X: {{range: [0, {CELLS - 1}]}}
  U: {{states: [left, stay, right]}}
  D: {{states: [door, wall]}}
time:
  previous: {{X_before: X}}
decomposition:
  - {{term: P(X_before), form: table, table: {json.dumps(START.tolist())}}}
  - term: P(X | X_before, U)
    form: table
    table: {json.dumps(MOVE.tolist())}
  - term: P(D | X)
    form: table
    table: {json.dumps(SEES.tolist())}
questions:
  where: {{ask: "P(X | D, U)", kind: filter}}
"""


def _corridor_by_hand(u: list[str], d: list[str]):
    """The forward recursion (filtered beliefs, log P(d_t | d_<t, u_1..t)), the smoothed
    beliefs by the backward recursion, and the most likely sequence by enumeration."""
    ui, di = [COMMANDS.index(c) for c in u], [DOORS.index(s) for s in d]
    belief, filtered, logs = START, [], []
    for c, s in zip(ui, di, strict=True):
        joint = (belief @ MOVE[:, c, :]) * SEES[:, s]
        logs.append(np.log(joint.sum()))
        belief = joint / joint.sum()
        filtered.append(belief)
    backward, smoothed = np.ones(CELLS), [filtered[-1]]
    for t in range(len(u) - 1, 0, -1):
        backward = MOVE[:, ui[t], :] @ (SEES[:, di[t]] * backward)
        both = filtered[t - 1] * backward
        smoothed.append(both / both.sum())
    scores = {}
    for path in itertools.product(range(CELLS), repeat=len(u)):
        p = START @ MOVE[:, ui[0], path[0]] * SEES[path[0], di[0]]
        for t in range(1, len(u)):
            p *= MOVE[path[t - 1], ui[t], path[t]] * SEES[path[t], di[t]]
        scores[path] = p
    best = max(scores, key=scores.__getitem__)
    return (np.array(filtered), np.array(logs), np.array(smoothed[::-1]), list(best),
            scores[best] / sum(scores.values()))


U_STEPS = ["right", "right", "stay", "left", "right"]
D_STEPS = ["door", "wall", "door", "wall", "wall"]


def test_a_corridor_filter_given_the_command_at_every_step():
    program = bayesprog.loads(CORRIDOR)
    assert program.conditioning == ("U",)
    filtered, logs, smoothed, best, probability = _corridor_by_hand(U_STEPS, D_STEPS)
    answer = program.ask("where", {"U": U_STEPS, "D": D_STEPS})
    np.testing.assert_allclose(answer.probabilities, filtered, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, logs, rtol=0, atol=1e-12)
    back = program.ask("P(X | D, U)", {"U": U_STEPS, "D": D_STEPS}, kind="smooth")
    np.testing.assert_allclose(back.probabilities, smoothed, rtol=0, atol=1e-12)
    sequence = program.ask("P(X | D, U)", {"U": U_STEPS, "D": D_STEPS}, kind="sequence")
    assert sequence.assignment["X"].tolist() == best
    assert abs(float(sequence.probability) - probability) < 1e-12


def test_a_batch_of_corridor_runs_each_with_its_commands():
    program = bayesprog.loads(CORRIDOR)
    other_u = ["left", "stay", "stay", "right", "right"]
    other_d = ["wall", "wall", "door", "door", "wall"]
    answer = program.ask("where", {"U": np.array([U_STEPS, other_u]).T,
                                   "D": np.array([D_STEPS, other_d]).T})
    assert answer.probabilities.shape == (5, 2, CELLS)
    for run, (u, d) in enumerate([(U_STEPS, D_STEPS), (other_u, other_d)]):
        filtered, logs, *_ = _corridor_by_hand(u, d)
        np.testing.assert_allclose(answer.probabilities[:, run], filtered, rtol=0, atol=1e-12)
        np.testing.assert_allclose(answer.log_evidence[:, run], logs, rtol=0, atol=1e-12)


def test_a_prior_on_the_command_would_offset_every_step():
    """With a uniform P(U) every step's log-evidence is lower by log 3."""
    program = bayesprog.loads(CORRIDOR)
    with_prior = bayesprog.loads(CORRIDOR.replace(
        "decomposition:\n", "decomposition:\n  - {term: P(U), form: uniform}\n"))
    ours = program.ask("where", {"U": U_STEPS, "D": D_STEPS})
    theirs = with_prior.ask("where", {"U": U_STEPS, "D": D_STEPS})
    np.testing.assert_allclose(theirs.probabilities, ours.probabilities, atol=1e-12)
    np.testing.assert_allclose(theirs.log_evidence - ours.log_evidence,
                               np.full(5, np.log(1 / 3)), rtol=0, atol=1e-12)


MACHINE = """\
bayesprog: 1
name: machine
variables:
  Wear_before: {states: [new, worn]}
  Load_before: {states: [light, heavy]}
  Wear: {states: [new, worn]}
  Load: {states: [light, heavy]}
  U: {states: [rest, work]}
  Noise: {states: [quiet, loud]}
time:
  previous: {Wear_before: Wear, Load_before: Load}
decomposition:
  - {term: P(Wear_before), form: table, table: [0.9, 0.1]}
  - {term: P(Load_before), form: table, table: [0.5, 0.5]}
  - term: "P(Load | Load_before, U)"
    form: table
    table: {light: {rest: [0.9, 0.1], work: [0.3, 0.7]},
            heavy: {rest: [0.6, 0.4], work: [0.1, 0.9]}}
  - term: P(Wear | Wear_before, Load)
    form: table
    table: {new: {light: [0.95, 0.05], heavy: [0.7, 0.3]}, worn: {light: [0, 1], heavy: [0, 1]}}
  - term: P(Noise | Wear, Load)
    form: table
    table: {new: {light: [0.9, 0.1], heavy: [0.6, 0.4]},
            worn: {light: [0.3, 0.7], heavy: [0.1, 0.9]}}
"""


def test_a_filter_over_two_states_given_the_command_at_every_step():
    program = bayesprog.loads(MACHINE)
    commands, noise = ["work", "rest", "work", "work"], ["quiet", "loud", "loud", "quiet"]
    answer = program.ask("P(Wear Load | Noise, U)", {"Noise": noise, "U": commands},
                         kind="filter")
    load = {"rest": np.array([[0.9, 0.1], [0.6, 0.4]]),
            "work": np.array([[0.3, 0.7], [0.1, 0.9]])}  # [before, after]
    wear = np.array([[[0.95, 0.05], [0.7, 0.3]], [[0, 1], [0, 1]]])  # [before, load, after]
    sound = np.array([[[0.9, 0.1], [0.6, 0.4]], [[0.3, 0.7], [0.1, 0.9]]])  # [wear, load, noise]
    belief = np.outer([0.9, 0.1], [0.5, 0.5])  # [wear, load]
    for t, (u, n) in enumerate(zip(commands, noise, strict=True)):
        joint = np.einsum("ab,bl,alw,wl->wl", belief, load[u], wear,
                          sound[:, :, ["quiet", "loud"].index(n)])
        belief = joint / joint.sum()
        np.testing.assert_allclose(answer.probabilities[t], belief, rtol=0, atol=1e-12)
        assert abs(answer.log_evidence[t] - np.log(joint.sum())) < 1e-12


#: a cart driven by a real command: X_t = 0.9 X_t-1 + U_t + N(0, 0.3^2), Y_t = 2 X_t + N(0, 0.5^2)
DRIVEN = """\
bayesprog: 1
name: driven
variables:
  X_before: {continuous: [-.inf, .inf]}
  X: {continuous: [-.inf, .inf]}
  U: {continuous: [-.inf, .inf]}
  Y: {continuous: [-.inf, .inf]}
time:
  previous: {X_before: X}
decomposition:
  - {term: P(X_before), form: normal, mean: 0.0, sigma: 1.0}
  - {term: "P(X | X_before, U)", form: normal, mean: "0.9*X_before + U", sigma: 0.3}
  - {term: P(Y | X), form: normal, mean: "2*X", sigma: 0.5}
"""


def _driven_by_hand(ys, us, a=0.9, q=0.3**2, h=2.0, r=0.5**2):
    """The scalar Kalman filter and Rauch-Tung-Striebel smoother with the command as the
    transition's offset: filtered and smoothed means and variances, log p(y_t | y_<t)."""
    m, p = 0.0, 1.0
    fm, fp, pm, pp, logs = [], [], [], [], []
    for y, u in zip(ys, us, strict=True):
        m_pred, p_pred = a * m + u, a * a * p + q
        s = h * h * p_pred + r
        logs.append(scipy.stats.norm.logpdf(y, h * m_pred, np.sqrt(s)))
        gain = p_pred * h / s
        m, p = m_pred + gain * (y - h * m_pred), (1 - gain * h) * p_pred
        fm.append(m), fp.append(p), pm.append(m_pred), pp.append(p_pred)
    sm, sp = [fm[-1]], [fp[-1]]
    for t in range(len(ys) - 2, -1, -1):
        j = fp[t] * a / pp[t + 1]
        sm.append(fm[t] + j * (sm[-1] - pm[t + 1]))
        sp.append(fp[t] + j * j * (sp[-1] - pp[t + 1]))
    return (np.array(fm), np.array(fp), np.array(logs), np.array(sm[::-1]),
            np.array(sp[::-1]))


YS, US = [1.0, 2.1, 0.3, 0.8], [0.5, -0.2, 0.1, 0.4]


def test_a_kalman_filter_and_smoother_given_a_real_command_at_every_step():
    program = bayesprog.loads(DRIVEN)
    fm, fp, logs, sm, sp = _driven_by_hand(YS, US)
    answer = program.ask("P(X | Y, U)", {"Y": YS, "U": US}, kind="filter")
    assert answer.method == "kalman"
    np.testing.assert_allclose(answer.mean("X"), fm, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.sd("X") ** 2, fp, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, logs, rtol=0, atol=1e-12)
    back = program.ask("P(X | Y, U)", {"Y": YS, "U": US}, kind="smooth")
    assert back.method == "kalman-rts"
    np.testing.assert_allclose(back.mean("X"), sm, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back.sd("X") ** 2, sp, rtol=0, atol=1e-12)
    # two runs at once, each with its commands; the observations shared
    other = [0.0, 0.0, 1.0, -1.0]
    both = program.ask("P(X | Y, U)", {"Y": YS, "U": np.array([US, other]).T}, kind="filter")
    for run, us in enumerate([US, other]):
        fm, _, logs, _, _ = _driven_by_hand(YS, us)
        np.testing.assert_allclose(both.mean("X")[:, run], fm, rtol=0, atol=1e-12)
        np.testing.assert_allclose(both.log_evidence[:, run], logs, rtol=0, atol=1e-12)


def test_a_kalman_filter_given_a_discrete_command():
    program = bayesprog.loads(DRIVEN.replace(
        "U: {continuous: [-.inf, .inf]}", "U: {states: [slow, fast]}").replace(
        'mean: "0.9*X_before + U"', 'mean: {slow: "0.9*X_before + 0.5", fast: "0.9*X_before + 2"}'))
    commands = ["fast", "slow", "slow", "fast"]
    fm, fp, logs, _, _ = _driven_by_hand(YS, [2.0 if c == "fast" else 0.5 for c in commands])
    answer = program.ask("P(X | Y, U)", {"Y": YS, "U": commands}, kind="filter")
    np.testing.assert_allclose(answer.mean("X"), fm, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.sd("X") ** 2, fp, rtol=0, atol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, logs, rtol=0, atol=1e-12)


def test_a_particle_filter_given_a_real_command_agrees_with_kalman():
    """Eight independent particle systems (a batch of the same sequence): each step's mean and
    log-evidence over the runs within 5 standard errors of the Kalman filter's (Student's t with 7
    degrees of freedom: a false failure about one in 600 per number, seeded)."""
    program = bayesprog.loads(DRIVEN)
    runs = 8
    answer = program.ask("P(X | Y, U)", {"Y": np.tile(YS, (runs, 1)).T,
                                         "U": np.tile(US, (runs, 1)).T},
                         kind="filter", method="pf", samples=2000, rng=11)
    assert answer.method == "pf"
    means = np.asarray(answer.mean("X"))
    error = means.std(axis=1, ddof=1) / np.sqrt(runs)
    fm, _, logs, _, _ = _driven_by_hand(YS, US)
    assert np.all(np.abs(means.mean(axis=1) - fm) < 5 * error), (means.mean(axis=1), fm, error)
    log_evidence = np.asarray(answer.log_evidence)
    log_error = log_evidence.std(axis=1, ddof=1) / np.sqrt(runs)
    assert np.all(np.abs(log_evidence.mean(axis=1) - logs) < 5 * log_error), (log_evidence, logs)


# refusals ---------------------------------------------------------------------------------------
QUOTE = '"'


def _at(text: str, line_has: str, token: str) -> str:
    """``LINE:COL`` of ``token`` on the first line of ``text`` that holds ``line_has``."""
    for number, line in enumerate(text.splitlines(), 1):
        if line_has in line:
            return f"{number}:{line.index(token) + 1}"
    raise AssertionError(line_has)


def test_questions_of_the_file_that_leave_the_command_unknown_are_refused_at_their_place(
        tmp_path, capsys):
    text = COMMANDED + ("questions:\n  fine: P(X | Y, U)\n  forgets: P(X | Y)\n"
                        '  searches: {ask: "P(U | Y=y0)"}\n  event: "P(U=u0, Y=y0)"\n')
    path = tmp_path / "commanded.yaml"
    path.write_text(text)
    with pytest.raises(SpecError) as caught:
        bayesprog.load(path)
    lines = str(caught.value).splitlines()
    assert len(lines) == 3, lines
    forgets, searches, event = lines
    assert forgets.startswith(f"{path}:{_at(text, 'forgets:', 'P(')}: question 'forgets': ")
    assert ("leaves U unknown, but U has no term in the decomposition" in forgets
            and forgets.endswith("expected P(X | Y, U)"))
    assert searches.startswith(f"{path}:{_at(text, 'searches:', QUOTE)}: question 'searches': ")
    assert "searches U, but U has no term" in searches
    assert event.startswith(f"{path}:{_at(text, 'event:', QUOTE)}: question 'event': ")
    assert event.endswith("expected P(Y=y0 | U=u0)")
    # the command line: every problem at once, exit 2, no traceback
    assert main(["validate", str(path)]) == 2
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    assert err.count("has no term in the decomposition") == 3


def test_questions_asked_without_the_command_are_refused(commanded):
    with pytest.raises(QuestionError, match=r"^P\(X \| Y=y0\) leaves U unknown, but U has no "
                       r"term in the decomposition .* expected P\(X \| Y=y0, U\)$"):
        commanded.ask("P(X | Y=y0)")
    with pytest.raises(QuestionError, match=r"searches U, but U has no term"):
        commanded.ask("P(U X | Y=y0)")
    with pytest.raises(QuestionError, match=r"expected P\(X \| U\)"):
        commanded.ask("P(X)", kind="map")
    with pytest.raises(QuestionError, match=r"expected P\(Y=y1 \| U=u0\)"):
        commanded.probability("P(U=u0, Y=y1)")
    question = bayesprog.Question(parse_expression("P(X | Y)"), "posterior")
    with pytest.raises(QuestionError, match="leaves U unknown"):
        commanded.ask(question, {"Y": "y0"})
    with pytest.raises(QuestionError, match="all marginals are asked given U, which has no "
                       "term"):
        commanded.marginals({"Y": "y0"})
    with pytest.raises(QuestionError, match="soft evidence on U: it has no term"):
        commanded.ask("P(X | Y, U)", {"Y": "y0", "U": "u0"}, soft={"U": [0.2, 0.3, 0.5]})
    with pytest.raises(QuestionError, match="leaves U unknown"):
        bayesprog.loads(CORRIDOR).ask("P(X | D)", {"D": ["door", "wall"]}, kind="filter")


def test_the_command_line_refuses_a_question_without_the_command(tmp_path, capsys):
    path = tmp_path / "commanded.yaml"
    path.write_text(COMMANDED)
    for args in (["query", path, "P(X | Y=y0)"], ["query", path, "--marginals"],
                 ["sample", path, "-n", "5", "-o", tmp_path / "draws.csv"],
                 ["export", path, "-o", tmp_path / "commanded.bif"]):
        assert main([str(a) for a in args]) == 2
        out, err = capsys.readouterr()
        assert out == "" and "Traceback" not in err
        assert err.startswith("bayesprog: ") and len(err.strip().splitlines()) == 1
        assert "U" in err and "no term" in err
    assert not (tmp_path / "draws.csv").exists() and not (tmp_path / "commanded.bif").exists()
    assert main(["query", str(path), "P(X | Y=y0, U=u1)", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    posterior, log_evidence = _hand(0, 1)
    np.testing.assert_allclose(out["probabilities"], posterior, rtol=0, atol=1e-12)
    assert abs(out["log_evidence"] - log_evidence) < 1e-12


def test_a_variable_without_a_term_that_conditions_nothing_is_a_term_forgotten():
    text = COMMANDED.replace("  Y: {states: [y0, y1]}\n",
                             "  Y: {states: [y0, y1]}\n  Z: {range: [0, 1]}\n")
    with pytest.raises(SpecError) as caught:
        bayesprog.loads(text)
    assert str(caught.value) == (
        f"<string>:{_at(text, 'Z: {', '{')}: variable 'Z' has no term in the decomposition: "
        "expected one P(Z | ...), or Z as a parent of a term (a variable that every question "
        "gives)")


def test_the_states_over_time_have_terms():
    start = f"  - {{term: P(X_before), form: table, table: {json.dumps(START.tolist())}}}\n"
    assert start in CORRIDOR
    text = CORRIDOR.replace(start, "")
    with pytest.raises(SpecError) as caught:
        bayesprog.loads(text)
    assert str(caught.value) == (
        f"<string>:{_at(text, 'previous:', 'X_before')}: time: X_before has no term in the "
        "decomposition: expected one, the belief before the first step")


def test_soft_evidence_written_on_the_command_is_refused_at_its_place():
    text = COMMANDED + ("soft_evidence:\n"
                        "  - {variable: U, form: categorical, probabilities: [0.2, 0.3, 0.5]}\n")
    with pytest.raises(SpecError) as caught:
        bayesprog.loads(text)
    message = str(caught.value)
    assert message.startswith(f"<string>:{_at(text, 'variable: U', 'U')}: soft evidence on U: "
                              "it has no term"), message


# sampling ---------------------------------------------------------------------------------------
def test_draws_are_made_given_the_command(commanded):
    with pytest.raises(QuestionError, match=r"sampling the program needs U: it has no term .* "
                       r"give it as evidence \(U=\.\.\.\)"):
        commanded.sample(10)
    n = 20_000
    draws = commanded.sample(n, {"U": "u2"}, rng=3)
    assert list(draws.columns) == ["X", "Y"]  # forward, unweighted: no weight column
    # each cell's frequency within 5 binomial standard errors (a false failure below 1e-6)
    for (x, y), p in zip(itertools.product(range(2), range(2)),
                         (PX[:, None] * PY[:, 2, :]).ravel(), strict=True):
        found = np.mean((draws["X"] == X_STATES[x]) & (draws["Y"] == Y_STATES[y]))
        assert abs(found - p) < 5 * np.sqrt(p * (1 - p) / n), (x, y, found, p)
    kept = commanded.sample(n, {"U": "u1", "Y": "y0"}, method="rejection", rng=4)
    p = _hand(0, 1)[0][0]
    assert abs(np.mean(kept["X"] == "x0") - p) < 5 * np.sqrt(p * (1 - p) / n)


# learning ---------------------------------------------------------------------------------------
def _rows(n: int, seed: int) -> pd.DataFrame:
    """Rows drawn here by numpy: the command chosen at random, X and Y from the program."""
    rng = np.random.default_rng(seed)
    u = rng.integers(0, 3, n)
    x = (rng.random(n) > PX[0]).astype(int)
    y = (rng.random(n) > PY[x, u, 0]).astype(int)
    return pd.DataFrame({"X": np.array(X_STATES)[x], "U": np.array(U_STATES)[u],
                         "Y": np.array(Y_STATES)[y]})


def test_learning_reads_the_command_as_evidence_and_never_learns_it(tmp_path):
    path = tmp_path / "commanded.yaml"
    path.write_text(COMMANDED)
    program = bayesprog.load(path)
    data = _rows(600, 5)
    fit = program.fit(data)
    x = data["X"].map(X_STATES.index).to_numpy()
    u = data["U"].map(U_STATES.index).to_numpy()
    y = data["Y"].map(Y_STATES.index).to_numpy()
    counts = np.zeros((2, 3, 2))
    np.add.at(counts, (x, u, y), 1)
    px = np.bincount(x, minlength=2) / len(x)
    py = counts / counts.sum(-1, keepdims=True)
    np.testing.assert_allclose(fit.program.table("P(X)").to_numpy()[0], px, atol=1e-12)
    table = fit.program.table("P(Y | X, U)")
    for i, j in np.ndindex(2, 3):
        np.testing.assert_allclose(table.loc[(X_STATES[i], U_STATES[j])].to_numpy(), py[i, j],
                                   atol=1e-12)
    # the likelihood of the rows given their commands: no log P(U)
    expected = np.sum(np.log(px[x]) + np.log(py[x, u, y]))
    assert abs(fit.log_likelihood - expected) < 1e-9
    assert fit.record.terms == ["P(X)", "P(Y | X, U)"]
    fitted = bayesprog.loads(fit.text())
    assert fitted.conditioning == ("U",)
    np.testing.assert_allclose(fitted.ask("P(X | Y=y0, U=u1)").probabilities,
                               px * py[:, 1, 0] / (px @ py[:, 1, 0]), atol=1e-12)


def test_learning_with_missing_values_of_other_variables_sums_them_given_the_command():
    data = _rows(400, 6)
    data.loc[::7, "X"] = None
    fit = bayesprog.loads(COMMANDED).fit(data)
    px = fit.program.table("P(X)").to_numpy()[0]
    table = fit.program.table("P(Y | X, U)")
    py = np.array([[table.loc[(xs, us)].to_numpy() for us in U_STATES] for xs in X_STATES])
    u = data["U"].map(U_STATES.index).to_numpy()
    y = data["Y"].map(Y_STATES.index).to_numpy()
    seen = data["X"].notna().to_numpy()
    x = data["X"].map({s: i for i, s in enumerate(X_STATES)}).fillna(0).astype(int).to_numpy()
    rows = np.where(seen, np.log(px[x] * py[x, u, y]), np.log(px @ py[:, u, y]))
    assert fit.record.method.startswith("EM")
    assert abs(fit.log_likelihood - rows.sum()) < 1e-9


def test_rows_must_give_the_command(tmp_path, capsys):
    program = bayesprog.loads(COMMANDED)
    data = _rows(10, 7)
    data.loc[2, "U"] = None
    csv = tmp_path / "rows.csv"
    data.to_csv(csv, index=False)
    with pytest.raises(DataError, match=r"rows\.csv: row 3 \(line 4\), column 'U': no value, but "
                       r"U has no term in the decomposition .* \(rows without it: 1\)$"):
        program.fit(csv)
    with pytest.raises(DataError, match=r"no column 'U': U has no term in the decomposition"):
        program.fit(data.drop(columns="U"))
    (tmp_path / "commanded.yaml").write_text(COMMANDED)
    assert main(["learn", str(tmp_path / "commanded.yaml"), str(csv), "-o",
                 str(tmp_path / "fitted.yaml")]) == 2
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err and "column 'U': no value" in err
    assert not (tmp_path / "fitted.yaml").exists()


# the notation -----------------------------------------------------------------------------------
def test_the_program_is_shown_as_a_conditional_one(commanded, tmp_path, capsys):
    text = render(commanded)
    assert "      P(X Y | U) = P(X) P(Y | X, U)" in text.splitlines()
    assert "U : {u0, u1, u2}  (no term: every question gives it)" in text
    assert repr(commanded) == ("Program('commanded', variables=['X', 'U', 'Y'], "
                               "terms=['P(X)', 'P(Y | X, U)'], conditioning=['U'])")
    path = tmp_path / "corridor.yaml"
    path.write_text(CORRIDOR)
    assert main(["show", str(path)]) == 0
    out = capsys.readouterr().out
    assert "      P(X_before X D | U) = P(X_before) P(X | X_before, U) P(D | X)" in out
