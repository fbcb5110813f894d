"""Identification: learning a program's parameters from data (``Program.fit``,
``bayesprog learn``), and the data sets it learns from, summarised group by group
(``bayesprog show DATA.csv``).

The names are imported at their first read: ``bayesprog learn`` starts reading its data file
(:class:`~bayesprog.learning.plain_csv.ReadAhead`) before the fit's modules are imported."""

from typing import TYPE_CHECKING

from bayesprog.support.extras import lazy_names

_WHERE = {
    "BadRow": "bayesprog.learning.csv_rows",
    "BadRowError": "bayesprog.learning.data",
    "BadRowsWarning": "bayesprog.learning.data",
    "Data": "bayesprog.learning.data",
    "DataError": "bayesprog.learning.data",
    "load_data": "bayesprog.learning.data",
    "read_data": "bayesprog.learning.data",
    "Estimate": "bayesprog.learning.fit",
    "fit_terms": "bayesprog.learning.fit",
    "render_fitted": "bayesprog.learning.write",
    "Summary": "bayesprog.learning.summary",
    "summarise": "bayesprog.learning.summary",
}

if TYPE_CHECKING:  # what the names are, for type checkers and editors
    from bayesprog.learning.csv_rows import BadRow
    from bayesprog.learning.data import (
        BadRowError,
        BadRowsWarning,
        Data,
        DataError,
        load_data,
        read_data,
    )
    from bayesprog.learning.fit import Estimate, fit_terms
    from bayesprog.learning.summary import Summary, summarise
    from bayesprog.learning.write import render_fitted

__getattr__, __dir__ = lazy_names(globals(), _WHERE, __name__)

__all__ = ["BadRow", "BadRowError", "BadRowsWarning", "Data", "DataError", "Estimate",
           "Summary", "fit_terms", "load_data", "read_data", "render_fitted", "summarise"]
