"""Functions of discrete variables and coherence variables: deterministic discrete terms
(``dirac`` over a discrete child), probabilities written as formulas, and the book's fusion of
sub-models through coherence variables, each checked against the same product computed by hand
with numpy."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
from scipy import stats

import bayesprog
from bayesprog.errors import QuestionError, SpecError
from bayesprog.support import bundled

PA = np.array([0.1, 0.2, 0.3, 0.4])
PB = np.array([0.4, 0.3, 0.2, 0.1])


def program(body: str) -> bayesprog.Program:
    return bayesprog.loads("bayesprog: 1\n" + textwrap.dedent(body))


def coherence(states: str, term: str) -> bayesprog.Program:
    return program(f"""
        variables:
          A: {states}
          B: {states}
          L: {{states: ["no", "yes"]}}
        decomposition:
          - {{term: P(A), form: table, table: [0.1, 0.2, 0.3, 0.4]}}
          - {{term: P(B), form: table, table: [0.4, 0.3, 0.2, 0.1]}}
          - {term}
        """)


# deterministic discrete terms ------------------------------------------------------------------
@pytest.mark.parametrize("states, value", [
    ("{range: [0, 3]}", '"A == B"'),
    ("{states: [1, 2, 3, 4]}", '"A == B"'),
    ("{states: [n, e, s, w]}", '"A == B"'),
    ("{states: [n, e, s, w]}", '"not (A != B)"'),
])
def test_a_hard_coherence_keeps_only_what_agrees(states, value):
    p = coherence(states, f'{{term: "P(L | A, B)", form: dirac, value: {value}}}')
    answer = p.ask("P(A | L=yes)")
    joint = PA * PB  # P(A = a, B = a)
    np.testing.assert_allclose(answer.probabilities, joint / joint.sum(), rtol=0, atol=1e-15)
    assert float(np.squeeze(answer.log_evidence)) == pytest.approx(np.log(joint.sum()), abs=1e-14)
    # no evidence on L: its term sums to one, and the program is the two priors
    np.testing.assert_allclose(p.ask("P(A)").probabilities, PA, atol=1e-15)
    # and L's own distribution: the probability that they agree
    np.testing.assert_allclose(p.ask("P(L)").probabilities, [1 - joint.sum(), joint.sum()],
                               atol=1e-15)


def test_named_states_compare_with_their_quoted_names():
    p = coherence("{states: [n, e, s, w]}",
                  '''{term: "P(L | A, B)", form: dirac, value: "A == B and A != 'w'"}''')
    joint = PA * PB * np.array([1, 1, 1, 0])
    np.testing.assert_allclose(p.ask("P(A | L=yes)").probabilities, joint / joint.sum(),
                               atol=1e-15)
    with pytest.raises(SpecError, match=r"10:\d+: .*not one of A's"):
        coherence("{states: [n, e, s, w]}",
                  '''{term: "P(L | A, B)", form: dirac, value: "A == 'up'"}''')
    with pytest.raises(SpecError, match="may only be compared"):
        coherence("{states: [n, e, s, w]}",
                  '{term: "P(L | A, B)", form: dirac, value: "A + 1 == B + 1"}')


CORRIDOR = """
    variables:
      X0: {range: [0, 9]}
      U: {range: [-1, 1]}
      X1: {range: [0, 9]}
    decomposition:
      - {term: P(X0), form: table, table: [0.05, 0.05, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.15, 0.15]}
      - {term: P(U), form: table, table: [0.2, 0.5, 0.3]}
      - {term: "P(X1 | X0, U)", form: dirac, value: "min(max(X0 + U, 0), 9)"}
    """


def test_a_deterministic_motion_is_the_table_of_its_function():
    p = program(CORRIDOR)
    px0, pu = np.array([0.05, 0.05, .1, .1, .1, .1, .1, .1, .15, .15]), np.array([.2, .5, .3])
    kernel = np.zeros((10, 3, 10))  # [x0, u, x1]
    for x0 in range(10):
        for i, u in enumerate((-1, 0, 1)):
            kernel[x0, i, min(max(x0 + u, 0), 9)] = 1
    joint = px0[:, None, None] * pu[None, :, None] * kernel
    np.testing.assert_allclose(p.ask("P(X1)").probabilities, joint.sum((0, 1)), atol=1e-15)
    np.testing.assert_allclose(p.ask("P(X0 | X1=0)").probabilities,
                               joint[:, :, 0].sum(1) / joint[:, :, 0].sum(), atol=1e-15)
    # every state of the parents at once, as a batch: X1 is where the function puts it
    x0 = np.repeat(np.arange(10), 3)
    u = np.tile([-1, 0, 1], 10)
    answer = p.ask("P(X1 | X0, U)", {"X0": x0, "U": u})
    np.testing.assert_array_equal(answer.probabilities.argmax(-1), np.clip(x0 + u, 0, 9))
    np.testing.assert_array_equal(answer.probabilities.max(-1), 1.0)
    # the most probable explanation of X1 = 9
    found = p.ask("P(X0 U | X1=9)", kind="map")
    best = np.unravel_index(np.argmax(joint[:, :, 9]), (10, 3))
    assert (found.assignment["X0"], found.assignment["U"]) == (best[0], (-1, 0, 1)[best[1]])


def test_a_value_that_is_not_a_state_is_reported_where_it_is_written():
    with pytest.raises(SpecError) as err:
        program(CORRIDOR.replace("min(max(X0 + U, 0), 9)", "X0 + U"))
    (diag,) = err.value.diagnostics
    assert diag.line == 10
    assert "the value -1 for X0=0, U=-1 is not a state of X1" in diag.message
    assert "expected one of its values (0, ..., 9)" in diag.message


def test_a_real_parent_is_compared_with_each_question_s_evidence():
    p = program("""
        variables:
          X: {continuous: [-.inf, .inf]}
          L: {range: [0, 1]}
          K: {range: [0, 3]}
        decomposition:
          - {term: P(X), form: normal, mean: 0, sigma: 1}
          - {term: P(L | X), form: dirac, value: "X > 0.5"}
          - {term: P(K | X), form: dirac, value: "clip(floor(X), 0, 3)"}
        """)
    x = np.array([-0.3, 0.4, 0.6, 2.0])
    answer = p.ask("P(L | X)", {"X": x})
    np.testing.assert_array_equal(answer.probabilities[:, 1], (x > 0.5) * 1.0)
    # likelihood weighting draws X and keeps the draws where L = 1: P(X > 0.5)
    lw = p.ask("P(K | L=1)", method="lw", samples=40_000, rng=3)
    exact = np.diff(stats.norm.cdf([0.5, 1, 2, 3, np.inf])) / stats.norm.sf(0.5)
    assert np.all(np.abs(lw.probabilities - exact) < 5 * lw.stderr + 1e-12)
    unclipped = program("""
        variables:
          X: {continuous: [-.inf, .inf]}
          K: {range: [0, 3]}
        decomposition:
          - {term: P(X), form: normal, mean: 0, sigma: 1}
          - {term: P(K | X), form: dirac, value: "floor(X)"}
        """)
    with pytest.raises(QuestionError, match=r"P\(K \| X\): the value -1 is not a state of K"):
        unclipped.ask("P(K | X)", {"X": [0.5, -0.5]})


# probabilities as formulas ---------------------------------------------------------------------
def soft(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.exp(-(a - b) ** 2 / 2)


@pytest.mark.parametrize("probabilities", [
    '{0: "1 - exp(-(A - B)**2 / 2)", 1: "exp(-(A - B)**2 / 2)"}',
    '["1 - exp(-(A - B)**2 / 2)", "exp(-(A - B)**2 / 2)"]',
    '"exp(-(A - B)**2 / 2)"',  # two states: the probability of the second
    '"where(L == 1, exp(-(A - B)**2 / 2), 1 - exp(-(A - B)**2 / 2))"',  # names the child
    '{1: "exp(-(A - B)**2 / 2)", 0: "1 - exp(-(A - B)**2 / 2)"}',  # keyed in any order
])
@pytest.mark.parametrize("form", ["categorical", "table"])
def test_a_soft_coherence_weighs_agreement_by_its_formula(probabilities, form):
    key = "probabilities" if form == "categorical" else "table"
    p = program(f"""
        variables:
          A: {{range: [0, 3]}}
          B: {{range: [0, 3]}}
          L: {{range: [0, 1]}}
        decomposition:
          - {{term: P(A), form: table, table: [0.1, 0.2, 0.3, 0.4]}}
          - {{term: P(B), form: table, table: [0.4, 0.3, 0.2, 0.1]}}
          - term: P(L | A, B)
            form: {form}
            {key}: {probabilities}
        """)
    a, b = np.arange(4.0)[:, None], np.arange(4.0)[None, :]
    joint = PA[:, None] * PB[None, :] * soft(a, b)
    answer = p.ask("P(A | L=1)")
    np.testing.assert_allclose(answer.probabilities, joint.sum(1) / joint.sum(), atol=1e-15)
    assert float(np.squeeze(answer.log_evidence)) == pytest.approx(np.log(joint.sum()),
                                                                   abs=1e-14)


def test_probabilities_are_normalised_per_configuration_of_the_parents():
    p = program("""
        variables:
          X0: {range: [0, 9]}
          U: {range: [-1, 1]}
          X1: {range: [0, 9]}
        decomposition:
          - {term: P(X0), form: uniform}
          - {term: P(U), form: uniform}
          - term: "P(X1 | X0, U)"
            form: categorical
            probabilities: {-1: "exp(-(X1 - X0 + 1)**2)", 0: "where(X1 == X0, 3, 1)",
                            1: "exp(-(X1 - X0 - 1)**2 / 2)"}
        """)
    x1 = np.arange(10.0)
    for x0 in range(10):
        for u in (-1, 0, 1):
            weights = {-1: np.exp(-(x1 - x0 + 1) ** 2), 0: np.where(x1 == x0, 3.0, 1.0),
                       1: np.exp(-(x1 - x0 - 1) ** 2 / 2)}[u]
            got = p.ask("P(X1 | X0, U)", {"X0": x0, "U": u}).probabilities
            np.testing.assert_allclose(got, weights / weights.sum(), rtol=1e-14, atol=1e-300)


def test_a_discrete_child_of_real_parents_reads_them_from_the_evidence():
    p = program("""
        variables:
          A: {continuous: [-.inf, .inf]}
          B: {continuous: [-.inf, .inf]}
          L: {states: ["no", "yes"]}
        decomposition:
          - {term: P(A), form: normal, mean: 0, sigma: 1}
          - {term: P(B), form: normal, mean: 1, sigma: 1}
          - {term: "P(L | A, B)", form: categorical, probabilities: "exp(-(A - B)**2 / 2)"}
        """)
    a, b = np.array([0.0, 1.0, 2.0, -1.5]), np.array([0.0, 0.0, 0.5, 1.0])
    answer = p.ask("P(L | A, B)", {"A": a, "B": b})
    np.testing.assert_allclose(answer.probabilities[:, 1], soft(a, b), rtol=1e-15)
    # the evidence's density: the two priors at the readings (L is not given)
    np.testing.assert_allclose(np.reshape(answer.log_evidence, -1),
                               stats.norm.logpdf(a) + stats.norm.logpdf(b, 1), rtol=1e-14)
    # and, given L = yes too, times the kernel
    event = p.ask("P(L=yes | A, B)", {"A": a, "B": b})
    np.testing.assert_allclose(np.reshape(event.probability, -1), soft(a, b), rtol=1e-14)


def test_a_bad_row_of_probabilities_is_reported_with_the_parents_states():
    with pytest.raises(SpecError) as err:
        program("""
            variables:
              A: {range: [0, 3]}
              L: {range: [0, 1]}
            decomposition:
              - {term: P(A), form: uniform}
              - term: P(L | A)
                form: categorical
                probabilities: {0: "A - 1", 1: "2 * (A - 1)"}
            """)
    (diag,) = err.value.diagnostics
    assert diag.line == 10
    assert "not all finite and >= 0 for A=0 (found [-1, -2])" in diag.message
    with pytest.raises(SpecError, match=r"sum to 0 for A=1 \(found \[0, 0\]\)"):
        program("""
            variables:
              A: {range: [0, 3]}
              L: {range: [0, 1]}
            decomposition:
              - {term: P(A), form: uniform}
              - {term: P(L | A), form: categorical, probabilities: "abs(A - 1) * where(L == 0, 1, 2)"}
            """)
    real = program("""
        variables:
          X: {continuous: [-.inf, .inf]}
          L: {range: [0, 1]}
        decomposition:
          - {term: P(X), form: normal, mean: 0, sigma: 1}
          - {term: P(L | X), form: categorical, probabilities: ["X", "X"]}
        """)
    with pytest.raises(QuestionError, match=r"P\(L \| X\): the probabilities .* sum to 0"):
        real.ask("P(L | X=0)")
    with pytest.raises(SpecError, match="name X1 in the formula"):
        program("""
            variables:
              X0: {range: [0, 9]}
              X1: {range: [0, 9]}
            decomposition:
              - {term: P(X0), form: uniform}
              - {term: "P(X1 | X0)", form: table, table: "X0 / 9"}
            """)


# the book's fusion by coherence, bundled -------------------------------------------------------
def test_the_bundled_fusion_is_the_product_of_its_sub_models():
    p = bayesprog.load(bundled.find("coherence", "program"))
    cells = np.arange(10.0)
    sonar = np.exp(-(cells[:, None] - cells[None, :]) ** 2 / (2 * 1.5**2))  # [reading, ps]
    sonar /= sonar.sum(1, keepdims=True)
    camera = np.where(cells[:, None] == cells[None, :], 0.6, 0.4 / 9)  # [reading, pc]
    camera /= camera.sum(1, keepdims=True)
    kernel = soft(cells[:, None], cells[None, :])  # P(LC = 1 | position, pc)
    # P(position | sonar=3, camera=6, LS=1, LC=1): uniform prior, PS = position
    by_hand = sonar[3] * (kernel @ camera[6])
    np.testing.assert_allclose(p.ask("fused").probabilities, by_hand / by_hand.sum(),
                               rtol=1e-13, atol=1e-16)
    np.testing.assert_allclose(p.ask("sonar").probabilities, sonar[3], rtol=1e-13)
    alone = kernel @ camera[6]
    np.testing.assert_allclose(p.ask("camera").probabilities, alone / alone.sum(), rtol=1e-13)
    # every reading of both sensors at once
    s, c = np.meshgrid(np.arange(10), np.arange(10), indexing="ij")
    batch = p.ask("P(Position | Sonar, Camera, LS=1, LC=1)",
                  {"Sonar": s.ravel(), "Camera": c.ravel()}).probabilities
    hand = sonar[s.ravel()] * (camera[c.ravel()] @ kernel.T)
    np.testing.assert_allclose(batch, hand / hand.sum(1, keepdims=True), rtol=1e-12, atol=1e-16)


def test_the_command_line_shows_and_answers_a_coherence_program():
    path = bundled.find("coherence", "program")
    show = subprocess.run([sys.executable, "-m", "bayesprog", "show", str(path)],
                          capture_output=True, text=True)
    assert show.returncode == 0, show.stderr
    assert 'P(LS | Position, PS) = Dirac(value = "Position == PS")' in show.stdout
    assert ('P(LC | Position, PC) = Categorical(probabilities = '
            '"exp(-(Position - PC)**2 / 2)")') in show.stdout
    query = subprocess.run([sys.executable, "-m", "bayesprog", "query", str(path), "fused",
                            "--json"], capture_output=True, text=True)
    assert query.returncode == 0, query.stderr
    import json

    got = json.loads(query.stdout)
    probabilities = got["answers"][0]["probabilities"] if "answers" in got else got[
        "probabilities"]
    np.testing.assert_allclose(probabilities,
                               bayesprog.load(path).ask("fused").probabilities, rtol=1e-12)


def test_learning_leaves_a_deterministic_term_as_written():
    p = coherence("{range: [0, 3]}", '{term: "P(L | A, B)", form: dirac, value: "A == B"}')
    rng = np.random.default_rng(5)
    a, b = rng.integers(0, 4, 400), rng.integers(0, 4, 400)
    import pandas as pd

    data = pd.DataFrame({"A": a, "B": b, "L": np.where(a == b, "yes", "no")})
    learned = p.fit(data).program
    np.testing.assert_allclose(learned.ask("P(A)").probabilities, np.bincount(a, minlength=4)
                               / 400, atol=1e-12)
    joint = np.bincount(a, minlength=4) * np.bincount(b, minlength=4)
    np.testing.assert_allclose(learned.ask("P(A | L=yes)").probabilities, joint / joint.sum(),
                               atol=1e-12)


def test_exported_as_bif_pyagrum_fuses_the_same(tmp_path):
    """The tables the formulas give, written out, answer the same in another engine (the
    readings given a uniform prior: a network has no variable without a table)."""
    gum = pytest.importorskip("pyagrum")
    text = bundled.find("coherence", "program").read_text()
    text = text.replace("  - {term: P(Position), form: uniform}\n",
                        "  - {term: P(Position), form: uniform}\n"
                        "  - {term: P(Sonar), form: uniform}\n"
                        "  - {term: P(Camera), form: uniform}\n")
    path = tmp_path / "with_priors.yaml"
    path.write_text(text)
    bif = tmp_path / "coherence.bif"
    done = subprocess.run([sys.executable, "-m", "bayesprog", "export", str(path), "-o", str(bif)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    net = gum.loadBN(str(bif))
    inference = gum.LazyPropagation(net)
    inference.setEvidence({"Sonar": "3", "Camera": "6", "LS": "1", "LC": "1"})
    inference.makeInference()
    theirs = inference.posterior("Position").toarray()
    # (BIF holds the tables' numbers to about 8 significant digits)
    ours = bayesprog.load(bundled.find("coherence", "program")).ask("fused").probabilities
    np.testing.assert_allclose(ours, theirs, rtol=1e-6, atol=1e-12)


# the bundled corridor: a formula kernel and a command with no term ------------------------------
def corridor_by_hand(doors: list[str], commands: list[int]) -> tuple[np.ndarray, np.ndarray,
                                                                       np.ndarray, list]:
    """Forward and backward recursions of the corridor, written out: the filtered and smoothed
    beliefs, each step's log P(door_t | doors before, commands), and the likeliest paths (every
    one that ties with the best, within a MAP's relative 1e-12)."""
    at_door = np.where(np.isin(np.arange(10), [1, 4, 7]), 0.9, 0.1)
    seen = [at_door if d == "yes" else 1 - at_door for d in doors]
    kernels = []
    for u in commands:
        k = np.zeros((10, 10))
        for x0 in range(10):
            k[x0, min(max(x0 + u, 0), 9)] += 0.8
            k[x0, x0] += 0.2
        kernels.append(k)
    belief, filtered, log_z = np.full(10, 0.1), [], []
    for k, lik in zip(kernels, seen, strict=True):
        joint = (belief @ k) * lik
        log_z.append(np.log(joint.sum()))
        belief = joint / joint.sum()
        filtered.append(belief)
    back, smoothed = np.ones(10), [filtered[-1]]
    for t in range(len(doors) - 1, 0, -1):
        back = kernels[t] @ (seen[t] * back)
        s = filtered[t - 1] * back
        smoothed.insert(0, s / s.sum())
    weights = {}
    for path in np.ndindex(*(10,) * len(doors)):  # every path, by brute force
        before = np.full(10, 0.1)
        prob = float(before @ kernels[0][:, path[0]]) * seen[0][path[0]]
        for t in range(1, len(doors)):
            prob *= kernels[t][path[t - 1], path[t]] * seen[t][path[t]]
        weights[path] = prob
    best_p = max(weights.values())
    best = [list(path) for path, p in weights.items() if p >= best_p * (1 - 1e-12)]
    return np.array(filtered), np.array(smoothed), np.array(log_z), best


def test_the_bundled_corridor_filters_its_commands_through_its_formula_kernel():
    p = bayesprog.load(bundled.find("corridor", "program"))
    assert p.conditioning == ("U",)
    doors, commands = ["yes", "no", "no", "yes"], [1, 1, 1, 0]
    filtered, smoothed, log_z, paths = corridor_by_hand(doors, commands)
    evidence = {"Door": doors, "U": commands}
    answer = p.ask("where", evidence)
    np.testing.assert_allclose(answer.probabilities, filtered, rtol=1e-12, atol=1e-15)
    # no log P(U): the evidence is the doors' alone, given the commands
    np.testing.assert_allclose(np.reshape(answer.log_evidence, -1), log_z, rtol=1e-12)
    np.testing.assert_allclose(p.ask("looking_back", evidence).probabilities, smoothed,
                               rtol=1e-12, atol=1e-15)
    # the doors at 1, 4 and 7 alike: the paths from each tie, one of them drawn by the seed
    likeliest = p.ask("path", evidence)
    assert int(likeliest.ties) == len(paths) == 3
    assert likeliest.assignment["X"].tolist() in paths
    with pytest.raises(QuestionError, match="missing evidence for U"):
        p.ask("where", {"Door": doors})
