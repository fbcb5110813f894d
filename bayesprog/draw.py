"""Drawing the graphical model of a program: Graphviz DOT text, or a matplotlib figure.

Discrete variables are circles, continuous ones ellipses with a double border, fields carry
their index (``I[O]``); known variables of a question are shaded, as in the paper's figures.
"""

from __future__ import annotations

from pathlib import Path

import networkx as nx

from bayesprog.expressions import Question
from bayesprog.program import Program
from bayesprog.variables import Continuous


def _label(program: Program, name: str) -> str:
    var = program.variables[name]
    if isinstance(var, Continuous) and var.index:
        return f"{name}[{var.index}]"
    return name


def to_dot(program: Program, question: Question | None = None) -> str:
    """The DAG as Graphviz DOT (soft evidence drawn as small square factors)."""
    known = set(question.expression.right) if question else set()
    searched = set(question.expression.left) if question else set()
    lines = [f'digraph "{program.name}" {{', "  rankdir=TB;", '  node [fontname="Helvetica"];']
    for name, var in program.variables.items():
        attrs = [f'label="{_label(program, name)}"']
        attrs.append("shape=circle" if var.is_discrete else "shape=ellipse, peripheries=2")
        if name in known:
            attrs.append('style=filled, fillcolor="#bbbbbb"')
        elif name in searched:
            attrs.append('style=filled, fillcolor="#cfe2f3"')
        if str(name) in {t.child.name for t in program.terms if str(t.expression) in program.ablated}:
            attrs.append("style=dashed")
        lines.append(f'  "{name}" [{", ".join(attrs)}];')
    for u, v in program.graph.edges:
        lines.append(f'  "{u}" -> "{v}";')
    for i, t in enumerate(t for t in program.terms if t.soft):
        node = f"soft{i}"
        lines.append(f'  "{node}" [shape=box, width=0.2, height=0.2, label="", style=filled, '
                     'fillcolor=black];')
        lines.append(f'  "{node}" -> "{t.child.name}" [style=dotted];')
    lines.append("}")
    return "\n".join(lines) + "\n"


def _layers(graph: nx.DiGraph) -> dict[str, tuple[float, float]]:
    layer: dict[str, int] = {}
    for node in nx.topological_sort(graph):
        preds = list(graph.predecessors(node))
        layer[node] = 1 + max((layer[p] for p in preds), default=-1)
    by_layer: dict[int, list[str]] = {}
    for node, k in layer.items():
        by_layer.setdefault(k, []).append(node)
    pos: dict[str, tuple[float, float]] = {}
    for k, nodes in by_layer.items():
        for i, node in enumerate(nodes):
            pos[node] = (i - (len(nodes) - 1) / 2, -k)
    return pos


def write_graph(program: Program, out: Path, question: Question | None = None) -> None:
    """Write ``out`` as .dot text, or as a .png/.pdf/.svg figure drawn with matplotlib."""
    if out.suffix.lower() == ".dot":
        out.write_text(to_dot(program, question), encoding="utf-8")
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    graph = program.graph
    pos = _layers(graph)
    known = set(question.expression.right) if question else set()
    width = max(4.0, 1.4 * max(sum(1 for p in pos.values() if p[1] == y) for y in {p[1] for p in pos.values()}))
    height = max(3.0, 1.3 * (1 - min(p[1] for p in pos.values())))
    fig, ax = plt.subplots(figsize=(width, height))
    ablated_children = {t.child.name for t in program.terms if str(t.expression) in program.ablated}
    for u, v in graph.edges:
        ax.annotate("", xy=pos[v], xytext=pos[u],
                    arrowprops=dict(arrowstyle="-|>", color="black", shrinkA=18, shrinkB=18, lw=1.2))
    for name, (x, y) in pos.items():
        var = program.variables[name]
        face = "#bbbbbb" if name in known else "white"
        style = "--" if name in ablated_children else "-"
        shape = plt.Circle((x, y), 0.28, facecolor=face, edgecolor="black", ls=style, lw=1.3)
        ax.add_patch(shape)
        if not var.is_discrete:
            ax.add_patch(plt.Circle((x, y), 0.24, facecolor="none", edgecolor="black", lw=0.8))
        ax.text(x, y, _label(program, name), ha="center", va="center", fontsize=10)
    xs = [p[0] for p in pos.values()]
    ys = [p[1] for p in pos.values()]
    ax.set_xlim(min(xs) - 0.8, max(xs) + 0.8)
    ax.set_ylim(min(ys) - 0.8, max(ys) + 0.8)
    ax.set_aspect("equal")
    ax.axis("off")
    title = program.name + (f" (ablated: {', '.join(program.ablated)})" if program.ablated else "")
    ax.set_title(title, fontsize=11)
    fig.savefig(out, bbox_inches="tight")
    plt.close(fig)
