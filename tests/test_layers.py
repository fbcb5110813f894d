"""The package's layering: bayesprog's rooms (its sub-packages, and the few modules directly in
it) import one way, from its errors and support up to the command line, with no import circle
between its modules or its rooms, and bayesprog never imports the haptic application (runner);
the application's rooms (runner's sub-packages) import one way, from the world up to the report
and the robot.

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

#: bayesprog's rooms from the bottom up: a room may import its own modules and the rooms below
#: it only; the rooms of one floor (the views and the exchange with other tools) know nothing of
#: each other.
LAYERS = [
    {"errors"},  # the errors users catch
    {"limits"},  # sizes refused before they are allocated
    {"support"},  # files, the cache, bundled models, YAML text, extras, display hooks
    {"vocabulary"},  # variables, P(A | B) expressions and questions, formulas
    {"forms"},  # parametric forms
    {"model"},  # a checked program's terms and inputs, the records of a fit
    {"language"},  # YAML read and checked
    {"inference"},  # the engine
    {"learning"},  # identification from data
    {"program"},  # Program, questions over time, discovered structure
    {"views", "io", "__init__"},  # notation, figures, notebook; networks in and out
    {"cli", "__main__"},  # the command line
]
#: rooms of one floor that never import each other
SIDE_BY_SIDE_IN_BAYESPROG = {"views", "io"}


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
    assert g.has_edge("bayesprog.program.program", "bayesprog.inference")
    assert g.has_edge("bayesprog.program.program", "bayesprog.program.dynamic")  # (a lazy one)
    assert g.has_edge("bayesprog.language.check.terms", "bayesprog.language.check.parameters")
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
    above = [t for t in g.successors(module) if t != "bayesprog" and (
        layer_of(t) > mine
        or {room(t), room(module)} == SIDE_BY_SIDE_IN_BAYESPROG)]
    assert not above, f"{module} (layer {mine}) imports upper layers or rooms beside: {above}"


def room(module: str) -> str:
    """The room of one of bayesprog's modules: its sub-package, or the module itself when it
    stands directly in bayesprog/ (``__init__`` for the package's own)."""
    return module.split(".")[1] if "." in module else "__init__"


def rooms_graph() -> nx.DiGraph:
    """bayesprog's rooms, and an arrow from one to another where a module of the first imports
    a module of the second."""
    g = graph()
    rooms = nx.DiGraph()
    rooms.add_nodes_from(room(n) for n in g if n.startswith("bayesprog"))
    rooms.add_edges_from((room(a), room(b)) for a, b in g.edges
                         if b.startswith("bayesprog") and b != "bayesprog" and room(a) != room(b))
    return rooms


def test_bayesprogs_rooms_have_no_circle_and_no_arrow_running_up():
    rooms = rooms_graph()
    assert rooms.number_of_nodes() >= 12 and rooms.number_of_edges() > 20
    assert not list(nx.simple_cycles(rooms)), list(nx.simple_cycles(rooms))
    upward = [(a, b) for a, b in rooms.edges if LAYERS.index(next(
        x for x in LAYERS if b in x)) > LAYERS.index(next(x for x in LAYERS if a in x))]
    assert not upward, f"arrows running up: {upward}"
    beside = [(a, b) for a, b in rooms.edges if {a, b} == SIDE_BY_SIDE_IN_BAYESPROG]
    assert not beside, beside
    # every room is in one layer, and every layer names rooms that exist
    named = set().union(*LAYERS)
    assert set(rooms) <= named, set(rooms) - named
    assert named <= set(rooms), named - set(rooms)


def test_the_framework_is_a_few_rooms_of_a_few_modules():
    """At most 8 modules directly in bayesprog/, at most 12 in each of its sub-packages (a
    sub-package's own sub-packages counted apart) but the engine's (inference/), and every
    sub-package a package, in a layer."""
    direct = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(direct) <= 8, direct
    for folder in sorted({p.parent for p in PACKAGE.rglob("*.py")} - {PACKAGE}):
        modules = sorted(p.name for p in folder.glob("*.py"))
        assert "__init__.py" in modules, f"{folder.name}: not a package"
        if folder != PACKAGE / "inference":
            assert len(modules) <= 12, (folder.name, modules)
        layer_of("bayesprog." + folder.relative_to(PACKAGE).parts[0])


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
    assert g.has_edge("runner.report.build.write", "runner.experiments.experiment")
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
