"""The checks of the decomposition: one term per variable, each term's variables declared and
its form taking them, its table within the limits, its ``learn:`` options, soft evidence, the
variables without a term, and no cycle."""

from __future__ import annotations

import graphlib
import math
import re
from typing import TYPE_CHECKING, Any

import numpy as np

from bayesprog.errors import did_you_mean
from bayesprog.forms import FormulaParam, Param, ParamValue, available_forms, get_form, unknown_form
from bayesprog.forms.base import nonnegative
from bayesprog.language.check.base import MAX_TERM_VARIABLES, _child_of, _form_named, _forms_taking
from bayesprog.language.check.parameters import ParametersCheck, _LiteralError, _LiteralSpec
from bayesprog.language.loader import Path as YPath
from bayesprog.limits import limit
from bayesprog.model import LearnOptions, Term
from bayesprog.vocabulary.expressions import Expression, ExpressionError, parse_expression
from bayesprog.vocabulary.variables import Continuous, Discrete, Variable

if TYPE_CHECKING:  # (pydantic's models are built only for a file the plain reader leaves)
    from bayesprog.language.document import LearnSpec
    from bayesprog.language.plain import PlainLearn


class TermsCheck(ParametersCheck):
    """The ``decomposition:`` and ``soft_evidence:`` sections (each term's parameters by
    :class:`~bayesprog.language.check.parameters.ParametersCheck`)."""

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
