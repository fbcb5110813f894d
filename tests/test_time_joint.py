"""Programs over time with several discrete state variables (``time: {previous: {A_before: A,
B_before: B}}``): filter, smooth and sequence questions on one of them or several jointly,
exact without unrolling, checked against enumeration of the unrolled joint and against pgmpy's
DBN inference."""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest

import bayesprog
from bayesprog.cli import main

TWO_CHAINS = """\
bayesprog: 1
name: two_chains
variables:
  A_before: {states: [a0, a1]}
  B_before: {states: [b0, b1, b2]}
  A: {states: [a0, a1]}
  B: {states: [b0, b1, b2]}
  O: {states: [o0, o1]}
time:
  previous: {A_before: A, B_before: B}
decomposition:
  - {term: P(A_before), form: table, table: [0.6, 0.4]}
  - {term: P(B_before | A_before), form: table, table: {a0: [0.5, 0.3, 0.2], a1: [0.1, 0.3, 0.6]}}
  - {term: P(A | A_before), form: table, table: {a0: [0.8, 0.2], a1: [0.3, 0.7]}}
  - term: P(B | B_before, A)
    form: table
    table:
      b0: {a0: [0.7, 0.2, 0.1], a1: [0.2, 0.5, 0.3]}
      b1: {a0: [0.1, 0.8, 0.1], a1: [0.3, 0.3, 0.4]}
      b2: {a0: [0.2, 0.2, 0.6], a1: [0.1, 0.1, 0.8]}
  - term: P(O | A, B)
    form: table
    table:
      a0: {b0: [0.9, 0.1], b1: [0.6, 0.4], b2: [0.3, 0.7]}
      a1: {b0: [0.2, 0.8], b1: [0.5, 0.5], b2: [0.95, 0.05]}
questions:
  both: {ask: P(A B | O), kind: filter}
  path: {ask: P(A B | O), kind: sequence}
"""

PRIOR_A = np.array([0.6, 0.4])
PRIOR_B = np.array([[0.5, 0.3, 0.2], [0.1, 0.3, 0.6]])  # A_before, B_before
MOVE_A = np.array([[0.8, 0.2], [0.3, 0.7]])  # A_before, A
MOVE_B = np.array([[[0.7, 0.2, 0.1], [0.2, 0.5, 0.3]], [[0.1, 0.8, 0.1], [0.3, 0.3, 0.4]],
                   [[0.2, 0.2, 0.6], [0.1, 0.1, 0.8]]])  # B_before, A, B
SEE = np.array([[[0.9, 0.1], [0.6, 0.4], [0.3, 0.7]],
                [[0.2, 0.8], [0.5, 0.5], [0.95, 0.05]]])  # A, B, O


def _enumerate(observed: list[int]) -> dict:
    """Every joint sequence of the unrolled program, and its probability with the evidence."""
    steps = len(observed)
    weights = {}
    for start in itertools.product(range(2), range(3)):
        for seq in itertools.product(itertools.product(range(2), range(3)), repeat=steps):
            p = PRIOR_A[start[0]] * PRIOR_B[start[0], start[1]]
            before = start
            for (a, b), o in zip(seq, observed, strict=True):
                p *= MOVE_A[before[0], a] * MOVE_B[before[1], a, b] * SEE[a, b, o]
                before = (a, b)
            weights[seq] = weights.get(seq, 0.0) + p
    return weights


def _marginal(weights: dict, steps_seen: int, t: int) -> np.ndarray:
    """P(A_t B_t | o_1..steps_seen) from the joint over sequences of that many steps."""
    out = np.zeros((2, 3))
    for seq, w in weights.items():
        out[seq[t]] += w
    return out / out.sum()


@pytest.fixture(scope="module")
def program():
    return bayesprog.loads(TWO_CHAINS)


OBSERVED = [[1, 0, 0, 1], [0, 0, 1, 1]]


def test_filter_and_smooth_equal_enumeration_of_the_unrolled_joint(program):
    names = np.array(["o0", "o1"])
    evidence = {"O": names[np.array(OBSERVED).T]}  # time first, then the batch of 2 sequences
    filtered = program.ask("P(A B | O)", evidence, kind="filter")
    smoothed = program.ask("P(A B | O)", evidence, kind="smooth")
    only_b = program.ask("P(B | O)", evidence, kind="smooth")
    b_then_a = program.ask("P(B A | O)", evidence, kind="filter")
    assert filtered.probabilities.shape == (4, 2, 2, 3)
    for k, observed in enumerate(OBSERVED):
        full = _enumerate(observed)
        for t in range(4):
            expected = _marginal(_enumerate(observed[: t + 1]), t + 1, t)
            np.testing.assert_allclose(filtered.probabilities[t, k], expected, atol=1e-12)
            np.testing.assert_allclose(b_then_a.probabilities[t, k], expected.T, atol=1e-12)
            both = _marginal(full, 4, t)
            np.testing.assert_allclose(smoothed.probabilities[t, k], both, atol=1e-12)
            np.testing.assert_allclose(only_b.probabilities[t, k], both.sum(axis=0), atol=1e-12)
        # log P(o_t | o_<t), summed: log P(o_1..T)
        np.testing.assert_allclose(filtered.log_evidence[:, k].sum(),
                                   np.log(sum(full.values())), atol=1e-12)


def test_the_most_likely_joint_sequence_equals_enumeration(program):
    for observed in OBSERVED:
        weights = _enumerate(observed)
        best = max(weights, key=weights.get)
        answer = program.ask("path", {"O": [f"o{o}" for o in observed]})
        assert answer.kind == "sequence"
        assert answer.assignment["A"].tolist() == [f"a{a}" for a, _ in best]
        assert answer.assignment["B"].tolist() == [f"b{b}" for _, b in best]
        assert float(answer.probability) == pytest.approx(
            weights[best] / sum(weights.values()), rel=1e-12)


def test_filtering_equals_pgmpys_dbn_inference(program):
    from pgmpy.factors.discrete import TabularCPD
    from pgmpy.inference import DBNInference
    from pgmpy.models import DynamicBayesianNetwork

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dbn = DynamicBayesianNetwork([
            (("A", 0), ("B", 0)), (("A", 0), ("O", 0)), (("B", 0), ("O", 0)),
            (("A", 0), ("A", 1)), (("B", 0), ("B", 1)), (("A", 1), ("B", 1)),
            (("A", 1), ("O", 1)), (("B", 1), ("O", 1))])
        see = SEE.reshape(6, 2).T
        dbn.add_cpds(
            TabularCPD(("A", 0), 2, PRIOR_A[:, None]),
            TabularCPD(("B", 0), 3, PRIOR_B.T, evidence=[("A", 0)], evidence_card=[2]),
            # the slice before the first step observes nothing: its O is never given
            TabularCPD(("O", 0), 2, see, evidence=[("A", 0), ("B", 0)], evidence_card=[2, 3]),
            TabularCPD(("A", 1), 2, MOVE_A.T, evidence=[("A", 0)], evidence_card=[2]),
            TabularCPD(("B", 1), 3, MOVE_B.reshape(6, 3).T, evidence=[("B", 0), ("A", 1)],
                       evidence_card=[3, 2]),
            TabularCPD(("O", 1), 2, see, evidence=[("A", 1), ("B", 1)], evidence_card=[2, 3]))
        dbn.initialize_initial_state()
        engine = DBNInference(dbn)
        observed = OBSERVED[0]
        ours_a = program.ask("P(A | O)", {"O": [f"o{o}" for o in observed]}, kind="filter")
        ours_b = program.ask("P(B | O)", {"O": [f"o{o}" for o in observed]}, kind="filter")
        for t in range(1, len(observed) + 1):
            evidence = {("O", s): observed[s - 1] for s in range(1, t + 1)}
            theirs = engine.forward_inference([("A", t), ("B", t)], evidence)
            np.testing.assert_allclose(ours_a.probabilities[t - 1], theirs[("A", t)].values,
                                       atol=1e-10)
            np.testing.assert_allclose(ours_b.probabilities[t - 1], theirs[("B", t)].values,
                                       atol=1e-10)


def test_the_command_line_answers_jointly(tmp_path, capsys):
    (tmp_path / "two.yaml").write_text(TWO_CHAINS)
    assert main(["query", str(tmp_path / "two.yaml"), "both", "--evidence", "O=o1,o0"]) == 0
    out = capsys.readouterr().out
    assert "(filtered, 2 steps)" in out and "a1  b2" in out
    assert main(["show", str(tmp_path / "two.yaml")]) == 0
    assert "A_before is A, B_before is B one step earlier" in capsys.readouterr().out


@pytest.mark.parametrize("change, said", [
    ("path: {ask: P(A B | O), kind: sequence}", "path: {ask: P(A | O), kind: sequence}"),
    ("previous: {A_before: A, B_before: B}", "previous: {A_before: A, B_before: A}"),
])
def test_what_the_recursions_cannot_answer_is_refused_at_its_place(change, said):
    with pytest.raises(bayesprog.SpecError) as info:
        bayesprog.loads(TWO_CHAINS.replace(change, said))
    text = str(info.value)
    assert ("expected P(A B | ...)" in text) or ("must have the same states" in text
                                                 or "each state variable once" in text)


def test_soft_evidence_on_what_a_step_observes_equals_enumeration(program):
    like = np.array([[0.9, 0.2], [0.3, 0.6], [0.5, 0.5], [0.1, 0.7]])  # time, O's states
    answer = program.ask("P(A B)", soft={"O": like}, kind="smooth")
    # enumeration: each step's likelihood of O summed over O's states
    weights = {}
    for start in itertools.product(range(2), range(3)):
        for seq in itertools.product(itertools.product(range(2), range(3)), repeat=4):
            p = PRIOR_A[start[0]] * PRIOR_B[start[0], start[1]]
            before = start
            for (a, b), lt in zip(seq, like, strict=True):
                p *= MOVE_A[before[0], a] * MOVE_B[before[1], a, b] * (SEE[a, b] @ lt)
                before = (a, b)
            weights[seq] = weights.get(seq, 0.0) + p
    for t in range(4):
        np.testing.assert_allclose(answer.probabilities[t], _marginal(weights, 4, t), atol=1e-12)
    with pytest.raises(bayesprog.QuestionError, match="soft evidence on A"):
        program.ask("P(B)", soft={"A": like[:, :2]}, kind="filter")


def test_soft_evidence_over_steps_of_one_state_equals_the_hand_recursion():
    umbrella = bayesprog.load(__import__("pathlib").Path(__file__).parents[1] / "models"
                              / "examples" / "umbrella.yaml")
    like = np.array([[0.9, 0.1], [0.6, 0.4], [0.2, 0.8]])
    answer = umbrella.ask("P(Rain)", soft={"Umbrella": like}, kind="filter")
    move, see = np.array([[0.7, 0.3], [0.3, 0.7]]), np.array([[0.9, 0.1], [0.2, 0.8]])
    belief = np.array([0.5, 0.5])
    for t in range(3):
        belief = (belief @ move) * (see @ like[t])
        belief = belief / belief.sum()
        np.testing.assert_allclose(answer.probabilities[t], belief, atol=1e-12)


def test_soft_evidence_over_steps_from_the_command_line(tmp_path, capsys):
    like = np.array([[0.9, 0.1], [0.6, 0.4], [0.2, 0.8]])
    np.save(tmp_path / "like.npy", like)
    umbrella = __import__("pathlib").Path(__file__).parents[1] / "models" / "examples" / \
        "umbrella.yaml"
    assert main(["query", str(umbrella), "P(Rain)", "--over-time", "filter", "--soft",
                 f"Umbrella={tmp_path / 'like.npy'}", "--json"]) == 0
    out = __import__("json").loads(capsys.readouterr().out)
    expected = bayesprog.load(umbrella).ask("P(Rain)", soft={"Umbrella": like}, kind="filter")
    np.testing.assert_allclose(out["probabilities"], expected.probabilities, atol=1e-12)
