"""Programs that repeat per time step: filtering, smoothing and the most likely sequence,
against a hand-written forward-backward and Viterbi, and pgmpy's DBN inference."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import bayesprog
from bayesprog.cli import main
from bayesprog.errors import QuestionError, SpecError

UMBRELLA = Path(__file__).parents[1] / "models" / "examples" / "umbrella.yaml"


def hmm_program(prior, transition, emission, continuous: bool = False) -> bayesprog.Program:
    """An HMM as a step program: ``prior`` over the state before the first step,
    ``transition[i, j] = P(X = j | PREV = i)``, and ``emission[j]``: a row over the
    observations, or (mean, sigma) of a Normal when ``continuous``."""
    k = len(prior)
    states = [f"s{i}" for i in range(k)]
    if continuous:
        observed = "  Obs: {continuous: [-.inf, .inf]}\n"
        means = ", ".join(f"{s}: {m}" for s, (m, _) in zip(states, emission, strict=True))
        sigmas = ", ".join(f"{s}: {sd}" for s, (_, sd) in zip(states, emission, strict=True))
        sensor = f"  - {{term: P(Obs | X), form: normal, mean: {{{means}}}, sigma: {{{sigmas}}}}}\n"
    else:
        observed = f"  Obs: {{states: [{', '.join(f'y{i}' for i in range(emission.shape[1]))}]}}\n"
        sensor = f"  - {{term: P(Obs | X), form: table, table: {emission.tolist()}}}\n"
    text = (f"bayesprog: 1\nvariables:\n  PREV: {{states: [{', '.join(states)}]}}\n"
            f"  X: {{states: [{', '.join(states)}]}}\n{observed}"
            "time: {previous: {PREV: X}}\ndecomposition:\n"
            f"  - {{term: P(PREV), form: table, table: {[float(v) for v in prior]}}}\n"
            f"  - {{term: P(X | PREV), form: table, table: {transition.tolist()}}}\n" + sensor)
    return bayesprog.loads(text)


def forward_backward(prior, transition, likelihoods):
    """Textbook forward-backward on likelihoods [T, K]; returns filtered, smoothed, log P(y)."""
    alpha, log_p = [], 0.0
    belief = np.asarray(prior, float)
    for lik in likelihoods:
        a = (belief @ transition) * lik
        log_p += np.log(a.sum())
        belief = a / a.sum()
        alpha.append(belief)
    beta = np.ones(len(prior))
    smoothed = [alpha[-1]]
    for t in range(len(likelihoods) - 1, 0, -1):
        beta = transition @ (likelihoods[t] * beta)
        beta /= beta.sum()
        g = alpha[t - 1] * beta
        smoothed.append(g / g.sum())
    return np.array(alpha), np.array(smoothed[::-1]), log_p


def viterbi(prior, transition, likelihoods):
    """Textbook Viterbi by enumeration of every sequence (small T): path and P(path | y)."""
    import itertools

    k, steps = len(prior), len(likelihoods)
    best, best_p, total = None, -1.0, 0.0
    for path in itertools.product(range(k), repeat=steps):
        p = 0.0
        for x0 in range(k):  # the state before the first step is summed out
            q = prior[x0]
            previous = x0
            for t, x in enumerate(path):
                q *= transition[previous, x] * likelihoods[t][x]
                previous = x
            p += q
        total += p
        if p > best_p:
            best, best_p = path, p
    return np.array(best), best_p / total


@pytest.fixture(scope="module")
def random_hmm():
    rng = np.random.default_rng(4)
    k, m = 3, 4
    prior = rng.dirichlet(np.ones(k))
    transition = rng.dirichlet(np.ones(k), size=k)
    emission = rng.dirichlet(np.ones(m), size=k)
    observations = rng.integers(0, m, size=(6,))
    return prior, transition, emission, observations


def test_filter_and_smooth_equal_forward_backward(random_hmm):
    prior, transition, emission, y = random_hmm
    program = hmm_program(prior, transition, emission)
    evidence = {"Obs": [f"y{i}" for i in y]}
    filtered = program.ask("P(X | Obs)", evidence, kind="filter")
    smoothed = program.ask("P(X | Obs)", evidence, kind="smooth")
    alpha, gamma, log_p = forward_backward(prior, transition, emission[:, y].T)
    np.testing.assert_allclose(filtered.probabilities, alpha, atol=1e-12)
    np.testing.assert_allclose(smoothed.probabilities, gamma, atol=1e-12)
    np.testing.assert_allclose(filtered.log_evidence.sum(), log_p, atol=1e-10)


def test_the_most_likely_sequence_equals_viterbi_by_enumeration(random_hmm):
    prior, transition, emission, y = random_hmm
    program = hmm_program(prior, transition, emission)
    answer = program.ask("P(X | Obs)", {"Obs": [f"y{i}" for i in y]}, kind="sequence")
    path, p = viterbi(prior, transition, emission[:, y].T)
    np.testing.assert_array_equal(answer.indices[:, 0], path)
    np.testing.assert_allclose(answer.probability, p, rtol=1e-10)


def test_continuous_observations(random_hmm):
    prior, transition, _, _ = random_hmm
    emission = [(-1.0, 0.5), (0.0, 0.8), (1.5, 0.4)]
    program = hmm_program(prior, transition, emission, continuous=True)
    y = np.array([0.2, -1.1, 1.4, 1.6, -0.3])
    from scipy import stats

    likelihoods = np.array([[stats.norm(m, s).pdf(v) for m, s in emission] for v in y])
    alpha, gamma, log_p = forward_backward(prior, transition, likelihoods)
    np.testing.assert_allclose(program.ask("P(X | Obs)", {"Obs": y}, kind="filter").probabilities,
                               alpha, atol=1e-12)
    np.testing.assert_allclose(program.ask("P(X | Obs)", {"Obs": y}, kind="smooth").probabilities,
                               gamma, atol=1e-12)
    path, _ = viterbi(prior, transition, likelihoods)
    np.testing.assert_array_equal(
        program.ask("P(X | Obs)", {"Obs": y}, kind="sequence").indices[:, 0], path)


def test_sequences_of_a_batch_are_answered_as_each_alone(random_hmm):
    prior, transition, emission, _ = random_hmm
    program = hmm_program(prior, transition, emission)
    sequences = np.array([["y0", "y1"], ["y3", "y3"], ["y2", "y0"]])  # [T=3, batch=2]
    both = program.ask("P(X | Obs)", {"Obs": sequences}, kind="smooth")
    assert both.probabilities.shape == (3, 2, 3)
    for b in range(2):
        alone = program.ask("P(X | Obs)", {"Obs": list(sequences[:, b])}, kind="smooth")
        np.testing.assert_allclose(both.probabilities[:, b], alone.probabilities, atol=1e-12)


def test_umbrella_world_against_pgmpys_dbn_inference():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from pgmpy.factors.discrete import TabularCPD
        from pgmpy.inference import DBNInference
        from pgmpy.models import DynamicBayesianNetwork as DBN
    program = bayesprog.load(UMBRELLA)
    transition = np.array([[0.7, 0.3], [0.3, 0.7]])  # [before, today]
    sensor = np.array([[0.9, 0.1], [0.2, 0.8]])  # [rain, umbrella]
    first = np.array([0.5, 0.5]) @ transition  # pgmpy's slice 0: the belief after one step
    dbn = DBN([(("R", 0), ("U", 0)), (("R", 0), ("R", 1)), (("R", 1), ("U", 1))])
    dbn.add_cpds(TabularCPD(("R", 0), 2, first.reshape(2, 1)),
                 TabularCPD(("R", 1), 2, transition.T, evidence=[("R", 0)], evidence_card=[2]),
                 TabularCPD(("U", 0), 2, sensor.T, evidence=[("R", 0)], evidence_card=[2]))
    dbn.initialize_initial_state()
    umbrella = [0, 0, 1, 0, 0]  # yes, yes, no, yes, yes
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        inference = DBNInference(dbn)
        evidence = {("U", t): u for t, u in enumerate(umbrella)}
        theirs = [inference.forward_inference([("R", t)], {k: v for k, v in evidence.items()
                                                           if k[1] <= t})[("R", t)].values
                  for t in range(len(umbrella))]
    ours = program.ask("today", {"Umbrella": ["yes" if u == 0 else "no" for u in umbrella]})
    np.testing.assert_allclose(ours.probabilities, np.array(theirs), atol=1e-10)
    assert ours.probabilities[:2, 0].round(3).tolist() == [0.818, 0.883]  # the textbook's


def test_cli_questions_over_steps(capsys):
    assert main(["query", str(UMBRELLA), "most_likely", "--evidence",
                 "Umbrella=yes,yes,no,yes,yes"]) == 0
    out = capsys.readouterr().out
    assert "step 3: Rain=dry" in out and "step 5: Rain=rain" in out
    assert main(["query", str(UMBRELLA), "P(Rain | Umbrella)", "--over-time", "filter",
                 "--evidence", "Umbrella=yes,yes"]) == 0
    assert "step 2" in capsys.readouterr().out
    assert main(["query", str(UMBRELLA), "today", "--evidence", "Umbrella=yes,maybe"]) == 2
    assert "unknown state 'maybe'" in capsys.readouterr().err


def test_questions_over_steps_are_checked():
    program = bayesprog.load(UMBRELLA)
    with pytest.raises(QuestionError, match="searches the state: expected P\\(Rain"):
        program.ask("P(Umbrella | Rain)", {"Rain": ["rain"]}, kind="filter")
    with pytest.raises(QuestionError, match="different lengths"):
        bayesprog.loads(UMBRELLA.read_text().replace(
            "ask: P(Rain | Umbrella),", "ask: 'P(Rain | Umbrella, Rain_before)',")).ask(
            "today", {"Umbrella": ["yes"], "Rain_before": ["rain", "dry"]})
    rain = bayesprog.load(UMBRELLA.parent / "rain.yaml")
    with pytest.raises(QuestionError, match="needs a program that repeats per step"):
        rain.ask("P(Rain | Grass)", {"Grass": ["wet"]}, kind="filter")
    with pytest.raises(SpecError, match="must have the same states"):
        bayesprog.loads(UMBRELLA.read_text().replace(
            "Rain: {states: [rain, dry]", "Rain: {states: [rain, dry, snow]").replace(
            "{rain: [0.9, 0.1], dry: [0.2, 0.8]}",
            "{rain: [0.9, 0.1], dry: [0.2, 0.8], snow: [0.5, 0.5]}").replace(
            "table: {rain: [0.7, 0.3], dry: [0.3, 0.7]}",
            "table: {rain: [0.7, 0.3, 0.0], dry: [0.3, 0.7, 0.0]}"))
