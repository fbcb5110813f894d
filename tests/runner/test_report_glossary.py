"""The report explains its words to a reader who has not read the paper: a glossary at the top
of report.md and report.html says what S, U, I, R, pi_tar and Gamma are, what the
configurations remove, and which way of Gamma is better."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from bayesprog.cli import main

MODELS = Path(__file__).parents[2] / "models"


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> tuple[str, str]:
    """The quick experiment (every configuration), shortened, run and reported."""
    folder = tmp_path_factory.mktemp("glossary")
    spec = yaml.safe_load((MODELS / "experiments" / "quick.yaml").read_text())
    spec.update(scenario=str(MODELS / "scenarios" / "paper.yaml"), runs=3, iterations=8,
                chunk=3)
    path = folder / "quick.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    out = folder / "out"
    assert main(["run", str(path), "--out", str(out), "--no-animation", "-q"]) == 0
    report = out / "report"
    return ((report / "report.md").read_text(encoding="utf-8"),
            (report / "report.html").read_text(encoding="utf-8"))


def test_the_glossary_comes_before_the_first_figure_and_defines_every_word(report):
    md, _ = report
    glossary = md.index("## What the words mean")
    assert glossary < md.index("## Gamma(k) (paper Fig. 10)") < md.index("(eq. 16) sums")
    text = md[glossary:md.index("## Gamma(k) (paper Fig. 10)")]
    for word in ("**S, haptic saliency** (eq. 12)", "**U, uncertainty** (eq. 11)",
                 "**I, inhibition of return** (eq. 10)", "**R, shape cues** (eq. 14-15)",
                 "**pi_tar**", "**Gamma** (Γ, eq. 16)", "**full**", "**without_S**"):
        assert word in text, word
    # every configuration the report compares is one the glossary explains
    for configuration in re.findall(r"^\| T2 \| (\w+) \|", md, re.M):
        cue = configuration.removeprefix("without_")
        assert configuration == "full" or f"**{cue}, " in text, configuration
    # which way is better, for Gamma and for the area under it
    gamma = text[text.index("**Gamma**"):]
    assert "nearest probed cell" in gamma and "**Lower is better**" in gamma
    assert "**area under Gamma(k)**" in gamma and "**lower is better** too" in gamma
    assert "A cue helps when removing it raises the area" in gamma
    # the equations cited are said to be the paper's
    assert "'eq. N' cites the equations of the paper" in text


def test_the_html_report_carries_the_glossary_at_its_top(report):
    _, page = report
    heading = page.index("<h2>What the words mean</h2>")
    assert heading < page.index("<h2>Gamma(k) (paper Fig. 10)</h2>")
    assert "<strong>Lower is better</strong>" in page
    assert "<strong>S, haptic saliency</strong>" in page
