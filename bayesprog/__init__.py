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

from typing import Any

from bayesprog.display import show_inference
from bayesprog.errors import (
    BayesprogError,
    Diagnostic,
    QuestionError,
    SpecError,
    ZeroEvidenceError,
    short_repr,
)
from bayesprog.expressions import Question, canonical
from bayesprog.files import atomic_write
from bayesprog.forms import Form, Param, ParamValue, available_forms, register_form
from bayesprog.inference import MapResult, Posterior
from bayesprog.inference.density import Density
from bayesprog.language.document import load_document
from bayesprog.language.loader import Located, load_yaml, wrong_kind
from bayesprog.limits import SizeError, check_size, limit
from bayesprog.model import Term
from bayesprog.program import Program, load, loads

__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    # the learning layer (and ruamel.yaml) is loaded when it is first used, never at import
    if name == "render_values":
        from bayesprog.learning.write import render_values

        return render_values
    raise AttributeError(f"module 'bayesprog' has no attribute {name!r}")


__all__ = [
    # programs, questions and their answers
    "BayesprogError",
    "Density",
    "Diagnostic",
    "Form",
    "MapResult",
    "Param",
    "Posterior",
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
    # for applications built on bayesprog (runner plugins, see bayesprog.cli): their own
    # YAML files read with the same diagnostics (load_yaml, load_document, Located,
    # wrong_kind), the same size limits (check_size, SizeError, limit), files written whole
    # (atomic_write), a term's canonical spelling and its parameters (canonical, ParamValue),
    # learned values written into a program's text (render_values), short reprs in messages
    "Located",
    "ParamValue",
    "SizeError",
    "atomic_write",
    "canonical",
    "check_size",
    "limit",
    "load_document",
    "load_yaml",
    "render_values",
    "short_repr",
    "wrong_kind",
]
