"""The package's layering: no import circle between bayesprog's modules or its layers, and
bayesprog never imports the haptic application (runner); the application's rooms (runner's
sub-packages) import one way, from the world up to the report and the robot.

Imports are read from the source with ``ast`` (every import statement, wherever it stands:
module level, inside functions, under ``TYPE_CHECKING``), so a lazy import counts too.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import networkx as nx
import pytest

PACKAGE = Path(__file__).parents[1] / "bayesprog"
RUNNER = PACKAGE.parent / "runner"

#: From the bottom up: a layer may import its own modules and the layers below it only.
LAYERS = [
    {"errors", "variables", "expressions", "formula", "files", "rich", "limits", "bundled",
     "extras", "cache", "yamltext"},
    {"forms"},
    {"model", "records"},
    {"language"},
    {"inference"},
    {"learning"},
    {"program", "dynamic"},
    {"compile", "draw", "show", "display", "discovery", "__init__"},
    {"io"},
    {"cli", "__main__"},
]


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> set[str]:
    """Modules of bayesprog (or runner) that the file at ``path`` imports, fully named."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    here = module_name(path)
    package = here if path.name == "__init__.py" else here.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1]
                                + ([base] if base else []))
            found.add(base)
            # ``from bayesprog.forms import standard`` imports the module bayesprog.forms.standard
            found |= {f"{base}.{alias.name}" for alias in node.names}
    return {name for name in found if name.split(".")[0] in ("bayesprog", "runner")}


@functools.cache  # read once: the tests only look at it
def graph(package: Path = PACKAGE) -> nx.DiGraph:
    files = {module_name(p): p for p in package.rglob("*.py")}
    g = nx.DiGraph()
    for name, path in files.items():
        g.add_node(name)
        for target in imports(path):
            while target not in files and "." in target:
                target = target.rpartition(".")[0]  # a name imported from a module
            # a package's own __init__ runs before any of its modules: not an import edge
            ancestor = name.startswith(target + ".")
            if target != name and not ancestor and (target in files or target.startswith("runner")):
                g.add_edge(name, target)
    return g


def layer_of(module: str) -> int:
    top = module.split(".")[1] if "." in module else "__init__"
    for i, layer in enumerate(LAYERS):
        if top in layer:
            return i
    raise AssertionError(f"{module} is in no layer: add it to LAYERS")


def test_the_graph_sees_the_imports():
    g = graph()
    assert g.has_edge("bayesprog.program", "bayesprog.inference")
    assert g.has_edge("bayesprog.inference.methods.table", "bayesprog.inference.methods.base")
    assert g.number_of_edges() > 40


def test_no_import_circle_between_modules():
    cycles = list(nx.simple_cycles(graph()))
    assert not cycles, f"import circles: {cycles}"


def test_bayesprog_never_imports_runner():
    g = graph()
    offenders = [(a, b) for a, b in g.edges if b.startswith("runner")]
    assert not offenders, offenders


def test_inference_and_learning_never_import_the_language():
    """The engine and the estimators work on the program's data types (bayesprog.model), not on
    the YAML reader that builds them."""
    g = graph()
    offenders = [(a, b) for a, b in g.edges
                 if a.split(".")[1:2] in (["inference"], ["learning"])
                 and b.startswith("bayesprog.language")]
    assert not offenders, offenders
    assert g.has_edge("bayesprog.inference.factors", "bayesprog.model")  # (the test sees them)


@pytest.mark.parametrize("module", sorted(graph().nodes - {"bayesprog"}))
def test_each_module_imports_only_its_layer_and_below(module):
    g = graph()
    mine = layer_of(module)
    above = [t for t in g.successors(module) if t != "bayesprog" and layer_of(t) > mine]
    assert not above, f"{module} (layer {mine}) imports upper layers: {above}"


def test_the_runner_uses_only_the_public_api():
    """The haptic application imports bayesprog's top-level names only (bayesprog.__all__), so
    the framework's modules can move without breaking it."""
    import bayesprog

    runner = PACKAGE.parent / "runner"
    offenders = []
    for path in runner.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("bayesprog"):
                if node.module != "bayesprog":
                    offenders.append(f"{path.name}: from {node.module} import ...")
                else:
                    offenders += [f"{path.name}: {a.name} is not in bayesprog.__all__"
                                  for a in node.names if a.name not in bayesprog.__all__]
            elif isinstance(node, ast.Import):
                offenders += [f"{path.name}: import {a.name}" for a in node.names
                              if a.name.startswith("bayesprog.")]
    assert not offenders, offenders


def test_the_framework_names_no_application():
    """Nothing in bayesprog/ speaks of the haptic application: its commands, figures and
    metrics are the runner plugin's."""
    import re

    words = re.compile(r"\bhaptic|\bGamma\b|\bFig\. ?\d|\bpi_(tar|per|obj)\b|\bexplore\b",
                       re.IGNORECASE)
    found = [f"{path.relative_to(PACKAGE.parent)}:{i}: {line.strip()}"
             for path in PACKAGE.rglob("*.py")
             for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
             if words.search(line)]
    assert not found, found


def _is_form_name(node: ast.AST) -> bool:
    """``form.name`` or ``anything.form.name``."""
    return (isinstance(node, ast.Attribute) and node.attr == "name"
            and ((isinstance(node.value, ast.Attribute) and node.value.attr == "form")
                 or (isinstance(node.value, ast.Name) and node.value.id == "form")))


def test_no_code_outside_the_forms_compares_a_forms_name():
    """What a form can do (an estimator, an affine mean, soft evidence, a sub-program) is
    declared by its class; the engine, the learning, the checker and the display ask for it,
    never for a name: a new form is one class."""
    from bayesprog.forms import available_forms

    names = set(available_forms())
    found = []
    for path in PACKAGE.rglob("*.py"):
        if "forms" in path.relative_to(PACKAGE).parts[:1]:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.Compare):
                continue
            operands = [node.left, *node.comparators]
            literals = {c.value for o in operands for c in ast.walk(o)
                        if isinstance(c, ast.Constant) and isinstance(c.value, str)}
            if any(_is_form_name(o) for o in operands) or literals & names:
                found.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno}")
    assert not found, found


#: runner's rooms from the bottom up: a room may import its own modules, the rooms below it and
#: bayesprog; the report and the robot stand side by side and know nothing of each other.
ROOMS = [
    {"world"},
    {"attention"},
    {"experiments"},
    {"report"},
    {"robot"},
    {"plugin", "sensor", "__init__"},
]
SIDE_BY_SIDE = {"report", "robot"}


def room_of(module: str) -> int:
    top = module.split(".")[1] if "." in module else "__init__"
    for i, room in enumerate(ROOMS):
        if top in room:
            return i
    raise AssertionError(f"{module} is in no room: add it to ROOMS")


@functools.cache
def runner_graph() -> nx.DiGraph:
    g = graph(RUNNER)
    return g.subgraph([n for n in g if n.startswith("runner")]).copy()


def test_the_runner_graph_sees_the_imports():
    g = runner_graph()
    assert g.has_edge("runner.attention.explorer", "runner.world.scenario")
    assert g.has_edge("runner.report.build", "runner.experiments.experiment")
    assert g.has_edge("runner.robot.ros.robot_node", "runner.experiments.loop")
    assert g.number_of_edges() > 40


def test_no_import_circle_in_the_runner():
    cycles = list(nx.simple_cycles(runner_graph()))
    assert not cycles, f"import circles: {cycles}"


@pytest.mark.parametrize("module", sorted(runner_graph().nodes - {"runner"}))
def test_each_room_of_the_runner_imports_only_the_rooms_below(module):
    g = runner_graph()
    mine = room_of(module)
    wrong = [t for t in g.successors(module) if t != "runner" and (
        room_of(t) > mine
        or ({t.split(".")[1], module.split(".")[1]} == SIDE_BY_SIDE))]
    assert not wrong, f"{module} (room {mine}) imports rooms above or beside it: {wrong}"


def test_the_runner_is_a_few_rooms_of_a_few_modules():
    """At most 6 modules directly in runner/, at most 9 in each of its sub-packages (a
    sub-package's own sub-packages counted apart), and every sub-package in a room."""
    direct = sorted(p.name for p in RUNNER.glob("*.py"))
    assert len(direct) <= 6, direct
    for folder in sorted({p.parent for p in RUNNER.rglob("*.py")} - {RUNNER}):
        modules = sorted(p.name for p in folder.glob("*.py"))
        assert "__init__.py" in modules, f"{folder.name}: not a package"
        assert len(modules) <= 9, (folder.name, modules)
        room_of("runner." + folder.relative_to(RUNNER).parts[0])
