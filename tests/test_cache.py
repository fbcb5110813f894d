"""Checked programs kept between loads: the same bytes read back, anything else read and
checked again (diagnostics at their line and column), files that name others never kept."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import bayesprog
import bayesprog.program.program
from bayesprog import limits
from bayesprog.errors import SpecError
from bayesprog.io import dump_document
from bayesprog.support import cache


def _network(states: int = 30, seed: int = 0) -> str:
    """A program file over the cache's smallest size: a chain of four variables."""
    rng = np.random.default_rng(seed)
    names = ["A", "B", "C", "D"]
    doc = {"bayesprog": 1, "variables": {n: {"states": [f"s{i}" for i in range(states)]}
                                         for n in names},
           "decomposition": [{"term": "P(A)", "form": "table",
                              "table": rng.dirichlet(np.ones(states)).tolist()}]}
    for parent, child in zip(names, names[1:], strict=False):
        doc["decomposition"].append({"term": f"P({child} | {parent})", "form": "table",
                                     "table": rng.dirichlet(np.ones(states), states).tolist()})
    text = dump_document(doc)
    assert len(text) > cache.MIN_BYTES
    return text


@pytest.fixture
def kept(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("BAYESPROG_CACHE", str(folder))
    return folder / "programs"


def _read_only_from_cache(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("read and checked again")

    monkeypatch.setattr(bayesprog.program.program, "loads", refuse)


def test_the_same_bytes_are_read_back_and_answer_the_same(tmp_path, kept, monkeypatch):
    path = tmp_path / "net.yaml"
    path.write_text(_network())
    first = bayesprog.load(path)
    assert len(list(kept.glob("*.pickle"))) == 1
    with monkeypatch.context() as patch:
        _read_only_from_cache(patch)
        again = bayesprog.load(path)
    assert again is not first and again.path == path
    for question in ["P(D)", "P(A | D=s3)", "P(B | A=s1, D=s7)"]:
        assert np.array_equal(first.posterior(question).probabilities,
                              again.posterior(question).probabilities)


def test_a_fresh_process_reads_the_kept_program(tmp_path, kept):
    path = tmp_path / "net.yaml"
    path.write_text(_network())
    script = ("import sys, json, bayesprog, bayesprog.program\n"
              "p = bayesprog.load(sys.argv[1])\n"
              "print(json.dumps(p.posterior('P(A | D=s2)').probabilities.tolist()))\n")
    env = dict(os.environ)
    runs = [subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True,
                           text=True, timeout=120, env=env) for _ in range(2)]
    assert all(r.returncode == 0 for r in runs), [r.stderr for r in runs]
    assert json.loads(runs[0].stdout) == json.loads(runs[1].stdout)
    assert len(list(kept.glob("*.pickle"))) == 1


def test_a_changed_file_is_checked_again_with_its_diagnostics(tmp_path, kept, monkeypatch):
    path = tmp_path / "net.yaml"
    text = _network()
    path.write_text(text)
    bayesprog.load(path)
    lines = text.splitlines()
    row = next(i for i, line in enumerate(lines) if line.lstrip().startswith("[0."))
    first_number = lines[row].index("0.")
    lines[row] = lines[row][:first_number] + "7" + lines[row][first_number + 1:]  # 0.x -> 7.x
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(SpecError) as caught:
        bayesprog.load(path)
    # at the row (its bracket), as when every number is read as YAML
    assert any(d.line == row + 1 and d.column == lines[row].index("[") + 1
               and "summing to 1" in d.message for d in caught.value.diagnostics), \
        caught.value.diagnostics


def test_a_program_that_names_another_file_is_not_kept(tmp_path, kept):
    (tmp_path / "sub.yaml").write_text(
        "bayesprog: 1\nvariables:\n  A: {states: [a0, a1]}\n  B: {states: [b0, b1]}\n"
        "decomposition:\n  - {term: P(A), form: uniform}\n"
        "  - {term: P(B | A), form: table, table: [[0.9, 0.1], [0.2, 0.8]]}\n")
    text = ("bayesprog: 1\n" + "# " + "x" * cache.MIN_BYTES + "\n"
            "variables:\n  A: {states: [a0, a1]}\n  B: {states: [b0, b1]}\n"
            "decomposition:\n  - {term: P(A), form: uniform}\n"
            "  - {term: P(B | A), form: program, program: sub.yaml, question: 'P(B | A)'}\n")
    path = tmp_path / "main.yaml"
    path.write_text(text)
    first = bayesprog.load(path)
    assert not kept.exists() or not list(kept.glob("*.pickle"))
    (tmp_path / "sub.yaml").write_text((tmp_path / "sub.yaml").read_text().replace(
        "[[0.9, 0.1], [0.2, 0.8]]", "[[0.5, 0.5], [0.2, 0.8]]"))
    assert not np.allclose(first.posterior("P(B | A=a0)").probabilities,
                           bayesprog.load(path).posterior("P(B | A=a0)").probabilities)


def test_other_limits_make_another_key(tmp_path, kept):
    path = tmp_path / "net.yaml"
    path.write_text(_network(states=40))
    bayesprog.load(path)
    limits.set_limits(entries=1000)  # a 40 x 40 table needs 1,600
    try:
        with pytest.raises(SpecError, match="more than the limit of 1,000"):
            bayesprog.load(path)
    finally:
        limits.set_limits()


def test_a_damaged_entry_is_read_again_and_replaced(tmp_path, kept):
    path = tmp_path / "net.yaml"
    path.write_text(_network())
    bayesprog.load(path)
    (entry,) = kept.glob("*.pickle")
    entry.write_bytes(entry.read_bytes()[:100])
    assert bayesprog.load(path).posterior("P(D)").probabilities.shape == (30,)
    assert len(entry.read_bytes()) > 100


def test_off_keeps_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("BAYESPROG_CACHE", "off")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    path = tmp_path / "net.yaml"
    path.write_text(_network())
    bayesprog.load(path)
    assert cache.folder() is None and not (tmp_path / "xdg").exists()


def test_the_least_recently_used_go_first(tmp_path, kept, monkeypatch):
    monkeypatch.setattr(cache, "MAX_ENTRIES", 2)
    paths = [tmp_path / f"net{seed}.yaml" for seed in range(3)]
    for seed, path in enumerate(paths):
        path.write_text(_network(seed=seed))
        bayesprog.load(path)
    assert len(list(kept.glob("*.pickle"))) == 2
    with monkeypatch.context() as patch:
        _read_only_from_cache(patch)
        bayesprog.load(paths[2])
        with pytest.raises(AssertionError, match="checked again"):
            bayesprog.load(paths[0])
