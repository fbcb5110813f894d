"""Rich display hooks (IPython's ``_repr_html_``): programs and answers ask here for their HTML.

The renderers live in :mod:`bayesprog.display`, above the layers whose objects they draw, and
register themselves when that module is imported: at the first display, by name (so the engine
and the program never import plotting code, and ``import bayesprog`` loads none of it).
"""

from __future__ import annotations

from collections.abc import Callable
from importlib import import_module
from typing import Any

_RENDERERS: dict[str, Callable[[Any], str]] = {}


def register(kind: str, renderer: Callable[[Any], str]) -> None:
    """Use ``renderer(obj) -> HTML`` for objects of ``kind`` ("program", "posterior", "map")."""
    _RENDERERS[kind] = renderer


def html(kind: str, obj: Any) -> str | None:
    """The HTML of ``obj``, or None when no renderer is registered (plain text is shown)."""
    if not _RENDERERS:
        import_module("bayesprog.display")  # registers the package's renderers
    renderer = _RENDERERS.get(kind)
    return renderer(obj) if renderer is not None else None
