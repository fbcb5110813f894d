"""A term made uniform on some rows of a batch (``ask(..., ablate={term: rows})``): each row
answers as the program with that term ablated (:meth:`bayesprog.Program.ablate`) when it is
marked, as the program itself when not; against the joint enumerated by hand (discrete) and
scipy's densities multiplied by hand (tests/programs/tar.yaml, a gmm over a grid)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from scipy.special import softmax
from test_recurring import tar_reference

import bayesprog
from bayesprog.errors import ArgumentError, QuestionError

PROGRAMS = Path(__file__).parent / "programs"
CHAIN = """
bayesprog: 1
variables: {A: {states: [a0, a1, a2]}, B: {states: [b0, b1]}, C: {states: [c0, c1, c2]}}
decomposition:
  - {term: P(A), form: table, table: [0.5, 0.3, 0.2]}
  - {term: P(B | A), form: table, table: {a0: [0.9, 0.1], a1: [0.4, 0.6], a2: [0.05, 0.95]}}
  - term: P(C | B)
    form: table
    table: {b0: [0.7, 0.2, 0.1], b1: [0.1, 0.3, 0.6]}
"""
P_A = np.array([0.5, 0.3, 0.2])
P_B_A = np.array([[0.9, 0.1], [0.4, 0.6], [0.05, 0.95]])
P_C_B = np.array([[0.7, 0.2, 0.1], [0.1, 0.3, 0.6]])


def _ask(program, question, evidence=None, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return program.ask(question, evidence, **kw)


def _chain_reference(c: int, uniform_b: bool) -> np.ndarray:
    """P(A | C = c) enumerated over the joint, with P(B | A) uniform when ``uniform_b``."""
    b_a = np.full((3, 2), 0.5) if uniform_b else P_B_A
    joint = P_A[:, None] * b_a * P_C_B[:, c][None, :]  # [A, B]
    return joint.sum(axis=1) / joint.sum()


@pytest.mark.parametrize("method", [None, "contraction", "lbp"])
def test_rows_that_ablate_a_table_answer_as_the_joint_with_it_uniform(method):
    program = bayesprog.loads(CHAIN)
    c = np.array([0, 1, 2, 2, 1, 0])
    rows = np.array([True, False, True, False, False, True])
    kw = {"method": method} if method else {}
    result = _ask(program, "P(A | C)", {"C": c}, ablate={"P(B | A)": rows}, **kw)
    for row in range(len(c)):
        np.testing.assert_allclose(result.probabilities[row],
                                   _chain_reference(c[row], bool(rows[row])), rtol=1e-9)
    # and as the program ablated for every row, or not at all
    ablated = _ask(program.ablate("P(B | A)"), "P(A | C)", {"C": c}, **kw)
    whole = _ask(program, "P(A | C)", {"C": c}, **kw)
    np.testing.assert_allclose(result.probabilities[rows], ablated.probabilities[rows],
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(result.probabilities[~rows], whole.probabilities[~rows],
                               rtol=0, atol=1e-15)


def test_the_evidence_of_rows_that_ablate_a_term_counts_that_term_as_uniform():
    program = bayesprog.loads(CHAIN)
    c = np.array([0, 2, 1])
    rows = np.array([False, True, True])
    result = _ask(program, "P(A | C)", {"C": c}, ablate={"P(B | A)": rows})
    for row in range(3):
        b_a = np.full((3, 2), 0.5) if rows[row] else P_B_A
        joint = P_A[:, None] * b_a * P_C_B[:, c[row]][None, :]
        np.testing.assert_allclose(result.log_evidence[row], np.log(joint.sum()), rtol=1e-12)


def test_ablating_on_no_row_or_on_every_row():
    program = bayesprog.loads(CHAIN)
    c = np.array([0, 1, 2])
    none = _ask(program, "P(A | C)", {"C": c}, ablate={"P(B | A)": np.zeros(3, bool)})
    assert np.array_equal(none.probabilities, _ask(program, "P(A | C)", {"C": c}).probabilities)
    every = _ask(program, "P(A | C)", {"C": c}, ablate={"P(B | A)": True})
    ablated = _ask(program.ablate("P(B | A)"), "P(A | C)", {"C": c})
    np.testing.assert_allclose(every.probabilities, ablated.probabilities, rtol=0, atol=1e-15)
    # a term the program already ablates is uniform on every row anyway
    again = _ask(program.ablate("P(B | A)"), "P(A | C)", {"C": c},
                 ablate={"P(B|A)": np.array([True, False, True])})
    assert np.array_equal(again.probabilities, ablated.probabilities)


def test_rows_that_ablate_the_gmm_over_a_grid_answer_as_scipy_and_read_no_template():
    program = bayesprog.load(PROGRAMS / "tar.yaml")
    rng = np.random.default_rng(3)
    rows = np.array([True, False, False, True, False])
    templates = rng.uniform(0, 0.05, (5, 2, 3, 2))
    i_field, s_field = rng.uniform(0.01, 0.99, (2, 5, 20))
    t = np.array([0, 1, 1, 0, 1])
    l1 = rng.uniform(0.01, 0.99, 5)
    evidence = {"T": np.array(["T1", "T2"])[t], "I": i_field, "S": s_field}
    inputs = {"templates": templates, "l1": l1, "l2": 0.3}
    result = _ask(program, "P(O | T, I, S)", evidence, inputs=inputs,
                  ablate={"P(R | O)": rows})
    for row in range(5):
        if rows[row]:  # P(R | O) uniform: 1/2 for every cell and shape
            log_ref = _without_gmm(t[row], i_field[row], s_field[row])
        else:
            log_ref = tar_reference(t[row], i_field[row], s_field[row], templates[row], l1[row],
                                    0.3)
        np.testing.assert_allclose(result.probabilities[row], softmax(log_ref), rtol=1e-9,
                                   atol=1e-15)
    # the ablated rows' templates are not read: any finite values give the same answer
    wild = templates.copy()
    wild[rows] = 1e6
    again = _ask(program, "P(O | T, I, S)", evidence,
                 inputs={"templates": wild, "l1": l1, "l2": 0.3}, ablate={"P(R | O)": rows})
    assert np.array_equal(again.probabilities, result.probabilities)


def _without_gmm(t, i_field, s_field) -> np.ndarray:
    """tar.yaml's log joint over the cells with P(R | O) uniform: the soft evidence on R sums
    out to a constant."""
    return (np.log(1 / 20) + np.log(1 / 2) + stats.beta.logpdf(i_field, 1, 2.5)
            + stats.beta.logpdf(s_field, [3.0, 2.0][t], 1))


def test_a_map_with_rows_that_ablate_a_term_is_each_row_s_map():
    program = bayesprog.loads(CHAIN)
    c = np.array([0, 1, 2, 0])
    rows = np.array([False, True, False, True])
    best = _ask(program, "P(A | C)", {"C": c}, kind="map", ablate={"P(B | A)": rows})
    for row in range(4):
        reference = _chain_reference(c[row], bool(rows[row]))
        assert best.indices[row, 0] == int(np.argmax(reference))


def test_methods_that_do_not_answer_rows_that_ablate_a_term_say_which_do():
    program = bayesprog.loads(CHAIN)
    for method in ("gibbs", "lw"):
        with pytest.raises(QuestionError, match="contraction"):
            program.ask("P(A | C)", {"C": np.array([0, 1])}, method=method,
                        ablate={"P(B | A)": np.array([True, False])})


def test_a_bad_ablate_is_refused():
    program = bayesprog.loads(CHAIN)
    c = np.array([0, 1])
    with pytest.raises(QuestionError, match="booleans"):
        program.ask("P(A | C)", {"C": c}, ablate={"P(B | A)": np.array([1, 0])})
    with pytest.raises(QuestionError):
        program.ask("P(A | C)", {"C": c}, ablate={"P(D | A)": np.array([True, False])})
    with pytest.raises(ArgumentError, match="ablate"):
        program.ask("P(A | C)", {"C": c}, ablate=["P(B | A)"])
    with pytest.raises(QuestionError, match="broadcast"):
        program.ask("P(A | C)", {"C": c}, ablate={"P(B | A)": np.array([True, False, True])})
