"""Shared test set-up."""

import warnings

with warnings.catch_warnings():
    # pyAgrum's SWIG module emits DeprecationWarnings while it loads and crashes the interpreter
    # when they are errors (pytest runs with warnings as errors); pgmpy warns about its own
    # deprecated modules. Import both once, quietly, before any test module does.
    warnings.simplefilter("ignore")
    import pgmpy.inference  # noqa: F401
    import pyagrum  # noqa: F401
