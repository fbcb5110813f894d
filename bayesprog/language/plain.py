"""A program file of the common shape read without pydantic: what most files hold (named states,
ranges, real variables, fields, inputs, terms, questions, time, the records of fits and of
discovered structures), checked by hand and returned as plain objects with the attributes of
:mod:`bayesprog.language.document`'s models.

Building pydantic's validators costs more than a question asked once (docs/performance.md,
start-up), so a program whose keys and values all fall inside that shape is read here; anything
else (a grid, bins, a value of another type, a key that is not one of the document's, any
problem at all) gives None, and the document is validated by pydantic, which then says what is
wrong or reads what is unusual. The two agree on every file this reader
takes (tests/test_schema.py reads every shipped program both ways).
"""

from __future__ import annotations

from collections.abc import Iterator
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

from bayesprog.limits import limit

if TYPE_CHECKING:
    from bayesprog.model.records import FitRecord

#: The kinds of question a file may name.
KINDS = ("posterior", "map", "filter", "smooth", "sequence", "probability")


def check_states(count: int, what: str) -> None:
    """Refuse a variable of more states than ``BAYESPROG_MAX_STATES``."""
    cap = limit("states")
    if count > cap:
        raise ValueError(f"{what} has {count:,} states, more than the limit of {cap:,} (raise "
                         "it with the environment variable BAYESPROG_MAX_STATES)")


def name_of_number(value: Any) -> Any:
    """A number where a name stands, as its name (``1`` -> ``"1"``, ``0.5`` -> ``"0.5"``)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return repr(value)
    return value


class PlainVariable(SimpleNamespace):
    """A variable's declaration (exactly one of ``states``, ``range``, ``continuous``)."""

    states: list[str] | None
    range: list[int] | None
    grid: None
    continuous: list[float] | None
    indexed_by: str | None
    discretise: None
    description: str


class PlainInput(SimpleNamespace):
    shape: list[int | str]
    description: str


class PlainLearn(SimpleNamespace):
    pseudo_counts: Any
    components: int | list[int] | None
    shared: list[str]


class PlainTerm(SimpleNamespace):
    term: str
    form: str
    parameters: dict[str, Any]
    description: str
    learn: bool | PlainLearn


class PlainSoftEvidence(SimpleNamespace):
    variable: str
    form: str
    parameters: dict[str, Any]
    description: str


class PlainQuestion(SimpleNamespace):
    ask: str
    kind: str
    description: str


class PlainTime(SimpleNamespace):
    previous: dict[str, str]


class PlainDocument(SimpleNamespace):
    """The document: the attributes of :class:`bayesprog.language.document.Document`."""

    bayesprog: int
    variables: dict[str, PlainVariable]
    decomposition: list[PlainTerm]
    name: str | None
    description: str
    inputs: dict[str, PlainInput]
    soft_evidence: list[PlainSoftEvidence]
    questions: dict[str, PlainQuestion | str]
    time: PlainTime | None
    ablate: list[str]
    learned: list[Any]

    def question(self, name: str) -> PlainQuestion:
        q = self.questions[name]
        return PlainQuestion(ask=q, kind="posterior", description="") if isinstance(q, str) \
            else q


class _Other(Exception):
    """The document is not of the common shape: pydantic reads it."""


def _expect(ok: bool) -> None:
    if not ok:
        raise _Other


def _text(value: Any) -> str:
    _expect(type(value) is str)
    return value


def _mapping(value: Any, keys: tuple[str, ...] | None = None) -> dict:
    _expect(type(value) is dict and all(type(k) is str for k in value))
    if keys is not None:
        _expect(all(k in keys for k in value))
    return value


def _integer(value: Any) -> int:
    _expect(type(value) is int)
    return value


def _number(value: Any) -> float:
    _expect(type(value) in (int, float))
    return float(value)


def _list(value: Any) -> list:
    _expect(type(value) is list)
    return value


def _texts(value: Any) -> list[str]:
    _expect(type(value) is list)
    return [_text(v) for v in value]


def _variable(raw: Any) -> PlainVariable:
    spec = _mapping(raw, ("states", "range", "continuous", "indexed_by", "description"))
    out = PlainVariable(states=None, range=None, grid=None, continuous=None, indexed_by=None,
                        discretise=None, description=_text(spec.get("description", "")))
    kinds = [k for k in ("states", "range", "continuous") if spec.get(k) is not None]
    _expect(len(kinds) == 1 and all(spec.get(k, 0) is not None for k in spec))
    if "states" in spec:
        states = spec["states"]
        _expect(type(states) is list and len(states) > 0)
        out.states = [_text(name_of_number(s)) for s in states]
        _expect(len(set(out.states)) == len(out.states))
        check_states(len(out.states), "a variable")
    elif "range" in spec:
        bounds = spec["range"]
        _expect(type(bounds) is list and len(bounds) == 2)
        low, high = _integer(bounds[0]), _integer(bounds[1])
        _expect(low <= high)
        check_states(high - low + 1, f"the range {bounds}")
        out.range = [low, high]
    else:
        support = spec["continuous"]
        _expect(type(support) is list and len(support) == 2)
        low_f, high_f = _number(support[0]), _number(support[1])
        _expect(low_f < high_f)
        out.continuous = [low_f, high_f]
    if "indexed_by" in spec:
        _expect(out.continuous is not None)
        out.indexed_by = _text(spec["indexed_by"])
    return out


def _learn(value: Any) -> bool | PlainLearn:
    if type(value) is bool:
        return value
    spec = _mapping(value, ("pseudo_counts", "components", "shared"))
    components = spec.get("components")
    if components is not None:
        _expect(type(components) is int or (type(components) is list and all(
            type(c) is int for c in components)))
    return PlainLearn(pseudo_counts=spec.get("pseudo_counts"), components=components,
                      shared=_texts(spec.get("shared", [])))


def _with_parameters(raw: Any, own: tuple[str, ...]) -> tuple[dict, dict[str, Any]]:
    spec = _mapping(raw)
    return spec, {k: v for k, v in spec.items() if k not in own}


def _terms(raw: Any) -> Iterator[PlainTerm]:
    _expect(type(raw) is list and len(raw) > 0)
    for item in raw:
        spec, parameters = _with_parameters(item, ("term", "form", "description", "learn"))
        yield PlainTerm(term=_text(spec.get("term")), form=_text(spec.get("form")),
                        parameters=parameters, description=_text(spec.get("description", "")),
                        learn=_learn(spec.get("learn", True)))


def _soft(raw: Any) -> Iterator[PlainSoftEvidence]:
    _expect(type(raw) is list)
    for item in raw:
        spec, parameters = _with_parameters(item, ("variable", "form", "description"))
        yield PlainSoftEvidence(variable=_text(spec.get("variable")),
                                form=_text(spec.get("form")), parameters=parameters,
                                description=_text(spec.get("description", "")))


def _question(raw: Any) -> PlainQuestion | str:
    if type(raw) is str:
        return raw
    spec = _mapping(raw, ("ask", "kind", "description"))
    kind = spec.get("kind", "posterior")
    _expect(kind in KINDS)
    return PlainQuestion(ask=_text(spec.get("ask")), kind=kind,
                         description=_text(spec.get("description", "")))


def _input(raw: Any) -> PlainInput:
    spec = _mapping(raw, ("shape", "description"))
    shape = spec.get("shape", [])
    _expect(type(shape) is list and all(type(d) in (int, str) for d in shape))
    return PlainInput(shape=list(shape), description=_text(spec.get("description", "")))


#: A fit's record: each field's plain type (a number may be an integer; None where optional).
_RECORD: dict[str, tuple[type, ...]] = {
    "data": (str,), "sha256": (str,), "rows": (int,), "rows_used": (int,),
    "log_likelihood": (int, float), "method": (str,), "iterations": (int,),
    "digits": (int, type(None)), "columns": (dict,), "rows_supporting": (int, type(None)),
    "rows_set_aside": (int, type(None)), "terms": (list,), "statistics": (dict,),
    "structure": (dict, type(None))}

#: A discovered structure's record: each field's plain type (None where optional); the fields
#: of numbers (float) may be written as integers
_STRUCTURE: dict[str, tuple[type, ...]] = {
    "method": (str,), "score": (str, type(None)), "score_value": (int, float, type(None)),
    "equivalent_sample_size": (int, float, type(None)), "test": (str, type(None)),
    "significance": (int, float, type(None)), "max_conditioning": (int, type(None)),
    "tests": (int, type(None)), "iterations": (int, type(None)),
    "restarts": (int, type(None)), "seed": (int, type(None)),
    "families_scored": (int, type(None)), "seconds": (int, float), "missing": (str,),
    "constraints": (dict,), "oriented_by_choice": (list,), "discretised": (dict,),
    "warnings": (list,)}
_STRUCTURE_FLOATS = ("score_value", "equivalent_sample_size", "significance", "seconds")


def _float(value: Any) -> float:
    """A number of a float field, as pydantic reads it (an integer as its float)."""
    _expect(type(value) is float or (type(value) is int and abs(value) < 2**53))
    return float(value)


def _structure(raw: Any) -> Any:
    from bayesprog.model.records import StructureRecord

    spec = dict(_mapping(raw, tuple(_STRUCTURE)))
    _expect(all(type(v) in _STRUCTURE[k] for k, v in spec.items()))
    for key in _STRUCTURE_FLOATS:
        if spec.get(key) is not None:
            spec[key] = _float(spec[key])
    # the constraints as written (dict[str, Any]): plain YAML values only, no tag's object
    _expect(_plain_values(_mapping(spec.get("constraints", {}))))
    spec["oriented_by_choice"] = _texts(spec.get("oriented_by_choice", []))
    spec["warnings"] = _texts(spec.get("warnings", []))
    spec["discretised"] = {k: [_float(x) for x in _list(edges)]
                           for k, edges in _mapping(spec.get("discretised", {})).items()}
    try:
        return StructureRecord(**spec)
    except TypeError:  # a required field missing
        raise _Other from None


def _plain_values(value: Any) -> bool:
    """Whether ``value`` is made of YAML's plain values only (as pydantic keeps them as Any)."""
    if type(value) is dict:
        return all(type(k) is str and _plain_values(v) for k, v in value.items())
    if type(value) is list:
        return all(_plain_values(v) for v in value)
    return value is None or type(value) in (str, int, float, bool)


def _record(raw: Any) -> FitRecord:
    from bayesprog.model.records import FitRecord  # (a program that was never learned needs none)

    spec = _mapping(raw, tuple(_RECORD))
    _expect(all(type(v) in _RECORD[k] for k, v in spec.items()))
    columns = _mapping(spec.get("columns", {}))
    _expect(all(type(v) is str for v in columns.values()))
    statistics = _mapping(spec.get("statistics", {}))
    for named in statistics.values():
        _mapping(named)
    if "log_likelihood" in spec:
        _expect(type(spec["log_likelihood"]) is float or abs(spec["log_likelihood"]) < 2**53)
        spec = {**spec, "log_likelihood": float(spec["log_likelihood"])}
    if spec.get("structure") is not None:
        spec = {**spec, "structure": _structure(spec["structure"])}
    try:
        return FitRecord(**{**spec, "terms": _texts(spec.get("terms", []))})
    except TypeError:  # a required field missing
        raise _Other from None


TOP = ("bayesprog", "name", "description", "variables", "inputs", "decomposition",
       "soft_evidence", "questions", "time", "ablate", "learned")


def read_plain(data: Any) -> PlainDocument | None:
    """The document ``data`` (as loaded from YAML) when it is of the common shape and valid
    as such, else None (pydantic then validates it)."""
    try:
        top = _mapping(data, TOP)
        _expect(type(top.get("bayesprog")) is int and top["bayesprog"] == 1)
        name = top.get("name")
        _expect(name is None or type(name) is str)
        variables = _mapping(top.get("variables"))
        _expect(len(variables) > 0)
        time = None
        if top.get("time") is not None:
            previous = _mapping(_mapping(top["time"], ("previous",)).get("previous"))
            _expect(len(previous) > 0 and all(type(v) is str for v in previous.values()))
            time = PlainTime(previous=dict(previous))
        return PlainDocument(
            bayesprog=1,
            variables={k: _variable(v) for k, v in variables.items()},
            decomposition=list(_terms(top.get("decomposition"))),
            name=name,
            description=_text(top.get("description", "")),
            inputs={k: _input(v) for k, v in _mapping(top.get("inputs", {})).items()},
            soft_evidence=list(_soft(top.get("soft_evidence", []))),
            questions={k: _question(v) for k, v in _mapping(top.get("questions", {})).items()},
            time=time,
            ablate=_texts(top.get("ablate", [])),
            learned=[_record(r) for r in _list(top.get("learned", []))],
        )
    except (_Other, ValueError):
        return None
