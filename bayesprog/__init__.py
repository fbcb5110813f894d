"""bayesprog: Bayesian programs written as YAML, compiled once and asked questions in batches.

>>> import bayesprog
>>> program = bayesprog.loads('''
... bayesprog: 1
... variables:
...   M: {states: [wood, silicone]}
...   E: {continuous: [-.inf, .inf]}
... decomposition:
...   - {term: P(M), form: uniform}
...   - {term: P(E | M), form: normal, mean: {wood: 0.5, silicone: 0.1}, sigma: 0.1}
... ''')
>>> program.ask("P(M | E)", {"E": [0.45, 0.15]}).probabilities.round(3).tolist()
[[0.998, 0.002], [0.002, 0.998]]
"""

from typing import TYPE_CHECKING

from bayesprog import rich
from bayesprog.extras import lazy_names

__version__ = "0.5.0"

#: Where each public name lives. They are imported when first used, so that ``import
#: bayesprog`` costs little (a command-line question pays only for what it asks; the notebook
#: display and the drawing load matplotlib-side modules only when a figure is drawn).
_WHERE = {
    "BayesprogError": "bayesprog.errors",
    "Diagnostic": "bayesprog.errors",
    "QuestionError": "bayesprog.errors",
    "SpecError": "bayesprog.errors",
    "ZeroEvidenceError": "bayesprog.errors",
    "short_repr": "bayesprog.errors",
    "did_you_mean": "bayesprog.errors",
    "Question": "bayesprog.expressions",
    "canonical": "bayesprog.expressions",
    "atomic_write": "bayesprog.files",
    "Form": "bayesprog.forms",
    "Param": "bayesprog.forms",
    "ParamValue": "bayesprog.forms",
    "available_forms": "bayesprog.forms",
    "register_form": "bayesprog.forms",
    "MapResult": "bayesprog.inference",
    "Posterior": "bayesprog.inference",
    "Density": "bayesprog.inference.density",
    "Probability": "bayesprog.inference.event",
    "load_document": "bayesprog.language.document",
    "Located": "bayesprog.language.loader",
    "load_yaml": "bayesprog.language.loader",
    "wrong_kind": "bayesprog.files",
    "reference_problem": "bayesprog.files",
    "SizeError": "bayesprog.limits",
    "check_size": "bayesprog.limits",
    "limit": "bayesprog.limits",
    "Term": "bayesprog.model",
    "Program": "bayesprog.program",
    "load": "bayesprog.program",
    "loads": "bayesprog.program",
    "show_inference": "bayesprog.display",
    "render_values": "bayesprog.learning.write",
    "discover": "bayesprog.discovery",
    "bundled_path": "bayesprog.bundled",
    "bundled_root": "bayesprog.bundled",
    "require_extra": "bayesprog.extras",
    "compare": "bayesprog.learning.evidence",
    "read_data": "bayesprog.learning.data",
    "BadRow": "bayesprog.learning.csv_rows",
    "BadRowsWarning": "bayesprog.learning.data",
    "Discovery": "bayesprog.discovery",
    "StructureWarning": "bayesprog.discovery",
    "Summary": "bayesprog.learning.summary",
    "summarise": "bayesprog.learning.summary",
    "scatter_matrix": "bayesprog.draw",
}

if TYPE_CHECKING:  # what the names are, for type checkers and editors
    from bayesprog.bundled import bundled_path, bundled_root
    from bayesprog.discovery import Discovery, StructureWarning, discover
    from bayesprog.display import show_inference
    from bayesprog.draw import scatter_matrix
    from bayesprog.errors import (
        BayesprogError,
        Diagnostic,
        QuestionError,
        SpecError,
        ZeroEvidenceError,
        short_repr,
    )
    from bayesprog.expressions import Question, canonical
    from bayesprog.extras import require_extra
    from bayesprog.files import atomic_write, reference_problem, wrong_kind
    from bayesprog.forms import Form, Param, ParamValue, available_forms, register_form
    from bayesprog.inference import MapResult, Posterior
    from bayesprog.inference.density import Density
    from bayesprog.inference.event import Probability
    from bayesprog.language.document import load_document
    from bayesprog.language.loader import Located, load_yaml
    from bayesprog.learning.csv_rows import BadRow
    from bayesprog.learning.data import BadRowsWarning, read_data
    from bayesprog.learning.evidence import compare
    from bayesprog.learning.summary import Summary, summarise
    from bayesprog.learning.write import render_values
    from bayesprog.limits import SizeError, check_size, limit
    from bayesprog.model import Term
    from bayesprog.program import Program, load, loads


def _load_display() -> None:
    from bayesprog import display  # noqa: F401  (its renderers register themselves)


# Programs and answers render themselves in a notebook through the hooks of bayesprog.rich, the
# package's lowest floor; the notebook display, near its top, is imported at the first display.
rich.defer(_load_display)


__getattr__, __dir__ = lazy_names(globals(), _WHERE, __name__)


__all__ = [
    # programs, questions and their answers
    "BayesprogError",
    "did_you_mean",
    "Density",
    "Diagnostic",
    "Form",
    "MapResult",
    "Param",
    "Posterior",
    "Probability",
    "Program",
    "Question",
    "QuestionError",
    "SpecError",
    "Term",
    "ZeroEvidenceError",
    "available_forms",
    "load",
    "loads",
    "register_form",
    "show_inference",
    # structure: a decomposition discovered from data, programs compared by their evidence
    "Discovery",
    "StructureWarning",
    "compare",
    "discover",
    # data sets: summarised group by group, drawn pair by pair
    "Summary",
    "scatter_matrix",
    "summarise",
    # data sets: their rows that can be read, the bad ones set aside and named (read_data,
    # BadRow; Program.fit(on_bad_lines=...) warns with BadRowsWarning)
    "BadRow",
    "BadRowsWarning",
    "read_data",
    # for applications built on bayesprog (runner plugins, see bayesprog.cli): their own
    # YAML files read with the same diagnostics (load_yaml, load_document, Located,
    # wrong_kind; reference_problem for the files they name), the same size limits
    # (check_size, SizeError, limit), files written whole (atomic_write), a term's canonical
    # spelling and its parameters (canonical, ParamValue), learned values written into a
    # program's text (render_values), short reprs in messages, their bundled files found by
    # name (bundled_path, bundled_root), a missing extra named (require_extra)
    "Located",
    "ParamValue",
    "SizeError",
    "atomic_write",
    "bundled_path",
    "bundled_root",
    "canonical",
    "check_size",
    "limit",
    "load_document",
    "load_yaml",
    "reference_problem",
    "render_values",
    "require_extra",
    "short_repr",
    "wrong_kind",
]
