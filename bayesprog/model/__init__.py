"""The program's data types: what a checked program is made of (:class:`Term`,
:class:`InputDecl`, :class:`LearnOptions`, in :mod:`~bayesprog.model.terms`) and the records of
a fit or of a discovered structure as a fitted file carries them
(:mod:`~bayesprog.model.records`).

Below both the language that builds them from YAML (:mod:`bayesprog.language`) and the
inference and learning that use them, which never import the language.
"""

from bayesprog.model.terms import InputDecl, LearnOptions, Term

__all__ = ["InputDecl", "LearnOptions", "Term"]
