"""Parameters written as formulas of the parents, evaluated for a question's evidence, and the
bins of a discretised variable, which take the probability of their interval from its term.

>>> import bayesprog
>>> p = bayesprog.loads('''
... bayesprog: 1
... variables:
...   Pos: {continuous: [-.inf, .inf]}
...   Reading: {continuous: [-.inf, .inf]}
... decomposition:
...   - {term: P(Pos), form: normal, mean: 0, sigma: 1}
...   - {term: P(Reading | Pos), form: normal, mean: "2*Pos + 1", sigma: 0.5}
... ''')
>>> round(float(p.ask("P(Reading)", method="gaussian").mean("Reading")), 12)
1.0
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from bayesprog.errors import QuestionError
from bayesprog.forms import Form, FormulaParam, ParamValue, TermContext, is_binned
from bayesprog.inference.binding import Bound
from bayesprog.vocabulary.variables import Discrete, Variable


def formula_value(variables: Mapping[str, Variable], param: FormulaParam, bound: Bound,
                  what: str) -> ParamValue:
    """The values of ``param`` for the question's evidence and inputs: over the table's axes
    and the discrete parents the formulas name, with a batch axis when an observed parent or an
    input is batched; probabilities normalised per parent configuration. A name that is not a
    variable is a (scalar) runtime input.
    """
    known = {n: bound.continuous[n] if n in variables else bound.inputs[n]
             for n in param.names if n in bound.continuous or
             (n not in variables and n in bound.inputs)}
    for name in param.names:
        var = variables.get(name)
        if var is None and name not in known:
            raise QuestionError(f"missing input {name!r}, needed by {what}")
        if not isinstance(var, Discrete) and name not in known:
            raise QuestionError(f"{what}: {name} is neither known nor summed out here")
    batched = any(pv.batched for pv in known.values())
    rows = bound.size if batched else 1
    axes, out = param.evaluate(variables, {n: pv.array for n, pv in known.items()}, rows)
    if param.event:
        try:
            out = param.normalised(axes, out, variables)
        except ValueError as exc:
            raise QuestionError(f"{what}: {exc}") from None
    return ParamValue(axes, out if batched else out[0], batched)


def log_factor(form: Form, ctx: TermContext) -> np.ndarray:
    """The term's log values: the form's own, or for a discretised child of a density, the
    probability of each bin (:func:`bins_log_factor`)."""
    if is_binned(ctx.child) and "continuous" in form.child_kinds:
        return np.asarray(bins_log_factor(form, ctx), dtype=float)
    return np.asarray(form.log_factor(ctx), dtype=float)


def bins_log_factor(form: Form, ctx: TermContext) -> np.ndarray:
    """The log-probability of each bin of a discretised child: its term's CDF at the bin's
    upper edge minus at its lower edge; the outer bins also take the tails."""
    child = ctx.child
    assert isinstance(child, Discrete) and child.edges is not None
    edges = child.edges.copy()
    edges[0], edges[-1] = -np.inf, np.inf
    parts = []
    for bound in (edges[1:], edges[:-1]):
        ctx.value = ParamValue((child.name,), bound)
        cdf = form.cdf(ctx)
        if cdf is None:
            raise ValueError(f"form {form.name!r} cannot give the bins of {child.name} their "
                             "probability (it has no CDF here)")
        parts.append(np.asarray(cdf, float))
    with np.errstate(divide="ignore"):
        return np.log(np.clip(parts[0] - parts[1], 0.0, None))
