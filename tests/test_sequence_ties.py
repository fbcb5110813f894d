"""The most likely sequence reports its ties as a MAP question does: the number of sequences
as probable as the one shown (in ``ties``, in ``--json`` and as "(N tied)"), and one of them
drawn by the seed. Each count is checked against the enumeration of every sequence."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from scipy import stats

import bayesprog
from bayesprog.cli import main


def chain_text(prior, transition, emission) -> str:
    """A two-state chain: ``transition[i][j] = P(S = j | S_before = i)``, ``emission[j]`` the
    row of ``P(O | S = j)`` over ``x``, ``y``."""
    return ("bayesprog: 1\nname: chain\nvariables:\n  S_before: {states: [a, b]}\n"
            "  S: {states: [a, b]}\n  O: {states: [x, y]}\ntime: {previous: {S_before: S}}\n"
            "decomposition:\n"
            f"  - {{term: P(S_before), form: table, table: {list(prior)}}}\n"
            f"  - {{term: P(S | S_before), form: table, table: {[list(r) for r in transition]}}}\n"
            f"  - {{term: P(O | S), form: table, table: {[list(r) for r in emission]}}}\n")


def chain(prior, transition, emission) -> bayesprog.Program:
    return bayesprog.loads(chain_text(prior, transition, emission))


def enumerate_sequences(prior, transition, emission, observed):
    """Every sequence of states and ``P(sequence | observations)``, by the unrolled joint (the
    state before the first step summed out)."""
    prior, transition, emission = (np.asarray(a, float) for a in (prior, transition, emission))
    weights = {}
    for path in itertools.product(range(len(prior)), repeat=len(observed)):
        p = 0.0
        for start in range(len(prior)):
            q, before = prior[start], start
            for x, o in zip(path, observed, strict=True):
                q *= transition[before, x] * emission[x, o]
                before = x
            p += q
        weights[path] = p
    total = sum(weights.values())
    return {path: w / total for path, w in weights.items()}


def tied_best(weights):
    """The sequences whose probability is the best's within MAP's relative tolerance."""
    best = max(weights.values())
    return {path for path, w in weights.items() if w >= best * (1 - 1e-12)}


UNIFORM = ([0.5, 0.5], [[0.5, 0.5], [0.5, 0.5]], [[0.5, 0.5], [0.5, 0.5]])
STICKY = ([0.5, 0.5], [[0.8, 0.2], [0.2, 0.8]], [[0.5, 0.5], [0.5, 0.5]])  # aaa and bbb tie
CLEAR = ([0.6, 0.4], [[0.7, 0.3], [0.2, 0.8]], [[0.9, 0.1], [0.3, 0.7]])


@pytest.mark.parametrize(("tables", "expected"), [(UNIFORM, 8), (STICKY, 2), (CLEAR, 1)],
                         ids=["all-tied", "two-tied", "unique"])
def test_the_ties_of_a_sequence_are_counted_as_by_enumeration(tables, expected):
    program = chain(*tables)
    observed = [0, 0, 1]
    weights = enumerate_sequences(*tables, observed)
    tied = tied_best(weights)
    assert len(tied) == expected  # the model is what its name says
    for seed in range(5):
        answer = program.ask("P(S | O)", {"O": ["x", "x", "y"]}, kind="sequence", rng=seed)
        assert int(answer.ties) == expected
        assert tuple(answer.indices[:, 0]) in tied
        assert float(answer.probability) == pytest.approx(max(weights.values()), rel=1e-10)


def test_the_sequence_shown_is_drawn_uniformly_among_the_tied_ones():
    # 8 tied sequences, one per seed for 800 seeds: a chi-square test of uniformity at a
    # false-failure budget of 1e-3 (the seeds are fixed: it passes or fails alike every run)
    program = chain(*UNIFORM)
    chosen = [tuple(program.ask("P(S | O)", {"O": ["x", "x", "y"]}, kind="sequence",
                                rng=seed).indices[:, 0]) for seed in range(800)]
    counts = [chosen.count(path) for path in itertools.product(range(2), repeat=3)]
    assert min(counts) > 0
    assert stats.chisquare(counts).pvalue > 1e-3


def test_a_sequence_of_one_step_is_the_map_of_that_step_with_the_same_seed():
    # the same rule as a MAP question: the same tied candidates, the same draw of the seed
    program = chain(*UNIFORM)
    for seed in range(10):
        sequence = program.ask("P(S | O)", {"O": ["x"]}, kind="sequence", rng=seed)
        best = program.ask("P(S | O=x)", kind="map", rng=seed)
        assert int(sequence.ties) == int(best.ties) == 2
        assert sequence.assignment["S"].tolist() == [best.assignment["S"]]


def test_each_sequence_of_a_batch_has_its_ties_and_its_own_generator():
    program = chain(*STICKY)
    observed = np.array([["x", "x"], ["x", "x"], ["y", "x"]])  # [T=3, batch=2]
    clear = chain(*CLEAR)
    both = program.ask("P(S | O)", {"O": observed}, kind="sequence",
                       rng=[np.random.default_rng(5), np.random.default_rng(6)])
    assert both.ties.tolist() == [2, 2]
    for b, seed in enumerate((5, 6)):
        alone = program.ask("P(S | O)", {"O": list(observed[:, b])}, kind="sequence",
                            rng=np.random.default_rng(seed))
        assert both.indices[:, b, 0].tolist() == alone.indices[:, 0].tolist()
    assert clear.ask("P(S | O)", {"O": observed}, kind="sequence").ties.tolist() == [1, 1]


def test_a_count_past_what_a_float_holds_is_exact():
    program = chain(*UNIFORM)
    for steps in (60, 70):  # 2**60 fits in int64 and not exactly in a float; 2**70 in neither
        answer = program.ask("P(S | O)", {"O": ["x"] * steps}, kind="sequence", rng=1)
        assert int(answer.ties) == 2**steps
        assert json.loads(json.dumps(answer.to_json()))["ties"] == 2**steps


TWO_CHAINS = """\
bayesprog: 1
name: two_chains
variables:
  A_before: {states: [a0, a1]}
  B_before: {states: [b0, b1]}
  A: {states: [a0, a1]}
  B: {states: [b0, b1]}
  O: {states: [o0, o1]}
time:
  previous: {A_before: A, B_before: B}
decomposition:
  - {term: P(A_before), form: table, table: [0.5, 0.5]}
  - {term: P(B_before), form: table, table: [0.5, 0.5]}
  - {term: P(A | A_before), form: table, table: {a0: [0.9, 0.1], a1: [0.1, 0.9]}}
  - {term: P(B | B_before), form: table, table: {b0: [0.5, 0.5], b1: [0.5, 0.5]}}
  - term: P(O | A, B)
    form: table
    table: {a0: {b0: [0.5, 0.5], b1: [0.5, 0.5]}, a1: {b0: [0.5, 0.5], b1: [0.5, 0.5]}}
"""


def test_the_ties_of_a_joint_sequence_of_several_states_are_counted_as_by_enumeration():
    program = bayesprog.loads(TWO_CHAINS)
    # the joint state (a, b) as one chain of four states
    move_a = np.array([[0.9, 0.1], [0.1, 0.9]])
    transition = np.kron(move_a, np.full((2, 2), 0.5))
    weights = enumerate_sequences(np.full(4, 0.25), transition, np.full((4, 2), 0.5), [0, 1, 0])
    tied = tied_best(weights)
    assert len(tied) == 2 * 2**3  # A stays in a0 or in a1; B is anything
    answer = program.ask("P(A B | O)", {"O": ["o0", "o1", "o0"]}, kind="sequence", rng=3)
    assert int(answer.ties) == len(tied)
    joint = tuple(int(a) * 2 + int(b) for a, b in answer.indices)
    assert joint in tied


def test_the_command_line_reports_the_ties_of_a_sequence(tmp_path, capsys):
    path = tmp_path / "tied.yaml"
    path.write_text(chain_text(*UNIFORM))
    assert main(["query", str(path), "P(S | O)", "--over-time", "sequence",
                 "--evidence", "O=x,x,y"]) == 0
    out = capsys.readouterr().out
    assert "probability of the sequence: 0.125   (8 tied)" in out
    assert main(["query", str(path), "P(S | O)", "--over-time", "sequence",
                 "--evidence", "O=x,x,y", "--json", "--seed", "4"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["ties"] == 8 and data["method"] == "sequence"
    again = bayesprog.load(path).ask("P(S | O)", {"O": ["x", "x", "y"]}, kind="sequence",
                                     rng=4)
    assert data["map"]["S"] == again.assignment["S"].tolist()
    path.write_text(chain_text(*CLEAR))
    assert main(["query", str(path), "P(S | O)", "--over-time", "sequence",
                 "--evidence", "O=x,x,y", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ties"] == 1
    assert main(["query", str(path), "P(S | O)", "--over-time", "sequence",
                 "--evidence", "O=x,x,y"]) == 0
    assert "tied" not in capsys.readouterr().out

