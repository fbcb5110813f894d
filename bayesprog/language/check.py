"""Whole-program checking: from a located, schema-valid document to checked program parts.

Every problem of a file is collected (with its line and column) before anything is raised, so a
user sees all of them at once.
"""

from __future__ import annotations

import graphlib
import math
import re
from collections.abc import Callable, Collection
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bayesprog.errors import Diagnostic, did_you_mean, short_repr
from bayesprog.forms import (
    Form,
    FormulaParam,
    InputRef,
    Param,
    ParamValue,
    available_forms,
    get_form,
    unknown_form,
)
from bayesprog.forms.base import nonnegative, real
from bayesprog.forms.standard import deterministic_problem
from bayesprog.language.loader import Located
from bayesprog.language.loader import Path as YPath
from bayesprog.limits import limit
from bayesprog.model import InputDecl, LearnOptions, Term
from bayesprog.vocabulary.expressions import Expression, ExpressionError, parse_expression
from bayesprog.vocabulary.formula import Formula, FormulaError, parse_formula
from bayesprog.vocabulary.variables import (
    Continuous,
    Discrete,
    Variable,
    binned_variable,
    grid_variable,
)

if TYPE_CHECKING:  # (pydantic's models are built only for a file the plain reader leaves)
    from bayesprog.language.document import Document, InputSpec, LearnSpec
    from bayesprog.language.plain import PlainDocument, PlainInput, PlainLearn

#: The most discrete variables a term may have: its table has one axis per variable and one
#: for a batch of evidence, and numpy's einsum takes arrays of at most 32 axes.
MAX_TERM_VARIABLES = 31


@dataclass
class Checked:
    variables: dict[str, Variable]
    inputs: dict[str, InputDecl]
    terms: list[Term]
    questions: dict[str, tuple[Expression, str, str]]
    ablate: list[Expression]
    problems: list[Diagnostic]
    #: the (previous, state) pairs of a program that repeats per time step, else None
    time: tuple[tuple[str, str], ...] | None = None


def build_variable(name: str, spec: Any) -> Variable:
    if spec.states is not None:
        states = tuple(spec.states)
        # states named by integers (1, 2, 3): an integer in evidence or data is a name, not
        # an index, as for a range
        numbers = [int(s) for s in states if re.fullmatch(r"-?[0-9]+", s) and str(int(s)) == s]
        values = np.array(numbers) if len(numbers) == len(states) else None
        return Discrete(name, states, values=values, description=spec.description)
    if spec.range is not None:
        low, high = spec.range
        values = np.arange(low, high + 1)
        return Discrete(
            name, tuple(str(v) for v in values), values=values, description=spec.description,
            kind="range",
        )
    if spec.grid is not None:
        g = spec.grid
        return grid_variable(name, tuple(g.shape), g.cell, g.origin, spec.description)
    low, high = spec.continuous
    if spec.discretise is not None:
        return binned_variable(name, np.asarray(spec.discretise.edges(spec.continuous)),
                               (low, high), spec.description)
    return Continuous(name, float(low), float(high), spec.indexed_by, spec.description)


class _Checker:
    def __init__(self, located: Located, doc: Document | PlainDocument, base_dir: Path,
                 load_program: Callable[..., Any] | None = None):
        self.located = located
        #: pydantic's Document or the plain reader's: the same attributes, unrelated types
        self.doc: Any = doc
        self.base_dir = base_dir
        #: loads another program file (for ``program`` terms), with the names of the variables
        #: it shares with the term; given by the program layer
        self.load_program = load_program
        self.problems: list[Diagnostic] = []
        self.variables: dict[str, Variable] = {}
        self.inputs: dict[str, InputDecl] = {}
        #: the variables without a term (not one that failed to be read), and those of them
        #: that condition a term: every question gives them
        self.untermed: list[str] = []
        self.conditioning: tuple[str, ...] = ()

    def error(self, path: YPath, message: str, at_key: bool = False) -> None:
        self.problems.append(self.located.diagnostic(path, message, at_key=at_key))

    # variables and inputs -------------------------------------------------------------------
    def check_variables(self) -> None:
        for name, spec in self.doc.variables.items():
            self.variables[name] = build_variable(name, spec)
        for name, var in self.variables.items():
            if isinstance(var, Continuous) and var.index is not None:
                index = self.variables.get(var.index)
                if index is None or not index.is_discrete:
                    self.error(
                        ("variables", name, "indexed_by"),
                        f"variable {name!r} is indexed_by {var.index!r}: expected a declared "
                        f"discrete variable, found {'nothing' if index is None else 'a continuous one'}",
                    )

    def check_inputs(self) -> None:
        for name, spec in self.doc.inputs.items():
            self.inputs[name] = self.input_decl(name, spec)

    def input_decl(self, name: str, spec: InputSpec | PlainInput) -> InputDecl:
        axes: list[str] = []
        event: list[int | str] = []
        for i, dim in enumerate(spec.shape):
            if isinstance(dim, str) and dim in self.variables:
                if not self.variables[dim].is_discrete:
                    self.error(
                        ("inputs", name, "shape", i),
                        f"input {name!r}: dimension {dim!r} names a continuous variable; "
                        "expected a discrete variable, an integer or a free symbol",
                    )
                elif event:
                    self.error(
                        ("inputs", name, "shape", i),
                        f"input {name!r}: variable dimensions must come first, "
                        f"found {dim!r} after {event}",
                    )
                else:
                    axes.append(dim)
            elif isinstance(dim, int) and dim < 1:
                self.error(("inputs", name, "shape", i), f"expected a size >= 1, found {dim}")
            else:
                event.append(dim)
        return InputDecl(name, tuple(axes), tuple(event), spec.description)

    # terms ------------------------------------------------------------------------------------
    def check_terms(self) -> list[Term]:
        terms: list[Term] = []
        defined: dict[str, int] = {}
        for i, spec in enumerate(self.doc.decomposition):
            path: YPath = ("decomposition", i)
            name = _child_of(spec.term)
            if name in self.variables:
                if name in defined:
                    self.error(
                        path + ("term",),
                        f"variable {name!r} has a second term {spec.term}: expected one term "
                        f"per variable, found one already at decomposition[{defined[name]}]",
                    )
                    continue
                defined[name] = i
            term = self.check_term(path + ("term",), spec.term, spec.form, spec.parameters, path)
            if term is not None:
                term.description = spec.description
                term.learn = self.learn_options(term, spec.learn, path + ("learn",))
                terms.append(term)
        missing = [n for n in self.variables if n not in defined]
        failed_children = self._failed_children()
        # a variable without a term that conditions one (a control, a known input) is given by
        # every question; one that conditions nothing is a term forgotten (and a state over
        # time without a term is refused by check_time)
        parents = self._named_parents()
        over_time = self._time_names()
        self.untermed = [n for n in missing if n not in failed_children]
        self.conditioning = tuple(n for n in self.untermed if n in parents and n not in over_time)
        for name in self.untermed:
            if name not in parents and name not in over_time:
                self.error(
                    ("variables", name),
                    f"variable {name!r} has no term in the decomposition: expected one "
                    f"P({name} | ...), or {name} as a parent of a term (a variable that "
                    "every question gives)",
                )
        for i, soft in enumerate(self.doc.soft_evidence):
            path = ("soft_evidence", i)
            term = self.check_term(path + ("variable",), f"P({soft.variable})", soft.form,
                                   soft.parameters, path)
            if term is not None:
                if term.child.name in self.conditioning:
                    self.error(path + ("variable",), f"soft evidence on {soft.variable}: it "
                               "has no term in the decomposition, so every question gives its "
                               "value; expected soft evidence on a variable with a term")
                    continue
                if not term.child.is_discrete:
                    self.error(path + ("variable",), f"soft evidence needs a discrete "
                               f"variable, found continuous {soft.variable!r}")
                    continue
                if not term.form.soft_evidence:
                    takes = " or ".join(repr(n) for n in available_forms()
                                        if _form_named(n).soft_evidence)
                    self.error(path + ("form",), f"soft evidence takes form {takes}, found "
                               f"{term.form.name!r}")
                    continue
                term.soft = True
                term.description = soft.description
                terms.append(term)
        self.check_cycles(terms)
        return terms

    def learn_options(self, term: Term, spec: bool | LearnSpec | PlainLearn,
                      path: YPath) -> LearnOptions | None:
        """The term's ``learn:`` entry, checked against its form."""
        if spec is False:
            return None
        if spec is True:
            return LearnOptions()
        form, what = term.form.name, f"term {term.label}: learn"
        estimator = term.form.estimator(term.child)
        takes = estimator.options if estimator is not None else frozenset()
        pseudo = None
        if spec.pseudo_counts is not None:
            if "pseudo_counts" not in takes:
                self.error(path + ("pseudo_counts",), f"{what}: pseudo_counts are for forms "
                           f"{_forms_taking('pseudo_counts')}, found form {form!r}",
                           at_key=True)
            elif isinstance(spec.pseudo_counts, (int, float)) and not isinstance(
                    spec.pseudo_counts, bool):
                if not np.isfinite(spec.pseudo_counts) or spec.pseudo_counts < 0:
                    self.error(path + ("pseudo_counts",), f"{what}: pseudo_counts must be a "
                               f"finite number >= 0, found {spec.pseudo_counts}")
                else:
                    pseudo = ParamValue((), np.asarray(float(spec.pseudo_counts)))
            else:
                param = Param("pseudo_counts", nonnegative, event_ndim=1,
                              keyed_by_child_states=True)
                shape = term.form.event_shape(term.form.params[0], term.child)
                lit = _LiteralSpec(param, term.child, 1, shape, f"{what} pseudo_counts")
                try:
                    pseudo = ParamValue(*self._literal(spec.pseudo_counts, lit,
                                                       term.form.keyable(term.child, term.parents),
                                                       path + ("pseudo_counts",)))
                except _LiteralError as exc:
                    self.error(exc.path, exc.message)
        components: tuple[int, ...] = ()
        if spec.components is not None:
            components = ((spec.components,) if isinstance(spec.components, int)
                          else tuple(spec.components))
            if "components" not in takes:
                self.error(path + ("components",), f"{what}: components are for form "
                           f"{_forms_taking('components')} over a continuous variable, found "
                           f"form {form!r}", at_key=True)
            elif not components or min(components) < 1:
                self.error(path + ("components",), f"{what}: expected numbers of components "
                           f">= 1, found {list(components)}")
        names = [p.name for p in term.form.params]
        if spec.shared and "shared" not in takes:
            self.error(path + ("shared",), f"{what}: shared is for forms "
                       f"{_forms_taking('shared')}, found form {form!r}", at_key=True)
            return LearnOptions(pseudo, components, ())
        for name in spec.shared:
            if name not in names:
                self.error(path + ("shared",), f"{what}: shared names {name!r}, expected "
                           f"parameters of form {form!r} ({', '.join(names) or 'none'})")
        return LearnOptions(pseudo, components, tuple(spec.shared))

    def _named_parents(self) -> set[str]:
        """Variables named as parents in a term, even in a term whose form is wrong."""
        names: set[str] = set()
        for spec in self.doc.decomposition:
            try:
                names.update(parse_expression(spec.term).right)
            except ExpressionError:
                pass
        return names

    def _time_names(self) -> set[str]:
        """The states over time and their copies one step earlier, as the time section names
        them."""
        spec = self.doc.time
        return set() if spec is None else {n for pair in spec.previous.items() for n in pair}

    def _failed_children(self) -> set[str]:
        """Variables named first in a term, even in a term too broken to parse."""
        names: set[str] = set()
        for spec in self.doc.decomposition:
            try:
                names.update(parse_expression(spec.term).left)
            except ExpressionError:
                match = re.match(r"\s*P\s*\(\s*([A-Za-z_][A-Za-z0-9_.\-]*)", spec.term)
                if match:
                    names.add(match.group(1))
        return names

    def check_term(
        self, tpath: YPath, text: str, form_name: str, raw: dict[str, Any], path: YPath
    ) -> Term | None:
        try:
            expr = parse_expression(text)
        except ExpressionError as exc:
            hint = ""
            if text.count("(") != text.count(")"):
                hint = " (inside a flow mapping {...}, quote a term that contains a comma)"
            self.error(tpath, f"term: {exc}{hint}")
            return None
        ok = True
        if len(expr.left) != 1:
            self.error(tpath, f"term {expr}: expected one variable before '|', "
                       f"found {len(expr.left)} ({' '.join(expr.left)})")
            ok = False
        if expr.values:
            self.error(tpath, f"term {expr}: expected parents without values, found "
                       + ", ".join(f"{k}={v}" for k, v in expr.values.items()))
            ok = False
        for name in expr.left + expr.right:
            if name not in self.variables:
                self.error(tpath, f"term {expr}: undeclared variable {name!r}"
                           f"{did_you_mean(name, self.variables)} (declared: "
                           f"{', '.join(self.variables)})")
                ok = False
        form = get_form(form_name)
        if form is None:
            self.error(path + ("form",), unknown_form(form_name))
            ok = False
        if not ok or form is None:
            return None
        child = self.variables[expr.left[0]]
        parents = tuple(self.variables[n] for n in expr.right)
        for message in form.check(child, parents):
            self.error(path + ("form",), f"term {expr}: {message}")
            ok = False
        for parent in parents:
            if isinstance(parent, Continuous) and parent.index is not None:
                self.error(tpath, f"term {expr}: parent {parent.name!r} is a field (one value "
                           f"per state of {parent.index}); expected a discrete or a real parent")
                ok = False
        if isinstance(child, Continuous) and child.index is not None and child.index not in expr.right:
            self.error(tpath, f"term {expr}: {child.name!r} is a field indexed by "
                       f"{child.index!r}, so its term must condition on {child.index!r}")
            ok = False
        if ok:
            ok = self.check_term_size(tpath, expr, child, parents)
        if not ok:
            return None
        term = Term(expr, child, parents, form, {}, (self.located.file, *self.located.where(tpath)))
        resolve = getattr(form, "resolve", None)
        if resolve is not None:
            problems = resolve(term, raw, self, path)
        else:
            problems = self.resolve_params(term, raw, path)
        if not problems:
            used = {n for v in term.params.values() if isinstance(v, FormulaParam)
                    for n in v.names}
            for parent in parents:
                if not parent.is_discrete and parent.name not in used:
                    hint = ("; a discrete child of a real variable needs it discretised "
                            "(discretise: {bins: ...})" if child.is_discrete else "")
                    self.error(tpath, f"term {expr}: parent {parent.name!r} is real-valued; "
                               f"expected a parameter that uses it, as a formula (for instance "
                               f"mean: \"2*{parent.name} + 1\"){hint}")
                    problems += 1
        return None if problems else term

    def check_term_size(self, tpath: YPath, expr: Expression, child: Variable,
                        parents: tuple[Variable, ...]) -> bool:
        """A term's table (one axis per discrete variable) fits: no more axes than numpy's
        arrays take beside a batch axis, no more entries than the limit. Counted before
        anything is allocated."""
        axes = [v for v in (child, *parents) if isinstance(v, Discrete)]
        if len(axes) > MAX_TERM_VARIABLES:
            self.error(tpath, f"term {expr}: its table would have one axis per discrete "
                       f"variable, {len(axes)}; expected at most {MAX_TERM_VARIABLES} (numpy's "
                       "arrays take 32 axes, one of them for a batch): split the term, or "
                       "group parents into one variable")
            return False
        entries = math.prod(v.card for v in axes)
        cap = limit("entries")
        if entries > cap:
            shown = f"{entries:,}" if entries < 10**18 else f"{float(entries):.3g}"
            sizes = (" x ".join(str(v.card) for v in axes) if len(axes) <= 6 else
                     f"{len(axes)} variables of {min(v.card for v in axes)} to "
                     f"{max(v.card for v in axes)} states")
            self.error(tpath, f"term {expr}: its table needs {shown} entries ({sizes}), "
                       f"more than the limit of "
                       f"{cap:,} (raise it with the environment variable "
                       "BAYESPROG_MAX_ENTRIES)")
            return False
        return True

    def resolve_params(self, term: Term, raw: dict[str, Any], path: YPath) -> int:
        form = term.form
        declared = {p.name: p for p in form.params}
        before = len(self.problems)
        for key in raw:
            if key not in declared:
                expected = ", ".join(declared) or "no parameters"
                self.error(path + (key,), f"term {term.label}: unknown parameter {key!r} for "
                           f"form {form.name!r}: expected {expected}", at_key=True)
        for param in form.params:
            if param.name not in raw:
                if param.required:
                    self.error(path, f"term {term.label}: form {form.name!r} needs parameter "
                               f"{param.name!r} ({param.doc or param.constraint})")
                elif not isinstance(param.default, str):
                    term.params[param.name] = ParamValue((), np.asarray(param.default, float))
                continue
            value = self.param_value(term, param, raw[param.name], path + (param.name,))
            if value is not None:
                term.params[param.name] = value
        if len(self.problems) == before:
            for name, message in form.check_params(term.params, term.child):
                self.error(path + (name,), f"term {term.label}: {message}")
        return len(self.problems) - before

    # parameter values ---------------------------------------------------------------------------
    def param_value(
        self, term: Term, param: Param, raw: Any, path: YPath
    ) -> ParamValue | InputRef | FormulaParam | None:
        form, child = term.form, term.child
        event_ndim = form.event_ndim(param, child)
        keyable = form.keyable(child, term.parents)
        what = f"term {term.label}: {form.name} parameter {param.name!r}"
        if isinstance(raw, dict) and set(raw) == {"input"}:
            return self.input_ref(term, param, raw["input"], path, event_ndim, keyable, what)
        if _has_text(raw) and event_ndim == 0:
            return self.formula_param(term, param, raw, path, keyable, what)
        if (_has_text(raw) and event_ndim == 1 and param.keyed_by_child_states
                and isinstance(child, Discrete)):
            return self.formula_param(term, param, raw, path, keyable, what, event=True)
        spec = _LiteralSpec(param, child, event_ndim, form.event_shape(param, child), what)
        try:
            axes, array = self._literal(raw, spec, keyable, path)
        except _LiteralError as exc:
            self.error(exc.path, exc.message)
            return None
        return ParamValue(axes, array)

    def formula_param(self, term: Term, param: Param, raw: Any, path: YPath, keyable: list,
                      what: str, event: bool = False) -> FormulaParam | ParamValue | None:
        """A parameter given as formulas of the parents and the runtime inputs
        (``mean: "gain*X + 1"``), possibly one per state of discrete parents
        (``mean: {a: "X", b: "-X"}``); numbers are formulas too. With ``event``, the child's
        probabilities: one formula per child state (a list, or a mapping by the child's
        states), or for a two-state child one formula, the probability of its second state;
        normalised per parent configuration."""
        formulas: list[Formula] = []
        child = term.child
        parents = {p.name: p for p in term.parents}
        inputs = {n: d for n, d in self.inputs.items() if n not in parents}
        own = [child.name] if event else []  # a formula may name the child: its weights
        named = {v.name: v.states for v in (*parents.values(), *([child] if event else []))
                 if isinstance(v, Discrete) and v.values is None and v.kind == "states"}
        failed = False

        def located(where: YPath, value: Any, exc: FormulaError) -> None:
            # at the offending character of the formula, inside its string
            line, column = self.located.where(where)
            if isinstance(value, str) and "\\" not in value:
                column += exc.offset + (1 if tuple(where) in self.located.quoted else 0)
            self.problems.append(Diagnostic(self.located.file, line, column, f"{what}: {exc}"))

        def leaf(value: Any, where: YPath) -> Any:
            nonlocal failed
            if isinstance(value, dict):
                return {k: leaf(v, where + (k,)) for k, v in value.items()}
            if isinstance(value, list):
                return [leaf(v, where + (i,)) for i, v in enumerate(value)]
            if isinstance(value, bool) or not isinstance(value, (str, int, float)):
                self.error(where, f"{what}: expected a number or a formula, found "
                           f"{short_repr(value)}")
                failed = True
                return 0.0
            try:
                formula = parse_formula(str(value), names=list(parents) + list(inputs) + own)
                formula = formula.with_states({n: named[n] for n in formula.names if n in named})
            except FormulaError as exc:
                located(where, value, exc)
                failed = True
                return 0.0
            for name in formula.names:
                if name in own:
                    continue
                if name in inputs:
                    if inputs[name].ndim:
                        self.error(where, f"{what}: formula {str(value)!r} uses the input "
                                   f"{name}, which has a shape; a formula takes scalar inputs "
                                   f"(declared as {name}: {{}})")
                        failed = True
                    continue
                var = parents[name]
                if isinstance(var, Discrete) and var.kind == "grid":
                    self.error(where, f"{what}: formula {str(value)!r} uses the grid {name}, "
                               f"whose states are cells; expected real parents, integer "
                               f"ranges, named states or discretised variables (key a table "
                               f"by {name}'s states instead)")
                    failed = True
            if formula.is_constant and not failed and not event:
                number = np.asarray(formula.evaluate({}), float)
                if not param.constraint.ok(number):
                    self.error(where, f"{what} must be {param.constraint}, got "
                               f"{float(number):g}")
                    failed = True
            formulas.append(formula)
            return float(len(formulas) - 1)

        indices: Any = leaf(raw, path)
        if failed:
            return None
        weights = event and any(child.name in f.names for f in formulas)
        written = ""
        if event and not weights and isinstance(raw, str):
            if child.card != 2:  # type: ignore[union-attr]
                self.error(path, f"{what}: one formula that does not name {child.name} is the "
                           f"probability of the second of two states, but {child.name} has "
                           f"{child.card}: name {child.name} in the formula (the weight of "  # type: ignore[union-attr]
                           "each of its states) or give one formula per state")
                return None
            # one formula for a two-state child: its second state's probability
            first = parse_formula(f"1 - ({raw})", names=list(parents) + list(inputs))
            formulas.append(first.with_states({n: named[n] for n in first.names if n in named}))
            indices = [1.0, 0.0]
            written = raw
        if (event and isinstance(indices, dict) and isinstance(child, Discrete)
                and {str(k) for k in indices} == set(child.states)):
            by_state = {str(k): v for k, v in indices.items()}  # one row by the child's states
            indices = [by_state[state] for state in child.states]
        spec = (_LiteralSpec(Param(param.name, real, event_ndim=1, keyed_by_child_states=True),
                             child, 1, (child.card,), what)  # type: ignore[union-attr]
                if event and not weights
                else _LiteralSpec(Param(param.name, real), child, 0, None, what))
        try:
            axes, array = self._literal(indices, spec, keyable, path)
        except _LiteralError as exc:
            self.error(exc.path, exc.message)
            return None
        table = np.empty(array.shape, dtype=object)
        for index in np.ndindex(*array.shape):
            table[index] = formulas[int(array[index])]
        found = FormulaParam(axes, table, event=event, child=child.name if weights else None,
                             written=written)
        if any(n in inputs or not parents[n].is_discrete for n in found.names):
            return found  # evaluated with each question's evidence and inputs
        # of discrete parents only: checked once, on every configuration of the parents
        variables = {p.name: p for p in (*term.parents, child)}
        every, values = found.evaluate(variables, {}, 1)
        if event:
            try:
                values = found.normalised(every, values, variables)
            except ValueError as exc:
                self.error(path, f"{what}: {exc}")
                return None
        elif term.form.deterministic and isinstance(child, Discrete):
            problem = deterministic_problem(child, every, values[0], variables)
            if problem:
                self.error(path, f"{what}: {problem}")
                return None
        if all(f.is_constant for f in formulas) and not weights:  # numbers, written as text
            return ParamValue(every, values[0])
        return found

    def input_ref(self, term: Term, param: Param, name: Any, path: YPath, event_ndim: int,
                  keyable: list, what: str) -> InputRef | None:
        decl = self.inputs.get(name) if isinstance(name, str) else None
        if decl is None:
            self.error(path, f"{what}: unknown input {name!r} (declared inputs: "
                       f"{', '.join(self.inputs) or 'none'})")
            return None
        allowed = {v.name for v in keyable}
        bad = [a for a in decl.axes if a not in allowed]
        if bad:
            self.error(path, f"{what}: input {name!r} varies over {bad[0]!r}, expected only "
                       f"variables of the term ({', '.join(sorted(allowed)) or 'none'})")
            return None
        if len(decl.event) != event_ndim:
            self.error(path, f"{what}: expected an input with {event_ndim} dimension(s) after "
                       f"its variable axes, input {name!r} declares {len(decl.event)}")
            return None
        return InputRef(name)

    def _literal(self, raw: Any, spec: _LiteralSpec, keyable: list,
                 path: YPath) -> tuple[tuple[str, ...], np.ndarray]:
        """(axes, array) of a literal parameter; every row is checked where it is written."""
        child, what = spec.child, spec.what
        if isinstance(raw, dict):
            named = _named_keys(raw, child, keyable, path, what)
            if named is not None:  # keys that name their variable: {Choice=1: ...}
                var, rows = named
                if var is child:
                    if not (spec.param.keyed_by_child_states and isinstance(child, Discrete)
                            and spec.event_ndim == 1):
                        raise _LiteralError(path, f"{what}: a row keyed by the states of "
                                            f"{child.name} is not taken here")
                    return self._child_row({k: v for k, (_, v) in rows.items()}, spec, keyable,
                                           path)
                return self._keyed_by(var, rows, spec, keyable, path)
            keys = {str(k) for k in raw}
            if (
                spec.param.keyed_by_child_states
                and isinstance(child, Discrete)
                and spec.event_ndim == 1
                and keys <= set(child.states)
                and not any(keys <= set(v.states) for v in keyable)
            ):
                return self._child_row({str(k): v for k, v in raw.items()}, spec, keyable, path)
            matches = [v for v in keyable if keys <= set(v.states)]
            if not matches:
                names = ", ".join(v.name for v in keyable) or "none"
                raise _LiteralError(path, f"{what}: expected a table keyed by the states of "
                                    f"one of ({names}), found keys {sorted(keys)}")
            exact = [v for v in matches if keys == set(v.states)]
            if len(exact) > 1:
                first = exact[0]
                raise _LiteralError(path, f"{what}: keys {sorted(keys)} match the states of "
                                    f"several variables ({', '.join(v.name for v in exact)}): "
                                    f"name the variable in each key ({first.name}="
                                    f"{first.states[0]}: ...)")
            var = exact[0] if exact else max(matches, key=lambda v: len(keys & set(v.states)))
            return self._keyed_by(var, {str(k): (k, v) for k, v in raw.items()}, spec, keyable,
                                  path)
        leaf = spec.expected[-1] if spec.expected and spec.event_ndim else None
        array = _nested(raw, path, what, leaf, spec)
        lead = array.ndim - spec.event_ndim
        if lead < 0:
            raise _LiteralError(path, f"{what}: expected {spec.event_ndim} nested list "
                                f"level(s), found {array.ndim}")
        if lead > len(keyable):
            raise _LiteralError(path, f"{what}: expected at most {len(keyable) + spec.event_ndim} "
                                f"nested list levels, found {array.ndim}")
        axes = tuple(v.name for v in keyable[:lead])
        want = tuple(v.card for v in keyable[:lead])
        if array.shape[:lead] != want:
            raise _LiteralError(path, f"{what}: expected shape {want + array.shape[lead:]} "
                                f"(one level per state of {', '.join(axes)}), found "
                                f"{array.shape}")
        if spec.expected is not None and array.shape[lead:] == spec.expected \
                and spec.param.constraint.ok(array):
            return axes, array  # every row at once; else the first wrong row is found below
        for idx in np.ndindex(*array.shape[:lead]):
            row, where = array[idx], path + tuple(int(i) for i in idx)
            if spec.expected is not None and row.shape != spec.expected:
                raise _LiteralError(where, f"{what}: expected {_count(spec)}, found "
                                    f"{row.shape[-1] if row.ndim else 'a single number'}")
            if not spec.param.constraint.ok(row):
                raise _LiteralError(where, f"{what} must be {spec.param.constraint}, got "
                                    f"{_offender(row, spec.param, spec.event_ndim)}")
        return axes, array

    # questions and ablations --------------------------------------------------------------------

    def _child_row(self, rows: dict[str, Any], spec: _LiteralSpec, keyable: list,
                   path: YPath) -> tuple[tuple[str, ...], np.ndarray]:
        """A row keyed by the states of the term's variable: every state named once."""
        child = spec.child
        assert isinstance(child, Discrete)
        missing = [s for s in child.states if s not in rows]
        if missing:
            raise _LiteralError(path, f"{spec.what}: a row keyed by the states of "
                                f"{child.name} misses {', '.join(missing[:5])}")
        return self._literal([rows[s] for s in child.states], spec, keyable, path)

    def _keyed_by(self, var: Discrete, rows: dict[str, tuple[Any, Any]], spec: _LiteralSpec,
                  keyable: list, path: YPath) -> tuple[tuple[str, ...], np.ndarray]:
        """A table keyed by the states of the parent ``var`` (``rows``: each state's key as
        written and its value): one entry per state, the rest of the parents inside."""
        what = spec.what
        missing = [s for s in var.states if s not in rows]
        if missing:
            raise _LiteralError(path, f"{what}: table keyed by {var.name} misses state(s) "
                                f"{', '.join(missing[:5])}")
        rest = [v for v in keyable if v.name != var.name]
        key_of = {s: rows[s][0] for s in var.states}
        parts = [self._literal(rows[s][1], spec, rest, path + (key_of[s],)) for s in var.states]
        for state, (axes, arr) in zip(var.states, parts, strict=True):
            if axes != parts[0][0] or arr.shape != parts[0][1].shape:
                raise _LiteralError(path + (key_of[state],), f"{what}: rows keyed by {var.name} "
                                    f"must have the same layout; {var.states[0]!r} is "
                                    f"{_layout(*parts[0])}, {state!r} is {_layout(axes, arr)}")
        return (var.name,) + parts[0][0], np.stack([arr for _, arr in parts])
    def check_questions(self) -> dict[str, tuple[Expression, str, str]]:
        out: dict[str, tuple[Expression, str, str]] = {}
        for name in self.doc.questions:
            spec = self.doc.question(name)
            raw = self.doc.questions[name]
            path: YPath = ("questions", name) + (() if isinstance(raw, str) else ("ask",))
            try:
                expr = parse_expression(spec.ask)
            except ExpressionError as exc:
                self.error(path, f"question {name!r}: {exc}")
                continue
            problem = question_problem(expr, self.variables, self.conditioning)
            kind = "probability" if expr.event and spec.kind == "posterior" else spec.kind
            if not problem and expr.event and kind != "probability":
                problem = (f"{expr} asks the probability of an event, not a {kind} question "
                           "(leave out kind:, or ask P(searched | known) without values on "
                           "the left)")
            if problem:
                self.error(path, f"question {name!r}: {problem}")
                continue
            out[name] = (expr, kind, spec.description)
        return out

    def check_time(self, terms: list[Term], questions: dict[str, tuple[Expression, str, str]]
                   ) -> tuple[tuple[str, str], ...] | None:
        """The time section: each PREVIOUS and its STATE discrete with the same states, PREVIOUS
        without parents in a step; questions over steps search state variables (a sequence
        question all of them)."""
        spec = self.doc.time
        over_time = [(name, q) for name, q in questions.items()
                     if q[1] in ("filter", "smooth", "sequence")]
        if spec is None:
            for name, (_, kind, _) in over_time:
                self.error(("questions", name), f"question {name!r}: a {kind} question needs "
                           "a program that repeats per step (a time: section)", at_key=True)
            return None
        pairs = []
        failed = False
        previous_names = set(spec.previous)
        for previous, state in spec.previous.items():
            where = ("time", "previous", previous)
            problems = []
            for name in (previous, state):
                var = self.variables.get(name)
                if var is None:
                    problems.append(f"expected a declared variable, found nothing named {name!r}")
                elif name in self.untermed:
                    problems.append(f"{name} has no term in the decomposition: expected one, "
                                    + ("the belief before the first step" if name == previous
                                       else "the transition"))
            if state in previous_names:
                problems.append(f"{state} is a state one step earlier itself: expected a state "
                                "of this step")
            if not problems:
                a, b = self.variables[previous], self.variables[state]
                if a.is_discrete != b.is_discrete:
                    problems.append(f"{previous} and {state} must be of one kind, found one "
                                    "discrete and one real")
                elif a.is_discrete and a.states != b.states:  # type: ignore[union-attr]
                    problems.append(f"{previous} and {state} must have the same states, found "
                                    f"{a.describe_states()} and {b.describe_states()}")  # type: ignore[union-attr]
                elif not a.is_discrete and (a.low, a.high) != (b.low, b.high):  # type: ignore[union-attr]
                    problems.append(f"{previous} and {state} must have the same support, found "
                                    f"[{a.low}, {a.high}] and [{b.low}, {b.high}]")  # type: ignore[union-attr]
                own = next((t for t in terms if not t.soft and t.child.name == previous), None)
                if own is not None and any(p.name not in previous_names for p in own.parents):
                    problems.append(f"{previous}, the state one step earlier, has no parents "
                                    f"in a step but the other states one step earlier; found "
                                    f"{own.label}")
            for problem in problems:
                self.error(where, f"time: {problem}", at_key=True)
            failed = failed or bool(problems)
            pairs.append((previous, state))
        if failed:
            return None
        states = [state for _, state in pairs]
        kinds = {self.variables[s].is_discrete for s in states}
        if len(kinds) > 1:
            self.error(("time", "previous"), "time: the states over time are all discrete or "
                       "all real (a filter over a discrete and a real state together is out of "
                       "reach)", at_key=True)
            return None
        if len(set(states)) != len(states):
            self.error(("time", "previous"), "time: each state variable once, found "
                       f"{', '.join(states)}", at_key=True)
            return None
        built = {t.child.name for t in terms if not t.soft}
        for previous, state in pairs:
            ancestors = self._ancestors(terms, state)
            if state in built and not ancestors & previous_names:
                self.error(("time", "previous", previous), f"time: the term of {state} should "
                           "depend on the states one step earlier (the transition)", at_key=True)
                return None
        for name, (expr, kind, _) in over_time:
            outside = [v for v in expr.left if v not in states]
            if outside or (kind == "sequence" and len(states) > 1
                           and set(expr.left) != set(states)):
                wanted = (f"P({' '.join(states)} | ...)" if kind == "sequence"
                          else f"P({' or '.join(states)} | ...)")
                self.error(("questions", name), f"question {name!r}: a {kind} question "
                           f"searches the state: expected {wanted}, found {expr}", at_key=True)
        return tuple(pairs)

    @staticmethod
    def _ancestors(terms: list[Term], name: str) -> set[str]:
        """The variables ``name``'s term depends on, directly or through others of the step."""
        parents = {t.child.name: [p.name for p in t.parents] for t in terms if not t.soft}
        seen: set[str] = set()
        todo = list(parents.get(name, []))
        while todo:
            current = todo.pop()
            if current not in seen:
                seen.add(current)
                todo += parents.get(current, [])
        return seen

    def check_ablate(self, terms: list[Term]) -> list[Expression]:
        out = []
        for i, text in enumerate(self.doc.ablate):
            try:
                expr = parse_expression(text)
            except ExpressionError as exc:
                self.error(("ablate", i), f"ablate: {exc}")
                continue
            if not any(t.expression.key == expr.key for t in terms if not t.soft):
                known = ", ".join(str(t.expression) for t in terms if not t.soft)
                self.error(("ablate", i), f"ablate: no term {expr} in the decomposition "
                           f"(terms: {known})")
                continue
            out.append(expr)
        return out

    def check_cycles(self, terms: list[Term]) -> None:
        parents: dict[str, list[str]] = {}  # lists, not sets: the same cycle named every time
        for t in terms:
            if not t.soft:
                parents.setdefault(t.child.name, []).extend(p.name for p in t.parents)
        try:
            graphlib.TopologicalSorter(parents).prepare()
        except graphlib.CycleError as exc:
            loop = list(exc.args[1])  # each node a parent of the next; first and last the same
        else:
            return
        first = next(i for i, s in enumerate(self.doc.decomposition)
                     if _child_of(s.term) in loop)
        self.error(("decomposition", first, "term"), "the decomposition has a cycle: "
                   f"{' -> '.join(loop)}; expected a directed acyclic graph")


def question_problem(expr: Expression, variables: dict[str, Variable],
                     conditioning: Collection[str] = ()) -> str | None:
    """Why ``expr`` cannot be asked of these variables (None if it can), of a program
    conditioned on the variables ``conditioning`` (which have no term)."""
    for name in expr.left + expr.right:
        if name not in variables:
            return (f"undeclared variable {name!r} in {expr}{did_you_mean(name, variables)} "
                    f"(declared: {', '.join(variables)})")
    if conditioning:
        problem = conditioning_problem(expr, conditioning)
        if problem:
            return problem
    for name in expr.left:
        var = variables[name]
        if isinstance(var, Continuous) and var.index is not None:
            return (f"cannot search the field {name!r} (one value per state of {var.index}): "
                    "fields are known or summed out")
    for name, text in expr.values.items():
        var = variables[name]
        if isinstance(var, Discrete):
            try:
                var.index_of(text)
            except KeyError:
                return (f"unknown state {text!r} of {name}{did_you_mean(text, var.states)} "
                        f"(expected one of {var.describe_states()})")
        elif var.index is None:
            try:
                value = float(text)
            except ValueError:
                return f"expected a number for {name}, found {text!r}"
            if not var.low <= value <= var.high:
                return (f"{name}={value} is outside its support [{var.low}, {var.high}]")
    searched = [v for name in expr.left if isinstance(v := variables[name], Discrete)]
    # a joint answer past the size limit is refused by the engine, with its estimate; one of
    # many variables of one state each would pass it and still not fit numpy's arrays
    if (len(searched) > MAX_TERM_VARIABLES and len(searched) == len(expr.left)
            and math.prod(v.card for v in searched) <= limit("entries")):
        return (f"{expr} searches {len(searched)} variables jointly; expected at most "
                f"{MAX_TERM_VARIABLES} (its answer has one axis per variable, and numpy's "
                "arrays take 32 axes, one of them for a batch)")
    return None


def conditioning_problem(expr: Expression, conditioning: Collection[str]) -> str | None:
    """Why ``expr`` cannot be asked of a program conditioned on ``conditioning`` (None if it
    can): a variable without a term has no distribution, so a question gives its value; it
    is neither searched nor summed out.

    >>> problem = conditioning_problem(parse_expression("P(X | Y=y0)"), ["U"])
    >>> problem.startswith("P(X | Y=y0) leaves U unknown, but U has no term"), problem[-23:]
    (True, 'expected P(X | Y=y0, U)')
    """
    searched = [n for n in conditioning if n in expr.left]
    unknown = [n for n in conditioning if n not in expr.left and n not in expr.right]
    if not searched and not unknown:
        return None
    names = searched + unknown
    listed = ", ".join(names)
    has = "have no term" if len(names) > 1 else "has no term"
    what = (f"searches {', '.join(searched)}" if searched else "") + (
        " and " if searched and unknown else "") + (
        f"leaves {', '.join(unknown)} unknown" if unknown else "")
    left = tuple(n for n in expr.left if n not in searched)
    fix = ""
    if left:
        given = Expression(left, expr.right + tuple(names), expr.values)
        fix = f": expected {given}"
    return (f"{expr} {what}, but {listed} {has} in the decomposition (the program is "
            f"conditioned on {'them' if len(names) > 1 else 'it'}), so every question gives "
            f"{'their values' if len(names) > 1 else 'its value'}{fix}")


def _has_text(raw: Any) -> bool:
    """Whether a parameter's value holds a string (a formula) anywhere."""
    if isinstance(raw, str):
        return True
    if isinstance(raw, dict):
        return any(_has_text(v) for v in raw.values())
    if isinstance(raw, list):
        return any(_has_text(v) for v in raw)
    return False


@dataclass(frozen=True)
class _LiteralSpec:
    param: Param
    child: Variable
    event_ndim: int
    expected: tuple[int, ...] | None
    what: str


def _named_keys(raw: dict, child: Variable, keyable: list, path: YPath,
                what: str) -> tuple[Any, dict[str, tuple[Any, Any]]] | None:
    """The variable and the rows of a mapping whose keys name it (``Choice=1``), or None when
    no key does. Every key must then name the same variable, one of the term's (its parents,
    or the term's variable for a row of probabilities)."""
    named = [k for k in raw if isinstance(k, str) and "=" in k]
    if not named:
        return None
    if len(named) < len(raw):
        plain = next(k for k in raw if k not in named)
        raise _LiteralError(path, f"{what}: expected every key to name its variable "
                            f"(VAR=state) or none, found {named[0]!r} beside {plain!r}")
    rows: dict[str, tuple[Any, Any]] = {}
    names = set()
    for key in named:
        name, _, state = (part.strip() for part in key.partition("="))
        names.add(name)
        rows[state] = (key, raw[key])
    candidates = {v.name: v for v in keyable}
    if isinstance(child, Discrete):
        candidates.setdefault(child.name, child)
    if len(names) > 1:
        raise _LiteralError(path, f"{what}: expected the keys of one mapping to name one "
                            f"variable, found {', '.join(sorted(names))}")
    name = names.pop()
    var = candidates.get(name)
    if var is None:
        raise _LiteralError(path, f"{what}: key {named[0]!r} names {name!r}, expected one of "
                            f"{', '.join(candidates) or 'no variable'} (the term's variables)")
    unknown = [s for s in rows if s not in var.states]
    if unknown:
        raise _LiteralError(path + (rows[unknown[0]][0],),
                            f"{what}: unknown state {unknown[0]!r} of {name}"
                            f"{did_you_mean(unknown[0], var.states)} (expected one of "
                            f"{var.describe_states()})")
    return var, rows


def _count(spec: _LiteralSpec) -> str:
    n = spec.expected[-1] if spec.expected else 0
    if isinstance(spec.child, Discrete) and spec.param.keyed_by_child_states:
        return (f"{n} values per row (one per state of {spec.child.name}: "
                f"{spec.child.describe_states()})")
    return f"{n} values per row"


def _layout(axes: tuple[str, ...], arr: np.ndarray) -> str:
    keyed = f"keyed by {', '.join(axes)}, " if axes else ""
    return f"{keyed}shape {list(arr.shape)}"


def _nested(raw: Any, path: YPath, what: str, leaf: int | None, spec: _LiteralSpec) -> np.ndarray:
    """An array from nested lists, naming the row whose length or content is wrong."""
    if isinstance(raw, bool) or raw is None or isinstance(raw, str):
        raise _LiteralError(path, f"{what}: expected a number, a list of numbers, a table keyed "
                            f"by states or {{input: NAME}}, found {raw!r}")
    if isinstance(raw, (int, float)):
        return np.asarray(float(raw))
    if isinstance(raw, np.ndarray):  # a table of numbers the loader read as an array
        if leaf is not None and raw.shape[-1] != leaf:
            raise _LiteralError(path + (0,) * (raw.ndim - 1), f"{what}: expected "
                                f"{_count(spec)}, found {raw.shape[-1]}")
        return raw
    if isinstance(raw, dict):
        raise _LiteralError(path, f"{what}: expected a number or a list here (tables keyed by "
                            "states go outside nested lists), found a mapping")
    if not isinstance(raw, list):
        raise _LiteralError(path, f"{what}: expected numbers, found {raw!r}")
    if raw and all(not isinstance(x, list) for x in raw) and leaf is not None and len(raw) != leaf:
        raise _LiteralError(path, f"{what}: expected {_count(spec)}, found {len(raw)}")
    parts = [_nested(x, path + (i,), what, leaf, spec) for i, x in enumerate(raw)]
    for i, part in enumerate(parts):
        if part.shape != parts[0].shape:
            raise _LiteralError(path + (i,), f"{what}: rows must have equal lengths; row 0 has "
                                f"shape {list(parts[0].shape)}, row {i} has {list(part.shape)}")
    return np.stack(parts) if parts else np.zeros((0,))


class _LiteralError(Exception):
    def __init__(self, path: YPath, message: str):
        self.path, self.message = path, message


def _maybe_int(s: str) -> Any:
    try:
        return int(s)
    except ValueError:
        return s


def _child_of(text: str) -> str | None:
    try:
        left = parse_expression(text).left
    except ExpressionError:
        return None
    return left[0] if len(left) == 1 else None


def _offender(array: np.ndarray, param: Param, event_ndim: int) -> str:
    if event_ndim and array.ndim:
        sums = array.sum(axis=-1).ravel()
        bad = [s for s in sums if not np.isclose(s, 1.0, atol=1e-6)]
        if np.any(array < 0):
            return f"a negative value {array[array < 0].ravel()[0]:g}"
        if bad:
            return f"a row summing to {bad[0]:.6g}"
    flat = array.ravel()
    for v in flat:
        if not param.constraint.ok(np.asarray([v])):
            return f"{v:g}"
    return str(array.tolist())


def check_document(located: Located, doc: Document | PlainDocument, base_dir: Path,
                   load_program: Callable[..., Any] | None = None) -> Checked:
    """Check a validated document whole; ``load_program`` loads the files that ``program`` terms
    name (sub-programs), which this layer cannot do itself."""
    c = _Checker(located, doc, base_dir, load_program)
    c.check_variables()
    c.check_inputs()
    terms = c.check_terms()
    questions = c.check_questions()
    ablate = c.check_ablate(terms)
    time = c.check_time(terms, questions)
    return Checked(c.variables, c.inputs, terms, questions, ablate, c.problems, time)


def _form_named(name: str) -> Form:
    form = get_form(name)
    assert form is not None, name
    return form


def _forms_taking(option: str) -> str:
    """The forms whose estimator takes the ``learn:`` option, as a message lists them (over a
    variable of the kind each learns)."""
    from bayesprog.vocabulary.variables import Continuous, Discrete

    probes = (Discrete("X", ("a", "b")), Continuous("X", -np.inf, np.inf))
    names = [name for name in available_forms()
             if any((e := _form_named(name).estimator(v)) is not None and option in e.options
                    for v in probes)]
    return " and ".join(names) if len(names) <= 2 else ", ".join(names[:-1]) + " and " + names[-1]
