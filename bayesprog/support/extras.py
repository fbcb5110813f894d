"""The optional parts of the installation: a feature whose library comes with an extra
(``pip install "bayesprog[tune]"``) says so in one line when that library is missing, instead
of failing with an import error.

>>> require_extra("math", "parquet", "Parquet files").pi > 3
True
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from types import ModuleType
from typing import Any

from bayesprog.errors import BayesprogError


def require_extra(module: str, extra: str, feature: str) -> ModuleType:
    """``module`` imported, or a :class:`BayesprogError` that names the extra to install for
    ``feature`` (the command line prints it and exits with status 2)."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise BayesprogError(f"{feature} needs {module}, which is not installed: install it "
                             f'with pip install "bayesprog[{extra}]"') from None


class LazyModule:
    """A module imported at the first read of one of its names, then read as the module itself:
    a required library that only some questions use (``special = LazyModule("scipy.special")``;
    ``special.ndtr(x)`` imports scipy.special the first time), so that the package and a
    question that does not use it do not wait for it.

    >>> special = LazyModule("math")
    >>> special.sqrt(16.0)
    4.0
    """

    def __init__(self, name: str) -> None:
        self._name = name

    def __getattr__(self, attribute: str) -> Any:
        value = getattr(importlib.import_module(self._name), attribute)
        setattr(self, attribute, value)  # read directly from now on
        return value


def lazy_names(namespace: dict[str, Any], where: Mapping[str, str], package: str
               ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """A package's ``__getattr__`` and ``__dir__`` (PEP 562) for the public names of ``where``
    (name -> the module it lives in): each is imported from its module at its first read and
    kept in ``namespace`` (the package's globals), so that importing the package costs little
    and later reads are plain attribute reads."""

    def __getattr__(name: str) -> Any:
        module = where.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(where))

    return __getattr__, __dir__
