"""A sub-program's question misspelt (the ``question:`` of a ``form: program`` term or soft
evidence, naming a question the other program does not have) is reported at its place with the
other program's questions and the one meant."""

from __future__ import annotations

import pytest

import bayesprog
from bayesprog.cli import main
from bayesprog.errors import SpecError

SHAPE = """\
bayesprog: 1
name: shape
variables:
  R: {states: [rectangle, triangle]}
  V: {states: [slow, fast]}
  L: {continuous: [0, 1], description: matching error}
decomposition:
  - {term: P(R), form: uniform}
  - {term: P(V), form: uniform}
  - term: "P(L | R, V)"
    form: beta
    a: 1
    b: {rectangle: [4.5, 9.0], triangle: [1.0, 1.0]}
questions:
  shape: "P(R | V, L)"
  speed: "P(V | R)"
"""

USE = """\
bayesprog: 1
name: use_shape
variables:
  V: {states: [slow, fast]}
  R: {states: [rectangle, triangle]}
inputs:
  error: {}
decomposition:
  - {term: P(V), form: table, table: [0.7, 0.3]}
  - term: P(R | V)
    form: program
    program: shape.yaml
    question: QUESTION
    bind: {L: {input: error}}
"""

SOFT = """\
bayesprog: 1
name: soft_shape
variables:
  R: {states: [rectangle, triangle]}
  V: {states: [slow, fast]}
inputs:
  error: {}
decomposition:
  - {term: P(R), form: uniform}
  - {term: P(V), form: uniform}
soft_evidence:
  - variable: R
    form: program
    program: shape.yaml
    question: QUESTION
    bind: {L: {input: error}}
"""


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "shape.yaml").write_text(SHAPE)
    return tmp_path


@pytest.mark.parametrize(("text", "line"), [(USE, 13), (SOFT, 15)], ids=["term", "soft"])
@pytest.mark.parametrize("written", ["shpae", "Shape", "shap"])
def test_a_misspelt_question_of_a_sub_program_is_pointed_at(folder, capsys, text, line,
                                                             written):
    path = folder / "use.yaml"
    path.write_text(text.replace("QUESTION", written))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"{path}:{line}:15: ")
    assert (f"{written!r} is not a question of 'shape.yaml': did you mean 'shape'? (its "
            "questions: shape, speed)") in err
    with pytest.raises(SpecError, match="did you mean 'shape'"):
        bayesprog.load(path)


def test_a_name_far_from_every_question_lists_them_without_a_guess(folder, capsys):
    path = folder / "use.yaml"
    path.write_text(USE.replace("QUESTION", "where"))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "'where' is not a question of 'shape.yaml' (its questions: shape, speed); expected " \
           "one of them, or P(R | ...)" in err
    assert "did you mean" not in err


def test_a_broken_expression_is_reported_as_an_expression(folder, capsys):
    path = folder / "use.yaml"
    path.write_text(USE.replace("QUESTION", '"P(R | V, L"'))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "is neither a question of 'shape.yaml' (shape, speed) nor an expression" in err


def test_the_question_spelt_right_answers(folder):
    path = folder / "use.yaml"
    path.write_text(USE.replace("QUESTION", "shape"))
    answer = bayesprog.load(path).ask("P(R | V=slow)", inputs={"error": 0.2})
    alone = bayesprog.load(folder / "shape.yaml").ask("shape", {"V": "slow", "L": 0.2})
    assert answer.probabilities.tolist() == pytest.approx(alone.probabilities.tolist(),
                                                          abs=1e-12)
