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

from bayesprog.support import rich
from bayesprog.support.extras import lazy_names
from bayesprog.support.moved import old_paths

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
    "Question": "bayesprog.vocabulary.expressions",
    "canonical": "bayesprog.vocabulary.expressions",
    "atomic_write": "bayesprog.support.files",
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
    "wrong_kind": "bayesprog.support.files",
    "reference_problem": "bayesprog.support.files",
    "SizeError": "bayesprog.limits",
    "check_size": "bayesprog.limits",
    "limit": "bayesprog.limits",
    "Term": "bayesprog.model",
    "Program": "bayesprog.program",
    "load": "bayesprog.program",
    "loads": "bayesprog.program",
    "show_inference": "bayesprog.views.display",
    "render_values": "bayesprog.learning.write",
    "discover": "bayesprog.program.discovery",
    "bundled_path": "bayesprog.support.bundled",
    "bundled_root": "bayesprog.support.bundled",
    "require_extra": "bayesprog.support.extras",
    "compare": "bayesprog.learning.evidence",
    "read_data": "bayesprog.learning.data",
    "BadRow": "bayesprog.learning.csv_rows",
    "BadRowsWarning": "bayesprog.learning.data",
    "Discovery": "bayesprog.program.discovery",
    "StructureWarning": "bayesprog.program.discovery",
    "Summary": "bayesprog.learning.summary",
    "summarise": "bayesprog.learning.summary",
    "scatter_matrix": "bayesprog.views.draw",
}

#: The modules that stood directly in bayesprog/ until 0.5, and the packages they live in now.
#: Their old paths still work (``import bayesprog.bundled``, ``from bayesprog.files import
#: atomic_write``, ``bayesprog.expressions`` read as an attribute, a pickle that names a class
#: by its old module): each is the same module under both names, imported at its first use.
#: (``bayesprog.program`` and ``bayesprog.model`` are packages of those names: their public
#: names are read from them as before.)
_MOVED = {
    "bundled": "bayesprog.support.bundled",
    "cache": "bayesprog.support.cache",
    "extras": "bayesprog.support.extras",
    "files": "bayesprog.support.files",
    "rich": "bayesprog.support.rich",
    "yamltext": "bayesprog.support.yamltext",
    "expressions": "bayesprog.vocabulary.expressions",
    "formula": "bayesprog.vocabulary.formula",
    "variables": "bayesprog.vocabulary.variables",
    "records": "bayesprog.model.records",
    "dynamic": "bayesprog.program.dynamic",
    "discovery": "bayesprog.program.discovery",
    "show": "bayesprog.views.show",
    "draw": "bayesprog.views.draw",
    "display": "bayesprog.views.display",
    "compile": "bayesprog.io.compile",
}

if TYPE_CHECKING:  # what the names are, for type checkers and editors
    from bayesprog.errors import (
        BayesprogError,
        Diagnostic,
        QuestionError,
        SpecError,
        ZeroEvidenceError,
        short_repr,
    )
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
    from bayesprog.program.discovery import Discovery, StructureWarning, discover
    from bayesprog.support.bundled import bundled_path, bundled_root
    from bayesprog.support.extras import require_extra
    from bayesprog.support.files import atomic_write, reference_problem, wrong_kind
    from bayesprog.views.display import show_inference
    from bayesprog.views.draw import scatter_matrix
    from bayesprog.vocabulary.expressions import Question, canonical


def _load_display() -> None:
    from bayesprog.views import display  # noqa: F401  (its renderers register themselves)


# Programs and answers render themselves in a notebook through the hooks of
# bayesprog.support.rich, on the package's lowest floor; the notebook display, near its top, is
# imported at the first display.
rich.defer(_load_display)


__getattr__, __dir__ = lazy_names(globals(), _WHERE, __name__)
__getattr__ = old_paths(__name__, _MOVED, __getattr__)


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
