"""A griffe extension for the API reference: the docstrings' reStructuredText roles
(``:func:`load```, ``:class:`~bayesprog.Program```) as Markdown code spans, which is how they
read in a terminal's ``help()`` too, and their doctest examples (``>>>`` lines and the output
under them, up to a blank line) as Python console blocks."""

from __future__ import annotations

import re
from typing import Any

import griffe

#: a role and its target: :func:`name`, :class:`~module.Name`
_ROLE = re.compile(r":(?:func|class|meth|attr|mod|data|obj|exc):`~?([^`]+)`")


def _fenced(text: str) -> str:
    """Each doctest example of ``text`` in a ``pycon`` fence."""
    out: list[str] = []
    inside = False
    for line in text.splitlines():
        starts = line.lstrip().startswith(">>>")
        if starts and not inside:
            out.append("```pycon")
            inside = True
        elif inside and not line.strip():
            out.append("```")
            inside = False
        out.append(line)
    if inside:
        out.append("```")
    return "\n".join(out)


class RstRoles(griffe.Extension):
    """Rewrite roles and examples in every docstring as the object loads."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            text = _ROLE.sub(lambda m: f"`{m.group(1)}`", obj.docstring.value)
            obj.docstring.value = _fenced(text)
