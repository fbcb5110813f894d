"""Structure learning on coded discrete data: the decomposition itself found from data.

The data are a matrix of state indices (rows x variables, ``-1`` where a value is missing) and
each variable's number of states. Two families of methods:

* **score-based**: :func:`hill_climb` adds, deletes and reverses arcs while the score grows,
  with a tabu list and seeded random restarts. The score of a DAG is a sum of family scores
  (:class:`Scores`: BIC, BDeu or K2), each computed once from the family's counts (one
  ``bincount`` over the rows) and kept, so that an operation costs only the families it
  touches.
* **constraint-based**: :func:`pc` removes the edges between variables found independent
  (chi-square or G-test, stratified by the conditioning set) at growing sizes of conditioning
  sets, with the adjacencies of each level fixed at its start (the stable PC, whose result
  does not depend on the order of the variables); :func:`orient` then orients it by its
  v-structures and Meek's rules, and the edges left undirected in a fixed order.

Missing values are used per family (available-case): a family's counts come from the rows where
all its variables are observed, and a test's from the rows where its variables are.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from bayesprog.errors import BayesprogError

#: the largest family table (child states x parent configurations) a score is computed for
MAX_FAMILY_CELLS = 1 << 22

SCORES = ("bic", "bdeu", "k2")
#: the K2 closed form itself (the log marginal likelihood under one count per cell), which
#: :mod:`bayesprog.learning.evidence` uses; ``"k2"`` is the score as pgmpy computes it
K2_EXACT = "k2-exact"
TESTS = ("chi2", "g")


class StructureError(BayesprogError):
    """Structure learning was asked for something it cannot do (contradictory constraints,
    a family too large, an unknown score)."""


# scores ----------------------------------------------------------------------------------------

class Scores:
    """Family scores of coded data, computed once each: ``local(child, parents)``."""

    def __init__(self, codes: np.ndarray, card: Sequence[int], score: str = "bic",
                 ess: float = 10.0) -> None:
        if score not in SCORES and score != K2_EXACT:
            raise StructureError(f"score {score!r}: expected one of {', '.join(SCORES)}")
        if not ess > 0:
            raise StructureError(f"equivalent sample size {ess}: expected a number > 0")
        self.codes = np.ascontiguousarray(codes, dtype=np.int64)
        if self.codes.ndim != 2:
            raise StructureError("expected a matrix of state indices: rows x variables")
        self.card = np.asarray(card, dtype=np.int64)
        self.score = score
        self.ess = float(ess)
        self.observed = self.codes >= 0
        self.complete = bool(self.observed.all())
        self.full: np.ndarray = np.asarray(self.observed.all(axis=0))  # columns with no gap
        self.columns = [self.codes[:, i] for i in range(self.codes.shape[1])]
        self.cache: dict[tuple[int, tuple[int, ...]], float] = {}
        self.computed = 0
        self._last: tuple[tuple[int, tuple[int, ...]], np.ndarray, np.ndarray | None] | None = None

    def cells(self, child: int, parents: Iterable[int]) -> int:
        return int(self.card[child]) * math.prod(int(self.card[p]) for p in parents)

    def _index(self, child: int, parents: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray | None]:
        """Each available row's cell in the family's table (child state + r x parent
        configuration, the parents in the order given), and the available rows' mask (None:
        all rows); the last one is kept, for the families that add one parent to it."""
        key = (child, parents)
        if self._last is not None and self._last[0] == key:
            return self._last[1], self._last[2]
        rows: np.ndarray | None = None
        if not self.complete:
            rows = np.asarray(self.observed[:, (child, *parents)].all(axis=1))
        index = self.columns[child] if rows is None else self.columns[child][rows]
        stride = int(self.card[child])
        for p in parents:
            column = self.columns[p] if rows is None else self.columns[p][rows]
            index = index + stride * column
            stride *= int(self.card[p])
        self._last = (key, index, rows)
        return index, rows

    def counts(self, child: int, parents: tuple[int, ...]) -> np.ndarray:
        """Counts of the family over its available rows: (parent configurations, child states)."""
        index, _ = self._index(child, parents)
        q = math.prod(int(self.card[p]) for p in parents)
        r = int(self.card[child])
        return np.bincount(index, minlength=q * r).reshape(q, r)

    def local(self, child: int, parents: tuple[int, ...]) -> float:
        """The score of ``child`` given ``parents`` (sorted), from the cache when known."""
        key = (child, parents)
        found = self.cache.get(key)
        if found is not None:
            return found
        value = self._score(self.counts(child, parents))
        self.cache[key] = value
        return value

    def local_with(self, child: int, parents: tuple[int, ...], extra: int) -> float:
        """The score of ``child`` given ``parents`` (sorted) and ``extra``: counted from the
        rows' cells of the family without ``extra`` (one pass instead of one per parent)."""
        key = (child, tuple(sorted((*parents, extra))))
        found = self.cache.get(key)
        if found is not None:
            return found
        index, rows = self._index(child, parents)
        column = self.columns[extra]
        if rows is not None or not self.full[extra]:
            # the rows available to the wider family: those of the narrower one that also
            # have a value of ``extra``
            value = self._score(self.counts(key[0], key[1]))
            self.cache[key] = value
            return value
        r = int(self.card[child])
        q = math.prod(int(self.card[p]) for p in parents)
        wide = index + (r * q) * column
        counts = np.bincount(wide, minlength=r * q * int(self.card[extra]))
        # the layout (extra slowest) differs from the sorted order's; a score does not depend
        # on the order of the parent configurations
        value = self._score(counts.reshape(-1, r))
        self.cache[key] = value
        return value

    def _score(self, counts: np.ndarray) -> float:
        import scipy.special

        self.computed += 1
        counts = counts.astype(float)
        q, r = counts.shape
        totals = counts.sum(axis=1)
        if self.score == "bic":
            n = totals.sum()
            safe = np.where(counts > 0, counts, 1.0)
            denominators = np.where(totals > 0, totals, 1.0)[:, None]
            ll = float(np.sum(counts * np.log(safe / denominators)))
            return ll - 0.5 * np.log(n) * q * (r - 1) if n > 0 else 0.0
        gammaln = scipy.special.gammaln
        if self.score in ("k2", K2_EXACT):
            # the closed form: a parent configuration without rows adds lgamma(r) -
            # lgamma(0 + r) = 0
            value = (np.sum(gammaln(counts + 1)) - np.sum(gammaln(totals + r))
                     + q * gammaln(r))
            if self.score == "k2":  # as pgmpy: lgamma(r) more per configuration without rows
                value += (q - np.count_nonzero(totals)) * gammaln(r)
            return float(value)
        alpha = self.ess / q  # bdeu
        beta = self.ess / (q * r)
        return float(np.sum(gammaln(counts + beta)) - np.sum(gammaln(totals + alpha))
                     + q * gammaln(alpha) - q * r * gammaln(beta))

    def total(self, parents: Sequence[Iterable[int]]) -> float:
        return sum(self.local(v, tuple(sorted(ps))) for v, ps in enumerate(parents))


# constraints -------------------------------------------------------------------------------

@dataclass
class Constraints:
    """What the domain says of the arcs: ``forbidden`` and ``required`` (u, v) pairs, ``tiers``
    (the tier of each variable: no arc from a later tier to an earlier one), ``max_parents``."""

    n: int
    forbidden: set[tuple[int, int]] = field(default_factory=set)
    required: set[tuple[int, int]] = field(default_factory=set)
    tiers: list[int] | None = None
    max_parents: int | None = None

    def allowed(self, u: int, v: int) -> bool:
        """May the arc u -> v exist?"""
        if (u, v) in self.forbidden:
            return False
        return self.tiers is None or self.tiers[u] <= self.tiers[v]


# hill climbing -----------------------------------------------------------------------------

@dataclass
class Climb:
    """What hill climbing found: each variable's parents, the score, how it went."""

    parents: list[tuple[int, ...]]
    score: float
    iterations: int
    restarts: int
    families_scored: int


def _reach(parents: Sequence[set[int]]) -> np.ndarray:
    """reach[a, b]: is there a directed path from a to b (of length >= 1)?"""
    n = len(parents)
    adjacency = np.zeros((n, n), dtype=bool)
    for v, ps in enumerate(parents):
        for u in ps:
            adjacency[u, v] = True
    return _closure(adjacency)


def _climb(scores: Scores, parents: list[set[int]], rules: Constraints, tabu_length: int,
           max_iter: int, epsilon: float, patience: int,
           ties: np.ndarray | None = None) -> tuple[list[set[int]], int]:
    """Climb from ``parents``; past a local optimum, go on for up to ``patience`` steps with
    the best move that is not tabu (even one that lowers the score), and return the best graph
    met (a tabu search: the tabu list keeps it from climbing straight back).

    Every move's change of score is read from two matrices kept up to date: ``gain[u, v]``,
    the change of v's family score when u is added to its parents (or removed, when u is one),
    recomputed for a variable only when its parents change; the legal moves are masks over
    them (no cycle, the constraints, the tabu list). ``ties`` (n x n, tiny) breaks the ties of
    equal moves (the two directions of an arc are equal under a score-equivalent score) in
    another order than the variables'."""
    n = len(parents)
    ties = np.zeros((n, n)) if ties is None else ties
    limit = rules.max_parents if rules.max_parents is not None else n
    allowed = np.array([[u != v and rules.allowed(u, v) for v in range(n)] for u in range(n)])
    required = np.zeros((n, n), dtype=bool)
    for u, v in rules.required:
        required[u, v] = True
    too_big = np.zeros((n, n), dtype=bool)  # adding u to v's parents makes too large a family
    gain = np.zeros((n, n))

    def refresh(v: int) -> None:
        own = tuple(sorted(parents[v]))
        now = scores.local(v, own)
        for u in range(n):
            if u == v:
                continue
            if u in parents[v]:
                gain[u, v] = scores.local(v, tuple(p for p in own if p != u)) - now
                too_big[u, v] = False
            else:
                too_big[u, v] = scores.cells(v, own) * int(scores.card[u]) > MAX_FAMILY_CELLS
                gain[u, v] = (-np.inf if too_big[u, v] or not allowed[u, v]
                              else scores.local_with(v, own, u) - now)

    for v in range(n):
        refresh(v)
    tabu: list[tuple[str, int, int]] = []
    iterations = 0
    current = scores.total(parents)
    best_parents, best_score = [set(ps) for ps in parents], current
    stalled = 0
    while iterations < max_iter:
        adjacency = np.zeros((n, n), dtype=bool)
        for v in range(n):
            for u in parents[v]:
                adjacency[u, v] = True
        reach = _closure(adjacency)
        counts = adjacency.sum(axis=0)
        room = counts < limit  # v may take one more parent
        # additions: no arc either way, no path v ~> u, allowed, room, not too big
        add = (~adjacency & ~adjacency.T & ~reach.T & allowed & room[None, :] & ~too_big)
        np.fill_diagonal(add, False)
        # deletions: an arc that is not required
        delete = adjacency & ~required
        # reversals of u -> v: not required, v -> u allowed, room at u, no other path u ~> v
        other = (adjacency.astype(np.int32) @ reach.astype(np.int32)) > 0
        flip = (adjacency & ~required & allowed.T & room[:, None] & ~other
                & ~too_big.T)
        for op, u, v in tabu:
            (add if op == "+" else delete if op == "-" else flip)[u, v] = False
        moves = (np.where(add, gain, -np.inf), np.where(delete, gain, -np.inf),
                 np.where(flip, gain + gain.T, -np.inf))
        best_kind = max(range(3), key=lambda k: (moves[k] + ties).max())
        u, v = (int(i) for i in np.unravel_index(np.argmax(moves[best_kind] + ties), (n, n)))
        delta = float(moves[best_kind][u, v])
        if not np.isfinite(delta) or (delta < epsilon and stalled >= patience):
            break
        if best_kind == 0:
            parents[v].add(u)
            tabu.append(("-", u, v))
            refresh(v)
        elif best_kind == 1:
            parents[v].discard(u)
            tabu.append(("+", u, v))
            refresh(v)
        else:
            parents[v].discard(u)
            parents[u].add(v)
            tabu.append(("flip", v, u))
            refresh(v)
            refresh(u)
        if tabu_length > 0:
            del tabu[:-tabu_length]
        else:
            tabu.clear()
        iterations += 1
        current += delta
        if current > best_score + epsilon:
            best_parents, best_score, stalled = [set(ps) for ps in parents], current, 0
        else:
            stalled += 1
    return best_parents, iterations


def _closure(adjacency: np.ndarray) -> np.ndarray:
    """reach[a, b]: a directed path from a to b (of length >= 1)."""
    reach = adjacency.copy()
    while True:
        wider = reach | ((reach.astype(np.int32) @ reach.astype(np.int32)) > 0)
        if (wider == reach).all():
            return reach
        reach = wider


def _perturbed(parents: list[set[int]], rules: Constraints, scores: Scores, steps: int,
               rng: np.random.Generator) -> list[set[int]]:
    """``parents`` after ``steps`` random legal operations (a restart's starting point)."""
    out = [set(ps) for ps in parents]
    n = len(out)
    limit = rules.max_parents if rules.max_parents is not None else n
    for _ in range(steps):
        reach = _reach(out)
        moves = []
        for u in range(n):
            for v in range(n):
                if u == v:
                    continue
                if u in out[v]:
                    if (u, v) not in rules.required:
                        moves.append(("-", u, v))
                        if (rules.allowed(v, u) and len(out[u]) < limit
                                and not any(reach[w, v] for w in range(n)
                                            if u in out[w] and w != v)):
                            moves.append(("flip", u, v))
                elif (v not in out[u] and rules.allowed(u, v) and len(out[v]) < limit
                      and not reach[v, u] and scores.cells(v, out[v] | {u}) <= MAX_FAMILY_CELLS):
                    moves.append(("+", u, v))
        if not moves:
            break
        op, u, v = moves[int(rng.integers(len(moves)))]
        if op == "+":
            out[v].add(u)
        elif op == "-":
            out[v].discard(u)
        else:
            out[v].discard(u)
            out[u].add(v)
    return out


def hill_climb(scores: Scores, rules: Constraints, *, start: Sequence[Iterable[int]] | None = None,
               tabu_length: int = 100, restarts: int = 5, seed: int = 0,
               max_iter: int = 1_000_000, epsilon: float = 1e-4, patience: int = 10,
               names: Sequence[str] | None = None) -> Climb:
    """Greedy search over DAGs from ``start`` (by default the empty graph with the required
    arcs): at each step the best of every legal addition, deletion and reversal of an arc that
    is not tabu (the last ``tabu_length`` operations may not be undone), until none improves
    the score by ``epsilon``; then up to ``patience`` steps more with the best move that is not
    tabu, even one that lowers the score, to leave a local optimum (the best graph met is
    kept; ``patience=0`` stops at the first optimum, as pgmpy's HillClimbSearch does). Then
    ``restarts`` times: from the best DAG perturbed by random
    operations (seeded by ``seed``), climb again; the best DAG found is returned."""
    n = rules.n
    parents = [set(ps) for ps in start] if start is not None else [set() for _ in range(n)]
    for u, v in rules.required:
        parents[v].add(u)
    check_dag(parents, rules, scores, names)
    parents, iterations = _climb(scores, parents, rules, tabu_length, max_iter, epsilon,
                                 patience)
    best = [set(ps) for ps in parents]
    best_score = scores.total(best)
    rng = np.random.default_rng([seed, 1])
    steps = max(1, n // 2)
    for restart in range(restarts):
        # every other restart from the best graph perturbed, the others from the start again
        # with the ties of equal moves broken in another order
        ties = rng.random((n, n)) * 1e-7
        if restart % 2 == 0:
            moved = _perturbed(best, rules, scores, steps, rng)
        else:
            moved = [set(ps) for ps in start] if start is not None else [set() for _ in range(n)]
            for u, v in rules.required:
                moved[v].add(u)
        found, more = _climb(scores, moved, rules, tabu_length, max_iter, epsilon, patience,
                             ties)
        iterations += more
        value = scores.total(found)
        if value > best_score + epsilon:
            best, best_score = [set(ps) for ps in found], value
    return Climb([tuple(sorted(ps)) for ps in best], best_score, iterations, restarts,
                 scores.computed)


def check_dag(parents: Sequence[set[int]], rules: Constraints, scores: Scores | None = None,
              names: Sequence[str] | None = None) -> None:
    """A starting graph must be a DAG within the constraints."""
    def name(i: int) -> str:
        return names[i] if names is not None else str(i)

    order = topological(parents)
    if order is None:
        raise StructureError("the starting arcs (required, or of the starting program) make "
                             "a cycle")
    for v, ps in enumerate(parents):
        for u in ps:
            if not rules.allowed(u, v):
                raise StructureError(f"the arc {name(u)} -> {name(v)} is required (or in the "
                                     "starting program) and forbidden (by --forbid or the tiers)")
        if rules.max_parents is not None and len(ps) > rules.max_parents:
            raise StructureError(f"{name(v)} has {len(ps)} parents in the starting graph, more "
                                 f"than --max-parents {rules.max_parents}")
        if scores is not None and scores.cells(v, ps) > MAX_FAMILY_CELLS:
            raise StructureError(f"the family of {name(v)} ({len(ps)} parents) has "
                                 f"{scores.cells(v, ps):,.0f} cells, more than the "
                                 f"{MAX_FAMILY_CELLS:,} a family may have")


def topological(parents: Sequence[Iterable[int]]) -> list[int] | None:
    """The variables parents first (ties by index), or None when the arcs make a cycle."""
    import heapq

    n = len(parents)
    children: list[list[int]] = [[] for _ in range(n)]
    waiting = [0] * n
    for v, ps in enumerate(parents):
        for u in ps:
            children[u].append(v)
            waiting[v] += 1
    ready = [v for v in range(n) if waiting[v] == 0]
    heapq.heapify(ready)
    order = []
    while ready:
        u = heapq.heappop(ready)
        order.append(u)
        for v in children[u]:
            waiting[v] -= 1
            if waiting[v] == 0:
                heapq.heappush(ready, v)
    return order if len(order) == n else None


# conditional independence tests ------------------------------------------------------------

def ci_test(codes: np.ndarray, card: Sequence[int], x: int, y: int, given: Sequence[int],
            test: str = "chi2") -> tuple[float, int, float]:
    """(statistic, degrees of freedom, p-value) of ``x`` independent of ``y`` given ``given``:
    Pearson's chi-square (``chi2``) or the G-test (``g``) summed over the observed strata of
    ``given``, each stratum's table over the values of x and y present in it (with Yates'
    continuity correction where that table has one degree of freedom), as
    ``scipy.stats.chi2_contingency`` computes it per stratum. When no stratum leaves a degree
    of freedom (x or y constant in each, as when one is a function of the others), the p-value
    is NaN: the test cannot show independence, and PC keeps the edge."""
    import scipy.special
    import scipy.stats

    columns = (x, y, *given)
    block = codes[:, columns]
    if (block < 0).any():
        block = block[(block >= 0).all(axis=1)]
    rx, ry = int(card[x]), int(card[y])
    if given:
        strata = np.zeros(len(block), dtype=np.int64)
        for j, g in enumerate(given):
            strata = strata * int(card[g]) + block[:, 2 + j]
        _, strata = np.unique(strata, return_inverse=True)
        nz = int(strata.max()) + 1 if len(strata) else 0
    else:
        strata = np.zeros(len(block), dtype=np.int64)
        nz = 1 if len(block) else 0
    if nz == 0:
        return 0.0, 0, 1.0
    observed = np.bincount((strata * rx + block[:, 0]) * ry + block[:, 1],
                           minlength=nz * rx * ry).reshape(nz, rx, ry).astype(float)
    rows = observed.sum(axis=2)
    cols = observed.sum(axis=1)
    total = rows.sum(axis=1)
    expected = rows[:, :, None] * cols[:, None, :] / total[:, None, None]
    dof = (np.count_nonzero(rows, axis=1) - 1) * (np.count_nonzero(cols, axis=1) - 1)
    dof = np.maximum(dof, 0)
    yates = dof == 1
    if yates.any():
        diff = expected[yates] - observed[yates]
        observed[yates] += np.sign(diff) * np.minimum(0.5, np.abs(diff))
    cells = expected > 0
    cells &= (dof > 0)[:, None, None]
    if test == "chi2":
        statistic = float(np.sum((observed[cells] - expected[cells]) ** 2 / expected[cells]))
    elif test == "g":
        o, e = observed[cells], expected[cells]
        statistic = float(2.0 * np.sum(scipy.special.xlogy(o, o / e)))
    else:
        raise StructureError(f"test {test!r}: expected one of {', '.join(TESTS)}")
    freedom = int(dof.sum())
    if freedom > 0:
        p = float(scipy.stats.chi2.sf(statistic, freedom))
    else:  # x or y constant in every stratum (a deterministic variable): no test is possible,
        # and independence is not shown (without a conditioning set: one of them is constant)
        p = 1.0 if not given else float("nan")
    return statistic, freedom, p


@dataclass
class Skeleton:
    """The undirected graph PC keeps, the separating set of each removed pair, the tests run."""

    adjacent: list[set[int]]
    sepsets: dict[frozenset[int], tuple[int, ...]]
    tests: int


def pc_skeleton(codes: np.ndarray, card: Sequence[int], rules: Constraints, *,
                test: str = "chi2", significance: float = 0.01,
                max_conditioning: int = 5) -> Skeleton:
    """The stable PC's skeleton: from the complete graph (less the pairs with both arcs
    forbidden), for conditioning sets of 0, 1, 2, ... variables taken among the neighbours each
    variable had at the start of that size, an edge is removed when a test finds its ends
    independent (p >= ``significance``). Required arcs stay."""
    if test not in TESTS:
        raise StructureError(f"test {test!r}: expected one of {', '.join(TESTS)}")
    if not 0 < significance < 1:
        raise StructureError(f"significance {significance}: expected a number in (0, 1)")
    n = rules.n
    adjacent = [{v for v in range(n) if v != u and (rules.allowed(u, v) or rules.allowed(v, u))}
                for u in range(n)]
    kept = {frozenset(e) for e in rules.required}
    sepsets: dict[frozenset[int], tuple[int, ...]] = {}
    tests = 0
    size = 0
    while size <= max_conditioning and any(len(a) - 1 >= size for a in adjacent):
        frozen = [set(a) for a in adjacent]
        for u in range(n):
            for v in sorted(frozen[u]):
                if v < u or v not in adjacent[u] or frozenset((u, v)) in kept:
                    continue
                found = None
                for side in (frozen[u] - {v}, frozen[v] - {u}):
                    for given in itertools.combinations(sorted(side), size):
                        tests += 1
                        if ci_test(codes, card, u, v, given, test)[2] >= significance:  # NaN: no
                            found = given
                            break
                    if found is not None:
                        break
                if found is not None:
                    adjacent[u].discard(v)
                    adjacent[v].discard(u)
                    sepsets[frozenset((u, v))] = found
        size += 1
    return Skeleton(adjacent, sepsets, tests)


# orientation -------------------------------------------------------------------------------

@dataclass
class Orientation:
    """A DAG from a skeleton: each variable's parents, and the arcs whose direction the data
    did not decide (chosen so that no v-structure or cycle is made)."""

    parents: list[tuple[int, ...]]
    chosen: list[tuple[int, int]]


def orient(skeleton: Skeleton, rules: Constraints) -> Orientation:
    """Orient the skeleton: required arcs, arcs whose other direction is forbidden or against
    the tiers, then the v-structures (x -> z <- y where x, y are not adjacent and z is not in
    their separating set), then Meek's rules R1-R3 until nothing changes; the edges still
    undirected are oriented as a consistent extension (Dor and Tarsi) when there is one, else
    by the order of the variables, and listed in ``chosen``."""
    n = rules.n
    adjacent = [set(a) for a in skeleton.adjacent]
    directed: set[tuple[int, int]] = set()

    def undirected(a: int, b: int) -> bool:
        return b in adjacent[a] and (a, b) not in directed and (b, a) not in directed

    def direct(a: int, b: int) -> bool:
        if undirected(a, b):
            directed.add((a, b))
            return True
        return False

    for u, v in sorted(rules.required):
        direct(u, v)
    for u in range(n):
        for v in sorted(adjacent[u]):
            if not rules.allowed(u, v) and rules.allowed(v, u):
                direct(v, u)
    for z in range(n):
        for x, y in itertools.combinations(sorted(adjacent[z]), 2):
            if y in adjacent[x]:
                continue
            if z not in skeleton.sepsets.get(frozenset((x, y)), ()):
                if (z, x) not in directed and (z, y) not in directed:
                    direct(x, z)
                    direct(y, z)
    changed = True
    while changed:
        changed = False
        for a, b in sorted(directed):
            for c in sorted(adjacent[b]):  # R1: a -> b - c, a and c not adjacent
                if c != a and c not in adjacent[a] and undirected(b, c):
                    changed |= direct(b, c)
        for a in range(n):
            for c in sorted(adjacent[a]):
                if not undirected(a, c):
                    continue
                # R2: a -> b -> c and a - c
                if any((a, b) in directed and (b, c) in directed for b in adjacent[a]):
                    changed |= direct(a, c)
                    continue
                # R3: a - b1 -> c, a - b2 -> c, b1 and b2 not adjacent, a - c
                into = [b for b in adjacent[a] if undirected(a, b) and (b, c) in directed]
                if any(b2 not in adjacent[b1] for b1, b2 in itertools.combinations(into, 2)):
                    changed |= direct(a, c)
    rest = sorted((a, b) for a in range(n) for b in adjacent[a] if a < b and undirected(a, b))
    chosen = _extension(n, adjacent, directed, rest)
    parents: list[set[int]] = [set() for _ in range(n)]
    for a, b in directed | set(chosen):
        parents[b].add(a)
    if topological(parents) is None:
        raise StructureError("the tests' orientations make a cycle (conflicting v-structures, "
                             "or constraints against the data): try another --significance or "
                             "hc")
    return Orientation([tuple(sorted(p)) for p in parents], chosen)


def _extension(n: int, adjacent: list[set[int]], directed: set[tuple[int, int]],
               rest: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """Directions for the undirected edges ``rest`` that make no new v-structure and no cycle
    (Dor and Tarsi's extension of a partially directed graph); when the graph has none, each
    edge from its lower-numbered end, in order, keeping the graph acyclic."""
    if not rest:
        return []
    undirected = {frozenset(e) for e in rest}
    arcs = set(directed)
    alive = set(range(n))
    chosen: list[tuple[int, int]] = []
    while alive:
        for x in sorted(alive):
            out = [y for y in alive if (x, y) in arcs]
            if out:
                continue  # x must be a sink among the remaining
            neighbours = [y for y in alive if frozenset((x, y)) in undirected]
            parents_x = [y for y in alive if (y, x) in arcs]
            adjacent_x = set(neighbours) | set(parents_x)
            if all(adjacent_x - {y} <= (adjacent[y] | {y}) for y in neighbours):
                for y in sorted(neighbours):
                    chosen.append((y, x))
                    undirected.discard(frozenset((x, y)))
                alive.discard(x)
                break
        else:
            break
    if not undirected:
        return chosen
    # not extendable: orient what is left from the lower index, avoiding cycles
    parents: list[set[int]] = [set() for _ in range(n)]
    for a, b in arcs | set(chosen):
        parents[b].add(a)
    for edge in sorted(tuple(sorted(e)) for e in undirected):
        a, b = edge
        parents[b].add(a)
        if topological(parents) is None:
            parents[b].discard(a)
            parents[a].add(b)
            chosen.append((b, a))
        else:
            chosen.append((a, b))
    return chosen
