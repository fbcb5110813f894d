"""Compiled loops (numba) of score-based structure learning: the counts of a family, its
score, a cache of the scores computed, and the hill climb itself.

The data are held twice, coded once (:func:`prepare`):

* as their distinct rows (variables x distinct rows, small ints, -1 where a value is missing)
  with each one's number of occurrences: a family's counts are one pass over them (asia's
  10,000 rows are 55 distinct ones), its parents' configurations numbered as they are met once
  there are more of them than rows, so that no table is larger than the rows it counts;
* as bit sets, the rows where each variable takes each state: the rows of a family's cell are
  the AND of its states' sets, counted by ``popcount``, 64 rows an instruction. A family with
  few configurations (a pair, a child with one or two parents) is counted so, its candidates'
  last state by difference when they have a value in every row; a larger one in a pass over
  the distinct rows (whichever costs less, as measured: 0.3 ns a word, 2.5 ns a row).

A family's score is kept in an open-addressing hash table keyed by the family (the child, then
the parents as a bit set), computed once: a restart that meets a family again reads it. The
climb keeps ``gain[u, v]``, the change of v's family score when u joins its parents (or
leaves them, when u is one), recomputed only for the variables whose parents a move changes;
the candidates a refresh has not met before are counted together.

Imported at the first use (numba takes a while to load).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

#: the scores, as :class:`~bayesprog.learning.structure.Scores` names them
KINDS = {"bic": 0, "bdeu": 1, "k2": 2, "k2-exact": 3}
BIC, BDEU, K2, K2_EXACT = 0, 1, 2, 3

_M1 = np.uint64(0x9E3779B97F4A7C15)
_M2 = np.uint64(0xBF58476D1CE4E5B9)
_ONE = np.uint64(1)
_S32 = np.uint64(32)


#: the data as the kernels read them: the distinct rows (variables x rows), their numbers of
#: occurrences, each variable's number of states, the rows of each state of each variable as
#: bit sets (from ``offset[v]``), the set of all rows, which variables have a value in every row
Data = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
#: the cache of family scores: keys (child, parents as bits), values, filled slots,
#: [entries, families computed]
Table = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
#: the most memory the bit sets of the rows take (beyond it, the rows are counted one by one)
BITS_LIMIT = 64 << 20


def prepare(codes: np.ndarray, card: np.ndarray) -> Data:
    """The kernels' view of coded data (rows x variables, -1 where missing)."""
    small = np.int8 if card.size == 0 or card.max() <= 127 else np.int32
    coded = np.ascontiguousarray(codes, dtype=small)
    rows, weights = distinct_rows(coded)
    offset = np.zeros(card.size + 1, np.int64)
    offset[1:] = np.cumsum(card)
    m = codes.shape[0]
    width = (m + 63) // 64
    if offset[-1] * width * 8 > BITS_LIMIT:
        width = 0
    bits = np.zeros((offset[-1], width), np.uint64)
    everyone = np.zeros(width, np.uint64)
    if width:
        _fill_bits(coded, offset, bits)
        everyone[:] = np.uint64(0xFFFFFFFFFFFFFFFF)
        if m % 64:
            everyone[-1] = np.uint64((1 << (m % 64)) - 1)
    complete = np.asarray((codes >= 0).all(axis=0), dtype=np.bool_)
    return (rows, weights, np.ascontiguousarray(card, dtype=np.int64), bits, offset, everyone,
            complete)


@njit(cache=True)
def _fill_bits(codes: np.ndarray, offset: np.ndarray, bits: np.ndarray) -> None:
    for i in range(codes.shape[0]):
        word = i >> 6
        bit = _ONE << np.uint64(i & 63)
        for c in range(codes.shape[1]):
            x = codes[i, c]
            if x >= 0:
                bits[offset[c] + x, word] |= bit


def key_width(n: int) -> int:
    """Words of a family's key: the child, then one bit per variable."""
    return 1 + (n + 63) // 64


def empty_table(n: int, capacity: int = 1 << 10) -> Table:
    """A cache of family scores: keys, values, which slots are filled, and [entries,
    families computed]."""
    return (np.zeros((capacity, key_width(n)), np.uint64), np.zeros(capacity),
            np.zeros(capacity, np.bool_), np.zeros(2, np.int64))


# the data as distinct rows -------------------------------------------------------------------

@njit(cache=True)
def distinct_rows(codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of ``codes`` (rows x variables), as columns (variables x distinct
    rows, in the order first met), and how many times each occurs."""
    m, n = codes.shape
    capacity = 16
    while capacity < 2 * m:
        capacity *= 2
    mask = np.uint64(capacity - 1)
    slots = np.full(capacity, -1, np.int64)
    first = np.empty(m, np.int64)
    weights = np.zeros(m, np.int32)
    k = 0
    for i in range(m):
        h = _M1
        for c in range(n):
            h = (h ^ np.uint64(codes[i, c] + 1)) * _M2
            h ^= h >> _S32
        s = np.int64(h & mask)
        while True:
            j = slots[s]
            if j < 0:
                slots[s] = k
                first[k] = i
                weights[k] = 1
                k += 1
                break
            same = True
            row = first[j]
            for c in range(n):
                if codes[row, c] != codes[i, c]:
                    same = False
                    break
            if same:
                weights[j] += 1
                break
            s = (s + 1) & (capacity - 1)
    rows = np.empty((n, k), codes.dtype)
    for j in range(k):
        row = first[j]
        for c in range(n):
            rows[c, j] = codes[row, c]
    return rows, weights[:k].copy()


# counts and scores -----------------------------------------------------------------------------

@njit(cache=True)
def _configurations(rows: np.ndarray, card: np.ndarray, child: int,
                    parents: np.ndarray) -> tuple[np.ndarray, int]:
    """Each distinct row's configuration of ``parents`` (-1 where the child or a parent is
    missing) and the number of configurations: mixed radix while there are no more of them
    than rows, numbered in the order met past that."""
    k = rows.shape[1]
    conf = np.zeros(k, np.int64)
    own = rows[child]
    for i in range(k):
        if own[i] < 0:
            conf[i] = -1
    count = 1
    for t in range(parents.size):
        p = parents[t]
        c = int(card[p])
        column = rows[p]
        span = count * c
        if span <= k:
            for i in range(k):
                if conf[i] >= 0:
                    x = column[i]
                    conf[i] = -1 if x < 0 else conf[i] * c + x
            count = span
        else:
            number = np.full(span, -1, np.int64)
            met = 0
            for i in range(k):
                if conf[i] >= 0:
                    x = column[i]
                    if x < 0:
                        conf[i] = -1
                        continue
                    cell = conf[i] * c + x
                    if number[cell] < 0:
                        number[cell] = met
                        met += 1
                    conf[i] = number[cell]
            count = met
    return conf, count


@njit(cache=True)
def _score_counts(counts: np.ndarray, configurations: int, r: int, q: float, kind: int,
                  ess: float) -> float:
    """The score of a family from its counts (``configurations`` x ``r``, flat) when its
    parents have ``q`` configurations in all (those without rows add nothing, but to K2 as
    pgmpy computes it and to BIC's penalty)."""
    if kind == BIC:
        ll = 0.0
        total = 0.0
        for j in range(configurations):
            nj = 0.0
            for s in range(r):
                nj += counts[j * r + s]
            if nj == 0.0:
                continue
            total += nj
            for s in range(r):
                x = float(counts[j * r + s])
                if x > 0.0:
                    ll += x * math.log(x / nj)
        if total == 0.0:
            return 0.0
        return ll - 0.5 * math.log(total) * q * (r - 1)
    # BDeu and K2: a Dirichlet prior of ``beta`` per cell (``alpha`` per configuration); K2's
    # is one count per cell, and pgmpy's counts lgamma(r) for a configuration without rows
    alpha, beta = (ess / q, ess / (q * r)) if kind == BDEU else (float(r), 1.0)
    lg_alpha = math.lgamma(alpha)
    lg_beta = math.lgamma(beta)
    value = 0.0
    seen = 0
    for j in range(configurations):
        nj = 0.0
        for s in range(r):
            x = float(counts[j * r + s])
            if x > 0.0:
                nj += x
                value += math.lgamma(x + beta) - lg_beta
        if nj > 0.0:
            value += lg_alpha - math.lgamma(nj + alpha)
            seen += 1
    if kind == K2:
        value += (q - seen) * lg_alpha
    return value


@njit(cache=True)
def _configurations_q(card: np.ndarray, parents: np.ndarray) -> float:
    q = 1.0
    for t in range(parents.size):
        q *= card[parents[t]]
    return q


@njit(cache=True)
def family_counts(rows: np.ndarray, weights: np.ndarray, card: np.ndarray, child: int,
                  parents: np.ndarray) -> tuple[np.ndarray, int]:
    """The counts of ``child`` given ``parents`` over the rows where all are observed:
    (configurations, child states), flat, and the number of configurations (all of them in
    mixed radix, the last parent fastest, while they are no more than the distinct rows; else
    those met, in the order met)."""
    conf, configurations = _configurations(rows, card, child, parents)
    r = card[child]
    counts = np.zeros(configurations * r, np.int64)
    own = rows[child]
    for i in range(conf.size):
        if conf[i] >= 0:
            counts[conf[i] * r + own[i]] += weights[i]
    return counts, configurations


# the cache of family scores ------------------------------------------------------------------

@njit(cache=True)
def _slot(keys: np.ndarray, filled: np.ndarray, key: np.ndarray) -> np.int64:
    """The slot of ``key``: where it is, or the empty slot where it goes."""
    capacity, width = keys.shape
    h = _M1
    for w in range(width):
        h = (h ^ key[w]) * _M2
        h ^= h >> _S32
    s = np.int64(h & np.uint64(capacity - 1))
    while filled[s]:
        same = True
        for w in range(width):
            if keys[s, w] != key[w]:
                same = False
                break
        if same:
            return s
        s = (s + 1) & (capacity - 1)
    return s


@njit(cache=True)
def _insert(table: Table, key: np.ndarray, value: float) -> Table:
    keys, values, filled, meta = table
    s = _slot(keys, filled, key)
    if filled[s]:
        values[s] = value
        return table
    keys[s, :] = key
    values[s] = value
    filled[s] = True
    meta[0] += 1
    if 2 * meta[0] <= keys.shape[0]:
        return table
    bigger = np.zeros((2 * keys.shape[0], keys.shape[1]), np.uint64)
    more = np.zeros(2 * keys.shape[0])
    taken = np.zeros(2 * keys.shape[0], np.bool_)
    for old in range(keys.shape[0]):
        if filled[old]:
            t = _slot(bigger, taken, keys[old])
            bigger[t, :] = keys[old]
            more[t] = values[old]
            taken[t] = True
    return bigger, more, taken, meta


@njit(cache=True)
def _key(child: int, parents: np.ndarray, width: int) -> np.ndarray:
    key = np.zeros(width, np.uint64)
    key[0] = np.uint64(child)
    for t in range(parents.size):
        p = parents[t]
        key[1 + p // 64] |= _ONE << np.uint64(p % 64)
    return key


@njit(cache=True)
def _toggled(key: np.ndarray, u: int) -> np.ndarray:
    out = key.copy()
    out[1 + u // 64] ^= _ONE << np.uint64(u % 64)
    return out


@njit(cache=True)
def family_score(data: Data, kind: int, ess: float, child: int, parents: np.ndarray,
                 table: Table) -> tuple[float, Table]:
    """The score of ``child`` given ``parents``: from the cache, or counted, scored and
    kept."""
    key = _key(child, parents, table[0].shape[1])
    s = _slot(table[0], table[2], key)
    if table[2][s]:
        return table[1][s], table
    card = data[2]
    counts, configurations = family_counts(data[0], data[1], card, child, parents)
    value = _score_counts(counts, configurations, card[child], _configurations_q(card, parents),
                          kind, ess)
    table[3][1] += 1
    return value, _insert(table, key, value)


# the moves' gains ----------------------------------------------------------------------------

def _ctpop(typingctx: Any, x: Any) -> Any:
    signature = types.int64(types.uint64)  # an int64, so that sums of counts stay integers

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        return builder.call(builder.module.declare_intrinsic("llvm.ctpop", [args[0].type]),
                            args)

    return signature, codegen


#: the bits set in a uint64 (LLVM's ctpop: one instruction), as an int64
_popcount: Any = intrinsic(_ctpop)


@njit(cache=True)
def _joint_bits(bits: np.ndarray, offset: np.ndarray, everyone: np.ndarray, card: np.ndarray,
                child: int, parents: np.ndarray) -> tuple[np.ndarray, int]:
    """The rows of each configuration of ``parents`` met and state of ``child``, as bit sets
    (configuration x child states, flat), and the number of configurations met."""
    width = everyone.size
    level = everyone.reshape(1, width).copy()
    met = 1
    for t in range(parents.size):
        p = parents[t]
        c = card[p]
        wider = np.empty((met * c, width), np.uint64)
        count = 0
        for j in range(met):
            for x in range(c):
                seen = np.uint64(0)
                row = bits[offset[p] + x]
                for w in range(width):
                    value = level[j, w] & row[w]
                    wider[count, w] = value
                    seen |= value
                if seen != np.uint64(0):
                    count += 1
        level = wider[:count]
        met = count
    r = card[child]
    joint = np.empty((met * r, width), np.uint64)
    for j in range(met):
        for s in range(r):
            row = bits[offset[child] + s]
            for w in range(width):
                joint[j * r + s, w] = level[j, w] & row[w]
    return joint, met


@njit(cache=True)
def _count_bits(joint: np.ndarray, r: int, bits: np.ndarray, offset: np.ndarray,
                complete: np.ndarray, card: np.ndarray, candidates: np.ndarray,
                starts: np.ndarray, counts: np.ndarray) -> None:
    """The counts of each candidate u joined to a family whose rows by configuration and
    child state are the bit sets ``joint``, into ``counts[starts[i]:]`` laid out
    (configuration, state of u, child state); the rows of u's last state are the others less
    the rest, when u has a value in every row."""
    width = joint.shape[1]
    where = np.empty(width, np.int64)
    for js in range(joint.shape[0]):
        j = js // r
        s = js % r
        total = 0
        used = 0
        for w in range(width):
            value = joint[js, w]
            if value != np.uint64(0):
                total += _popcount(value)
                where[used] = w
                used += 1
        if total == 0:
            continue
        sparse = 3 * used < width
        for i in range(candidates.size):
            u = candidates[i]
            cu = card[u]
            last = cu - 1 if complete[u] else cu
            rest = total
            for x in range(last):
                row = bits[offset[u] + x]
                n = 0
                if sparse:
                    for k in range(used):
                        w = where[k]
                        n += _popcount(joint[js, w] & row[w])
                else:
                    for w in range(width):
                        n += _popcount(joint[js, w] & row[w])
                counts[starts[i] + (j * cu + x) * r + s] = n
                rest -= n
            if last < cu:
                counts[starts[i] + (j * cu + last) * r + s] = rest


@njit(cache=True)
def _refresh(v: int, adjacency: np.ndarray, data: Data, kind: int, ess: float,
             allowed: np.ndarray, max_cells: int, gain: np.ndarray, too_big: np.ndarray,
             table: Table) -> Table:
    """Column v of ``gain`` and ``too_big`` for v's parents in ``adjacency``: the families
    the cache lacks, those that add one parent, are counted together, as bit sets of rows when
    that is cheaper (few configurations), else in one pass each over the distinct rows from
    their parent configurations numbered once."""
    rows, weights, card, bits, offset, everyone, complete = data
    n = card.size
    parents = np.nonzero(adjacency[:, v])[0]
    now, table = family_score(data, kind, ess, v, parents, table)
    key = _key(v, parents, table[0].shape[1])
    cells = np.int64(card[v])
    for t in range(parents.size):
        cells *= card[parents[t]]
    q = _configurations_q(card, parents)
    r = int(card[v])
    missing = np.empty(n, np.int64)
    misses = 0
    states = 0
    for u in range(n):
        if u == v:
            continue
        if adjacency[u, v]:
            too_big[u, v] = False
            fewer = np.empty(parents.size - 1, np.int64)
            f = 0
            for t in range(parents.size):
                if parents[t] != u:
                    fewer[f] = parents[t]
                    f += 1
            value, table = family_score(data, kind, ess, v, fewer, table)
            gain[u, v] = value - now
            continue
        big = cells * card[u] > max_cells
        too_big[u, v] = big
        if big or not allowed[u, v]:
            gain[u, v] = -np.inf
            continue
        s = _slot(table[0], table[2], _toggled(key, u))
        if table[2][s]:
            gain[u, v] = table[1][s] - now
        else:
            missing[misses] = u
            states += card[u]
            misses += 1
    if misses == 0:
        return table
    candidates = missing[:misses]
    starts = np.empty(misses, np.int64)
    # bit sets cost a pass over the rows' words per configuration, child state and state of a
    # candidate; a pass over the distinct rows, per candidate (measured: 0.3 ns a word, 2.5 ns
    # a row)
    width = everyone.size
    by_bits = width > 0 and 0.3 * q * r * width * (states + parents.size) < (
        2.5 * rows.shape[1] * misses)
    if by_bits:
        joint, configurations = _joint_bits(bits, offset, everyone, card, v, parents)
    else:
        conf, configurations = _configurations(rows, card, v, parents)
    size = 0
    for i in range(misses):
        starts[i] = size
        size += configurations * card[candidates[i]] * r
    counts = np.zeros(size, np.int64)
    if by_bits:
        _count_bits(joint, r, bits, offset, complete, card, candidates, starts, counts)
    else:
        own = rows[v]
        for i in range(misses):
            u = candidates[i]
            cu = int(card[u])
            column = rows[u]
            base = starts[i]
            for row in range(conf.size):
                x = column[row]
                if conf[row] >= 0 and x >= 0:
                    counts[base + (conf[row] * cu + x) * r + own[row]] += weights[row]
    width_key = table[0].shape[1]
    for i in range(misses):
        u = candidates[i]
        cu = int(card[u])
        block = counts[starts[i]:starts[i] + configurations * cu * r]
        value = _score_counts(block, configurations * cu, r, q * cu, kind, ess)
        table[3][1] += 1
        table = _insert(table, _toggled(key, u), value)
        gain[u, v] = value - now
        if parents.size == 0:
            # the same counts, the other way round: u given v
            other = _key(u, np.array([v], np.int64), width_key)
            if not table[2][_slot(table[0], table[2], other)]:
                flipped = np.empty(cu * r, np.int64)
                for a in range(cu):
                    for b in range(r):
                        flipped[b * cu + a] = block[a * r + b]
                table[3][1] += 1
                table = _insert(table, other, _score_counts(flipped, r, cu, float(r), kind,
                                                            ess))
    return table


@njit(cache=True)
def gains(data: Data, kind: int, ess: float, adjacency: np.ndarray, allowed: np.ndarray,
          max_cells: int, table: Table) -> tuple[np.ndarray, np.ndarray, Table]:
    """``gain[u, v]`` for the DAG ``adjacency`` (adjacency[u, v]: the arc u -> v): the change
    of v's family score when the arc u -> v is added (deleted, when it is there); -inf where
    it may not be added; and where adding it makes too large a family."""
    n = adjacency.shape[0]
    gain = np.zeros((n, n))
    too_big = np.zeros((n, n), np.bool_)
    for v in range(n):
        table = _refresh(v, adjacency, data, kind, ess, allowed, max_cells, gain, too_big,
                         table)
    return gain, too_big, table


# the climb -----------------------------------------------------------------------------------

@njit(cache=True)
def _reach(adjacency: np.ndarray, reach: np.ndarray) -> None:
    """reach[a, b]: a directed path from a to b (of length >= 1), for a DAG: each variable's
    descendants are its children's and the children themselves, children first."""
    n = adjacency.shape[0]
    waiting = np.zeros(n, np.int64)
    for u in range(n):
        for v in range(n):
            if adjacency[u, v]:
                waiting[v] += 1
    order = np.empty(n, np.int64)
    head = 0
    tail = 0
    for v in range(n):
        if waiting[v] == 0:
            order[tail] = v
            tail += 1
    while head < tail:
        u = order[head]
        head += 1
        for v in range(n):
            if adjacency[u, v]:
                waiting[v] -= 1
                if waiting[v] == 0:
                    order[tail] = v
                    tail += 1
    reach[:, :] = False
    for t in range(n - 1, -1, -1):
        u = order[t]
        for c in range(n):
            if adjacency[u, c]:
                reach[u, c] = True
                for w in range(n):
                    if reach[c, w]:
                        reach[u, w] = True


@njit(cache=True)
def _other_path(adjacency: np.ndarray, reach: np.ndarray, u: int, v: int) -> bool:
    """A path from u to v besides the arc u -> v: reversing that arc would close a cycle."""
    for w in range(adjacency.shape[0]):
        if w != v and adjacency[u, w] and reach[w, v]:
            return True
    return False


@njit(cache=True)
def climb(data: Data, kind: int, ess: float, adjacency: np.ndarray, allowed: np.ndarray,
          required: np.ndarray, limit: int, tabu_length: int, max_iter: int, epsilon: float,
          patience: int, ties: np.ndarray, max_cells: int,
          table: Table) -> tuple[np.ndarray, float, int, Table]:
    """Climb from the DAG ``adjacency`` (changed in place) as
    :func:`bayesprog.learning.structure.hill_climb` describes; the best DAG met, its score
    (the sum of its families'), the moves made, and the cache."""
    n = adjacency.shape[0]
    gain, too_big, table = gains(data, kind, ess, adjacency, allowed, max_cells, table)
    current = 0.0
    for v in range(n):
        value, table = family_score(data, kind, ess, v, np.nonzero(adjacency[:, v])[0], table)
        current += value
    count = np.zeros(n, np.int64)  # parents of each variable
    for v in range(n):
        for u in range(n):
            if adjacency[u, v]:
                count[v] += 1
    best = adjacency.copy()
    best_score = current
    stalled = 0
    # the tabu list: the last ``tabu_length`` operations' inverses (0 add, 1 delete, 2 reverse
    # u -> v), in a ring, and how many times each is in it
    ring = np.zeros((max(tabu_length, 1), 3), np.int64)
    start = 0
    size = 0
    tabu = np.zeros((3, n, n), np.int64)
    reach = np.zeros((n, n), np.bool_)
    iterations = 0
    while iterations < max_iter:
        _reach(adjacency, reach)
        top = -np.inf
        chosen = -1
        bu = -1
        bv = -1
        delta = -np.inf
        for u in range(n):  # additions
            for v in range(n):
                if (u == v or adjacency[u, v] or adjacency[v, u] or reach[v, u]
                        or not allowed[u, v] or count[v] >= limit or too_big[u, v]
                        or tabu[0, u, v] > 0):
                    continue
                value = gain[u, v]
                rank = value + ties[u, v]
                if rank > top:
                    top, chosen, bu, bv, delta = rank, 0, u, v, value
        for u in range(n):  # deletions
            for v in range(n):
                if not adjacency[u, v] or required[u, v] or tabu[1, u, v] > 0:
                    continue
                value = gain[u, v]
                rank = value + ties[u, v]
                if rank > top:
                    top, chosen, bu, bv, delta = rank, 1, u, v, value
        for u in range(n):  # reversals of u -> v: no other path from u to v
            for v in range(n):
                if (not adjacency[u, v] or required[u, v] or not allowed[v, u]
                        or count[u] >= limit or too_big[v, u] or tabu[2, u, v] > 0):
                    continue
                if _other_path(adjacency, reach, u, v):
                    continue
                value = gain[u, v] + gain[v, u]
                rank = value + ties[u, v]
                if rank > top:
                    top, chosen, bu, bv, delta = rank, 2, u, v, value
        if chosen < 0 or not np.isfinite(delta) or (delta < epsilon and stalled >= patience):
            break
        if chosen == 0:
            adjacency[bu, bv] = True
            count[bv] += 1
            op, tu, tv = 1, bu, bv
        elif chosen == 1:
            adjacency[bu, bv] = False
            count[bv] -= 1
            op, tu, tv = 0, bu, bv
        else:
            adjacency[bu, bv] = False
            adjacency[bv, bu] = True
            count[bv] -= 1
            count[bu] += 1
            op, tu, tv = 2, bv, bu
        table = _refresh(bv, adjacency, data, kind, ess, allowed, max_cells, gain, too_big,
                         table)
        if chosen == 2:
            table = _refresh(bu, adjacency, data, kind, ess, allowed, max_cells, gain, too_big,
                             table)
        if tabu_length > 0:
            at = (start + size) % tabu_length
            if size == tabu_length:  # the oldest leaves
                tabu[ring[start, 0], ring[start, 1], ring[start, 2]] -= 1
                start = (start + 1) % tabu_length
                at = (start + size - 1) % tabu_length
            else:
                size += 1
            ring[at, 0], ring[at, 1], ring[at, 2] = op, tu, tv
            tabu[op, tu, tv] += 1
        iterations += 1
        current += delta
        if current > best_score + epsilon:
            best[:, :] = adjacency
            best_score = current
            stalled = 0
        else:
            stalled += 1
    total = 0.0
    for v in range(n):
        value, table = family_score(data, kind, ess, v, np.nonzero(best[:, v])[0], table)
        total += value
    return best, total, iterations, table


@njit(cache=True)
def legal_moves(adjacency: np.ndarray, allowed: np.ndarray, required: np.ndarray, limit: int,
                card: np.ndarray, max_cells: int) -> np.ndarray:
    """Every legal operation on the DAG ``adjacency`` as (0 add, 1 delete, 2 reverse; u, v),
    arc by arc: for an arc u -> v its deletion then its reversal, else the addition."""
    n = adjacency.shape[0]
    reach = np.zeros((n, n), np.bool_)
    _reach(adjacency, reach)
    moves = np.empty((2 * n * n, 3), np.int64)
    count = 0
    for u in range(n):
        for v in range(n):
            if u == v:
                continue
            if adjacency[u, v]:
                if required[u, v]:
                    continue
                moves[count, 0], moves[count, 1], moves[count, 2] = 1, u, v
                count += 1
                parents_u = 0
                cells = np.int64(card[u]) * card[v]
                for w in range(n):
                    if adjacency[w, u]:
                        parents_u += 1
                        cells *= card[w]
                if not allowed[v, u] or parents_u >= limit or cells > max_cells:
                    continue
                if not _other_path(adjacency, reach, u, v):
                    moves[count, 0], moves[count, 1], moves[count, 2] = 2, u, v
                    count += 1
            elif not adjacency[v, u] and allowed[u, v] and not reach[v, u]:
                parents_v = 0
                cells = np.int64(card[v]) * card[u]
                for w in range(n):
                    if adjacency[w, v]:
                        parents_v += 1
                        cells *= card[w]
                if parents_v < limit and cells <= max_cells:
                    moves[count, 0], moves[count, 1], moves[count, 2] = 0, u, v
                    count += 1
    return moves[:count].copy()
