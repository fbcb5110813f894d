"""Exchange with other tools: BIF, XMLBIF and UAI networks, read and written through pgmpy,
and linear-Gaussian networks as JSON (:mod:`bayesprog.io.gaussian`).

``import_network`` turns a network file into a program document (states and CPT layout kept:
one ``table`` term per variable, parents in the file's order; rows that sum to 1 within 1e-6,
as rounded files print them, are renormalised); ``export_program`` writes a discrete program
back. pgmpy is imported lazily (importing it is slow).
"""

from __future__ import annotations

import gzip
import re
import warnings
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


def read_network(path: str | Path) -> Any:
    """A pgmpy ``DiscreteBayesianNetwork`` (or, for UAI Markov files, an error) from ``path``."""
    path = Path(path)
    fmt = network_format(path)
    if fmt == "json":
        raise NetworkError(f"{path}: a linear-Gaussian network: read it with "
                           "bayesprog.io.gaussian.read_gaussian")
    try:
        raw = gzip.open(path, "rt", encoding="utf-8").read() if path.suffix == ".gz" \
            else path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise NetworkError(f"cannot read {path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise NetworkError(f"cannot read {path}: {exc}") from None
    from pgmpy.readwrite import BIFReader, UAIReader, XMLBIFReader

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if fmt == "bif":
                model = BIFReader(string=raw).get_model()
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
    """A program document with one ``table`` term per CPD (parents in the CPD's order)."""
    cpds = {cpd.variable: cpd for cpd in model.get_cpds()}
    missing = [v for v in model.nodes() if v not in cpds]
    if missing:
        raise NetworkError(f"{source or name}: no CPD for {', '.join(map(str, missing))}")
    names: dict[str, str] = {}
    for var in model.nodes():
        names[var] = _safe_name(str(var), set(names.values()))
    variables: dict[str, Any] = {}
    decomposition = []
    for var in _topological(model):
        cpd = cpds[var]
        states = [str(s) for s in cpd.state_names[var]]
        entry: dict[str, Any] = {"states": states}
        if names[var] != str(var):
            entry["description"] = f"named {var!r} in {source or name}"
        variables[names[var]] = entry
        parents = list(cpd.variables[1:])
        table = np.moveaxis(np.asarray(cpd.values, dtype=float), 0, -1)
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


def _topological(model: Any) -> list[str]:
    import networkx as nx

    graph = nx.DiGraph()
    graph.add_nodes_from(model.nodes())
    graph.add_edges_from(model.edges())
    return list(nx.topological_sort(graph))


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
    """Whether ``table`` is made of numbers only, in nested lists."""
    return all(_numbers(x) if isinstance(x, list) else
               isinstance(x, (int, float)) and not isinstance(x, bool) for x in table)


def import_network(path: str | Path, out: str | Path) -> Path:
    """Convert the network at ``path`` into a program file ``out``; returns ``out``."""
    path, out = Path(path), Path(out)
    if network_format(path) == "json":
        from bayesprog.io.gaussian import import_gaussian

        return import_gaussian(path, out)
    model = read_network(path)
    if not list(model.nodes()):
        raise NetworkError(f"{path}: no variables found: expected a {network_format(path).upper()} "
                           "network")
    name = path.name.split(".")[0]
    out.write_text(dump_document(network_to_document(model, name, path.name)), encoding="utf-8")
    return out


def export_program(program: Any, out: str | Path) -> Path:
    """Write a discrete program with literal tables as BIF, XMLBIF or UAI, or a linear-Gaussian
    program as JSON (by ``out``'s suffix)."""
    from bayesprog.compile import to_bayesian_network

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
