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

from bayesprog.display import show_inference
from bayesprog.errors import BayesprogError, Diagnostic, QuestionError, SpecError, ZeroEvidenceError
from bayesprog.expressions import Question
from bayesprog.forms import Form, Param, available_forms, register_form
from bayesprog.inference import MapResult, Posterior
from bayesprog.inference.density import Density
from bayesprog.program import Program, load, loads

__version__ = "0.1.0"

__all__ = [
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
    "ZeroEvidenceError",
    "available_forms",
    "load",
    "loads",
    "register_form",
    "show_inference",
]
