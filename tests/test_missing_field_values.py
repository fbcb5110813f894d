"""A field value that is not observed (NaN) is marginalised: its term contributes 1 there.

Checked against the posterior written out by hand with scipy.stats densities, batched and not.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import bayesprog

PROGRAM = """
bayesprog: 1
variables:
  O: {range: [0, 3]}
  S: {continuous: [0, 1], indexed_by: O}
  U: {continuous: [0, 1], indexed_by: O}
decomposition:
  - {term: P(O), form: table, table: [0.1, 0.2, 0.3, 0.4]}
  - {term: P(S | O), form: beta, a: 3.0, b: 1.0}
  - {term: P(U | O), form: beta, a: 2.0, b: 5.0}
"""


def by_hand(s: np.ndarray, u: np.ndarray) -> np.ndarray:
    prior = np.array([0.1, 0.2, 0.3, 0.4])
    fs = np.where(np.isnan(s), 1.0, stats.beta(3, 1).pdf(np.nan_to_num(s)))
    fu = np.where(np.isnan(u), 1.0, stats.beta(2, 5).pdf(np.nan_to_num(u)))
    joint = prior * fs * fu
    return joint / joint.sum(axis=-1, keepdims=True)


def test_missing_entries_are_marginalised():
    program = bayesprog.loads(PROGRAM)
    s = np.array([0.2, np.nan, 0.7, np.nan])
    u = np.array([0.3, 0.1, np.nan, 0.5])
    answer = program.ask("P(O | S, U)", {"S": s, "U": u})
    np.testing.assert_allclose(answer.probabilities, by_hand(s, u), rtol=1e-12)


def test_missing_entries_batched_rows_are_independent():
    program = bayesprog.loads(PROGRAM)
    rng = np.random.default_rng(0)
    s = rng.random((5, 4))
    u = rng.random((5, 4))
    s[rng.random((5, 4)) < 0.4] = np.nan
    u[rng.random((5, 4)) < 0.4] = np.nan
    answer = program.ask("P(O | S, U)", {"S": s, "U": u})
    np.testing.assert_allclose(answer.probabilities, by_hand(s, u), rtol=1e-12)
    for row in range(5):
        single = program.ask("P(O | S, U)", {"S": s[row], "U": u[row]})
        np.testing.assert_allclose(single.probabilities, answer.probabilities[row], rtol=1e-12)


def test_every_entry_missing_leaves_the_prior():
    program = bayesprog.loads(PROGRAM)
    nan = np.full(4, np.nan)
    answer = program.ask("P(O | S, U)", {"S": nan, "U": nan})
    np.testing.assert_allclose(answer.probabilities, [0.1, 0.2, 0.3, 0.4], rtol=1e-12)


def test_nan_for_a_plain_continuous_variable_is_still_refused():
    program = bayesprog.loads("""
bayesprog: 1
variables:
  M: {states: [a, b]}
  E: {continuous: [0, 1]}
decomposition:
  - {term: P(M), form: uniform}
  - {term: P(E | M), form: beta, a: {a: 2.0, b: 5.0}, b: 2.0}
""")
    with pytest.raises(bayesprog.QuestionError, match="NaN"):
        program.ask("P(M | E)", {"E": float("nan")})
