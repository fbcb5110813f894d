"""A data file summarised group by group and drawn pair by pair (``bayesprog show DATA.csv``):
the numbers against pandas' own groupby, the figure's panels, labels and colours read off the
matplotlib Figure, and the command line's output and errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayesprog.cli import main
from bayesprog.learning.data import DataError
from bayesprog.learning.summary import REAL_STATISTICS, summarise
from bayesprog.views.draw import scatter_matrix

ROOT = Path(__file__).parents[1]
LAB = ROOT / "models" / "data" / "lab_recordings.csv"
MATERIALS = ["cork", "felt", "steel", "wood"]
STATES = ["smooth", "ridged", "bumpy"]


@pytest.fixture
def recordings(tmp_path) -> Path:
    """Four readings of four materials of different sizes (seed 11): three real, one of
    states, a few cells of each empty; a cell column that is not a reading."""
    rng = np.random.default_rng(11)
    sizes = [30, 45, 60, 25]
    material = np.repeat(MATERIALS, sizes)
    n = material.size
    frame = pd.DataFrame({
        "material": material,
        "pdc": rng.normal(np.repeat([0, 1, 2, 3], sizes), 0.3),
        "pac_rms": rng.gamma(2.0, np.repeat([0.5, 1.0, 1.5, 2.0], sizes)),
        "tdc": rng.normal(30, 1, n),
        "electrode": rng.choice(STATES, n),
        "ix": rng.integers(0, 20, n),
    })
    for column in ("pdc", "tdc", "electrode"):
        frame.loc[rng.choice(n, 6, replace=False), column] = None
    path = tmp_path / "recordings.csv"
    frame.to_csv(path, index=False)
    return path


def test_the_summary_is_pandas_groupby_describe(recordings):
    summary = summarise(recordings)
    truth = pd.read_csv(recordings)  # pandas' own reading: empty cells are NaN
    assert summary.by == "material" and summary.rows == len(truth)
    assert summary.counts == truth["material"].value_counts().sort_index().to_dict()
    assert set(summary.real) == {"pdc", "pac_rms", "tdc", "ix"}
    assert set(summary.discrete) == {"electrode"}
    for column in summary.real:
        described = truth.groupby("material")[column].describe()
        ours = summary.real[column]
        assert list(ours.columns) == list(REAL_STATISTICS)
        for ours_key, theirs in [("count", "count"), ("mean", "mean"), ("sd", "std"),
                                 ("min", "min"), ("max", "max")]:
            np.testing.assert_allclose(ours[ours_key].to_numpy(float),
                                       described.loc[ours.index, theirs].to_numpy(float),
                                       rtol=1e-12, err_msg=f"{column} {ours_key}")
        missing = truth[column].isna().groupby(truth["material"]).sum()
        assert ours["missing"].astype(int).tolist() == missing.loc[ours.index].tolist()
    states = pd.crosstab(truth["material"], truth["electrode"])
    ours = summary.discrete["electrode"]
    assert sorted(c for c in ours.columns if c != "missing") == sorted(STATES)
    for state in STATES:
        assert ours[state].tolist() == states.loc[ours.index, state].tolist()
    assert ours["missing"].tolist() == truth["electrode"].isna().groupby(
        truth["material"]).sum().loc[ours.index].tolist()


def test_the_group_column_is_named_or_found(tmp_path):
    path = tmp_path / "d.csv"
    pd.DataFrame({"E": [0.1, 0.2, 0.3], "kind": ["a", "b", "a"], "M": [1, 2, 1]}).to_csv(
        path, index=False)
    assert summarise(path).by == "M"  # by its name, before the first column of text
    assert summarise(path).counts == {"1": 2, "2": 1}  # numbers named as written, not 1.0
    assert summarise(path, by="kind").counts == {"a": 2, "b": 1}
    pd.DataFrame({"E": [0.1, 0.2], "kind": ["a", "b"]}).to_csv(path, index=False)
    assert summarise(path).by == "kind"
    pd.DataFrame({"E": [0.1, 0.2], "C": [1, 2]}).to_csv(path, index=False)
    with pytest.raises(DataError, match="d.csv: no column to group the rows by"):
        summarise(path)
    with pytest.raises(DataError, match="no column 'kynd' to group by"):
        summarise(tmp_path / "d.csv", by="kynd")


def _grid(fig) -> list:
    """The panels of a scatter matrix, row by row (the counts' scales are child axes)."""
    return sorted(fig.axes, key=lambda ax: ax.get_subplotspec().get_geometry()[2])


@pytest.mark.parametrize("columns", [["pdc"], ["pdc", "electrode"],
                                     ["pdc", "pac_rms", "tdc", "electrode"]])
def test_the_figure_is_readings_by_readings_one_colour_per_material(recordings, columns):
    fig = scatter_matrix(recordings, columns=columns)
    n = len(columns)
    panels = _grid(fig)
    assert len(panels) == n * n
    assert {ax.get_subplotspec().get_geometry()[:2] for ax in panels} == {(n, n)}
    grid = np.array(panels, dtype=object).reshape(n, n)
    assert [ax.get_xlabel() for ax in grid[-1]] == columns
    if n > 1:
        assert [ax.get_ylabel() for ax in grid[:, 0]] == columns
        assert all(not ax.get_xlabel() for ax in grid[:-1].ravel())
    legend = fig.legends[0]
    assert legend.get_title().get_text() == "material"
    labels = [t.get_text() for t in legend.get_texts()]
    assert labels == [f"{m} ({k})" for m, k in zip(MATERIALS, [30, 45, 60, 25], strict=True)]
    legend_colours = [tuple(h.get_color()) for h in legend.legend_handles]
    assert len(set(legend_colours)) == len(MATERIALS)
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            lines = grid[i, j].get_lines()
            # one set of points per material, in the legend's colour and order
            assert [line.get_label() for line in lines] == MATERIALS
            assert [tuple(line.get_color()) for line in lines] == legend_colours
    # the panels of pdc against pac_rms hold the rows where both are present
    if n == 4:
        truth = pd.read_csv(recordings)
        both = truth.dropna(subset=["pdc", "pac_rms"])
        drawn = grid[1, 0].get_lines()
        assert [len(line.get_xdata()) for line in drawn] == \
            both["material"].value_counts().loc[MATERIALS].tolist()
        np.testing.assert_allclose(np.sort(drawn[0].get_xdata()),
                                   np.sort(both.loc[both.material == "cork", "pdc"]))
    title = fig._suptitle.get_text()
    assert "pdc 6" in title  # the empty cells counted in the title
    assert ("electrode 6" in title) == ("electrode" in columns)


def test_a_reading_of_states_is_bars_of_counts_per_material(recordings):
    fig = scatter_matrix(recordings, columns=["electrode"])
    (ax,) = _grid(fig)
    truth = pd.read_csv(recordings)
    states = sorted(STATES)
    assert [t.get_text() for t in ax.get_xticklabels()] == states
    heights = [p.get_height() for p in ax.patches]
    expected = pd.crosstab(truth["material"], truth["electrode"]).loc[MATERIALS, states]
    assert heights == expected.to_numpy().ravel().tolist()  # material by material


def test_show_summarises_a_data_file(capsys, recordings, tmp_path):
    out = tmp_path / "pairs.png"
    code = main(["show", str(recordings), "--columns", "pdc,electrode", "--plot", str(out)])
    text, err = capsys.readouterr()
    assert code == 0, err
    assert "Traceback" not in text + err
    # (the first line wrapped at 96 characters)
    assert "160 rows; material (4 values): cork 30, felt 45, steel 60, wood 25" in " ".join(
        text.split())
    assert "pdc (real):" in text and "electrode (discrete, 3 states):" in text
    assert "pac_rms" not in text
    row = next(line.split() for line in text.splitlines()
               if line.split()[:1] == ["steel"] and len(line.split()) == 7)
    truth = pd.read_csv(recordings)
    pdc = truth.loc[truth.material == "steel", "pdc"]
    assert [int(row[1]), int(row[2])] == [pdc.count(), pdc.isna().sum()]
    assert float(row[3]) == pytest.approx(pdc.mean(), rel=1e-3)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_show_of_a_bundled_data_file_by_its_name(capsys):
    assert main(["show", "lab_recordings"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert f"{LAB}: 900 rows; material (3 values): cork 300, felt 300, steel 300" in text


@pytest.mark.parametrize("make, args, expected", [
    (None, [], "cannot read data {path}: no such file"),
    ("a,b\n1,2\n3,4\n", [], "{path}: no column to group the rows by"),
    ("material,a\nx,1\n", ["--by", "mat"], "{path}: no column 'mat' to group by"),
    ("material,a\n,1\n,2\n", [], "{path}: no row has a value in the column 'material'"),
    ("material,a\n", ["--plot", "x.png"], "the file has a header only"),
    ("material,a\nx,1\n", ["--columns", "b"], "{path}: no column 'b'"),
    ("material,a\nx,1\n", ["--ablate", "P(a)"], "--ablate: for a program; {path} is a data"),
])
def test_show_of_a_bad_data_file_is_one_line(capsys, tmp_path, make, args, expected):
    path = tmp_path / "presses.csv"
    if make is not None:
        path.write_text(make)
    assert main(["show", str(path), *args]) == 2
    out, err = capsys.readouterr()
    assert out == "" and "Traceback" not in err
    assert err.count("\n") == 1 and err.startswith("bayesprog: "), err
    assert expected.format(path=path) in err


def test_the_data_options_are_refused_for_a_program(capsys):
    assert main(["show", str(ROOT / "models" / "pi_per.yaml"), "--plot", "x.png"]) == 2
    err = capsys.readouterr().err
    assert "--plot: for a data file" in err and "Traceback" not in err
