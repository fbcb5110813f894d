"""Linear-Gaussian networks as JSON, the format of bnlearn's Gaussian networks in pgmpy
(``ecoli70.json``, ``magic-niab.json``, ``magic-irri.json``, ``arth150.json``, and what
``LinearGaussianBayesianNetwork.save`` writes):

.. code-block:: json

    {"nodes": ["A", "B"],
     "arcs": [["A", "B"]],
     "cpds": {"A": {"coefficients": {"(Intercept)": [1.2]}, "variance": [0.5], "parents": []},
              "B": {"coefficients": {"(Intercept)": [0.1], "A": [-0.3]}, "variance": [0.2],
                    "parents": ["A"]}}}

Each node ``X`` with parents ``P1..Pk`` is ``X = b0 + b1 P1 + ... + bk Pk + e``,
``e ~ N(0, variance)``: ``variance`` is the variance, not the standard deviation (pgmpy's
reader takes ``std = sqrt(variance[0])``). As a program, each node is a real variable on the
whole line and a ``normal`` term whose mean is that affine formula and whose sigma is
``sqrt(variance)`` with the variance as written; the file's numbers come back unchanged on
export (:func:`variance_of`):

>>> doc = gaussian_to_document(check_network({"nodes": ["A", "b.1"], "arcs": [["A", "b.1"]],
...     "cpds": {"A": {"coefficients": {"(Intercept)": [1.2]}, "variance": [0.5],
...                    "parents": []},
...              "b.1": {"coefficients": {"(Intercept)": [0.1], "A": [-0.3]},
...                      "variance": [0.2], "parents": ["A"]}}}, "net.json"), "net", "net.json")
>>> [(t["term"], t["mean"], t["sigma"]) for t in doc["decomposition"]]
[('P(A)', 1.2, 'sqrt(0.5)'), ('P(b_1 | A)', '0.1 - 0.3*A', 'sqrt(0.2)')]
>>> doc["variables"]["b_1"]["description"]
"named 'b.1' in net.json"

Names that a formula cannot hold (``YR.GLASS``, ``4``, a formula's function or constant such
as ``e``) are rewritten as identifiers (``YR_GLASS``, ``v_4``, ``e_``), the original kept in
the variable's description, as the BIF importer does; export reads it back from there.
Everything is checked before anything is built, and every problem of a file is reported in
one line: a file that is not JSON, a missing key, a cycle, a variance that is not a positive
number, a coefficient or parent that names no node, arcs that disagree with the parents.
"""

from __future__ import annotations

import ast
import gzip
import json
import keyword
import math
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from bayesprog.io import NetworkError, dump_document, find_cycle, read_text

#: The largest network file read (decompressed), in bytes: bnlearn's largest Gaussian network
#: (arth150, 107 nodes) takes 22 kB, so this is some hundred thousand nodes; Python's JSON
#: parser takes several times a file's size in memory, which is bounded before it runs.
MAX_BYTES = 64 * 2**20
#: The key of the intercept among a node's coefficients (bnlearn's, as R names it).
INTERCEPT = "(Intercept)"
#: Problems reported at most, in one line (then how many more).
SHOWN = 8

_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_NAMED = re.compile(r"^named ('(?:[^'\\]|\\.)*'|\"(?:[^\"\\]|\\.)*\") in ")


def read_gaussian(path: str | Path) -> dict[str, Any]:
    """The checked network of the JSON file at ``path`` (see :func:`check_network`)."""
    path = Path(path)
    text = read_text(path, MAX_BYTES, "a JSON network")

    def no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in pairs:
            if key in out:
                raise ValueError(f"the key {key!r} is given twice in one object")
            out[key] = value
        return out

    def no_constant(name: str) -> float:
        raise ValueError(f"{name} is not a JSON number")

    try:
        data = json.loads(text, object_pairs_hook=no_duplicates, parse_constant=no_constant)
    except json.JSONDecodeError as exc:
        raise NetworkError(f"{path}: not JSON ({exc.msg} at line {exc.lineno}, column "
                           f"{exc.colno}): expected a linear-Gaussian network with nodes, arcs "
                           "and cpds") from None
    except (ValueError, RecursionError) as exc:
        raise NetworkError(f"{path}: not a network: {exc}") from None
    return check_network(data, str(path))


def check_network(data: Any, source: str) -> dict[str, Any]:
    """``data`` (a parsed JSON network) checked: ``{"nodes": [...], "parents": {node: [...]},
    "intercept": {node: float}, "coefficients": {node: [float per parent]}, "variance":
    {node: float}, "order": [nodes, parents first]}``; a :class:`NetworkError` naming
    ``source`` and every problem otherwise."""
    problems: list[str] = []
    if not isinstance(data, dict):
        raise NetworkError(f"{source}: expected a JSON object with nodes, arcs and cpds, found "
                           f"{_kind(data)}")
    missing = [k for k in ("nodes", "arcs", "cpds") if k not in data]
    if missing:
        raise NetworkError(f"{source}: missing key{'s' if len(missing) > 1 else ''} "
                           f"{', '.join(repr(k) for k in missing)}: expected nodes, arcs and "
                           "cpds, as pgmpy's LinearGaussianBayesianNetwork.save writes")
    nodes = data["nodes"]
    if not isinstance(nodes, list) or not all(isinstance(n, str) and n for n in nodes):
        raise NetworkError(f"{source}: nodes: expected a list of names, found {_kind(nodes)}")
    known = set(nodes)
    if len(known) < len(nodes):
        twice = sorted({n for n in nodes if nodes.count(n) > 1})
        problems.append(f"nodes: {', '.join(map(repr, twice))} given twice")
    if not nodes:
        problems.append("nodes: empty: expected at least one node")
    arcs: set[tuple[str, str]] = set()
    if not isinstance(data["arcs"], list):
        problems.append(f"arcs: expected a list of [from, to] pairs, found {_kind(data['arcs'])}")
    else:
        for i, arc in enumerate(data["arcs"]):
            if not (isinstance(arc, list) and len(arc) == 2
                    and all(isinstance(a, str) for a in arc)):
                problems.append(f"arcs[{i}]: expected a [from, to] pair of names, found "
                                f"{_short(arc)}")
                continue
            unknown = [a for a in arc if a not in known]
            if unknown:
                problems.append(f"arcs[{i}]: {', '.join(map(repr, unknown))} is not a node")
            arcs.add((arc[0], arc[1]))
    cpds = data["cpds"]
    if not isinstance(cpds, dict):
        raise NetworkError(f"{source}: cpds: expected an object with one entry per node, found "
                           f"{_kind(cpds)}")
    out: dict[str, Any] = {"nodes": list(nodes), "parents": {}, "intercept": {},
                           "coefficients": {}, "variance": {}}
    for name in cpds:
        if name not in known:
            problems.append(f"cpds[{name!r}]: not a node")
    for name in nodes:
        if name not in cpds:
            problems.append(f"cpds: no entry for the node {name!r}")
            continue
        _check_cpd(name, cpds[name], known, out, problems)
    given = {(p, v) for v, ps in out["parents"].items() for p in ps}
    for p, v in sorted(arcs - given):
        if p in known and v in out["parents"]:
            problems.append(f"arcs: {p} -> {v}, but {p!r} is not among {v!r}'s parents")
    for p, v in sorted(given - arcs):
        if isinstance(data["arcs"], list):
            problems.append(f"cpds[{v!r}].parents: {p!r}, but arcs has no {p} -> {v}")
    if problems:
        raise NetworkError(_joined(source, problems))
    cycle = find_cycle(nodes, out["parents"])
    if cycle:
        raise NetworkError(f"{source}: a cycle: {' -> '.join(cycle)}: expected a directed "
                           "acyclic graph")
    out["order"] = _topological(nodes, out["parents"])
    return out


def _check_cpd(name: str, cpd: Any, known: set[str], out: dict[str, Any],
               problems: list[str]) -> None:
    where = f"cpds[{name!r}]"
    if not isinstance(cpd, dict):
        problems.append(f"{where}: expected an object with coefficients, variance and parents, "
                        f"found {_kind(cpd)}")
        return
    missing = [k for k in ("coefficients", "variance", "parents") if k not in cpd]
    if missing:
        problems.append(f"{where}: missing {', '.join(map(repr, missing))}: expected "
                        "coefficients, variance and parents")
        return
    extra = sorted(set(cpd) - {"coefficients", "variance", "parents"})
    if extra:
        problems.append(f"{where}: unknown key{'s' if len(extra) > 1 else ''} "
                        f"{', '.join(map(repr, extra))}: expected coefficients, variance and "
                        "parents")
    parents = cpd["parents"]
    if not isinstance(parents, list) or not all(isinstance(p, str) for p in parents):
        problems.append(f"{where}.parents: expected a list of node names, found "
                        f"{_short(parents)}")
        return
    bad = [p for p in parents if p not in known]
    if bad:
        problems.append(f"{where}.parents: {', '.join(map(repr, bad))} is not a node")
    if len(set(parents)) < len(parents) or name in parents:
        problems.append(f"{where}.parents: expected distinct nodes other than {name!r}, found "
                        f"{_short(parents)}")
    coefficients = cpd["coefficients"]
    if not isinstance(coefficients, dict):
        problems.append(f"{where}.coefficients: expected an object, found {_kind(coefficients)}")
        return
    for key in coefficients:
        if key != INTERCEPT and key not in parents:
            what = "is not a node" if key not in known else f"is not among {name!r}'s parents"
            problems.append(f"{where}.coefficients: {key!r} {what} (expected {INTERCEPT!r} "
                            "and one coefficient per parent)")
    values = {}
    for key in (INTERCEPT, *parents):
        if key not in coefficients:
            problems.append(f"{where}.coefficients: no {key!r}"
                            + (" (a coefficient per parent)" if key != INTERCEPT else ""))
            continue
        values[key] = _number(coefficients[key], f"{where}.coefficients[{key!r}]", problems)
    variance = _number(cpd["variance"], f"{where}.variance", problems)
    if variance is not None and not variance > 0:
        problems.append(f"{where}.variance: expected a number > 0 (a variance), found "
                        f"{variance!r}")
    if len(values) == len(parents) + 1 and None not in values.values() and not bad:
        out["parents"][name] = list(parents)
        out["intercept"][name] = values[INTERCEPT]
        out["coefficients"][name] = [values[p] for p in parents]
        out["variance"][name] = variance
    elif not bad:
        out["parents"][name] = list(parents)


def _number(value: Any, where: str, problems: list[str]) -> float | None:
    """A one-element list of a finite number (as bnlearn writes it), or a plain number."""
    if isinstance(value, list) and len(value) == 1:
        value = value[0]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        problems.append(f"{where}: expected a finite number (or a list of one), found "
                        f"{_short(value)}")
        return None
    return float(value)


def _topological(nodes: list[str], parents: dict[str, list[str]]) -> list[str]:
    """The nodes, each after its parents, otherwise in the file's order."""
    import heapq

    rank = {n: i for i, n in enumerate(nodes)}
    waiting = {n: len(parents.get(n, [])) for n in nodes}
    children: dict[str, list[str]] = {n: [] for n in nodes}
    for v, ps in parents.items():
        for p in ps:
            children[p].append(v)
    ready = [rank[n] for n in nodes if not waiting[n]]
    heapq.heapify(ready)
    order = []
    while ready:
        node = nodes[heapq.heappop(ready)]
        order.append(node)
        for child in children[node]:
            waiting[child] -= 1
            if not waiting[child]:
                heapq.heappush(ready, rank[child])
    return order


def formula_names(names: Iterable[str]) -> dict[str, str]:
    """A name that a formula can hold for each of ``names``: the name itself when it is an
    identifier (not a Python keyword, nor a formula's function or constant), else the name
    with ``_`` for each other character (``v_`` before a leading digit, ``_`` after a reserved
    word), made unique.

    >>> formula_names(["YR.GLASS", "YR_GLASS", "4", "e", "lambda"])
    {'YR.GLASS': 'YR_GLASS_1', 'YR_GLASS': 'YR_GLASS', '4': 'v_4', 'e': 'e_', 'lambda': 'lambda_'}
    """
    from bayesprog.vocabulary.formula import CONSTANTS, FUNCTIONS

    def usable(name: str) -> bool:
        return (bool(_IDENTIFIER.match(name)) and not keyword.iskeyword(name)
                and name not in FUNCTIONS and name not in CONSTANTS)

    names = list(names)
    out = {n: n for n in names if usable(n)}
    taken = set(out)
    for name in names:
        if name in out:
            continue
        base = re.sub(r"[^A-Za-z0-9_]", "_", name)
        base = base if re.match(r"^[A-Za-z_]", base) else f"v_{base}"
        base = base if usable(base) else f"{base}_"
        found, i = base, 1
        while found in taken:
            found, i = f"{base}_{i}", i + 1
        out[name] = found
        taken.add(found)
    return {n: out[n] for n in names}


def gaussian_to_document(network: dict[str, Any], name: str, source: str = "") -> dict[str, Any]:
    """A program document of a checked network (:func:`check_network`): one real variable per
    node (in the file's order) and one ``normal`` term per node (parents first)."""
    from bayesprog.vocabulary.formula import MAX_LENGTH

    names = formula_names(network["nodes"])
    variables: dict[str, Any] = {}
    for node in network["nodes"]:
        entry: dict[str, Any] = {"continuous": [-math.inf, math.inf]}
        if names[node] != node:
            entry["description"] = f"named {node!r} in {source or name}"
        variables[names[node]] = entry
    decomposition = []
    for node in network["order"]:
        parents = [names[p] for p in network["parents"][node]]
        intercept = network["intercept"][node]
        term = f"P({names[node]} | {', '.join(parents)})" if parents else f"P({names[node]})"
        mean: float | str = intercept
        if parents:
            mean = repr(intercept) + "".join(
                f" {'-' if math.copysign(1, c) < 0 else '+'} {abs(c)!r}*{p}"
                for p, c in zip(parents, network["coefficients"][node], strict=True))
            if len(mean) > MAX_LENGTH:
                raise NetworkError(f"{source or name}: {node!r} has {len(parents)} parents: its "
                                   f"mean takes {len(mean):,} characters, more than the "
                                   f"{MAX_LENGTH:,} a formula may hold")
        decomposition.append({"term": term, "form": "normal", "mean": mean,
                              "sigma": f"sqrt({network['variance'][node]!r})"})
    doc: dict[str, Any] = {"bayesprog": 1, "name": name}
    if source:
        doc["description"] = f"imported from {source} (a linear-Gaussian network)"
    doc["variables"] = variables
    doc["decomposition"] = decomposition
    return doc


def import_gaussian(path: str | Path, out: str | Path) -> Path:
    """Convert the JSON network at ``path`` into the program file ``out``; returns ``out``."""
    path, out = Path(path), Path(out)
    network = read_gaussian(path)
    name = path.name.split(".")[0]
    out.write_text(dump_document(gaussian_to_document(network, name, path.name)),
                   encoding="utf-8")
    return out


def program_to_gaussian(program: Any) -> dict[str, Any]:
    """The JSON network of a linear-Gaussian program: every variable real, every term a Gaussian
    (a form with a mean and a scale, ``normal``) whose mean is a number or one affine formula of
    its parents and whose sigma is a number (:func:`variance_of` gives its variance); original
    names read back from the descriptions the importer wrote."""
    from bayesprog.forms import FormulaParam, ParamValue

    def fail(why: str) -> NetworkError:
        return NetworkError(f"{program.name}: {why}: a linear-Gaussian network (JSON) needs "
                            "real variables with normal terms, means affine in the parents "
                            "and literal sigmas")

    if program.conditioning:
        raise fail(f"{', '.join(program.conditioning)} has no term (the program is conditioned "
                   "on it), and a network gives every variable one")
    original: dict[str, str] = {}
    for name, var in program.variables.items():
        if var.is_discrete:
            raise fail(f"{name} is discrete")
        found = _NAMED.match(var.description or "")
        original[name] = ast.literal_eval(found.group(1)) if found else name
    cpds: dict[str, Any] = {}
    for term in program.active_terms:
        if term.soft:
            raise fail("soft evidence has no place in a network")
        child = term.child.name
        mean_key, scale_key = term.form.mean_param, term.form.scale_param
        if mean_key is None or scale_key is None or set(term.params) != {mean_key, scale_key}:
            raise fail(f"{term.label} is a {term.form.name} term")
        parents = [p.name for p in term.parents]
        mean = term.params[mean_key]
        if isinstance(mean, FormulaParam) and not mean.axes:
            affine = mean.formulas.flat[0].affine()
            if affine is None:
                raise fail(f"{term.label}: its mean \"{mean.formulas.flat[0]}\" is not affine")
            intercept, slopes = affine
            others = [n for n in slopes if n not in parents]
            if others:
                raise fail(f"{term.label}: its mean names {', '.join(others)}, not a parent")
        elif isinstance(mean, ParamValue) and not mean.axes and not parents:
            intercept, slopes = float(mean.array), {}
        else:
            raise fail(f"{term.label}: its mean is not one number or formula")
        sigma = term.params[scale_key]
        if isinstance(sigma, ParamValue) and not sigma.axes and not sigma.batched:
            variance = variance_of(float(sigma.array))
        else:
            raise fail(f"{term.label}: its {scale_key} is not one number")
        coefficients = {INTERCEPT: [intercept]}
        coefficients.update({original[p]: [slopes.get(p, 0.0)] for p in parents})
        cpds[child] = {"coefficients": coefficients, "variance": [variance],
                       "parents": [original[p] for p in parents]}
    missing = [n for n in program.variables if n not in cpds]
    if missing:
        raise fail(f"no term for {', '.join(missing)}")
    nodes = list(program.variables)
    rank = {n: i for i, n in enumerate(nodes)}
    arcs = sorted(((p.name, t.child.name) for t in program.active_terms for p in t.parents),
                  key=lambda arc: (rank[arc[0]], rank[arc[1]]))
    return {"nodes": [original[n] for n in nodes],
            "arcs": [[original[a], original[b]] for a, b in arcs],
            "cpds": {original[n]: cpds[n] for n in nodes}}


def variance_of(sigma: float) -> float:
    """The variance whose square root is ``sigma``, written with the fewest digits: of the
    two or three floats ``v`` with ``sqrt(v) == sigma``, the one with the shortest decimal
    form. A variance of up to 15 significant digits (bnlearn's have four) is the only one of
    that length among them, so ``sigma: sqrt(0.0853)``, which the loader keeps as the float
    ``sqrt(0.0853)``, gives back ``0.0853``; a longer one comes back within a unit of the last
    place.

    >>> import math
    >>> variance_of(math.sqrt(0.0853)), math.sqrt(0.0853) ** 2
    (0.0853, 0.08530000000000001)
    """
    from decimal import Decimal

    square = sigma * sigma
    for digits in range(1, 18):
        nearest = Decimal(f"{square:.{digits - 1}e}")
        step = Decimal(1).scaleb(nearest.adjusted() - digits + 1)
        for candidate in (nearest, nearest - step, nearest + step):
            value = float(candidate)
            if value > 0 and math.sqrt(value) == sigma:
                return value
    return square


def dump_gaussian(network: dict[str, Any]) -> str:
    """JSON text laid out as bnlearn's files in pgmpy are (one arc a line, each node's
    coefficients one a line), numbers written as Python's shortest repr."""
    def line(value: Any) -> str:
        return json.dumps(value, ensure_ascii=False)

    lines = ["{", f'  "nodes": {line(network["nodes"])},', '  "arcs": [']
    lines += [f"    {line(arc)}," for arc in network["arcs"]]
    if network["arcs"]:
        lines[-1] = lines[-1][:-1]
    lines += ["  ],", '  "cpds": {']
    for i, (node, cpd) in enumerate(network["cpds"].items()):
        lines.append(f"    {line(node)}: {{")
        lines.append('      "coefficients": {')
        entries = [f"        {line(k)}: {line(v)}" for k, v in cpd["coefficients"].items()]
        lines.append(",\n".join(entries))
        lines.append("      },")
        lines.append(f'      "variance": {line(cpd["variance"])},')
        lines.append(f'      "parents": {line(cpd["parents"])}')
        lines.append("    }" + ("," if i < len(network["cpds"]) - 1 else ""))
    lines += ["  }", "}"]
    return "\n".join(lines) + "\n"


def export_gaussian(program: Any, out: str | Path) -> Path:
    """Write a linear-Gaussian program as a JSON network (gzipped when ``out`` ends in
    ``.gz``)."""
    out = Path(out)
    text = dump_gaussian(program_to_gaussian(program))
    if out.suffix.lower() == ".gz":
        with gzip.open(out, "wt", encoding="utf-8") as f:
            f.write(text)
    else:
        out.write_text(text, encoding="utf-8")
    return out


def _kind(value: Any) -> str:
    names = {dict: "an object", list: "a list", str: "a string", bool: "a boolean",
             type(None): "null", int: "a number", float: "a number"}
    return names.get(type(value), type(value).__name__)


def _short(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, float) or math.isfinite(value) \
        else repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _joined(source: str, problems: list[str]) -> str:
    shown = "; ".join(problems[:SHOWN])
    more = len(problems) - SHOWN
    return f"{source}: {shown}" + (f"; and {more} more problem{'s' * (more > 1)}"
                                   if more > 0 else "")
