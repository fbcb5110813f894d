"""How a program and its answers are shown: in Bayesian-programming notation as text
(:mod:`~bayesprog.views.show`, ``bayesprog show``), drawn as figures (the graphical model, a
data set's scatter matrix: :mod:`~bayesprog.views.draw`, ``bayesprog graph``), and as HTML in
a notebook (:mod:`~bayesprog.views.display`, whose renderers register themselves with
:mod:`bayesprog.support.rich` when it is imported, at the first display).

Above the program; nothing below it imports it, so the engine never loads plotting code.
"""
