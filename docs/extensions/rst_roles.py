"""A griffe extension for the API reference: the docstrings' reStructuredText roles
(``:func:`load```, ``:class:`~bayesprog.Program```) as Markdown code spans, which is how they
read in a terminal's ``help()`` too."""

from __future__ import annotations

import re
from typing import Any

import griffe

#: a role and its target: :func:`name`, :class:`~module.Name`
_ROLE = re.compile(r":(?:func|class|meth|attr|mod|data|obj|exc):`~?([^`]+)`")


class RstRoles(griffe.Extension):
    """Rewrite roles in every docstring as the object loads."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = _ROLE.sub(lambda m: f"`{m.group(1)}`", obj.docstring.value)
