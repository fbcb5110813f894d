"""Threads sharing a program (the threaded workers of a Dask cluster, which share the loaded
scenarios): a layout's question asked again reuses what the layout's last question computed
(:mod:`bayesprog.inference.recurring`), changing those arrays in place. The operands a question
contracts are such arrays, so what it keeps is left for the next question only once it has
contracted them: a question of another thread asked in between computes afresh, and every
answer is the one the question asked alone gives, to the bit."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np

import bayesprog
from bayesprog.inference import contraction
from tests.test_recurring import taking_turns

PROGRAMS = Path(__file__).parent / "programs"
ROWS = 6

#: Two cue fields over a grid: their factors are one product over O, kept from question to
#: question and computed again on the rows whose fields changed.
FIELDS = """
bayesprog: 1
variables:
  O: {grid: {shape: [4, 5], cell: 0.01}}
  T: {states: [T1, T2]}
  I: {continuous: [0, 1], indexed_by: O}
  S: {continuous: [0, 1], indexed_by: O}
decomposition:
  - {term: P(O), form: uniform}
  - {term: P(T), form: uniform}
  - {term: P(I | O), form: beta, a: 1, b: 2.5}
  - {term: "P(S | O, T)", form: beta, a: {T1: 3, T2: 2}, b: 1}
"""


def _tar_steps(seed: int, count: int) -> list[tuple[dict, dict]]:
    """``count`` questions of tests/programs/tar.yaml in a row (evidence, inputs), each
    changing a few cells of a few rows of the last."""
    rng = np.random.default_rng(seed)
    cells = 20
    i_field = rng.uniform(0.01, 0.99, (ROWS, cells))
    s_field = rng.uniform(0.01, 0.99, (ROWS, cells))
    t = rng.integers(0, 2, ROWS)
    templates = rng.uniform(0, 0.05, (ROWS, 2, 3, 2))
    l1 = rng.uniform(0.01, 0.99, ROWS)
    out = []
    for _ in range(count):
        out.append(({"T": np.array(["T1", "T2"])[t], "I": i_field.copy(),
                     "S": s_field.copy()},
                    {"templates": templates.copy(), "l1": l1.copy(), "l2": 0.3}))
        rows = rng.choice(ROWS, 2, replace=False)
        s_field[rows, rng.integers(0, cells, 2)] = rng.uniform(0.01, 0.99, 2)
        i_field[rng.integers(0, ROWS), rng.integers(0, cells)] = rng.uniform(0.01, 0.99)
    return out


def _one_row_changed(evidence: dict, row: int) -> dict:
    """``evidence`` with the I field of one row changed (the others as they are)."""
    other = dict(evidence)
    other["I"] = evidence["I"].copy()
    other["I"][row] = 1.0 - other["I"][row]
    return other


def test_a_question_asked_between_anothers_operands_and_its_contraction_changes_nothing(
        monkeypatch):
    """The interleaving of two threads made deterministic: a question of the layout is asked
    while another has its operands and has not contracted them yet (as a thread sharing the
    program would, between the two). It differs from that question on one row only, so it
    would reuse what the first question computed, changed in place on that row."""
    program = bayesprog.load(PROGRAMS / "tar.yaml")
    steps = _tar_steps(11, 4)
    for evidence, inputs in steps[:3]:  # the layout planned, its factors kept
        program.ask("P(O | T, I, S)", evidence, inputs=inputs)
    evidence, inputs = steps[3]
    between = _one_row_changed(evidence, row=2)
    real = contraction.contract
    asked: list = []

    def contract(on, *args, **kwargs):
        if on is program and not asked:  # the other thread's question, once
            asked.append(None)
            asked[0] = program.ask("P(O | T, I, S)", between, inputs=inputs)
        return real(on, *args, **kwargs)

    monkeypatch.setattr(contraction, "contract", contract)
    first = program.ask("P(O | T, I, S)", evidence, inputs=inputs)
    monkeypatch.setattr(contraction, "contract", real)
    assert len(asked) == 1
    for got, (e, i) in ((first, (evidence, inputs)), (asked[0], (between, inputs))):
        alone = bayesprog.load(PROGRAMS / "tar.yaml").ask("P(O | T, I, S)", e, inputs=i)
        assert np.array_equal(got.probabilities, alone.probabilities)
        assert np.array_equal(got.log_evidence, alone.log_evidence)
    assert not np.array_equal(first.probabilities[2], asked[0].probabilities[2])
    # what the layout keeps still serves the questions after them
    again = program.ask("P(O | T, I, S)", evidence, inputs=inputs)
    assert np.array_equal(again.probabilities, first.probabilities)


def test_threads_asking_nearly_the_same_questions_of_one_program_get_their_own_answers(
        monkeypatch):
    """Two threads ask one program the same run of questions but for one row (a cluster's
    workers exploring two tasks from the same start cells): each takes over what the other's
    last question kept and changes it on that row. A thread gives the interpreter up between
    its operands and their contraction (as one that loses its turn there does), and the
    threads take turns as often as they can: each answer is still the one asked alone."""
    rng = np.random.default_rng(7)
    cells, count = 20, 20
    runs: dict[int, list[dict]] = {0: [], 1: []}
    i_field, s_field = rng.uniform(0.01, 0.99, (2, ROWS, cells))
    for _ in range(count):
        evidence = {"T": "T1", "I": i_field.copy(), "S": s_field.copy()}
        runs[0].append(evidence)
        runs[1].append(_one_row_changed(evidence, row=int(rng.integers(0, ROWS))))
        s_field[rng.integers(0, ROWS, 2), rng.integers(0, cells, 2)] = rng.uniform(0.01, 0.99, 2)
    alone = {k: [bayesprog.loads(FIELDS).ask("P(O | T, I, S)", e) for e in run]
             for k, run in runs.items()}
    real = contraction.contract

    def contract(*args, **kwargs):
        time.sleep(1e-4)  # the other thread's turn
        return real(*args, **kwargs)

    monkeypatch.setattr(contraction, "contract", contract)
    for _ in range(4):
        shared = bayesprog.loads(FIELDS)
        got: dict[int, list] = {}
        errors: list[BaseException] = []
        start = threading.Barrier(len(runs))

        def ask(k: int, shared=shared, got=got, errors=errors, start=start) -> None:
            try:
                start.wait()
                got[k] = [shared.ask("P(O | T, I, S)", e) for e in runs[k]]
            except BaseException as exc:  # noqa: BLE001  (reported below)
                errors.append(exc)

        taking_turns([lambda k=k: ask(k) for k in runs])
        assert not errors
        for k in runs:
            for step, (mine, reference) in enumerate(zip(got[k], alone[k], strict=True)):
                assert np.array_equal(mine.probabilities, reference.probabilities), (k, step)
                assert np.array_equal(mine.log_evidence, reference.log_evidence), (k, step)
