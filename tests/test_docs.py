"""The documentation is executable: the tutorial's files, commands and Python sessions are run
and compared with what the pages show; every shipped program validates; the language reference
covers every registered form.

Conventions in the Markdown pages:

* a ```yaml block preceded by a line ``<!-- file: NAME.yaml -->`` is a file the reader writes;
* a ```console block holds ``$ bayesprog ...`` commands, each followed by its exact output
  (stdout, or stderr for a command that fails with status 2);
* a ```python block is a doctest session; the sessions of one page share their names.

Blocks run in the order of the page, in a temporary folder.
"""

from __future__ import annotations

import doctest
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

import bayesprog
import bayesprog.cli
from bayesprog.forms import base as forms_base

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
MODELS = ROOT / "models"

_FENCE = re.compile(r"^```(?P<info>[A-Za-z0-9_-]*)[ \t]*$")
_FILE = re.compile(r"^<!--\s*file:\s*(?P<name>\S+)\s*-->\s*$")


@dataclass
class Block:
    kind: str  # "file", "console" or "python"
    text: str
    line: int  # 1-based line of the opening fence
    name: str = ""  # file name, for "file" blocks


def blocks(page: Path) -> list[Block]:
    """The file, console and python blocks of ``page``, in order."""
    lines = page.read_text(encoding="utf-8").splitlines()
    out: list[Block] = []
    i = 0
    while i < len(lines):
        match = _FENCE.match(lines[i])
        if not match or not match.group("info"):
            i += 1
            continue
        info, start = match.group("info"), i
        end = start + 1
        while end < len(lines) and lines[end].rstrip() != "```":
            end += 1
        if end == len(lines):
            raise AssertionError(f"{page.name}:{start + 1}: unclosed ``` block")
        body = "\n".join(lines[start + 1 : end]) + "\n"
        previous = next((lines[k] for k in range(start - 1, -1, -1) if lines[k].strip()), "")
        file = _FILE.match(previous.strip())
        if info in ("yaml", "csv") and file:
            out.append(Block("file", body, start + 1, file.group("name")))
        elif info in ("console", "python"):
            out.append(Block(info, body, start + 1))
        i = end + 1
    return out


def commands(block: Block) -> list[tuple[str, str, int]]:
    """``(command, expected output, line)`` for each ``$ `` line of a console block."""
    out: list[tuple[str, list[str], int]] = []
    for offset, line in enumerate(block.text.splitlines()):
        if line.startswith("$ "):
            out.append((line[2:], [], block.line + 1 + offset))
        elif out:
            out[-1][1].append(line)
        elif line.strip():
            raise AssertionError(f"line {block.line + 1 + offset}: output before any '$ ' command")
    return [(cmd, "\n".join(expected), line) for cmd, expected, line in out]


def _clean(text: str) -> str:
    return "\n".join(line.rstrip() for line in text.strip("\n").splitlines())


def run_page(page: Path, folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Write the page's files into ``folder`` and run its commands and sessions there."""
    globs: dict[str, object] = {"__name__": f"docs.{page.stem}"}
    parser = doctest.DocTestParser()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    found = blocks(page)
    assert found, f"{page.name}: no runnable blocks"
    for block in found:
        where = f"{page.name}:{block.line}"
        if block.kind == "file":
            (folder / block.name).write_text(block.text, encoding="utf-8")
        elif block.kind == "console":
            for command, expected, line in commands(block):
                argv = shlex.split(command)
                assert argv[0] == "bayesprog", f"{page.name}:{line}: not a bayesprog command"
                capsys.readouterr()
                status = bayesprog.cli.main(argv[1:])
                out, err = capsys.readouterr()
                assert status == (2 if err else 0), f"{page.name}:{line}: status {status}\n{err}"
                assert _clean(out + err) == _clean(expected), (
                    f"{page.name}:{line}: $ {command}\n--- expected\n{_clean(expected)}\n"
                    f"--- found\n{_clean(out + err)}"
                )
        else:
            test = parser.get_doctest(block.text, globs, where, str(page), block.line)
            report: list[str] = []
            result = runner.run(test, out=report.append, clear_globs=False)
            globs.update(test.globs)  # a DocTest works on a copy; later sessions see the names
            assert result.failed == 0, "".join(report)


@pytest.fixture
def isolated_forms():
    """Forms registered by a page's sessions do not outlive the test."""
    saved = dict(forms_base._REGISTRY)
    yield
    forms_base._REGISTRY.clear()
    forms_base._REGISTRY.update(saved)


def test_tutorial_runs_as_written(tmp_path, monkeypatch, capsys, isolated_forms):
    monkeypatch.chdir(tmp_path)
    run_page(DOCS / "tutorial.md", tmp_path, capsys)


def test_language_reference_runs_as_written(tmp_path, monkeypatch, capsys, isolated_forms):
    monkeypatch.chdir(tmp_path)
    run_page(DOCS / "language.md", tmp_path, capsys)


def _model_files() -> list[Path]:
    out = []
    for path in sorted(MODELS.rglob("*.yaml")) + sorted(MODELS.rglob("*.yml")):
        rel = path.relative_to(MODELS)
        if rel.parts[0] in ("scenarios", "experiments", "sensors", "physics"):
            data = yaml.safe_load(path.read_text(encoding="utf-8"))
            if not (isinstance(data, dict) and "bayesprog" in data):
                continue  # a scenario or experiment description, not a program
        out.append(path)
    return out


@pytest.mark.parametrize("path", _model_files(), ids=lambda p: str(p.relative_to(MODELS)))
def test_shipped_programs_validate(path):
    program = bayesprog.load(path)
    assert program.terms


def test_language_reference_mentions_every_form():
    text = (DOCS / "language.md").read_text(encoding="utf-8")
    forms = [name for name in bayesprog.available_forms() if "example" not in name]
    assert forms
    missing = [name for name in forms if f"`{name}`" not in text]
    assert not missing, f"docs/language.md does not document the form(s) {missing}"


def test_every_file_the_readme_names_exists():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    named = set(re.findall(r"(?<![\w/.])((?:models|docs|benchmarks|tests)/[\w./-]+\.\w+)", text))
    assert named, "the README names no file"
    missing = sorted(n for n in named if not (ROOT / n).exists())
    assert not missing, f"the README names files that do not exist: {missing}"
