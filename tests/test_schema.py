"""The published JSON Schema: up to date, accepts every bundled program, rejects bad ones."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
import yaml

from bayesprog.language.json_schema import json_schema

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
