"""Drawing the graphical model of a program: Graphviz DOT text, or a matplotlib figure.

Discrete variables are circles, continuous ones ellipses with a double border, fields carry
their index (``I[O]``); known variables of a question are shaded, as in the paper's figures.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

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
    graph_figure(program, question).savefig(out, bbox_inches="tight")


def graph_figure(program: Program, question: Question | None = None,
                 panels: dict[str, Any] | None = None) -> Any:
    """The graph as a matplotlib figure. ``panels`` maps a variable to a function
    ``draw(ax)`` that fills a small axes under its node (posterior bars, an observed value)."""
    # a bare Figure, not pyplot: no backend state, nothing shown behind a notebook's back
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    graph = program.graph
    pos = _layers(graph)
    if panels:  # room for a panel to the right of each node
        pos = {n: (3.0 * x, 1.15 * y) for n, (x, y) in pos.items()}
    known = set(question.expression.right) if question else set()
    xs = [p[0] for p in pos.values()]
    ys = [p[1] for p in pos.values()]
    right = 2.5 if panels else 0.8
    width = max(4.0, 1.4 * (max(xs) - min(xs) + 0.8 + right))
    height = max(3.0, 1.3 * (max(ys) - min(ys) + 1.6))
    fig = Figure(figsize=(width, height))
    ax = fig.add_subplot()
    ablated_children = {t.child.name for t in program.terms if str(t.expression) in program.ablated}
    for u, v in graph.edges:
        ax.annotate("", xy=pos[v], xytext=pos[u],
                    arrowprops=dict(arrowstyle="-|>", color="black", shrinkA=18, shrinkB=18, lw=1.2))
    for name, (x, y) in pos.items():
        var = program.variables[name]
        face = "#bbbbbb" if name in known else "white"
        style = "--" if name in ablated_children else "-"
        shape = Circle((x, y), 0.28, facecolor=face, edgecolor="black", ls=style, lw=1.3)
        ax.add_patch(shape)
        if not var.is_discrete:
            ax.add_patch(Circle((x, y), 0.24, facecolor="none", edgecolor="black", lw=0.8))
        ax.text(x, y, _label(program, name), ha="center", va="center", fontsize=10)
    ax.set_xlim(min(xs) - 0.8, max(xs) + right)
    ax.set_ylim(min(ys) - 0.8, max(ys) + 0.8)
    ax.set_aspect("equal")
    ax.axis("off")
    title = program.name + (f" (ablated: {', '.join(program.ablated)})" if program.ablated else "")
    ax.set_title(title, fontsize=11)
    if panels:
        fig.canvas.draw()
        for name, draw in panels.items():
            x, y = pos[name]
            # a small axes under the node, placed in figure coordinates
            corner = fig.transFigure.inverted().transform(ax.transData.transform((x + 1.2, y - 0.4)))
            top = fig.transFigure.inverted().transform(ax.transData.transform((x + 2.3, y + 0.4)))
            inset = fig.add_axes((corner[0], corner[1], top[0] - corner[0], top[1] - corner[1]))
            draw(inset)
    return fig
