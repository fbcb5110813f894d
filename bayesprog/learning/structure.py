"""Structure learning on coded discrete data: the decomposition itself found from data.

The data are a matrix of state indices (rows x variables, ``-1`` where a value is missing) and
each variable's number of states. Two families of methods:

* **score-based**: :func:`hill_climb` adds, deletes and reverses arcs while the score grows,
  with a tabu list and seeded random restarts. The score of a DAG is a sum of family scores
  (:class:`Scores`: BIC, BDeu or K2), each counted once in one pass over the data's distinct
  rows and kept, so that an operation costs only the families it touches and a restart reads
  the families it meets again. The counts, the scores, their cache and the climb are compiled
  loops (:mod:`bayesprog.learning._score_kernels`).
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
    """Family scores of coded data, computed once each: ``local(child, parents)``.

    With ``N_jk`` the rows where the child takes its state k and the parents their
    configuration j (of q; r states of the child), ``N_j = sum_k N_jk`` and N the rows where
    the family is observed:

    * BIC: ``sum_jk N_jk log(N_jk / N_j) - log(N) / 2 * q (r - 1)``;
    * BDeu (equivalent sample size a): ``sum_j [lgamma(a/q) - lgamma(N_j + a/q)
      + sum_k (lgamma(N_jk + a/qr) - lgamma(a/qr))]``;
    * K2: ``sum_j [lgamma(r) - lgamma(N_j + r) + sum_k lgamma(N_jk + 1)]``, plus ``lgamma(r)``
      per configuration without rows as pgmpy computes it (``"k2"``; ``"k2-exact"`` without).

    >>> import numpy as np
    >>> codes = np.array([[0, 0], [0, 0], [1, 1], [1, 0]])
    >>> scores = Scores(codes, [2, 2])
    >>> round(scores.local(1, (0,)), 4)  # 2 log 1 + log(1/2) + log(1/2) - log(4) / 2 * 2
    -2.7726
    """

    def __init__(self, codes: np.ndarray, card: Sequence[int], score: str = "bic",
                 ess: float = 10.0) -> None:
        from bayesprog.learning import _score_kernels as kernels

        if score not in SCORES and score != K2_EXACT:
            raise StructureError(f"score {score!r}: expected one of {', '.join(SCORES)}")
        if not ess > 0:
            raise StructureError(f"equivalent sample size {ess}: expected a number > 0")
        self.codes = np.asarray(codes, dtype=np.int64)
        if self.codes.ndim != 2:
            raise StructureError("expected a matrix of state indices: rows x variables")
        self.card = np.asarray(card, dtype=np.int64)
        if self.card.shape != (self.codes.shape[1],):
            raise StructureError(f"expected a number of states for each of the "
                                 f"{self.codes.shape[1]} variables, found {self.card.size}")
        if self.codes.size and (self.codes >= self.card).any():
            v = int(np.nonzero((self.codes >= self.card).any(axis=0))[0][0])
            raise StructureError(f"variable {v} has a state index above its "
                                 f"{int(self.card[v])} states")
        self.score = score
        self.ess = float(ess)
        self._kind = kernels.KINDS[score]
        self._data = kernels.prepare(self.codes, self.card)
        self._table = kernels.empty_table(self.codes.shape[1])

    @property
    def computed(self) -> int:
        """Family scores computed (each once: the others were read from the cache)."""
        return int(self._table[3][1])

    @property
    def cache(self) -> dict[tuple[int, tuple[int, ...]], float]:
        """The family scores computed: (child, sorted parents) -> score."""
        keys, values, filled, _ = self._table
        out = {}
        for slot in np.nonzero(filled)[0]:
            bits = np.unpackbits(keys[slot, 1:].view(np.uint8), bitorder="little")
            out[(int(keys[slot, 0]), tuple(int(p) for p in np.nonzero(bits)[0]))] = float(
                values[slot])
        return out

    def cells(self, child: int, parents: Iterable[int]) -> int:
        return int(self.card[child]) * math.prod(int(self.card[p]) for p in parents)

    def counts(self, child: int, parents: tuple[int, ...]) -> np.ndarray:
        """Counts of the family over its available rows: (parent configurations, child states),
        the parents' configurations in mixed radix, the last parent fastest."""
        columns = self.codes[:, (child, *parents)]
        columns = columns[(columns >= 0).all(axis=1)]
        q = math.prod(int(self.card[p]) for p in parents)
        r = int(self.card[child])
        index = np.zeros(len(columns), dtype=np.int64)
        for j, p in enumerate(parents):
            index = index * int(self.card[p]) + columns[:, 1 + j]
        return np.bincount(index * r + columns[:, 0], minlength=q * r).reshape(q, r)

    def observed_counts(self, child: int, parents: Iterable[int]) -> np.ndarray:
        """Counts of the family over its available rows: (parent configurations, child
        states), the configurations in no particular order, and only those met when there are
        more configurations than rows."""
        from bayesprog.learning import _score_kernels as kernels

        rows, weights, card = self._data[:3]
        counts, configurations = kernels.family_counts(
            rows, weights, card, int(child), np.array(list(parents), dtype=np.int64))
        return counts.reshape(configurations, int(self.card[child]))

    def local(self, child: int, parents: tuple[int, ...]) -> float:
        """The score of ``child`` given ``parents``, from the cache when known."""
        from bayesprog.learning import _score_kernels as kernels

        value, self._table = kernels.family_score(
            self._data, self._kind, self.ess, int(child),
            np.array(sorted(parents), dtype=np.int64), self._table)
        return float(value)

    def total(self, parents: Sequence[Iterable[int]]) -> float:
        return sum(self.local(v, tuple(sorted(ps))) for v, ps in enumerate(parents))

    def gains(self, parents: Sequence[Iterable[int]],
              rules: Constraints | None = None) -> np.ndarray:
        """``gain[u, v]``: the change of the DAG's score when the arc u -> v is added (or
        deleted, when it is there); -inf where the constraints forbid it or the family would
        have more than ``MAX_FAMILY_CELLS`` cells. The climb reads its moves from these."""
        from bayesprog.learning import _score_kernels as kernels

        n = len(parents)
        allowed = (rules or Constraints(n)).matrices()[0]
        gain, _, self._table = kernels.gains(self._data, self._kind, self.ess,
                                             _adjacency(parents), allowed, MAX_FAMILY_CELLS,
                                             self._table)
        return gain

    def climb(self, adjacency: np.ndarray, rules: Constraints, tabu_length: int, max_iter: int,
              epsilon: float, patience: int, ties: np.ndarray) -> tuple[np.ndarray, float, int]:
        """One tabu climb from ``adjacency`` (adjacency[u, v]: the arc u -> v): the best DAG
        met, its score and the moves made (see :func:`hill_climb`)."""
        from bayesprog.learning import _score_kernels as kernels

        allowed, required, limit = rules.matrices()
        best, score, iterations, self._table = kernels.climb(
            self._data, self._kind, self.ess, adjacency, allowed, required, limit, tabu_length,
            max_iter, epsilon, patience, ties, MAX_FAMILY_CELLS, self._table)
        return best, float(score), int(iterations)


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

    def matrices(self) -> tuple[np.ndarray, np.ndarray, int]:
        """allowed[u, v] (may the arc u -> v exist), required[u, v], and the most parents a
        variable may have."""
        n = self.n
        allowed = ~np.eye(n, dtype=bool)
        if self.tiers is not None:
            tier = np.asarray(self.tiers)
            allowed &= tier[:, None] <= tier[None, :]
        for u, v in self.forbidden:
            allowed[u, v] = False
        required = np.zeros((n, n), dtype=bool)
        for u, v in self.required:
            required[u, v] = True
        return allowed, required, self.max_parents if self.max_parents is not None else n


# hill climbing -----------------------------------------------------------------------------

@dataclass
class Climb:
    """What hill climbing found: each variable's parents, the score, how it went."""

    parents: list[tuple[int, ...]]
    score: float
    iterations: int
    restarts: int
    families_scored: int


def _adjacency(parents: Sequence[Iterable[int]]) -> np.ndarray:
    """adjacency[u, v]: is u a parent of v?"""
    n = len(parents)
    adjacency = np.zeros((n, n), dtype=bool)
    for v, ps in enumerate(parents):
        for u in ps:
            adjacency[u, v] = True
    return adjacency


def _parents(adjacency: np.ndarray) -> list[tuple[int, ...]]:
    return [tuple(int(u) for u in np.nonzero(adjacency[:, v])[0])
            for v in range(adjacency.shape[0])]


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
    operations (seeded by ``seed``), climb again; the best DAG found is returned.

    Every move's change of score is read from ``gain[u, v]`` (:meth:`Scores.gains`), the
    change of v's family score when u joins (or leaves) its parents, recomputed for a variable
    only when its parents change; ties between equal moves go to the first in the order
    additions, deletions, reversals, each by (u, v), and a restart from the start breaks them
    in another order (the two directions of an arc score the same under BIC and BDeu, to the
    rounding of their sums, which then decides). The families met are kept, so that a restart
    counts only those it has not met."""
    from bayesprog.learning import _score_kernels as kernels

    n = rules.n
    parents = [set(ps) for ps in start] if start is not None else [set() for _ in range(n)]
    for u, v in rules.required:
        parents[v].add(u)
    check_dag(parents, rules, scores, names)
    begin = _adjacency(parents)
    best, best_score, iterations = scores.climb(begin.copy(), rules, tabu_length, max_iter,
                                                epsilon, patience, np.zeros((n, n)))
    rng = np.random.default_rng([seed, 1])
    steps = max(1, n // 2)
    allowed, required, limit = rules.matrices()
    for restart in range(restarts):
        # every other restart from the best graph perturbed, the others from the start again
        # with the ties of equal moves broken in another order
        ties = rng.random((n, n)) * 1e-7
        if restart % 2 == 0:
            moved = best.copy()
            for _ in range(steps):  # random legal operations
                moves = kernels.legal_moves(moved, allowed, required, limit, scores.card,
                                            MAX_FAMILY_CELLS)
                if len(moves) == 0:
                    break
                op, u, v = (int(x) for x in moves[int(rng.integers(len(moves)))])
                moved[u, v] = op == 0
                if op == 2:
                    moved[v, u] = True
        else:
            moved = begin.copy()
        found, value, more = scores.climb(moved, rules, tabu_length, max_iter, epsilon,
                                          patience, ties)
        iterations += more
        if value > best_score + epsilon:
            best, best_score = found, value
    return Climb(_parents(best), best_score, iterations, restarts, scores.computed)


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
