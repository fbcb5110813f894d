"""``bayesprog report LOG.csv``: a session's log replayed through a fresh explorer and drawn
(runner/report/session.py), for logs written by ``explore --stdio`` in process."""

from __future__ import annotations

import io
import json
import math
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayesprog.cli import main
from runner.attention.explorer import Explorer
from runner.experiments.log import SessionLog
from runner.experiments.loop import make_sensor
from runner.experiments.metrics import gamma_brute_force
from runner.report import session_figures
from runner.report.session import build_session_report, load_session, replay, summary
from runner.robot.session import probe_line
from runner.robot.stdio import serve
from runner.world.scenario import load_scenario

ROOT = Path(__file__).parents[2]
PAPER = ROOT / "models" / "scenarios" / "paper.yaml"
FINGERTIP = ROOT / "models" / "scenarios" / "fingertip.yaml"


class Replies(io.StringIO):
    """The standard output of ``serve``: keeps the last reply, which the driver follows."""

    def __init__(self) -> None:
        super().__init__()
        self.last: dict = {}

    def write(self, text: str) -> int:
        self.last = json.loads(text)
        return len(text)


def drive(scenario_path: Path, log_path: Path, probes: int, seed: int,
          resets: tuple[dict, ...] = (), first: int = 0, missed: int | None = None) -> Path:
    """A session of ``explore --stdio`` in process, its replies followed with readings of the
    scenario's simulated sensor, written to ``log_path``: ``first`` probes, then each of
    ``resets`` and ``probes`` more; every seventh probe misses a reading, and probe ``missed``
    is made one cell beside the one asked for."""
    scenario = load_scenario(scenario_path)
    explorer = Explorer(scenario, next(iter(scenario.spec.tasks)))
    sensor = make_sensor(scenario, [seed])
    replies = Replies()

    def lines() -> Iterator[str]:
        cell = [n // 3 for n in scenario.shape]
        for k in range(first + probes):
            if k == first:
                for reset in resets:
                    yield json.dumps({"reset": reset})
            flat = int(np.ravel_multi_index(tuple(cell), scenario.shape))
            line = probe_line(cell, sensor.probe(np.array([flat])),
                              perception=scenario.readings)
            if k % 7 == 3:
                line["readings"][scenario.readings.names[k % len(scenario.readings.names)]] = None
            yield json.dumps(line)
            assert "error" not in replies.last, replies.last
            cell = replies.last["next"]
            if k == missed:
                cell = [cell[0] + 1 if cell[0] + 1 < scenario.shape[0] else cell[0] - 1,
                        *cell[1:]]

    log = SessionLog(log_path)
    try:
        assert serve(explorer, lines(), replies, seed=seed, log=log) == first + probes
    finally:
        log.close()
    return log_path


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    """A paper session reset after three probes (to run 2 of seed 5), whose probe 21 (step
    18 of the second exploration) missed its target; a fingertip session as Parquet."""
    pytest.importorskip("pyarrow")
    folder = tmp_path_factory.mktemp("logs")
    return {"paper": drive(PAPER, folder / "paper.csv", 40, seed=4, first=3, missed=20,
                           resets=({"seed": 5, "run": 2},)),
            "fingertip": drive(FINGERTIP, folder / "fingertip.parquet", 30, seed=1)}


def _copy(log: Path, folder: Path) -> Path:
    """The log and its description copied into ``folder`` (a test edits its own)."""
    for path in (log, log.with_suffix(".json")):
        shutil.copy(path, folder / path.name)
    return folder / log.name


@pytest.mark.parametrize("name", ["paper", "fingertip"])
def test_the_replay_decides_the_logs_next_cells(logs, name):
    session = load_session(logs[name])
    frame = (pd.read_csv(logs[name]) if name == "paper" else pd.read_parquet(logs[name]))
    if name == "paper":  # a reset after three probes: the second exploration is drawn
        assert session.explorations == 2 and session.meta["run"] == 2
        frame = frame.iloc[3:]
    assert [p.step for p in session.probes] == list(range(len(frame)))
    replayed = replay(session)
    logged = [tuple(int(v) for v in row) for row in frame[["next_ix", "next_iy"]].to_numpy()]
    assert replayed.next_cells == logged
    numbers = summary(session, replayed)
    assert numbers["replay"] == {"compared": len(frame), "equal": len(frame),
                                 "first_difference": None}
    # the decided material of every probed cell is the log's, at that cell's last probe
    explorer = replayed.explorer
    last = frame.drop_duplicates(["ix", "iy"], keep="last")
    flat = np.ravel_multi_index((last["ix"].to_numpy(), last["iy"].to_numpy()),
                                session.scenario.shape)
    decided = [session.scenario.materials[m] for m in explorer.posterior[0, flat].argmax(axis=1)]
    assert decided == last["decided"].tolist()


def test_a_missed_target_is_replayed_where_the_probe_was_made_and_said(logs):
    session = load_session(logs["paper"])
    numbers = summary(session, replay(session))
    assert numbers["missed_targets"] == [18]  # the probe after step 17 landed one cell over
    assert "missed targets" in (report := (build_session_report(logs["paper"])
                                           / "report.md").read_text())
    assert "decides the log's next cell at every one of the 40 steps" in report


def test_a_replay_that_decides_otherwise_is_reported_not_refused(logs, tmp_path, capsys):
    log = _copy(logs["paper"], tmp_path)
    meta = json.loads(log.with_suffix(".json").read_text())
    meta["ablate"] = ["P(S | O, T)"]  # not the explorer the session had
    log.with_suffix(".json").write_text(json.dumps(meta))
    assert main(["report", str(log)]) == 0
    numbers = json.loads((tmp_path / "paper_report" / "summary.json").read_text())
    assert numbers["replay"]["equal"] < numbers["replay"]["compared"] == 40
    first = numbers["replay"]["first_difference"]
    assert first["log"] != first["replay"]
    assert "**The replay differs from the session**" in (tmp_path / "paper_report"
                                                        / "report.md").read_text()


def test_the_report_writes_its_figures_and_the_path_has_a_marker_per_probe(logs):
    folder = build_session_report(logs["fingertip"])
    assert folder == logs["fingertip"].with_name("fingertip_report")
    for name in ("path.png", "maps.png", "report.md", "report.html", "summary.json"):
        assert (folder / name).stat().st_size > 1000, name
    session = load_session(logs["fingertip"])
    frame = pd.read_parquet(logs["fingertip"])
    fig = session_figures.path_figure(session)
    ax = fig.axes[0]
    probes, = [c for c in ax.collections if c.get_label() == "probes"]
    offsets = probes.get_offsets()
    assert len(offsets) == len(frame) == 30
    cell = session.scenario.cell * 100
    np.testing.assert_allclose(offsets, (frame[["ix", "iy"]].to_numpy() + 0.5) * cell)
    lines = {line.get_label(): line for line in ax.lines}
    empty = frame[list(session.scenario.readings.names)].isna().any(axis=1)
    assert empty.sum() > 0
    missing = lines[f"a reading missing ({empty.sum()})"]
    np.testing.assert_allclose(missing.get_xdata(), (frame.loc[empty, "ix"] + 0.5) * cell)
    start, end = lines["start"], lines["last probe"]
    assert (start.get_xdata()[0], end.get_xdata()[0]) == (offsets[0, 0], offsets[-1, 0])
    # the maps: belief, decided, posterior over the next cell, and the three cues
    titles = [a.get_title() for a in session_figures.maps_figure(session, replay(session)).axes]
    assert sum(t.startswith(("belief", "material decided", "P(O", "inhibition", "saliency",
                             "uncertainty")) for t in titles) == 6


def test_the_confusion_counts_and_shares_are_the_logs(logs):
    session = load_session(logs["fingertip"])
    numbers = summary(session, replay(session))
    frame = pd.read_parquet(logs["fingertip"])
    table = pd.crosstab(frame["material"], frame["decided"])
    c = numbers["confusion"]
    got = pd.DataFrame(c["counts"], index=c["materials"], columns=c["decided"])
    pd.testing.assert_frame_equal(got.loc[table.index, table.columns], table,
                                  check_names=False)
    assert got.to_numpy().sum() == len(frame) == numbers["probes"]
    assert numbers["recognised"] == pytest.approx((frame["material"]
                                                   == frame["decided"]).mean())
    for reading, share in numbers["missing"].items():
        assert share == pytest.approx(frame[reading].isna().mean()), reading
    scenario = session.scenario
    path = session.flat().tolist()
    assert numbers["gamma_m"] == pytest.approx(gamma_brute_force(
        scenario.centres, scenario.border(session.task), path))
    steps = np.diff(frame[["x_m", "y_m"]].to_numpy(), axis=0)
    assert numbers["path_m"] == pytest.approx(np.linalg.norm(steps, axis=1).sum())
    assert numbers["median_ms"]["total"] == pytest.approx(frame["total_ms"].median())


def _no_meta(log: Path) -> str:
    log.with_suffix(".json").unlink()
    return f"no {log.stem}.json beside it"


def _scenario_gone(log: Path) -> str:
    meta = json.loads(log.with_suffix(".json").read_text())
    meta["scenario"] = str(log.parent / "moved.yaml")
    log.with_suffix(".json").write_text(json.dumps(meta))
    return "moved.yaml no longer exists"


def _bad_row(log: Path) -> str:
    lines = log.read_text().splitlines()
    fields = lines[5].split(",")
    fields[5] = "soft"  # a texture (of step 1 of the second exploration)
    lines[5] = ",".join(fields)
    log.write_text("\n".join(lines) + "\n")
    return f"{log.name}:6: column 'texture': expected a number, found 'soft'"


def _outside(log: Path) -> str:
    lines = log.read_text().splitlines()
    fields = lines[8].split(",")
    fields[1] = "31"  # ix, on a grid 30 cells wide
    lines[8] = ",".join(fields)
    log.write_text("\n".join(lines) + "\n")
    return f"{log.name}:9: cell [31,"


@pytest.mark.parametrize("edit", [_no_meta, _scenario_gone, _bad_row, _outside])
def test_a_log_that_cannot_be_drawn_is_one_line_and_status_2(logs, tmp_path, capsys, edit):
    log = _copy(logs["paper"], tmp_path)
    expected = edit(log)
    assert main(["report", str(log)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert expected in err and log.stem in err, err  # the log, or the file beside it
    assert not (tmp_path / "paper_report").exists()


def test_compare_takes_experiments_not_logs(logs, capsys):
    assert main(["report", str(logs["paper"]), "--compare", str(logs["paper"].parent)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a session's log" in err, err


def test_a_folder_is_still_an_experiments_output_folder(tmp_path, capsys):
    folder = tmp_path / "looks.csv"  # a folder, whatever its name
    folder.mkdir()
    assert main(["report", str(folder)]) == 2
    assert "no experiment.json: not an experiment's output folder" in capsys.readouterr().err


def test_a_volumes_log_is_drawn_seen_from_above(tmp_path):
    log = drive(ROOT / "models" / "scenarios" / "volume.yaml", tmp_path / "volume.csv", 12,
                seed=2)
    session = load_session(log)
    replayed = replay(session)
    assert summary(session, replayed)["replay"]["equal"] == 12
    fig = session_figures.path_figure(session)
    assert "seen from above" in fig.axes[0].get_title()
    maps = session_figures.maps_figure(session, replayed)
    assert all("slice z" in a.get_title() for a in maps.axes if a.get_title())
    assert not math.isnan(np.nanmax(replayed.explorer.belief()))
