"""A program as its users hold it: :class:`Program` (read by :func:`load` and :func:`loads`,
asked questions, ablated, fitted to data into a :class:`Fit`), in
:mod:`~bayesprog.program.program`; a program of one time step asked over many (filter,
smooth, the most likely sequence: :mod:`~bayesprog.program.dynamic`); a program's
decomposition discovered from data (:mod:`~bayesprog.program.discovery`).

Above the language, the engine and the learning, which it puts together; below the views and
the command line.
"""

from bayesprog.program.program import Fit, Program, load, loads

__all__ = ["Fit", "Program", "load", "loads"]
