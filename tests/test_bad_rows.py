"""Bad rows: refused by default in one line that names the file and the line; set aside on
request (``on_bad_lines="skip"``/``"warn"``, ``bayesprog learn --on-bad-lines``), each named by
its line and why, the fit then equal to a fit on the file without them and to numpy's
maximum-likelihood estimates; missing values are never bad rows. Both readers (numpy's plain
CSV reader and the csv module's) and the pandas path (Parquet, a data frame) honour it, and
``bayesprog.read_data`` reads a data set so for an application."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest

import bayesprog
from bayesprog.cli import main
from bayesprog.learning import BadRow, BadRowsWarning, DataError
from bayesprog.learning.plain_csv import read_file

PROGRAM = """\
bayesprog: 1
name: probe
variables:
  M: {states: [glass, wood, felt]}
  E: {continuous: [-.inf, .inf], description: texture}
decomposition:
  - {term: P(M), form: table, table: [0.2, 0.3, 0.5]}
  - {term: P(E | M), form: normal, mean: 0.0, sigma: 1.0}
"""

MEANS = {"glass": 0.1, "wood": 0.5, "felt": 0.8}


def good_lines(seed: int, n: int = 60) -> list[str]:
    """``n`` rows ``M,E`` drawn with a fixed seed, every state with many rows."""
    rng = np.random.default_rng(seed)
    states = rng.choice(list(MEANS), size=n, p=[0.3, 0.3, 0.4])
    return [f"{m},{rng.normal(MEANS[m], 0.05):.6f}" for m in states]


#: the bad rows put into the file, by the line they take, and words of why each is bad
BAD = {
    5: ("wood", "1 field, expected 2"),
    9: ("wood,0.3,7", "3 fields, expected 2"),
    14: ("felt,abc", "column 'E': expected a number for continuous E, found 'abc'"),
    20: ("glas,0.12", "column 'M': unknown state 'glas' of M (did you mean 'glass'?): expected "
                      "one of glass, wood, felt"),
}
#: rows with a missing value: not bad (the first misses its texture, the second a whole row)
MISSING = {7: "felt,", 25: ""}


def files(tmp_path, seed: int = 0, bad: dict | None = None, missing: dict | None = None
          ) -> tuple:
    """(the file with bad rows and rows with missing values, the same file without the bad
    rows)."""
    bad = BAD if bad is None else bad
    missing = MISSING if missing is None else missing
    good = good_lines(seed)
    lines, clean = ["M,E"], ["M,E"]
    for line in range(2, len(good) + len(bad) + len(missing) + 2):
        if line in bad:
            lines.append(bad[line][0])
        else:
            text = missing[line] if line in missing else good.pop()
            lines.append(text)
            clean.append(text)
    dirty_path, clean_path = tmp_path / "probes.csv", tmp_path / "clean.csv"
    dirty_path.write_text("\n".join(lines) + "\n")
    clean_path.write_text("\n".join(clean) + "\n")
    return dirty_path, clean_path


def program(tmp_path=None):
    if tmp_path is None:
        return bayesprog.loads(PROGRAM)
    path = tmp_path / "probe.yaml"
    path.write_text(PROGRAM)
    return path


def assert_same_fit(a, b):
    for term in ("P(M)", "P(E | M)"):
        for name, value in a.program.term(term).params.items():
            np.testing.assert_allclose(b.program.term(term).params[name].array, value.array,
                                       rtol=1e-13, atol=0)


def maximum_likelihood(clean_path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """P(M) and the Normals' means and standard deviations by numpy, from the clean file."""
    frame = pd.read_csv(clean_path, skip_blank_lines=False)
    named = frame.dropna(subset=["M"])
    table = np.array([(named["M"] == m).mean() for m in MEANS])
    both = named.dropna(subset=["E"])
    means = np.array([both.loc[both["M"] == m, "E"].mean() for m in MEANS])
    sds = np.array([both.loc[both["M"] == m, "E"].std(ddof=0) for m in MEANS])
    return table, means, sds


def test_the_first_bad_row_is_refused_in_one_line_with_its_line(tmp_path):
    dirty, _ = files(tmp_path)
    with pytest.raises(DataError) as err:
        program().fit(dirty)
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith(f"{dirty}: row 4 (line 5): 1 field, expected 2"), message
    assert 'on_bad_lines="skip"' in message
    # the earliest bad row, whatever its kind: a value before any short row
    values_first = {3: ("felt,abc", ""), 8: ("wood", "")}
    dirty, _ = files(tmp_path, bad=values_first)
    with pytest.raises(DataError, match=r"probes.csv: row 2 \(line 3\), column 'E': expected a "
                       "number for continuous E, found 'abc'"):
        program().fit(dirty)


def test_skip_sets_aside_exactly_the_bad_rows_and_fits_as_without_them(tmp_path):
    dirty, clean = files(tmp_path)
    fit = program().fit(dirty, on_bad_lines="skip")
    assert [(b.line, b.why) for b in fit.set_aside] == [(k, v[1]) for k, v in BAD.items()]
    assert [b.row for b in fit.set_aside] == [k - 1 for k in BAD]
    assert all(isinstance(b, BadRow) for b in fit.set_aside)
    reference = program().fit(clean)
    assert_same_fit(fit, reference)
    record, theirs = fit.record, reference.record
    assert record.rows == theirs.rows + len(BAD) and record.rows_set_aside == len(BAD)
    assert record.rows_used == theirs.rows_used == theirs.rows - 1  # the blank row is unused
    assert record.log_likelihood == pytest.approx(theirs.log_likelihood, rel=1e-13)
    assert theirs.rows_set_aside is None  # bad rows refused (there were none)
    # and as numpy counts and averages the clean rows
    table, means, sds = maximum_likelihood(clean)
    params = fit.program.term("P(E | M)").params
    np.testing.assert_allclose(fit.program.term("P(M)").params["table"].array, table, rtol=1e-12)
    np.testing.assert_allclose(params["mean"].array, means, rtol=1e-12)
    np.testing.assert_allclose(params["sigma"].array, sds, rtol=1e-10)


def test_warn_warns_with_the_lines_and_fits_as_skip(tmp_path):
    dirty, _ = files(tmp_path)
    with pytest.warns(BadRowsWarning) as caught:
        fit = program().fit(dirty, on_bad_lines="warn")
    text = str(caught[0].message)
    assert text.startswith("probes.csv: 4 bad rows set aside:")
    assert all(f"line {k}: {v[1]}" in text for k, v in BAD.items()), text
    assert_same_fit(fit, program().fit(dirty, on_bad_lines="skip"))
    with warnings.catch_warnings():  # nothing bad: nothing to say
        warnings.simplefilter("error")
        program().fit(files(tmp_path, bad={})[0], on_bad_lines="warn")


def test_the_plain_reader_and_the_csv_module_set_aside_the_same_rows(tmp_path):
    """Values that cannot be read are set aside by the fast reader itself; a row of another
    length sends the file to the csv module's reader, which names every row alike."""
    values_only = {k: v for k, v in BAD.items() if "column" in v[1]}
    dirty, clean = files(tmp_path, bad=values_only, missing={7: "felt,"})  # no blank line
    assert read_file(dirty) is not None  # plain: read by numpy
    fast = program().fit(dirty, on_bad_lines="skip")
    assert [b.line for b in fast.set_aside] == list(values_only)
    assert_same_fit(fast, program().fit(clean))
    quoted = tmp_path / "quoted.csv"  # the same rows, quoted: the csv module reads them
    quoted.write_text("".join(
        ",".join(f'"{cell}"' if cell else "" for cell in line.split(",")) + "\n"
        for line in dirty.read_text().splitlines()))
    assert read_file(quoted) is None
    careful = program().fit(quoted, on_bad_lines="skip")
    assert careful.set_aside == fast.set_aside
    assert_same_fit(careful, fast)


def test_lines_are_counted_as_an_editor_shows_them(tmp_path):
    """A quoted value spanning two lines, and bytes that are not UTF-8."""
    data = tmp_path / "odd.csv"
    data.write_bytes(b'M,E\nwood,0.5\n"wo\nod",0.4\nfelt,abc\nw\xffod,0.2\nfelt,0.8\n'
                     b"wood,0.45\nfelt,0.9\nglass,0.1\nglass,0.15\n")
    fit = program().fit(data, on_bad_lines="skip")
    assert [(b.line, b.row) for b in fit.set_aside] == [(3, 2), (5, 3), (6, 4)]
    assert "unknown state 'wo\\nod'" in fit.set_aside[0].why
    assert fit.set_aside[2].why == "not UTF-8 text (byte 0xff)"
    assert fit.record.rows_used == 6
    spanning = tmp_path / "spanning.csv"  # a good row on two lines: the next is on line 5
    spanning.write_bytes(b'M,E\nwood,0.5\nwood,"0.4\n"\nfelt,abc\n')
    with pytest.raises(DataError, match=r"spanning.csv: row 3 \(line 5\), column 'E'"):
        program().fit(spanning)
    bytes_only = tmp_path / "bytes.csv"
    bytes_only.write_bytes(b"M,E\nwood,0.5\nw\xffod,0.2\n")
    with pytest.raises(DataError, match=r"bytes.csv: row 2 \(line 3\): not UTF-8 text"):
        program().fit(bytes_only)


def test_data_frames_and_parquet_files_set_aside_their_bad_rows_by_row(tmp_path):
    pytest.importorskip("pyarrow")
    rows = [line.split(",") for line in good_lines(3, 40)]
    rows.insert(6, ["felt", "abc"])
    rows.insert(11, ["glas", "0.3"])
    rows.insert(15, ["wood", None])  # missing: kept
    frame = pd.DataFrame(rows, columns=["M", "E"])
    clean = frame.drop(index=[6, 11]).reset_index(drop=True)
    path = tmp_path / "probes.parquet"
    frame.to_parquet(path)
    for source in (frame, path):
        fit = program().fit(source, on_bad_lines="skip")
        assert [(b.line, b.row) for b in fit.set_aside] == [(None, 7), (None, 12)]
        assert [str(b).split(":")[0] for b in fit.set_aside] == ["row 7", "row 12"]
        assert_same_fit(fit, program().fit(clean))
        assert fit.record.rows_set_aside == 2
    with pytest.raises(DataError, match=r"probes.parquet: row 7, column 'E': expected a number"):
        program().fit(path)


def test_states_from_the_data_are_those_of_the_rows_kept(tmp_path):
    """Any value is a state of a variable that takes its states from the data: a misspelt
    material is then no bad row, but a material found only in a bad row is no state."""
    bad = {6: ("cork,abc", ""), 12: ("wood,0.3,1", "")}
    dirty, clean = files(tmp_path, bad=bad)
    fit = program().fit(dirty, states_from_data=["M"], on_bad_lines="skip")
    assert [b.line for b in fit.set_aside] == [6, 12]
    assert fit.states == {"M": ["felt", "glass", "wood"]}
    assert fit.program.variables["M"].states == ("felt", "glass", "wood")
    assert_same_fit(fit, program().fit(clean, states_from_data=["M"]))
    with pytest.raises(DataError, match=r"row 5 \(line 6\), column 'E'"):
        program().fit(dirty, states_from_data=["M"])


def test_missing_values_alone_are_never_bad_rows(tmp_path):
    dirty, clean = files(tmp_path, bad={})
    for mode in ("error", "skip"):
        fit = program().fit(dirty, on_bad_lines=mode)
        assert fit.set_aside == []
        assert fit.record.rows_set_aside == (None if mode == "error" else 0)
    with pytest.raises(bayesprog.BayesprogError, match="on_bad_lines: expected one of 'error', "
                       "'warn', 'skip', found 'ignore'"):
        program().fit(dirty, on_bad_lines="ignore")


def test_learn_refuses_the_first_bad_row_by_default(tmp_path, capsys):
    dirty, _ = files(tmp_path)
    out = tmp_path / "fitted.yaml"
    assert main(["learn", str(program(tmp_path)), str(dirty), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == (f"bayesprog: {dirty}: row 4 (line 5): 1 field, expected 2 (--on-bad-lines "
                   "skip sets bad rows aside)\n")
    assert not out.exists() and not out.with_suffix(".set-aside.txt").exists()


@pytest.mark.parametrize("mode", ["skip", "warn"])
def test_learn_sets_bad_rows_aside_lists_them_and_counts_them(tmp_path, capsys, mode):
    dirty, clean = files(tmp_path)
    source = program(tmp_path)
    out = tmp_path / "fitted.yaml"
    assert main(["learn", str(source), str(dirty), "-o", str(out), "--on-bad-lines", mode]) == 0
    stdout, stderr = capsys.readouterr()
    listing = tmp_path / "fitted.set-aside.txt"
    assert stdout.splitlines()[-1] == f"4 bad rows of probes.csv set aside, listed in {listing}"
    expected = [f"{dirty}:{line}: {why}" for line, (_, why) in BAD.items()]
    assert listing.read_text().splitlines() == expected
    if mode == "warn":
        assert stderr.splitlines() == [f"{dirty}:{line}: set aside: {why}"
                                       for line, (_, why) in BAD.items()]
    else:
        assert stderr == ""
    fitted = bayesprog.load(out)
    assert fitted.learned[-1].rows_set_aside == 4 and "rows_set_aside: 4" in out.read_text()
    reference = program().fit(clean).program
    for term in ("P(M)", "P(E | M)"):
        for name, value in reference.term(term).params.items():
            np.testing.assert_allclose(fitted.term(term).params[name].array, value.array,
                                       rtol=1e-13)
    # a file with nothing bad: the list is written, empty, and the count says so
    assert main(["learn", str(source), str(clean), "-o", str(out), "--on-bad-lines", mode]) == 0
    assert capsys.readouterr().out.splitlines()[-1].startswith("no bad rows of clean.csv set")
    assert listing.read_text() == ""


def test_read_data_gives_the_rows_that_can_be_read_and_those_set_aside(tmp_path):
    data = tmp_path / "lab.csv"
    data.write_text("material,texture,cell\nglass,0.1,3\ncork,0.5,4\nfelt,abc,5\nfelt,,6\n"
                    "glas,0.2\nwood,0.52,8\n")
    variables = program().variables
    frame, set_aside = bayesprog.read_data(data, variables, columns={"material": "M",
                                                                     "texture": "E"})
    assert [(b.line, b.row) for b in set_aside] == [(3, 2), (4, 3), (6, 5)]
    assert "unknown state 'cork'" in set_aside[0].why and "'abc'" in set_aside[1].why
    assert set_aside[2].why == "2 fields, expected 3"
    expected = pd.DataFrame({"M": ["glass", "felt", "wood"], "E": [0.1, np.nan, 0.52],
                             "cell": [3, 6, 8]})
    pd.testing.assert_frame_equal(frame, expected, check_dtype=False)
    assert frame["E"].dtype == float and frame["cell"].dtype.kind in "if"
    # the materials as found: only the non-number and the short row are bad
    frame, set_aside = bayesprog.read_data(data, variables, states_from_data=["M"],
                                           columns={"material": "M", "texture": "E"})
    assert [b.line for b in set_aside] == [4, 6]
    assert frame["M"].tolist() == ["glass", "cork", "felt", "wood"]
    # no program: only the rows that cannot be split are bad
    frame, set_aside = bayesprog.read_data(data)
    assert [b.line for b in set_aside] == [6]
    texture = frame["texture"]
    assert texture[~texture.isna()].tolist() == ["0.1", "0.5", "abc", "0.52"]
    assert texture.isna().tolist() == [False, False, False, True, False]
    with pytest.warns(BadRowsWarning, match="line 6: 2 fields, expected 3"):
        bayesprog.read_data(data, on_bad_lines="warn")
    with pytest.raises(DataError, match=r"lab.csv: row 5 \(line 6\): 2 fields, expected 3"):
        bayesprog.read_data(data, on_bad_lines="error")
