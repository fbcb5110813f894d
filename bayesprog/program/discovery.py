"""Discovering a program's decomposition from data.

:func:`discover` reads a data set (as :meth:`Program.fit` does), takes each column's states from
it, finds a DAG over the columns (hill climbing on a score, or the PC algorithm; see
:mod:`bayesprog.learning.structure`), writes it as a program of tables, fits the tables as
``bayesprog learn`` does and records how, under ``learned:``. Programs are compared by their
evidence in :mod:`bayesprog.learning.evidence`.
"""

from __future__ import annotations

import functools
import json
import math
import re
import time
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bayesprog.learning.data import Columns, DataError, _missing, frame_columns, read_columns
from bayesprog.learning.structure import (
    MAX_FAMILY_CELLS,
    SCORES,
    TESTS,
    Constraints,
    Scores,
    StructureError,
    check_dag,
    hill_climb,
    orient,
    pc_skeleton,
    topological,
)

if TYPE_CHECKING:
    import pandas as pd

    from bayesprog.program import Program

METHODS = ("hc", "pc")
#: hill climbing's random restarts when none are asked for
RESTARTS = 5
#: the most states a column of numbers takes as they are (more: discretise it)
MAX_NUMBER_STATES = 50
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")
_ARC = re.compile(r"^\s*([^\s>-][^>]*?)\s*->\s*(\S.*?)\s*$")


@dataclass
class Coded:
    """A data set coded for structure learning: each column's states (as written, sorted, or
    bins), the rows as state indices (-1 where missing), and the rows as state names
    (categorical columns, the categories the states in order)."""

    source: str
    sha256: str
    names: list[str]
    states: list[list[str]]
    codes: np.ndarray
    bins: dict[str, list[float]] = field(default_factory=dict)

    @functools.cached_property
    def frame(self) -> pd.DataFrame:
        """The rows as their states' names (made when first read: the search reads codes)."""
        import pandas as pd

        return pd.DataFrame({column: _named(self.codes[:, j], self.states[j])
                             for j, column in enumerate(self.names)}, columns=self.names)

    @property
    def card(self) -> list[int]:
        return [len(s) for s in self.states]

    @property
    def missing_rows(self) -> int:
        return int((self.codes < 0).any(axis=1).sum())


def _name_of(value: Any) -> str:
    """A cell's value as a state's name, as written: ``3.0`` read from Parquet is ``3``."""
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (float, np.floating)) and float(value).is_integer():
        return str(int(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return str(value).strip()


def _number(text: str) -> float | None:
    try:
        x = float(text)
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def _distinct(values: pd.Series) -> tuple[np.ndarray, list[Any]]:
    """Each row's index among a column's distinct values (a missing value one of them), and
    those values. A column of Python objects of several kinds is read value by value: pandas
    takes ``True``, ``1`` and ``1.0`` for one value, where ``True`` is written ``true`` and
    the others ``1``: two states (a column of integers alone, or of booleans alone, with or
    without nulls, has its equal values written alike, and is coded by pandas as a column of
    strings is)."""
    import pandas as pd

    which, uniques = pd.factorize(values, use_na_sentinel=False)
    distinct = list(uniques)
    if values.dtype == object and not all(isinstance(v, str) or _missing(v) for v in distinct):
        cells = values.to_numpy(dtype=object)
        kinds = set(map(type, cells)) - {type(None), type(pd.NA)}
        if not (len(kinds) == 1 and issubclass(kinds.pop(), (int, np.integer, np.bool_))):
            return np.arange(len(values)), list(cells)
    return np.asarray(which, dtype=np.int64), distinct


def _named(codes: np.ndarray, states: list[str]) -> Any:
    """A column of state indices as its states' names (missing where -1): categorical, the
    categories the states in order, unless two states have one name."""
    import pandas as pd

    if len(set(states)) == len(states):
        return pd.Categorical.from_codes(codes, categories=pd.Index(states, dtype=object))
    return np.array([*states, None], dtype=object)[codes]


def code_data(data: Any, *, discretise: int | None = None,
              columns: Mapping[str, str] | None = None) -> Coded:
    """Read ``data`` (a CSV or Parquet file, a DataFrame, a mapping of columns) and code every
    column as a discrete variable: its states are the values found, as written (sorted by value
    when all are numbers, else alphabetically); with ``discretise=K``, a column of numbers with
    more than K distinct values is cut into K bins of equal counts (named ``"[a, b)"``, as the
    language's discretised variables). A column that cannot be a variable is refused, named."""
    import pandas as pd

    if isinstance(data, pd.DataFrame):  # coded once, its hash read from the codes
        read = frame_columns(data, _distinct)
    else:  # a plain CSV file by the learner's reader
        read = read_columns(data, factorised=_distinct)
    source, digest, written, rows = read.source, read.sha256, read.names, read.rows
    if columns:
        missing = [c for c in columns if c not in written]
        if missing:
            raise DataError(f"{source}: no column {missing[0]!r} to rename (columns: "
                            f"{', '.join(written)})")
    names = [columns.get(c, c) for c in written] if columns else written
    if not names:
        raise DataError(f"{source}: no column: expected one column per variable")
    if rows == 0:
        raise DataError(f"{source}: no row: expected one row per observation")
    if len(set(names)) != len(names):
        dup = next(c for c in names if names.count(c) > 1)
        raise DataError(f"{source}: column {dup!r} appears twice")
    if discretise is not None and (isinstance(discretise, bool) or not isinstance(
            discretise, (int, np.integer)) or discretise < 2):
        raise DataError(f"discretise: expected a number of bins >= 2, found {discretise!r}")
    states: list[list[str]] = []
    codes = np.full((rows, len(names)), -1, dtype=np.int64, order="F")
    bins: dict[str, list[float]] = {}
    for j, column in enumerate(names):
        if not _NAME.match(column):
            raise DataError(f"{source}: column {j + 1} {column!r} cannot name a variable: "
                            "expected a letter or _ then letters, digits, _ . - (rename it, or "
                            "--column)")
        which, values = read.column(j)
        distinct = list(values)
        # each distinct value's text (None when missing), read once
        absent = np.array([_missing(v) for v in distinct], dtype=bool)
        text_of = np.array([None if a else _name_of(v) for v, a in zip(distinct, absent,
                                                                         strict=True)],
                           dtype=object)
        present = ~absent[which]
        found = sorted(set(text_of[~absent]))
        count = int(present.sum())
        if count == 0:
            raise DataError(f"{source}: column {column!r} has no value in any of its "
                            f"{len(which)} rows")
        numbers = [_number(t) for t in found]
        numeric = all(x is not None for x in numbers)
        if discretise is not None and numeric and len(found) > discretise:
            number_of = np.array([np.nan if t is None else float(t) for t in text_of])
            x = number_of[which[present]]
            edges = np.unique(np.quantile(x, np.linspace(0, 1, discretise + 1)))
            inner = edges[1:-1]
            index = np.searchsorted(inner, x, side="right")
            labels = [f"[{edges[i]:.6g}, {edges[i + 1]:.6g}" + (")" if i < len(edges) - 2
                                                                  else "]")
                      for i in range(len(edges) - 1)]
            codes[present, j] = index
            column_states = labels
            bins[column] = [float(e) for e in edges]
        else:
            if numeric:
                found = sorted(found, key=lambda t: (float(t), t))
            lookup = {s: i for i, s in enumerate(found)}
            state_of = np.array([-1 if t is None else lookup[t] for t in text_of],
                                dtype=np.int64)
            codes[:, j] = state_of[which]
            column_states = found
        if len(column_states) == 1:
            raise DataError(f"{source}: column {column!r} holds one value, "
                            f"{column_states[0]!r}, in all its {count} rows: a constant "
                            "tells nothing of the others (drop the column)")
        if len(column_states) == count and count > 2:
            hint = " or --discretise it" if numeric else ""
            raise DataError(f"{source}: column {column!r} has a different value in each of its "
                            f"{count} rows: every state seen once, an identifier rather than "
                            f"a variable (drop the column{hint})")
        if numeric and discretise is None and len(column_states) > MAX_NUMBER_STATES:
            raise DataError(f"{source}: column {column!r} holds {len(column_states)} different "
                            f"numbers: as states, each would be seen about "
                            f"{count / len(column_states):.1f} times (discretise it into bins: "
                            "--discretise K)")
        states.append(column_states)
    return Coded(source, digest, names, states, codes, bins)


# constraints from text ---------------------------------------------------------------------

def _arcs(given: Iterable[str | tuple[str, str]], names: Sequence[str],
          option: str) -> set[tuple[int, int]]:
    out = set()
    index = {n: i for i, n in enumerate(names)}
    for item in given:
        if isinstance(item, str):
            match = _ARC.match(item)
            if match is None:
                hint = (" (quote the arc, --forbid 'A->B': a shell reads > as a redirection)"
                        if item.rstrip().endswith("-") else "")
                raise StructureError(f"{option} {item!r}: expected an arc A->B{hint}")
            pair = (match.group(1), match.group(2))
        else:
            pair = (str(item[0]), str(item[1]))
        for name in pair:
            if name not in index:
                raise StructureError(f"{option} {pair[0]}->{pair[1]}: no variable {name!r} "
                                     f"(the data's columns: {', '.join(names)})")
        if pair[0] == pair[1]:
            raise StructureError(f"{option} {pair[0]}->{pair[1]}: an arc joins two variables")
        out.add((index[pair[0]], index[pair[1]]))
    return out


def read_tiers(tiers: Any, names: Sequence[str]) -> list[int]:
    """Each variable's tier from a list of groups (earliest first), or a YAML/text file of
    them: one group per line (names separated by commas or spaces), or a YAML list of lists.
    Variables in no group come after every tier."""
    where = "tiers"
    if isinstance(tiers, (str, Path)):
        path = Path(tiers)
        where = str(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise StructureError(f"--tiers {path}: cannot read it: {exc.strerror or exc}") \
                from None
        if path.suffix in (".yaml", ".yml"):
            import yaml

            groups = yaml.safe_load(text)
        else:
            groups = [re.split(r"[,\s]+", line.strip()) for line in text.splitlines()
                      if line.strip() and not line.lstrip().startswith("#")]
    else:
        groups = tiers
    if not isinstance(groups, list) or not all(isinstance(g, list) for g in groups):
        raise StructureError(f"{where}: expected ordered groups of variables (a list of lists, "
                             "or one group per line)")
    index = {n: i for i, n in enumerate(names)}
    tier = [len(groups)] * len(names)
    seen: dict[str, int] = {}
    for t, group in enumerate(groups):
        for name in group:
            name = str(name)
            if name not in index:
                raise StructureError(f"{where}: tier {t + 1} names {name!r}, which is no "
                                     f"column of the data ({', '.join(names)})")
            if name in seen:
                raise StructureError(f"{where}: {name} is in tiers {seen[name] + 1} and {t + 1}")
            seen[name] = t
            tier[index[name]] = t
    return tier


# what the data's independences cannot show ------------------------------------------------

class StructureWarning(UserWarning):
    """A discovered arc that the data contradict in a way the search cannot see (an arc into a
    variable that is a function of its other parents)."""


#: rows per configuration of the determining variables, on average, before a variable is
#: said to be a function of them (fewer rows make a function of chance)
ROWS_PER_CONFIGURATION = 5


def determined_by(codes: np.ndarray, child: int, candidates: Sequence[int],
                  scores: Scores | None = None) -> list[int] | None:
    """The smallest set of ``candidates`` (the first of its size) of which the column ``child``
    is a function in the data: each configuration of them seen (rows where all are known)
    shows one value of ``child``, with ``ROWS_PER_CONFIGURATION`` rows per configuration on
    average; None when there is none, or ``child`` takes one value only. ``scores``: the
    :class:`Scores` of ``codes``, whose counts are read (else they are made)."""
    import itertools

    if scores is None:
        scores = Scores(codes, np.maximum(np.asarray(codes).max(axis=0) + 1, 1))
    for size in range(1, len(candidates)):
        for subset in itertools.combinations(sorted(candidates), size):
            counts = scores.observed_counts(child, subset)  # configurations x child states
            seen = counts > 0
            if np.count_nonzero(seen.any(axis=0)) < 2:
                continue
            configurations = int(seen.any(axis=1).sum())
            known = int(counts.sum())
            if (int(seen.sum()) == configurations
                    and known >= ROWS_PER_CONFIGURATION * configurations):
                return list(subset)
    return None


def deterministic_warnings(coded: Coded, parents: Sequence[Sequence[int]], method: str,
                           scores: Scores | None = None) -> list[str]:
    """An arc into a variable that the data show to be a function of its other parents: the
    independence tests (pc) or the scores (hc) cannot place it, since given those parents it
    carries nothing more (the faithfulness the search assumes fails there); such arcs usually
    point the wrong way (the variable's children taken for its parents)."""
    names = coded.names
    out = []
    if scores is None and any(len(ps) >= 2 for ps in parents):
        scores = Scores(coded.codes, coded.card)
    for v, ps in enumerate(parents):
        if len(ps) < 2:
            continue
        determining = determined_by(coded.codes, v, ps, scores)
        if determining is None:
            continue
        extra = [names[p] for p in sorted(ps) if p not in determining]
        by = ", ".join(names[p] for p in determining)
        arcs = ", ".join(f"{e} -> {names[v]}" for e in extra)
        out.append(f"{names[v]} is a function of {by} in the data (each of their "
                   f"configurations shows one value of {names[v]}): the arcs {arcs} contradict "
                   f"that deterministic table, which needs no other parent. {method} cannot "
                   "place the arcs at a variable its other parents determine (given them it "
                   "tells nothing more, which the search reads as independence) and often "
                   f"takes its children for parents: check them, and forbid those that point "
                   f"the wrong way (--forbid {extra[0]}->{names[v]})")
    return out


# discovery ---------------------------------------------------------------------------------

@dataclass
class Discovery:
    """What :func:`discover` found: the fitted program, its file's text, the parents of each
    variable, the record written under ``learned:``, and the data as the program reads them
    (each value the name of its state: a binned number its bin's)."""

    program: Program
    text: str
    parents: dict[str, list[str]]
    record: Any
    #: the data as coded for the search
    coded: Coded = field(repr=False)

    @property
    def data(self) -> pd.DataFrame:
        """The data as the program reads them (made when first read)."""
        return self.coded.frame

    def save(self, path: str | Path) -> Path:
        from bayesprog.support.files import atomic_write

        path = Path(path)
        atomic_write(path, self.text.encode("utf-8"), parents=False)
        return path


def discover(data: Any, *, method: str = "hc", score: str = "bic",
             equivalent_sample_size: float = 10.0, test: str = "chi2",
             significance: float = 0.01, max_conditioning: int = 5,
             forbid: Iterable[str | tuple[str, str]] = (),
             require: Iterable[str | tuple[str, str]] = (), tiers: Any = None,
             max_parents: int | None = None, start: Any = None, restarts: int | None = None,
             tabu: int = 100, seed: int = 0, discretise: int | None = None,
             columns: Mapping[str, str] | None = None, name: str | None = None,
             max_iter: int = 200, tol: float = 1e-8) -> Discovery:
    """Discover a program's decomposition from ``data`` and fit its tables.

    ``method`` is ``"hc"`` (hill climbing on ``score``: ``"bic"``, ``"bdeu"`` with
    ``equivalent_sample_size``, or ``"k2"``; with a tabu list of ``tabu`` operations and
    ``restarts`` random restarts (5 by default) seeded by ``seed``, from the empty graph or from ``start``, a
    program or its file, whose decomposition it begins with) or ``"pc"`` (the stable PC with
    the ``"chi2"`` or ``"g"`` test at ``significance``, conditioning sets of at most
    ``max_conditioning`` variables). Constraints: arcs to ``forbid`` and to ``require``
    (``"A->B"``), ``tiers`` (ordered groups: no arc into an earlier tier), ``max_parents``
    (hc). Missing values are used per family (available-case). The tables are then fitted as
    :meth:`Program.fit` fits them (EM when values are missing, ``max_iter``, ``tol``).
    """
    from bayesprog.program import loads

    if method not in METHODS:
        raise StructureError(f"method {method!r}: expected one of {', '.join(METHODS)}")
    if score not in SCORES:
        raise StructureError(f"score {score!r}: expected one of {', '.join(SCORES)}")
    if test not in TESTS:
        raise StructureError(f"test {test!r}: expected one of {', '.join(TESTS)}")
    if method == "pc" and (max_parents is not None or start is not None or restarts):
        option = ("max_parents" if max_parents is not None else "start" if start is not None
                  else "restarts")
        raise StructureError(f"{option} applies to hill climbing (method hc), not to pc")
    if max_parents is not None and (isinstance(max_parents, bool) or max_parents < 0):
        raise StructureError(f"max_parents: expected a number >= 0, found {max_parents!r}")
    restarts = RESTARTS if restarts is None else restarts
    if restarts < 0 or tabu < 0 or max_conditioning < 0:
        raise StructureError("restarts, tabu and max_conditioning: expected numbers >= 0")
    coded = code_data(data, discretise=discretise, columns=columns)
    names = coded.names
    rules = Constraints(len(names), _arcs(forbid, names, "--forbid"),
                        _arcs(require, names, "--require"),
                        read_tiers(tiers, names) if tiers is not None else None, max_parents)
    both = rules.forbidden & rules.required
    if both:
        u, v = sorted(both)[0]
        raise StructureError(f"the arc {names[u]}->{names[v]} is both forbidden (--forbid) and "
                             "required (--require)")
    required_parents: list[set[int]] = [set() for _ in names]
    for u, v in rules.required:
        required_parents[v].add(u)
    if topological(required_parents) is None:
        cycle = ", ".join(f"{names[u]}->{names[v]}" for u, v in sorted(rules.required))
        raise StructureError(f"the required arcs make a cycle ({cycle})")
    scores = Scores(coded.codes, coded.card, score, equivalent_sample_size)
    check_dag(required_parents, rules, scores, names)
    constraints: dict[str, Any] = {}
    if rules.forbidden:
        constraints["forbid"] = sorted(f"{names[u]}->{names[v]}" for u, v in rules.forbidden)
    if rules.required:
        constraints["require"] = sorted(f"{names[u]}->{names[v]}" for u, v in rules.required)
    if rules.tiers is not None:
        groups: dict[int, list[str]] = {}
        for n_, t in zip(names, rules.tiers, strict=True):
            groups.setdefault(t, []).append(n_)
        constraints["tiers"] = [groups[t] for t in sorted(groups)]
    if max_parents is not None:
        constraints["max_parents"] = int(max_parents)
    clock = time.perf_counter()
    structure: dict[str, Any]
    if method == "hc":
        start_parents = _start(start, names) if start is not None else None
        if start is not None:
            constraints["start"] = str(getattr(start, "path", None) or start)
        climb = hill_climb(scores, rules, start=start_parents, tabu_length=tabu,
                           restarts=restarts, seed=seed, names=names)
        parents = [list(ps) for ps in climb.parents]
        structure = dict(method="hc", score=score, score_value=climb.score,
                         equivalent_sample_size=(equivalent_sample_size if score == "bdeu"
                                                 else None),
                         iterations=climb.iterations, restarts=restarts, seed=seed,
                         families_scored=climb.families_scored)
    else:
        skeleton = pc_skeleton(coded.codes, coded.card, rules, test=test,
                               significance=significance, max_conditioning=max_conditioning)
        oriented = orient(skeleton, rules)
        parents = [list(ps) for ps in oriented.parents]
        structure = dict(method="pc", test=test, significance=significance,
                         max_conditioning=max_conditioning, tests=skeleton.tests,
                         oriented_by_choice=[f"{names[a]} -> {names[b]}"
                                             for a, b in oriented.chosen])
    structure["seconds"] = round(time.perf_counter() - clock, 3)
    missing = coded.missing_rows
    structure["missing"] = ("none" if missing == 0 else
                            f"available-case: each family scored (each test run) on the rows "
                            f"where all its variables are observed; {missing} of "
                            f"{len(coded.codes)} rows miss a value")
    structure["constraints"] = constraints
    structure["discretised"] = coded.bins
    structure["warnings"] = deterministic_warnings(coded, parents, method, scores)
    for message in structure["warnings"]:
        warnings.warn(message, StructureWarning, stacklevel=2)
    for v, ps in enumerate(parents):
        cells = scores.cells(v, ps)
        if cells > MAX_FAMILY_CELLS:
            raise StructureError(f"the family of {names[v]} would have {cells:,} cells")
    title = name or "discovered"
    # the tables' prior: the score's own (BDeu of that weight, or K2's one count per cell), and
    # for BIC and PC a BDeu prior of weight 1, so that a parent configuration the data never
    # show has a uniform row rather than none
    prior = (equivalent_sample_size if method == "hc" and score == "bdeu" else 1.0)
    text = _program_text(coded, parents, title, method, prior,
                         k2=method == "hc" and score == "k2")
    skeleton_program = loads(text, f"<{title}>")
    # the columns as coded (their states' names, -1 missing): not read or hashed again
    data = Columns(coded.source, coded.sha256, len(coded.codes), False, names,
                   lambda j: (coded.codes[:, j], coded.states[j]))
    fit = skeleton_program.fit(data, max_iter=max_iter, tol=tol)
    from bayesprog.model.records import StructureRecord

    record = fit.record.replace(data=coded.source, sha256=coded.sha256,
                                structure=StructureRecord(**structure))
    # the fit's record, the search's in it, written with the fitted values (what is written
    # is loaded, which checks it)
    fit.estimate.record = record
    written = fit.fitted_text(text)
    program = loads(written, f"<{title}>")
    return Discovery(program, written,
                     {names[v]: [names[p] for p in ps] for v, ps in enumerate(parents)}, record,
                     coded)


def _start(start: Any, names: Sequence[str]) -> list[set[int]]:
    """The parents of each column in a starting program (its terms over the data's columns)."""
    from bayesprog.program import Program, load

    program = start if isinstance(start, Program) else load(start)
    index = {n: i for i, n in enumerate(names)}
    parents: list[set[int]] = [set() for _ in names]
    for term in program.terms:
        child = term.child.name
        if child not in index:
            raise StructureError(f"--start: the starting program's variable {child} has no "
                                 "column in the data: the structure is discovered over "
                                 "observed variables only (a hidden variable is out of scope; "
                                 f"the data's columns: {', '.join(names)})")
        for p in term.parents:
            if p.name not in index:
                raise StructureError(f"--start: {term.label} names {p.name}, which has no "
                                     "column in the data (a hidden variable is out of scope)")
            parents[index[child]].add(index[p.name])
    return parents


#: names that YAML 1.1 reads as booleans or null: quoted where they are keys
_AMBIGUOUS = {"y", "n", "yes", "no", "on", "off", "true", "false", "null", "~"}


def _key(name: str) -> str:
    return json.dumps(name) if name.lower() in _AMBIGUOUS else name


def _program_text(coded: Coded, parents: Sequence[Sequence[int]], title: str,
                  method: str, prior: float, k2: bool = False) -> str:
    names = coded.names
    lines = ["bayesprog: 1", f"name: {json.dumps(title)}",
             f"description: {json.dumps(f'Discovered from {coded.source} by {method}')}",
             "variables:"]
    for column, states in zip(names, coded.states, strict=True):
        listed = ", ".join(json.dumps(s) for s in states)
        lines.append(f"  {_key(column)}: {{states: [{listed}]}}")
    lines.append("decomposition:")
    order = topological([set(ps) for ps in parents])
    assert order is not None
    for v in order:
        ps = sorted(parents[v])
        term = f"P({names[v]} | {', '.join(names[p] for p in ps)})" if ps else f"P({names[v]})"
        r = len(coded.states[v])
        table = "[" + ", ".join([f"{1 / r:.6g}"] * (r - 1)
                                + [f"{1 - (r - 1) * float(f'{1 / r:.6g}'):.6g}"]) + "]"
        # the whole table, a row per configuration of the parents (the first parent's states
        # outermost), so that the fitted values are written over these numbers in place
        for p in reversed(ps):
            table = "[" + ", ".join([table] * len(coded.states[p])) + "]"
        q = int(np.prod([len(coded.states[p]) for p in ps], dtype=float))
        counts = 1.0 if k2 else prior / (q * r)
        lines.append(f"  - {{term: {json.dumps(term)}, form: table, table: {table}, "
                     f"learn: {{pseudo_counts: {counts:.6g}}}}}")
    return "\n".join(lines) + "\n"
