"""Strict YAML loading that remembers where every value came from.

PyYAML follows YAML 1.1: ``no`` and ``on`` become booleans, ``1e-3`` stays a string and a
duplicate key silently wins. Program files are read with YAML 1.2 core rules instead: ``yes``,
``no``, ``on``, ``off``, ``y``, ``n`` are words, only ``true``/``false`` are booleans and only
``null``/``~`` is null; duplicate keys are reported; every value keeps its line and column so
that later checks can point at it, and a plain scalar that YAML reads as a number, a boolean or
null keeps its text too (:attr:`Located.texts`), so that where a name stands (a key, a state)
the name is the text as written: ``1.50``, ``true``, ``null``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

import yaml

from bayesprog.errors import Diagnostic
from bayesprog.support import yamltext
from bayesprog.support.files import a_or_an
from bayesprog.support.yamltext import FAST_LOADER

Path = tuple[str | int | float, ...]

_INT = re.compile(r"^[-+]?[0-9]+$")
_FLOAT = re.compile(r"^[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?$")
_INF = re.compile(r"^[-+]?\.(inf|Inf|INF)$")
_NAN = re.compile(r"^\.(nan|NaN|NAN)$")


@dataclass
class Located:
    """A loaded document: plain Python data plus the position of every path inside it."""

    data: Any
    file: str
    positions: dict[Path, tuple[int, int]] = field(default_factory=dict)
    key_positions: dict[Path, tuple[int, int]] = field(default_factory=dict)
    #: the text of each number, as written (``1.50``), for where a name stands
    texts: dict[Path, str] = field(default_factory=dict)
    #: the paths of values written in quotes on one line (their text starts a column later)
    quoted: set[Path] = field(default_factory=set)
    #: tables of numbers read as arrays (see :func:`bayesprog.support.yamltext.number_blocks`): their text, by path
    blocks: dict[Path, str] = field(default_factory=dict)

    def where(self, path: Path) -> tuple[int, int]:
        """Line and column of ``path``, or of its closest located ancestor."""
        path = tuple(path)
        inside: list[Any] = []
        while path not in self.positions and path:
            inside.insert(0, path[-1])
            path = path[:-1]
        line, column = self.positions.get(path, (1, 1))
        if inside and path in self.blocks:  # a row or a number of a table read as an array
            return _position_in_block(self.blocks[path], line, column, inside)
        return line, column

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


_TOKENS = {"<scalar>": "a value", "<stream end>": "the end of the file",
           "<block end>": "the end of the indented block", "'?'": "a key",
           "<block mapping start>": "a key indented more than the lines above it", "'-'": "a list item",
           "<block sequence start>": "a list", "'{'": "'{'", "'['": "'['"}


def _token(text: str) -> str:
    text = text.strip()
    if text.startswith("'<") and text.endswith(">'"):
        text = text[1:-1]
    return _TOKENS.get(text, text)


def yaml_problem(exc: yaml.MarkedYAMLError, text: str) -> str:
    """PyYAML's complaint in plain words: what was expected, what was found (and where the
    construct that is not finished began)."""
    problem = (exc.problem or exc.context or "").strip()
    where = ""
    if exc.context_mark is not None and exc.problem_mark is not None and \
            exc.context_mark.line != exc.problem_mark.line:
        where = f" (the {{...}} or [...] opened at line {exc.context_mark.line + 1})" \
            if "flow" in (exc.context or "") else \
            f" (in what began at line {exc.context_mark.line + 1})"
    indented = _misindented(text, exc)
    if indented:
        return indented
    found = re.match(r"expected (.+), but (?:found|got) (.+)$", problem)
    if found:
        expected, got = found.groups()
        expected = expected.replace("',' or '}'", "',' or '}' (the end of a {...} mapping)")
        expected = expected.replace("',' or ']'", "',' or ']' (the end of a [...] list)")
        return f"malformed YAML: expected {_token(expected)}, found {_token(got)}{where}"
    if "found another document" in problem:
        return ("malformed YAML: expected one document, found a second (after a '---' line): "
                "a file holds one program")
    if "mapping values are not allowed here" in problem:
        return ("malformed YAML: expected one 'key: value' per line, found a second ':' "
                "(quote a value that contains ': ')")
    if "cannot start any token" in problem and "\\t" in problem:
        return "malformed YAML: expected spaces for indentation, found a tab"
    if "found unexpected end of stream" in problem:
        return (f"malformed YAML: expected the closing quote of a string, found the end of the "
                f"file{where}")
    if "could not find expected ':'" in problem:
        return f"malformed YAML: expected 'key: value', found a line without ':'{where}"
    return f"malformed YAML: {problem}{where}"


#: a line that holds a key: its leading spaces and list dashes, then the key and its colon
_KEY_LINE = re.compile(r"^(?P<lead>[ ]*(?:-[ ]+)*)(?P<key>[^\s#:{}\[\],&*!|>'\"%@`][^:#]*?)"
                       r"[ ]*:(?:[ ]|$)")


def _key_at(line: str) -> tuple[int, str] | None:
    """(the column of the key, the key) of a line that starts with ``key:``, else None."""
    match = _KEY_LINE.match(line)
    return (len(match["lead"]), match["key"].strip()) if match else None


def _misindented(text: str, exc: yaml.MarkedYAMLError) -> str | None:
    """A key that is not lined up with the keys beside it, said as such: indented less than
    the key above it (which PyYAML takes for a key indented more than the block it closes), or
    more (a second ':' in what PyYAML reads as the line above's value going on)."""
    mark = exc.problem_mark
    problem = exc.problem or ""
    if mark is None:
        return None
    lines = text.splitlines()
    if mark.line >= len(lines):
        return None
    here = _key_at(lines[mark.line])
    if here is None:
        return None
    column, key = here
    above: tuple[int, tuple[int, str] | None] | None = None
    for line_number in range(mark.line - 1, -1, -1):
        stripped = lines[line_number].strip()
        if stripped and not stripped.startswith("#"):
            above = (line_number, _key_at(lines[line_number]))
            break
    if above is None or above[1] is None:
        return None
    number, (their_column, their_key) = above[0], above[1]
    where = f"{their_key!r} on line {number + 1} (column {their_column + 1})"
    if "block mapping start" in problem and column < their_column:
        chain: list[tuple[int, str, int]] = []  # the keys whose blocks hold the line above
        for n in range(number, -1, -1):
            found = _key_at(lines[n])
            if found and (not chain or found[0] < chain[-1][0]):
                chain.append((found[0], found[1], n))
        places = " or ".join(f"{c + 1} ({k!r}, line {n + 1})" for c, k, n in chain)
        return (f"malformed YAML: expected the key {key!r} lined up with the keys beside it, "
                f"found it indented less than {where}: indent it to the column of the key it "
                f"goes beside: {places}")
    if "block mapping start" in problem and column > their_column:
        return (f"malformed YAML: expected the key {key!r} lined up with the keys beside it, "
                f"found it indented more than {where}: only the keys of a mapping opened by "
                f"'{their_key}:' with nothing after the ':' go further in; indent it to column "
                f"{their_column + 1}")
    if "mapping values are not allowed" in problem and mark.column == column + len(key) \
            and column > their_column and lines[number].rstrip()[-1:] != ":":
        return (f"malformed YAML: expected the key {key!r} lined up with the keys beside it, "
                f"found it indented more than {where}, which already has a value (read as "
                f"that value going on over a second line): indent {key!r} to column "
                f"{their_column + 1}")
    return None


def load_yaml(text: str, file: str, kind: str = "program") -> tuple[Located, list[Diagnostic]]:
    """Parse ``text`` strictly (``kind``: what the file should hold, for the messages). Returns
    the located data and the problems found (maybe several)."""
    problems: list[Diagnostic] = []
    # large tables of numbers are read as arrays, not as a YAML node per number
    text, blocks, numbers = yamltext.number_blocks(text)
    if numbers > yamltext.MAX_TABLE_NUMBERS:
        return Located(None, file), [Diagnostic(
            file, 1, 1, f"the file's tables hold at least {numbers:,} numbers, more than the "
            f"{yamltext.MAX_TABLE_NUMBERS:,} a file may hold: give large arrays as inputs (.npy files)")]
    # a linear count before anything is built: no file holds more values than it has commas
    # and lines, and one past the limit is refused without parsing it
    estimate = text.count(",") + text.count("\n")
    if estimate > MAX_VALUES:
        values = _count_values(text)
        if values > MAX_VALUES:
            return Located(None, file), [Diagnostic(
                file, 1, 1, f"the file holds about {values:,} values, more than the "
                f"{MAX_VALUES:,} a file may hold: give large arrays as inputs (.npy files)")]
    try:
        # libyaml's parser where it is installed (a few times faster); PyYAML's own to say
        # what is malformed, in the words of yaml_problem
        node = yaml.compose(text, Loader=FAST_LOADER)
    except yaml.YAMLError:
        node = None
        try:
            node = yaml.compose(text, Loader=yaml.SafeLoader)
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark or exc.context_mark
            line, column = (mark.line + 1, mark.column + 1) if mark else (1, 1)
            message = yaml_problem(exc, text)
            return Located(None, file), [Diagnostic(file, line, column, message)]
        except RecursionError:
            return Located(None, file), [Diagnostic(file, 1, 1, "malformed YAML: nested too "
                                                    "deeply, or an alias that contains itself")]
        except yaml.YAMLError as exc:  # pragma: no cover - every PyYAML error carries a mark
            return Located(None, file), [Diagnostic(file, 1, 1, f"malformed YAML: {exc}")]
    except RecursionError:
        return Located(None, file), [Diagnostic(file, 1, 1, "malformed YAML: nested too deeply, "
                                                "or an alias that contains itself")]
    located = Located(None, file)
    if node is None:
        return located, [Diagnostic(file, 1, 1, f"empty file: expected {a_or_an(kind)} {kind} "
                                    "(a mapping)")]

    built = [0]
    active: set[int] = set()

    def build(node: yaml.Node, path: Path) -> Any:
        built[0] += 1
        if built[0] > MAX_VALUES:
            raise _Refused(node, f"more than {MAX_VALUES:,} values (aliases that repeat "
                           "aliases?): refused before it fills the memory")
        if id(node) in active:
            raise _Refused(node, "an alias that contains itself: the value would be infinite")
        located.positions[path] = (node.start_mark.line + 1, node.start_mark.column + 1)
        if isinstance(node, (yaml.MappingNode, yaml.SequenceNode)):
            active.add(id(node))
            try:
                return build_collection(node, path)
            finally:
                active.discard(id(node))
        return build_scalar(node, path)

    def build_collection(node: yaml.Node, path: Path) -> Any:
        if isinstance(node, yaml.MappingNode):
            out: dict[Any, Any] = {}
            for key_node, value_node in node.value:
                key = build(key_node, path + ("<key>",))
                if key is None or isinstance(key, (bool, int, float)):
                    key = key_node.value  # a key is a name, as written (1.50, true, null)
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
        return [build(item, path + (i,)) for i, item in enumerate(node.value)]

    def build_scalar(node: yaml.Node, path: Path) -> Any:
        assert isinstance(node, yaml.ScalarNode)
        if blocks and not node.style and node.value in blocks:
            array, written, _ = blocks.pop(node.value)  # each placeholder stands once
            located.blocks[path] = written
            return array
        if node.style:  # quoted or block scalar: always a string (plain: None, or "" from libyaml)
            if node.style in ("'", '"') and node.start_mark.line == node.end_mark.line:
                located.quoted.add(path)
            return node.value
        value = _plain_scalar(node.value)
        if not isinstance(value, str) and node.value:
            located.texts[path] = node.value  # where a name stands, the value as written
        return value

    try:
        located.data = build(node, ())
    except _Refused as exc:
        mark = exc.node.start_mark
        return Located(None, file), [Diagnostic(file, mark.line + 1, mark.column + 1,
                                                f"malformed YAML: {exc}")]
    except RecursionError:
        return Located(None, file), [Diagnostic(file, 1, 1, "malformed YAML: nested too "
                                                "deeply to read")]
    return located, problems


#: the most values a file may expand to (aliases included), tables of numbers read as arrays
#: aside (:data:`bayesprog.support.yamltext.MAX_TABLE_NUMBERS`); reading that many as YAML takes about 3 s and 400 MB
MAX_VALUES = 500_000
def _position_in_block(written: str, line: int, column: int, inside: list[Any]) -> tuple[int, int]:
    """Line and column of the row or number at indices ``inside`` of a table written as
    ``written`` from (``line``, ``column``)."""
    at = _offset_in_block(written, [int(i) for i in inside])
    newlines = written.count("\n", 0, at)
    if newlines == 0:
        return line, column + at
    return line + newlines, at - written.rfind("\n", 0, at)


_SCALAR = re.compile(r"[^\s,\[\]{}:#-][^,\[\]{}\n]*")


def _count_values(text: str) -> int:
    """About how many scalars ``text`` holds (words between separators, comments left out):
    linear, and never fewer than PyYAML would build for plain flow lists."""
    return sum(sum(1 for _ in _SCALAR.finditer(line.split(" #", 1)[0]))
               for line in text.splitlines() if not line.lstrip().startswith("#"))


def _offset_in_block(written: str, target: list[int]) -> int:
    """Where the item at indices ``target`` of the nested list ``written`` starts (0 when it
    has none)."""
    stack: list[int] = []  # the index of the item being read at each open bracket
    expecting = False
    for at, char in enumerate(written):
        if char.isspace():
            continue
        if expecting:
            expecting = False
            if stack == target:
                return at
        if char == "[":
            stack.append(0)
            expecting = True
        elif char == "]":
            stack.pop()
        elif char == ",":
            stack[-1] += 1
            expecting = True
    return 0


class _Refused(Exception):
    def __init__(self, node: yaml.Node, message: str):
        super().__init__(message)
        self.node = node
