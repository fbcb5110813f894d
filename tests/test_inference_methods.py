"""The inference layer's methods, one by one, and the cost model that picks among them.

Each method is forced on the same questions and checked against brute-force enumeration of the
joint distribution; the cost model is checked to pick the compiled table where it applies, the
contraction otherwise, and to use a newly registered method when it is the cheapest.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

import bayesprog
from bayesprog.inference import QuestionPlan, bind, registered_methods
from bayesprog.inference.cost import ranked
from bayesprog.inference.methods import base as methods_base
from bayesprog.inference.methods.base import Cost, Method, register_method


def chain(seed: int) -> tuple[bayesprog.Program, dict[str, np.ndarray]]:
    """A -> B -> C and A -> C, with random tables (A: 2, B: 3, C: 2 states)."""
    rng = np.random.default_rng(seed)
    pa = rng.dirichlet(np.ones(2))
    pb = rng.dirichlet(np.ones(3), size=2)  # [a, b]
    pc = rng.dirichlet(np.ones(2), size=(2, 3))  # [a, b, c]

    def rows(arr: np.ndarray) -> str:
        return "[" + ", ".join(f"{x:.17g}" for x in arr) + "]"

    text = f"""
bayesprog: 1
variables:
  A: {{states: [a0, a1]}}
  B: {{states: [b0, b1, b2]}}
  C: {{states: [c0, c1]}}
decomposition:
  - {{term: P(A), form: table, table: {rows(pa)}}}
  - term: P(B | A)
    form: table
    table: {{a0: {rows(pb[0])}, a1: {rows(pb[1])}}}
  - term: P(C | A, B)
    form: table
    table: {{{", ".join(f"a{i}: {{" + ", ".join(f"b{j}: {rows(pc[i, j])}" for j in range(3)) + "}"
                       for i in range(2))}}}
"""
    joint = pa[:, None, None] * pb[:, :, None] * pc
    return bayesprog.loads(text), {"joint": joint}


def brute(joint: np.ndarray, searched: str, known: dict[str, int]) -> np.ndarray:
    axes = "ABC"
    out = np.zeros(joint.shape[axes.index(searched)])
    for index in itertools.product(*map(range, joint.shape)):
        if all(index[axes.index(k)] == v for k, v in known.items()):
            out[index[axes.index(searched)]] += joint[index]
    return out / out.sum()


@pytest.mark.parametrize("method", ["table", "contraction"])
@pytest.mark.parametrize("seed", range(5))
def test_each_method_matches_brute_force(method, seed):
    program, tables = chain(seed)
    for searched, known in [("A", {"C": 1}), ("B", {"A": 0, "C": 0}), ("C", {}), ("A", {"B": 2})]:
        question = program.question(f"P({searched} | {', '.join(known)})" if known
                                    else f"P({searched})")
        plan = QuestionPlan(program, question, bind(program, question, known, None, None))
        answer = registered_methods()[method].posterior(plan)
        assert answer is not None
        np.testing.assert_allclose(answer.probabilities, brute(tables["joint"], searched, known),
                                   rtol=1e-12)


def test_the_methods_agree_on_a_batch():
    program, tables = chain(7)
    question = program.question("P(A | B, C)")
    evidence = {"B": np.array([0, 1, 2, 0]), "C": np.array([1, 1, 0, 0])}
    plan = QuestionPlan(program, question, bind(program, question, evidence, None, None))
    answers = [registered_methods()[m].posterior(plan) for m in ("table", "contraction")]
    np.testing.assert_allclose(answers[0].probabilities, answers[1].probabilities, rtol=1e-12)
    for row, (b, c) in enumerate(zip(evidence["B"], evidence["C"], strict=True)):
        np.testing.assert_allclose(answers[0].probabilities[row],
                                   brute(tables["joint"], "A", {"B": b, "C": c}), rtol=1e-12)


def switch(first: float, per_call: float, table) -> int:
    """The question of a layout at which the cost model first takes the table: the first
    question is answered without a plan (spending ``first``), each later one by contraction
    (``per_call``) until the table's setup is paid (ski rental)."""
    return next(k for k in range(1, 1000) if table.operations + table.fixed
                + max(table.setup - first - (k - 1) * per_call, 0.0) < per_call)


def test_cost_model_compiles_the_table_once_it_pays():
    """A table's compilation is a setup: the table is chosen once the questions of its layout
    have spent as much on contraction (ski rental), at once for a large batch."""
    program, _ = chain(1)
    question = program.question("P(A | C)")
    plan = QuestionPlan(program, question, bind(program, question, {"C": 0}, None, None))
    costs = {method.name: cost for method, cost in ranked(plan)}
    assert list(costs) == ["contraction", "table"]  # one question: no table yet
    per_call = costs["contraction"].operations + costs["contraction"].fixed
    table = costs["table"]
    assert table.setup > per_call
    used = [program.ask("P(A | C)", {"C": 0}).method]
    first = plan.layout.schedule.spent  # the first question's elimination
    assert 0 < first < table.setup
    expected = switch(first, per_call, table)
    used += [program.ask("P(A | C)", {"C": k % 2}).method for k in range(1, expected + 5)]
    assert used == ["contraction"] * expected + ["table"] * 5
    # a batch large enough pays for the table at once
    rows = 100_000
    contraction = costs["contraction"]
    assert (rows * contraction.operations + contraction.fixed
            > rows * table.operations + table.fixed + table.setup)
    fresh, _ = chain(1)
    assert fresh.ask("P(A | C)", {"C": [0, 1] * (rows // 2)}).method == "table"


def test_cost_model_skips_the_table_with_continuous_evidence():
    program = bayesprog.load("models/pi_per.yaml")
    question = program.question("P(M | E, C)")
    plan = QuestionPlan(program, question, bind(program, question, {"E": 0.5, "C": 0.1}, None,
                                                None))
    assert [method.name for method, _ in ranked(plan)] == ["contraction"]


def test_a_registered_method_is_used_when_it_is_the_cheapest(monkeypatch):
    monkeypatch.setattr(methods_base, "_METHODS", dict(methods_base._METHODS))
    calls = []
    program, _ = chain(2)
    before = program.ask("P(B | A)", {"A": "a1"}).probabilities  # ranked before registration
    assert before.tolist() != pytest.approx([1 / 3] * 3)

    @register_method
    class Uniform(Method):
        """Answers every posterior with a uniform, at no cost: only to see it chosen."""

        name = "uniform-for-test"
        exact = True  # the cost model picks among exact methods only

        def estimate(self, plan):
            return Cost(operations=0.0, memory=0.0)

        def posterior(self, plan):
            calls.append(plan.question)
            contraction = registered_methods()["contraction"].posterior(plan)
            contraction.probabilities[...] = 1.0 / contraction.probabilities.shape[-1]
            return contraction

    answer = program.ask("P(B | A)", {"A": "a1"})
    assert calls and answer.probabilities.tolist() == pytest.approx([1 / 3] * 3)
    # from the first question of a layout: a method from outside the package is ranked at once
    fresh, _ = chain(2)
    assert fresh.ask("P(B | A)", {"A": "a1"}).method == "uniform-for-test"


def test_one_row_and_batched_answers_agree_on_every_path():
    """The scalar paths for one row of evidence (prepared tables, compiled table) give what
    the batched path gives, to 1e-12, and brute force."""
    program, tables = chain(3)
    rows = [(b, c) for b in range(3) for c in range(2)]
    evidence = {"B": np.array([b for b, _ in rows]), "C": np.array([c for _, c in rows])}
    for method in ("table", "contraction"):
        batch = program.ask("P(A | B, C)", evidence, method=method)
        for row, (b, c) in enumerate(rows):
            one = program.ask("P(A | B, C)", {"B": f"b{b}", "C": f"c{c}"}, method=method)
            np.testing.assert_allclose(one.probabilities, batch.probabilities[row], rtol=1e-12)
            np.testing.assert_allclose(one.log_evidence, batch.log_evidence[row], rtol=1e-12)
            joint = tables["joint"][:, b, c]
            np.testing.assert_allclose(one.probabilities, joint / joint.sum(), rtol=1e-12)
            np.testing.assert_allclose(one.log_evidence, np.log(joint.sum()), rtol=1e-12)


def independent() -> tuple[bayesprog.Program, np.ndarray]:
    """A -> B and C -> D: P(A | D) does not depend on D's value."""
    rng = np.random.default_rng(5)
    pa, pc = rng.dirichlet(np.ones(3)), rng.dirichlet(np.ones(2))
    pb, pd = rng.dirichlet(np.ones(2), size=3), rng.dirichlet(np.ones(4), size=2)
    program = bayesprog.loads(f"""
bayesprog: 1
variables:
  A: {{states: [a0, a1, a2]}}
  B: {{states: [b0, b1]}}
  C: {{states: [c0, c1]}}
  D: {{states: [d0, d1, d2, d3]}}
decomposition:
  - {{term: P(A), form: table, table: {pa.tolist()}}}
  - {{term: P(B | A), form: table, table: {pb.tolist()}}}
  - {{term: P(C), form: table, table: {pc.tolist()}}}
  - {{term: P(D | C), form: table, table: {pd.tolist()}}}
""")
    joint = np.einsum("a,ab,c,cd->abcd", pa, pb, pc, pd)
    return program, joint


def test_an_independent_target_is_answered_from_its_own_terms():
    program, joint = independent()
    question = program.question("P(A | D)")
    plan = QuestionPlan(program, question, bind(program, question, {"D": "d1"}, None, None))
    assert [t.child.name for t in plan.terms] == ["A"]  # B is barren, D screened off
    assert plan.layout.constant and plan.layout.pruned
    marginal = joint.sum(axis=(1, 2, 3))
    for d in range(4):
        answer = program.ask("P(A | D)", {"D": f"d{d}"})
        np.testing.assert_allclose(answer.probabilities, marginal, rtol=1e-12)
        # the evidence's probability, computed when read, over every term it depends on
        np.testing.assert_allclose(answer.log_evidence, np.log(joint[..., d].sum()),
                                   rtol=1e-12)
    batch = program.ask("P(A | D)", {"D": ["d0", "d3", "d2"]})
    np.testing.assert_allclose(batch.probabilities, np.tile(marginal, (3, 1)), rtol=1e-12)
    np.testing.assert_allclose(batch.log_evidence,
                               np.log(joint.sum(axis=(0, 1, 2))[[0, 3, 2]]), rtol=1e-12)
    # the answer is fresh each time: changing one leaves the next intact
    answer = program.ask("P(A | D)", {"D": "d0"})
    answer.probabilities[:] = 0.0
    np.testing.assert_allclose(program.ask("P(A | D)", {"D": "d0"}).probabilities, marginal,
                               rtol=1e-12)


def test_the_contraction_runner_matches_numpy_einsum():
    """The step-by-step runner (einsum steps, aligned for large ones, tensordot for large
    matrix products, stacks of them) against one numpy einsum, on random equations, batched or
    not."""
    from bayesprog.inference.core import Contraction, contraction_path, equation

    rng = np.random.default_rng(11)
    names = "ABCDEFGH"
    kinds = set()
    for case in range(40):
        cards = {n: int(rng.integers(2, 17)) for n in names}
        operands = [tuple(rng.choice(list(names), size=int(rng.integers(1, 4)), replace=False))
                    for _ in range(int(rng.integers(2, 7)))]
        output = tuple(rng.choice(sorted({a for axes in operands for a in axes}), size=2,
                                  replace=False))
        batched = [bool(rng.integers(2)) for _ in operands] if case % 2 else None
        rows = 7 if batched and any(batched) else None
        eq = equation(operands, output, batched, bool(rows))
        arrays = [rng.random(((rows,) if b else ()) + tuple(cards[a] for a in axes))
                  for axes, b in zip(operands, batched or [False] * len(operands), strict=True)]
        _, info, _ = contraction_path(eq, [a.shape for a in arrays])
        expected = np.einsum(",".join(t for t in eq.split("->")[0].split(",")).translate(
            _letters(eq)) + "->" + eq.split("->")[1].translate(_letters(eq)), *arrays)
        runner = Contraction(info)
        kinds |= {kind for _, kind, _ in runner.steps}
        np.testing.assert_allclose(runner(*arrays), expected, rtol=1e-12)
    assert kinds == {"einsum", "aligned", "tensordot", "matmul"}  # every kind was run


def test_an_aligned_einsum_equals_numpy_einsum_whatever_the_layouts():
    """Small operands laid out in the largest's memory order give numpy einsum's answer, when
    the largest is itself a transposed view, with summed, kept and broadcast indices, and
    0-d operands."""
    from bayesprog.inference.core import aligned_einsum

    rng = np.random.default_rng(5)
    letters = "abcdefghijklmn"
    for _ in range(60):
        n = int(rng.integers(4, 13))
        big = "".join(letters[:n])
        cards = {s: int(rng.integers(1, 4)) for s in big}
        smalls = [tuple(rng.choice(list(big), size=int(rng.integers(0, 4)), replace=False))
                  for _ in range(int(rng.integers(1, 3)))]  # (a 0-d operand: a number)
        kept = [s for s in big if rng.random() < 0.7]
        output = "".join(rng.permutation(kept)) if rng.random() < 0.5 else "".join(kept)
        array = rng.random(tuple(cards[s] for s in big))
        if rng.random() < 0.5:  # the largest as a view in another memory order
            order = rng.permutation(n)
            array = np.ascontiguousarray(array.transpose(order)).transpose(np.argsort(order))
        others = [rng.random(tuple(cards[s] for s in t)) for t in smalls]
        subscripts = ",".join([big, *("".join(t) for t in smalls)]) + "->" + output
        np.testing.assert_allclose(aligned_einsum(subscripts, array, *others),
                                   np.einsum(subscripts, array, *others), rtol=1e-12,
                                   atol=1e-300)


def _letters(equation: str) -> dict[int, str]:
    """opt_einsum's symbols of ``equation`` as ASCII letters, for numpy's einsum."""
    used = sorted({c for c in equation if c not in ",->"})
    return {ord(c): "abcdefghijklmnopqrstuvwxyz"[i] for i, c in enumerate(used)}


def test_a_batch_larger_than_the_memory_limit_is_answered_in_slices(monkeypatch):
    import bayesprog.inference.dispatch as inference
    from bayesprog.limits import SizeError, set_limits

    program, tables = chain(4)
    rng = np.random.default_rng(0)
    # soft evidence: only the contraction answers, with memory in proportion to the rows
    evidence = {"B": rng.integers(0, 3, size=(50, 2)), "C": rng.integers(0, 2, size=(50, 2))}
    soft = {"A": rng.uniform(0.1, 1.0, size=(50, 2, 2))}
    whole = program.ask("P(A | B, C)", evidence, soft=soft)
    slices = []
    original = inference._in_slices
    monkeypatch.setattr(inference, "_in_slices",
                        lambda *args: slices.append(args[-1]) or original(*args))
    small, _ = chain(4)
    try:
        set_limits(entries=60)  # a few rows of the contraction at a time
        sliced = small.ask("P(A | B, C)", evidence, soft=soft)
        with pytest.raises(SizeError):  # not even one row fits
            set_limits(entries=1)
            small.ask("P(A | B, C)", evidence, soft=soft)
    finally:
        set_limits(entries=None)
    assert slices and slices[0] < 100
    assert sliced.batch_shape == (50, 2) and sliced.probabilities.shape == (50, 2, 2)
    np.testing.assert_allclose(sliced.probabilities, whole.probabilities, rtol=1e-12)
    np.testing.assert_allclose(sliced.log_evidence, whole.log_evidence, rtol=1e-12)
    b, c = evidence["B"][7, 1], evidence["C"][7, 1]
    row = tables["joint"][:, b, c] * soft["A"][7, 1]
    np.testing.assert_allclose(sliced.probabilities[7, 1], row / row.sum(), rtol=1e-12)


def test_an_answer_with_a_deferred_evidence_probability_pickles_with_it():
    import pickle

    program, joint = independent()
    answer = program.ask("P(A | D)", {"D": "d2"})
    copy = pickle.loads(pickle.dumps(answer))
    np.testing.assert_allclose(copy.probabilities, answer.probabilities, rtol=0)
    np.testing.assert_allclose(copy.log_evidence, np.log(joint[..., 2].sum()), rtol=1e-12)


def test_a_path_account_matches_opt_einsums():
    """The account of a contraction path (its steps, operations, matrix products and
    largest intermediate) against opt_einsum's ``contract_path`` on the same path."""
    import opt_einsum

    from bayesprog.inference.core import Account, equation

    rng = np.random.default_rng(5)
    names = "ABCDEFGHIJ"
    for _ in range(60):
        cards = {n: int(rng.integers(2, 9)) for n in names}
        operands = [tuple(rng.choice(list(names), size=int(rng.integers(1, 4)), replace=False))
                    for _ in range(int(rng.integers(3, 9)))]
        output = tuple(rng.choice(sorted({a for axes in operands for a in axes}),
                                  size=int(rng.integers(0, 3)), replace=False))
        eq = equation(operands, output)
        shapes = [tuple(cards[a] for a in axes) for axes in operands]
        terms, out = eq.split("->")[0].split(","), eq.split("->")[1]
        sizes = {s: n for t, shape in zip(terms, shapes, strict=True)
                 for s, n in zip(t, shape, strict=True)}
        path = opt_einsum.paths.greedy([frozenset(t) for t in terms], frozenset(out), sizes)
        ours = Account.of(terms, out, sizes, path)
        _, theirs = opt_einsum.contract_path(eq, *shapes, shapes=True, optimize=path)
        assert ours.largest_intermediate == theirs.largest_intermediate
        assert len(ours.steps) == len(theirs.contraction_list)
        for (inds, removed, text, flops, kind, _, moved), (t_inds, t_removed, t_text, _,
                                                           t_blas) in zip(
                ours.steps, theirs.contraction_list, strict=True):
            assert (inds, removed, text) == (t_inds, t_removed, t_text)
            involved = set(text.split("->")[0].replace(",", ""))
            assert flops == opt_einsum.helpers.flop_count(involved, bool(removed), len(inds),
                                                          sizes)
            assert moved == sum(opt_einsum.helpers.compute_size_by_dict(t, sizes)
                                for t in text.replace("->", ",").split(","))
            tensordot = bool(t_blas) and "EINSUM" not in t_blas and flops >= 4096
            assert (kind == "tensordot") == tensordot


def grid(n: int, seed: int) -> bayesprog.Program:
    """An n x n grid of binary variables, each with its up and left neighbours as parents
    (random tables)."""
    rng = np.random.default_rng(seed)
    lines = ["bayesprog: 1", "variables:"]
    lines += [f"  X{i}_{j}: {{states: [s0, s1]}}" for i in range(n) for j in range(n)]
    lines.append("decomposition:")
    for i in range(n):
        for j in range(n):
            parents = [f"X{a}_{b}" for a, b in ((i - 1, j), (i, j - 1)) if a >= 0 and b >= 0]
            rows = rng.dirichlet(np.ones(2), size=2 ** len(parents)).round(6)
            rows[:, 1] = 1 - rows[:, 0]
            given = f" | {', '.join(parents)}" if parents else ""
            table = _nested(rows, len(parents))
            lines.append(f"  - {{term: 'P(X{i}_{j}{given})', form: table, table: {table}}}")
    return bayesprog.loads("\n".join(lines))


def _nested(rows: np.ndarray, parents: int) -> str:
    """Rows of a binary table (one per parent configuration, the first parent slowest) as
    lists nested by parent."""
    if parents == 0:
        return f"[{rows[0, 0]:.6f}, {rows[0, 1]:.6f}]"
    half = len(rows) // 2
    return f"[{_nested(rows[:half], parents - 1)}, {_nested(rows[half:], parents - 1)}]"


def test_quick_estimates_choose_as_the_full_ones_do(monkeypatch):
    """The table's quick estimate (its setup bounded, without a path search) leads the cost
    model to the same method at every question as the full estimates do, singly and in
    batches, and the answers agree."""
    from bayesprog.inference.methods.table import TableMethod

    def run() -> tuple[list[str], list[np.ndarray]]:
        # a 10 x 10 grid: compiling the table costs more than its bound says (a path search
        # is needed to know how much more), so the switch comes one question later
        program, rng = grid(10, seed=2), np.random.default_rng(0)
        used, answers = [], []
        for k in range(16):
            rows = 1 if k < 12 else 50
            evidence = {name: rng.integers(2, size=rows) for name in ("X9_0", "X0_9", "X4_4")}
            answer = program.ask("P(X9_9 | X9_0, X0_9, X4_4)", evidence)
            used.append(answer.method)
            answers.append(answer.probabilities)
        return used, answers

    program = grid(10, seed=2)
    question = program.question("P(X9_9 | X9_0, X0_9, X4_4)")
    plan = QuestionPlan(program, question, bind(program, question, {"X9_0": 0, "X0_9": 0,
                                                                     "X4_4": 0}, None, None))
    costs = {method.name: cost for method, cost in ranked(plan)}
    per_call = costs["contraction"].operations + costs["contraction"].fixed
    table = costs["table"]
    program.ask("P(X9_9 | X9_0, X0_9, X4_4)", {"X9_0": 0, "X0_9": 0, "X4_4": 0})
    at = switch(plan.layout.schedule.spent, per_call, table)
    assert at < 12
    quick_table = {m.name: c for m, c in ranked(plan, quick=True)}["table"]
    assert quick_table.floor and quick_table.setup < table.setup  # a bound, below the cost
    quick = run()
    monkeypatch.setattr(TableMethod, "quick_estimate", TableMethod.estimate)
    full = run()
    assert quick[0] == full[0] == ["contraction"] * at + ["table"] * (16 - at)
    for a, b in zip(quick[1], full[1], strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12)


# -- a layout's first question: answered by elimination, nothing planned -----------------------

def random_factors(rng: np.random.Generator, names: str, count: int
                   ) -> tuple[list[tuple[tuple[str, ...], np.ndarray]], dict[str, int]]:
    """``count`` random positive tables over random subsets of ``names`` (2 to 4 states)."""
    cards = {n: int(rng.integers(2, 5)) for n in names}
    factors = []
    for _ in range(count):
        k = int(rng.integers(1, 4))
        axes = tuple(str(a) for a in rng.choice(list(names), size=k, replace=False))
        factors.append((axes, rng.uniform(0.05, 1.0, size=[cards[a] for a in axes])))
    return factors, cards


@pytest.mark.parametrize("seed", range(20))
def test_eliminate_equals_one_einsum_over_every_factor(seed):
    """Variable elimination in greedy order against numpy's einsum of all the factors at once
    (the joint, then summed), for outputs of zero to two variables."""
    from bayesprog.inference.contraction import eliminate

    rng = np.random.default_rng(seed)
    names = "ABCDEFG"
    factors, cards = random_factors(rng, names, int(rng.integers(2, 9)))
    present = sorted({a for axes, _ in factors for a in axes})
    output = tuple(str(a) for a in rng.choice(present, size=int(rng.integers(0, 3)),
                                              replace=False))
    output += ("Z",) if seed % 5 == 0 else ()  # a variable in no factor: uniform
    cards["Z"] = 3
    found = eliminate(factors, output, cards, limit=1e9)
    assert found is not None
    table, work = found
    letter = {n: chr(97 + i) for i, n in enumerate(sorted(cards))}
    text = ",".join("".join(letter[a] for a in axes) for axes, _ in factors)
    joint = np.einsum(text + "->" + "".join(letter[a] for a in output if a != "Z"),
                      *(t for _, t in factors))
    if "Z" in output:
        joint = joint[..., np.newaxis] * np.ones(3)
    np.testing.assert_allclose(table, joint, rtol=1e-12)
    assert work >= table.size
    assert eliminate(factors, output, cards, limit=work - 1) is None  # refused before the end


def test_first_question_is_answered_without_a_plan_then_planned():
    """The first question of a layout makes no path nor compiled table; the next one of the
    same layout is planned; both equal brute force."""
    program, tables = chain(3)
    first = program.ask("P(A | C)", {"C": 1})
    layout = next(iter(program.inference_cache.layouts.values()))
    assert layout.schedule.asked and not layout.schedule.rankings and not layout.prepared
    assert not program.inference_cache.plans._paths  # no contraction path searched
    second = program.ask("P(A | C)", {"C": 1})
    assert layout.schedule.rankings and layout.prepared
    for answer in (first, second):
        np.testing.assert_allclose(answer.probabilities, brute(tables["joint"], "A", {"C": 1}),
                                   rtol=1e-12)
    np.testing.assert_allclose(first.log_evidence, second.log_evidence, rtol=1e-12)
    # a batch of one row is one row
    fresh, _ = chain(3)
    one = fresh.ask("P(A | C)", {"C": np.array([1])})
    assert one.probabilities.shape == (1, 2) and not fresh.inference_cache.plans._paths
    np.testing.assert_allclose(one.probabilities[0], first.probabilities, rtol=1e-12)
    # a question that named its method has prepared the layout: the next one uses it
    named, _ = chain(3)
    named.ask("P(A | C)", {"C": 0}, method="table")
    assert named.ask("P(A | C)", {"C": 1}).method == "table"
    # a batch, soft evidence or a named method never take that way
    for ask in (lambda p: p.ask("P(A | C)", {"C": [0, 1]}),
                lambda p: p.ask("P(A | C)", {"C": 1}, soft={"B": [0.2, 0.5, 0.3]}),
                lambda p: p.ask("P(A | C)", {"C": 1}, method="contraction")):
        fresh, _ = chain(3)
        ask(fresh)
        assert fresh.inference_cache.plans._paths or any(
            layout.prepared for layout in fresh.inference_cache.layouts.values())


def test_first_question_gives_way_to_the_plan_when_large(monkeypatch):
    """Above FIRST_WORK entries the first question is planned (a path searched), and answers
    as the elimination would."""
    from bayesprog.inference import contraction

    question, evidence = "P(X9_9 | X9_0, X0_9, X4_4)", {"X9_0": 1, "X0_9": 0, "X4_4": 1}
    direct = grid(10, seed=4)
    answer = direct.ask(question, evidence)
    assert not direct.inference_cache.plans._paths
    monkeypatch.setattr(contraction, "FIRST_WORK", 100)
    planned = grid(10, seed=4)
    again = planned.ask(question, evidence)
    assert planned.inference_cache.plans._paths
    np.testing.assert_allclose(answer.probabilities, again.probabilities, rtol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, again.log_evidence, rtol=1e-12)


def test_first_question_gives_way_when_the_tables_underflow():
    """Evidence whose probability is below what the tables' arithmetic resolves (1e-400, a
    chain of 40 observations of probability 1e-10 each): the first question falls back to
    the planned path, whose rows are redone in log space; the answer is brute force's."""
    lines = ["bayesprog: 1", "variables:", "  A: {states: [a0, a1]}"]
    lines += [f"  O{i}: {{states: [o0, o1]}}" for i in range(40)]
    lines += ["decomposition:", "  - {term: P(A), form: table, table: [0.3, 0.7]}"]
    lines += [f"  - {{term: 'P(O{i} | A)', form: table, table: {{a0: [0.9999999999, 1e-10], "
              f"a1: [0.99999999995, 5e-11]}}}}" for i in range(40)]
    program = bayesprog.loads("\n".join(lines))
    evidence = {f"O{i}": "o1" for i in range(40)}
    answer = program.ask(f"P(A | {', '.join(evidence)})", evidence)
    assert any(layout.prepared for layout in program.inference_cache.layouts.values())
    log_joint = np.log([0.3, 0.7]) + 40 * np.log([1e-10, 5e-11])
    expected = np.exp(log_joint - np.logaddexp.reduce(log_joint))
    np.testing.assert_allclose(answer.probabilities, expected, rtol=1e-12)
    np.testing.assert_allclose(answer.log_evidence, np.logaddexp.reduce(log_joint), rtol=1e-12)


def test_lbp_gives_the_evidence_by_the_bethe_approximation_exact_on_a_tree():
    """On a tree the Bethe log Z is the exact log-probability of the evidence; on a loopy
    program it is an approximation, and the answer says so."""
    import bayesprog as bp

    models = Path(__file__).parents[1] / "models" / "examples"
    student = bp.load(models / "student.yaml")
    evidence = {"G": np.array(["A", "B", "C", "A"])}
    exact = student.ask("P(I | G)", evidence)
    lbp = student.ask("P(I | G)", evidence, method="lbp")
    np.testing.assert_allclose(lbp.log_evidence, exact.log_evidence, atol=1e-10)
    assert lbp.evidence == "Bethe approximation"
    assert lbp.to_json()["log_evidence_method"] == "Bethe approximation"
    assert "log_evidence_method" not in exact.to_json()
    # a loop A - B - D - C - A of weak dependencies: the Bethe error is of second order in the
    # coupling (a wrong energy or entropy term would be off by the whole evidence)
    loop = bp.loads("""
bayesprog: 1
variables: {A: {states: [a0, a1]}, B: {states: [b0, b1]}, C: {states: [c0, c1]},
            D: {states: [d0, d1]}}
decomposition:
  - {term: P(A), form: table, table: [0.3, 0.7]}
  - {term: P(B | A), form: table, table: {a0: [0.55, 0.45], a1: [0.5, 0.5]}}
  - {term: P(C | A), form: table, table: {a0: [0.4, 0.6], a1: [0.45, 0.55]}}
  - term: "P(D | B, C)"
    form: table
    table: {b0: {c0: [0.2, 0.8], c1: [0.25, 0.75]}, b1: {c0: [0.3, 0.7], c1: [0.22, 0.78]}}
""")
    for value in ("d0", "d1"):
        exact = loop.ask(f"P(A | D={value})")
        lbp = loop.ask(f"P(A | D={value})", method="lbp")
        assert abs(float(lbp.log_evidence - exact.log_evidence)) < 1e-3
        assert abs(float(lbp.log_evidence - exact.log_evidence)) > 0  # not exact: a loop
