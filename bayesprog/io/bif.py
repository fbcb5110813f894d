"""BIF networks read by regular expressions over the whole text and numpy for the numbers:
under a second for the largest network pgmpy ships (diabetes, 5.5 MB), where pgmpy's
``BIFReader`` takes most of a minute.

The text is read as pgmpy reads it, so that both give the same network::

    network unknown { property ...; }
    variable X { type discrete [ 3 ] { low, mid, high }; property ...; }
    probability ( A ) { table 0.2, 0.8; }
    probability ( X | A, B ) {
      (a1, b1) 0.1, 0.2, 0.7;        // rows keyed by the parents' states, in any order
      default 0.3, 0.3, 0.4;         // the parents' states no row names
    }

- comments (``//`` to the end of the line, ``/* */``) are blanks, and a ``"`` is a blank: a
  quoted ``"Dog problem"`` is the name ``Dog problem``;
- states are split at commas (at blanks when there is no comma), blanks around them dropped;
- a name in a ``probability`` header that is not declared as written is the declared name
  equal to it but for case (pgmpy's rule); ``probability ( X A B )``, the old form, is
  ``X | A, B``;
- ``table`` lists the child's states slowest: ``table`` of ``P(X | A)`` is
  ``x1|a1, x1|a2, ..., x2|a1, ...`` (pgmpy's reading); a parents' row missing with no
  ``default`` is zeros (pgmpy's; the program's checker then says which row does not sum to 1);
- ``variable`` blocks may come after the ``probability`` blocks that name them.

It also reads what pgmpy's reader does not: ``default`` rows, a header over several lines, a
name with blanks in a header without parents, a last block with no newline after it. A
construct outside these raises :class:`BifError` with its line and column; the caller may give
the file to pgmpy's reader (see :func:`bayesprog.io.import_network`). Every table's size (the
child's states times the product of the parents'), and their sum, is checked against
:mod:`bayesprog.limits` before it is allocated; :func:`check_sizes_as_pgmpy_reads` does the same
for a file that pgmpy's reader will read.

>>> net = read_bif('''variable A { type discrete [ 2 ] { yes, no }; }
... variable B { type discrete [ 2 ] { on, off }; }
... probability ( A ) { table 0.2, 0.8; }
... probability ( B | A ) { (no) 0.3, 0.7; default 0.9, 0.1; }''')
>>> net.states
{'A': ['yes', 'no'], 'B': ['on', 'off']}
>>> net.tables["B"].parents, net.tables["B"].values.tolist()
(('A',), [[0.9, 0.3], [0.1, 0.7]])
>>> read_bif("variable A { type discrete [ 3 ] { yes, no }; }", "net.bif")
Traceback (most recent call last):
...
bayesprog.io.bif.BifError: net.bif:1:30: variable A declares 3 states and lists 2: yes, no
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from bayesprog.errors import BayesprogError
from bayesprog.limits import check_size

__all__ = ["BifError", "Network", "Table", "check_sizes_as_pgmpy_reads", "read_bif"]

#: BIF's word for a CPT given whole ("table 0.1, 0.9;"), beside rows keyed by parent states
_TABLE_WORD = "table"


class BifError(BayesprogError, ValueError):
    """A BIF text this reader does not read, at ``line``:``column`` (1-based)."""

    def __init__(self, source: str, line: int, column: int, message: str):
        self.source, self.line, self.column, self.message = source, line, column, message
        super().__init__(f"{source or '<text>'}:{line}:{column}: {message}")


@dataclass(frozen=True)
class Table:
    """``P(variable | parents)``: ``values[i, j1, ..., jk]`` is the probability of the
    variable's state ``i`` given the parents' states ``j1 ... jk`` (pgmpy's ``TabularCPD``
    layout)."""

    variable: str
    parents: tuple[str, ...]
    values: np.ndarray


@dataclass(frozen=True)
class Network:
    """A discrete Bayesian network as its BIF file states it: each variable's states in
    declaration order, each ``probability`` block's table in the file's order."""

    states: dict[str, list[str]]
    tables: dict[str, Table]

    def edges(self) -> list[tuple[str, str]]:
        """(parent, child) arcs, in the order of the file's ``probability`` blocks."""
        return [(p, t.variable) for t in self.tables.values() for p in t.parents]


# pgmpy's: a comment outside double quotes
_COMMENT = re.compile(r'("[^"\\]*(?:\\.[^"\\]*)*")|(/\*.*?\*/|//[^\n]*)', re.DOTALL)
# ours: a comment left open runs to the end (pgmpy's leaves it, and looks for its end again at
# every "/*" after it: time that grows as the square of the file)
_OUR_COMMENT = re.compile(r'("[^"\\]*(?:\\.[^"\\]*)*")|(/\*.*?(?:\*/|\Z)|//[^\n]*)', re.DOTALL)
_NOT_NEWLINE = re.compile(r"[^\n]")
_BLANKS = re.compile(r"\s+")
_WORD = re.compile(r"[A-Za-z]+\b")
_TOKEN = re.compile(r"[^\s,;(){}|]{1,24}|\S")
_NETWORK = re.compile(r"network\b[^{}]*\{[^{}]*\}")
_VARIABLE = re.compile(r"variable(?P<name>\s[^{}]*)\{(?P<body>[^{}]*\{[^{}]*\}[^{}]*)\}")
_PROPERTIES = r"(?:\s*property\b[^;]*;)*+"
_VARIABLE_BODY = re.compile(
    rf"{_PROPERTIES}\s*type\s+discrete\s*\[\s*(?P<count>\d+)\s*\]\s*\{{(?P<states>[^{{}}]*)\}}"
    rf"\s*;{_PROPERTIES}\s*")
_PROBABILITY = re.compile(r"probability\s*\((?P<head>[^(){}]*)\)\s*\{(?P<body>[^{}]*)\}")
# a name: no blank at either end, none of the characters that delimit names in a header
_NAME = re.compile(r"[^\s{}()|,;]+(?:\s+[^\s{}()|,;]+)*")
# a number as pgmpy reads one (Python's float of digits, ".", "e", "E", "+", "-"), nothing
# glued to it; a list of them, separated by commas or blanks
_NUMBER = r"(?>[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?)(?![\w.+-])"
_NUMBERS = re.compile(rf"\s*{_NUMBER}(?:(?:\s*,\s*|\s+){_NUMBER})*+(?:\s*,)?\s*", re.ASCII)
_NUMBER_ITEM = re.compile(rf"\s*{_NUMBER}\s*,?", re.ASCII)
# what the numbers of a body may hold, and the empty items (",,", a comma first) they may not
_NUMBER_BYTES = b" \t\n\r\f\v0123456789.,;eE+-"
_EMPTY_ITEMS = re.compile(r",\s*,"), re.compile(r";\s*,")  # each searched fast, from its literal
# the bodies of probability blocks (possessive: a body that is not one fails in linear time)
_TABLE_BODY = re.compile(rf"{_PROPERTIES}\s*table\b(?P<numbers>[^;]*);{_PROPERTIES}\s*")
_ROWS_BODY = re.compile(r"(?:\s*(?:property\b|\([^()]*\)|default\b)[^;]*;)*+\s*")
# the statements of a body, found in order once the body is known to be made of them
_ROW = re.compile(r"\s*(?:property\b[^;]*|\((?P<key>[^()]*)\)(?P<numbers>[^;]*)"
                  r"|default\b(?P<default>[^;]*));")
# any statement, to say which one is wrong, and how one begins
_STATEMENT = re.compile(r"\s*(?:(?P<property>property\b)[^;]*|\((?P<key>[^()]*)\)"
                        r"(?P<numbers>[^;]*)|(?P<word>table|default)\b(?P<listed>[^;]*));")
_STATEMENT_START = re.compile(r"\(|(?:property|table|default)\b")


def read_bif(text: str, source: str = "") -> Network:
    """The network of the BIF ``text`` (``source``: the file's name, for messages); a
    :class:`BifError` at the first construct not read, a :class:`~bayesprog.limits.SizeError`
    for a table larger than the limit."""
    return _Reader(_blanked(text), source).network()


def _blanked(text: str) -> str:
    """``text`` with comments and double quotes made blanks (lines and columns kept)."""
    if "/*" in text or "//" in text:
        text = _OUR_COMMENT.sub(lambda m: m.group(1) or _NOT_NEWLINE.sub(" ", m.group(2)), text)
    if text.startswith("\ufeff"):  # a byte order mark
        text = " " + text[1:]
    return text.replace('"', " ")


class _Reader:
    def __init__(self, text: str, source: str):
        self.text, self.source = text, source
        self.states: dict[str, list[str]] = {}
        self.index: dict[str, dict[str, int]] = {}
        self.tables: dict[str, Table] = {}
        self.lowered: dict[str, str] = {}
        self.counted = (0, 1)  # a position and its line
        self.entries = 0  # of the tables read so far

    def fail(self, pos: int, message: str) -> BifError:
        return BifError(self.source, *self.line_column(pos), message)

    def line_column(self, pos: int) -> tuple[int, int]:
        # lines counted on from the last position asked for: the blocks are read in order
        if pos < self.counted[0]:
            self.counted = (0, 1)
        line = self.counted[1] + self.text.count("\n", self.counted[0], pos)
        self.counted = (pos, line)
        return line, pos - self.text.rfind("\n", 0, pos)

    def where(self, pos: int) -> str:
        """``source:line:column: `` of ``pos``, to begin a message."""
        line, column = self.line_column(pos)
        return f"{self.source or '<text>'}:{line}:{column}: "

    def found(self, pos: int) -> str:
        token = _TOKEN.match(self.text, pos)
        return repr(token.group()) if token else "the end of the file"

    def network(self) -> Network:
        text, pos = self.text, _after_blanks(self.text, 0)
        probabilities = []  # read once every variable is declared, wherever (as pgmpy does)
        if pos == len(text):
            raise self.fail(0, "no network: expected variable and probability blocks")
        while pos < len(text):
            word = _WORD.match(text, pos)
            keyword = word.group() if word else ""
            if keyword == "network":
                block = _NETWORK.match(text, pos)
                if block is None:
                    raise self.fail(pos, "expected network NAME { property ...; }")
            elif keyword == "variable":
                block = _VARIABLE.match(text, pos)
                if block is None:
                    raise self.fail(pos, "expected variable NAME { type discrete [ N ] "
                                         "{ STATE, ... }; }")
                self.variable(block)
            elif keyword == "probability":
                block = _PROBABILITY.match(text, pos)
                if block is None:
                    raise self.fail(pos, "expected probability ( VARIABLE | PARENT, ... ) "
                                         "{ ... }")
                probabilities.append(block)
            else:
                raise self.fail(pos, "expected network, variable or probability, found "
                                     f"{self.found(pos)}")
            pos = _after_blanks(text, block.end())
        self.lowered = {name.lower(): name for name in self.states}
        for block in probabilities:
            self.probability(block)
        return Network(self.states, self.tables)

    def variable(self, block: re.Match[str]) -> None:
        name, at = block["name"].strip(), _after_blanks(self.text, block.start("name"))
        if not _NAME.fullmatch(name):
            raise self.fail(at, f"expected a variable's name, found {name!r}")
        if name in self.states:
            raise self.fail(at, f"variable {name} is declared twice")
        body = _VARIABLE_BODY.fullmatch(block["body"])
        if body is None:
            declared = re.search(r"\btype\b", block["body"])
            at = block.start("body") + (declared.start() if declared else 0)
            raise self.fail(_after_blanks(self.text, at), f"variable {name}: expected "
                            "type discrete [ N ] { STATE, ... }; and properties")
        at = block.start("body") + body.start("states")
        raw = body["states"]
        states = [s.strip() for s in raw.split(",")] if "," in raw else raw.split()
        check_size(len(states), f"{self.where(at)}variable {name}", "states")
        if int(body["count"]) != len(states) or "" in states or not states:
            at = block.start("body") + body.start("count")
            raise self.fail(at, f"variable {name} declares {body['count']} states and lists "
                                f"{len([s for s in states if s])}: {', '.join(states)}")
        index = {s: i for i, s in enumerate(states)}
        if len(index) < len(states):
            raise self.fail(at, f"variable {name} lists a state twice: {', '.join(states)}")
        self.states[name], self.index[name] = states, index

    def resolve(self, name: str, head: str, at: int) -> str:
        """The declared variable ``name`` (in the header ``head`` at ``at``) stands for
        (pgmpy's rule: as written, else the last declared equal to it but for case)."""
        if name in self.states:
            return name
        found = self.lowered.get(name.lower())
        if found is None:
            raise self.fail(at + _offset(head, name), f"{name!r} is not a declared variable: "
                                                      "expected a name declared by variable NAME "
                                                      "{ ... }")
        return found

    def probability(self, block: re.Match[str]) -> None:
        head, at = block["head"], block.start("head")
        child_part, bar, parent_part = head.partition("|")
        if bar:
            names = [child_part.strip()] + [p.strip() for p in parent_part.split(",")]
        elif head.strip() in self.states or not head.strip():
            names = [head.strip()]
        else:  # the old form, probability ( X A B ), as pgmpy reads it
            names = head.split()
        if not all(_NAME.fullmatch(n) for n in names):
            raise self.fail(at, f"expected ( VARIABLE | PARENT, ... ), found ({head})")
        child, *parents = (self.resolve(n, head, at) for n in names)
        if child in self.tables:
            raise self.fail(at, f"a second probability block for {child}")
        if len(set(parents)) < len(parents) or child in parents:
            raise self.fail(at, f"probability ( {head.strip()} ): a variable named twice")
        cards = [len(self.states[p]) for p in parents]
        count, columns = len(self.states[child]), math.prod(cards)
        where = self.where(block.start())
        check_size(count * columns, f"{where}the table of {child} "
                                    f"({' x '.join(map(str, [count, *cards]))} states)")
        self.entries += count * columns  # every table is kept: their sum is bounded too
        check_size(self.entries, f"{where}the tables up to that of {child}")
        if _TABLE_BODY.fullmatch(block["body"]):
            values = self.table(block, count * columns)
        elif _ROWS_BODY.fullmatch(block["body"]):
            values = self.rows(block, parents, count, columns)
        else:
            raise self.statement_error(block, count)
        self.tables[child] = Table(child, tuple(parents),
                                   np.ascontiguousarray(values.reshape(count, *cards)))

    def table(self, block: re.Match[str], size: int) -> np.ndarray:
        """The numbers of ``table``, ``size`` of them, the child's states slowest."""
        listed = _TABLE_BODY.fullmatch(block["body"])
        assert listed is not None
        values = _floats([listed["numbers"]])
        if values is None:
            raise self.statement_error(block, size)
        if values.size != size:
            raise self.fail(_after_blanks(self.text, block.start("body") + listed.start("numbers")),
                            f"table: expected {size} numbers, found {values.size}")
        return values

    def rows(self, block: re.Match[str], parents: list[str], count: int,
             columns: int) -> np.ndarray:
        """The rows of a body of ``(states) numbers;`` and ``default numbers;``: the child's
        ``count`` states by the parents' ``columns`` states (zeros where no row is given)."""
        found = _ROW.findall(block["body"])
        keys = [key for key, numbers, default in found if numbers]
        listed = [numbers for key, numbers, default in found if numbers]
        defaults = [default for key, numbers, default in found if default]
        if len(defaults) > 1:
            raise self.fail(block.start("body"), "expected at most one default row, found "
                                                 f"{len(defaults)}")
        if keys and not parents:
            raise self.fail(block.start("body"), "a row of parents' states in the table of "
                                                 "a variable without parents: expected table")
        rows = _floats(listed + defaults, count)
        if rows is None:
            raise self.statement_error(block, count)
        table = np.zeros((columns, count))
        if defaults:
            table[:] = rows[-1]
        if keys:
            table[self.columns(block, parents, keys)] = rows[:len(keys)]
        return table.T

    def columns(self, block: re.Match[str], parents: list[str], keys: list[str]) -> np.ndarray:
        """The column of each row's parents' states (the first parent's slowest)."""
        indexes = [self.index[p] for p in parents]
        try:
            codes = [[ix[s.strip()] for ix, s in zip(indexes, key.split(","), strict=True)]
                     for key in keys]
        except (KeyError, ValueError):
            raise self.key_error(block, parents) from None
        return np.ravel_multi_index(tuple(np.array(codes, dtype=np.intp).T),
                                    [len(ix) for ix in indexes])

    def key_error(self, block: re.Match[str], parents: list[str]) -> BifError:
        """The first row whose states are not one of each parent's."""
        for row in _ROW.finditer(block["body"]):
            if not row["numbers"]:
                continue
            states = [s.strip() for s in row["key"].split(",")]
            at = block.start("body") + row.start("key")
            if len(states) != len(parents):
                return self.fail(at, f"expected the states of {', '.join(parents)}, found "
                                     f"({row['key']})")
            for parent, state in zip(parents, states, strict=True):
                if state not in self.index[parent]:
                    return self.fail(at, f"{state!r} is not a state of {parent}: expected one "
                                         f"of {', '.join(self.states[parent])}")
        raise AssertionError("every row's states were read")

    def statement_error(self, block: re.Match[str], count: int) -> BifError:
        """Why the body of the ``probability`` block ``block``, a table of ``count`` states,
        is not read: the first statement that is not one, or what is wrong with them all."""
        text, start, end = self.text, block.start("body"), block.end("body")
        pos, kinds = start, []
        while (pos := _after_blanks(text, pos, end)) < end:
            statement = _STATEMENT.match(text, pos, end)
            if statement is None and _STATEMENT_START.match(text, pos, end):
                return self.fail(end, "expected ';' at the end of the statement, found '}'")
            if statement is None:
                return self.fail(pos, "expected (STATE, ...), table, default or property, "
                                      f"found {self.found(pos)}")
            kind = "property" if statement["property"] else statement["word"] or "row"
            if kind != "property":
                group = "numbers" if kind == "row" else "listed"
                at = _after_blanks(text, statement.start(group))
                if not _NUMBERS.fullmatch(statement[group]):
                    at = statement.start(group) + _first_not_number(statement[group])
                    return self.fail(at, f"{kind}: expected a number, found {self.found(at)}")
                found = len(statement[group].replace(",", " ").split())
                if kind != _TABLE_WORD and found != count:
                    return self.fail(at, f"{kind}: expected {count} numbers (one per state), "
                                         f"found {found}")
                kinds.append(kind)
            pos = statement.end()
        if _TABLE_WORD in kinds and len(kinds) > 1:
            return self.fail(start, "expected one table statement or rows, found "
                                    f"{' and '.join(sorted(set(kinds)))}")
        return self.fail(start, "expected (STATE, ...) numbers; rows, or table numbers;")


def _after_blanks(text: str, pos: int, end: int | None = None) -> int:
    """The position of the first character at or after ``pos`` that is not a blank."""
    blanks = _BLANKS.match(text, pos, len(text) if end is None else end)
    return blanks.end() if blanks else pos


def _offset(head: str, name: str) -> int:
    """Where ``name`` is in the ``probability`` header ``head`` (0 when it is not found)."""
    found = re.search(rf"(?<![^\s|,]){re.escape(name)}(?![^\s|,])", head)
    return found.start() if found else 0


def _first_not_number(numbers: str) -> int:
    """Where in ``numbers`` the list of numbers stops being one."""
    pos = 0
    while (item := _NUMBER_ITEM.match(numbers, pos)) and item.end() > pos:
        pos = item.end()
    return _after_blanks(numbers, pos)


def _floats(lists: list[str], count: int | None = None) -> np.ndarray | None:
    """The numbers of each of ``lists`` (numbers separated by commas or blanks), as rows of
    ``count`` (or as one row when ``count`` is None); None when one is not such a list. The
    checks run over all the text at once; :meth:`_Reader.statement_error` says which."""
    text = ";" + ";".join(lists)
    if text.encode().translate(None, _NUMBER_BYTES) or any(e.search(text) for e in _EMPTY_ITEMS):
        return None
    if count is None:
        items = text[1:].replace(",", " ").split()
    else:
        rows = [numbers.replace(",", " ").split() for numbers in lists]
        if any(len(row) != count for row in rows):
            return None
        items = [item for row in rows for item in row]
    try:  # numpy reads a number as Python's float does (correctly rounded)
        values = np.array(items, dtype=float)
    except ValueError:  # "1.2.3", "1e", "-"
        return None
    return values if count is None else values.reshape(len(lists), count)


# pgmpy's BIFReader's own expressions (pgmpy/readwrite/BIF.py), to size what it allocates
_PGMPY_BLOCK = re.compile(r"(variable|probability).*?\}\n", re.DOTALL)
_PGMPY_HEADER = re.compile(r"probability\s*\(\s*(.+?)(?:\s*\|\s*(.+?))?\s*\)")
_PGMPY_STATES = re.compile(r"type\s+\w+\s*\[\s*\d+\s*\]\s*\{([^}]+)\}\s*;")


def check_sizes_as_pgmpy_reads(text: str, source: str = "") -> None:
    """Refuse (:class:`~bayesprog.limits.SizeError`) a BIF text with a table larger than the
    limit as pgmpy's ``BIFReader`` reads it: it allocates each table (the child's states times
    the product of the parents') before it reads the rows, so a few declared lines could ask
    for any size. The blocks, names and states are found as that reader finds them."""
    if "/*" in text or "//" in text:
        text = _COMMENT.sub(lambda m: m.group(1) or "", text)
    text = text.replace('"', " ")
    counts: dict[str, int] = {}
    entries = 0
    for block in _PGMPY_BLOCK.finditer(text):
        content = block.group()
        if content.startswith("variable"):
            declared = _PGMPY_STATES.search(content)
            if declared:
                raw = declared.group(1)
                states = [s for s in raw.split(",") if s.strip()] if "," in raw else raw.split()
                name = content[len("variable"):].partition("{")[0].strip()
                counts[name.lower()] = len(states)
            continue
        header = _PGMPY_HEADER.search(content.partition("\n")[0])
        if header is None:
            continue
        names = [header.group(1).strip(), *(p.strip() for p in header.group(2).split(","))] \
            if header.group(2) else header.group(1).split()
        size = math.prod(counts.get(n.lower(), 1) for n in names)
        check_size(size, f"{source or '<text>'}: the table of {names[0]} (as pgmpy reads it)")
        entries += size
        check_size(entries, f"{source or '<text>'}: the tables up to that of {names[0]} (as "
                            "pgmpy reads them)")
