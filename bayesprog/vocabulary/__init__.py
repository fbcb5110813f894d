"""The words a program is written with, shared by every layer above: its variables (discrete:
named states, integer ranges, grids, bins; continuous, and fields indexed by a discrete one:
:mod:`~bayesprog.vocabulary.variables`), the ``P(left | right)`` notation of terms, questions
and ablations (:mod:`~bayesprog.vocabulary.expressions`), and the formulas a parameter may be
given as (:mod:`~bayesprog.vocabulary.formula`).

It imports nothing of bayesprog but its errors (:mod:`bayesprog.errors`); the forms, the
language, the engine and the learning all read it.
"""
