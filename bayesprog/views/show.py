"""Text rendering: a program in Bayesian-programming notation, and answers as tables."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from bayesprog.forms import FormulaParam, InputRef, ParamValue
from bayesprog.inference import MapResult, Posterior
from bayesprog.inference.density import Density
from bayesprog.inference.event import Probability
from bayesprog.inference.mixed import Joint
from bayesprog.model import Term
from bayesprog.program import Program
from bayesprog.vocabulary.variables import Continuous, Discrete, Variable


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def _domain(var: Variable) -> str:
    if isinstance(var, Discrete):
        if var.kind == "grid":
            shape = " x ".join(map(str, var.grid_shape or ()))
            return f"grid {shape} cells of {_fmt(var.cell or 1)} ({var.card} states)"
        if var.kind == "range":
            return f"{{{var.states[0]}, ..., {var.states[-1]}}} ({var.card} states)"
        return "{" + ", ".join(var.states) + "}"
    assert isinstance(var, Continuous)
    if np.isfinite(var.low) or np.isfinite(var.high):
        support = f"[{_fmt(var.low)}, {_fmt(var.high)}]"
    else:
        support = "R"
    if var.index is None:
        return f"real in {support}"
    return f"field over {var.index}: one real in {support} per state"


def _param(program: Program, value: ParamValue | InputRef | FormulaParam) -> str:
    if isinstance(value, InputRef):
        decl = program.inputs[value.name]
        return f"input {value.name} {list(decl.axes) + list(decl.event)}"
    if isinstance(value, FormulaParam):
        if len(value.axes) == 1:
            states = program.variables[value.axes[0]].states  # type: ignore[union-attr]
            return "{" + ", ".join(f"{s}: \"{f}\"" for s, f in zip(states, value.formulas,
                                                                strict=True)) + "}"
        return str(value)
    arr = np.asarray(value.array)
    if not value.axes:
        if arr.ndim == 1 and arr.size > 8:
            return "below"
        return _fmt(float(arr)) if arr.ndim == 0 else _array(arr)
    if len(value.axes) == 1 and arr.ndim <= 2 and arr.shape[0] <= 12 and arr[0].size <= 8:
        states = program.variables[value.axes[0]].states  # type: ignore[union-attr]
        body = ", ".join(f"{s}: {_array(v) if np.ndim(v) else _fmt(float(v))}"
                         for s, v in zip(states, arr, strict=False))
        return "{" + body + "}"
    return "below"  # a table of the parents' states (in the term's order) by values


#: The most rows and value columns a table printed under its term shows (a screen's worth).
TABLE_ROWS, TABLE_COLUMNS = 24, 12


def _grids(program: Program, term: Term) -> list[str]:
    """The parameters shown as ``below``: a table of the states of the variables the
    parameter varies over (rows) by its values (columns: the states of the term's variable for
    a table), elided beyond a screen and saying so."""
    if term.form.subprogram:
        return []  # what it passes to the sub-question, shown by that question
    out = []
    for name, value in term.params.items():
        if not isinstance(value, ParamValue) or value.batched:
            continue
        if not value.axes:
            if _param(program, value) == "below":
                out += _listing(term, name, np.asarray(value.array, dtype=float))
            continue
        if _param(program, value) != "below":
            continue
        # rows in the order of the term's parents, as program.table gives them
        axes = tuple(p.name for p in term.parents if p.name in value.axes)
        if set(axes) != set(value.axes):
            axes = value.axes
        lead = len(axes)
        arr = np.asarray(value.array, dtype=float).transpose(
            [value.axes.index(a) for a in axes] + list(range(lead, np.ndim(value.array))))
        rows = arr.reshape(int(np.prod(arr.shape[:lead])), -1)
        child = term.child
        if arr.ndim == lead:
            headers = [name]
        elif (arr.ndim == lead + 1 and isinstance(child, Discrete)
              and any(p.name == name and p.keyed_by_child_states for p in term.form.params)
              and arr.shape[-1] == child.card):
            headers = list(child.states)
        else:
            headers = [str(i) for i in np.ndindex(*arr.shape[lead:])]
        states = [program.variables[a].states for a in axes]  # type: ignore[union-attr]
        labels = [[str(s) for s in combo] for combo in itertools.product(*states)]
        shown_rows = rows.shape[0] if rows.shape[0] <= TABLE_ROWS else TABLE_ROWS - 4
        shown_cols = len(headers) if len(headers) <= TABLE_COLUMNS else TABLE_COLUMNS - 2
        cells = [[_fmt(float(x)) for x in row[:shown_cols]] for row in rows[:shown_rows]]
        head = list(axes) + headers[:shown_cols]
        body = [label + row for label, row in zip(labels, cells, strict=False)]
        widths = [max(len(r[i]) for r in [head, *body]) for i in range(len(head))]
        more = "  ..." if shown_cols < len(headers) else ""

        def line(row: list[str], widths: list[int] = widths, lead: int = lead,
                 more: str = more) -> str:
            keys = "  ".join(f"{c:<{w}}" for c, w in zip(row[:lead], widths, strict=False))
            vals = "  ".join(f"{c:>{w}}" for c, w in zip(row[lead:], widths[lead:],
                                                           strict=False))
            return f"          {keys}  | {vals}{more}"

        title = f"        {name} of {term.expression}" if len(term.params) > 1 else ""
        out += ([title] if title else []) + [line(head)] + [line(r) for r in body]
        hidden_rows, hidden_cols = rows.shape[0] - shown_rows, len(headers) - shown_cols
        if hidden_rows or hidden_cols:
            what = " and ".join(x for x in (
                f"{hidden_rows:,} more rows" if hidden_rows else "",
                f"{hidden_cols:,} more columns" if hidden_cols else "") if x)
            out.append(f"          ... {what} (all of them in Python: "
                       f"program.table(\"{term.expression}\"))")
    return out


def _listing(term: Term, name: str, values: np.ndarray) -> list[str]:
    """A long vector without parents, one value per line (the states of the term's variable
    beside a table's probabilities), elided beyond a screen and saying so."""
    child = term.child
    labels = (list(child.states) if isinstance(child, Discrete) and values.size == child.card
              else [str(i) for i in range(values.size)])
    shown = values.size if values.size <= TABLE_ROWS else TABLE_ROWS - 4
    width = max(len(x) for x in labels[:shown] + [child.name])
    keyed = any(p.name == name and p.keyed_by_child_states for p in term.form.params)
    out = [f"        {name} of {term.expression}" if len(term.params) > 1 else "",
           f"          {child.name:<{width}}  | {'probability' if keyed else name}"]
    out += [f"          {label:<{width}}  | {_fmt(float(v))}"
            for label, v in zip(labels[:shown], values[:shown], strict=True)]
    if shown < values.size:
        out.append(f"          ... {values.size - shown:,} more rows (all of them in Python: "
                   f"program.table(\"{term.expression}\"))")
    return [line for line in out if line]


def _array(arr: np.ndarray) -> str:
    flat = np.asarray(arr).ravel()
    if flat.size > 8:
        return f"[{', '.join(_fmt(x) for x in flat[:6])}, ... ({flat.size} values)]"
    formatter: Any = {"float_kind": _fmt}
    text = np.array2string(np.asarray(arr), separator=", ", formatter=formatter)
    return text.replace("\n", "")


def _form(program: Program, term: Term) -> str:
    if str(term.expression) in program.ablated:
        return "Uniform  (ablated)"
    if term.form.subprogram:
        return f"Program {term.extra['source']}: {term.extra['question']}"
    params = ", ".join(f"{k} = {_param(program, v)}" for k, v in term.params.items())
    name = term.form.display_name
    return f"{name}({params})" if params else name


def render(program: Program) -> str:
    """The program as ProBT-style text: variables, decomposition, forms, questions."""
    lines = [f"Program {program.name}" + (f"  ({program.path})" if program.path else "")]
    if program.description:
        lines += ["  " + program.description.strip().replace("\n", "\n  ")]
    lines += ["  Specification", "    Variables"]
    width = max(len(n) for n in program.variables)
    for name, var in program.variables.items():
        note = f"  -- {var.description}" if var.description else ""
        if name in program.conditioning:
            note = "  (no term: every question gives it)" + note
        lines.append(f"      {name:<{width}} : {_domain(var)}{note}")
    if program.inputs:
        lines.append("    Runtime inputs")
        for name, decl in program.inputs.items():
            note = f"  -- {decl.description}" if decl.description else ""
            lines.append(f"      {name} : shape {list(decl.axes) + list(decl.event)}{note}")
    if program.time is not None:
        earlier = ", ".join(f"{previous} is {state}" for previous, state in program.time)
        lines.append(f"    Time: one step of a sequence; {earlier} one step earlier")
    terms = [t for t in program.terms if not t.soft]
    given = program.conditioning  # no term: the program is conditioned on them
    joint = " ".join(n for n in program.variables if n not in given)
    if given:
        joint += " | " + ", ".join(given)
    lines += ["    Decomposition",
              f"      P({joint}) = " + " ".join(str(t.expression) for t in terms)]
    lines.append("    Parametric forms")
    for t in terms:
        lines.append(f"      {t.expression} = {_form(program, t)}")
        if str(t.expression) not in program.ablated:
            lines += _grids(program, t)
    soft = [t for t in program.terms if t.soft]
    if soft:
        lines.append("    Soft evidence (likelihoods multiplied in)")
        for t in soft:
            lines.append(f"      on {t.child.name}: {_form(program, t)}")
    lines.append("  Questions")
    if not program.questions:
        lines.append("      (none named; any P(searched | known) can be asked)")
    for name, q in program.questions.items():
        note = f"  -- {q.description}" if q.description else ""
        lines.append(f"      {name}: {q.expression}  [{q.kind}]{note}")
    if program.ablated:
        lines.append("  Ablated: " + ", ".join(program.ablated))
    return "\n".join(lines)


def format_density(result: Density) -> str:
    """Mean, sd, quantiles and MAP of each searched real variable (one block per batch row)."""
    how = {"gaussian": "exact, Gaussian algebra",
           "kalman": "exact, Kalman filter", "kalman-rts": "exact, Rauch-Tung-Striebel",
           "pf": "particle filter: the particles' moments, no error estimate",
           "pf-smooth": "particle smoother (FFBSm): the particles' moments, no error estimate"}
    named = (f"   ({how[result.method]})" if result.method in how
             else _approximate(result) or (f"   ({result.method})" if result.method else ""))
    out = [f"{result.question}" + _ablated(result.ablated) + named]
    summary = result.summary()
    over_time = result.method in ("kalman", "kalman-rts", "pf", "pf-smooth")
    for pos in np.ndindex(*result.batch_shape):
        if over_time:
            rest = f", batch row [{', '.join(map(str, pos[1:]))}]" if pos[1:] else ""
            out.append(f"  step {pos[0] + 1}{rest}")
        elif pos:
            out.append(f"  batch row [{', '.join(map(str, pos))}]")
        for v, s in summary.items():
            def num(x: np.ndarray, stat: str | None = None, v: str = v,
                    pos: tuple[int, ...] = pos) -> str:
                text = f"{float(np.asarray(x)[pos]):.6g}"
                if stat and result.error:
                    text += f" (+- {float(np.asarray(result.error[stat][v])[pos]):.2g})"
                return text
            quantiles = "  ".join(f"{q:g}: {num(x)}" for q, x in s["quantiles"].items())
            out.append(f"  {v}: mean {num(s['mean'], 'mean')}   sd {num(s['sd'], 'sd')}   "
                       f"MAP {num(s['map'], 'map')}")
            out.append(f"     quantiles  {quantiles}"
                       + (f"   (+- {float(np.asarray(result.error['quantiles'][v])[pos]):.2g})"
                          if result.error else ""))
        if result.ess is not None:
            out.append(f"  effective sample size {float(np.asarray(result.ess)[pos]):.0f}")
    return "\n".join(out)


def format_joint(result: Joint) -> str:
    """Per configuration of the discrete variables: its probability, and the mean and sd of
    each real variable given it; then the MAP (one block per batch row when batched)."""
    made = []
    for part, name in ((result.discrete, result.methods.get("discrete", "")),
                       (result.real, result.methods.get("real", ""))):
        method = _method(name)
        if method is not None and not method.exact:
            made.append(f"{', '.join(part)}: {method.title or method.name}")
    approximate = f"; {', '.join(made)}, no error given" if made else ""
    out = [f"{result.question}" + _ablated(result.ablated)
           + f"   (discrete and real together{approximate})"]
    best = result.map()
    means = {v: result.mean(v) for v in result.real}
    sds = {v: result.sd(v) for v in result.real}
    for pos in np.ndindex(*result.batch_shape):
        if pos:
            out.append(f"  batch row [{', '.join(map(str, pos))}]")
        widths = [max(len(v), *(len(n) for n in result.names[v])) for v in result.discrete]
        columns = [f"{v} mean" for v in result.real] + [f"{v} sd" for v in result.real]
        wide = max(12, *(len(c) for c in columns))
        out.append("  " + "  ".join(v.ljust(w) for v, w in zip(result.discrete, widths,
                                                               strict=True))
                   + "  probability  " + "  ".join(c.ljust(wide) for c in columns).rstrip())
        for config in np.ndindex(*result.cards):
            names = "  ".join(result.names[v][i].ljust(w) for v, i, w in
                              zip(result.discrete, config, widths, strict=True))
            key = pos + config
            stats = [f"{float(means[v][key]):.6g}" for v in result.real] + \
                [f"{float(sds[v][key]):.6g}" for v in result.real]
            out.append(f"  {names}  {_fmt(float(result.weights[key])).ljust(11)}  "
                       + "  ".join(x.ljust(wide) for x in stats).rstrip())
        assignment = ", ".join(f"{v}={np.asarray(best[v])[pos]}" if v in result.discrete
                               else f"{v}={float(np.asarray(best[v])[pos]):.6g}"
                               for v in result.variables)
        out.append(f"  MAP: {assignment} (joint density {float(np.asarray(best['density'])[pos]):.6g})")
    return "\n".join(out)


def format_result(result: Posterior | MapResult | Density | Joint | Probability,
                  limit: int = 20) -> str:
    """A readable table (one block per batch row when batched)."""
    if isinstance(result, Probability):
        return format_probability(result, limit)
    if isinstance(result, Joint):
        return format_joint(result)
    if isinstance(result, Density):
        return format_density(result)
    if isinstance(result, MapResult) and result.kind == "sequence":
        return _format_sequence(result)
    if isinstance(result, MapResult):
        rows = np.ndindex(*result.indices.shape[:-1])
        posterior = result.posterior
        out = [f"MAP of {result.question}" + _ablated(result.ablated) + _approximate(posterior)]
        plus = posterior.stderr if posterior.stderr is not None else posterior.error
        for pos in rows:
            at = tuple(int(i) for i in result.indices[pos])
            names = [result.names[v][i] for v, i in zip(result.variables, at, strict=False)]
            label = f"[{', '.join(map(str, pos))}] " if pos else ""
            assignment = ", ".join(f"{v}={s}" for v, s in zip(result.variables, names, strict=False))
            error = f" +- {float(plus[pos + at]):.2g}" if plus is not None else ""
            out.append(f"  {label}{assignment}   p = {_fmt(float(result.probability[pos]))}"
                       f"{error}" + _tied(result.ties[pos]))
        return "\n".join(out)
    out = [f"{result.question}" + _ablated(result.ablated) + _approximate(result)]
    over_time = result.method in ("filter", "smooth")
    for pos in np.ndindex(*result.batch_shape):
        if over_time:
            rest = f", batch row [{', '.join(map(str, pos[1:]))}]" if pos[1:] else ""
            out.append(f"  step {pos[0] + 1}{rest}")
        elif pos:
            out.append(f"  batch row [{', '.join(map(str, pos))}]")
        plus = result.stderr if result.stderr is not None else result.error
        out += _table(result, result.probabilities[pos], limit,
                      plus[pos] if plus is not None else None)
        if result.ess is not None:
            out.append(f"  effective sample size {float(result.ess[pos]):.0f}")
    return "\n".join(out)


def format_probability(result: Probability, limit: int = 20) -> str:
    """The probability of an event (a density where it fixes a real variable), with its
    logarithm; one line per batch row."""
    word = "density" if result.density else "probability"
    out = [result.question + _ablated(result.ablated) + _approximate(result, plus=False)]
    rows = list(np.ndindex(*result.batch_shape))
    for pos in rows[:limit]:
        label = f"[{', '.join(map(str, pos))}] " if pos else ""
        out.append(f"  {label}{word} {_fmt(float(result.probability[pos]))}   (log "
                   f"{_fmt(float(result.log_probability[pos]))})")
    if len(rows) > limit:
        out.append(f"  ... {len(rows) - limit} more rows (--limit)")
    return "\n".join(out)


def _format_sequence(result: MapResult) -> str:
    """The most likely sequence: its state at each step, then its probability (per sequence of
    a batch)."""
    out = [result.question + _ablated(result.ablated) + _approximate(result.posterior)]
    batch = result.probability.shape
    for row in np.ndindex(*batch):
        indent = "  "
        if row:
            out.append(f"  sequence [{', '.join(map(str, row))}]")
            indent = "    "
        for t in range(result.indices.shape[0]):
            at = result.indices[(t,) + row]
            assignment = ", ".join(f"{v}={result.names[v][int(i)]}"
                                   for v, i in zip(result.variables, at, strict=True))
            out.append(f"{indent}step {t + 1}: {assignment}")
        if result.zero_evidence[row]:
            out.append(f"{indent}the evidence has probability zero: no sequence is likelier")
        else:
            out.append(f"{indent}probability of the sequence: "
                       f"{_fmt(float(result.probability[row]))}" + _tied(result.ties[row]))
    return "\n".join(out)


def _tied(ties: Any) -> str:
    """How many assignments (or sequences) share the maximum, when more than one do."""
    return f"   ({int(ties)} tied)" if ties > 1 else ""


def _approximate(result: Any, plus: bool = True) -> str:
    """How an approximate answer was made and what its +- is (nothing for an exact one), as
    its method describes it; ``plus`` False for an answer that shows no +- (an estimate
    alone)."""
    steps = getattr(result, "steps_method", "")
    method = _method(steps or result.method)
    if method is None or method.exact:
        return ""
    title = method.title or method.name
    if steps:
        return f"   (each step by {title}: no error estimate)"
    return f"   ({method.describe(result) if plus else title + ': an estimate, no error given'})"


def _method(name: str) -> Any:
    """The registered inference method called ``name`` (None for the other answers)."""
    if not name:
        return None
    from bayesprog.inference.methods.base import method_named

    return method_named(name)


def _ablated(ablated: tuple[str, ...]) -> str:
    return f"   (ablated: {', '.join(ablated)})" if ablated else ""


def _table(result: Posterior, probs: np.ndarray, limit: int,
           stderr: np.ndarray | None = None) -> list[str]:
    flat = probs.ravel()
    order = np.arange(flat.size)
    note = ""
    if flat.size > limit:
        order = np.argsort(-flat, kind="stable")[:limit]
        note = f"  ... {flat.size - limit} more (the {limit} most probable are shown; --limit N)"
    names = [result.names[v] for v in result.variables]
    cells = []
    for k in order:
        idx = np.unravel_index(k, probs.shape)
        cells.append(([names[i][j] for i, j in enumerate(idx)], flat[k]))
    widths = [max(len(v), *(len(c[0][i]) for c in cells)) for i, v in enumerate(result.variables)]
    header = "  " + "  ".join(f"{v:<{w}}" for v, w in zip(result.variables, widths, strict=False)) + "  probability"
    lines = [header]
    errors = stderr.ravel() if stderr is not None else None
    for (states, p), k in zip(cells, order, strict=True):
        error = f" +- {errors[k]:.2g}" if errors is not None else ""
        lines.append("  " + "  ".join(f"{s:<{w}}" for s, w in zip(states, widths, strict=False))
                     + f"  {p:.6g}{error}")
    if note:
        lines.append(note)
    return lines
