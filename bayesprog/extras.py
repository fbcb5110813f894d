"""The optional parts of the installation: a feature whose library comes with an extra
(``pip install "bayesprog[tune]"``) says so in one line when that library is missing, instead
of failing with an import error.

>>> require_extra("math", "parquet", "Parquet files").pi > 3
True
"""

from __future__ import annotations

import importlib
from types import ModuleType

from bayesprog.errors import BayesprogError


def require_extra(module: str, extra: str, feature: str) -> ModuleType:
    """``module`` imported, or a :class:`BayesprogError` that names the extra to install for
    ``feature`` (the command line prints it and exits with status 2)."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise BayesprogError(f"{feature} needs {module}, which is not installed: install it "
                             f'with pip install "bayesprog[{extra}]"') from None
