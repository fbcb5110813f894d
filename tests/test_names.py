"""Names as written (YAML 1.2): ``yes``, ``no``, ``on``, ``off``, ``Y``, ``N``, ``y``, ``n``,
``true``, ``false``, ``null`` unquoted are names wherever a name stands (a variable, a state, a
table's key, an evidence value, a question), answered as pgmpy answers the same network; flags
still take booleans; imported networks are written with such names unquoted."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

import bayesprog
from bayesprog.cli import main

#: every word of the issue, unquoted, in every position a name stands
WORDS = """\
bayesprog: 1
variables:
  Y: {states: [yes, no]}
  N: {states: [on, off]}
  y: {states: [true, false, null]}
  n: {states: [Y, N, y, n]}
decomposition:
  - {term: P(Y), form: table, table: {yes: 0.3, no: 0.7}}
  - term: P(N | Y)
    form: table
    table:
      yes: {on: 0.9, off: 0.1}
      no: [0.2, 0.8]
  - term: P(y | N)
    form: table
    table: {on: [0.5, 0.3, 0.2], off: {true: 0.1, false: 0.1, null: 0.8}}
  - term: P(n | y, Y)
    form: table
    table:
      true: {yes: [0.1, 0.2, 0.3, 0.4], no: [0.4, 0.3, 0.2, 0.1]}
      false: {yes: {Y: 0.25, N: 0.25, y: 0.25, n: 0.25}, no: [0.7, 0.1, 0.1, 0.1]}
      null: {yes: [0.05, 0.05, 0.1, 0.8], no: [0.05, 0.05, 0.1, 0.8]}
questions:
  yes: P(Y | n=N, N=on)
"""

STATES = {"Y": ["yes", "no"], "N": ["on", "off"], "y": ["true", "false", "null"],
          "n": ["Y", "N", "y", "n"]}


def _quoted(text: str) -> str:
    """The same program with every name quoted (as YAML 1.1 readers needed)."""
    pairs = [("[yes, no]", '["yes", "no"]'), ("[on, off]", '["on", "off"]'),
             ("[true, false, null]", '["true", "false", "null"]'),
             ("[Y, N, y, n]", '["Y", "N", "y", "n"]'),
             ("{yes: 0.3, no: 0.7}", '{"yes": 0.3, "no": 0.7}'),
             ("yes: {on: 0.9, off: 0.1}", '"yes": {"on": 0.9, "off": 0.1}'),
             ("      no: [0.2", '      "no": [0.2'),
             ("{on: [0.5, 0.3, 0.2], off: {true: 0.1, false: 0.1, null: 0.8}}",
              '{"on": [0.5, 0.3, 0.2], "off": {"true": 0.1, "false": 0.1, "null": 0.8}}'),
             ("true: {yes: [0.1, 0.2, 0.3, 0.4], no:", '"true": {"yes": [0.1, 0.2, 0.3, 0.4], "no":'),
             ("false: {yes: {Y: 0.25, N: 0.25, y: 0.25, n: 0.25}, no:",
              '"false": {"yes": {"Y": 0.25, "N": 0.25, "y": 0.25, "n": 0.25}, "no":'),
             ("null: {yes: [0.05, 0.05, 0.1, 0.8], no:", '"null": {"yes": [0.05, 0.05, 0.1, 0.8], "no":'),
             ("  Y: {states", '  "Y": {states'), ("  N: {states", '  "N": {states'),
             ("  y: {states", '  "y": {states'), ("  n: {states", '  "n": {states'),
             ("  yes: P(Y", '  "yes": P(Y')]
    out = text
    for plain, quoted in pairs:
        assert plain in out, plain
        out = out.replace(plain, quoted)
    return out


def _pgmpy():
    from pgmpy.factors.discrete import TabularCPD
    from pgmpy.models import DiscreteBayesianNetwork

    net = DiscreteBayesianNetwork([("Y", "N"), ("N", "y"), ("y", "n"), ("Y", "n")])
    n_table = np.array([[[0.1, 0.2, 0.3, 0.4], [0.4, 0.3, 0.2, 0.1]],
                        [[0.25, 0.25, 0.25, 0.25], [0.7, 0.1, 0.1, 0.1]],
                        [[0.05, 0.05, 0.1, 0.8], [0.05, 0.05, 0.1, 0.8]]])  # y, Y, n
    net.add_cpds(
        TabularCPD("Y", 2, [[0.3], [0.7]], state_names=STATES),
        TabularCPD("N", 2, [[0.9, 0.2], [0.1, 0.8]], evidence=["Y"], evidence_card=[2],
                   state_names=STATES),
        TabularCPD("y", 3, [[0.5, 0.1], [0.3, 0.1], [0.2, 0.8]], evidence=["N"],
                   evidence_card=[2], state_names=STATES),
        TabularCPD("n", 4, np.moveaxis(n_table, 2, 0).reshape(4, 6), evidence=["y", "Y"],
                   evidence_card=[3, 2], state_names=STATES))
    return net


def test_every_word_is_a_name_in_every_position_and_answers_as_pgmpy():
    from pgmpy.inference import VariableElimination

    program = bayesprog.loads(WORDS)
    assert {n: list(v.states) for n, v in program.variables.items()} == STATES
    quoted = bayesprog.loads(_quoted(WORDS))
    assert {n: list(v.states) for n, v in quoted.variables.items()} == STATES
    engine = VariableElimination(_pgmpy())
    for target in STATES:
        others = [v for v in STATES if v != target]
        for known in itertools.combinations(others, 2):
            for values in itertools.product(*(STATES[k] for k in known)):
                evidence = dict(zip(known, values, strict=True))
                expected = engine.query([target], evidence=evidence, show_progress=False).values
                question = f"P({target} | {', '.join(f'{k}={v}' for k, v in evidence.items())})"
                np.testing.assert_allclose(program.ask(question).probabilities, expected,
                                           atol=1e-12)
                np.testing.assert_allclose(quoted.ask(question).probabilities, expected,
                                           atol=1e-12)
                np.testing.assert_allclose(program.ask(f"P({target} | {', '.join(known)})",
                                                       evidence).probabilities, expected,
                                           atol=1e-12)


def test_a_named_question_and_evidence_on_the_command_line(tmp_path, capsys):
    (tmp_path / "words.yaml").write_text(WORDS)
    assert main(["query", str(tmp_path / "words.yaml"), "yes", "--json"]) == 0
    named = json.loads(capsys.readouterr().out)
    assert main(["query", str(tmp_path / "words.yaml"), "P(Y | n, N)", "--evidence", "n=N",
                 "--evidence", "N=on", "--json"]) == 0
    given = json.loads(capsys.readouterr().out)
    assert named["probabilities"] == pytest.approx(given["probabilities"], abs=1e-15)
    assert "yes" in json.dumps(named) and "no" in json.dumps(named)
    assert main(["show", str(tmp_path / "words.yaml")]) == 0
    assert "Y : {yes, no}" in capsys.readouterr().out


def test_flags_still_take_booleans():
    text = WORDS.replace("{term: P(Y), form: table, table: {yes: 0.3, no: 0.7}}",
                         "{term: P(Y), form: table, table: {yes: 0.3, no: 0.7}, learn: false}")
    program = bayesprog.loads(text)
    assert program.term("P(Y)").learn is None
    assert program.term("P(N | Y)").learn is not None
    fitted = program.fit({"Y": ["yes"] * 3 + ["no"], "N": ["on", "off", "on", "off"]})
    assert fitted.program.table("P(Y)").to_numpy().ravel().tolist() == [0.3, 0.7]


def test_data_with_these_words_learns_and_the_fitted_file_keeps_them_unquoted(tmp_path):
    (tmp_path / "words.yaml").write_text(WORDS)
    rows = "Y,N\nyes,on\nyes,on\nno,off\nno,on\n"
    (tmp_path / "d.csv").write_text(rows)
    fit = bayesprog.load(tmp_path / "words.yaml").fit(tmp_path / "d.csv")
    fit.save(tmp_path / "fitted.yaml")
    text = (tmp_path / "fitted.yaml").read_text()
    assert "states: [yes, no]" in text and '"yes"' not in text
    again = bayesprog.load(tmp_path / "fitted.yaml")
    assert again.table("P(Y)").to_numpy().ravel().tolist() == [0.5, 0.5]


def test_an_imported_network_writes_these_names_unquoted(tmp_path, capsys):
    (tmp_path / "yn.bif").write_text(
        "network t {}\nvariable A { type discrete [ 2 ] { yes, no }; }\n"
        "variable B { type discrete [ 2 ] { on, off }; }\n"
        "probability ( A ) { table 0.2, 0.8; }\n"
        "probability ( B | A ) { (yes) 0.9, 0.1; (no) 0.3, 0.7; }\n")
    assert main(["import", str(tmp_path / "yn.bif"), "-o", str(tmp_path / "yn.yaml")]) == 0
    text = (tmp_path / "yn.yaml").read_text()
    assert "states: [yes, no]" in text and "states: [on, off]" in text
    answer = bayesprog.load(tmp_path / "yn.yaml").ask("P(A | B=on)").probabilities
    np.testing.assert_allclose(answer, [0.2 * 0.9 / (0.18 + 0.24), 0.24 / 0.42], atol=1e-12)
