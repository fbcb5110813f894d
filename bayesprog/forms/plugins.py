"""Forms of installed packages: the ``bayesprog.forms`` entry point group.

A package declares each of its forms as an entry point named after the form, whose object is a
:class:`~bayesprog.forms.base.Form` subclass (or an instance of one)::

    [project.entry-points."bayesprog.forms"]
    exponential = "bayesprog_exponential:Exponential"

The group is read, and a plugin imported, only when a program names a form that is not
registered (:func:`bayesprog.forms.base.get_form`): a program of the built-in forms reads no
package metadata, and a package whose import fails takes down only the programs that use its
form, with a message naming the entry point and its package.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any

#: The entry point group of the forms of installed packages.
GROUP = "bayesprog.forms"


@dataclass(frozen=True)
class Plugin:
    """One entry point of the group: the form's ``name``, the ``value`` it points at
    (``module:object``) and the package that declares it (``name version``)."""

    name: str
    value: str
    package: str
    entry_point: Any

    def __str__(self) -> str:
        return f"entry point '{self.name} = {self.value}' of package {self.package}"

    def load(self) -> Any:
        """The object the entry point names (importing its module)."""
        return self.entry_point.load()


@cache
def installed() -> dict[str, Plugin]:
    """The group's entry points by name (a name declared twice: the first found on the path)."""
    from importlib.metadata import entry_points

    found: dict[str, Plugin] = {}
    for ep in entry_points(group=GROUP):
        if ep.name in found:
            continue
        dist = getattr(ep, "dist", None)
        package = f"{dist.name} {dist.version}" if dist is not None else "(unknown)"
        found[ep.name] = Plugin(ep.name, ep.value, package, ep)
    return found
