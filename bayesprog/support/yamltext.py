"""Program files as YAML text, below the language: the parser that builds their nodes, and
their large tables of numbers found in the text.

The loader (:mod:`bayesprog.language.loader`) reads a file with both; the writer of fitted
values (:mod:`bayesprog.learning.inplace`) finds with both where each number it replaces
stands, so that the two read a file alike.
"""

from __future__ import annotations

import json
import re
from typing import Any

import numpy as np
import yaml

_LIBYAML = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _Untagged(_LIBYAML):  # type: ignore[misc,valid-type]
    """libyaml's parser (PyYAML's where it is not installed) building nodes without resolving
    their tags: a program file's plain scalars are read by the loader itself (YAML 1.2's core
    rules, not PyYAML's 1.1 resolver), and the resolver's patterns, tried on every scalar,
    took most of the time of building the nodes."""

    def resolve(self, kind: type, value: Any, implicit: Any) -> str:
        return _TAGS[kind]


_TAGS = {yaml.ScalarNode: "tag:yaml.org,2002:str", yaml.SequenceNode: "tag:yaml.org,2002:seq",
         yaml.MappingNode: "tag:yaml.org,2002:map"}
#: the parser that builds the nodes of a program file (see :class:`_Untagged`)
FAST_LOADER = _Untagged

#: the most numbers the tables of a file may hold (8 bytes each once read; the largest bnlearn
#: networks, diabetes and mildew, hold about half a million)
MAX_TABLE_NUMBERS = 20_000_000
#: a table shorter than this (in characters) is read as YAML, like everything else
BLOCK_MIN_CHARS = 10
#: the characters of a table's text looked at a time for its closing bracket
SCAN_CHARS = 1 << 16
#: ``table:`` followed by a nested list made only of numbers, brackets, commas and spaces (the
#: key found first, then what stands before it: a pattern that starts with a word is looked for
#: by the word, one that starts with a choice is tried at every character)
_TABLE_KEY = re.compile(r"table[ \t]*:[ \t]*(?=\[)")
_BLOCK_BODY = re.compile(r"[\[\]0-9.,eE+\- \t\r\n]*")
#: the fits' records (``learned:`` at the start of a line), and in them each one's sufficient
#: statistics (a key per statistic), ``statistics:`` after its line's indentation and dash
_LEARNED = re.compile(r"learned[ \t]*:")
_STATISTICS = re.compile(r"statistics[ \t]*:[ \t]*(?:#[^\n]*)?$", re.MULTILINE)
_STATISTICS_INDENT = re.compile(r"[ \t]*(?:-[ \t]+)?")
_LIST_VALUE = re.compile(r":[ \t]*(?=\[)")
#: the line break before a line that starts a top-level key
_TOP_LEVEL = re.compile(r"\n(?=[^ \t\r\n#-])")


def _block_starts(text: str) -> list[int]:
    """Where each list that may be read as an array starts: a table's, and each statistic's
    in the ``statistics:`` of a fit's record (under the top-level ``learned:``)."""
    starts = [m.end() for m in _TABLE_KEY.finditer(text)
              if m.start() == 0 or text[m.start() - 1].isspace() or text[m.start() - 1] in "{,"]
    learned = next((m for m in _LEARNED.finditer(text)
                    if m.start() == 0 or text[m.start() - 1] == "\n"), None)
    if learned is not None:
        # up to the next top-level key (a record's dash may stand in the first column)
        following = _TOP_LEVEL.search(text, learned.end())
        records_end = following.start() + 1 if following is not None else len(text)
        for found in _STATISTICS.finditer(text, learned.end(), records_end):
            line = text.rfind("\n", 0, found.start()) + 1
            indent = _STATISTICS_INDENT.fullmatch(text, line, found.start())
            if line < learned.end() or indent is None:
                continue  # not the key of a line
            # the statistics' lines: those indented past the key, up to the next that is not
            column = indent.end() - line
            after = re.compile(rf"\n[ ]{{0,{column}}}(?=[^ \t\r\n#])").search(text, found.end())
            stop = after.start() + 1 if after is not None else len(text)
            starts += [m.end() for m in _LIST_VALUE.finditer(text, found.end(), stop)]
    return sorted(set(starts))


def number_blocks(text: str) -> tuple[str, dict[str, tuple[Any, str, int]], int]:
    """The text with each large table of numbers (``table: [[0.1, 0.9], ...]``, or a fit's
    statistic, ``counts: [[7.0, 99.0], ...]``) replaced by a placeholder on its first line
    (the lines and the columns after it kept), the arrays by placeholder (with their text, to
    place a row later, and where that text starts in ``text``), and how many numbers they
    hold.

    A table is taken only when it is a regular nested list of plain decimal numbers (what JSON
    reads); anything else (a ragged row, a word, ``.5``) is left to the YAML reader and its
    diagnostics."""
    if len(text) < BLOCK_MIN_CHARS:
        return text, {}, 0
    token, n = "__table_", 0  # a placeholder the text does not hold
    while token in text:
        n += 1
        token = f"__table{n}_"
    pieces: list[str] = []
    blocks: dict[str, tuple[Any, str, int]] = {}
    numbers, done, at = 0, 0, 0
    for start in _block_starts(text):
        if start < at:  # inside the list just looked at
            continue
        body = _BLOCK_BODY.match(text, start)
        end = _closing(text, start, body.end() if body else start)
        at = max(end, start + 1)
        if end - start < BLOCK_MIN_CHARS:
            continue
        written = text[start:end]
        if numbers + written.count(",") + 1 > MAX_TABLE_NUMBERS:  # refused before it is read
            return text, {}, numbers + written.count(",") + 1
        try:
            array = np.asarray(json.loads(written), dtype=float)
        except (ValueError, TypeError):  # not JSON's numbers, or ragged
            continue
        if array.dtype != np.float64 or array.ndim < 1 or not np.all(np.isfinite(array)):
            continue
        name = f"{token}_{len(blocks)}"
        blocks[name] = (array, written, start)
        numbers += array.size
        lines = written.count("\n")
        # what follows the table keeps its line and column
        pad = end - (text.rfind("\n", 0, end) + 1) if lines else end - start - len(name)
        pieces += [text[done:start], name, "\n" * lines, " " * pad]
        done = end
    if not blocks:
        return text, {}, 0
    pieces.append(text[done:])
    return "".join(pieces), blocks, numbers


def _closing(text: str, start: int, stop: int) -> int:
    """Where the bracket opened at ``start`` closes (one past it), looking no further than
    ``stop``; ``start`` when it does not close there. (The text up to ``stop`` is a table's
    body: numbers, brackets, commas and spaces; it is read a block at a time.)"""
    depth = 0
    for low in range(start, stop, SCAN_CHARS):
        codes = np.frombuffer(text[low:min(low + SCAN_CHARS, stop)].encode("ascii", "replace"),
                              dtype=np.uint8)
        steps = (codes == ord("[")).astype(np.int64) - (codes == ord("]"))
        depths = depth + np.cumsum(steps)
        closed = np.flatnonzero((depths == 0) & (steps != 0))  # back outside, at a bracket
        if closed.size:
            return low + int(closed[0]) + 1
        depth = int(depths[-1])
    return start
