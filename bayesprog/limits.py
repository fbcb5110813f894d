"""How large a program or a question may grow: sizes are estimated before anything is
allocated and refused past these limits, with a message that says the estimate.

Two limits, each raised by an environment variable (or :func:`set_limits` from Python):

``BAYESPROG_MAX_STATES`` (default 2,000,000)
    states of one discrete variable (a grid's cells, a range's integers, named states).
``BAYESPROG_MAX_ENTRIES`` (default 100,000,000, 800 MB of float64)
    entries of the largest array a question, a run or a scenario allocates.

>>> check_size(10**6, "the joint of A B", "entries")
>>> check_size(10**12, "the joint of A B", "entries")
Traceback (most recent call last):
...
bayesprog.limits.SizeError: the joint of A B needs 1,000,000,000,000 entries, more than the limit of 100,000,000 (raise it with the environment variable BAYESPROG_MAX_ENTRIES)
"""

from __future__ import annotations

import os

from bayesprog.errors import BayesprogError

_DEFAULTS = {"states": 2_000_000, "entries": 100_000_000}
_ENV = {"states": "BAYESPROG_MAX_STATES", "entries": "BAYESPROG_MAX_ENTRIES"}
_SET: dict[str, int] = {}
#: how many times set_limits was called (see generation)
_GENERATION = [0]


class SizeError(BayesprogError, ValueError):
    """Something a user wrote would need more memory than the limit allows."""


def limit(kind: str) -> int:
    """The limit on ``kind`` (``"states"`` or ``"entries"``): set by :func:`set_limits`, else
    by the environment variable, else the default."""
    if kind in _SET:
        return _SET[kind]
    text = os.environ.get(_ENV[kind], "").replace("_", "").strip()
    if not text:
        return _DEFAULTS[kind]
    try:
        value = int(float(text))
    except ValueError:
        raise SizeError(f"{_ENV[kind]}={os.environ[_ENV[kind]]!r}: expected a positive "
                        "integer") from None
    if value < 1:
        raise SizeError(f"{_ENV[kind]}={value}: expected a positive integer")
    return value


def set_limits(states: int | None = None, entries: int | None = None) -> None:
    """Set the limits for this process (None: back to the environment variable or default)."""
    _GENERATION[0] += 1
    for kind, value in (("states", states), ("entries", entries)):
        if value is None:
            _SET.pop(kind, None)
        elif isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise SizeError(f"set_limits({kind}=...): expected a positive integer, found "
                            f"{value!r}")
        else:
            _SET[kind] = value


def generation() -> int:
    """How many times :func:`set_limits` was called: what was checked against the limits
    under another generation is checked again."""
    return _GENERATION[0]


def check_size(size: float, what: str, kind: str = "entries", hint: str = "") -> None:
    """Refuse ``what`` when it needs more than the limit on ``kind`` (``hint``: what else the
    user can do, appended to the message)."""
    cap = limit(kind)
    if size > cap:
        shown = f"{size:,.0f}" if size < 1e18 else f"{size:.3g}"
        raise SizeError(f"{what} needs {shown} {kind}, more than the limit of {cap:,} "
                        f"(raise it with the environment variable {_ENV[kind]}){hint}")
