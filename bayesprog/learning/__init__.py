"""Identification: learning a program's parameters from data (``Program.fit``,
``bayesprog learn``)."""

from bayesprog.learning.data import Data, DataError, load_data
from bayesprog.learning.fit import Estimate, fit_terms
from bayesprog.learning.write import render_fitted

__all__ = ["Data", "DataError", "Estimate", "fit_terms", "load_data", "render_fitted"]
