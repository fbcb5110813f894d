"""What every inference method shares: the log-factor, and the per-program cache of compiled
pieces (contraction expressions, evidence-free factors, compiled tables)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from bayesprog.support.extras import LazyModule

#: opt_einsum, imported by the first contraction path searched or compiled (a layout's first
#: question, answered by elimination, needs none)
opt_einsum = LazyModule("opt_einsum")


@dataclass
class Factor:
    """A log-factor over ``axes``: ``log`` is ``[B] + cards`` if ``batched``, else ``cards``."""

    axes: tuple[str, ...]
    log: np.ndarray
    batched: bool


#: Above this many operations, opt_einsum's greedy path is set beside a min-fill elimination
#: order and the cheaper one taken.
SECOND_OPINION = 1e6
#: A step that is a matrix product (BLAS) does this many operations in the time numpy's einsum
#: does one (measured: about 5e10 against 1e9 per second on large steps, both paths of the
#: benchmark's networks and grids); costs are counted in einsum operations.
BLAS_SPEED = 40.0
#: In choosing between two paths, an einsum step that sums out an index (outside BLAS) counts
#: this many times a product: on large batched steps its loops are that much slower (insurance,
#: 10,000 rows: greedy 0.06 s, min-fill 0.16 s); the estimate of the time counts it once
#: (small steps, as on grids, run at the product's speed).
EINSUM_SUM = 4.0
#: What each product of a stack of matrix products costs beside its operations (about 70 ns:
#: numpy's matmul over many small matrices runs near einsum's speed, over a few large ones at
#: BLAS's), in operations.
MATMUL_EACH = 80.0
#: A stack of matrix products each smaller than this (operations) runs as an einsum: numpy's
#: matmul pays per product (10,000 rows of 3 x 3 products: twice einsum's time).
MATMUL_MIN = 256
#: What a matrix-product step (tensordot or matmul) costs per entry it reads and writes, in
#: operations: its operands are transposed into place and its result written back, which costs
#: what BLAS's arithmetic does not once the operands outgrow the caches (16 x 16 grid: the
#: estimate without it was a third of the clock, benchmarks/engine.py).
MOVED = 1.0


def contraction_path(equation: str, shapes: list[tuple[int, ...]]) -> tuple[list, Any, float]:
    """The contraction path for ``equation`` (opt_einsum's notation) over ``shapes``, its
    :class:`Account` (steps, ``largest_intermediate``) and its cost in operations, a matrix
    product's counting ``1 / BLAS_SPEED``.

    opt_einsum's greedy path, or where it costs more than ``SECOND_OPINION`` operations, the
    cheaper of it and the path of a min-fill elimination order (variable elimination's classic
    heuristic: eliminate the index whose neighbours need the fewest new links). On grid-like
    networks the greedy path is several times costlier (16 x 16 binary grid: 6.8e8 against
    1.9e8 operations); on batched questions over networks such as insurance, min-fill's steps
    fall outside matrix products and greedy is faster. Both are deterministic."""
    small = _one_step(equation, shapes)
    if small is not None:
        return small
    inputs, output = equation.split("->")
    terms = inputs.split(",")
    sizes: dict[str, int] = {}
    for term, shape in zip(terms, shapes, strict=True):
        sizes.update(zip(term, shape, strict=True))
    if len(terms) < 3:
        path: list[tuple[int, ...]] = [tuple(range(len(terms)))]
    else:
        path = opt_einsum.paths.greedy([frozenset(t) for t in terms], frozenset(output), sizes)
    info = Account.of(terms, output, sizes, path)
    cost = info.cost()
    if len(shapes) < 3 or cost <= SECOND_OPINION:
        return path, info, cost
    other_path = _min_fill_path(equation, shapes)
    other = Account.of(terms, output, sizes, other_path)
    if other.cost(EINSUM_SUM) < info.cost(EINSUM_SUM):
        return other_path, other, other.cost()
    return path, info, cost


#: A contraction whose indices span at most this many combinations is done in one einsum
#: step, without a path search (which would cost more than the contraction).
ONE_STEP = 1024


class Step(NamedTuple):
    """One step of a contraction path (see :class:`Account`)."""

    positions: tuple[int, ...]
    removed: frozenset[str]
    text: str
    flops: int
    kind: str
    #: how many matrix products a ``matmul`` step stacks (1 for the other kinds)
    stack: int
    #: entries of the operands and the result
    moved: int = 0


@dataclass
class Account:
    """The steps of a contraction path: for each, the positions of its operands (popped from
    the end, the result appended, as opt_einsum does), the indices it sums out, its einsum
    string, its operations, and how the runner does it (``einsum``; ``tensordot``, a matrix
    product BLAS does; ``matmul``, a stack of them over the indices both operands keep); with the
    index sizes and the largest intermediate (entries). What opt_einsum's ``contract_path``
    tells of a path, made without its checks and printing (a third of a first question's
    time on a 40-variable network)."""

    steps: list[Step]
    size_dict: dict[str, int]
    largest_intermediate: float

    @classmethod
    def of(cls, terms: list[str], output: str, sizes: dict[str, int],
           path: list[tuple[int, ...]]) -> Account:
        """The account of ``path`` over operands with index strings ``terms``."""
        remaining = list(terms)
        steps = []
        largest = 1.0
        for number, positions in enumerate(path):
            order = tuple(sorted(positions, reverse=True))
            taken = [remaining.pop(i) for i in order]
            involved = set("".join(taken))
            if number == len(path) - 1:
                result = output
            else:
                kept = set(output).union(*remaining) & involved
                joined = "".join(taken)  # tensordot's order: fewer transpositions
                result = "".join(sorted(kept, key=joined.find))
            removed = frozenset(involved.difference(result))
            flops = math.prod(sizes[i] for i in involved) * (
                max(1, len(taken) - 1) + (1 if removed else 0))
            kind, stack = "einsum", 1
            if len(taken) == 2 and flops >= BLAS_MIN and removed:
                if blas_kind(taken, result, removed, [tuple(sizes[i] for i in t) for t in taken]):
                    kind = "tensordot"
                elif removed <= set(taken[0]) & set(taken[1]) and all(
                        set(t).difference(u) for t, u in (taken, taken[::-1])):
                    # a matrix product per value of the indices both operands keep (each
                    # keeping some of its own: a matrix times a vector is einsum's), unless
                    # the products are so small that einsum's loops do them faster
                    stack = math.prod(sizes[i] for i in set(taken[0]) & set(taken[1])
                                      if i not in removed)
                    kind = "matmul" if flops >= MATMUL_MIN * stack else "einsum"
            moved = sum(math.prod(sizes[i] for i in t) for t in taken) \
                + math.prod(sizes[i] for i in result)
            steps.append(Step(order, removed, ",".join(taken) + "->" + result, flops, kind,
                              stack, moved))
            remaining.append(result)
            largest = max(largest, float(math.prod(sizes[i] for i in result)))
        return cls(steps, sizes, largest)

    def cost(self, summing: float = 1.0) -> float:
        """The path's operations, a matrix product's counting 1 / BLAS_SPEED (and a stack of
        them ``MATMUL_EACH`` more per product, and ``MOVED`` per entry read and written) and an
        einsum step that sums out an index ``summing``."""
        total = 0.0
        for step in self.steps:
            if step.kind == "einsum":
                total += step.flops * (summing if step.removed else 1.0)
            else:
                total += (step.flops / BLAS_SPEED + (step.stack - 1) * MATMUL_EACH
                          + MOVED * step.moved)
        return total


def blas_kind(taken: list[str], result: str, removed: frozenset[str],
              shapes: list[tuple[int, ...]]) -> bool:
    """Whether a pairwise step is a matrix product numpy's tensordot does by BLAS."""
    kind = opt_einsum.blas.can_blas(taken, result, removed, shapes)
    return bool(kind) and "EINSUM" not in kind


def _one_step(equation: str, shapes: list[tuple[int, ...]]) -> tuple[list, Any, float] | None:
    """A path of one step over all operands when their indices span at most ``ONE_STEP``
    combinations (its operations: that many per operand), else None."""
    inputs, output = equation.split("->")
    terms = inputs.split(",")
    sizes: dict[str, int] = {}
    for term, shape in zip(terms, shapes, strict=True):
        sizes.update(zip(term, shape, strict=True))
    span = math.prod(sizes.values())
    if span > ONE_STEP:
        return None
    order = tuple(range(len(terms) - 1, -1, -1))  # popped last first, as opt_einsum does
    step = ",".join(terms[i] for i in order) + "->" + output
    removed = frozenset(sizes) - set(output)
    info = Account([Step(order, removed, step, span * len(terms), "einsum", 1)], sizes,
                   float(span))
    return [tuple(range(len(terms)))], info, float(span * len(terms))


def _min_fill_path(equation: str, shapes: list[tuple[int, ...]]) -> list[tuple[int, ...]]:
    """A contraction path from a min-fill elimination order: for each index in turn, the
    operands that hold it contracted pairwise, smallest first (the output's indices stay)."""
    inputs, output = equation.split("->")
    operands = [frozenset(term) for term in inputs.split(",")]
    card: dict[str, int] = {}  # in order of first appearance: ties go to the earliest index
    for text, shape in zip(inputs.split(","), shapes, strict=True):
        card.update(zip(text, shape, strict=True))
    first = {a: i for i, a in enumerate(card)}
    adjacent: dict[str, set[str]] = {a: set() for a in card}
    for operand in operands:
        for a in operand:
            adjacent[a] |= operand - {a}

    def score(v: str) -> tuple[int, float, int]:
        around = list(adjacent[v])
        fill = sum(1 for i, x in enumerate(around) for y in around[i + 1:]
                   if y not in adjacent[x])
        return fill, float(np.prod([card[x] for x in around])), first[v]

    todo = set(card) - set(output)
    scores: dict[str, tuple[int, float, int]] = {v: score(v) for v in todo}
    path: list[tuple[int, ...]] = []
    current = list(operands)

    def size(term: frozenset[str]) -> float:
        return float(np.prod([card[a] for a in term]))

    while todo:
        v = min(todo, key=scores.__getitem__)
        todo.discard(v)
        holding = [i for i, term in enumerate(current) if v in term]
        while len(holding) > 1:
            i, j = sorted(holding, key=lambda k: size(current[k]))[:2]
            path.append((i, j))
            merged = current[i] | current[j]
            current = [t for k, t in enumerate(current) if k not in (i, j)] + [merged]
            holding = [k for k, term in enumerate(current) if v in term]
        around = adjacent.pop(v)
        for x in around:
            adjacent[x].discard(v)
            adjacent[x] |= around - {x}
        touched = set(around).union(*(adjacent[x] for x in around)) if around else set()
        for x in touched & todo:
            scores[x] = score(x)
    if len(current) > 1:
        path.append(tuple(range(len(current))))
    return path


#: A matrix-product step with fewer operations than this runs as an einsum: its call costs
#: less than tensordot's reshapes and transposes.
BLAS_MIN = 4096
#: An einsum step with at least this many operations first lays its smaller operands out in
#: the memory order of its largest (see :func:`aligned_einsum`).
ALIGN_MIN = 1 << 14


def aligned_einsum(subscripts: str, *arrays: np.ndarray) -> np.ndarray:
    """``np.einsum(subscripts, *arrays)``, each operand of at most a sixteenth of the largest's
    entries first copied into the largest's memory order (a copy of a few entries). numpy's
    einsum walks the largest operand in its memory order and runs its inner loop over the axes
    that every operand steps through alike: a small operand whose axes run in another order
    splits that loop into loops of one index each (16 x 16 grid: a 2^20-entry step took 7.5 ms
    where its operands in one order take 0.9 ms)."""
    inputs, result = subscripts.split("->")
    terms = inputs.split(",")
    big = max(range(len(arrays)), key=lambda i: arrays[i].size)
    strides = arrays[big].strides
    # the largest operand's indices from its outermost axis in memory to its innermost
    rank = {terms[big][axis]: r for r, axis in enumerate(
        sorted(range(len(strides)), key=lambda a: -abs(strides[a])))}
    laid, changed = list(arrays), False
    for i, (term, array) in enumerate(zip(terms, arrays, strict=True)):
        if i == big or 16 * array.size > arrays[big].size:
            continue
        order = sorted(range(len(term)), key=lambda a: (rank.get(term[a], -1), a))
        laid[i] = np.asarray(array.transpose(order), order="C")  # (0-d stays 0-d)
        if order != list(range(len(term))):
            terms[i] = "".join(term[a] for a in order)
            changed = True
    if changed:
        subscripts = ",".join(terms) + "->" + result
    return np.einsum(subscripts, *laid)


class Contraction:
    """A contraction path, run step by step with numpy: each pairwise step as an einsum, or,
    for large matrix products, as a tensordot (BLAS) and a transpose, or where both operands
    keep some indices, as a stack of matrix products (``np.matmul``: numpy's einsum runs such
    steps over many small indices ten times slower per operation). What opt_einsum's compiled
    expressions do, with the per-step choices and index strings settled once, so that a
    contraction of small tables costs a few microseconds of Python, not tens."""

    def __init__(self, info: Any) -> None:
        """``info``: the path's :class:`Account`."""
        self.steps: list[tuple[tuple[int, ...], str, Any]] = []
        for inds, _, einsum_str, flops, kind, _, _ in info.steps:
            einsum_str = opt_einsum.parser.convert_to_valid_einsum_chars(einsum_str)
            inputs, result = einsum_str.split("->")
            if kind == "tensordot":
                left, right = inputs.split(",")
                gone = [s for s in set(left) & set(right) if s not in result]
                axes = tuple(zip(*sorted((left.find(s), right.find(s)) for s in gone),
                                 strict=True)) \
                    if gone else ((), ())
                produced = "".join(s for s in left + right if s not in gone)
                order = tuple(map(produced.index, result)) if produced != result else None
                self.steps.append((tuple(inds), "tensordot", (axes, order)))
            elif kind == "matmul":
                self.steps.append((tuple(inds), "matmul", _stacked(inputs, result)))
            elif flops >= ALIGN_MIN and len(inds) > 1:
                self.steps.append((tuple(inds), "aligned", einsum_str))
            else:
                self.steps.append((tuple(inds), "einsum", einsum_str))

    def __call__(self, *arrays: np.ndarray) -> np.ndarray:
        operands = list(arrays)
        for inds, kind, how in self.steps:
            taken = [operands.pop(i) for i in inds]
            if kind == "einsum":
                operands.append(np.einsum(how, *taken))
            elif kind == "aligned":
                operands.append(aligned_einsum(how, *taken))
            elif kind == "tensordot":
                axes, order = how
                product = np.tensordot(taken[0], taken[1], axes=axes)
                operands.append(product if order is None else product.transpose(order))
            else:
                left, right, (kept, own, summed), order = how
                a, b = taken[0].transpose(left), taken[1].transpose(right)
                rows = a.shape[kept:kept + own]
                stacked = np.matmul(
                    a.reshape(math.prod(a.shape[:kept]), math.prod(rows), -1),
                    b.reshape(math.prod(b.shape[:kept]), math.prod(b.shape[kept:kept + summed]),
                              -1))
                product = stacked.reshape(a.shape[:kept] + rows + b.shape[kept + summed:])
                operands.append(product if order is None else product.transpose(order))
        return operands[0]


def _stacked(inputs: str, result: str) -> tuple[tuple[int, ...], tuple[int, ...],
                                                  tuple[int, int, int], tuple[int, ...] | None]:
    """How a pairwise step ``inputs -> result`` is a stack of matrix products: the left
    operand's axes in the order (kept by both, its own, summed), the right's in the order
    (kept by both, summed, its own), the counts of the first three groups, and the order of
    the product's axes in the result (None: already in it)."""
    left, right = inputs.split(",")
    kept = [s for s in left if s in right and s in result]
    summed = [s for s in left if s in right and s not in result]
    own_left = [s for s in left if s not in right]
    own_right = [s for s in right if s not in left]
    produced = kept + own_left + own_right
    order = tuple(produced.index(s) for s in result)
    return (tuple(left.index(s) for s in kept + own_left + summed),
            tuple(right.index(s) for s in kept + summed + own_right),
            (len(kept), len(own_left), len(summed)),
            None if order == tuple(range(len(order))) else order)


_LETTERS = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"


def symbol(i: int) -> str:
    """The ``i``-th einsum symbol, as opt_einsum's ``get_symbol`` gives it (its 52 letters, then
    characters from ``chr(192)`` on, surrogates skipped), without importing opt_einsum for it.

    >>> symbol(2), symbol(200), symbol(60000) == chr(62048)
    ('c', 'Ŕ', True)
    """
    if i < 52:
        return _LETTERS[i]
    return chr(i + 2048) if i >= 55296 else chr(i + 140)


def equation(operands: list[tuple[str, ...]], output: tuple[str, ...],
             batched: list[bool] | None = None, batched_out: bool = False) -> str:
    """The einsum equation (opt_einsum's symbols) contracting factors over ``operands`` axes
    down to ``output``: each variable's symbol from its rank among the names, the batch axis
    (of the factors that are ``batched``) the first symbol. The same factors give the same
    equation, so that the cost model's path serves the contraction."""
    names = sorted({a for axes in operands for a in axes} | set(output))
    sym = {n: symbol(i + 1) for i, n in enumerate(names)}
    batch = symbol(0)
    flags = batched or [False] * len(operands)
    terms = [(batch if b else "") + "".join(sym[a] for a in axes)
             for axes, b in zip(operands, flags, strict=True)]
    return ",".join(terms) + "->" + (batch if batched_out else "") + "".join(
        sym[a] for a in output)


class Plans:
    """Contraction paths by equation and shapes (searched once: the cost model's estimate
    and the contraction share them), and contraction runners by the operands' layout."""

    def __init__(self) -> None:
        self._cache: dict[Any, Any] = {}
        self._paths: dict[Any, tuple[list, Any, float]] = {}

    def path(self, equation: str, shapes: list[tuple[int, ...]]) -> tuple[list, Any, float]:
        """:func:`contraction_path` of ``equation`` over ``shapes``, searched once."""
        key = (equation, tuple(shapes))
        found = self._paths.get(key)
        if found is None:
            found = self._paths[key] = contraction_path(equation, shapes)
        return found

    def get(self, operands: list[Factor], output: tuple[str, ...], batched_out: bool) -> Any:
        # the batch size enters the key by its order of magnitude only (powers of 4): a plan
        # serves batches of similar sizes (opt_einsum checks ranks, not sizes), and the best
        # path for 10,000 rows is not the best for one
        rows = max((f.log.shape[0] for f in operands if f.batched), default=1)
        key = (tuple((f.axes, f.batched, f.log.shape[f.batched:]) for f in operands), output,
               batched_out, rows.bit_length() // 2)
        expr = self._cache.get(key)
        if expr is None:
            eq = equation([f.axes for f in operands], output, [f.batched for f in operands],
                          batched_out)
            _, info, _ = self.path(eq, [f.log.shape for f in operands])
            expr = self._cache[key] = Contraction(info)
        return expr


@dataclass
class InferenceCache:
    """Compiled pieces a program keeps between questions (its terms never change: an ablation
    is a new program with a cache of its own)."""

    plans: Plans = field(default_factory=Plans)
    #: layouts of questions (searched and known variables by name), by their key
    layouts: dict[Any, Any] = field(default_factory=dict)
    #: factors of terms that depend on no evidence nor input, by id of the term
    static_factors: dict[int, Factor] = field(default_factory=dict)
    #: the program's terms made uniform, for the questions that ablate them on some rows, by
    #: id of the term
    uniform_terms: dict[int, Any] = field(default_factory=dict)
    #: the same factors in the probability domain, each divided by its largest entry, and
    #: the log of that entry
    static_tables: dict[int, tuple[np.ndarray, float]] = field(default_factory=dict)
    #: compiled tables of the table method, by (searched, observed)
    tables: dict[Any, Any] = field(default_factory=dict)
    #: programs derived from this one for a method (its real variables on bins, ...)
    derived: dict[Any, Any] = field(default_factory=dict)
    #: each discrete variable's states by name (binding evidence given by name)
    state_lookups: dict[str, dict[str, int]] | None = None
    #: the program's graph as questions walk it (:func:`~bayesprog.inference.relevance.family`)
    family: Any = None
    #: warm paths of questions asked again (:mod:`~bayesprog.inference.quick`), by question
    #: text, kind, method and known variables
    quick: dict[Any, Any] = field(default_factory=dict)
