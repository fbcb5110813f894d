"""The old paths of modules that moved: ``import bayesprog.bundled``, ``from bayesprog.files
import atomic_write``, ``bayesprog.expressions`` read as an attribute, a pickle that names a
class by the module it was defined in then, all keep working after the module has moved to a
sub-package (:mod:`bayesprog.support.bundled`, ...): the old name is the module itself, the same
object under both names, imported at the first use of either."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from importlib.machinery import ModuleSpec
from types import ModuleType
from typing import TYPE_CHECKING, Any, cast

if TYPE_CHECKING:
    from importlib.abc import Loader


class MovedModules:
    """A finder of the import system (:data:`sys.meta_path`) for modules that moved: the old
    full name ``old`` is the module ``moved[old]``. Asked only for names no file answers.

    >>> finder = MovedModules({"an_old_name_of_json": "json"})
    >>> sys.meta_path.append(finder)
    >>> import json, an_old_name_of_json
    >>> an_old_name_of_json is json, json.__spec__.name
    (True, 'json')
    >>> sys.meta_path.remove(finder); del sys.modules["an_old_name_of_json"]
    """

    def __init__(self, moved: Mapping[str, str]) -> None:
        self.moved = dict(moved)
        #: the module's own spec while the import system has put the old name's in its place
        self._specs: dict[str, ModuleSpec | None] = {}

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> ModuleSpec | None:
        # a loader by its methods (importlib.abc, whose base it would take, costs the
        # package's start-up more than this module)
        return ModuleSpec(name, cast("Loader", self)) if name in self.moved else None

    def create_module(self, spec: ModuleSpec) -> ModuleType:
        module = importlib.import_module(self.moved[spec.name])
        self._specs[spec.name] = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run (the module ran under its own name); its own spec put back, which the
        import system replaced with the old name's."""
        spec = module.__spec__
        if spec is not None and spec.name in self._specs:
            module.__spec__ = self._specs.pop(spec.name)


def old_paths(package: str, moved: Mapping[str, str], getattr_: Callable[[str], Any]
              ) -> Callable[[str], Any]:
    """Make the modules that stood in ``package`` and live elsewhere now (``moved``: the old
    name in the package -> the module's full name now) importable at their old paths, and
    return the package's ``__getattr__`` (PEP 562): ``getattr_``'s, and the moved modules read
    as attributes of the package."""
    if not any(isinstance(f, MovedModules) and f.moved.keys() >= {f"{package}.{n}" for n in moved}
               for f in sys.meta_path):  # (once, should the package be imported again)
        sys.meta_path.append(MovedModules({f"{package}.{old}": new for old, new in moved.items()}))

    def __getattr__(name: str) -> Any:
        if name in moved:
            return importlib.import_module(f"{package}.{name}")  # (kept as the attribute)
        return getattr_(name)

    return __getattr__
