"""Drawing a program and its data: the graphical model as Graphviz DOT text or a matplotlib
figure, and a data set's columns pair by pair, one colour per group (:func:`scatter_matrix`).

Discrete variables are circles, continuous ones ellipses with a double border, fields carry
their index (``I[O]``); known variables of a question are shaded, as in the paper's figures.
matplotlib is imported only when something is drawn.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

import networkx as nx

from bayesprog.errors import BayesprogError
from bayesprog.program import Program
from bayesprog.vocabulary.expressions import Question
from bayesprog.vocabulary.variables import Continuous


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


# a data set, pair by pair --------------------------------------------------------------------
#: the rows of a group drawn in one panel at most (a random choice of them, seeded): more
#: hide each other, and the histograms on the diagonal count every row
MOST_POINTS = 1500

#: the states of a discrete column drawn at most, the most frequent
MOST_STATES = 12


def _new_figure(figsize: tuple[float, float]) -> Any:
    """A matplotlib figure drawn by Agg, outside pyplot (no backend switched, nothing kept open
    once it is dropped)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise BayesprogError("drawing needs matplotlib, which is not installed: install it "
                             "with pip install matplotlib (or reinstall bayesprog)") from None
    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def _palette(count: int) -> list[Any]:
    import matplotlib

    name = "tab10" if count <= 10 else "tab20"
    colours = list(matplotlib.colormaps[name].colors)  # type: ignore[attr-defined]
    return [colours[i % len(colours)] for i in range(count)]


def _limits(values: Any) -> tuple[float, float]:
    import numpy as np

    finite = values[np.isfinite(values)]
    if not finite.size:
        return (0.0, 1.0)
    lo, hi = float(finite.min()), float(finite.max())
    pad = 0.05 * (hi - lo) if hi > lo else 0.5 * max(abs(lo), 1e-12)
    return lo - pad, hi + pad


class _Column:
    """One column as drawn: real values, or a discrete column's states at positions 0, 1, ...
    (the :data:`MOST_STATES` most frequent; the rows of the others left out)."""

    def __init__(self, name: str, column: Any, real: bool) -> None:
        import numpy as np

        self.name, self.real = name, real
        if real:
            self.values = column.to_numpy(float)
            self.states: list[str] = []
            self.limits = _limits(self.values)
            self.left_out = 0
            return
        counts = column.value_counts()
        kept = counts.index[:MOST_STATES].tolist()
        from bayesprog.learning.summary import _sorted_groups

        self.states = [s for s in _sorted_groups(column) if s in kept]
        index = {s: float(i) for i, s in enumerate(self.states)}
        self.values = np.array([index.get(v, np.nan) if v is not None else np.nan
                                for v in column], dtype=float)
        self.left_out = int(counts.iloc[MOST_STATES:].sum())
        self.limits = (-0.6, len(self.states) - 0.4)

    def place(self, values: Any, group: int, groups: int, rng: Any) -> Any:
        """Positions of a discrete column's values: each group beside the others within its
        state's slot, spread a little so that equal values do not hide each other."""
        if self.real:
            return values
        width = 0.8 / groups
        return values - 0.4 + width * (group + 0.5) + rng.uniform(-0.35, 0.35, values.size) * width

    def ticks(self, axis: Any) -> None:
        if not self.real:
            axis.set_ticks(range(len(self.states)))
            axis.set_ticklabels([_short(s) for s in self.states])


def _short(text: str, most: int = 10) -> str:
    return text if len(text) <= most else text[: most - 1] + "…"


def scatter_matrix(data: Any, by: str | None = None, columns: Sequence[str] | None = None,
                   discrete: Collection[str] = (), title: str | None = None,
                   source: str | None = None) -> Any:
    """A data set's ``columns`` (default: every column but ``by``) pair by pair, as a matplotlib
    figure of len(columns) x len(columns) panels, one colour per value of the column ``by``
    (default: ``material``, ``M``, else the first discrete column; see
    :func:`~bayesprog.learning.summary.group_column`), with a legend.

    Off the diagonal, the panel of row i and column j draws column j (across) against column i
    (up), the rows where either is empty left out; on the diagonal, each column's histogram
    per group (the same bins for every group), or for a discrete column (one that is not all
    numbers, or named in ``discrete``) the count of each state per group as bars; a discrete
    column against another column draws each group beside the others within its state's slot.
    The title (``title``, else the data's ``source`` and size) says how many cells of each
    column are empty. ``data``: a CSV or Parquet file, a DataFrame or a mapping of columns;
    ``source``: the name of the data in the title (default: the file's). Raises DataError (a
    file that cannot be read, a column it lacks).

    >>> fig = scatter_matrix({"M": ["a", "b"] * 20, "E": range(40), "C": [0.5, None] * 20})
    >>> [ax.get_xlabel() for ax in fig.axes[-2:]]
    ['E', 'C']
    """
    import numpy as np

    from bayesprog.learning.summary import is_real, read_typed, summarise_frame

    frame, read = read_typed(data, discrete)
    summary = summarise_frame(frame, source or read, by, columns)
    by = summary.by
    if not summary.columns:
        raise BayesprogError(f"{summary.source}: nothing to draw: no column beside {by!r}")
    groups = list(summary.groups)
    key = frame[by].to_numpy(object) if not is_real(frame[by]) else \
        frame[by].map(lambda v: f"{v:g}").to_numpy(object)
    members = [np.flatnonzero(key == g) for g in groups]
    drawn = [_Column(c, frame[c], is_real(frame[c])) for c in summary.columns]
    labels = [f"{_short(g, 18)} ({m.size})" for g, m in zip(groups, members, strict=True)]
    # the figure in inches: panels, the margins, the legend on the right, the caption on top
    n = len(drawn)
    panel = 3.2 if n == 1 else min(2.4, max(1.25, 9.5 / n))
    left, bottom = 0.75, 0.6
    right = float(np.clip(0.55 + 0.065 * max(*map(len, labels), len(by)), 1.0, 2.2))
    width = n * panel + left + right
    # about 16 characters of 8 points to the inch
    caption = _caption(summary, drawn, title, any(m.size > MOST_POINTS for m in members),
                       int(16 * (width - left - 0.2)))
    top = 0.25 + 0.14 * (caption.count("\n") + 1)
    height = n * panel + bottom + top
    fig = _new_figure((width, height))  # (matplotlib imported here, or its absence said)
    from matplotlib.lines import Line2D

    colours = _palette(len(groups))
    axes = fig.subplots(n, n, squeeze=False)
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height,
                        top=1 - top / height, wspace=0.2 if n > 1 else 0,
                        hspace=0.1 if n > 1 else 0)
    rng = np.random.default_rng(0)
    shown = [m if m.size <= MOST_POINTS else np.sort(rng.choice(m, MOST_POINTS, replace=False))
             for m in members]
    for i, y in enumerate(drawn):
        for j, x in enumerate(drawn):
            ax = axes[i, j]
            ax.tick_params(labelsize=6, length=2, pad=1)
            ax.set_xlim(*x.limits)
            if i == j:
                _diagonal(ax, x, members, colours, alone=n == 1)
            else:
                _pairs(ax, x, y, shown, groups, colours, rng, 2.6 if n <= 3 else 1.8)
            _labels(ax, x, y, i, j, n, panel)
    handles = [Line2D([], [], ls="", marker="o", ms=6, color=c, label=text)
               for c, text in zip(colours, labels, strict=True)]
    fig.legend(handles=handles, title=by, loc="upper left", fontsize=7, title_fontsize=8,
               frameon=False, bbox_to_anchor=(1 - (right - 0.12) / width, 1 - top / height))
    fig.suptitle(caption, fontsize=8, x=left / width, ha="left", y=1 - 0.08 / height,
                 va="top")
    return fig


def _pairs(ax: Any, x: _Column, y: _Column, shown: list[Any], groups: list[str],
           colours: list[Any], rng: Any, size: float) -> None:
    """Column ``x`` across, ``y`` up, a group at a time; rows lacking either left out."""
    import numpy as np

    ax.set_ylim(*y.limits)
    for g, rows in enumerate(shown):
        xs, ys = x.values[rows], y.values[rows]
        both = ~(np.isnan(xs) | np.isnan(ys))
        # the more points, the fainter each: a dense cloud shows where it is dense
        alpha = float(np.clip(8 / np.sqrt(max(both.sum(), 1)), 0.25, 0.85))
        ax.plot(x.place(xs[both], g, len(groups), rng), y.place(ys[both], g, len(groups), rng),
                ls="", marker="o", ms=size, mew=0, alpha=alpha, color=colours[g],
                label=groups[g], rasterized=True)
    y.ticks(ax.yaxis)


def _labels(ax: Any, x: _Column, y: _Column, i: int, j: int, n: int, panel: float) -> None:
    """The names on the bottom row and the left column, the ticks' labels beside them only."""
    x.ticks(ax.xaxis)
    ax.set_xlabel(x.name if i == n - 1 else "", fontsize=8)
    ax.set_ylabel((y.name if j == 0 else "") if n > 1 or i != j else "rows", fontsize=8)
    if i != n - 1:
        ax.tick_params(labelbottom=False)
    elif not x.real and 0.06 * sum(len(_short(s)) + 1 for s in x.states) > panel:
        ax.tick_params(axis="x", labelrotation=60)  # states' names too long to stand side by side
    if j != 0:
        ax.tick_params(labelleft=False)


def _diagonal(ax: Any, column: _Column, members: list[Any], colours: list[Any],
              alone: bool) -> None:
    """A column's distribution per group: histograms over the same bins, or bars of counts.
    In a matrix (not ``alone``) the panel's own scale is its row's, as its neighbours' (so the
    row's values read off its left edge), the counts scaled into it and read on the right."""
    import numpy as np

    values = column.values
    if np.isnan(values).all():
        ax.text(0.5, 0.5, "no values", ha="center", va="center", fontsize=7,
                transform=ax.transAxes)
        return
    if column.real:
        finite = values[np.isfinite(values)]
        # bins for the rows of one group (Rice's rule), twice as many over the range of all
        bins = int(np.clip(round(2 * np.cbrt(finite.size / len(members))), 8, 40))
        edges = np.linspace(finite.min(), finite.max(), 2 * bins + 1)
        counts = [np.histogram(values[rows], edges)[0] for rows in members]
        positions = None
    else:
        edges = None
        positions = np.arange(len(column.states), dtype=float)
        counts = [np.bincount(values[rows][np.isfinite(values[rows])].astype(int),
                              minlength=positions.size) for rows in members]
    top = max(int(c.max()) for c in counts) or 1
    low, scale = 0.0, 1.0
    if not alone:
        low, high = column.limits
        scale = 0.92 * (high - low) / top
        ax.set_ylim(low, high)
        column.ticks(ax.yaxis)
        right = ax.secondary_yaxis("right", functions=(lambda v: (v - low) / scale,
                                                       lambda c: low + c * scale))
        right.tick_params(labelsize=5, length=2, pad=1)
        from matplotlib.ticker import MaxNLocator

        right.yaxis.set_major_locator(MaxNLocator(nbins=5, integer=True))  # rows, whole
    width = 0.8 / len(members)
    for g, own in enumerate(counts):
        if edges is not None:
            fill = 0.15 if len(members) <= 4 else 0.0
            ax.stairs(low + own * scale, edges, baseline=low, fill=True, color=colours[g],
                      alpha=fill, lw=0)
            ax.stairs(low + own * scale, edges, baseline=low, color=colours[g], lw=1.1)
        else:
            assert positions is not None
            ax.bar(positions - 0.4 + width * (g + 0.5), own * scale, width, bottom=low,
                   color=colours[g])


def _caption(summary: Any, drawn: list[_Column], title: str | None, thinned: bool,
             width: int) -> str:
    """The figure's title, in lines of ``width`` characters at most: what is drawn, and what
    of it is missing or left out."""
    empty = {name: int(sum(t.loc[g, "missing"] for g in t.index))
             for name, t in {**summary.real, **summary.discrete}.items()}
    missing = ", ".join(f"{c} {empty[c]}" for c in summary.columns if empty[c])
    lines = [title or f"{summary.source}: {summary.rows} rows, {len(summary.counts)} values of "
             f"{summary.by}"]
    lines.append(f"empty cells (left out{' pair by pair' if len(drawn) > 1 else ''}): "
                 f"{missing}" if missing else "no empty cells")
    if len(drawn) > 1:
        lines[-1] += "; on the diagonal, rows per bin or per state (the scale on the right)"
    rarer = [f"{c.name} {c.left_out}" for c in drawn if c.left_out]
    if rarer:
        lines[-1] += f"; rows of rarer states left out: {', '.join(rarer)}"
    if summary.ungrouped:
        lines[-1] += f"; rows without a {summary.by}: {summary.ungrouped}"
    if thinned:
        lines.append(f"at most {MOST_POINTS} rows per {summary.by} drawn in each panel; the "
                     "histograms count all")
    import textwrap

    return "\n".join(part for line in lines for part in textwrap.wrap(
        line, width, break_long_words=False, break_on_hyphens=False))
