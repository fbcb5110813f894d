"""Notebook display: the rich reprs parse as HTML/SVG and say what the answers say, a posterior's
display renders in a real headless browser, importing bayesprog draws nothing, and the tutorial
notebook runs with the numbers the tutorial gives."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

import bayesprog

ROOT = Path(__file__).parents[1]
SVG = "{http://www.w3.org/2000/svg}"

TAP = """\
bayesprog: 1
name: tap
variables:
  M: {states: [wood, metal, foam]}
  H: {continuous: [0, 1]}
  S: {states: [thud, ring, silent]}
decomposition:
  - {term: P(M), form: table, table: {wood: 0.5, metal: 0.3, foam: 0.2}}
  - {term: P(H | M), form: normal, mean: {wood: 0.6, metal: 0.9, foam: 0.2}, sigma: 0.1}
  - term: P(S | M)
    form: table
    table:
      wood: {thud: 0.7, ring: 0.2, silent: 0.1}
      metal: {thud: 0.1, ring: 0.85, silent: 0.05}
      foam: {thud: 0.2, ring: 0.0, silent: 0.8}
"""


def parse(markup: str) -> ET.Element:
    """Markup as XML (the reprs are well-formed XHTML with inline SVG)."""
    return ET.fromstring(f"<root>{markup}</root>")


def cells_of(root: ET.Element) -> list[list[str]]:
    return [[(td.text or "") for td in tr.findall("td")] for tr in root.iter("tr")
            if tr.findall("td")]


def svg_texts(root: ET.Element) -> list[str]:
    return ["".join(t.itertext()) for t in root.iter(f"{SVG}text")]


def test_a_posterior_displays_as_a_table_and_a_bar_chart_of_its_probabilities():
    answer = bayesprog.loads(TAP).ask("P(M | H, S)", {"H": 0.75, "S": "thud"})
    root = parse(answer._repr_html_())
    rows = cells_of(root)
    assert [r[0] for r in rows] == ["wood", "metal", "foam"]
    np.testing.assert_allclose([float(r[1]) for r in rows], answer.probabilities, rtol=1e-5)
    svg = root.find(f".//{SVG}svg")
    assert svg is not None
    labels = svg_texts(svg)
    assert {"wood", "metal", "foam", "probability"} <= set(labels)
    bars = [p for p in svg.iter(f"{SVG}g") if (p.get("id") or "").startswith("patch_")]
    assert len(bars) >= 3  # one patch per state (plus the axes' background)


def test_a_batched_posterior_and_a_map_answer_display_as_tables():
    program = bayesprog.loads(TAP)
    batch = program.ask("P(M | H, S)", {"H": [0.75, 0.2], "S": ["thud", "silent"]})
    rows = cells_of(parse(batch._repr_html_()))
    assert len(rows) == 2
    np.testing.assert_allclose([[float(x) for x in r[1:]] for r in rows], batch.probabilities,
                               rtol=1e-5)
    best = program.ask("P(M | H, S)", {"H": 0.75, "S": "thud"}, kind="map")
    rows = dict(r[:2] for r in cells_of(parse(best._repr_html_())))
    assert rows["M"] == "wood"
    assert float(rows["probability"]) == pytest.approx(float(best.probability), rel=1e-5)


def test_a_program_displays_its_decomposition_and_its_graph():
    program = bayesprog.loads(TAP).ablate("P(S | M)")
    root = parse(program._repr_html_())
    text = "".join(root.find(".//pre").itertext())
    assert "P(M H S) = P(M) P(H | M) P(S | M)" in text
    svg = root.find(f".//{SVG}svg")
    assert {"M", "H", "S"} <= set(svg_texts(svg))
    assert "ablated: P(S | M)" in " ".join(svg_texts(svg))


def test_show_inference_draws_each_posterior_at_its_node():
    program = bayesprog.loads(TAP)
    view = bayesprog.show_inference(program, {"S": "ring", "H": 0.8})
    np.testing.assert_allclose(view.marginals["M"].probabilities,
                               program.ask("P(M | S, H)", {"S": "ring", "H": 0.8}).probabilities)
    assert set(view.marginals) == {"M"}
    svg = ET.fromstring(view._repr_svg_())
    texts = svg_texts(svg)
    assert "S = ring" in texts and "H = 0.8" in texts
    assert f"{float(view.marginals['M'].probabilities[1]):.2f}" in texts  # metal's bar label
    ablated = bayesprog.show_inference(program, {"S": "ring"}, ablate=["P(S | M)"])
    np.testing.assert_allclose(ablated.marginals["M"].probabilities, [0.5, 0.3, 0.2])


def test_importing_bayesprog_draws_nothing():
    code = ("import sys, bayesprog; print(sorted(m for m in ('matplotlib', 'pandas', 'ruamel', "
            "'tqdm', 'bayesprog.learning') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_a_posterior_display_renders_in_a_headless_browser(tmp_path, screenshot):
    answer = bayesprog.loads(TAP).ask("P(M | H, S)", {"H": 0.75, "S": "thud"})
    page = tmp_path / "answer.html"
    page.write_text(f"<!DOCTYPE html><html><body>{answer._repr_html_()}</body></html>")
    pixels = screenshot(page, 800, 500)
    assert pixels.std() > 0.05  # not blank
    bar = np.array([0x48, 0x78, 0xA8]) / 255  # the bars' colour
    near = np.abs(pixels - bar).max(axis=-1) < 0.06
    assert near.sum() > 500  # the bar chart was drawn, not just the table's text


def test_the_tutorial_notebook_runs_with_the_tutorials_numbers():
    import nbclient
    import nbformat

    notebook = nbformat.read(ROOT / "docs" / "tutorial.ipynb", as_version=4)
    nbclient.NotebookClient(notebook, timeout=300, kernel_name="python3",
                            resources={"metadata": {"path": str(ROOT / "docs")}}).execute()
    outputs = [o for c in notebook.cells if c.cell_type == "code" for o in c.outputs]
    streams = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    assert "[0.921, 0.079, 0.0]" in streams  # the tutorial's answer
    assert "[0.625, 0.375, 0.0]" in streams  # and with the sound term ablated
    assert "Removing R has no strong influence." in streams
    html = [o["data"]["text/html"] for o in outputs if "text/html" in o.get("data", {})]
    assert any("Experiment quick" in h and "data:image/png;base64" in h for h in html)
    assert any("data:video/mp4;base64" in h and "run 0, 20 steps" in h for h in html)  # step view
    svgs = [o["data"]["image/svg+xml"] for o in outputs if "image/svg+xml" in o.get("data", {})]
    assert len(svgs) == 2
    assert not [o for o in outputs if o.output_type == "error"]


def test_show_inference_takes_arrays_and_a_single_term_to_ablate():
    program = bayesprog.load(ROOT / "models" / "pi_per.yaml")
    view = bayesprog.show_inference(program, {"E": [0.45, 0.15], "C": [0.08, 0.35]})
    assert "E: array of shape (2,)" in svg_texts(ET.fromstring(view._repr_svg_()))
    assert view.marginals["M"].probabilities.shape == (2, 10)
    ablated = bayesprog.show_inference(program, {"E": 0.5}, ablate="P(C | M)")
    assert ablated.program.ablated == ("P(C | M)",)
