"""Rich display hooks (IPython's ``_repr_html_``): programs and answers ask here for their HTML.

The renderers live in :mod:`bayesprog.views.display`, above the layers whose objects they draw, and
register themselves (:func:`register`) when that module is imported. This module names none of
them: the package's ``__init__`` hands it, with :func:`defer`, the import that brings them, run
at the first display, so the engine and the program never import plotting code and ``import
bayesprog`` loads none of it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

_RENDERERS: dict[str, Callable[[Any], str]] = {}
_DEFERRED: list[Callable[[], object]] = []


def register(kind: str, renderer: Callable[[Any], str]) -> None:
    """Use ``renderer(obj) -> HTML`` for objects of ``kind`` ("program", "posterior", "map")."""
    _RENDERERS[kind] = renderer


def defer(load: Callable[[], object]) -> None:
    """Call ``load()`` before the first display: an import whose module registers renderers."""
    _DEFERRED.append(load)


def html(kind: str, obj: Any) -> str | None:
    """The HTML of ``obj``, or None when no renderer is registered (plain text is shown)."""
    while _DEFERRED:
        _DEFERRED.pop(0)()
    renderer = _RENDERERS.get(kind)
    return renderer(obj) if renderer is not None else None
