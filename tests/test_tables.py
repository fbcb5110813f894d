"""Tables of numbers read as arrays: the same program and the same diagnostics (file, line,
column, message) as when every number is read as a YAML node; large networks within the
limits; tables written a row per line and read back to the bit."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import bayesprog
from bayesprog.errors import SpecError
from bayesprog.io import dump_document
from bayesprog.language import loader
from bayesprog.language.flow import flow_table
from bayesprog.support import yamltext

TWO_PARENTS = """\
bayesprog: 1
variables:
  A: {states: [a0, a1, a2]}
  B: {states: [b0, b1]}
  C: {states: [c0, c1, c2, c3]}
decomposition:
  - {term: P(A), form: table, table: [0.2, 0.3, 0.5]}
  - {term: P(B), form: uniform}
  - term: P(C | A, B)
    form: table
    table: TABLE
"""


def _table(seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).dirichlet(np.ones(4), size=(3, 2))


def _problems(text: str, as_yaml: bool, monkeypatch) -> list[str]:
    with monkeypatch.context() as patch:
        if as_yaml:
            patch.setattr(yamltext, "BLOCK_MIN_CHARS", 10**9)
        try:
            bayesprog.loads(text, "net.yaml")
        except SpecError as exc:
            return [str(d) for d in exc.diagnostics]
    return []


@pytest.mark.parametrize("layout", ["one line", "a row per line"])
@pytest.mark.parametrize("change", [
    ("a row that does not sum to 1", lambda t: t.__setitem__((2, 1, 3), 0.9)),
    ("a negative number", lambda t: (t.__setitem__((1, 0, 0), -0.1),
                                     t.__setitem__((1, 0, 1), t[1, 0, 1] + 0.1))),
    ("a number too large", lambda t: t.__setitem__((0, 1, 2), 1e300)),
])
def test_a_wrong_row_is_placed_as_when_every_number_is_read_as_yaml(layout, change,
                                                                    monkeypatch):
    table = _table()
    change[1](table)
    written = json.dumps(table.tolist()) if layout == "one line" else \
        flow_table(table, column=len("    table: "))
    text = TWO_PARENTS.replace("TABLE", written)
    as_arrays, as_yaml = _problems(text, False, monkeypatch), _problems(text, True, monkeypatch)
    assert as_arrays and as_arrays == as_yaml, (as_arrays, as_yaml)


@pytest.mark.parametrize("written", [
    "[[[0.5, 0.5, 0, 0], [0.25, 0.25, 0.25, 0.25]], [[1, 0, 0, 0], [0, 1, 0, 0]], "
    "[[0.1, 0.2, 0.3, 0.4], [0.5, 0.5]]]",  # a short row
    "[[[0.5, 0.5, 0, 0], [0.25, 0.25, 0.25, 0.25]], [[1, 0, 0, 0], [0, 1, 0, 0]], "
    "[[0.1, 0.2, 0.3, 0.4], [0.5, 0.5, 0, 0, 0]]]",  # a long row
    "[[[0.5, 0.5, 0], [0.25, 0.25, 0.5]], [[1, 0, 0], [0, 1, 0]], [[0.1, 0.2, 0.7], "
    "[0.5, 0.5, 0]]]",  # every row too short: read as an array
    "[[[0.5, 0.5, 0, 0], [0.25, 0.25, 0.25, 0.25]], [[1, 0, 0, 0], [0, 1, 0, 0]], "
    "[[0.1, 0.2, 0.3, 0.4], [0.5, 0.5, zero, 0]]]",  # a word
    "[[[0.5, 0.5, 0, 0], [0.25, 0.25, 0.25, 0.25]], [[1, 0, 0, 0], [0, 1, 0, 0]], "
    "[[0.1, 0.2, 0.3, 0.4], [.5, .5, 0, 0]]]",  # numbers JSON does not read
    "[[[0.5, 0.5, 0, 0], [0.25, 0.25, 0.25, 0.25]], [[1, 0, 0, 0], [0, 1, 0, 0]]]",  # 2 of 3
])
def test_a_malformed_table_is_reported_as_when_read_as_yaml(written, monkeypatch):
    text = TWO_PARENTS.replace("TABLE", written)
    as_arrays, as_yaml = _problems(text, False, monkeypatch), _problems(text, True, monkeypatch)
    assert as_arrays == as_yaml, (as_arrays, as_yaml)
    assert as_arrays or "[.5" in written


def test_a_good_table_gives_the_same_program_both_ways(monkeypatch):
    text = TWO_PARENTS.replace("TABLE", flow_table(_table(3), column=11))
    fast = bayesprog.loads(text)
    with monkeypatch.context() as patch:
        patch.setattr(yamltext, "BLOCK_MIN_CHARS", 10**9)
        slow = bayesprog.loads(text)
    for question in ["P(C)", "P(A | C=c2)", "P(B | C=c0)"]:
        assert np.array_equal(fast.posterior(question).probabilities,
                              slow.posterior(question).probabilities)


def test_what_follows_a_table_keeps_its_line_and_column():
    table = flow_table(_table(1), column=len("  - {term: 'P(C | A, B)', form: table, table: "))
    text = TWO_PARENTS.replace(
        "  - term: P(C | A, B)\n    form: table\n    table: TABLE\n",
        f"  - {{term: 'P(C | A, B)', form: table, table: {table}, bad: 1}}\n")
    with pytest.raises(SpecError) as caught:
        bayesprog.loads(text, "net.yaml")
    last = text.splitlines()[-1]
    line, column = len(text.splitlines()), last.index("bad") + 1
    assert any(f"net.yaml:{line}:{column}:" in str(d) for d in caught.value.diagnostics), \
        caught.value.diagnostics


@pytest.mark.parametrize("shape", [(5,), (3, 4), (2, 3, 7), (2, 2, 2, 40)])
def test_a_written_table_reads_back_to_the_bit(shape):
    rng = np.random.default_rng(len(shape))
    table = rng.dirichlet(np.ones(shape[-1]) * 0.3, size=shape[:-1])
    table[..., 0] = 0.0  # zeros, and numbers written with exponents
    table /= table.sum(axis=-1, keepdims=True)
    table[(0,) * (len(shape) - 1)] = np.r_[1e-300, 1 - 1e-300, np.zeros(shape[-1] - 2)] \
        if shape[-1] > 2 else table[(0,) * (len(shape) - 1)]
    doc = {"bayesprog": 1, "variables": {
        f"V{i}": {"states": [f"s{j}" for j in range(n)]} for i, n in enumerate(shape)},
        "decomposition": [{"term": f"P(V{i})", "form": "uniform"}
                          for i in range(len(shape) - 1)]}
    child, parents = f"V{len(shape) - 1}", [f"V{i}" for i in range(len(shape) - 1)]
    term = f"P({child} | {', '.join(parents)})" if parents else f"P({child})"
    doc["decomposition"].append({"term": term, "form": "table", "table": table.tolist()})
    text = dump_document(doc)
    written = text[text.index("  table: "):]
    assert max(len(line) for line in written.splitlines()) <= 100
    located, problems = loader.load_yaml(text, "t.yaml")
    assert not problems
    read = np.asarray(located.data["decomposition"][-1]["table"])
    assert read.shape == table.shape and np.array_equal(read, table)
    program = bayesprog.loads(text)
    assert program.ask(f"P({child})") is not None


#: a small process that runs the load in another and reads its peak memory (a child forked
#: from a large test process would report the parent's size as its own peak)
_MEASURE = ("import json, resource, subprocess, sys\n"
            "r = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
            "peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss\n"
            "print(json.dumps([r.returncode, r.stderr, peak]))")
_LOAD = "import sys, bayesprog; bayesprog.load(sys.argv[1])"


def test_a_network_of_a_million_numbers_loads_within_the_memory_it_needs(tmp_path):
    # a child of 50 states under three parents of 20, 25 and 40 states: 1,000,000 numbers, more
    # than the 500,000 values a file may hold as YAML nodes
    rng = np.random.default_rng(2)
    shape = (20, 25, 40, 50)
    doc = {"bayesprog": 1, "variables": {
        f"V{i}": {"states": [f"s{j}" for j in range(n)]} for i, n in enumerate(shape)},
        "decomposition": [{"term": f"P(V{i})", "form": "uniform"} for i in range(3)]
        + [{"term": "P(V3 | V0, V1, V2)", "form": "table",
            "table": rng.dirichlet(np.ones(50), size=shape[:-1]).tolist()}]}
    path = tmp_path / "large.yaml"
    path.write_text(dump_document(doc))
    result = subprocess.run([sys.executable, "-c", _MEASURE, sys.executable, "-c", _LOAD,
                             str(path)], capture_output=True, text=True, timeout=300,
                            env=dict(os.environ))
    status, err, peak_kb = json.loads(result.stdout)
    assert status == 0, err
    assert peak_kb / 1024 < 600


def test_an_alias_bomb_beside_a_large_table_is_still_refused(tmp_path):
    bomb = "bomb: &a0 [1, 2, 3, 4, 5, 6, 7, 8, 9]\n" + "".join(
        f"b{i}: &a{i + 1} [" + ", ".join([f"*a{i}"] * 9) + "]\n" for i in range(8))
    text = TWO_PARENTS.replace("TABLE", flow_table(_table(), column=11)) + bomb
    with pytest.raises(SpecError) as caught:
        bayesprog.loads(text, "bomb.yaml")
    assert f"more than {loader.MAX_VALUES:,} values" in str(caught.value)


def test_tables_past_the_limit_are_refused_before_they_are_read(monkeypatch):
    monkeypatch.setattr(yamltext, "MAX_TABLE_NUMBERS", 20)
    read = []
    monkeypatch.setattr(yamltext.json, "loads", lambda text: read.append(text) or [])
    text = TWO_PARENTS.replace("TABLE", flow_table(_table(), column=11))
    with pytest.raises(SpecError) as caught:
        bayesprog.loads(text, "big.yaml")
    assert "big.yaml:1:1: the file's tables hold at least 24 numbers, more than the 20" \
        in str(caught.value)
    assert not [t for t in read if t.count(",") > 2]  # P(A)'s three numbers only


def test_a_fitted_files_statistics_are_read_as_arrays_and_give_the_yaml_record(monkeypatch,
                                                                               tmp_path):
    """A fit's statistics under learned: are read like tables (as arrays, not a YAML node per
    number): the record is the one YAML gives, and what follows them keeps its place."""
    program = bayesprog.loads(TWO_PARENTS.replace("TABLE", flow_table(_table(2), column=11)))
    rng = np.random.default_rng(5)
    rows = {"A": rng.choice(["a0", "a1", "a2"], 400).tolist(),
            "B": rng.choice(["b0", "b1"], 400).tolist(),
            "C": rng.choice(["c0", "c1", "c2", "c3"], 400).tolist()}
    source = tmp_path / "net.yaml"
    source.write_text(TWO_PARENTS.replace("TABLE", flow_table(_table(2), column=11)))
    text = program.fit(rows).text(source) + "# after the record\nname: fitted\n"
    blocks = yamltext.number_blocks(text)[1]
    # the counts of P(C | A, B): one per row
    assert any(array.shape == (3, 2, 4) and array.sum() == 400 for array, _, _ in blocks.values())
    fast = bayesprog.loads(text)
    with monkeypatch.context() as patch:
        patch.setattr(yamltext, "BLOCK_MIN_CHARS", 10**9)
        slow = bayesprog.loads(text)
    assert fast.learned == slow.learned
    assert fast.learned[-1].statistics["P(C | A, B)"]["counts"] == \
        slow.learned[-1].statistics["P(C | A, B)"]["counts"]
    assert isinstance(fast.learned[-1].statistics["P(C | A, B)"]["counts"], list)
    assert fast.name == slow.name == "fitted"
    broken = text.replace("name: fitted", "name: [fitted")
    assert _problems(broken, False, monkeypatch) == _problems(broken, True, monkeypatch)


def test_only_the_statistics_of_the_fits_records_are_read_as_arrays():
    text = ("bayesprog: 1\nlearned:\n  - data: d.csv\n    statistics:\n      P(A):\n"
            "        counts: [137.0, 163.0, 100.0]\n"
            "inputs:\n  statistics:\n    shape: [100000, 3, 7]\n")
    taken = [written for _, written, _ in yamltext.number_blocks(text)[1].values()]
    assert taken == ["[137.0, 163.0, 100.0]"]


def test_the_lists_read_as_arrays_are_found_where_a_key_stands_not_inside_words():
    """A table's key after the start, a blank, ``{`` or ``,`` (any blank a YAML reader knows);
    the statistics of records under a ``learned:`` that starts its line, their lines up to the
    first indented no further than the key."""
    text = ("a: {table: [0.5, 0.5]}\nxtable: [0.1, 0.9]\nb: {c: 1,table: [0.2, 0.8]}\n"
            "\u2028table: [0.3, 0.7]\n# learned:\n  statistics:\n    P(A): {counts: [9.0, 1.0]}\n"
            "learned :\n- data: d.csv\n  statistics: # the counts\n    P(A):\n"
            "      counts: [1.0, 2.0]\n    P(B | A): {counts: [[1.0, 2.0], [3.0, 4.0]]}\n"
            "  rows: [10, 20]\n-  statistics:\n    P(A): {counts: [3.0, 4.0]}\nother: [5.0, 6.0]\n")
    starts = yamltext._block_starts(text)
    assert [text[s:yamltext._closing(text, s, len(text))] for s in starts] == [
        "[0.5, 0.5]", "[0.2, 0.8]", "[0.3, 0.7]", "[1.0, 2.0]", "[[1.0, 2.0], [3.0, 4.0]]",
        "[3.0, 4.0]"]


@pytest.mark.parametrize("scan", [1, 5, 1 << 16])
def test_a_tables_closing_bracket_is_found_whatever_the_block_read_at_a_time(monkeypatch, scan):
    monkeypatch.setattr(yamltext, "SCAN_CHARS", scan)
    text = "table: [[0.25, 0.75],\n        [1.0, 0.0]]\n- [0.5]"
    start = text.index("[")
    assert yamltext._closing(text, start, len(text)) == text.index("]]") + 2
    assert yamltext._closing(text, start, text.index("]]")) == start  # not closed before
    assert yamltext._closing("[1, [2]]]", 0, 9) == 8
