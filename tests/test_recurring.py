"""A layout asked again and again (:mod:`bayesprog.inference.recurring`): the factors kept from
one question to the next, computed again where their evidence or inputs changed, give the
answers of a program asked afresh, to the bit, and the hand-multiplied joint of scipy's
densities; the log densities kept by value (:mod:`bayesprog.inference.memo`) are the form's.

The program is ``tests/programs/tar.yaml``: Beta fields over a grid (one with a parameter keyed
by another variable), a gmm over the grid whose means are an input, soft evidence from a
sub-program whose evidence is bound to inputs."""

from __future__ import annotations

import sys
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from scipy.special import logsumexp, softmax

import bayesprog
from bayesprog.inference.memo import Memo

PROGRAMS = Path(__file__).parent / "programs"
ROWS, CELLS = 6, 20


def _ask(program, question, evidence, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return program.ask(question, evidence, **kw)


def tar_reference(t, i_field, s_field, templates, l1, l2, likelihood=None) -> np.ndarray:
    """log P(O = o, T = t, I, S | soft evidence on R) for every cell o of tar.yaml, by hand
    (times a ``likelihood`` over R given with the question); a missing (NaN) field value
    contributes nothing."""
    log_r = (stats.beta.logpdf(l1, [1, 1], [4.5, 1]) + stats.beta.logpdf(l2, 1, [1, 4.5])
             + np.log(0.5))
    soft = softmax(log_r)
    if likelihood is not None:
        soft = soft * likelihood
    cell, floor = 0.01, 0.1
    centres = np.array([((i + 0.5) * cell, (j + 0.5) * cell) for i in range(4) for j in range(5)])
    gmm = np.zeros((2, CELLS))
    k = templates.shape[1]
    for r in range(2):
        for j in range(k):
            gmm[r] += stats.multivariate_normal(templates[r, j], 0.015**2 * np.eye(2)).pdf(
                centres) / k
    gmm = (1 - floor) * gmm + floor / (CELLS * cell**2)
    missing = np.isnan(s_field)
    s_log = np.where(missing, 0.0, stats.beta.logpdf(np.where(missing, 0.5, s_field),
                                                     [3.0, 2.0][t], 1))
    return (np.log(1 / CELLS) + np.log(1 / 2) + stats.beta.logpdf(i_field, 1, 2.5) + s_log
            + np.log(soft @ gmm))


def _steps(seed: int, count: int):
    """Evidence and inputs of ``count`` questions in a row, each changing a little of the
    last: I over all cells from a table of a few values (they repeat), S at a few cells of a
    few rows (missing values and a zero's sign among them), T, the templates and l1 on some
    rows."""
    rng = np.random.default_rng(seed)
    table = rng.uniform(0.01, 0.99, 7)
    i_field = table[rng.integers(0, 7, (ROWS, CELLS))]
    s_field = rng.uniform(0.01, 0.99, (ROWS, CELLS))
    s_field[1, :3] = np.nan
    s_field[2, 4] = 0.0
    t = rng.integers(0, 2, ROWS)
    templates = rng.uniform(0, 0.05, (ROWS, 2, 3, 2))
    l1 = rng.uniform(0.01, 0.99, ROWS)
    for step in range(count):
        yield i_field.copy(), s_field.copy(), t.copy(), templates.copy(), l1.copy()
        if step % 3 == 0:  # every cell
            i_field = table[rng.integers(0, 7, (ROWS, CELLS))]
        elif step % 3 == 1:  # a few cells
            i_field[rng.integers(0, ROWS, 3), rng.integers(0, CELLS, 3)] = rng.uniform(0, 1, 3)
        rows = rng.choice(ROWS, 2, replace=False)
        cells = rng.choice(CELLS, 2, replace=False)
        s_field[np.ix_(rows, cells)] = rng.uniform(0.01, 0.99, (2, 2))
        if step == 1:
            s_field[3, 5] = np.nan  # a value becomes missing
            s_field[2, 4] = -0.0  # the same number, another bit pattern
        if step == 3:
            s_field[1, 0] = 0.5  # a missing value becomes known
        t[rng.integers(0, ROWS)] ^= 1
        templates[rng.integers(0, ROWS)] += rng.normal(0, 0.003, (2, 3, 2))
        if step % 2:
            l1[rng.integers(0, ROWS)] = rng.uniform(0.01, 0.99)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_layout_asked_again_answers_as_a_program_asked_afresh_and_as_scipy(seed):
    program = bayesprog.load(PROGRAMS / "tar.yaml")
    for step, (i_field, s_field, t, templates, l1) in enumerate(_steps(seed, 8)):
        evidence = {"T": np.array(["T1", "T2"])[t], "I": i_field, "S": s_field}
        l2 = 0.3 if step < 5 else 0.6  # an input without rows, changed once
        inputs = {"templates": templates, "l1": l1, "l2": l2}
        kept = _ask(program, "P(O | T, I, S)", evidence, inputs=inputs)
        fresh = _ask(bayesprog.load(PROGRAMS / "tar.yaml"), "P(O | T, I, S)", evidence,
                     inputs=inputs)
        assert np.array_equal(kept.probabilities, fresh.probabilities)
        assert np.array_equal(kept.log_evidence, fresh.log_evidence)
        for row in range(ROWS):
            log_ref = tar_reference(t[row], i_field[row], s_field[row], templates[row],
                                    l1[row], l2)
            np.testing.assert_allclose(kept.probabilities[row], softmax(log_ref), rtol=1e-9,
                                       atol=1e-15)
            np.testing.assert_allclose(kept.log_evidence[row], logsumexp(log_ref), rtol=1e-9)


def test_the_map_of_a_layout_asked_again_is_the_fresh_map_with_the_same_ties():
    program = bayesprog.load(PROGRAMS / "tar.yaml")
    for i_field, s_field, t, templates, l1 in _steps(5, 6):
        # a flat I: many cells tie, the generators break the ties
        evidence = {"T": np.array(["T1", "T2"])[t], "I": np.full_like(i_field, 0.5),
                    "S": np.where(np.isnan(s_field), np.nan, 0.5)}
        inputs = {"templates": templates * 0 + 0.02, "l1": l1 * 0 + 0.5, "l2": 0.5}
        rngs = [np.random.default_rng(r) for r in range(ROWS)]
        again = [np.random.default_rng(r) for r in range(ROWS)]
        kept = program.ask("next", evidence, inputs=inputs, rng=rngs)
        fresh = bayesprog.load(PROGRAMS / "tar.yaml").ask("next", evidence, inputs=inputs,
                                                          rng=again)
        assert np.array_equal(kept.indices, fresh.indices)
        assert np.array_equal(kept.ties, fresh.ties)


def test_soft_evidence_given_with_the_question_and_one_state_for_every_row():
    program = bayesprog.load(PROGRAMS / "tar.yaml")
    rng = np.random.default_rng(6)
    likelihoods = rng.uniform(0.1, 1, (ROWS, 2))
    for step, (i_field, s_field, _, templates, l1) in enumerate(_steps(6, 6)):
        task = "T1" if step < 3 else "T2"  # one state for all rows, changed once
        if step == 2:
            likelihoods[1] = rng.uniform(0.1, 1, 2)  # a row of the soft evidence
        soft = {"R": likelihoods if step != 4 else np.array([0.2, 0.8])}
        evidence = {"T": task, "I": i_field, "S": s_field}
        inputs = {"templates": templates, "l1": l1, "l2": 0.3}
        kept = _ask(program, "P(O | T, I, S)", evidence, inputs=inputs, soft=soft)
        fresh = _ask(bayesprog.load(PROGRAMS / "tar.yaml"), "P(O | T, I, S)", evidence,
                     inputs=inputs, soft=soft)
        assert np.array_equal(kept.probabilities, fresh.probabilities)
        for row in range(ROWS):
            given = np.broadcast_to(soft["R"], (ROWS, 2))[row]
            # soft evidence on R multiplies the sub-program's likelihood: as if l-terms and it
            log_ref = tar_reference(int(task == "T2"), i_field[row], s_field[row],
                                    templates[row], l1[row], 0.3, given)
            np.testing.assert_allclose(kept.probabilities[row], softmax(log_ref), rtol=1e-9,
                                       atol=1e-15)


def test_a_caller_that_changes_its_arrays_after_asking_changes_nothing_kept():
    program = bayesprog.load(PROGRAMS / "tar.yaml")
    steps = list(_steps(3, 3))
    i_field, s_field, t, templates, l1 = steps[0]
    evidence = {"T": np.array(["T1", "T2"])[t], "I": i_field, "S": s_field}
    inputs = {"templates": templates, "l1": l1, "l2": 0.3}
    _ask(program, "P(O | T, I, S)", evidence, inputs=inputs)
    # the same arrays, changed in place: the next question reads their new values
    s_field[:, :] = 0.25
    templates += 0.01
    l1[:] = 0.7
    kept = _ask(program, "P(O | T, I, S)", evidence, inputs=inputs)
    fresh = _ask(bayesprog.load(PROGRAMS / "tar.yaml"), "P(O | T, I, S)", evidence,
                 inputs=inputs)
    assert np.array_equal(kept.probabilities, fresh.probabilities)


def test_other_batch_sizes_in_between_are_answered_afresh():
    program = bayesprog.load(PROGRAMS / "tar.yaml")
    for i_field, s_field, t, templates, l1 in _steps(4, 5):
        for rows in (slice(None), slice(0, 2), slice(3, 4)):
            evidence = {"T": np.array(["T1", "T2"])[t[rows]], "I": i_field[rows],
                        "S": s_field[rows]}
            inputs = {"templates": templates[rows], "l1": l1[rows], "l2": 0.3}
            kept = _ask(program, "P(O | T, I, S)", evidence, inputs=inputs)
            fresh = _ask(bayesprog.load(PROGRAMS / "tar.yaml"), "P(O | T, I, S)", evidence,
                         inputs=inputs)
            assert np.array_equal(kept.probabilities, fresh.probabilities)


# the memo of log densities by value ----------------------------------------------------------------
def _log1p_minus(values: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.stack([np.log1p(-values), 2 * values], axis=1)


def test_the_memo_gives_what_it_was_given_for_each_value_to_the_bit():
    rng = np.random.default_rng(0)
    table = np.concatenate([rng.uniform(0, 1, 50), [np.nan, 0.0, -0.0, 1.0]])
    memo = Memo(2)
    computed = []

    def compute(values):
        computed.append(values.size)
        return _log1p_minus(values)

    for _ in range(4):
        values = table[rng.integers(0, len(table), 3000)]
        found = memo.lookup(values, compute)
        expected = _log1p_minus(values)
        assert found.shape == (3000, 2)
        assert np.array_equal(found.view(np.uint64), expected.view(np.uint64))
    assert computed[0] <= len(table)  # each distinct value once (-0.0 and 0.0 apart)
    assert sum(computed) == computed[0]  # and never again


def test_the_memo_grows_then_starts_again_and_stops_for_values_that_do_not_repeat():
    rng = np.random.default_rng(1)
    memo = Memo(2)
    values = rng.uniform(0, 1, 5000)  # more than its first table holds
    assert np.array_equal(memo.lookup(values, _log1p_minus), _log1p_minus(values))
    assert memo.count == 5000 and memo.keys.size > 5000
    assert np.array_equal(memo.lookup(values, lambda v: pytest.fail("all kept")),
                          _log1p_minus(values))
    for _ in range(3):  # new values each time: more than it keeps, found seldom
        values = rng.uniform(0, 1, 50_000)
        assert np.array_equal(memo.lookup(values, _log1p_minus), _log1p_minus(values))
    assert not memo.useful


SENSOR = """
bayesprog: 1
variables:
  M: {states: [m0, m1, m2]}
  E: {continuous: [-.inf, .inf]}
decomposition:
  - {term: P(M), form: uniform}
  - {term: P(E | M), form: normal, mean: {m0: 0.1, m1: 0.5, m2: 0.9}, sigma: 0.2}
"""


def test_readings_new_on_every_row_are_answered_afresh_and_alike():
    # nothing to reuse: after a few such questions the layout keeps nothing for a while, then
    # tries again; every answer is the fresh one, and scipy's
    program = bayesprog.loads(SENSOR)
    rng = np.random.default_rng(8)
    layouts = program.inference_cache.layouts
    resting = []
    for _ in range(45):
        e = rng.uniform(0, 1, ROWS)
        prior = rng.dirichlet(np.ones(3), ROWS)
        kept = _ask(program, "P(M | E)", {"E": e}, soft={"M": prior})
        fresh = _ask(bayesprog.loads(SENSOR), "P(M | E)", {"E": e}, soft={"M": prior})
        assert np.array_equal(kept.probabilities, fresh.probabilities)
        log_ref = np.log(prior) + stats.norm.logpdf(e[:, None], [0.1, 0.5, 0.9], 0.2)
        np.testing.assert_allclose(kept.probabilities, softmax(log_ref, axis=1), rtol=1e-9)
        (layout,) = layouts.values()
        resting.append(layout.prepared["contraction"].recurring.resting)
    assert max(resting) > 0 and resting[-1] < max(resting)


def taking_turns(targets) -> None:
    """Runs each of ``targets`` on a thread of its own, the threads taking turns as often as
    the interpreter lets them (its switch interval lowered meanwhile, and restored)."""
    threads = [threading.Thread(target=target) for target in targets]
    switch = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    finally:
        sys.setswitchinterval(switch)


def test_threads_asking_one_program_at_once_get_the_answers_asked_alone():
    """Two threads sharing a program (threaded workers of a cluster) each ask a run of
    questions of one layout: what the layout keeps, and the memo of its field, are taken by
    one question at a time, so each answer is the one a program asked alone gives."""

    runs = {seed: list(_steps(seed, 12)) for seed in (3, 4)}

    def question(step):
        i_field, s_field, t, templates, l1 = step
        return ({"T": np.array(["T1", "T2"])[t], "I": i_field, "S": s_field},
                {"templates": templates, "l1": l1, "l2": 0.3})

    alone = {seed: [_ask(bayesprog.load(PROGRAMS / "tar.yaml"), "P(O | T, I, S)",
                         question(step)[0], inputs=question(step)[1]) for step in steps]
             for seed, steps in runs.items()}
    for _ in range(3):
        shared = bayesprog.load(PROGRAMS / "tar.yaml")
        got: dict[int, list] = {}
        errors: list[BaseException] = []

        def ask(seed, into=got, shared=shared, errors=errors):
            try:
                into[seed] = [shared.ask("P(O | T, I, S)", evidence, inputs=inputs)
                              for evidence, inputs in map(question, runs[seed])]
            except BaseException as exc:  # noqa: BLE001  (reported below)
                errors.append(exc)

        taking_turns([lambda seed=seed: ask(seed) for seed in runs])
        assert not errors
        for seed in runs:
            for mine, reference in zip(got[seed], alone[seed], strict=True):
                assert np.array_equal(mine.probabilities, reference.probabilities)
                assert np.array_equal(mine.log_evidence, reference.log_evidence)
