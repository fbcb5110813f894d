"""Exchange with other tools: BIF, XMLBIF and UAI networks, read and written through pgmpy
(BIF imported by :mod:`bayesprog.io.bif`, pgmpy's reader only for what that one does not
know), and linear-Gaussian networks as JSON (:mod:`bayesprog.io.gaussian`).

``import_network`` turns a network file into a program document (states and CPT layout kept:
one ``table`` term per variable, parents in the file's order; rows that sum to 1 within 1e-6,
as rounded files print them, are renormalised); ``export_program`` writes a discrete program
back. pgmpy is imported lazily (importing it is slow).
"""

from __future__ import annotations

import functools
import graphlib
import gzip
import re
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from bayesprog.errors import BayesprogError

FORMATS = {".bif": "bif", ".xmlbif": "xmlbif", ".xml": "xmlbif", ".uai": "uai", ".json": "json"}
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")


class NetworkError(BayesprogError):
    """A network file that cannot be read or converted."""


def network_format(path: Path) -> str:
    suffixes = [s.lower() for s in path.suffixes]
    if suffixes and suffixes[-1] == ".gz":
        suffixes = suffixes[:-1]
    fmt = FORMATS.get(suffixes[-1] if suffixes else "")
    if fmt is None:
        raise NetworkError(f"{path}: unsupported network format: expected .bif, .xmlbif, .uai "
                           "or .json (a linear-Gaussian network), optionally gzipped")
    return fmt


#: The largest network file read (decompressed), in bytes: pgmpy's largest BIF network
#: (diabetes, 413 nodes, 429,409 numbers) takes 5.5 MB; this bounds what a gzipped file can
#: unfold into before anything is parsed.
MAX_BYTES = 256 * 2**20


def read_network(path: str | Path) -> Any:
    """A pgmpy ``DiscreteBayesianNetwork`` (or, for UAI Markov files, an error) from ``path``,
    read by pgmpy's readers (:func:`import_network` reads BIF by :mod:`bayesprog.io.bif`)."""
    path = Path(path)
    fmt = network_format(path)
    if fmt == "json":
        raise NetworkError(f"{path}: a linear-Gaussian network: read it with "
                           "bayesprog.io.gaussian.read_gaussian")
    return _pgmpy_model(read_text(path), fmt, path)


def read_text(path: Path, limit: int = MAX_BYTES, what: str = "a network file") -> str:
    """The text of ``path`` (gunzipped when it ends in ``.gz``), at most ``limit`` bytes;
    ``what``: what the file should be, for the messages."""
    try:
        opener = gzip.open if path.suffix.lower() == ".gz" else open
        with opener(path, "rb") as f:
            raw = f.read(limit + 1)
    except FileNotFoundError:
        raise NetworkError(f"cannot read {path}: no such file") from None
    except (OSError, EOFError) as exc:
        raise NetworkError(f"cannot read {path}: {exc}") from None
    if len(raw) > limit:
        raise NetworkError(f"{path}: more than {limit // 2**20} MB (decompressed): "
                           f"expected {what} of at most that size")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise NetworkError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start}): "
                           f"expected {what}") from None
    return text.replace("\r\n", "\n").replace("\r", "\n")  # as a file read as text


def _pgmpy_model(raw: str, fmt: str, path: Path) -> Any:
    """The network of the text ``raw`` of ``path``, read by pgmpy's reader of ``fmt``."""
    if fmt == "bif":
        from bayesprog.io.bif import check_sizes_as_pgmpy_reads

        check_sizes_as_pgmpy_reads(raw, str(path))
    from pgmpy.readwrite import UAIReader, XMLBIFReader

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if fmt == "bif":
                model = _bif_reader()(string=raw).get_model()
            elif fmt == "xmlbif":
                model = XMLBIFReader(string=raw).get_model()
            else:
                model = UAIReader(string=raw).get_model()
    except Exception as exc:  # pgmpy's parsers raise many kinds of errors on bad input
        raise NetworkError(f"{path}: cannot parse as {fmt.upper()}: "
                           f"{type(exc).__name__}: {exc}") from None
    if not hasattr(model, "get_cpds"):
        raise NetworkError(f"{path}: a Markov network (factors without direction) is not "
                           "supported: expected a Bayesian network")
    return model


@functools.cache
def _bif_reader() -> type:
    """pgmpy's ``BIFReader`` with its grammar built once in a process, not for every file:
    its words span every Unicode letter, and building them takes about two seconds. The
    grammar does not depend on the file, and reading with it is pgmpy's own."""
    from pgmpy.readwrite import BIFReader

    class Reader(BIFReader):
        grammars: tuple[Any, Any] | None = None

        def get_variable_grammar(self) -> Any:
            return self._grammars()[0]

        def get_probability_grammar(self) -> Any:
            return self._grammars()[1]

        def _grammars(self) -> tuple[Any, Any]:
            if Reader.grammars is None:
                Reader.grammars = (super().get_variable_grammar(),
                                   super().get_probability_grammar())
            return Reader.grammars

    return Reader


def _read_bif(path: Path) -> Any:
    """The network of the BIF file at ``path``, as :mod:`bayesprog.io.bif` reads it (a
    :class:`~bayesprog.io.bif.Network`) or, for a file with a construct that reader does not
    know, as pgmpy's ``BIFReader`` reads it (a pgmpy model); when neither reads it, a
    :class:`NetworkError` at the line and column of the first problem."""
    from bayesprog.io import bif

    raw = read_text(path)
    try:
        network = bif.read_bif(raw, str(path))
    except bif.BifError as exc:
        problem = NetworkError(f"{exc.source}:{exc.line}:{exc.column}: cannot parse as BIF: "
                               f"{exc.message}")
    else:
        if not network.states:
            raise NetworkError(f"{path}: no variables found: expected a BIF network")
        return network
    try:
        model = _pgmpy_model(raw, "bif", path)
    except NetworkError:
        raise problem from None
    # pgmpy's reader skips what it does not know: a network it reads without a variable or
    # without a CPD is no more read than by bayesprog.io.bif
    cpds = {cpd.variable for cpd in model.get_cpds()}
    if not cpds or any(node not in cpds for node in model.nodes()):
        raise problem from None
    return model


def _safe_name(name: str, taken: set[str]) -> str:
    if _NAME.match(name):
        return name
    base = re.sub(r"[^A-Za-z0-9_.\-]", "_", name)
    base = base if re.match(r"^[A-Za-z_]", base) else f"v_{base}"
    out, i = base, 1
    while out in taken:
        out, i = f"{base}_{i}", i + 1
    return out


def network_to_document(model: Any, name: str, source: str = "") -> dict[str, Any]:
    """A program document with one ``table`` term per CPD (parents in the CPD's order) of a
    pgmpy model or of a :class:`bayesprog.io.bif.Network`."""
    from bayesprog.io.bif import Network

    if isinstance(model, Network):
        tables = {t.variable: (model.states[t.variable], list(t.parents), t.values)
                  for t in model.tables.values()}
        return _tables_to_document(list(model.states), model.edges(), tables, name, source)
    tables = {cpd.variable: (cpd.state_names[cpd.variable], list(cpd.variables[1:]), cpd.values)
              for cpd in model.get_cpds()}
    return _tables_to_document(list(model.nodes()), list(model.edges()), tables, name, source)


def _tables_to_document(nodes: list[Any], edges: list[tuple[Any, Any]],
                        tables: dict[Any, tuple[list[Any], list[Any], Any]], name: str,
                        source: str) -> dict[str, Any]:
    """The document of a network: ``tables[variable]`` is (its states, its parents, the array
    of its CPD: its states first, then the parents', as pgmpy's ``TabularCPD.values``)."""
    missing = [v for v in nodes if v not in tables]
    if missing:
        raise NetworkError(f"{source or name}: no CPD for {', '.join(map(str, missing))}")
    names: dict[str, str] = {}
    for var in nodes:
        names[var] = _safe_name(str(var), set(names.values()))
    variables: dict[str, Any] = {}
    decomposition = []
    for var in _topological(nodes, edges, source or name):
        var_states, parents, values = tables[var]
        states = [str(s) for s in var_states]
        entry: dict[str, Any] = {"states": states}
        if names[var] != str(var):
            entry["description"] = f"named {var!r} in {source or name}"
        variables[names[var]] = entry
        # laid out as pgmpy's TabularCPD lays it out (C order), since the sums below, and so
        # the renormalised rows, depend to the last bit on the order numpy adds in
        table = np.moveaxis(np.ascontiguousarray(values, dtype=float), 0, -1)
        # Files print rounded numbers, so rows may sum to 1 +- 1e-7: make them sum to 1 (a
        # larger deviation is left for the checker to report).
        sums = table.sum(axis=-1, keepdims=True)
        if np.all(np.abs(sums - 1) <= 1e-6):
            table = table / sums
        term = f"P({names[var]} | {', '.join(names[p] for p in parents)})" if parents \
            else f"P({names[var]})"
        decomposition.append({"term": term, "form": "table", "table": table.tolist()})
    doc: dict[str, Any] = {"bayesprog": 1, "name": name}
    if source:
        doc["description"] = f"imported from {source}"
    doc["variables"] = variables
    doc["decomposition"] = decomposition
    return doc


def _topological(nodes: list[Any], edges: list[tuple[Any, Any]], source: str) -> list[Any]:
    """``nodes`` parents first, in networkx's ``topological_sort`` order (generation by
    generation, each in the order nodes and arcs were given), so that imported files keep
    their order; written out here since importing networkx takes most of a second."""
    children: dict[Any, dict[Any, None]] = {v: {} for v in nodes}
    for u, v in edges:  # a node first met in an arc comes after the nodes, as in networkx
        children.setdefault(u, {})[v] = None
        children.setdefault(v, {})
    parents: dict[Any, list[Any]] = {v: [] for v in children}
    for u in children:
        for v in children[u]:
            parents[v].append(u)
    waiting = {v: len(p) for v, p in parents.items() if p}
    order: list[Any] = []
    generation = [v for v, p in parents.items() if not p]
    while generation:
        order += generation
        following = []
        for node in generation:
            for child in children[node]:
                waiting[child] -= 1
                if not waiting[child]:
                    following.append(child)
                    del waiting[child]
        generation = following
    if waiting:
        cycle = find_cycle(list(parents), parents)
        assert cycle is not None
        raise NetworkError(f"{source}: a cycle: {' -> '.join(map(str, cycle))}: expected a "
                           "directed acyclic graph")
    return order


def find_cycle(nodes: list[Any], parents: Mapping[Any, Iterable[Any]]) -> list[Any] | None:
    """A cycle of the arcs parent -> node, as the nodes along it from the first of ``nodes``
    on it back to that node; None when there is none."""
    try:
        graphlib.TopologicalSorter({n: list(parents.get(n, ())) for n in nodes}).prepare()
    except graphlib.CycleError as exc:
        ring = list(exc.args[1])[:-1]  # each node a parent of the next, the first repeated
        first = min(ring, key=nodes.index)
        at = ring.index(first)
        return ring[at:] + ring[:at] + [first]
    return None


class _Dumper12(yaml.SafeDumper):
    """PyYAML's dumper with YAML 1.2's booleans (``true``/``false`` only): a name such as
    ``yes`` or ``off``, which the program loader reads as written, is written unquoted."""


_Dumper12.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers if tag != "tag:yaml.org,2002:bool"]
    for first, resolvers in yaml.SafeDumper.yaml_implicit_resolvers.items()}
for _first in "tTfF":
    _Dumper12.yaml_implicit_resolvers.setdefault(_first, []).append(
        ("tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")))


def dump_document(doc: dict[str, Any]) -> str:
    """YAML text of a document: block style for structure, flow style for the number rows;
    names written as they are (``yes``, ``on``: YAML 1.2 words), quoted only where a YAML 1.2
    reader would take them for something else (``true``, ``null``, ``1.0``)."""
    from bayesprog.language.flow import flow_table

    # tables go as flow lists, a row per line: readable, and read back as one array each
    tables: dict[str, Any] = {}
    entries = []
    for entry in doc.get("decomposition") or []:
        table = entry.get("table") if isinstance(entry, dict) else None
        if isinstance(table, list) and table and _numbers(table):
            name = f"__flow_table_{len(tables)}__"
            tables[name] = table
            entry = _Block({**entry, "table": name})
        entries.append(entry)
    if tables:
        doc = {**doc, "decomposition": entries}
    text = yaml.dump(doc, Dumper=_Dumper12, sort_keys=False, default_flow_style=None,
                     width=100, allow_unicode=True)
    if not tables:
        return text
    lines = text.split("\n")
    for i, line in enumerate(lines):
        name = line.rpartition(" ")[2]
        if name in tables:
            column = len(line) - len(name)
            lines[i] = line[:column] + flow_table(tables[name], column)
    return "\n".join(lines)


class _Block(dict):
    """A mapping written in block style (one key per line)."""


_Dumper12.add_representer(_Block, lambda dumper, data: dumper.represent_mapping(
    "tag:yaml.org,2002:map", data.items(), flow_style=False))


def _numbers(table: list) -> bool:
    """Whether ``table`` is made of numbers only (no booleans), in regular nested lists."""
    try:
        return np.asarray(table).dtype.kind in "iuf"
    except ValueError:  # ragged
        return False


def import_network(path: str | Path, out: str | Path) -> Path:
    """Convert the network at ``path`` into a program file ``out``; returns ``out``."""
    path, out = Path(path), Path(out)
    if network_format(path) == "json":
        from bayesprog.io.gaussian import import_gaussian

        return import_gaussian(path, out)
    if network_format(path) == "bif":
        model = _read_bif(path)
    else:
        model = read_network(path)
        if not list(model.nodes()):
            raise NetworkError(f"{path}: no variables found: expected a "
                               f"{network_format(path).upper()} network")
    name = path.name.split(".")[0]
    out.write_text(dump_document(network_to_document(model, name, path.name)), encoding="utf-8")
    return out


def export_program(program: Any, out: str | Path) -> Path:
    """Write a discrete program with literal tables as BIF, XMLBIF or UAI, or a linear-Gaussian
    program as JSON (by ``out``'s suffix)."""
    from bayesprog.io.compile import to_bayesian_network

    out = Path(out)
    fmt = network_format(out)
    if fmt == "json":
        from bayesprog.io.gaussian import export_gaussian

        return export_gaussian(program, out)
    model = to_bayesian_network(program)
    from pgmpy.readwrite import BIFWriter, UAIWriter, XMLBIFWriter

    writer = {"bif": BIFWriter, "xmlbif": XMLBIFWriter, "uai": UAIWriter}[fmt](model)
    writer.write(str(out))
    return out
