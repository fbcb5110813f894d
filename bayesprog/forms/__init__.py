"""Parametric forms: a registry of small classes, each declaring its parameters as data."""

from bayesprog.forms import lognormal as _lognormal  # noqa: F401  (registers lognormal)
from bayesprog.forms import standard as _standard  # noqa: F401  (registers the standard forms)
from bayesprog.forms import subprogram as _subprogram  # noqa: F401  (registers the program form)
from bayesprog.forms.base import (
    Constraint,
    Form,
    FormulaParam,
    InputRef,
    Param,
    ParamValue,
    TermContext,
    available_forms,
    formula_values,
    get_form,
    is_binned,
    nonnegative,
    positive,
    real,
    register_form,
    simplex,
    unit_interval,
    unknown_form,
)

__all__ = [
    "Constraint",
    "Form",
    "FormulaParam",
    "InputRef",
    "Param",
    "ParamValue",
    "TermContext",
    "available_forms",
    "get_form",
    "formula_values",
    "is_binned",
    "nonnegative",
    "positive",
    "real",
    "register_form",
    "simplex",
    "unit_interval",
    "unknown_form",
]
