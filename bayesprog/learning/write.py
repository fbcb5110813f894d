"""Writing a fitted program: the input file with its learned parameters replaced in place and
the fit's record appended, so that comments, key order and layout stay as the author wrote
them: number by number in the text where the values are nested lists
(:mod:`bayesprog.learning.inplace`), else read and written as a round trip by ruamel.yaml."""

from __future__ import annotations

import io
import math
import os
import re
from collections.abc import Collection, Mapping, MutableMapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bayesprog.forms import ParamValue
from bayesprog.model.records import FitRecord
from bayesprog.vocabulary.expressions import canonical, parse_expression
from bayesprog.vocabulary.variables import Discrete, Variable

if TYPE_CHECKING:  # ruamel.yaml is imported by the round trip, when a file needs it
    from ruamel.yaml import YAML

#: the most significant digits a value is written with where it is rounded (a tuned number;
#: learned parameters are written as fitted, or rounded to the digits their data supports, see
#: :func:`supported_digits`)
DIGITS = 8
#: the significant digits of a value written as fitted: as many as a double always reads back
#: from (DBL_DIG), so that the file is the fit to a relative 1e-15 and a fit's own rounding
#: (0.5000000000000001) is written 0.5
FULL = 15
#: a learned mapping is written on one line ({a: 1, b: 2}) when it is this short, else one entry
#: per line
FLOW_WIDTH = 80


def _yaml() -> YAML:
    from ruamel.yaml import YAML

    yaml = YAML()
    yaml.preserve_quotes = True
    yaml.width = 4096  # never re-wrap the author's lines
    yaml.indent(mapping=2, sequence=4, offset=2)
    return yaml


def _number(x: float) -> float | int:
    return float(f"{x:.{DIGITS}g}")


def _flow(value: Any) -> Any:
    """Nested lists as YAML flow sequences ([a, b]) at every level; anything else as it is."""
    from ruamel.yaml.comments import CommentedSeq

    if not isinstance(value, list):
        return value
    seq = CommentedSeq([_flow(v) for v in value])
    seq.fa.set_flow_style()
    return seq


def _leaf(array: np.ndarray) -> Any:
    """A parameter's array (already rounded) in flow sequences."""
    return _flow(np.asarray(array, float).tolist())


def supported_digits(rows: int) -> int:
    """The significant digits learned values are written with, from ``rows`` rows of data:
    enough that rounding moves a value by under a twentieth of ``1/sqrt(rows)``, the relative
    standard error of an average of that many rows (3 at least, DIGITS at most)."""
    return int(min(DIGITS, max(3, math.ceil(0.5 * math.log10(max(rows, 1))) + 2)))


def rounded_location(location: np.ndarray, scale: np.ndarray, rows: int) -> np.ndarray:
    """A learned location (a mean) to the decimal place of a twentieth of its standard error,
    ``scale / sqrt(rows)`` (the error of a mean of ``rows`` values of that spread; fewer rows
    per parent state only make it larger): 1000.1234 with a spread of 0.01 from 12 rows stays
    1000.1234, 0.51140987 with a spread of 0.11 from 3000 rows becomes 0.5114."""
    location = np.asarray(location, float)
    error = np.broadcast_to(np.asarray(scale, float), location.shape) / math.sqrt(max(rows, 1))
    out = location.copy()
    for index in np.ndindex(*location.shape):
        quantum = error[index] / 20
        if not (np.isfinite(quantum) and quantum > 0 and np.isfinite(location[index])):
            continue
        places = -math.floor(math.log10(quantum))
        out[index] = float(f"{location[index]:.{places}f}") if places >= 0 else \
            round(float(location[index]), places)
    return out


def rounded(array: np.ndarray, digits: int, simplex: bool = False) -> np.ndarray:
    """``array`` to ``digits`` significant digits. Each distribution of a ``simplex`` array
    (its last axis) still sums to one: its largest entry is one minus the others, computed in
    decimal, so that the written numbers add up exactly."""
    array = np.asarray(array, float)
    # each number through its text, as a float is printed (numpy's rounding is to decimal
    # places, not significant digits, and not always to the nearest)
    texts = list(map(f"{{:.{digits}g}}".format, array.ravel().tolist()))
    out = np.fromiter(map(float, texts), float, array.size).reshape(array.shape)
    if simplex and out.ndim and out.size:
        from decimal import Decimal  # (a rounded file's, not every file's)

        # a number's text of at most 15 digits is the only one of so few that reads as its
        # double: its value is the decimal the file shows (of more digits, the shortest is)
        if digits > FULL:
            texts = list(map(repr, out.ravel().tolist()))
        width = array.shape[-1]
        rows = out.reshape(-1, width)
        zero, one = Decimal(0), Decimal(1)
        largest = array.reshape(-1, width).argmax(axis=1).tolist()  # the first of equal ones
        for r, k in enumerate(largest):
            row = texts[r * width:(r + 1) * width]
            rows[r, k] = float(one - sum(map(Decimal, row[:k] + row[k + 1:]), zero))
        out = rows.reshape(array.shape)
    return out


def _is_flow(node: Any) -> bool:
    return bool(getattr(node, "fa", None) is not None and node.fa.flow_style())


def _written_states(node: Any) -> dict[str, Any]:
    """The keys of a mapping as written, by the state each names (``tub=yes`` names ``yes``)."""
    if not isinstance(node, Mapping):
        return {}
    return {str(k).partition("=")[2].strip() if "=" in str(k) else str(k): k for k in node}


def _names_its_keys(node: Any) -> bool:
    return isinstance(node, Mapping) and any("=" in str(k) for k in node)


def _level(old: Any, written: Mapping[str, Any], axes: tuple[str, ...],
           variables: Mapping[str, Variable]) -> str | None:
    """The variable of ``axes`` the old mapping was keyed by, where its keys say so."""
    names = {str(k).partition("=")[0].strip() for k in written.values() if "=" in str(k)}
    if len(names) == 1:
        name = names.pop()
        return name if name in axes else None
    keyed = [a for a in axes if isinstance(var := variables[a], Discrete)
             and set(written) == set(var.states)]
    return keyed[0] if len(keyed) == 1 else None


def _node(value: ParamValue, variables: Mapping[str, Variable], old: Any,
          child: Variable | None = None, term: Collection[str] = ()) -> Any:
    """The YAML node of a parameter, keyed by the states of its axes; a mapping keeps the flow or
    block style of the node it replaces, and a row written keyed by the child's states stays so.
    A key names its variable (``tub=yes``) where the old key did, or where another variable of
    the ``term`` has the same states, as the loader asks."""
    from ruamel.yaml.comments import CommentedMap

    def ambiguous(var: Discrete) -> bool:
        return any(isinstance(other := variables.get(name), Discrete) and other.name != var.name
                   and set(other.states) == set(var.states) for name in term)

    def build(axes: tuple[str, ...], array: np.ndarray, old: Any) -> Any:
        if isinstance(old, list):  # written as nested lists: stays so
            return _leaf(array)
        written = _written_states(old)
        if not axes:
            if (isinstance(child, Discrete) and array.ndim == 1 and isinstance(old, Mapping)
                    and set(written) == set(child.states)):
                named = _names_its_keys(old)
                row = CommentedMap((_key(child, s, named), float(v))
                                   for s, v in zip(child.states, array, strict=True))
                row.fa.set_flow_style()
                return row
            return _leaf(array)
        first = _level(old, written, axes, variables)
        if first:  # the author's order of the levels is kept
            array = np.moveaxis(array, axes.index(first), 0)
            axes = (first, *(a for a in axes if a != first))
        var = variables[axes[0]]
        assert isinstance(var, Discrete)
        named = _names_its_keys(old) or ambiguous(var)
        out = CommentedMap()
        for i, state in enumerate(var.states):
            previous = old[written[state]] if state in written else None
            out[_key(var, state, named)] = build(axes[1:], array[i], previous)
        short = len(str(dict(out))) <= FLOW_WIDTH
        if short and (_is_flow(old) or (len(axes) == 1 and not isinstance(old, Mapping))):
            out.fa.set_flow_style()
        return out

    return build(value.axes, np.asarray(value.array, float), old)


_PLAIN = re.compile(r"^[A-Za-z_][A-Za-z0-9_.-]*$")
#: words that a YAML 1.2 reader takes for booleans or null: written quoted (``yes``, ``on``
#: are words, written as they are)
_AMBIGUOUS = {"true", "false", "null", "~"}
#: a key naming its variable that a YAML reader takes as written, unquoted
_PLAIN_NAMED = re.compile(r"^[A-Za-z_][A-Za-z0-9_.-]*=[A-Za-z0-9_.-]+$")


def _key(var: Discrete, state: str, named: bool = False) -> Any:
    """A state as a mapping key: a range's values as numbers, names quoted where a YAML reader
    would take them for something else; ``named``, the key names its variable
    (``tub=yes``)."""
    from ruamel.yaml.scalarstring import DoubleQuotedScalarString

    if named:
        key = f"{var.name}={state}"
        return key if _PLAIN_NAMED.match(key) else DoubleQuotedScalarString(key)
    if var.kind == "range":
        return int(state)
    if _PLAIN.match(state) and state.lower() not in _AMBIGUOUS:
        return state
    return DoubleQuotedScalarString(state)


def _keep(old: Any, new: Any) -> Any:
    """``new`` written into ``old`` where they have the same keys or length, so the comments and
    style attached to ``old`` stay; else ``new``."""
    if isinstance(old, MutableMapping) and isinstance(new, Mapping) and \
            [str(k) for k in old] == [str(k) for k in new]:
        for (key, value), (_, fresh) in zip(list(old.items()), new.items(), strict=True):
            old[key] = _keep(value, fresh)
        return old
    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        for i, fresh in enumerate(new):
            old[i] = _keep(old[i], fresh)
        return old
    return new


def _record(record: FitRecord) -> Any:
    from ruamel.yaml.comments import CommentedMap

    out = CommentedMap()
    for key, value in record.as_data().items():
        if key in ("digits", "rows_set_aside") and value is None:  # as fitted; rows refused
            continue
        if key == "structure":
            if value is not None:
                out[key] = CommentedMap((k, _flow(v)) for k, v in value.items())
            continue
        if key == "statistics":
            stats = CommentedMap()
            for label, named in value.items():
                inner = CommentedMap()
                for name, array in named.items():
                    inner[name] = _flow(array)
                stats[label] = inner
            out[key] = stats
        else:
            out[key] = _flow(value)  # the terms' list in flow style
    return out


def render_fitted(text: str, params: Mapping[str, Mapping[str, ParamValue]],
                  variables: Mapping[str, Variable], record: FitRecord,
                  simplex: Mapping[str, Collection[str]] | None = None,
                  locations: Mapping[str, tuple[str, str]] | None = None,
                  states: Mapping[str, list[str]] | None = None) -> str:
    """``text`` (a program file) with the learned ``params`` (by term label) written in place of
    the old values, and ``record`` appended to its ``learned:`` list; ``states``: variables
    that take new states (from the data), declared so.

    The values are written as fitted, to ``FULL`` significant digits, unless the record has
    ``digits``: then to that many (``locations``: each term's location and scale parameters,
    the location written to a twentieth of its standard error instead); ``simplex``: the
    parameters of each term whose last axis is a distribution, kept summing to one as
    written.

    Values written as nested lists are replaced number by number in the text
    (:func:`bayesprog.learning.inplace.splice`); a file that needs more (keys naming states,
    new states) is read and written as a round trip."""
    values = _written_values(params, record, simplex or {}, locations or {})
    if not states:
        from bayesprog.learning.inplace import splice

        arrays = {label: {name: value.array for name, value in named.items()}
                  for label, named in values.items()}
        spliced = splice(text, arrays, record.as_data())
        if spliced is not None:
            return spliced
    return _round_trip(text, values, variables, record, states or {})


def _written_values(params: Mapping[str, Mapping[str, ParamValue]], record: FitRecord,
                    simplex: Mapping[str, Collection[str]],
                    locations: Mapping[str, tuple[str, str]]
                    ) -> dict[str, dict[str, ParamValue]]:
    """The learned values as they are written: as fitted, or rounded as the record says."""
    digits = record.digits
    rows = record.rows_supporting or record.rows_used
    out: dict[str, dict[str, ParamValue]] = {}
    for label, fitted in params.items():
        location, scale = locations.get(label, (None, None))
        out[label] = {}
        for name, value in fitted.items():
            spread = fitted.get(scale) if name == location and scale else None
            if digits is not None and spread is not None and spread.axes in ((), value.axes):
                array = rounded_location(value.array, spread.array, rows)
            else:
                array = rounded(value.array, digits or FULL, name in simplex.get(label, ()))
            out[label][name] = ParamValue(value.axes, array)
    return out


def _round_trip(text: str, values: Mapping[str, Mapping[str, ParamValue]],
                variables: Mapping[str, Variable], record: FitRecord,
                states: Mapping[str, list[str]]) -> str:
    """The file read and written by ruamel.yaml, which keeps its comments, key order and
    layout: keyed tables are rewritten key by key."""
    from ruamel.yaml.comments import CommentedSeq

    yaml = _yaml()
    doc = yaml.load(text)
    for name, names in states.items():
        declaration = doc["variables"][name]
        var = variables[name]
        assert isinstance(var, Discrete)
        declaration["states"] = _flow([_key(var, s) for s in names])
    done = set()
    for item in doc.get("decomposition", []):
        label = canonical(item.get("term"))
        if label is None or label not in values:
            continue
        expression = parse_expression(label)
        child = variables.get(expression.left[0])
        term = (*expression.left, *expression.right)
        for name, value in values[label].items():
            item[name] = _keep(item.get(name), _node(value, variables, item.get(name), child,
                                                     term))
        done.add(label)
    missing = set(values) - done
    if missing:
        raise ValueError(f"no term {sorted(missing)[0]} in the program text")
    learned = doc.get("learned")
    if learned is None:
        learned = CommentedSeq()
        doc["learned"] = learned
        doc.yaml_set_comment_before_after_key(
            "learned", before="\nFits that set this program's parameters (bayesprog learn).")
    learned.append(_record(record))
    out = io.StringIO()
    yaml.dump(doc, out)
    return out.getvalue()


def render_values(text: str, params: Mapping[str, Mapping[str, float]], header: str,
                  moved: tuple[Path, Path] | None = None) -> str:
    """``text`` (a program file) with single-number parameters (by term label) written in place
    of the old values and ``header`` as a comment on top; the rest stays as written. ``moved``
    is (the folder the text was read from, the folder it is written to): sub-programs named by
    a relative path are named from the new folder."""
    yaml = _yaml()
    doc = yaml.load(text)
    wanted = {canonical(label): values for label, values in params.items()}
    done = set()
    for item in [*doc.get("decomposition", []), *doc.get("soft_evidence", [])]:
        program = item.get("program")
        if moved is not None and isinstance(program, str) and not Path(program).is_absolute():
            item["program"] = os.path.relpath((moved[0] / program).resolve(),
                                              moved[1].resolve())
    for item in doc.get("decomposition", []):
        label = canonical(item.get("term"))
        if label in wanted:
            for name, value in wanted[label].items():
                item[name] = _number(float(value))
            done.add(label)
    missing = set(wanted) - done
    if missing:
        raise ValueError(f"no term {sorted(str(m) for m in missing)[0]} in the program text")
    doc.yaml_set_start_comment(header)
    out = io.StringIO()
    yaml.dump(doc, out)
    return out.getvalue()
