"""Notebook display: programs, posteriors and MAP answers as HTML (with inline SVG drawings), and
:func:`show_inference`, a program's graph with each variable's posterior drawn at its node.

matplotlib is imported only when something is drawn, so ``import bayesprog`` stays light.
"""

from __future__ import annotations

import html
import io
from collections.abc import Mapping
from typing import Any

import numpy as np

from bayesprog.errors import QuestionError
from bayesprog.inference import MapResult, Posterior
from bayesprog.program import Program
from bayesprog.support import rich
from bayesprog.views.draw import graph_figure
from bayesprog.views.show import render

#: rows of a table (and bars of a chart) shown for one answer; the rest are summarised
ROWS = 12

_STYLE = ("border-collapse:collapse;font-family:monospace;font-size:12px;"
          "margin:2px 0 6px 0")


def svg_of(fig: Any) -> str:
    """A matplotlib figure as inline SVG (text kept as text), without the XML prologue."""
    import matplotlib

    buffer = io.StringIO()
    with matplotlib.rc_context({"svg.fonttype": "none"}):
        fig.savefig(buffer, format="svg", bbox_inches="tight")
    text = buffer.getvalue()
    return text[text.index("<svg"):]


def _table(header: list[str], rows: list[list[str]]) -> str:
    head = "".join(f'<th style="text-align:left;padding:1px 8px">{html.escape(h)}</th>'
                   for h in header)
    body = "".join("<tr>" + "".join(f'<td style="padding:1px 8px">{html.escape(c)}</td>'
                                    for c in row) + "</tr>" for row in rows)
    return f'<table style="{_STYLE}"><tr>{head}</tr>{body}</table>'


def _ranked(post: Posterior, probs: np.ndarray) -> list[tuple[str, float]]:
    """(assignment, probability) of one batch row, in state order for one variable, else the
    most probable first."""
    values = probs.ravel()
    ranked = len(post.variables) > 1 or values.size > ROWS
    if ranked:  # the most probable first; only those are labelled
        order = np.argsort(-values, kind="stable")[: ROWS * 4]
    else:
        order = np.arange(values.size)

    def label(flat: int) -> str:
        idx = np.unravel_index(flat, probs.shape)
        return ", ".join(f"{v}={post.names[v][i]}" if len(post.variables) > 1 else
                         post.names[v][i] for v, i in zip(post.variables, idx, strict=True))

    return [(label(int(i)), float(values[i])) for i in order]


def _bars(pairs: list[tuple[str, float]], title: str) -> str:
    from matplotlib.figure import Figure

    shown = pairs[:ROWS]
    fig = Figure(figsize=(4.2, 0.3 * len(shown) + 0.7))
    ax = fig.add_subplot()
    ax.barh(range(len(shown)), [p for _, p in shown], color="#4878a8")
    ax.set_yticks(range(len(shown)), [label for label, _ in shown], fontsize=9)
    ax.invert_yaxis()
    ax.set_xlim(0, 1)
    ax.set_xlabel("probability", fontsize=9)
    ax.set_title(title, fontsize=10)
    ax.tick_params(axis="x", labelsize=8)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)
    return svg_of(fig)


def _ablated(ablated: tuple[str, ...]) -> str:
    if not ablated:
        return ""
    return f"<p><i>ablated: {html.escape(', '.join(ablated))}</i></p>"


def posterior_html(post: Posterior) -> str:
    """A posterior as a table and a bar chart (the first rows of a batch as a table)."""
    title = f"<b>{html.escape(post.question)}</b>" + _ablated(post.ablated)
    if post.batch_shape:
        rows = post.probabilities.reshape((-1,) + post.probabilities.shape[len(post.batch_shape):])
        shown = min(len(rows), ROWS)
        header = ["row"] + [label for label, _ in _ranked(post, rows[0])][:ROWS]
        if len(post.variables) > 1 or rows.shape[1:] != (len(header) - 1,):
            header = ["row", "most probable", "probability"]
            body = [[str(r)] + [f"{v}" if i == 0 else f"{v:.6g}" for i, v in
                                enumerate(_ranked(post, rows[r])[0])] for r in range(shown)]
        else:
            body = [[str(r)] + [f"{p:.6g}" for p in rows[r].ravel()] for r in range(shown)]
        more = (f"<p>{len(rows) - shown} more rows (batch shape {post.batch_shape})</p>"
                if len(rows) > shown else f"<p>batch shape {post.batch_shape}</p>")
        return f"<div>{title}{_table(header, body)}{more}</div>"
    pairs = _ranked(post, post.probabilities)
    name = ", ".join(post.variables)
    table = _table([name, "probability"], [[label, f"{p:.6g}"] for label, p in pairs[:ROWS]])
    size = post.probabilities.size
    more = f"<p>{size - ROWS} more (smaller) entries</p>" if size > ROWS else ""
    chart = _bars(pairs, post.question)
    return (f'<div>{title}<div style="display:flex;gap:16px;align-items:flex-start">'
            f"<div>{table}{more}</div><div>{chart}</div></div></div>")


def map_html(result: MapResult) -> str:
    """A MAP answer: the assignment, its posterior probability and the number of ties."""
    title = (f"<b>{'' if result.kind == 'sequence' else 'MAP '}{html.escape(result.question)}"
             "</b>" + _ablated(result.ablated))
    assignment = result.assignment
    if result.kind == "sequence":
        steps = {k: np.asarray(v).reshape(result.indices.shape[0], -1) for k, v in
                 assignment.items()}
        prob = result.probability.ravel()
        shown = min(len(prob), ROWS)
        header = ["step"] + [f"{k}" + (f" [{r}]" if prob.size > 1 else "")
                             for r in range(shown) for k in steps]
        body = [[str(t + 1)] + [str(steps[k][t, r]) for r in range(shown) for k in steps]
                for t in range(result.indices.shape[0])]
        body.append(["probability"] + [f"{prob[r]:.6g}" for r in range(shown) for _ in steps])
        ties = np.asarray(result.ties).ravel()
        if (ties[:shown] > 1).any():
            body.append(["tied sequences"] + [str(ties[r]) for r in range(shown) for _ in steps])
        return f"<div>{title}{_table(header, body)}</div>"
    if result.indices.ndim > 1:
        flat = {k: np.asarray(v).ravel() for k, v in assignment.items()}
        prob = result.probability.ravel()
        shown = min(len(prob), ROWS)
        body = [[str(r)] + [str(flat[k][r]) for k in flat] + [f"{prob[r]:.6g}"]
                for r in range(shown)]
        return f"<div>{title}{_table(['row', *flat, 'probability'], body)}</div>"
    body = [[k, str(v)] for k, v in assignment.items()]
    body.append(["probability", f"{float(result.probability):.6g}"])
    if int(result.ties) > 1:
        body.append(["tied assignments", str(int(result.ties))])
    return f"<div>{title}{_table(['variable', 'value'], body)}</div>"


def program_html(program: Program) -> str:
    """A program: its decomposition in Bayesian-programming notation, and its graph."""
    text = html.escape(render(program))
    graph = svg_of(graph_figure(program))
    return (f'<div style="display:flex;flex-wrap:wrap;gap:16px;align-items:flex-start">'
            f'<pre style="font-size:12px;margin:0;white-space:pre-wrap;max-width:60em">{text}</pre>'
            f"<div>{graph}</div></div>")


class InferenceView:
    """A program's graph with the posterior of each variable under the evidence drawn at its
    node: bars for a discrete variable, the value for an observed one. Displays as SVG in a
    notebook (``_repr_svg_``); ``save(path)`` writes it (.svg, .png, .pdf)."""

    def __init__(self, program: Program, figure: Any, marginals: dict[str, Posterior]):
        self.program, self.figure, self.marginals = program, figure, marginals

    def _repr_svg_(self) -> str:
        return svg_of(self.figure)

    def save(self, path: str) -> None:
        self.figure.savefig(path, bbox_inches="tight")


def show_inference(program: Program, evidence: Mapping[str, Any] | None = None, *,
                   ablate: tuple[str, ...] | list[str] = (),
                   inputs: Mapping[str, Any] | None = None) -> InferenceView:
    """The graph of ``program`` (with ``ablate`` applied, drawn dashed) with, at each discrete
    variable that is not observed, its posterior ``P(X | evidence)``, and at each observed one
    its value (as pyAgrum's showInference does).

    >>> import bayesprog
    >>> p = bayesprog.loads('''
    ... bayesprog: 1
    ... variables: {Rain: {states: [rain, dry]}, Grass: {states: [wet, dry]}}
    ... decomposition:
    ...   - {term: P(Rain), form: table, table: [0.2, 0.8]}
    ...   - {term: P(Grass | Rain), form: table, table: {rain: [0.9, 0.1], dry: [0.2, 0.8]}}
    ... ''')
    >>> view = show_inference(p, {"Grass": "wet"})
    >>> view.marginals["Rain"].probabilities.round(4).tolist()
    [0.5294, 0.4706]
    """
    from bayesprog.vocabulary.expressions import Expression, Question

    if ablate:
        program = program.ablate([ablate] if isinstance(ablate, str) else list(ablate))
    evidence = dict(evidence or {})
    given = ", ".join(evidence)
    panels = {}
    try:  # every posterior from one junction tree
        found = program.marginals(evidence, inputs=inputs)
    except QuestionError:  # a real variable not observed: a question per variable
        found = None
    marginals = {}
    for name, var in program.variables.items():
        if name in evidence:
            value = evidence[name]
            if isinstance(value, str):
                text = f"{name} = {value}"
            elif np.ndim(value) == 0:
                text = f"{name} = {float(np.asarray(value)):.4g}"
            else:  # a field, or a batch of values
                text = f"{name}: array of shape {np.shape(value)}"
            panels[name] = _value_panel(text)
        elif var.is_discrete:
            post = found[name] if found is not None else program.ask(
                f"P({name}" + (f" | {given})" if given else ")"), evidence, inputs=inputs)
            assert isinstance(post, Posterior)
            marginals[name] = post
            panels[name] = _bar_panel(post)
    question = Question(Expression(tuple(marginals), tuple(evidence), {}), "posterior")
    figure = graph_figure(program, question, panels)
    return InferenceView(program, figure, marginals)


def _bar_panel(post: Posterior) -> Any:
    probs = post.probabilities
    rows = int(np.prod(post.batch_shape, dtype=np.int64)) if post.batch_shape else 1
    if post.batch_shape:  # a batch of evidence: the first row's posterior
        probs = probs.reshape((rows,) + probs.shape[len(post.batch_shape):])[0]

    def draw(ax: Any) -> None:
        if rows > 1:
            ax.set_title(f"row 0 of {rows}", fontsize=6)
        pairs = _ranked(post, probs)
        if len(pairs) > 6:  # the most probable states, with what the others hold together
            pairs = sorted(pairs, key=lambda p: -p[1])[:5]
            pairs.append((f"{post.probabilities.size - 5} others", 1 - sum(p for _, p in pairs)))
        ax.barh(range(len(pairs)), [p for _, p in pairs], color="#4878a8", height=0.7)
        ax.set_yticks(range(len(pairs)), [label for label, _ in pairs], fontsize=6)
        ax.invert_yaxis()
        ax.set_xlim(0, 1)
        ax.set_xticks([])
        for i, (_, p) in enumerate(pairs):
            ax.text(min(p, 0.62) + 0.02, i, f"{p:.2f}", va="center", fontsize=6)
        for side in ("top", "right", "bottom"):
            ax.spines[side].set_visible(False)
    return draw


def _value_panel(text: str) -> Any:
    def draw(ax: Any) -> None:
        ax.text(0.5, 0.5, text, ha="center", va="center", fontsize=7)
        ax.axis("off")
    return draw


rich.register("program", program_html)
rich.register("posterior", posterior_html)
rich.register("map", map_html)
