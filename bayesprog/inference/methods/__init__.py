"""Inference methods, one module each, registered with the cost model when the registry is
first read (:data:`~bayesprog.inference.methods.base.BUILTIN`): the package's own methods load
with the first question that needs them, not with the package."""

from bayesprog.inference.methods.base import (
    Cost,
    Method,
    register_method,
    registered_methods,
    registry_version,
)

__all__ = ["Cost", "Method", "register_method", "registered_methods", "registry_version"]
