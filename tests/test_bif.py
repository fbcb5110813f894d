"""BIF files read by bayesprog.io.bif, checked against pgmpy's BIFReader: the program file
``bayesprog import`` writes is byte for byte the one written from pgmpy's model; what the
reader does not know is read by pgmpy; malformed files and oversized tables are refused with
the file, line and column."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

import bayesprog.io
from bayesprog.cli import main
from bayesprog.io import NetworkError, dump_document, import_network, network_to_document
from bayesprog.io import read_network as read_with_pgmpy
from bayesprog.io.bif import BifError, Network, check_sizes_as_pgmpy_reads, read_bif
from bayesprog.limits import SizeError, set_limits

EXAMPLES = Path(__import__("pgmpy").__file__).parent / "utils" / "example_models"


def _pgmpy_text(path: Path, name: str) -> str:
    """The program file the importer wrote before it had its own reader: pgmpy's model."""
    return dump_document(network_to_document(read_with_pgmpy(path), name, path.name))


def _written(path: Path, tmp_path: Path) -> str:
    return import_network(path, tmp_path / "out.yaml").read_text(encoding="utf-8")


def _refuse(*args, **kwargs):
    raise AssertionError("pgmpy's reader was used")


@pytest.fixture
def no_pgmpy(monkeypatch):
    """pgmpy's reader made unusable: what is read is read by bayesprog.io.bif alone."""
    monkeypatch.setattr(bayesprog.io, "_pgmpy_model", _refuse)


@pytest.mark.parametrize("name", ["asia", "cancer", "alarm", "child", "insurance"])
def test_a_shipped_network_imports_byte_for_byte_as_through_pgmpy(name, tmp_path, monkeypatch):
    path = tmp_path / f"{name}.bif"
    path.write_bytes(gzip.decompress((EXAMPLES / f"{name}.bif.gz").read_bytes()))
    expected = _pgmpy_text(path, name)
    monkeypatch.setattr(bayesprog.io, "_pgmpy_model", _refuse)  # bayesprog.io.bif alone
    assert _written(path, tmp_path) == expected
    # gzipped as shipped: only the file's name, in the description, differs
    gzipped = expected.replace(f"{name}.bif", f"{name}.bif.gz")
    assert _written(EXAMPLES / f"{name}.bif.gz", tmp_path) == gzipped


FORMS = """\
/* a network with the forms BIF allows */
network "test net" {
  property "a property; with // no comment" ;
}
variable "Dog-problem" {          // a quoted name
  type discrete [ 2 ] { "true", "false" };
  property position = (10, 20) ;
}
variable light {
  type discrete[3]{ on , dim , off } ;
}
variable bark {
  property note = here first;
  type discrete [ 2 ] { yes, no };
}
probability ( Dog-problem ) { table 0.3, 0.7; }
probability ( light | Dog-problem ) {
  (false) 0.2, 0.3, 0.5;
  (true) 0.6, 0.3, 0.1;
}
probability ( bark | light, Dog-problem ) {
  (dim, true) 0.4, 0.6;
  (on, false) 0.25, 0.75;
  ( off , true ) 0.9 0.1 ;
  (on, true) 0.5, 0.5;
  (dim, false) 0.35, 0.65;
  (off, false) 0.8, 0.2;
}
"""


def test_the_forms_of_bif_are_read_as_pgmpy_reads_them(tmp_path, monkeypatch):
    path = tmp_path / "forms.bif"
    path.write_text(FORMS)
    net = read_bif(FORMS)
    assert net.states == {"Dog-problem": ["true", "false"], "light": ["on", "dim", "off"],
                          "bark": ["yes", "no"]}
    bark = net.tables["bark"]
    assert bark.parents == ("light", "Dog-problem") and bark.values.shape == (2, 3, 2)
    np.testing.assert_array_equal(bark.values[0], [[0.5, 0.25], [0.4, 0.35], [0.9, 0.8]])
    expected = _pgmpy_text(path, "forms")
    monkeypatch.setattr(bayesprog.io, "_pgmpy_model", _refuse)
    assert _written(path, tmp_path) == expected


def test_a_name_with_blanks_is_read_where_pgmpy_reads_its_first_word(tmp_path, no_pgmpy):
    text = FORMS.replace("Dog-problem", "Dog problem")
    path = tmp_path / "blank.bif"
    path.write_text(text)
    assert read_bif(text).tables["bark"].parents == ("light", "Dog problem")
    assert "named 'Dog problem' in blank.bif" in _written(path, tmp_path)


def test_default_rows_fill_the_rows_not_given_and_table_lists_the_child_slowest(no_pgmpy):
    net = read_bif("""
variable A { type discrete [ 3 ] { a1, a2, a3 }; }
variable B { type discrete [ 2 ] { b1, b2 }; }
variable C { type discrete [ 2 ] { c1, c2 }; }
probability ( A ) { table 0.2, 0.3, 0.5; }
probability ( B | A ) { default 0.5, 0.5; (a2) 0.1, 0.9; }
probability ( C | A, B ) { table 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4; }
""")
    np.testing.assert_array_equal(net.tables["B"].values, [[0.5, 0.1, 0.5], [0.5, 0.9, 0.5]])
    c = net.tables["C"].values
    assert c.shape == (2, 3, 2)
    np.testing.assert_array_equal(c[0].ravel(), [0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    np.testing.assert_array_equal(c[:, 2, 1], [0.6, 0.4])


def test_pgmpy_quirks_kept_old_headers_names_in_any_case_missing_rows_and_no_last_newline(
        no_pgmpy):
    text = ("variable Smoker { type discrete [ 2 ] { yes, no }; }\n"
            "variable cough { type discrete [ 2 ] { yes, no }; }\n"
            "probability ( SMOKER ) { table 0.3, 0.7; }\n"
            "probability ( cough smoker ) { (yes) 0.8, 0.2; }")
    net = read_bif(text)
    assert net.tables["cough"].parents == ("Smoker",)
    # a parents' row not given, and no default: zeros, as pgmpy reads it (the checker says so)
    np.testing.assert_array_equal(net.tables["cough"].values, [[0.8, 0.0], [0.2, 0.0]])


def test_what_pgmpy_does_not_read_is_read_headers_over_lines_probabilities_first(tmp_path,
                                                                                  no_pgmpy):
    path = tmp_path / "lines.bif"
    path.write_bytes(b"probability ( B |\r\n    A ) {\r\n  (a) 0.1, /* a comment */ 0.9;\r\n"
                     b"  (b) 0.7, // the rest of the line\r\n  0.3;\r\n}\r\n"
                     b"probability ( A ) { table 0.4 0.6 ; }\r\n"
                     b"variable A { type discrete [ 2 ] { a, b }; }\r\n"
                     b"variable B { type discrete [ 2 ] { c, d }; }")
    text = _written(path, tmp_path)
    assert "term: P(B | A)" in text and "[[0.1, 0.9]," in text and "[0.7, 0.3]]" in text


def test_a_construct_the_reader_does_not_know_is_read_by_pgmpy(tmp_path):
    # pgmpy reads any type word, and takes the states listed whatever the count says
    text = FORMS.replace("type discrete[3]{ on , dim , off }",
                         "type nominal [ 4 ] { on, dim, off }")
    path = tmp_path / "other.bif"
    path.write_text(text)
    with pytest.raises(BifError, match=r"other.bif:10:3: variable light: expected type discrete"):
        read_bif(text, str(path))
    assert _written(path, tmp_path) == _pgmpy_text(path, "other")



def test_pgmpys_reader_with_its_grammar_built_once_reads_as_pgmpys_own(tmp_path):
    from pgmpy.readwrite import BIFReader

    def model(name: str):
        path = tmp_path / f"{name}.bif"
        path.write_bytes(gzip.decompress((EXAMPLES / f"{name}.bif.gz").read_bytes()))
        return path, read_with_pgmpy(path)

    def same(a, b) -> bool:
        return (sorted(a.edges()) == sorted(b.edges())
                and {c.variable: c for c in a.get_cpds()} == {c.variable: c for c in b.get_cpds()})

    _, first = model("cancer")
    path, second = model("asia")  # the grammar built for the first file
    assert same(second, BIFReader(str(path)).get_model())
    assert same(model("cancer")[1], first) and not same(first, second)

@pytest.mark.parametrize("content, where", [
    ("variable A { type discrete [ 2 ] { a, b }; }\nprobability ( A ) { table 0.5, x.5; }\n",
     "bad.bif:2:32: cannot parse as BIF: table: expected a number, found 'x.5'"),
    ("variable A { type discrete [ 2 ] { a, b }; }\nvariable B { type discrete [ 2 ] { c, d }; }\n"
     "probability ( A ) { table 0.5, 0.5; }\n"
     "probability ( B | A ) {\n  (a) 0.5, 0.5;\n  (e) 0.1, 0.9;\n}\n",
     "bad.bif:6:4: cannot parse as BIF: 'e' is not a state of A: expected one of a, b"),
    ("variable A { type discrete [ 2 ] { a, b }; }\nprobability ( A | Z ) { (a) 0.5, 0.5; }\n",
     "bad.bif:2:19: cannot parse as BIF: 'Z' is not a declared variable"),
    ("variable A { type discrete [ 2 ] { a, b }; }\nvariable B { type discrete [ 2 ] { c, d }; }\n"
     "probability ( B | A ) {\n  (a) 0.5, 0.5;\n  (b) 0.1, 0.8, 0.1;\n}\n",
     "bad.bif:5:7: cannot parse as BIF: row: expected 2 numbers (one per state), found 3"),
    ("variable A { type discrete [ 2 ] { a, b }; }\nvariable B { type discrete [ 2 ] { c, d }; }\n"
     "probability ( A | B ) { (c) 0.5, 0.5; (d) 0.5, 0.5; }\n"
     "probability ( B | A ) { (a) 0.5, 0.5; (b) 0.5, 0.5; }\n",
     "bad.bif: a cycle: A -> B -> A: expected a directed acyclic graph"),
    ("variable A { type discrete [ 2 ] { a, b }; }\ngarbage\n",
     "bad.bif:2:1: cannot parse as BIF: expected network, variable or probability, found "
     "'garbage'"),
])
def test_a_malformed_file_is_one_line_with_its_line_and_column(tmp_path, capsys, content, where):
    bad = tmp_path / "bad.bif"
    bad.write_text(content)
    assert main(["import", str(bad), "-o", str(tmp_path / "bad.yaml")]) == 2
    err = capsys.readouterr().err
    assert where in err and len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err
    assert not (tmp_path / "bad.yaml").exists()


HUGE = ("variable A { type discrete [ 10 ] { 0, 1, 2, 3, 4, 5, 6, 7, 8, 9 }; }\n"
        + "".join(f"variable P{i} {{ type discrete [ 10 ] {{ 0, 1, 2, 3, 4, 5, 6, 7, 8, 9 }}; }}\n"
                  for i in range(12))
        + f"probability ( A | {', '.join(f'P{i}' for i in range(12))} ) {{ default "
        + ", ".join(["0.1"] * 10) + "; }\n")


def test_a_table_larger_than_the_limit_is_refused_before_it_is_allocated(tmp_path, capsys):
    with pytest.raises(SizeError, match=r"x.bif:14:1: the table of A \(10 x 10 x .*"
                                        r"needs 10,000,000,000,000 entries"):
        read_bif(HUGE, "x.bif")
    # as pgmpy reads it too: its reader allocates the table before it reads a row
    with pytest.raises(SizeError, match="the table of A"):
        check_sizes_as_pgmpy_reads(HUGE.replace("[ 10 ]", "[ 9 ]"), "x.bif")
    path = tmp_path / "huge.bif"
    path.write_text(HUGE.replace("[ 10 ]", "[ 9 ]"))  # not read by bayesprog.io.bif
    with pytest.raises(SizeError):
        read_with_pgmpy(path)
    assert main(["import", str(path), "-o", str(tmp_path / "x.yaml")]) == 2
    assert "BAYESPROG_MAX_ENTRIES" in capsys.readouterr().err


def test_the_tables_together_are_bounded_too():
    text = "".join(f"variable V{i} {{ type discrete [ 6 ] {{ a, b, c, d, e, f }}; }}\n"
                   for i in range(4))
    text += "".join(f"probability ( V{i} | V{i - 1} ) {{ default 1, 0, 0, 0, 0, 0; }}\n"
                    for i in range(1, 4))
    set_limits(entries=100)  # each table takes 36
    try:
        with pytest.raises(SizeError, match=r"x.bif:7:1: the tables up to that of V3 needs 108"):
            read_bif(text, "x.bif")
        with pytest.raises(SizeError, match=r"the tables up to that of V3 \(as pgmpy"):
            check_sizes_as_pgmpy_reads(text, "x.bif")
    finally:
        set_limits()
    assert read_bif(text).tables["V3"].values.sum() == 6


def test_the_reader_returns_a_network_that_names_its_arcs_in_the_files_order():
    net = read_bif(FORMS)
    assert isinstance(net, Network)
    assert net.edges() == [("Dog-problem", "light"), ("light", "bark"), ("Dog-problem", "bark")]
    with pytest.raises(BifError, match="1:1: no network"):
        read_bif("// nothing\n")


def test_an_empty_bif_file_is_said_not_to_be_one(tmp_path):
    path = tmp_path / "empty.bif"
    path.write_text("network x {}\n")
    with pytest.raises(NetworkError, match="no variables found: expected a BIF network"):
        import_network(path, tmp_path / "x.yaml")
