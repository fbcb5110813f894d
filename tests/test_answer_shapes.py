"""Every answer's ``log_evidence`` has the answer's ``batch_shape``: one number per row of
evidence (per step and sequence over time, per sequence for the most likely one), so that
``float(answer.log_evidence)`` reads the evidence of a question asked once. Walked over every
question kind of every bundled program: its named questions, their MAP and the probability of
their event, the approximate methods that answer them, the marginals, and the questions over
time of the programs that repeat per step."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import bayesprog
from bayesprog.errors import QuestionError
from bayesprog.inference.answers import MapResult
from bayesprog.support import bundled

PROGRAMS = sorted(b.name for b in bundled.listing() if b.kind == "program")
#: the approximate methods, each asked where it answers (a refusal says it does not)
APPROXIMATE = ("lw", "gibbs", "lbp", "grid")
ROWS = 2

# a program over time with real states: the Kalman filter and the particle filter
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
"""


def inputs_for(program: bayesprog.Program) -> dict[str, np.ndarray]:
    """Each runtime input at 0.5 (a free dimension of size 2)."""
    out = {}
    for name, decl in program.inputs.items():
        shape = [program.variables[a].card for a in decl.axes]
        shape += [d if isinstance(d, int) else 2 for d in decl.event]
        out[name] = np.full(shape, 0.5)
    return out


def values_of(program: bayesprog.Program, names, rows: int | None, seed: int = 0,
              inputs=None) -> dict:
    """Values of ``names`` drawn from the program (a field: uniform inside its support; a
    variable without a term: one of its states, or the middle of its support), one per row,
    or one value when ``rows`` is None."""
    rng = np.random.default_rng(seed)
    given = {}
    for name in program.conditioning:
        var = program.variables[name]
        given[name] = (var.states[rng.integers(var.card)] if var.is_discrete
                       else float(np.clip(0.0, var.low, var.high)))
    draws = program.sample(rows or 1, given or None, rng=seed, inputs=inputs or None)
    out = {}
    for name in names:
        var = program.variables[name]
        if name in given:
            column = np.array([given[name]] * (rows or 1), dtype=object)
        elif getattr(var, "index", None) is not None:  # a field: one value per index state
            size = (rows or 1, program.variables[var.index].card)
            low, high = (max(var.low, -3.0), min(var.high, 3.0))
            column = rng.uniform(low + 0.1 * (high - low), high - 0.1 * (high - low), size)
        else:
            column = draws[name].to_numpy()
        out[name] = column if rows else column[0]
    return out


def check(answer, batch: tuple[int, ...]) -> None:
    assert np.shape(answer.log_evidence) == answer.batch_shape == batch, (
        answer.question, np.shape(answer.log_evidence), answer.batch_shape, batch)
    if batch == ():
        float(answer.log_evidence)


def questions_of(program: bayesprog.Program) -> list:
    """The named questions of one step, or one of the last variable given the others for a
    program that names none."""
    named = [q for q in program.questions.values()
             if q.kind not in ("filter", "smooth", "sequence")]
    if named:
        return named
    names = list(program.variables)
    return [program.question(f"P({names[-1]} | {', '.join(names[:-1])})")]


@pytest.mark.parametrize("name", PROGRAMS)
def test_every_answer_of_a_bundled_program_has_one_log_evidence_per_row(name):
    answered = walk(name)
    over_time = bayesprog.load(bundled.find(name, "program")).time is not None
    assert answered >= {"posterior", "probability"} | (
        {"filter", "smooth", "sequence"} if over_time else set()), answered


def test_every_approximate_method_is_walked():
    answered = set().union(*(walk(name) for name in ("examples/sprinkler",
                                                      "examples/range_beacon")))
    assert answered >= {"map", "probability", *APPROXIMATE}, answered


def walk(name: str) -> set[str]:
    """Every kind of question asked of the bundled program ``name``, each answer checked; the
    kinds and methods that answered."""
    program = bayesprog.load(bundled.find(name, "program"))
    inputs = inputs_for(program) or None
    answered = set()
    if program.time is not None:  # over steps, then the questions of one step
        answered |= ask_over_time(program, inputs)
    for named in questions_of(program):
        # as written, asked once; and without its values, for a batch of rows
        left, right = named.expression.left, named.expression.right
        unvalued = program.question(f"P({' '.join(left)}" + (f" | {', '.join(right)})"
                                                             if right else ")"))
        for question, rows, batch in ((named, None, ()), (unvalued, ROWS, (ROWS,))):
            expr = question.expression
            known = [v for v in expr.right if v not in expr.values]
            evidence = values_of(program, known, rows, inputs=inputs)
            if not known:
                batch = ()
            check(program.ask(question, evidence, inputs=inputs), batch)
            answered.add(question.kind)
            if all(program.variables[v].is_discrete for v in expr.left):
                best = program.ask(question, evidence, inputs=inputs, kind="map")
                assert isinstance(best, MapResult)
                check(best, batch)
                answered.add("map")
            event = values_of(program, expr.left, rows, seed=1, inputs=inputs)
            check(program.ask(question, {**evidence, **event}, inputs=inputs,
                              kind="probability"), batch)
            answered.add("probability")
            for method in APPROXIMATE:
                try:
                    answer = program.ask(question, evidence, inputs=inputs, method=method,
                                         samples=300, bins=16, burn_in=20)
                except QuestionError:  # the method does not answer this question
                    continue
                check(answer, batch)
                answered.add(method)
            if all(program.variables[v].is_discrete for v in expr.left) and not soft_only(
                    program):
                every = {k: v for k, v in {**expr.values, **evidence}.items()
                         if program.variables[k].is_discrete}
                for marginal in program.marginals(every, inputs=inputs).values():
                    check(marginal, batch if set(every) - set(expr.values) else ())
    return answered


def soft_only(program: bayesprog.Program) -> bool:
    """Programs the junction tree of ``marginals`` does not take (real or field variables)."""
    return any(not v.is_discrete for v in program.variables.values())


def ask_over_time(program: bayesprog.Program, inputs) -> set[str]:
    """Filter, smooth and sequence, over three steps, for one sequence and a batch of two."""
    (previous, state), = program.time
    observed = [v for v in program.variables if v not in (previous, state)]
    steps = 3
    draws = [values_of(program, observed, ROWS, seed=t, inputs=inputs) for t in range(steps)]
    question = f"P({state} | {', '.join(observed)})"
    for batched in (False, True):
        evidence = {v: np.stack([d[v] if batched else d[v][0] for d in draws])
                    for v in observed}
        batch = (ROWS,) if batched else ()
        for kind in ("filter", "smooth", "sequence"):
            answer = program.ask(question, evidence, kind=kind, inputs=inputs)
            check(answer, batch if kind == "sequence" else (steps, *batch))
        for named in program.questions.values():
            answer = program.ask(named.name, evidence, inputs=inputs)
            check(answer, batch if named.kind == "sequence" else (steps, *batch))
    return {"filter", "smooth", "sequence"}


def test_questions_over_real_states_have_one_log_evidence_per_step_and_sequence():
    program = bayesprog.loads(CART)
    for evidence, batch in (([1.0, 2.1, 2.0], ()), ([[1.0, 0.2], [2.1, 0.4], [2.0, 1.0]],
                                                    (2,))):
        for kind, method in (("filter", None), ("smooth", None), ("filter", "pf"),
                             ("smooth", "pf")):
            answer = program.ask("P(X | Y)", {"Y": evidence}, kind=kind, method=method,
                                 samples=200, rng=0)
            check(answer, (3, *batch))


def test_a_real_answer_asked_once_reads_its_evidence_as_one_number():
    program = bayesprog.load(bundled.find("kalman", "program"))
    answer = program.ask("filter")
    assert answer.batch_shape == () and np.shape(answer.log_evidence) == ()
    # log N(z; mean, var) of the three readings, the joint of Z1..Z3 by hand
    a = np.tril(np.ones((3, 3)))  # X_t = X0 + t + noise of each step
    cov = np.ones((3, 3)) + a @ np.diag([0.25] * 3) @ a.T + 0.64 * np.eye(3)
    z = np.array([1.2, 1.9, 3.4]) - np.array([1.0, 2.0, 3.0])
    expected = -0.5 * (z @ np.linalg.solve(cov, z) + np.linalg.slogdet(cov)[1]
                       + 3 * np.log(2 * np.pi))
    assert float(answer.log_evidence) == pytest.approx(expected, rel=1e-10)


def test_the_most_likely_sequence_reads_the_evidence_of_all_its_steps():
    program = bayesprog.load(bundled.find("umbrella", "program"))
    observed = ["yes", "no", "yes"]
    before, move = np.array([0.5, 0.5]), np.array([[0.7, 0.3], [0.3, 0.7]])
    sensor = np.array([[0.9, 0.1], [0.2, 0.8]])  # P(yes, no | rain), P(. | dry)
    y = [0 if o == "yes" else 1 for o in observed]
    total = 0.0  # P(y_1..T): every sequence of the weather, the day before summed out
    for path in itertools.product((0, 1), repeat=len(y)):
        p = sum(before[b] * move[b, path[0]] for b in (0, 1)) * sensor[path[0], y[0]]
        for t in range(1, len(y)):
            p *= move[path[t - 1], path[t]] * sensor[path[t], y[t]]
        total += p
    answer = program.ask("most_likely", {"Umbrella": observed})
    assert float(answer.log_evidence) == pytest.approx(np.log(total), rel=1e-12)
    data = answer.to_json()
    assert data["log_evidence"] == pytest.approx(np.log(total), rel=1e-12)
    filtered = program.ask("today", {"Umbrella": observed})
    assert data["log_evidence_per_step"] == pytest.approx(filtered.log_evidence.tolist())
