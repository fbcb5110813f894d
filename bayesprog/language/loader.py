"""Strict YAML loading that remembers where every value came from.

PyYAML follows YAML 1.1: ``no`` and ``on`` become booleans, ``1e-3`` stays a string and a
duplicate key silently wins. Program files are read with YAML 1.2 core rules instead, duplicate
keys and unquoted YAML 1.1 booleans are reported, and every value keeps its line and column so
that later checks can point at it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

import yaml

from bayesprog.errors import Diagnostic

Path = tuple[str | int | float, ...]

_INT = re.compile(r"^[-+]?[0-9]+$")
_FLOAT = re.compile(r"^[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?$")
_INF = re.compile(r"^[-+]?\.(inf|Inf|INF)$")
_NAN = re.compile(r"^\.(nan|NaN|NAN)$")
_YAML11_BOOL = re.compile(r"^(y|Y|yes|Yes|YES|n|N|no|No|NO|on|On|ON|off|Off|OFF)$")


@dataclass
class Located:
    """A loaded document: plain Python data plus the position of every path inside it."""

    data: Any
    file: str
    positions: dict[Path, tuple[int, int]] = field(default_factory=dict)
    key_positions: dict[Path, tuple[int, int]] = field(default_factory=dict)

    def where(self, path: Path) -> tuple[int, int]:
        """Line and column of ``path``, or of its closest located ancestor."""
        path = tuple(path)
        while path not in self.positions and path:
            path = path[:-1]
        return self.positions.get(path, (1, 1))

    def diagnostic(self, path: Path, message: str, at_key: bool = False) -> Diagnostic:
        """A diagnostic at ``path``'s value (or at its key, with ``at_key``)."""
        path = tuple(path)
        if at_key and path in self.key_positions:
            line, column = self.key_positions[path]
        else:
            line, column = self.where(path)
        return Diagnostic(self.file, line, column, message)


def _plain_scalar(value: str) -> Any:
    if value in ("", "~", "null", "Null", "NULL"):
        return None
    if value in ("true", "True", "TRUE"):
        return True
    if value in ("false", "False", "FALSE"):
        return False
    if _INT.match(value):
        return int(value)
    if _FLOAT.match(value):
        return float(value)
    if _INF.match(value):
        return -math.inf if value.startswith("-") else math.inf
    if _NAN.match(value):
        return math.nan
    return value


def load_yaml(text: str, file: str) -> tuple[Located, list[Diagnostic]]:
    """Parse ``text`` strictly. Returns the located data and the problems found (maybe several)."""
    problems: list[Diagnostic] = []
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line, column = (mark.line + 1, mark.column + 1) if mark else (1, 1)
        message = f"malformed YAML: {exc.problem or exc.context}"
        return Located(None, file), [Diagnostic(file, line, column, message)]
    except yaml.YAMLError as exc:  # pragma: no cover - every PyYAML error we know carries a mark
        return Located(None, file), [Diagnostic(file, 1, 1, f"malformed YAML: {exc}")]
    located = Located(None, file)
    if node is None:
        return located, [Diagnostic(file, 1, 1, "empty file: expected a program (a mapping)")]

    def build(node: yaml.Node, path: Path) -> Any:
        located.positions[path] = (node.start_mark.line + 1, node.start_mark.column + 1)
        if isinstance(node, yaml.MappingNode):
            out: dict[Any, Any] = {}
            for key_node, value_node in node.value:
                key = build(key_node, path + ("<key>",))
                if not isinstance(key, (str, int, float)):
                    problems.append(located.diagnostic(path + ("<key>",), "expected a plain key"))
                    continue
                key_path = path + (key,)
                if key in out:
                    first = located.where(key_path)
                    line, column = key_node.start_mark.line + 1, key_node.start_mark.column + 1
                    problems.append(
                        Diagnostic(
                            file,
                            line,
                            column,
                            f"duplicate key {key!r}: expected each key once, "
                            f"found it again (first at line {first[0]})",
                        )
                    )
                    continue
                out[key] = build(value_node, key_path)
                located.key_positions[key_path] = (
                    key_node.start_mark.line + 1,
                    key_node.start_mark.column + 1,
                )
            located.positions.pop(path + ("<key>",), None)
            return out
        if isinstance(node, yaml.SequenceNode):
            return [build(item, path + (i,)) for i, item in enumerate(node.value)]
        assert isinstance(node, yaml.ScalarNode)
        if node.style is not None:  # quoted or block scalar: always a string
            return node.value
        if _YAML11_BOOL.match(node.value):
            problems.append(
                located.diagnostic(
                    path,
                    f"ambiguous unquoted {node.value!r} (a boolean in YAML 1.1): "
                    f"quote it (\"{node.value}\") for a name, or write true/false",
                )
            )
            return node.value
        return _plain_scalar(node.value)

    located.data = build(node, ())
    return located, problems
