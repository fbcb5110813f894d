"""The warm path of a question asked again (``bayesprog.inference.quick``): the same answers,
errors and evidence probabilities as the full path, and answers that share nothing."""

from __future__ import annotations

import math

import numpy as np
import pytest

import bayesprog
from bayesprog.inference import quick

LAMP = """
bayesprog: 1
name: lamp
variables:
  W: {states: [dry, wet]}
  R: {states: [quiet, ringing]}
  L: {states: [lit, broken]}
  B: {states: [b0, b1, b2]}
decomposition:
  - {term: P(W), form: table, table: [0.7, 0.3]}
  - term: P(R | W)
    form: table
    table:
      dry: [0.9, 0.1]
      wet: [0.2, 0.8]
  - {term: P(L), form: table, table: [1.0, 0.0]}
  - term: P(B | R)
    form: table
    table:
      quiet: [0.5, 0.5, 0.0]
      ringing: [0.1, 0.6, 0.3]
"""


def _warm(program, question, evidence, method=None):
    """The warm path's answer (None: it would hand over to the full path)."""
    return quick.answer(program, (question, None, method, tuple(evidence)), evidence)


def _ask_often(program, question, evidence, method=None, times=40):
    for _ in range(times):
        answer = program.ask(question, evidence, method=method)
    return answer


@pytest.mark.parametrize("method", [None, "contraction", "table"])
def test_an_answer_asked_again_is_the_full_paths(method):
    program = bayesprog.loads(LAMP)
    question = "P(W | B, L)"
    for b in ("b0", "b1", "b2"):
        warm = _ask_often(program, question, {"B": b, "L": "lit"}, method)
        full = bayesprog.loads(LAMP).ask(question, {"B": [b], "L": ["lit"]}, method=method)
        np.testing.assert_allclose(warm.probabilities, full.probabilities[0], rtol=1e-12)
        assert float(warm.log_evidence) == pytest.approx(float(full.log_evidence[0]), rel=1e-12)
        assert warm.states == full.states and warm.batch_shape == ()
    assert _warm(program, question, {"B": "b1", "L": "lit"}, method) is not None
    # by brute force: P(W | B=b1) (L is independent and lit has probability one)
    joint = np.einsum("w,wr,rb->wb", [0.7, 0.3], [[0.9, 0.1], [0.2, 0.8]],
                      [[0.5, 0.5, 0.0], [0.1, 0.6, 0.3]])
    answer = program.ask(question, {"B": "b1", "L": "lit"}, method=method)
    np.testing.assert_allclose(answer.probabilities, joint[:, 1] / joint[:, 1].sum(), rtol=1e-12)
    assert float(answer.log_evidence) == pytest.approx(math.log(joint[:, 1].sum()), rel=1e-12)


@pytest.mark.parametrize("method", [None, "contraction"])
def test_impossible_evidence_left_out_shows_in_log_evidence_only(method):
    """The target R is d-separated from L (given W): L=broken, of probability zero, does not
    stop the posterior, warm or not; its log_evidence is -inf, computed when read."""
    program = bayesprog.loads(LAMP)
    for _ in range(5):
        answer = program.ask("P(R | W, L)", {"W": "wet", "L": "broken"}, method=method)
        np.testing.assert_allclose(answer.probabilities, [0.2, 0.8], rtol=1e-12)
        assert float(answer.log_evidence) == -math.inf
        lit = program.ask("P(R | W, L)", {"W": "wet", "L": "lit"}, method=method)
        assert float(lit.log_evidence) == pytest.approx(math.log(0.3), rel=1e-12)
    assert _warm(program, "P(R | W, L)", {"W": "wet", "L": "broken"}, method) is not None


def test_impossible_evidence_that_bears_on_the_answer_is_refused_warm_or_not():
    """S=s1 cannot happen, and S is W's child: it bears on W and on R."""
    text = LAMP.replace("  B: {states: [b0, b1, b2]}",
                        "  B: {states: [b0, b1, b2]}\n  S: {states: [s0, s1]}")
    program = bayesprog.loads(text + """
  - term: P(S | W)
    form: table
    table:
      dry: [1.0, 0.0]
      wet: [1.0, 0.0]
""")
    for method in (None, "contraction"):
        for _ in range(5):
            program.ask("P(R | S, B)", {"S": "s0", "B": "b1"}, method=method)
            with pytest.raises(bayesprog.ZeroEvidenceError, match="probability zero"):
                program.ask("P(R | S, B)", {"S": "s1", "B": "b1"}, method=method)
            with pytest.raises(bayesprog.ZeroEvidenceError, match="probability zero"):
                program.ask("P(W | S)", {"S": "s1"}, method=method)
            program.ask("P(W | S)", {"S": "s0"}, method=method)


def test_bad_values_asked_again_get_the_full_paths_errors():
    program = bayesprog.loads(LAMP)
    _ask_often(program, "P(W | B)", {"B": "b0"})
    with pytest.raises(bayesprog.QuestionError, match="unknown state 'b9' of B"):
        program.ask("P(W | B)", {"B": "b9"})
    with pytest.raises(bayesprog.QuestionError, match="out of range"):
        program.ask("P(W | B)", {"B": 7})
    # other kinds of values: the full path, the same answer
    by_index = program.ask("P(W | B)", {"B": 1})
    np.testing.assert_array_equal(by_index.probabilities,
                                  program.ask("P(W | B)", {"B": "b1"}).probabilities)
    batch = program.ask("P(W | B)", {"B": ["b0", "b1"]})
    assert batch.batch_shape == (2,)


def test_answers_asked_again_share_no_array():
    program = bayesprog.loads(LAMP)
    for question, evidence in (("P(R | L)", {"L": "lit"}), ("P(W | B)", {"B": "b1"})):
        first = _ask_often(program, question, evidence)
        kept = first.probabilities.copy()
        first.probabilities[...] = -1.0
        first.names[first.variables[0]] = ("changed",)
        again = program.ask(question, evidence)
        np.testing.assert_array_equal(again.probabilities, kept)
        assert again.names[again.variables[0]] != ("changed",)


def test_map_questions_and_other_kinds_keep_their_path():
    program = bayesprog.loads(LAMP)
    _ask_often(program, "P(W | B)", {"B": "b1"})
    chosen = program.ask("P(W | B)", {"B": "b1"}, kind="map")
    assert isinstance(chosen, bayesprog.MapResult)
    assert chosen.assignment["W"] == "dry"
    assert program.posterior("P(W | B)", {"B": "b1"}).batch_shape == ()


@pytest.mark.parametrize("method", [None, "contraction"])
def test_a_question_asked_again_is_checked_against_new_limits(method):
    from bayesprog.limits import SizeError, set_limits

    program = bayesprog.loads(LAMP)
    _ask_often(program, "P(W | B)", {"B": "b1"}, method)
    try:
        set_limits(entries=1)
        with pytest.raises(SizeError):
            program.ask("P(W | B)", {"B": "b1"}, method=method)
    finally:
        set_limits(entries=None)
    assert program.ask("P(W | B)", {"B": "b1"}, method=method).probabilities.shape == (2,)
    assert _warm(program, "P(W | B)", {"B": "b1"}, method) is not None


def test_a_question_without_evidence_asked_again_is_warm():
    program = bayesprog.loads(LAMP)
    first = program.ask("P(R)")
    again = _ask_often(program, "P(R)", None)
    assert quick.answer(program, ("P(R)", None, None, ()), {}) is not None
    np.testing.assert_allclose(again.probabilities, first.probabilities, rtol=1e-15)
    np.testing.assert_allclose(again.probabilities, [0.7 * 0.9 + 0.3 * 0.2, 0.7 * 0.1 + 0.3 * 0.8],
                               rtol=1e-12)
    assert float(again.log_evidence) == 0.0


def test_states_by_index_or_value_asked_again_are_those_by_name():
    """An integer is a state's index, a range's integer its value (a numpy integer too); a
    bool or a number is read, or refused, by the full path as before."""
    program = bayesprog.loads(LAMP.replace("  B: {states: [b0, b1, b2]}",
                                           "  B: {states: [b0, b1, b2]}\n  N: {range: [3, 5]}")
                              + """
  - term: P(N | R)
    form: table
    table:
      quiet: [0.2, 0.3, 0.5]
      ringing: [0.6, 0.3, 0.1]
""")
    for _ in range(3):
        by_name = _ask_often(program, "P(W | B, N)", {"B": "b1", "N": "4"})
        by_index = _ask_often(program, "P(W | B, N)", {"B": 1, "N": 4})
        by_numpy = program.ask("P(W | B, N)", {"B": np.int64(1), "N": np.int64(4)})
        np.testing.assert_allclose(by_index.probabilities, by_name.probabilities, rtol=1e-12)
        np.testing.assert_allclose(by_numpy.probabilities, by_name.probabilities, rtol=1e-12)
    assert quick.answer(program, ("P(W | B, N)", None, None, ("B", "N")), {"B": 1, "N": 4}) \
        is not None
    with pytest.raises(bayesprog.QuestionError, match="unknown value 9 of N"):
        program.ask("P(W | B, N)", {"B": 1, "N": 9})
    with pytest.raises(bayesprog.QuestionError, match="out of range"):
        program.ask("P(W | B, N)", {"B": 3, "N": 4})
    with pytest.raises(bayesprog.QuestionError, match="expected state names or indices"):
        program.ask("P(W | B, N)", {"B": True, "N": 4})
    with pytest.raises(bayesprog.QuestionError, match="expected state names or indices"):
        program.ask("P(W | B, N)", {"B": 1.0, "N": 4})
