"""The build step of an editable install (``pip install -e .``): the checkout's modules compiled
to bytecode where they are, as an installer compiles the modules of a regular install.

An editable install runs the sources of the checkout, and an installer compiles only the files
it copies: where Python writes no bytecode at run time (``PYTHONDONTWRITEBYTECODE=1``, as
development containers often set it), every start of such an install would compile the modules
it imports again (a first question compiles 53 modules, 10,700 lines: 0.12 s of its 0.32 s).
Compiled here, they are read as a wheel's are. A module edited later is compiled at its
imports, as Python does for any source newer than its bytecode (where no bytecode is written,
at every start until the next install).
"""

from __future__ import annotations

import compileall
from pathlib import Path
from typing import Any

from hatchling.builders.hooks.plugin.interface import BuildHookInterface

#: the packages an editable install runs from the checkout
PACKAGES = ("bayesprog", "runner")


class EditableBytecode(BuildHookInterface):  # type: ignore[type-arg]
    """Compiles the packages in place when the wheel built is an editable one."""

    PLUGIN_NAME = "custom"

    def initialize(self, version: str, build_data: dict[str, Any]) -> None:
        if self.target_name != "wheel" or version != "editable":
            return
        for package in PACKAGES:
            # a folder that cannot be written leaves the install as it was without this step
            compileall.compile_dir(Path(self.root) / package, quiet=2)
