"""The package as people install it: the bundled models and the names that find them, the
wheel and the sdist and what they carry, one version everywhere, the extras that a missing
library names, and a documentation site that covers every page."""

from __future__ import annotations

import importlib.metadata
import json
import re
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml

import bayesprog
from bayesprog.cli import main
from bayesprog.support import bundled

ROOT = Path(__file__).parents[1]
MODELS = ROOT / "models"


def run(capsys, *args) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


# the bundled models ------------------------------------------------------------------------

def test_every_shipped_model_is_listed_once_with_its_kind():
    shipped = {p.resolve() for p in MODELS.rglob("*")
               if p.is_file() and p.suffix in (".yaml", ".csv")}
    listed = [entry.path.resolve() for entry in bundled.listing()]
    assert sorted(listed) == sorted(shipped)
    kinds = {entry.name: entry.kind for entry in bundled.listing()}
    assert kinds["experiments/paper"] == "experiment"
    assert kinds["scenarios/paper"] == "scenario"
    assert kinds["examples/student"] == kinds["pi_per"] == "program"
    assert kinds["sensors/biotac_proxy"] == "sensor model"
    assert kinds["data/lab_recordings.csv"] == "data"


def test_a_name_finds_the_model_of_the_kind_a_command_expects():
    assert bundled.find("paper", "experiment") == MODELS / "experiments" / "paper.yaml"
    assert bundled.find("paper", "scenario") == MODELS / "scenarios" / "paper.yaml"
    assert bundled.find("paper") == MODELS / "experiments" / "paper.yaml"  # experiments first
    assert bundled.find("scenarios/paper.yaml") == MODELS / "scenarios" / "paper.yaml"
    assert bundled.find("student", "program") == MODELS / "examples" / "student.yaml"
    assert bundled.find("pi_per", "program") == MODELS / "pi_per.yaml"
    assert bundled.find("student", "experiment") is None
    assert bundled.find("no_such_model") is None
    # a name reads the heads of the files of that name alone: what it finds is the listing's
    # first file of that name, of the kind asked or else in the listing's order of kinds
    def names(e: bundled.Bundled) -> set[str]:
        bare = {e.name.rsplit(".", 1)[0], e.short.rsplit(".", 1)[0]} if e.kind == "data" else ()
        return {e.name, e.short, *bare}

    for entry in bundled.listing():
        for kind in (entry.kind, None):
            for name in {entry.name, entry.short, entry.name.rsplit(".", 1)[0]}:
                first = next(e.path for wanted in ([kind] if kind else bundled.ORDER)
                             for e in bundled.listing() if e.kind == wanted and name in names(e))
                assert bundled.find(name, kind) == first, (name, kind)


def test_a_file_of_that_name_wins_over_a_bundled_model(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "student").write_text("not a program\n")
    assert bundled.bundled_path("student", "program") == Path("student")
    assert bundled.bundled_path("rain", "program") == MODELS / "examples" / "rain.yaml"


def test_the_listing_names_each_model_by_a_name_that_finds_it(capsys):
    code, out, _ = run(capsys, "examples", "--json")
    assert code == 0
    entries = json.loads(out)
    assert {tuple(sorted(e)) for e in entries} == {("description", "kind", "name", "path")}
    for entry in entries:
        assert bundled.find(entry["name"]) == Path(entry["path"])
    names = [e["name"] for e in entries]
    assert len(names) == len(set(names))
    assert "paper" in names and "scenarios/paper" in names and "student" in names
    code, out, _ = run(capsys, "examples")
    assert code == 0 and "paper" in out and "Koller and Friedman" in out


def test_a_bundled_program_answers_by_its_name_as_by_its_path(capsys):
    code, by_name, _ = run(capsys, "query", "student", "P(I | G=A)", "--json")
    assert code == 0
    code, by_path, _ = run(capsys, "query", MODELS / "examples" / "student.yaml",
                           "P(I | G=A)", "--json")
    assert code == 0
    assert json.loads(by_name)["probabilities"] == json.loads(by_path)["probabilities"]


def test_an_unknown_name_is_a_user_error_that_points_to_the_listing(capsys):
    code, out, err = run(capsys, "query", "no_such_model", "P(A)")
    assert code == 2 and not out
    assert "no such file" in err and "bayesprog examples" in err and "Traceback" not in err
    code, _, err = run(capsys, "run", "no_such_experiment", "--out", "unused")
    assert code == 2 and "bayesprog examples" in err


def test_a_copied_experiment_carries_every_file_it_names_and_runs_from_there(tmp_path, capsys):
    code, out, _ = run(capsys, "examples", "copy", "paper", tmp_path / "mine")
    assert code == 0
    copied = sorted(p.relative_to(tmp_path / "mine").as_posix()
                    for p in (tmp_path / "mine").rglob("*") if p.is_file())
    assert copied == ["experiments/paper.yaml", "pi_obj.yaml", "pi_per.yaml", "pi_tar.yaml",
                      "scenarios/paper.yaml"]
    for name in copied:
        assert (tmp_path / "mine" / name).read_bytes() == (MODELS / name).read_bytes()
    code, out, err = run(capsys, "validate", tmp_path / "mine" / "experiments" / "paper.yaml",
                         tmp_path / "mine" / "scenarios" / "paper.yaml")
    assert code == 0, err
    # the lab example takes its recordings along
    code, _, _ = run(capsys, "examples", "copy", "lab_recorded", tmp_path / "lab")
    assert code == 0 and (tmp_path / "lab" / "data" / "lab_recordings.csv").is_file()


def test_a_copy_does_not_overwrite_unless_forced(tmp_path, capsys):
    assert run(capsys, "examples", "copy", "student", tmp_path)[0] == 0
    target = tmp_path / "student.yaml"
    target.write_text("# my edits\n")
    code, _, err = run(capsys, "examples", "copy", "student", tmp_path)
    assert code == 2 and "exists" in err and "--force" in err
    assert target.read_text() == "# my edits\n"
    assert run(capsys, "examples", "copy", "student", tmp_path, "--force")[0] == 0
    assert target.read_bytes() == (MODELS / "examples" / "student.yaml").read_bytes()
    code, _, err = run(capsys, "examples", "copy", "no_such_model", tmp_path)
    assert code == 2 and "no bundled model" in err


def test_a_copied_program_is_the_bundled_one(tmp_path):
    written = bundled.copy("umbrella", tmp_path)
    assert written == [tmp_path / "umbrella.yaml"]
    ours = bayesprog.load(written[0]).ask("P(Rain)")
    theirs = bayesprog.load(MODELS / "examples" / "umbrella.yaml").ask("P(Rain)")
    np.testing.assert_array_equal(ours.probabilities, theirs.probabilities)


def test_a_model_of_one_file_lands_as_that_file_and_the_next_command_finds_it(tmp_path, capsys):
    code, out, _ = run(capsys, "examples", "copy", "sprinkler", tmp_path / "my_sprinkler")
    assert code == 0 and str(tmp_path / "my_sprinkler" / "sprinkler.yaml") in out
    assert sorted(p.name for p in (tmp_path / "my_sprinkler").rglob("*")) == ["sprinkler.yaml"]
    code, out, err = run(capsys, "query", tmp_path / "my_sprinkler" / "sprinkler.yaml",
                         "why_wet")
    assert code == 0 and "P(Rain | Grass=wet)" in out, err
    # a data file is one file too
    code, _, _ = run(capsys, "examples", "copy", "probes", tmp_path / "data_here")
    assert code == 0 and (tmp_path / "data_here" / "probes.csv").is_file()


# one version ---------------------------------------------------------------------------------

def test_one_version_in_the_package_its_metadata_the_command_and_the_changelog(capsys):
    assert main(["--version"]) == 0
    printed = capsys.readouterr().out.split()[-1]
    changelog = (ROOT / "CHANGELOG.md").read_text()
    released = re.findall(r"^## \[(\d+\.\d+\.\d+)\] - \d{4}-\d{2}-\d{2}$", changelog, re.M)
    assert released and released[0] == bayesprog.__version__
    assert printed == importlib.metadata.version("bayesprog") == bayesprog.__version__
    assert "## [Unreleased]" in changelog and released[-1] == "0.1.0"


# the wheel and the sdist ---------------------------------------------------------------------

@pytest.fixture(scope="module")
def artefacts(tmp_path_factory):
    """The wheel and the sdist, built as a release is (without build isolation: offline)."""
    out = tmp_path_factory.mktemp("dist")
    subprocess.run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(out),
                    str(ROOT)], check=True, capture_output=True, timeout=300)
    wheel = next(out.glob("*.whl"))
    sdist = next(out.glob("*.tar.gz"))
    return wheel, sdist


def test_the_wheel_carries_the_models_and_its_name_says_the_version(artefacts):
    wheel, _ = artefacts
    assert wheel.name == f"bayesprog-{bayesprog.__version__}-py3-none-any.whl"
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = {f"bayesprog/models/{p.relative_to(MODELS).as_posix()}"
               for p in MODELS.rglob("*") if p.is_file()}
    assert shipped <= names, shipped - names
    assert {"bayesprog/py.typed", "runner/py.typed", "bayesprog/support/bundled.py",
            "runner/report/build/__init__.py"} <= names
    metadata = next(n for n in names if n.endswith(".dist-info/METADATA"))
    text = zipfile.ZipFile(wheel).read(metadata).decode()
    assert f"Version: {bayesprog.__version__}" in text
    extras = set(re.findall(r"^Provides-Extra: (\S+)$", text, re.M))
    assert {"ros", "parquet", "tune", "dask", "docs", "dev"} <= extras
    required = re.findall(r"^Requires-Dist: ([A-Za-z0-9_.-]+)[^;\n]*$", text, re.M)
    for base in ("pgmpy", "numpy", "scipy", "networkx", "pyyaml"):
        assert base in required
    assert "optuna" not in required and "pyarrow" not in required


def test_the_sdist_carries_what_builds_the_wheel_docs_and_tests(artefacts):
    _, sdist = artefacts
    top = sdist.name[: -len(".tar.gz")]
    names = set(tarfile.open(sdist).getnames())
    for name in ("pyproject.toml", "hatch_build.py", "README.md", "CHANGELOG.md", "LICENSE",
                 "mkdocs.yml", "models/experiments/paper.yaml", "docs/index.md",
                 "tests/test_packaging.py"):
        assert f"{top}/{name}" in names, name


def test_an_editable_install_compiles_the_checkouts_modules_and_a_wheel_carries_none(
        artefacts, tmp_path):
    """The build step of an editable install writes each module's bytecode beside it, as an
    installer compiles a regular install's; a regular wheel carries sources only."""
    import importlib.util

    sys.path.insert(0, str(ROOT))
    try:
        from hatch_build import EditableBytecode
    finally:
        sys.path.remove(str(ROOT))
    for package in ("bayesprog", "runner"):
        (tmp_path / package / "sub").mkdir(parents=True)
        (tmp_path / package / "sub" / "module.py").write_text("X = 1\n")

    def hook(target: str) -> EditableBytecode:
        return EditableBytecode(str(tmp_path), {}, None, None, str(tmp_path / "dist"), target)

    compiled = Path(importlib.util.cache_from_source(str(tmp_path / "bayesprog" / "sub" /
                                                         "module.py")))
    hook("wheel").initialize("standard", {})
    hook("sdist").initialize("editable", {})
    assert not compiled.exists()
    hook("wheel").initialize("editable", {})
    assert compiled.exists()
    assert Path(importlib.util.cache_from_source(
        str(tmp_path / "runner" / "sub" / "module.py"))).exists()
    wheel, _ = artefacts
    assert not [n for n in zipfile.ZipFile(wheel).namelist() if n.endswith(".pyc")]


def test_twine_finds_both_artefacts_fit_to_publish(artefacts):
    done = subprocess.run([sys.executable, "-m", "twine", "check", "--strict", *map(str,
                          artefacts)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.count("PASSED") == 2


# extras -----------------------------------------------------------------------------------

_WITHOUT = """
import sys
sys.modules[{module!r}] = None  # as if it were not installed
from bayesprog.cli import main
sys.exit(main({argv!r}))
"""


@pytest.mark.parametrize("module, extra, argv", [
    ("pyarrow", "parquet", ["sample", "rain", "-n", "5", "-o", "{tmp}/draws.parquet"]),
    ("pyarrow", "parquet", ["learn", "rain", "{tmp}/data.parquet", "-o", "{tmp}/out.yaml"]),
    ("optuna", "tune", ["tune", "tuned_profiles", "--out", "{tmp}/tune"]),
])
def test_a_feature_whose_extra_is_missing_names_the_extra(tmp_path, module, extra, argv):
    (tmp_path / "data.parquet").write_bytes(b"PAR1")
    argv = [a.format(tmp=tmp_path) for a in argv]
    done = subprocess.run([sys.executable, "-c", _WITHOUT.format(module=module, argv=argv)],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert f'pip install "bayesprog[{extra}]"' in done.stderr and module in done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "draws.parquet").exists() and not (tmp_path / "tune").exists()


# the documentation site ----------------------------------------------------------------------

def _nav_pages(nav: list) -> list[str]:
    pages = []
    for item in nav:
        value = next(iter(item.values())) if isinstance(item, dict) else item
        pages += _nav_pages(value) if isinstance(value, list) else [value]
    return pages


def test_the_site_has_every_page_and_an_api_page_for_the_public_names():
    config = yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=yaml.SafeLoader)
    pages = _nav_pages(config["nav"])
    docs = ROOT / "docs"
    written = {p.relative_to(docs).as_posix() for p in docs.rglob("*.md")} | {"tutorial.ipynb"}
    assert sorted(pages) == sorted(written)
    api = "\n".join((docs / p).read_text() for p in pages if p.startswith("api/"))
    for name in ("Program", "load", "loads", "Posterior", "MapResult", "Density", "SpecError",
                 "Diagnostic", "register_form", "bundled", "discover", "compare"):
        assert re.search(rf"^::: bayesprog\.[\w.]*\b{name}$", api, re.M), name


def test_python_dash_m_is_the_command_line():
    done = subprocess.run([sys.executable, "-m", "bayesprog", "--version"], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.strip() == f"bayesprog {bayesprog.__version__}"
    done = subprocess.run([sys.executable, "-m", "bayesprog", "query", "no_such_model", "P(A)"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "bayesprog examples" in done.stderr
