"""Answering questions: bind the evidence, plan the question, let the cost model pick a method.

The path of a question: :func:`~bayesprog.inference.binding.bind` checks the evidence, inputs
and soft evidence and flattens them to one batch axis; a
:class:`~bayesprog.inference.plan.QuestionPlan` holds the relevant terms;
:func:`~bayesprog.inference.cost.ranked` orders the methods that apply by estimated cost (the
ranking is kept per layout of the question: same variables known, any batch size); the cheapest
answers, or hands over to the next when some rows are beyond it. MAP questions then choose the
argmax of that posterior (:func:`~bayesprog.inference.answers.choose_map`).

Methods live in :mod:`bayesprog.inference.methods`, one module each, registered there: the
dispatcher knows them only through the registry. What it keeps per layout of question is one
:class:`~bayesprog.inference.schedule.Schedule`.
"""

from typing import TYPE_CHECKING

from bayesprog.support.extras import lazy_names

#: Where each public name lives. They are imported when first used: a program that is loaded,
#: learned or checked, and never asked, does not import the question machinery.
_WHERE = {
    "Bound": "bayesprog.inference.binding",
    "bind": "bayesprog.inference.binding",
    "Cost": "bayesprog.inference.methods",
    "InferenceCache": "bayesprog.inference.core",
    "MapResult": "bayesprog.inference.answers",
    "Method": "bayesprog.inference.methods",
    "Posterior": "bayesprog.inference.answers",
    "ProgramLike": "bayesprog.inference.protocol",
    "QuestionPlan": "bayesprog.inference.plan",
    "ask": "bayesprog.inference.dispatch",
    "compute_posterior": "bayesprog.inference.dispatch",
    "register_method": "bayesprog.inference.methods",
    "registered_methods": "bayesprog.inference.methods",
}

if TYPE_CHECKING:  # what the names are, for type checkers and editors
    from bayesprog.inference.answers import MapResult, Posterior
    from bayesprog.inference.binding import Bound, bind
    from bayesprog.inference.core import InferenceCache
    from bayesprog.inference.dispatch import ask, compute_posterior
    from bayesprog.inference.methods import Cost, Method, register_method, registered_methods
    from bayesprog.inference.plan import QuestionPlan
    from bayesprog.inference.protocol import ProgramLike


__getattr__, __dir__ = lazy_names(globals(), _WHERE, __name__)


__all__ = [
    "Bound", "Cost", "InferenceCache", "MapResult", "Method", "Posterior", "ProgramLike",
    "QuestionPlan", "ask", "bind", "compute_posterior", "register_method", "registered_methods",
]
