"""Rich display hooks (IPython's ``_repr_html_``): programs and answers ask here for their HTML.

The renderers live in :mod:`bayesprog.display`, above the layers whose objects they draw, and
register themselves when the package is imported; so the engine and the program never import
plotting code, and nothing is drawn until something is displayed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

_RENDERERS: dict[str, Callable[[Any], str]] = {}


def register(kind: str, renderer: Callable[[Any], str]) -> None:
    """Use ``renderer(obj) -> HTML`` for objects of ``kind`` ("program", "posterior", "map")."""
    _RENDERERS[kind] = renderer


def html(kind: str, obj: Any) -> str | None:
    """The HTML of ``obj``, or None when no renderer is registered (plain text is shown)."""
    renderer = _RENDERERS.get(kind)
    return renderer(obj) if renderer is not None else None
