"""What ``import bayesprog`` and a command-line question load: the names of the package are
imported when first used, and a discrete question never loads the modules of the features it
does not use (scipy.special, networkx, matplotlib, pandas). Each check runs in a fresh
interpreter, where nothing has been imported yet. How long they take is measured in
benchmarks/startup.py, not here."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

HEAVY = ("numpy", "scipy", "networkx", "matplotlib", "pandas", "pydantic", "pgmpy", "yaml",
         "ruamel", "opt_einsum", "pyarrow")

STUDENT = (Path(__file__).parents[1] / "models" / "examples" / "student.yaml").read_text()


def loaded_after(code: str, cwd: Path | None = None) -> set[str]:
    """The modules loaded after running ``code`` in a fresh interpreter."""
    script = code + "\nimport sys, json\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, cwd=cwd).stdout
    return set(json.loads(out.splitlines()[-1]))


def top_level(modules: set[str]) -> set[str]:
    return {m.split(".")[0] for m in modules}


def test_import_bayesprog_loads_none_of_its_dependencies():
    loaded = top_level(loaded_after("import bayesprog"))
    assert not loaded & set(HEAVY), loaded & set(HEAVY)
    assert loaded_after("import bayesprog") >= {"bayesprog"}


def test_every_public_name_is_found_when_first_used():
    code = ("import bayesprog\n"
            "missing = [n for n in bayesprog.__all__ if getattr(bayesprog, n, None) is None]\n"
            "assert not missing, missing\n"
            "assert set(dir(bayesprog)) >= set(bayesprog.__all__)\n"
            "assert bayesprog.Program is __import__('bayesprog.program').program.Program")
    subprocess.run([sys.executable, "-c", code], check=True)
    with pytest.raises(subprocess.CalledProcessError):
        subprocess.run([sys.executable, "-c", "import bayesprog; bayesprog.nothing_of_that_name"],
                       check=True, capture_output=True)


def test_a_discrete_question_on_the_command_line_loads_no_plotting_graph_or_table_library(
        tmp_path):
    (tmp_path / "student.yaml").write_text(STUDENT)
    loaded = loaded_after(
        "from bayesprog.cli import main\n"
        "assert main(['query', 'student.yaml', 'P(I | G)', '--evidence', 'G=A']) == 0",
        cwd=tmp_path)
    assert "bayesprog.program" in loaded  # the question was asked
    unused = {"scipy.special", "networkx", "matplotlib", "pandas", "pgmpy",
              "bayesprog.views.display", "bayesprog.views.draw", "bayesprog.learning"}
    assert not loaded & unused, loaded & unused


def test_a_script_that_loads_a_program_and_asks_once_builds_no_validator_and_no_plan():
    """The first question of a script: the file of the common shape is read without pydantic
    (its validators cost more than the question), the answer found by elimination with no
    method ranked, so no other method's module, scipy or opt_einsum is imported; a file
    with a learned: record, and a second question, load what they need."""
    code = ("import bayesprog\n"
            "p = bayesprog.load(bayesprog.bundled_path('student', 'program'))\n"
            "print(p.ask('P(I | G=A)').probabilities.round(6).tolist())")
    loaded = loaded_after(code)
    assert not top_level(loaded) & {"pydantic", "scipy", "opt_einsum", "networkx", "pandas"}
    methods = {m for m in loaded if m.startswith("bayesprog.inference.methods.")}
    assert methods == {"bayesprog.inference.methods.base",
                       "bayesprog.inference.methods.contraction"}, methods
    assert "bayesprog.model.records" not in loaded and "bayesprog.language.document" not in loaded
    # a program too small for the program cache is loaded without its hash (OpenSSL's), and a
    # layout's first question keeps nothing for the questions that recur
    assert "hashlib" not in loaded and "bayesprog.inference.recurring" not in loaded
    # by hand: P(I=low, G=A) = 0.7 (0.6 x 0.3 + 0.4 x 0.05) = 0.14, P(G=A) = 0.14 + 0.222
    assert _after(code).splitlines()[-1] == "[0.38674, 0.61326]"
    # a learned: record is read by pydantic, and a second layout ranks the methods
    later = loaded_after(code + "\np.ask('P(D | G=A)'); p.ask('P(D | G=B)')\n"
                         "import bayesprog.language.document")
    assert "bayesprog.inference.methods.table" in later


def test_a_discovery_and_its_program_build_no_validator():
    """discover writes its program with a discovered structure's record under learned:, which
    the plain reader reads: neither the search nor loading what it wrote builds pydantic's
    validators (they took about as long as a small network's whole search)."""
    code = ("import bayesprog\n"
            "rows = {'A': [0, 1] * 50, 'B': [0, 1] * 45 + [1, 0] * 5}\n"
            "found = bayesprog.discover(rows)\n"
            "assert found.parents == {'A': [], 'B': ['A']} or found.parents == "
            "{'A': ['B'], 'B': []}, found.parents\n"
            "again = bayesprog.loads(found.text)\n"
            "print(again.learned[0].structure.method)")
    loaded = loaded_after(code)
    assert "pydantic" not in top_level(loaded)
    assert "bayesprog.language.document" not in loaded
    assert _after(code).splitlines()[-1] == "hc"


def test_a_program_displays_in_a_notebook_without_importing_the_display_first():
    code = ("import bayesprog\n"
            "p = bayesprog.loads(" + repr(STUDENT) + ")\n"
            "html = p.ask('P(I | G)', {'G': 'A'})._repr_html_()\n"
            "assert html and '<table' in html, html")
    subprocess.run([sys.executable, "-c", code], check=True)


def _after(code: str) -> str:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout.strip()


def test_the_command_freezes_its_heap_when_done_and_returns_the_status(tmp_path):
    """``bayesprog`` (``command``) leaves the heap frozen for the exit (no collection visits it
    again), after the command has run and with its exit status; ``main`` (what tests and
    notebooks call) freezes nothing."""
    program = tmp_path / "student.yaml"
    program.write_text(STUDENT, encoding="utf-8")
    code = ("import gc, sys\nfrom bayesprog.cli import command, main\n"
            f"sys.argv = ['bayesprog', 'query', {str(program)!r}, 'P(I)']\n"
            "print('status', main(sys.argv[1:]), gc.get_freeze_count())\n"
            "print('status', command(), gc.get_freeze_count() > 0)\n"
            "sys.argv = ['bayesprog', 'query', 'missing.yaml', 'P(I)']\n"
            "print('status', command())")
    lines = [line for line in _after(code).splitlines() if line.startswith("status ")]
    assert lines == ["status 0 0", "status 0 True", "status 2"], lines


def test_a_worker_freezes_what_it_imported_and_freezes_again_at_exit():
    """A worker process's imports are frozen out of the collector's reach at start, and an
    exit handler freezes what it made since (the last collections at exit skip them)."""
    code = ("import atexit, gc\nfrom runner.experiments.executors import worker_init\n"
            "before = gc.get_freeze_count()\nworker_init(('json',))\n"
            "print(before == 0, gc.get_freeze_count() > 0, atexit._ncallbacks() >= 1)")
    assert _after(code).splitlines()[-1] == "True True True"


def test_the_report_freezes_its_heap_for_holms_collections_and_thaws_it():
    """statsmodels' Holm correction collects garbage at each call: the report runs it with the
    heap frozen, and thaws it after (a heap frozen before stays frozen)."""
    code = ("import gc\nfrom runner.report.build import _heap_frozen\n"
            "with _heap_frozen():\n    inside = gc.get_freeze_count() > 0\n"
            "after = gc.get_freeze_count()\n"
            "gc.freeze(); frozen = gc.get_freeze_count()\n"
            "with _heap_frozen():\n    pass\n"
            "print(inside, after, gc.get_freeze_count() == frozen)")
    assert _after(code).splitlines()[-1] == "True 0 True"
