"""Every marginal in one pass: a junction tree, calibrated once for the evidence, read for all
the searched variables.

The factors of a question, whole (an observed variable keeps its axis: its other states'
entries are made zero in its smallest clique), are joined in the cliques of an elimination
order chosen greedily by the size of the table each step makes (min-weight, ties to the first
variable met; by weighted fill-in for a large tree); a clique's parent is the clique of the
first of its other variables to be eliminated, and a clique contained in its parent is merged
into it. The tree is compiled once per program and set of terms, whatever is observed, and
kept by the program; each call then multiplies the factors into their cliques, enters the
evidence, sends the messages up (collect) and back down (distribute, Hugin's update), and sums
each searched variable's smallest clique down to it. Every table has the batch as its first
axis, so N evidence sets are one pass; messages are scaled to sum to one per row and their
scales kept in log, so that a large network's evidence neither underflows nor is lost.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bayesprog.errors import QuestionError, did_you_mean, expect_mapping
from bayesprog.inference.answers import Posterior, check_zero
from bayesprog.inference.binding import bind
from bayesprog.inference.core import Factor
from bayesprog.inference.factors import (
    latent_continuous,
    question_factors,
    relevant_names,
    slice_factor,
    terms_of,
)
from bayesprog.inference.protocol import ProgramLike
from bayesprog.limits import SizeError, check_size, limit
from bayesprog.vocabulary.expressions import Question, parse_expression
from bayesprog.vocabulary.variables import Discrete, discrete

#: an elimination whose cliques hold this many times the limit on entries in all is stopped:
#: merging the cliques contained in others does not bring it under (bnlearn's networks: by
#: under 2)
BUDGET = 4

#: what the cache keeps for a tree of the whole factors too large to build
_TOO_LARGE: Any = object()


@dataclass
class JunctionTree:
    """Cliques (axes in the tree's order of variables), their parents (-1 for a root: the tree
    may be a forest), the factors each clique multiplies, and where each variable is read."""

    cards: dict[str, int]
    cliques: list[tuple[str, ...]]
    parent: list[int]
    #: the cliques in collect order: each after its children
    post: list[int]
    #: factor index -> (clique, permutation of the factor's axes into the tree's order, shape)
    placed: list[tuple[int, tuple[int, ...], tuple[int, ...]]]
    #: clique -> the axes (after the batch) its message to its parent sums out, the shape that
    #: message takes in the parent, and the parent's axes summed out to the same message
    up: list[tuple[tuple[int, ...], tuple[int, ...], tuple[int, ...]]]
    #: clique -> the shape its parent's message takes in it
    down: list[tuple[int, ...]]
    #: variable -> (clique, axes summed out to read it)
    home: dict[str, tuple[int, tuple[int, ...]]]
    #: the most entries a clique's table holds (per row of evidence)
    largest: int
    #: clique -> its factors' arrays at the last call, when none varies by row: their
    #: product (before it is broadcast over the clique) and its log scale
    initial: dict[int, tuple[tuple[np.ndarray, ...], np.ndarray, float]] = field(
        default_factory=dict)

    @property
    def entries(self) -> int:
        return sum(math.prod(self.cards[a] for a in c) for c in self.cliques)


#: the greedy scores an elimination order can be chosen by: the size of the table a step
#: makes; the edges it adds, then that size; the edges it adds weighed by the sizes of the
#: variables they join, then that size. The last made the smallest trees in all, or within 3 %
#: of the smallest, on bnlearn's networks with hundreds of variables (hepar2, andes, pigs,
#: diabetes, munin); the first is far worse on pigs (3.3 million entries against 0.9), the
#: second on munin (30 million against 16).
HEURISTICS = ("weight", "fill", "weighted fill")
HEURISTIC = "weighted fill"
#: a tree this small (entries in all) by the size alone is kept as it is: choosing by the
#: fill-in costs more at the first call than it saves at the next few (hepar2: 3,201 entries
#: against 3,094; andes: 880,960 against 694,144 before cliques are merged, 485,534 against
#: 389,854 after: 25 ms more to choose, 8 ms less a call)
SMALL_TREE = 1 << 20


def _elimination(scopes: list[tuple[str, ...]], names: list[str], cards: dict[str, int],
                 heuristic: str, budget: float = math.inf
                 ) -> tuple[list[str], list[frozenset[str]], int]:
    """A greedy elimination order, the clique each step makes, and their entries in all; as
    far as it went when the entries passed ``budget`` (then more than it)."""
    rank = {a: i for i, a in enumerate(names)}
    adjacent: dict[str, set[str]] = {a: set() for a in names}
    for scope in scopes:
        for a in scope:
            adjacent[a].update(b for b in scope if b != a)

    def score(a: str) -> tuple[int, ...]:
        around = adjacent[a]
        weight = cards[a] * math.prod(cards[b] for b in around)
        if heuristic == "weight":
            return (weight,)
        # the pairs of neighbours not joined yet: all pairs less those joined (each joined
        # pair seen from both ends), by set intersections rather than pair by pair
        sizes = {cards[x] for x in around}
        if heuristic == "fill" or len(sizes) == 1:  # (weighed alike: the count, weighed)
            joined = sum(len(adjacent[x] & around) for x in around) // 2
            fill = len(around) * (len(around) - 1) // 2 - joined
            return (fill if heuristic == "fill" else fill * sizes.pop() ** 2, weight)
        total = sum(cards[x] for x in around)
        every = (total * total - sum(cards[x] * cards[x] for x in around)) // 2
        joined = sum(cards[x] * sum(cards[y] for y in adjacent[x] & around)
                     for x in around) // 2
        return (every - joined, weight)

    heap = [(score(a), rank[a], a) for a in names]
    heapq.heapify(heap)
    current = {a: found for found, _, a in heap}
    order: list[str] = []
    made: list[frozenset[str]] = []
    total = 0
    while heap:
        found, _, a = heapq.heappop(heap)
        if current.get(a) != found:
            continue
        del current[a]
        around = adjacent.pop(a)
        order.append(a)
        made.append(frozenset(around | {a}))
        total += cards[a] * math.prod(cards[b] for b in around)
        if total > budget:
            break
        added = []  # the edges this step adds, each once
        for b in around:
            neighbours = adjacent[b]
            added += [(b, c) for c in around if rank[c] > rank[b] and c not in neighbours]
            neighbours.discard(a)
            neighbours.update(around - {b})
        # the step's neighbours lost it (their weight and fill change); an added edge changes
        # the fill of the variables joined to both its ends, and of no other
        touched = set(around)
        if heuristic != "weight":
            for b, c in added:
                touched |= adjacent[b] & adjacent[c]
        for b in touched:
            if b in current:
                current[b] = score(b)
                heapq.heappush(heap, (current[b], rank[b], b))
    return order, made, total


def build(scopes: list[tuple[str, ...]], cards: dict[str, int],
          wanted: list[str]) -> JunctionTree:
    """The junction tree of factors over ``scopes`` (``cards``: every variable's states), for
    reading ``wanted`` (each of which is in a scope or has its own one-variable clique)."""
    names = list(dict.fromkeys([a for s in scopes for a in s] + list(wanted)))
    rank = {a: i for i, a in enumerate(names)}
    # an elimination stops once its cliques pass what merging them could bring under the
    # limit (a far too large tree is refused at once), or what a better one already made
    budget = BUDGET * limit("entries")
    order, made, total = _elimination(scopes, names, cards, "weight", budget)
    if total > SMALL_TREE:
        better = _elimination(scopes, names, cards, HEURISTIC, min(total, budget))
        if better[2] < total:
            order, made, total = better
    if total > budget:
        raise SizeError(f"the junction tree of {len(names)} variables needs more than "
                        f"{budget:,} entries, more than the limit of {limit('entries'):,} "
                        "(raise it with the environment variable BAYESPROG_MAX_ENTRIES)")
    position = {a: i for i, a in enumerate(order)}
    # the clique of each eliminated variable; its parent: that of its first other variable out
    parent = [min((position[b] for b in c if b != order[i]), default=-1)
              for i, c in enumerate(made)]
    # a parent held by its child is merged into the child, which takes its place
    into = list(range(len(made)))

    def final(i: int) -> int:
        while into[i] != i:
            into[i] = into[into[i]]
            i = into[i]
        return i

    for i in range(len(made)):
        while parent[i] >= 0:
            p = final(parent[i])
            if p == i or not made[p] <= made[i]:
                parent[i] = p
                break
            into[p] = i
            parent[i] = parent[p]
    kept = [i for i in range(len(made)) if into[i] == i]
    index = {i: k for k, i in enumerate(kept)}
    parents = []
    for i in kept:
        p = final(parent[i]) if parent[i] >= 0 else -1
        parents.append(index[p] if p >= 0 and p != i else -1)
    # collect order: children before their parents (the roots last)
    children: list[list[int]] = [[] for _ in kept]
    for k, p in enumerate(parents):
        if p >= 0:
            children[p].append(k)
    post: list[int] = []
    for root in (k for k, p in enumerate(parents) if p < 0):
        stack = [(root, False)]
        while stack:
            k, done = stack.pop()
            if done:
                post.append(k)
                continue
            stack.append((k, True))
            stack.extend((c, False) for c in children[k])

    def tree_order(clique: frozenset[str]) -> tuple[str, ...]:
        return tuple(sorted(clique, key=rank.__getitem__))

    cliques = [tree_order(made[i]) for i in kept]
    sizes = [math.prod(cards[a] for a in c) for c in cliques]
    check_size(float(sum(sizes)), f"the junction tree of {len(names)} variables "
               f"(largest clique {max(sizes, default=1):,} entries)")
    placed = []
    for scope in scopes:
        first = min((position[a] for a in scope), default=None)
        k = index[final(first)] if first is not None else post[-1]
        clique = cliques[k]
        assert set(scope) <= set(clique)
        perm = tuple(sorted(range(len(scope)), key=lambda j: rank[scope[j]]))
        shape = tuple(cards[a] if a in scope else 1 for a in clique)
        placed.append((k, perm, shape))
    up: list[tuple[tuple[int, ...], tuple[int, ...], tuple[int, ...]]] = []
    down: list[tuple[int, ...]] = []
    for k, clique in enumerate(cliques):
        p = parents[k]
        if p < 0:
            up.append(((), (), ()))
            down.append(())
            continue
        shared = set(clique) & set(cliques[p])
        summed = tuple(1 + j for j, a in enumerate(clique) if a not in shared)
        up.append((summed, tuple(cards[a] if a in shared else 1 for a in cliques[p]),
                   tuple(1 + j for j, a in enumerate(cliques[p]) if a not in shared)))
        down.append(tuple(cards[a] if a in shared else 1 for a in clique))
    holding: dict[str, list[int]] = {}
    for k, clique in enumerate(cliques):
        for a in clique:
            holding.setdefault(a, []).append(k)
    home = {}
    for a in wanted:
        k = min(holding[a], key=sizes.__getitem__)
        home[a] = (k, tuple(1 + j for j, b in enumerate(cliques[k]) if b != a))
    return JunctionTree(dict(cards), cliques, parents, post, placed, up, down, home,
                        max(sizes, default=1))


def calibrate(tree: JunctionTree, factors: list[Factor], size: int,
              observed: Mapping[str, np.ndarray | int] | None = None,
              read: Sequence[str] | None = None) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The posterior of each variable of ``read`` (default: every variable the tree was built
    to read; ``[size, card]``) and the log probability of the evidence (``[size]``) from the
    log-factors the tree was built for (in the same order) and the states ``observed`` (a
    state's index, or one per row), each entered in its variable's smallest clique."""
    check_size(float(size) * tree.entries, f"the junction tree's tables for {size:,} rows")
    log_scale = np.zeros(size)
    # each clique's table before any message: its factors' product, kept while its factors
    # are the same arrays as at the last call (the terms that no evidence value changes)
    by_clique: list[list[int]] = [[] for _ in tree.cliques]
    for i, (k, _, _) in enumerate(tree.placed):
        by_clique[k].append(i)
    tables: list[np.ndarray] = []
    for k, clique in enumerate(tree.cliques):
        full = (size,) + tuple(tree.cards[a] for a in clique)
        own = tuple(factors[i].log for i in by_clique[k])
        kept = tree.initial.get(k)
        if kept is not None and len(kept[0]) == len(own) \
                and all(a is b for a, b in zip(kept[0], own, strict=True)):
            log_scale += kept[2]
            tables.append(np.broadcast_to(kept[1], full).copy())
            continue
        table: np.ndarray | None = None
        offset = np.zeros(size)
        constant = 0.0  # the part of the offset that is the same for every row
        for i in by_clique[k]:
            factor, (_, perm, shape) = factors[i], tree.placed[i]
            log = factor.log
            # each factor scaled by its largest value (per row), kept in log
            if factor.batched:
                axes = tuple(range(1, log.ndim))
                with np.errstate(invalid="ignore"):
                    top = log.max(axis=axes, keepdims=True) if axes else log
                top = np.where(np.isfinite(top), top, 0.0)
                offset = offset + top.reshape(top.shape[0])
            else:
                largest = float(log.max()) if log.size else 0.0
                top = largest if math.isfinite(largest) else 0.0
                constant += top
                log = log[np.newaxis]
            values = np.exp(log - top)
            values = values.transpose((0,) + tuple(1 + j for j in perm)).reshape(
                (values.shape[0],) + shape)
            table = values if table is None else table * values
        if table is None:
            table = np.ones((1,) * len(full))
        log_scale += offset + constant
        if all(not factors[i].batched for i in by_clique[k]):  # the same for every row
            tree.initial[k] = (own, table, constant)
        tables.append(np.broadcast_to(table, full).copy())
    for name, state in (observed or {}).items():  # the other states' entries made zero
        k, _ = tree.home[name]
        clique, card = tree.cliques[k], tree.cards[name]
        sizes: list[int] = [1] * (1 + len(clique))
        sizes[1 + clique.index(name)] = card
        mask: np.ndarray
        if isinstance(state, np.ndarray):
            sizes[0] = size
            mask = np.zeros((size, card))
            mask[np.arange(size), state] = 1.0
        else:
            mask = np.zeros(card)
            mask[state] = 1.0
        tables[k] *= mask.reshape(sizes)
    sent: list[np.ndarray | None] = [None] * len(tree.cliques)
    scales: list[np.ndarray | None] = [None] * len(tree.cliques)
    # messages on their way into a clique, those of the same shape multiplied together first
    # (at the separator's size), each shape then multiplied into the clique's table once
    arriving: list[dict[tuple[int, ...], np.ndarray]] = [{} for _ in tree.cliques]
    with np.errstate(divide="ignore", invalid="ignore"):
        # collect: a clique after its children
        for k in tree.post:
            p = tree.parent[k]
            table = tables[k]
            for shape, product in arriving[k].items():
                table *= product.reshape((size,) + shape)
            if p < 0:
                continue
            summed, shape, _ = tree.up[k]
            message = table.sum(axis=summed) if summed else table.copy()
            total = message.reshape(size, -1).sum(axis=1)
            message /= np.where(total > 0, total, 1.0).reshape((size,) + (1,) * (message.ndim - 1))
            log_scale += np.log(total)
            sent[k] = message
            scales[k] = total
            waiting = arriving[p].get(shape)
            arriving[p][shape] = message if waiting is None else waiting * message
        for k, p in enumerate(tree.parent):  # the roots: each tree's total
            if p < 0:
                table = tables[k]
                assert table is not None
                total = table.reshape(size, -1).sum(axis=1)
                log_scale += np.log(total)
                table /= np.where(total > 0, total, 1.0).reshape((size,) + (1,) * (table.ndim - 1))
        # distribute: a parent before its children (its table summed once per separator)
        summed_parent: dict[tuple[int, tuple[int, ...]], np.ndarray] = {}
        for k in reversed(tree.post):
            p = tree.parent[k]
            if p < 0:
                continue
            _, _, others = tree.up[k]
            parent_table, table, old, scale = tables[p], tables[k], sent[k], scales[k]
            assert old is not None and scale is not None
            new = summed_parent.get((p, others))
            if new is None:
                new = summed_parent[p, others] = (parent_table.sum(axis=others) if others
                                                  else parent_table)
            # the clique's table summed to the scale of its message up: its belief sums to 1
            # (where the message up was zero, the parent's belief is zero too)
            before = old * scale.reshape((size,) + (1,) * (old.ndim - 1))
            ratio = np.zeros(before.shape)
            np.divide(new.reshape(before.shape), before, out=ratio, where=before > 0)
            table *= ratio.reshape((size,) + tree.down[k])
    marginals: dict[str, np.ndarray] = {}
    homed: dict[int, list[str]] = {}
    for name in tree.home if read is None else read:
        homed.setdefault(tree.home[name][0], []).append(name)
    for k, read in homed.items():
        clique = tree.cliques[k]
        where = [clique.index(name) for name in read]
        others = tuple(1 + j for j in range(len(clique)) if j not in where)
        found = tables[k].sum(axis=others) if others else tables[k]
        order = sorted(range(len(read)), key=where.__getitem__)
        _read_each(found, [read[i] for i in order], marginals)
    return marginals, log_scale


def _read_each(table: np.ndarray, names: list[str], into: dict[str, np.ndarray]) -> None:
    """Each axis's marginal of ``table`` (``[rows] + one axis per name``), normalised: the
    axes halved in turn, so that a clique of many read variables is summed over about twice
    its size, not once per variable."""
    if len(names) == 1:
        total = table.sum(axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            into[names[0]] = table / total
        return
    half = len(names) // 2
    _read_each(table.sum(axis=tuple(range(1 + half, 1 + len(names)))), names[:half], into)
    _read_each(table.sum(axis=tuple(range(1, 1 + half))), names[half:], into)


#: a tree of the whole factors larger than this (entries) is weighed against the tree of the
#: factors sliced at the evidence, once per set of observed variables
WHOLE_TREE = 1 << 20


def _tree(program: ProgramLike, factors: list[Factor], wanted: list[str], bound: Any
          ) -> tuple[JunctionTree, bool]:
    """The tree to calibrate, and whether it is that of the factors sliced at the evidence.

    The tree of the whole factors (the observed states entered as zeros) is the program's,
    whatever is observed: built once, it serves every question. Evidence can also split a
    graph (a grid with every other column observed), and then the whole factors' tree is far
    larger than it needs to be, or too large to build: where it is large, and its cliques
    without the observed variables hold under half its entries (or it could not be built),
    the sliced factors' tree is built for this set of observed variables and taken."""
    layouts = program.inference_cache.layouts
    scopes = [f.axes for f in factors]
    held = list(dict.fromkeys([n for axes in scopes for n in axes] + wanted))
    key = ("junction", tuple(scopes), tuple(held))
    whole = layouts.get(key)
    if whole is None:
        cards = {n: discrete(program.variables[n]).card for n in held}
        try:
            whole = build(scopes, cards, held)
        except SizeError:
            if not bound.discrete:
                raise
            whole = _TOO_LARGE
        layouts[key] = whole
    if not bound.discrete or (whole is not _TOO_LARGE and whole.entries <= WHOLE_TREE):
        return whole, False
    observed = tuple(sorted(bound.discrete))
    choice_key = ("junction sliced", tuple(scopes), tuple(wanted), observed)
    chosen = layouts.get(choice_key)
    if chosen is None:
        # the whole tree's cliques without the observed variables are a tree for the sliced
        # factors: their size bounds the sliced tree's, and costs nothing to count
        smaller = whole is _TOO_LARGE or 2 * sum(
            math.prod(whole.cards[a] for a in clique if a not in bound.discrete)
            for clique in whole.cliques) < whole.entries
        if smaller:
            cut = [tuple(a for a in axes if a not in bound.discrete) for axes in scopes]
            names = list(dict.fromkeys([a for axes in cut for a in axes] + wanted))
            chosen = build(cut, {n: discrete(program.variables[n]).card for n in names},
                           wanted)
        else:
            chosen = whole
        layouts[choice_key] = chosen
    return chosen, chosen is not whole


def all_marginals(program: ProgramLike, evidence: Mapping[str, Any] | None,
                  variables: Sequence[str] | None, inputs: Mapping[str, Any] | None = None,
                  soft: Mapping[str, Any] | None = None,
                  ablate: Mapping[str, Any] | None = None) -> dict[str, Posterior]:
    """The posterior of each of ``variables`` (default: every discrete variable not observed)
    given ``evidence``, by one junction tree (see the module's text)."""
    evidence = dict(expect_mapping(evidence, "evidence", "variable names to values"))
    unknown = [n for n in program.conditioning if n not in evidence]
    if unknown:
        raise QuestionError(f"all marginals are asked given {', '.join(unknown)}, which "
                            f"{'have' if len(unknown) > 1 else 'has'} no term in the "
                            "decomposition (the program is conditioned on "
                            f"{'them' if len(unknown) > 1 else 'it'}): give "
                            f"{'their values' if len(unknown) > 1 else 'its value'} in the "
                            "evidence")
    observed = tuple(evidence)
    if variables is None:
        wanted = [n for n, v in program.variables.items()
                  if n not in evidence and isinstance(v, Discrete)]
    else:
        if isinstance(variables, str):
            variables = [variables]
        wanted = list(dict.fromkeys(variables))
        for name in wanted:
            if name not in program.variables:
                raise QuestionError(f"unknown variable {name!r}"
                                    f"{did_you_mean(name, program.variables)} (declared: "
                                    f"{', '.join(program.variables)})")
            if name in evidence:
                raise QuestionError(f"{name} is observed (given as evidence): expected "
                                    "variables that are not")
            if not isinstance(program.variables[name], Discrete):
                raise QuestionError(f"{name} is real: all marginals are asked of discrete "
                                    "variables (ask its density with program.density)")
    if not wanted:
        return {}
    given = f" | {', '.join(observed)}" if observed else ""
    question = Question(parse_expression(f"P({wanted[0]}{given})"), "posterior")
    bound = bind(program, question, evidence, inputs, soft, ablate)
    names = relevant_names(program, wanted, observed, bound.soft)
    terms = terms_of(program, names)
    latent = latent_continuous(terms, bound.continuous)
    if latent:
        raise QuestionError(f"all marginals in one pass need every unobserved variable "
                            f"discrete; {', '.join(latent)} is real: ask each variable "
                            "(program.posterior) instead")
    factors = question_factors(program, terms, bound, sliced=False)
    tree, sliced = _tree(program, factors, wanted, bound)
    batch = bound.batch_shape
    if bound.size == 0:  # no rows of evidence: answers of no rows
        found = {n: np.empty((0, discrete(program.variables[n]).card)) for n in wanted}
        log_evidence = np.empty(0)
    elif sliced:
        found, log_evidence = calibrate(tree, [slice_factor(f, bound) for f in factors],
                                        bound.size, None, wanted)
    else:
        entered = {n: state for n, state in bound.discrete.items() if n in tree.home}
        found, log_evidence = calibrate(tree, factors, bound.size, entered, wanted)
    answers = {}
    for name in wanted:
        var = program.variables[name]
        assert isinstance(var, Discrete)
        answer = Posterior(
            question=f"P({name}{given})",
            variables=(name,),
            names={name: var.states},
            probabilities=found[name].reshape(batch + (var.card,)),
            log_evidence=log_evidence.reshape(batch),
            batch_shape=batch,
            ablated=program.ablated,
            values={name: var.typed_states},
            method="junction tree",
        )
        check_zero(answer)
        answers[name] = answer
    return answers
