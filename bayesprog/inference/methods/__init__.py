"""Inference methods, one module each; importing this package registers them."""

from bayesprog.inference.methods import contraction as _contraction  # noqa: F401  (registers)
from bayesprog.inference.methods import gaussian as _gaussian  # noqa: F401  (registers)
from bayesprog.inference.methods import gibbs as _gibbs  # noqa: F401  (registers)
from bayesprog.inference.methods import grid as _grid  # noqa: F401  (registers)
from bayesprog.inference.methods import lbp as _lbp  # noqa: F401  (registers)
from bayesprog.inference.methods import lw as _lw  # noqa: F401  (registers)
from bayesprog.inference.methods import table as _table  # noqa: F401  (registers)
from bayesprog.inference.methods.base import (
    Cost,
    Method,
    mark_builtin,
    register_method,
    registered_methods,
    registry_version,
)

mark_builtin()

__all__ = ["Cost", "Method", "register_method", "registered_methods", "registry_version"]
