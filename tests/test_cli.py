"""The ``bayesprog`` command line, driven through ``bayesprog.cli.main``.

Numbers are checked against probabilities computed here by enumeration of the sprinkler joint
(or with scipy for the continuous pi_per model), never against bayesprog's own output.
"""

from __future__ import annotations

import argparse
import itertools
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import bayesprog
from bayesprog.cli import main
from bayesprog.language.loader import MAX_VALUES

ROOT = Path(__file__).parents[1]
SPRINKLER = ROOT / "models" / "examples" / "sprinkler.yaml"
PI_PER = ROOT / "models" / "pi_per.yaml"
SPRINKLER_REL = "models/examples/sprinkler.yaml"
PI_PER_REL = "models/pi_per.yaml"


@pytest.fixture
def in_root(monkeypatch):
    """Run with the repository root as working directory (for the relative model paths)."""
    monkeypatch.chdir(ROOT)


def run(capsys, *args) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return code, out, err


def user_error(capsys, *args) -> str:
    """Run a command that must fail as a user error: exit 2, one `bayesprog: ...` line."""
    code, out, err = run(capsys, *args)
    assert code == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("bayesprog: "), err
    assert out == ""
    return lines[0]


# the sprinkler network, by enumeration ------------------------------------------------------------
RAIN = {"rain": 0.2, "dry": 0.8}
SPRINKLER_GIVEN_RAIN = {"rain": {"on": 0.01, "off": 0.99}, "dry": {"on": 0.4, "off": 0.6}}
WET_GIVEN = {("on", "rain"): 0.99, ("on", "dry"): 0.9, ("off", "rain"): 0.8, ("off", "dry"): 0.0}


def joint(ablate_sprinkler: bool = False) -> dict[tuple[str, str, str], float]:
    """P(Rain, Sprinkler, Grass); with ``ablate_sprinkler`` P(Sprinkler | Rain) is uniform."""
    out = {}
    for r, s, g in itertools.product(("rain", "dry"), ("on", "off"), ("wet", "dry")):
        p_s = 0.5 if ablate_sprinkler else SPRINKLER_GIVEN_RAIN[r][s]
        p_wet = WET_GIVEN[(s, r)]
        out[(r, s, g)] = RAIN[r] * p_s * (p_wet if g == "wet" else 1 - p_wet)
    return out


def p_rain_given_grass(grass: str, ablate_sprinkler: bool = False) -> list[float]:
    j = joint(ablate_sprinkler)
    num = [sum(p for (r, _s, g), p in j.items() if r == rain and g == grass)
           for rain in ("rain", "dry")]
    return [n / sum(num) for n in num]


def map_rain_sprinkler(grass: str) -> tuple[dict[str, str], float]:
    j = joint()
    table = {(r, s): p for (r, s, g), p in j.items() if g == grass}
    total = sum(table.values())
    (r, s), p = max(table.items(), key=lambda kv: kv[1])
    return {"Rain": r, "Sprinkler": s}, p / total


def test_enumeration_matches_the_known_value():
    # P(Rain=rain | Grass=wet) = .16038 / .44838 = 0.357688...
    assert p_rain_given_grass("wet")[0] == pytest.approx(0.357688, abs=1e-6)


# validate -----------------------------------------------------------------------------------------
def test_validate_good_files(capsys, in_root):
    code, out, err = run(capsys, "validate", SPRINKLER_REL, PI_PER_REL)
    assert code == 0, err
    assert err == ""
    assert out.splitlines() == [f"{SPRINKLER_REL}: ok", f"{PI_PER_REL}: ok"]


def test_validate_quiet(capsys, in_root):
    code, out, err = run(capsys, "validate", "-q", SPRINKLER_REL)
    assert (code, out, err) == (0, "", "")


BAD = """\
bayesprog: 1
variables:
  Rain: {states: [rain, dry]}
  Grass: {states: [yes, no]}
decomposition:
  - {term: P(Rain), form: table, table: [0.2, 0.9]}
  - {term: P(Grass | Rian), form: table, table: [[0.9, 0.1], [0.2, 0.8]]}
questions:
  q: P(Rain | Grass=maybe)
"""

# (line, column, words) of every problem of BAD, computed from the text above
BAD_PROBLEMS = [
    (6, BAD.splitlines()[5].index("[0.2") + 1, ("summing to 1",)),
    (7, BAD.splitlines()[6].index("P(Grass") + 1, ("undeclared variable 'Rian'",)),
    (9, BAD.splitlines()[8].index("P(Rain") + 1, ("unknown state 'maybe'",)),
]

LINE = re.compile(r"^(?P<file>.+):(?P<line>\d+):(?P<col>\d+): (?P<msg>.+)$")


def parse_diagnostics(err: str) -> list[tuple[str, int, int, str]]:
    out = []
    for text in err.strip().splitlines():
        m = LINE.match(text)
        assert m, f"not a FILE:LINE:COL: message line: {text!r}"
        out.append((m["file"], int(m["line"]), int(m["col"]), m["msg"]))
    return out


def check_bad_output(err: str, file: str) -> None:
    found = [d for d in parse_diagnostics(err) if d[0] == file]
    assert len(found) == len(BAD_PROBLEMS), err
    for line, col, words in BAD_PROBLEMS:
        hits = [d for d in found if all(w in d[3] for w in words)]
        assert len(hits) == 1, (words, err)
        assert hits[0][1:3] == (line, col), hits[0]


def test_validate_bad_file(capsys, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(BAD, encoding="utf-8")
    code, out, err = run(capsys, "validate", bad)
    assert code == 2
    assert out == ""
    check_bad_output(err, str(bad))


def test_validate_several_files(capsys, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(BAD, encoding="utf-8")
    other = tmp_path / "other.yaml"
    other.write_text("bayesprog: 3\nvariables: {}\n", encoding="utf-8")
    code, out, err = run(capsys, "validate", bad, SPRINKLER, other, PI_PER)
    assert code == 2
    assert out.splitlines() == [f"{SPRINKLER}: ok", f"{PI_PER}: ok"]
    check_bad_output(err, str(bad))
    others = [d for d in parse_diagnostics(err) if d[0] == str(other)]
    assert others, err
    version = [d for d in others if "format version" in d[3]]
    assert len(version) == 1 and version[0][1:3] == (1, len("bayesprog: ") + 1)
    assert any("variables" in d[3] for d in others), err
    # every line is attributed to one of the two bad files
    assert {d[0] for d in parse_diagnostics(err)} == {str(bad), str(other)}


def test_validate_lists_problems_of_a_sub_program_with_its_own_file(capsys, tmp_path):
    (tmp_path / "sub.yaml").write_text("""\
bayesprog: 1
variables:
  R: {states: [r0, r1]}
  L: {continuous: [0, 1]}
decomposition:
  - {term: P(R), form: uniform}
  - {term: P(L | R), form: beta, a: 1, b: -2}
""", encoding="utf-8")
    main_text = """\
bayesprog: 1
variables:
  R: {states: [r0, r1]}
inputs:
  l: {}
decomposition:
  - {term: P(R), form: uniform}
soft_evidence:
  - variable: R
    form: program
    program: sub.yaml
    question: P(R | L)
    bind: {L: {input: l}}
"""
    (tmp_path / "main.yaml").write_text(main_text, encoding="utf-8")
    code, _, err = run(capsys, "validate", tmp_path / "main.yaml")
    assert code == 2
    diags = parse_diagnostics(err)
    sub = [d for d in diags if d[0] == str(tmp_path / "sub.yaml")]
    assert len(sub) == 1 and "'b'" in sub[0][3] and "> 0" in sub[0][3]
    assert sub[0][1:3] == (7, "  - {term: P(L | R), form: beta, a: 1, b: -2}".index("-2") + 1)
    outer = [d for d in diags if d[0] == str(tmp_path / "main.yaml")]
    assert len(outer) == 1 and "sub.yaml" in outer[0][3]
    assert outer[0][1] == main_text.splitlines().index("    program: sub.yaml") + 1


def test_validate_missing_file(capsys, tmp_path):
    line = user_error(capsys, "validate", tmp_path / "nope.yaml")
    assert "nope.yaml" in line and "no such file" in line


def test_validate_directory_and_binary(capsys, tmp_path):
    assert "directory" in user_error(capsys, "validate", tmp_path)
    binary = tmp_path / "bin.yaml"
    binary.write_bytes(b"\xff\xfe\x00\x01bad")
    assert "UTF-8" in user_error(capsys, "validate", binary)


def test_validate_subprocess(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(BAD, encoding="utf-8")
    proc = subprocess.run(
        [sys.executable, "-m", "bayesprog.cli", "validate", str(bad)],
        capture_output=True, text=True, cwd=ROOT, timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    check_bad_output(proc.stderr, str(bad))


def test_console_script_subprocess(tmp_path):
    script = Path(sys.executable).with_name("bayesprog")
    if not script.exists():
        pytest.skip("no bayesprog console script next to the interpreter")
    proc = subprocess.run([str(script), "query", str(tmp_path / "missing.yaml"), "P(A)"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.startswith("bayesprog: ") and "no such file" in proc.stderr


# show and graph -----------------------------------------------------------------------------------
def test_show(capsys, in_root):
    code, out, err = run(capsys, "show", SPRINKLER_REL)
    assert code == 0, err
    lines = [line.strip() for line in out.splitlines()]
    # the variables with their states
    for name, states in [("Rain", "{rain, dry}"), ("Sprinkler", "{on, off}"),
                         ("Grass", "{wet, dry}")]:
        assert any(re.match(rf"{name}\s*: {re.escape(states)}", line) for line in lines), out
    assert ("P(Rain Sprinkler Grass) = P(Rain) P(Sprinkler | Rain) P(Grass | Sprinkler, Rain)"
            in lines)
    assert any(line.startswith("why_wet: P(Rain | Grass=wet)") for line in lines), out
    assert any(line.startswith("explain: P(Rain Sprinkler | Grass)") and "map" in line
               for line in lines), out
    # the order: variables, decomposition, questions
    assert out.index("Rain ") < out.index("P(Rain Sprinkler Grass)") < out.index("why_wet")


def test_show_ablated(capsys):
    code, out, _ = run(capsys, "show", SPRINKLER, "--ablate", "P(Sprinkler | Rain)")
    assert code == 0
    assert re.search(r"P\(Sprinkler \| Rain\) = Uniform", out), out
    assert "Ablated: P(Sprinkler | Rain)" in out


def test_graph_dot(capsys, tmp_path):
    out_file = tmp_path / "out.dot"
    code, out, err = run(capsys, "graph", SPRINKLER, "-o", out_file)
    assert code == 0, err
    dot = out_file.read_text(encoding="utf-8")
    assert dot.startswith("digraph")
    edges = set(re.findall(r'"(\w+)"\s*->\s*"(\w+)"', dot))
    assert edges == {("Rain", "Sprinkler"), ("Rain", "Grass"), ("Sprinkler", "Grass")}
    for name in ("Rain", "Sprinkler", "Grass"):
        assert re.search(rf'^\s*"{name}"\s*\[', dot, re.M), dot


def test_graph_dot_shades_known_variables(capsys, tmp_path):
    out_file = tmp_path / "q.dot"
    code, _, _ = run(capsys, "graph", SPRINKLER, "-o", out_file, "--question", "why_wet")
    assert code == 0
    dot = out_file.read_text(encoding="utf-8")
    grass = next(line for line in dot.splitlines() if line.strip().startswith('"Grass" ['))
    sprinkler = next(line for line in dot.splitlines() if line.strip().startswith('"Sprinkler" ['))
    assert "filled" in grass and "filled" not in sprinkler


@pytest.mark.parametrize("suffix, magic", [(".png", b"\x89PNG\r\n\x1a\n"), (".pdf", b"%PDF"),
                                           (".svg", b"<?xml")])
def test_graph_image(capsys, tmp_path, suffix, magic):
    out_file = tmp_path / f"out{suffix}"
    code, out, err = run(capsys, "graph", SPRINKLER, "-o", out_file)
    assert code == 0, err
    data = out_file.read_bytes()
    assert len(data) > 100
    assert data.startswith(magic)


def test_graph_bad_suffix(capsys, tmp_path):
    line = user_error(capsys, "graph", SPRINKLER, "-o", tmp_path / "out.txt")
    assert ".dot" in line and ".png" in line
    assert not (tmp_path / "out.txt").exists()


# query ------------------------------------------------------------------------------------------
def test_query_table(capsys):
    code, out, err = run(capsys, "query", SPRINKLER, "P(Rain | Grass=wet)")
    assert code == 0, err
    expected = p_rain_given_grass("wet")
    lines = out.splitlines()
    assert lines[0] == "P(Rain | Grass=wet)"
    assert re.match(r"^\s*Rain\s+probability\s*$", lines[1])
    for state, p in zip(("rain", "dry"), expected, strict=True):
        row = next(line for line in lines[2:] if line.split()[0] == state)
        assert float(row.split()[1]) == pytest.approx(p, rel=1e-5)


def test_query_named_question_same_as_text(capsys):
    _, by_name, _ = run(capsys, "query", SPRINKLER, "why_wet", "--json")
    _, by_text, _ = run(capsys, "query", SPRINKLER, "P(Rain | Grass=wet)", "--json")
    assert json.loads(by_name)["probabilities"] == pytest.approx(
        json.loads(by_text)["probabilities"])


REQUIRED_POSTERIOR = {"question", "variables", "states", "probabilities"}
REQUIRED_MAP = {"question", "map", "probability"}


def query_json(capsys, *args) -> dict:
    code, out, err = run(capsys, "query", *args, "--json")
    assert code == 0, err
    data = json.loads(out)
    assert isinstance(data, dict)
    return data


def test_query_json_posterior(capsys):
    data = query_json(capsys, SPRINKLER, "P(Rain | Grass=wet)")
    assert REQUIRED_POSTERIOR <= set(data)
    assert set(data) - REQUIRED_POSTERIOR <= {"ablated", "log_evidence", "method"}
    assert data["method"] in ("table", "contraction")  # exact: no error estimate
    assert data["question"] == "P(Rain | Grass=wet)"
    assert data["variables"] == ["Rain"]
    assert data["states"] == {"Rain": ["rain", "dry"]}
    assert data["probabilities"] == pytest.approx(p_rain_given_grass("wet"), abs=1e-12)
    wet = sum(p for (_r, _s, g), p in joint().items() if g == "wet")  # P(Grass = wet)
    assert data["log_evidence"] == pytest.approx(np.log(wet), abs=1e-12)


def test_query_json_two_variables(capsys):
    data = query_json(capsys, SPRINKLER, "P(Sprinkler Rain | Grass=wet)")
    assert data["variables"] == ["Sprinkler", "Rain"]
    assert data["states"] == {"Sprinkler": ["on", "off"], "Rain": ["rain", "dry"]}
    j = joint()
    total = sum(p for (_r, _s, g), p in j.items() if g == "wet")
    expected = [[j[(r, s, "wet")] / total for r in ("rain", "dry")] for s in ("on", "off")]
    probs = data["probabilities"]
    assert len(probs) == 2 and all(len(row) == 2 for row in probs)
    np.testing.assert_allclose(probs, expected, atol=1e-12)


def test_query_json_map(capsys):
    data = query_json(capsys, SPRINKLER, "P(Rain Sprinkler | Grass=wet)", "--map")
    assert REQUIRED_MAP <= set(data)
    assert set(data) - REQUIRED_MAP <= {"ablated", "ties", "zero_evidence", "log_evidence",
                                        "method"}
    assert data["ties"] == 1 and data["zero_evidence"] is False
    assignment, p = map_rain_sprinkler("wet")
    assert data["question"] == "P(Rain Sprinkler | Grass=wet)"
    assert data["map"] == assignment
    assert data["probability"] == pytest.approx(p, abs=1e-12)
    wet = sum(p for (_r, _s, g), p in joint().items() if g == "wet")
    assert data["log_evidence"] == pytest.approx(np.log(wet), abs=1e-12)


def test_a_map_answer_has_the_variables_type(tmp_path, capsys):
    path = tmp_path / "count.yaml"
    path.write_text("""\
bayesprog: 1
variables: {K: {range: [2, 5]}, A: {states: [u, v]}}
decomposition:
  - {term: P(K), form: table, table: [0.1, 0.2, 0.6, 0.1]}
  - {term: P(A | K), form: table, table: [[0.5, 0.5], [0.5, 0.5], [0.9, 0.1], [0.5, 0.5]]}
""")
    data = query_json(capsys, str(path), "P(K A)", "--map")
    assert data["map"] == {"K": 4, "A": "u"} and isinstance(data["map"]["K"], int)
    assert bayesprog.load(path).ask("P(K | A=u)", kind="map").assignment == {"K": 4}
    data = query_json(capsys, str(path), "P(K | A=u)")
    assert data["states"] == {"K": [2, 3, 4, 5]}


def test_query_named_map_question_with_evidence(capsys):
    data = query_json(capsys, SPRINKLER, "explain", "--evidence", "Grass=dry")
    assignment, p = map_rain_sprinkler("dry")
    assert data["map"] == assignment
    assert data["probability"] == pytest.approx(p, abs=1e-12)


def test_query_map_table(capsys):
    code, out, _ = run(capsys, "query", SPRINKLER, "P(Rain Sprinkler | Grass=wet)", "--map")
    assert code == 0
    assignment, p = map_rain_sprinkler("wet")
    assert f"Rain={assignment['Rain']}, Sprinkler={assignment['Sprinkler']}" in out
    found = float(re.search(r"p = ([0-9.eE+-]+)", out).group(1))
    assert found == pytest.approx(p, rel=1e-5)


def test_query_ablate(capsys):
    plain = query_json(capsys, SPRINKLER, "P(Rain | Grass=wet)")
    data = query_json(capsys, SPRINKLER, "P(Rain | Grass=wet)", "--ablate", "P(Sprinkler | Rain)")
    expected = p_rain_given_grass("wet", ablate_sprinkler=True)
    # 0.179 / 0.539 with a uniform sprinkler, against 0.16038 / 0.44838 without
    assert expected[0] == pytest.approx(0.2 * 0.5 * (0.99 + 0.8) / (0.2 * 0.5 * 1.79 + 0.8 * 0.5 * 0.9))
    assert data["probabilities"] == pytest.approx(expected, abs=1e-12)
    assert plain["probabilities"][0] != pytest.approx(expected[0], abs=1e-3)
    assert data.get("ablated", ["P(Sprinkler | Rain)"]) == ["P(Sprinkler | Rain)"]


def test_query_ablate_parents_in_any_order(capsys):
    data = query_json(capsys, SPRINKLER, "P(Rain | Grass=wet)", "--ablate",
                      "P(Grass | Rain, Sprinkler)")
    # with P(Grass | ...) uniform, Grass says nothing: the prior of Rain comes back
    assert data["probabilities"] == pytest.approx([0.2, 0.8], abs=1e-12)


def test_query_evidence_npy_states(capsys, tmp_path):
    grass = tmp_path / "grass.npy"
    np.save(grass, np.array(["wet", "dry", "wet"]))
    data = query_json(capsys, SPRINKLER, "P(Rain | Grass)", "--evidence", f"Grass={grass}")
    expected = [p_rain_given_grass(g) for g in ("wet", "dry", "wet")]
    np.testing.assert_allclose(data["probabilities"], expected, atol=1e-12)


def test_query_evidence_npy_indices(capsys, tmp_path):
    grass = tmp_path / "grass.npy"
    np.save(grass, np.array([[1], [0]]))  # batch shape (2, 1)
    data = query_json(capsys, SPRINKLER, "P(Rain | Grass)", "--evidence", f"Grass={grass}")
    expected = [[p_rain_given_grass("dry")], [p_rain_given_grass("wet")]]
    np.testing.assert_allclose(data["probabilities"], expected, atol=1e-12)


def _pi_per_posterior(e: float, c: float) -> np.ndarray:
    from scipy.stats import norm

    e_mean = [0.08, 0.85, 0.30, 0.38, 0.20, 0.90, 0.66, 0.12, 0.45, 0.52]
    c_mean = [0.05, 0.06, 0.04, 0.62, 0.95, 0.78, 0.62, 0.35, 0.88, 0.08]
    like = norm.pdf(e, e_mean, 0.08) * norm.pdf(c, c_mean, 0.08)
    return like / like.sum()


def test_query_continuous_evidence_npy(capsys, tmp_path, in_root):
    e = np.array([0.45, 0.15, 0.8])
    e_file = tmp_path / "e.npy"
    np.save(e_file, e)
    data = query_json(capsys, PI_PER_REL, "material", "--evidence", f"E={e_file}",
                      "--evidence", "C=0.1")
    assert data["variables"] == ["M"]
    assert data["states"]["M"][0] == "acrylic" and len(data["states"]["M"]) == 10
    expected = [_pi_per_posterior(x, 0.1) for x in e]
    np.testing.assert_allclose(data["probabilities"], expected, rtol=1e-8, atol=1e-15)


def test_query_limit(capsys):
    code, out, _ = run(capsys, "query", PI_PER, "P(M | E=0.4, C=0.1)", "--limit", "3")
    assert code == 0
    probs = _pi_per_posterior(0.4, 0.1)
    states = ["acrylic", "brick", "copper", "damp_sponge", "feather", "rough_foam", "plush",
              "silicone", "soft_foam", "wood"]
    top3 = [states[i] for i in np.argsort(-probs)[:3]]
    rows = [line.split()[0] for line in out.splitlines()[2:5]]
    assert rows == top3
    assert "7 more" in out


def test_query_soft_evidence(capsys):
    data = query_json(capsys, SPRINKLER, "P(Rain | Grass=wet)", "--soft", "Rain=0.5,1")
    prior = np.array(p_rain_given_grass("wet")) * [0.5, 1.0]
    assert data["probabilities"] == pytest.approx(list(prior / prior.sum()), abs=1e-12)


INPUT_PROGRAM = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  B: {states: [b0, b1]}
inputs:
  prior: {shape: [2], description: P(A) given at question time}
decomposition:
  - {term: P(A), form: categorical, probabilities: {input: prior}}
  - {term: P(B | A), form: table, table: [[0.9, 0.1], [0.2, 0.8]]}
"""


@pytest.fixture
def input_program(tmp_path) -> Path:
    path = tmp_path / "inputs.yaml"
    path.write_text(INPUT_PROGRAM, encoding="utf-8")
    return path


def _p_a_given_b0(prior) -> list[float]:
    num = [prior[0] * 0.9, prior[1] * 0.2]
    return [n / sum(num) for n in num]


def test_query_input_npy(capsys, tmp_path, input_program):
    prior = tmp_path / "prior.npy"
    np.save(prior, np.array([0.3, 0.7]))
    data = query_json(capsys, input_program, "P(A | B=b0)", "--input", f"prior={prior}")
    assert data["probabilities"] == pytest.approx(_p_a_given_b0([0.3, 0.7]), abs=1e-12)
    # a batch of priors
    priors = np.array([[0.3, 0.7], [0.5, 0.5], [0.9, 0.1]])
    np.save(prior, priors)
    data = query_json(capsys, input_program, "P(A | B=b0)", "--input", f"prior={prior}")
    np.testing.assert_allclose(data["probabilities"], [_p_a_given_b0(p) for p in priors],
                               atol=1e-12)


SCALED = """\
bayesprog: 1
variables:
  A: {states: [a0, a1]}
  X: {continuous: [-.inf, .inf]}
inputs:
  prior: {shape: [2]}
  spread: {shape: [], description: the sensor's noise given at question time}
decomposition:
  - {term: P(A), form: categorical, probabilities: {input: prior}}
  - {term: P(X | A), form: normal, mean: {a0: 0.0, a1: 1.0}, sigma: {input: spread}}
"""


def test_query_input_numbers_on_the_command_line(capsys, tmp_path):
    path = tmp_path / "scaled.yaml"
    path.write_text(SCALED, encoding="utf-8")
    data = query_json(capsys, path, "P(A | X=0.4)", "--input", "spread=0.5", "--input",
                      "prior=0.3,0.7")
    from scipy import stats

    joint = np.array([0.3, 0.7]) * stats.norm([0.0, 1.0], 0.5).pdf(0.4)
    assert data["probabilities"] == pytest.approx(list(joint / joint.sum()), abs=1e-12)
    # the same as .npy files
    np.save(tmp_path / "spread.npy", np.array(0.5))
    np.save(tmp_path / "prior.npy", np.array([0.3, 0.7]))
    again = query_json(capsys, path, "P(A | X=0.4)", "--input",
                       f"spread={tmp_path / 'spread.npy'}", "--input",
                       f"prior={tmp_path / 'prior.npy'}")
    assert again["probabilities"] == data["probabilities"]
    assert main(["sample", str(path), "-n", "5", "-o", str(tmp_path / "draws.csv"),
                 "--input", "spread=0.5", "--input", "prior=0.3,0.7"]) == 0


@pytest.mark.parametrize(("value", "expected"), [
    ("spread=0.5x", "--input spread=0.5x: expected a number, numbers separated by commas (a "
                    "vector) or FILE.npy (an array), found '0.5x'"),
    ("spread=1,,2", "found ''"),
    ("spread=-1", "input 'spread' for normal parameter 'sigma' of P(X | A): expected values > 0"),
    ("prior=0.2,0.3,0.5", "input 'prior': expected trailing shape [2]"),
    ("sprad=0.5", "unknown input 'sprad': did you mean 'spread'?"),
])
def test_query_input_bad_numbers(capsys, tmp_path, value, expected):
    path = tmp_path / "scaled.yaml"
    path.write_text(SCALED, encoding="utf-8")
    given = {"spread": "spread=0.5", "prior": "prior=0.3,0.7"}
    given[value.split("=")[0] if value.split("=")[0] in given else "extra"] = value
    line = user_error(capsys, "query", path, "P(A | X=0.4)",
                      *[arg for v in given.values() for arg in ("--input", v)])
    assert expected in line


def test_query_input_bad_shape(capsys, tmp_path, input_program):
    prior = tmp_path / "prior.npy"
    np.save(prior, np.array([0.2, 0.3, 0.5]))
    line = user_error(capsys, "query", input_program, "P(A | B=b0)", "--input", f"prior={prior}")
    assert "prior" in line and "[2]" in line and "[3]" in line


def test_query_input_missing(capsys, input_program):
    line = user_error(capsys, "query", input_program, "P(A | B=b0)")
    assert "missing input 'prior'" in line


def test_query_input_unknown(capsys, tmp_path, input_program):
    prior = tmp_path / "prior.npy"
    np.save(prior, np.array([0.3, 0.7]))
    line = user_error(capsys, "query", input_program, "P(A | B=b0)", "--input", f"prior={prior}",
                      "--input", f"priro={prior}")
    assert "unknown input 'priro'" in line and "prior" in line


# user errors -----------------------------------------------------------------------------------
ZERO_PROGRAM = """\
bayesprog: 1
variables:
  A: {states: [a0, a1, a2]}
  C: {states: [c0, c1]}
decomposition:
  - {term: P(A), form: table, table: [0.5, 0.5, 0.0]}
  - {term: P(C | A), form: table, table: [[1, 0], [1, 0], [0, 1]]}
"""


@pytest.mark.parametrize(
    "args, words",
    [
        (["P(Rain | Zed=1)"], ("undeclared variable 'Zed'", "Rain, Sprinkler, Grass")),
        (["P(Zed | Grass=wet)"], ("undeclared variable 'Zed'",)),
        (["P(Rain | Grass=soggy)"], ("unknown state 'soggy'", "wet, dry")),
        (["P(Rain | Grass)", "--evidence", "Grass=soggy"], ("unknown state 'soggy'",)),
        (["P(Rain | Grass)"], ("missing evidence for Grass",)),
        (["P(Rain | Grass)", "--evidence", "Grass=wet", "--evidence", "Zed=1"],
         ("unknown variable 'Zed'",)),
        (["P(Rain | Grass)", "--evidence", "Grass"], ("--evidence", "NAME=VALUE")),
        (["P(Rain | Grass"], ("expected the form", "P(Rain | Grass")),
        (["P(Rain || Grass)"], ("'|'",)),
        (["Rain given Grass"], ("expected the form", "Rain given Grass", "why_wet")),
        (["P(Rain | Grass=wet)", "--ablate", "P(Foo)"], ("no term P(Foo)", "P(Sprinkler | Rain)")),
        (["P(Rain | Grass=wet)", "--soft", "Rain=1,x"], ("--soft", "numbers")),
        (["P(Rain | Grass=wet)", "--soft", "Rain=1,2,3"], ("soft evidence on Rain", "2")),
    ],
    ids=["unknown-known-variable", "unknown-searched-variable", "unknown-state-in-question",
         "unknown-state-in-evidence", "missing-evidence", "evidence-unknown-variable",
         "evidence-without-value", "unbalanced-parenthesis", "two-bars", "not-an-expression",
         "ablate-unknown-term", "soft-not-numbers", "soft-wrong-length"],
)
def test_query_user_errors(capsys, args, words):
    line = user_error(capsys, "query", SPRINKLER, *args)
    for w in words:
        assert w in line, line


def test_query_out_of_support(capsys, tmp_path):
    (tmp_path / "obj.yaml").write_text("""\
bayesprog: 1
variables:
  R: {states: [rectangle, triangle]}
  L1: {continuous: [0, 1]}
decomposition:
  - {term: P(R), form: uniform}
  - {term: P(L1 | R), form: beta, a: {rectangle: 1, triangle: 2}, b: 2}
""", encoding="utf-8")
    line = user_error(capsys, "query", tmp_path / "obj.yaml", "P(R | L1)", "--evidence", "L1=1.5")
    assert "L1=1.5" in line and "outside its support" in line and "[0, 1]" in line
    line = user_error(capsys, "query", tmp_path / "obj.yaml", "P(R | L1=-0.5)")
    assert "L1" in line and "outside its support" in line
    line = user_error(capsys, "query", tmp_path / "obj.yaml", "P(R | L1)", "--evidence", "L1=abc")
    assert "L1" in line and "'abc'" in line


def test_query_missing_files(capsys, tmp_path):
    line = user_error(capsys, "query", tmp_path / "nope.yaml", "P(A)")
    assert "nope.yaml" in line and "no such file" in line
    line = user_error(capsys, "query", SPRINKLER, "P(Rain | Grass)", "--evidence",
                      f"Grass={tmp_path / 'missing.npy'}")
    assert "missing.npy" in line and "no such file" in line
    line = user_error(capsys, "query", SPRINKLER, "P(Rain)", "--input",
                      f"x={tmp_path / 'missing.npy'}")
    assert "--input" in line and "missing.npy" in line


def test_query_unreadable_npy(capsys, tmp_path):
    obj = tmp_path / "obj.npy"
    np.save(obj, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    line = user_error(capsys, "query", SPRINKLER, "P(Rain | Grass)", "--evidence", f"Grass={obj}")
    assert "obj.npy" in line and ".npy" in line


def test_query_text_file_as_npy(capsys, tmp_path):
    text = tmp_path / "grass.npy"
    text.write_text("wet\n", encoding="utf-8")
    line = user_error(capsys, "query", SPRINKLER, "P(Rain | Grass)", "--evidence", f"Grass={text}")
    assert "grass.npy" in line
    assert "pickle" not in line, line


def test_query_empty_npy(capsys, tmp_path):
    empty = tmp_path / "empty.npy"
    empty.write_bytes(b"")
    line = user_error(capsys, "query", SPRINKLER, "P(Rain | Grass)", "--evidence",
                      f"Grass={empty}")
    assert "empty.npy" in line


def test_query_negative_seed(capsys):
    line = user_error(capsys, "query", SPRINKLER, "P(Rain | Grass=wet)", "--map", "--seed", "-1")
    assert "seed" in line


def test_query_malformed_question_hint_is_not_about_yaml(capsys):
    line = user_error(capsys, "query", SPRINKLER, "P(Rain | Grass")
    assert "flow mapping" not in line


def test_query_bad_program_prints_diagnostics(capsys, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(BAD, encoding="utf-8")
    code, out, err = run(capsys, "query", bad, "P(Rain)")
    assert code == 2 and out == ""
    check_bad_output(err, str(bad))


def test_query_zero_evidence(capsys, tmp_path):
    path = tmp_path / "zero.yaml"
    path.write_text(ZERO_PROGRAM, encoding="utf-8")
    line = user_error(capsys, "query", path, "P(A | C=c1)")
    assert "probability zero" in line
    # MAP on the same evidence: a seeded choice among the (all tied) states
    first = query_json(capsys, path, "P(A | C=c1)", "--map", "--seed", "5")
    again = query_json(capsys, path, "P(A | C=c1)", "--map", "--seed", "5")
    assert first["map"] == again["map"]
    assert first["map"]["A"] in ("a0", "a1", "a2")
    picks = {query_json(capsys, path, "P(A | C=c1)", "--map", "--seed", str(s))["map"]["A"]
             for s in range(12)}
    assert len(picks) > 1, picks


def test_argparse_errors_are_user_errors(capsys):
    code, out, err = run(capsys, "query", SPRINKLER)  # no question (nor --marginals)
    assert code == 2 and "expected a question" in err and "--marginals" in err
    code, out, err = run(capsys, "frobnicate")
    assert code == 2 and "usage" in err
    code, out, err = run(capsys, "query", SPRINKLER, "why_wet", "--seed", "x")
    assert code == 2 and "--seed" in err


def test_version(capsys):
    import bayesprog

    code, out, _ = run(capsys, "--version")
    assert code == 0 and out.strip() == f"bayesprog {bayesprog.__version__}"


def test_schema(capsys, tmp_path):
    code, out, _ = run(capsys, "schema")
    assert code == 0
    schema = json.loads(out)
    assert "bayesprog" in schema["properties"] and "decomposition" in schema["properties"]
    target = tmp_path / "schema.json"
    code, _, _ = run(capsys, "schema", "-o", target)
    assert code == 0 and json.loads(target.read_text(encoding="utf-8")) == schema


def test_validate_checks_every_kind_of_file_the_runner_knows(capsys):
    root = Path(__file__).parents[1]
    files = ["models/scenarios/paper.yaml", "models/experiments/quick.yaml",
             "models/sensors/biotac_proxy.yaml", "models/pi_tar.yaml"]
    assert main(["validate", *(str(root / f) for f in files)]) == 0
    out, err = capsys.readouterr()
    assert "paper.yaml: ok (scenario)" in out and "quick.yaml: ok (experiment)" in out
    assert "biotac_proxy.yaml: ok (sensor model)" in out and "pi_tar.yaml: ok\n" in out
    assert not err


def test_import_of_a_file_without_variables_writes_nothing(tmp_path, capsys):
    bad = tmp_path / "bad.bif"
    bad.write_text("garbage\n")
    assert main(["import", str(bad), "-o", str(tmp_path / "x.yaml")]) == 2
    assert "bad.bif" in capsys.readouterr().err
    assert not (tmp_path / "x.yaml").exists()


@pytest.mark.parametrize("command, output", [
    (["learn", str(SPRINKLER), "DATA"], "x.yaml"),
    (["discover", "DATA"], "x.yaml"),
    (["sample", str(SPRINKLER), "-n", "5"], "x.csv"),
    (["graph", str(SPRINKLER)], "x.dot"),
    (["export", str(SPRINKLER)], "x.bif"),
    (["schema"], "x.json"),
])
def test_an_output_in_a_missing_folder_is_refused_and_no_folder_is_made(capsys, tmp_path,
                                                                         command, output):
    data = tmp_path / "data.csv"
    bayesprog.load(SPRINKLER).sample(2000, rng=1).to_csv(data, index=False)
    command = [str(data) if a == "DATA" else a for a in command]
    missing = tmp_path / "nonexistent" / "dir"
    line = user_error(capsys, *command, "-o", missing / output)
    assert f"the folder {missing} does not exist" in line
    assert not (tmp_path / "nonexistent").exists()
    # a file where the folder should be
    line = user_error(capsys, *command, "-o", data / output)
    assert f"{data} is a file, not a folder" in line
    # from Python, a fitted file is not written into a folder that does not exist either
    with pytest.raises(FileNotFoundError, match="no such folder"):
        bayesprog.load(SPRINKLER).fit(data).save(missing / "fitted.yaml")
    assert not (tmp_path / "nonexistent").exists()


def test_every_subcommand_documents_its_arguments_and_defaults():
    from bayesprog.cli import build_parser

    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, sub in commands.choices.items():
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            what = f"{name} {action.option_strings or action.dest}"
            assert action.help, f"{what}: no help"
            has_default = action.default not in (None, False, [], argparse.SUPPRESS)
            if has_default and action.option_strings:
                assert "default" in action.help, f"{what}: its default is not said"


@pytest.mark.parametrize("command, kind", [
    (["query", "models/scenarios/paper.yaml", "P(M)"], "this is a scenario file, not a program"),
    (["show", "models/experiments/quick.yaml"], "this is an experiment file, not a program"),
    (["run", "models/pi_per.yaml", "--out", "OUT"], "this is a program file, not an experiment"),
    (["run", "models/scenarios/paper.yaml", "--out", "OUT"], "a scenario file, not an experiment"),
    (["explore", "models/pi_per.yaml", "--stdio"], "this is a program file, not a scenario"),
])
def test_a_file_of_the_wrong_kind_is_named(capsys, tmp_path, command, kind):
    root = Path(__file__).parents[1]
    argv = [str(root / a) if a.startswith("models/") else a for a in command]
    argv = [str(tmp_path / "out") if a == "OUT" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert kind in err and "Traceback" not in err


@pytest.mark.parametrize("text, message", [
    ("bayesprog: 1\nvariables:\n  A: {states: [a, b]\ndecomposition: []\n",
     "4:1: malformed YAML: expected ',' or '}' (the end of a {...} mapping), found a value "
     "(the {...} or [...] opened at line 3)"),
    ("bayesprog: 1\nvariables:\n\tA: {states: [a, b]}\n",
     "3:1: malformed YAML: expected spaces for indentation, found a tab"),
    ("bayesprog: 1\nvariables:\n  A: \"abc\n",
     "4:1: malformed YAML: expected the closing quote of a string, found the end of the file"),
    ("a: b: c\n", "1:5: malformed YAML: expected one 'key: value' per line, found a second ':'"),
    # a key indented less than the key above it is said to be so, with where it may go
    ("bayesprog: 1\ndecomposition:\n  - term: P(B | A)\n   form: table\n",
     "4:4: malformed YAML: expected the key 'form' lined up with the keys beside it, found it "
     "indented less than 'term' on line 3 (column 5): indent it to the column of the key it "
     "goes beside: 5 ('term', line 3) or 1 ('decomposition', line 2)"),
    # and one indented more, under a key that has its value: not a quoting matter
    ("bayesprog: 1\ndecomposition:\n  - term: P(B | A)\n      form: table\n",
     "4:11: malformed YAML: expected the key 'form' lined up with the keys beside it, found it "
     "indented more than 'term' on line 3 (column 5), which already has a value (read as that "
     "value going on over a second line): indent 'form' to column 5"),
    ("bayesprog: 1\nvariables:\n  A: {states: [a0, a1]}\n   B: {states: [b0, b1]}\n",
     "4:4: malformed YAML: expected the key 'B' lined up with the keys beside it, found it "
     "indented more than 'A' on line 3 (column 3): only the keys of a mapping opened by 'A:' "
     "with nothing after the ':' go further in; indent it to column 3"),
])
def test_yaml_syntax_errors_say_what_was_expected_and_found(tmp_path, capsys, text, message):
    path = tmp_path / "broken.yaml"
    path.write_text(text)
    assert main(["validate", str(path)]) == 2
    assert f"broken.yaml:{message}" in capsys.readouterr().err


@pytest.mark.parametrize("text, message", [
    ("a: &x [*x]\n", "an alias that contains itself"),
    ("a: &a [1, 2, 3, 4, 5, 6, 7, 8, 9]\n" + "".join(
        f"{chr(98 + i)}: &{chr(98 + i)} [" + ", ".join([f"*{chr(97 + i)}"] * 9) + "]\n"
        for i in range(8)), f"more than {MAX_VALUES:,} values"),
    ("a: " + "[" * 5000 + "]" * 5000 + "\n", "malformed YAML"),
])
def test_yaml_that_would_never_end_is_refused(tmp_path, capsys, text, message):
    path = tmp_path / "bomb.yaml"
    path.write_text(text)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_a_second_yaml_document_and_a_limit_below_one_are_refused(tmp_path, capsys):
    path = tmp_path / "two.yaml"
    path.write_text("bayesprog: 1\n---\nbayesprog: 1\n")
    assert main(["validate", str(path)]) == 2
    assert "expected one document, found a second" in capsys.readouterr().err
    assert main(["query", str(SPRINKLER), "P(Rain)", "--limit", "0"]) == 2
    assert "--limit: expected at least 1 row, found 0" in capsys.readouterr().err


_FINALISER = """
import signal, sys, time
from bayesprog.cli import signals as cli
signal.signal(signal.SIGTERM, cli._terminate)
sys.unraisablehook = cli._deliver_again
class Stopped:
    def __del__(self):
        raise {raised}
try:
    Stopped()
    for _ in range({steps}):  # a stop comes back within milliseconds: waited for, up to 30 s
        time.sleep(0.05)
    print("went on")
except KeyboardInterrupt:
    print("interrupted")
except cli._Terminated:
    print("terminated")
"""


@pytest.mark.parametrize("raised, seen", [("KeyboardInterrupt", "interrupted"),
                                          ("cli._Terminated()", "terminated")])
def test_a_stop_that_lands_in_a_finaliser_is_not_lost(raised, seen):
    """Ctrl-C or SIGTERM raised inside a finaliser or weakref callback (where Python can only
    print "Exception ignored") still stops the command, where it is, without a traceback."""
    done = subprocess.run([sys.executable, "-c", _FINALISER.format(raised=raised, steps=600)],
                          capture_output=True, text=True, timeout=60)
    assert done.stdout.strip() == seen
    assert "Exception ignored" not in done.stderr and "Traceback" not in done.stderr


def test_other_errors_in_finalisers_are_still_reported():
    done = subprocess.run([sys.executable, "-c",
                           _FINALISER.format(raised="ValueError('x')", steps=20)],
                          capture_output=True, text=True, timeout=60)
    assert done.stdout.strip() == "went on"
    assert "Exception ignored" in done.stderr and "ValueError" in done.stderr


_SIGNAL_IN_FINALISER = """
import os, signal, sys, time, weakref
from bayesprog.cli import signals as cli
signal.signal(signal.SIGTERM, cli._terminate)
signal.signal(signal.SIGINT, cli._interrupt)
finished = []
class Thing:
    pass
def callback(_):
    os.kill(os.getpid(), signal.{name})  # the signal arrives while the callback runs
    for _ in range(200000):
        pass
    finished.append(True)  # the callback is not cut short
thing = Thing()
if {how!r} == "finalize":
    weakref.finalize(thing, callback, None)
else:
    def __del__(self):
        callback(None)
    Thing.__del__ = __del__
try:
    del thing
    for _ in range(600):  # the stop comes back within milliseconds: waited for, up to 30 s
        time.sleep(0.05)
    print("went on")
except KeyboardInterrupt:
    print("interrupted", finished)
except cli._Terminated:
    print("terminated", finished)
"""


@pytest.mark.parametrize("how", ["finalize", "__del__"])
@pytest.mark.parametrize("name, seen", [("SIGINT", "interrupted [True]"),
                                        ("SIGTERM", "terminated [True]")])
def test_a_signal_inside_a_finaliser_waits_for_it_to_finish(name, seen, how):
    """The handlers do not raise inside a finaliser (a ``weakref.finalize``, as multiprocessing's
    cleanups, or a ``__del__``): that would cut it short (a semaphore left registered, a leak
    reported at exit); the stop comes right after it."""
    done = subprocess.run([sys.executable, "-c", _SIGNAL_IN_FINALISER.format(name=name,
                                                                             how=how)],
                          capture_output=True, text=True, timeout=60)
    assert done.stdout.strip() == seen, done.stdout + done.stderr
    assert "Exception ignored" not in done.stderr and "Traceback" not in done.stderr
