"""The checks of a term's parameters: each one its form declares, given as a literal (a number,
nested lists, a table keyed by states), as formulas of the parents and the inputs, or as a
runtime input; every row checked against the parameter's constraint where it is written."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from bayesprog.errors import Diagnostic, did_you_mean, short_repr
from bayesprog.forms import FormulaParam, InputRef, Param, ParamValue
from bayesprog.forms.base import real
from bayesprog.forms.standard import deterministic_problem
from bayesprog.language.check.base import Checker
from bayesprog.language.loader import Path as YPath
from bayesprog.model import Term
from bayesprog.vocabulary.formula import Formula, FormulaError, parse_formula
from bayesprog.vocabulary.variables import Discrete, Variable


class ParametersCheck(Checker):
    """The parameters of each term of the decomposition."""

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

