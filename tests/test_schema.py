"""The published JSON Schema: up to date, accepts every bundled program, rejects bad ones; and
the plain reader of the common shape reads what pydantic reads, as it reads it."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

import bayesprog
from bayesprog.language.document import Document, validate_located
from bayesprog.language.json_schema import json_schema
from bayesprog.language.loader import Located, load_yaml
from bayesprog.language.plain import read_plain

ROOT = Path(__file__).parents[1]
PROGRAMS = sorted(p for p in (ROOT / "models").rglob("*.yaml")
                  if "bayesprog" in yaml.safe_load(p.read_text()))


def test_published_schema_is_up_to_date():
    published = json.loads((ROOT / "docs" / "bayesprog.schema.json").read_text())
    assert published == json_schema(), "run: bayesprog schema -o docs/bayesprog.schema.json"


def test_schema_is_a_valid_draft_2020_12_schema():
    jsonschema.Draft202012Validator.check_schema(json_schema())


@pytest.mark.parametrize("path", PROGRAMS, ids=lambda p: p.name)
def test_bundled_programs_satisfy_the_schema(path):
    jsonschema.validate(yaml.safe_load(path.read_text()), json_schema())


@pytest.mark.parametrize("change, word", [
    (lambda d: d.update(bayesprog=2), "bayesprog"),
    (lambda d: d["decomposition"][0].update(form="gausian"), "gausian"),
    (lambda d: d["decomposition"][1].pop("sigma"), "sigma"),
    (lambda d: d.update(variabels=d.pop("variables")), "variabels"),
])
def test_schema_rejects_bad_programs(change, word):
    doc = yaml.safe_load((ROOT / "models" / "pi_per.yaml").read_text())
    change(doc)
    with pytest.raises(jsonschema.ValidationError) as info:
        jsonschema.validate(doc, json_schema())
    assert word in str(info.value)


# the plain reader: the common shape read without pydantic, as pydantic reads it -----------------

EVERY_PROGRAM = PROGRAMS + sorted((ROOT / "tests" / "programs").glob("*.yaml"))


def _located(text: str):
    from bayesprog.program.program import _names_as_written

    located, problems = load_yaml(text, "<test>")
    assert not problems
    _names_as_written(located)
    return located


def _as_data(spec) -> object:
    """A document read either way as plain data, to compare the two."""
    if isinstance(spec, (str, int, float, bool, type(None))):
        return spec
    if isinstance(spec, np.ndarray):  # a table the loader read as an array
        return spec.tolist()
    if isinstance(spec, list):
        return [_as_data(v) for v in spec]
    if isinstance(spec, dict):
        return {k: _as_data(v) for k, v in spec.items()}
    if isinstance(spec, BaseModel):
        out = {name: _as_data(getattr(spec, name)) for name in type(spec).model_fields}
    else:
        out = {name: _as_data(value) for name, value in vars(spec).items()}
    if hasattr(spec, "parameters"):
        out["parameters"] = _as_data(spec.parameters)
    return out


def _agree(data) -> bool:
    """Whether the plain reader either leaves ``data`` to pydantic or reads it as pydantic does
    (then pydantic finds no problem with it). True when the plain reader took it."""
    import copy

    plain = read_plain(copy.deepcopy(data))
    if plain is None:
        return False
    validated, problems = validate_located(Located(copy.deepcopy(data), "<test>"), Document)
    assert not problems, problems
    assert _as_data(plain) == _as_data(validated)
    return True


@pytest.mark.parametrize("path", EVERY_PROGRAM, ids=lambda p: p.name)
def test_the_plain_reader_reads_a_shipped_program_as_pydantic_does(path):
    located = _located(path.read_text())
    took = _agree(located.data)
    # the common shape: every program without a grid, bins or a discovered structure's record
    # (a fitted program's learned: records are of it)
    text = path.read_text()
    assert took or any(word in text for word in ("grid:", "discretise:", "structure:")), path


LEAVES = st.sampled_from([None, 0, 1, 2, -1, 1.5, float("inf"), True, False, "", "x", "a0",
                          "1", [], [1], ["a", "a"], ["a", "b"], [0, 1], {}, {"x": 1}]).map(
    lambda leaf: __import__("copy").deepcopy(leaf))


@settings(max_examples=300, deadline=None)
@given(data=st.data())
def test_whatever_the_plain_reader_takes_pydantic_takes_the_same(data):
    """A shipped program with values replaced at random: the plain reader leaves it to
    pydantic, or reads it as pydantic does."""
    path = data.draw(st.sampled_from(EVERY_PROGRAM))
    doc = _located(path.read_text()).data
    for _ in range(data.draw(st.integers(1, 3))):
        node, key = doc, None
        while True:  # walk down to a random place: node[key]
            keys = list(node) if isinstance(node, dict) else list(range(len(node)))
            if not keys:
                key = None
                break
            key = data.draw(st.sampled_from(keys))
            child = node[key]
            if not isinstance(child, (dict, list)) or not child or data.draw(st.booleans()):
                break
            node = child
        if key is None:
            continue
        if isinstance(node, dict) and data.draw(st.booleans()):
            node[data.draw(st.sampled_from(["description", "extra", "learn", "kind",
                                            "indexed_by", "states", "range", "rows",
                                            "structure", "digits"]))] = \
                data.draw(LEAVES)
        else:
            node[key] = data.draw(LEAVES)
    _agree(doc)


def _discovered() -> list[str]:
    """The files of programs discovered from data (hill climbing and PC, with constraints and
    bins): each carries a discovered structure's record."""
    rng = np.random.default_rng(0)
    a = rng.integers(0, 2, 400)
    b = a ^ (rng.random(400) < 0.2)
    frame = {"A": a.tolist(), "B": b.astype(int).tolist(),
             "C": (rng.normal(size=400) + b).tolist()}
    return [bayesprog.discover(frame, discretise=3).text,
            bayesprog.discover(frame, method="pc", discretise=3).text,
            bayesprog.discover(frame, score="bdeu", forbid=["A->B"], tiers=[["A"], ["B", "C"]],
                               max_parents=2, discretise=4).text]


DISCOVERED = _discovered()


@pytest.mark.parametrize("which", range(len(DISCOVERED)))
def test_the_plain_reader_reads_a_discovered_program_as_pydantic_does(which):
    data = _located(DISCOVERED[which]).data
    assert data["learned"][0]["structure"]["method"] in ("hc", "pc")
    assert _agree(data)


@settings(max_examples=300, deadline=None)
@given(data=st.data())
def test_whatever_discovered_record_the_plain_reader_takes_pydantic_takes_the_same(data):
    """A discovered structure's record with values replaced, added or removed at random: the
    plain reader leaves it to pydantic, or reads it as pydantic does."""
    doc = _located(data.draw(st.sampled_from(DISCOVERED))).data
    record = doc["learned"][0]["structure"]
    for _ in range(data.draw(st.integers(1, 3))):
        key = data.draw(st.sampled_from([*record, "score", "tests", "seconds", "extra",
                                         "constraints", "discretised", "warnings"]))
        if data.draw(st.integers(0, 4)) == 0:
            record.pop(key, None)
        else:
            record[key] = data.draw(LEAVES | st.sampled_from(
                [{"C": [0, 1.5]}, {"C": ["a"]}, {"forbid": ["A->B"]}, {"forbid": [1.5, None]},
                 2**60, -3, 0.25]))
    _agree(doc)


@pytest.mark.parametrize("change, word", [
    (lambda record: record.pop("log_likelihood"), "log_likelihood"),
    (lambda record: record.update(log_likelihood=10**400), "log_likelihood"),
    (lambda record: record.update(rows="many"), "rows"),
])
def test_a_wrong_fit_record_is_left_to_pydantic_which_says_what_is_wrong(change, word):
    from bayesprog.errors import SpecError

    text = (ROOT / "models" / "pi_per_identified.yaml").read_text()
    located, plain = _located(text).data, yaml.safe_load(text)
    change(located["learned"][0])
    change(plain["learned"][0])
    assert not _agree(located)
    with pytest.raises(SpecError) as caught:
        bayesprog.loads(yaml.safe_dump(plain, sort_keys=False), "fitted.yaml")
    assert any(word in str(d) for d in caught.value.diagnostics), caught.value.diagnostics
