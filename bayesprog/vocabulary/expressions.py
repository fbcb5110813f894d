"""The ``P(left | right)`` notation shared by terms, questions and ablations, and questions.

>>> parse_expression("P(A B | C=c1, D=0.3)")
Expression(left=('A', 'B'), right=('C', 'D'), values={'C': 'c1', 'D': '0.3'})
>>> str(parse_expression("P(S|O,T)"))
'P(S | O, T)'

A question whose searched variables all take a value asks the probability of that event:

>>> parse_expression("P(smoke=yes, dysp=yes | asia=no)").event
{'smoke': 'yes', 'dysp': 'yes'}
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from bayesprog.errors import BayesprogError

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")
_SHAPE = re.compile(r"^\s*P\s*\((?P<body>.*)\)\s*$", re.DOTALL)
_N = r"[A-Za-z_][A-Za-z0-9_.\-]*"
#: ``P(A B | C, D)`` without values: the common case, read by one match
_PLAIN = re.compile(rf"\s*P\s*\(\s*({_N}(?:[\s,]+{_N})*)\s*(?:\|\s*({_N}(?:\s*,\s*{_N})*)\s*)?\)\s*")
_SPLIT_LEFT = re.compile(r"[\s,]+")
_SPLIT_RIGHT = re.compile(r"\s*,\s*")


class ExpressionError(BayesprogError, ValueError):
    """The text is not of the form ``P(A B | C, D=d)``; the message says what was found."""


@dataclass(frozen=True)
class Expression:
    """``P(left | right)``; ``values`` holds the ``Name=value`` bindings written, on the right
    (known values) and, for the probability of an event, on the left (:attr:`event`)."""

    left: tuple[str, ...]
    right: tuple[str, ...] = ()
    values: dict[str, str] = field(default_factory=dict, compare=False)

    def __str__(self) -> str:
        text = self.__dict__.get("_text")  # written once: every answer carries it
        if text is None:
            left = (", ".join(f"{n}={self.values[n]}" for n in self.left) if self.event
                    else " ".join(self.left))
            right = ", ".join(f"{n}={self.values[n]}" if n in self.values else n
                              for n in self.right)
            text = f"P({left} | {right})" if self.right else f"P({left})"
            object.__setattr__(self, "_text", text)
        return text

    @property
    def event(self) -> dict[str, str]:
        """The values of the searched variables, when the expression asks the probability of
        an event (``P(A=a, B=b | C)``); empty otherwise."""
        return {n: self.values[n] for n in self.left if n in self.values}

    @property
    def key(self) -> tuple[tuple[str, ...], frozenset[str]]:
        """What identifies a term: its variables, the order of the conditioning set aside."""
        return self.left, frozenset(self.right)


def _names(text: str, what: str, original: str) -> list[str]:
    names = [n for n in re.split(r"[\s,]+", text.strip()) if n]
    for name in names:
        if not _NAME.match(name):
            raise ExpressionError(
                f"{what} of {original!r}: expected variable names, found {name!r}"
            )
    return names


def _event(text: str, original: str, values: dict[str, str]) -> list[str]:
    """The names of an event ``A=a, B=b`` (the left of ``P(A=a, B=b | C)``), their values put
    in ``values``: every name takes one."""
    items = [tuple(s.strip() for s in item.partition("=")) for item in text.split(",")]
    for name, _, value in items:
        if not _NAME.match(name):
            raise ExpressionError(f"the searched part of {original!r}: expected a name, found "
                                  f"{name!r}")
        if "=" in value:
            raise ExpressionError(f"the searched part of {original!r}: expected one value "
                                  f"after '{name}=', found {value!r} (separate the variables "
                                  "of an event by commas: P(A=a, B=b))")
    bare = [name for name, eq, _ in items if not eq]
    if bare:
        raise ExpressionError(
            f"the searched part of {original!r}: {', '.join(bare)} without a value beside "
            f"{', '.join(name for name, eq, _ in items if eq)}; expected a value for every "
            "searched variable (the probability of an event, P(A=a, B=b)) or for none (a "
            "distribution, P(A B))")
    for name, _, value in items:
        if not value:
            raise ExpressionError(f"expected a value after '{name}=' in {original!r}")
        values[name] = value
    return [name for name, _, _ in items]


def parse_expression(text: str) -> Expression:
    """Parse ``P(A B | C, D=d)``. Names on the left are separated by spaces or commas."""
    if not isinstance(text, str):
        raise ExpressionError(f"expected a string like 'P(A | B)', found {text!r}")
    plain = _PLAIN.fullmatch(text)
    if plain is not None:  # names only: one match
        left = _SPLIT_LEFT.split(plain[1])
        right = _SPLIT_RIGHT.split(plain[2]) if plain[2] else []
        if len({*left, *right}) == len(left) + len(right):
            return Expression(tuple(left), tuple(right), {})
    return _parse_general(text)


def _parse_general(text: str) -> Expression:
    """:func:`parse_expression` of any text, saying what is wrong with it."""
    match = _SHAPE.match(text)
    if not match:
        raise ExpressionError(f"expected the form 'P(A B | C, D=d)', found {text!r}")
    body = match.group("body")
    if body.count("|") > 1:
        raise ExpressionError(f"expected at most one '|' in {text!r}")
    left_text, _, right_text = body.partition("|")
    values: dict[str, str] = {}
    left = (_event(left_text, text, values) if "=" in left_text
            else _names(left_text, "the searched part", text))
    if not left:
        raise ExpressionError(f"expected at least one variable before '|' in {text!r}")
    right: list[str] = []
    for item in (i.strip() for i in right_text.split(",")):
        if not item:
            if right_text.strip():
                raise ExpressionError(f"empty item between commas in {text!r}")
            continue
        name, eq, value = (s.strip() for s in item.partition("="))
        if not _NAME.match(name):
            raise ExpressionError(f"the known part of {text!r}: expected a name, found {name!r}")
        if eq:
            if not value:
                raise ExpressionError(f"expected a value after '{name}=' in {text!r}")
            values[name] = value
        right.append(name)
    for dup in {n for n in left + right if (left + right).count(n) > 1}:
        raise ExpressionError(f"variable {dup!r} appears twice in {text!r}")
    return Expression(tuple(left), tuple(right), values)


def canonical(text: object) -> str | None:
    """``text`` as the parser writes the expression (``P(A | B)`` however it was spaced), or
    None when it is not one: the key under which two spellings of a term are the same.

    >>> canonical("P( I|O )"), canonical("no term")
    ('P(I | O)', None)
    """
    try:
        return str(parse_expression(text))  # type: ignore[arg-type]
    except ExpressionError:
        return None


@dataclass(frozen=True)
class Question:
    """A question ``P(searched | known)`` of kind ``posterior`` or ``map`` (``filter``,
    ``smooth``, ``sequence`` over time steps), or ``probability`` for the probability of an
    event, ``P(A=a, B=b | C=c)``."""

    expression: Expression
    kind: str = "posterior"
    name: str | None = None
    description: str = ""

    def __str__(self) -> str:
        return str(self.expression)
