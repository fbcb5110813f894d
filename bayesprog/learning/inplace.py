"""Writing learned values into a program's text in place: each number of a learned parameter
written as nested lists (or as one number) is replaced where it stands, and the fit's record is
appended as YAML text; every other character of the file stays as it was, comments included.

This is the fast way of :func:`bayesprog.learning.write.render_fitted` (hepar2's file in tens
of milliseconds, where a round trip through ruamel.yaml takes over a second): it declines, with
None, what it cannot write in place (a parameter written keyed by states, a shape that
changed, a ``learned:`` list that is not the file's last block), and the round trip writes
those. The values read back the same either way.

>>> text = "bayesprog: 1\\ndecomposition:\\n  - term: P(A)  # the prior\\n    table: [0.5, 0.5]\\n"
>>> print(splice(text, {"P(A)": {"table": np.array([0.25, 0.75])}}, {"data": "a.csv"}), end="")
bayesprog: 1
decomposition:
  - term: P(A)  # the prior
    table: [0.25, 0.75]
<BLANKLINE>
# Fits that set this program's parameters (bayesprog learn).
learned:
  - data: a.csv
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import yaml

from bayesprog.support.yamltext import FAST_LOADER, number_blocks
from bayesprog.vocabulary.expressions import canonical

#: the comment the round trip writes above a new ``learned:`` list
LEARNED_COMMENT = "# Fits that set this program's parameters (bayesprog learn)."
#: an array of statistics is written on its key's line when the line stays this short, else
#: one row per line
LINE_WIDTH = 100

_NUMBER = re.compile(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?|[-+]?\.(inf|Inf|INF)"
                     r"|\.(nan|NaN|NAN)")
#: what ends a line for the YAML parser (its marks count lines so)
_LINE_BREAK = re.compile("\r\n|[\n\r\x85\u2028\u2029]")
_LONE_CR = re.compile("\r(?!\n)")
#: a number of a table read as a block (its text holds only numbers, brackets, commas, spaces)
_BLOCK_NUMBER = re.compile(r"[-+0-9.eE]+")
_DOCUMENT_END = re.compile(r"^\.\.\.\s*$", re.MULTILINE)


def splice(text: str, values: Mapping[str, Mapping[str, np.ndarray]],
           record: Mapping[str, Any]) -> str | None:
    """``text`` with the arrays of ``values`` (by term label, then parameter) written over the
    numbers they replace, and ``record`` (a fit's record, as plain data) appended to the
    ``learned:`` list; None where that cannot be done in place."""
    # the large tables found as the loader finds them (their numbers by a pattern, not a YAML
    # node each); the text around them keeps its lines and columns
    read, blocks, _ = number_blocks(text)
    if any(_LONE_CR.search(written) for _, written, _ in blocks.values()):
        return None  # a line the placeholder text would not have
    try:
        root = yaml.compose(read, Loader=FAST_LOADER)
    except (yaml.YAMLError, RecursionError):
        return None
    if not isinstance(root, yaml.MappingNode):
        return None
    line_starts = [0, *(m.end() for m in _LINE_BREAK.finditer(text))]

    def offset(mark: Any) -> int:
        return line_starts[mark.line] + mark.column

    top = {key.value: value for key, value in root.value if isinstance(key, yaml.ScalarNode)}
    decomposition = top.get("decomposition")
    if not isinstance(decomposition, yaml.SequenceNode):
        return None
    edits: dict[int, tuple[int, str]] = {}  # start -> (end, new text)
    done = set()
    for item in decomposition.value:
        if not isinstance(item, yaml.MappingNode):
            return None
        fields = {k.value: v for k, v in item.value if isinstance(k, yaml.ScalarNode)}
        term = fields.get("term")
        label = canonical(term.value) if isinstance(term, yaml.ScalarNode) else None
        if label is None or label not in values:
            continue
        for name, array in values[label].items():
            edited = _edits(fields.get(name), array, blocks, offset)
            if edited is None:
                return None
            for start, edit in edited:
                if start in edits:  # an alias: one text for two values
                    return None
                edits[start] = edit
        done.add(label)
    if set(values) - done:
        return None
    ending = _learned_ending(text, root, top, offset)
    if ending is None:
        return None
    prefix, indent = ending
    entry = record_lines(record, indent)
    if entry is None:
        return None
    pieces, at = [], 0
    for start in sorted(edits):
        end, new = edits[start]
        pieces += [text[at:start], new]
        at = end
    pieces.append(text[at:])
    out = "".join(pieces)
    if not out.endswith("\n"):
        out += "\n"
    return out + prefix + "".join(line + "\n" for line in entry)


def _edits(node: Any, array: Any, blocks: Mapping[str, tuple[Any, str, int]],
           offset: Callable[[Any], int]) -> list[tuple[int, tuple[int, str]]] | None:
    """The edits that write ``array`` over the numbers of ``node`` (start: end, new text), if
    it is nested lists of the array's shape: a table read as a block is written again whole,
    its numbers replaced in its text (what stands between them kept); the numbers of nodes one
    by one."""
    shape = np.shape(array)
    if isinstance(node, yaml.ScalarNode) and not node.style and node.value in blocks:
        read, written, start = blocks[node.value]
        if read.shape != shape:
            return None
        between = _BLOCK_NUMBER.split(written)  # the text around the numbers, in order
        texts = numbers(array)
        if len(between) != len(texts) + 1:
            return None
        pieces = [""] * (2 * len(texts) + 1)
        pieces[0::2], pieces[1::2] = between, texts
        return [(start, (start + len(written), "".join(pieces)))]
    leaves = _leaves(node, shape)
    if leaves is None:
        return None
    return [(offset(leaf.start_mark), (offset(leaf.end_mark), text))
            for leaf, text in zip(leaves, numbers(array), strict=True)]


def _leaves(node: Any, shape: tuple[int, ...]) -> list[yaml.ScalarNode] | None:
    """The plain numbers of ``node`` in row-major order, if it is nested lists of ``shape``
    (libyaml gives a plain scalar the style "", PyYAML None)."""
    if not shape:
        if isinstance(node, yaml.ScalarNode) and not node.style \
                and _NUMBER.fullmatch(node.value):
            return [node]
        return None
    if not isinstance(node, yaml.SequenceNode) or len(node.value) != shape[0]:
        return None
    out: list[yaml.ScalarNode] = []
    for child in node.value:
        inner = _leaves(child, shape[1:])
        if inner is None:
            return None
        out += inner
    return out


def _learned_ending(text: str, root: yaml.MappingNode, top: Mapping[str, Any],
                    offset: Callable[[Any], int]) -> tuple[str, str] | None:
    """What to write before the new record's lines, and their indentation: a new ``learned:``
    list at the end, or one more entry of the block list that ends the file."""
    if root.flow_style or _DOCUMENT_END.search(text):
        return None
    learned = top.get("learned")
    if learned is None:
        return "\n" + LEARNED_COMMENT + "\nlearned:\n", "  "
    last_key = root.value[-1][0]
    if (not isinstance(learned, yaml.SequenceNode) or learned.flow_style or not learned.value
            or last_key.value != "learned"):
        return None
    first = learned.value[0]
    at = offset(first.start_mark)
    line = text[text.rfind("\n", 0, at) + 1:at]
    dash = re.fullmatch(r"( *)- +", line)  # "  - " before the first entry's first key
    if dash is None or len(line) - len(dash.group(1)) != 2:
        return None
    return "", dash.group(1)


def record_lines(record: Mapping[str, Any], indent: str = "") -> list[str] | None:
    """A fit's record as the lines of a block list's entry (``- data: ...``, its keys two
    columns in) whose dash stands after ``indent``, or None when a value is not plain data
    this writer knows."""
    lines: list[str] = []
    for key, value in record.items():
        if value is None and key in ("digits", "rows_set_aside", "structure"):
            continue  # as fitted; bad rows refused; not discovered
        head = indent + ("- " if not lines else "  ")
        if key == "statistics" and isinstance(value, Mapping) and value:
            lines.append(f"{head}statistics:")
            for label, named in value.items():
                lines.append(f"{indent}    {scalar(str(label))}:")
                for name, array in named.items():
                    written = _array(array, f"{indent}      {scalar(str(name))}: ")
                    if written is None:
                        return None
                    lines += written
            continue
        flow = scalar(value) if isinstance(value, str) else _flow(value)
        if flow is None:
            return None
        lines.append(f"{head}{scalar(str(key))}: {flow}")
    return lines


def _array(value: Any, lead: str) -> list[str] | None:
    """An array of numbers on its key's line, or its innermost rows one per line (each under
    the one above, as numpy prints them) when that line would be long."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return None
    flow = _flow(value)
    if flow is None:
        return None
    if len(lead) + len(flow) <= LINE_WIDTH or array.ndim < 2:
        return [lead + flow]
    return (lead + _rows(array.tolist(), array.ndim, len(lead))).split("\n")


def _rows(values: list, ndim: int, column: int) -> str:
    """Nested lists of numbers whose ``[`` stands at ``column``, each innermost list on its
    own line under the one above."""
    if ndim == 1:  # (the floats of an array's tolist)
        return "[" + ", ".join(_texts(values)) + "]"
    inner = (",\n" + " " * (column + 1)).join(_rows(v, ndim - 1, column + 1) for v in values)
    return "[" + inner + "]"


def _flow(value: Any) -> str | None:
    """``value`` (numbers, strings, lists and mappings of them) as YAML flow text."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return number(value)
    if isinstance(value, str):
        return scalar(value, flow=True)
    if isinstance(value, (list, tuple)):
        if all(type(v) is float for v in value):  # a row of numbers (a statistic's)
            return "[" + ", ".join(_texts(value)) + "]"
        items = [_flow(v) for v in value]
        return None if None in items else "[" + ", ".join(items) + "]"  # type: ignore[arg-type]
    if isinstance(value, Mapping):
        pairs = [(scalar(str(k), flow=True), _flow(v)) for k, v in value.items()]
        if any(v is None for _, v in pairs):
            return None
        return "{" + ", ".join(f"{k}: {v}" for k, v in pairs) + "}"
    return None


def numbers(values: Any) -> list[str]:
    """The numbers of ``values`` (an array, or nested lists of numbers) in row-major order, each
    as :func:`number` writes it."""
    return _texts(np.ravel(np.asarray(values, dtype=float)).tolist())


def _texts(row: Sequence[float]) -> list[str]:
    """Each float of ``row`` as :func:`number` writes it."""
    if all(map(math.isfinite, row)):
        return list(map(repr, row))
    return [number(x) for x in row]


def number(x: float) -> str:
    """A float as YAML 1.2 writes it: the shortest text that reads back to the same double."""
    if math.isnan(x):
        return ".nan"
    if math.isinf(x):
        return ".inf" if x > 0 else "-.inf"
    return repr(x)


#: plain words a YAML reader takes for something other than a string
_NOT_STRINGS = {"true", "false", "null", "~", "yes", "no", "on", "off", "y", "n"}
_PLAIN = re.compile(r"[A-Za-z0-9_.()/=+][A-Za-z0-9_.()/=+|,; -]*")


def scalar(text: str, flow: bool = False) -> str:
    """A string as a YAML scalar: plain where every reader takes it for that string, else in
    double quotes (inside a flow list or mapping, a comma needs them)."""
    plain = (_PLAIN.fullmatch(text) is not None and not text.endswith((" ", "-"))
             and text.lower() not in _NOT_STRINGS and _NUMBER.fullmatch(text) is None
             and not (flow and "," in text) and " -" not in text)
    if plain:
        return text
    return json.dumps(text, ensure_ascii=not text.isprintable())
