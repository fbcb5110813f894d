"""The log densities of a pointwise term kept by value: a field read from a table (a cue that
depends on the distance to the last probed cell takes a thousand values over a hundred runs and
a hundred steps) has each of its values' densities computed once.

A :class:`Memo` is a hash table from a value's bits (a float64 seen as a uint64: NaN, -0.0 and
0.0 are values of their own) to the term's log densities at that value (one per configuration
of the term's other axes), filled with what the form computed (numpy's arithmetic, the same as
for a whole field): a value found in it gives the same numbers to the bit. Open addressing with
linear probing, in compiled loops (numba); the table grows as it fills and is emptied past its
largest size, and a term whose values are seldom found again stops using it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np
from numba import njit

#: Entries of a memo's table at most (a power of two; 17 bytes and more per entry), and at
#: first.
CAPACITY, SMALLEST = 1 << 18, 1 << 12
#: A table holds at most this share of its capacity (more, and its probes grow long).
LOAD = 8
#: A term stops using its memo after this many questions in a row found fewer than half of its
#: values in it (a field of values that do not repeat).
MISSES = 3
#: Fibonacci hashing: the multiplier (2^64 / golden ratio, odd).
_MULTIPLIER = np.uint64(0x9E3779B97F4A7C15)


@njit(cache=True)
def _find(keys: np.ndarray, filled: np.ndarray, values: np.ndarray, bits: np.ndarray,
          shift: np.uint64, out: np.ndarray) -> np.ndarray:
    """Each key of ``bits`` looked up: its values copied to ``out`` (rows), and the indices of
    the keys not found."""
    mask = np.uint64(keys.size - 1)
    one = np.uint64(1)
    width = values.shape[1]
    missing = np.empty(bits.size, np.int64)
    count = 0
    for i in range(bits.size):
        key = bits[i]
        slot = (key * _MULTIPLIER) >> shift
        while True:
            if not filled[slot]:
                missing[count] = i
                count += 1
                break
            if keys[slot] == key:
                for j in range(width):
                    out[i, j] = values[slot, j]
                break
            slot = (slot + one) & mask
    return missing[:count]


@njit(cache=True)
def _add(keys: np.ndarray, filled: np.ndarray, values: np.ndarray, bits: np.ndarray,
         rows: np.ndarray, shift: np.uint64) -> None:
    """Keys ``bits`` (each absent, and once) with their values ``rows`` put in the table."""
    mask = np.uint64(keys.size - 1)
    one = np.uint64(1)
    for i in range(bits.size):
        key = bits[i]
        slot = (key * _MULTIPLIER) >> shift
        while filled[slot]:
            slot = (slot + one) & mask
        keys[slot] = key
        filled[slot] = True
        for j in range(values.shape[1]):
            values[slot, j] = rows[i, j]


class Memo:
    """A term's log densities by value (see the module); ``width``: how many per value. The
    table starts small (a field of a thousand values stays in the processor's caches) and
    doubles as it fills, up to ``CAPACITY`` entries. Threads that share a program look it up
    one at a time (the table is read and grown by several steps)."""

    def __init__(self, width: int, capacity: int = SMALLEST) -> None:
        self.width = width
        self._lock = threading.Lock()
        self._allocate(capacity)
        #: questions in a row that found fewer than half of their values
        self.missed = 0

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k != "_lock"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()

    def _allocate(self, capacity: int) -> None:
        self.keys = np.zeros(capacity, np.uint64)
        self.filled = np.zeros(capacity, np.bool_)
        self.values = np.zeros((capacity, self.width))
        self.shift = np.uint64(64 - capacity.bit_length() + 1)
        self.count = 0

    @property
    def useful(self) -> bool:
        return self.missed < MISSES

    def lookup(self, values: np.ndarray,
               compute: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """The log densities at ``values`` (float64, ``[n]``): ``[n, width]``, those of the
        values not yet in the table computed by ``compute`` (their log densities
        ``[unique values, width]``), once per distinct value, and kept."""
        bits = np.ascontiguousarray(values, dtype=np.float64).view(np.uint64)
        out = np.empty((bits.size, self.width))
        with self._lock:
            missing = _find(self.keys, self.filled, self.values, bits, self.shift, out)
            self.missed = self.missed + 1 if 2 * missing.size > bits.size else 0
            if missing.size:
                new, where = np.unique(bits[missing], return_inverse=True)
                rows = np.ascontiguousarray(compute(new.view(np.float64)), dtype=np.float64)
                out[missing] = rows[where.reshape(-1)]
                self._keep(new, rows)
        return out

    def _keep(self, bits: np.ndarray, rows: np.ndarray) -> None:
        """Keys ``bits`` (absent, distinct) and their values put in the table: a larger one
        when it would hold more than ``1 / LOAD`` of its capacity (an empty one past
        ``CAPACITY``)."""
        capacity = self.keys.size
        while LOAD * (self.count + bits.size) > capacity and capacity < CAPACITY:
            capacity *= 2
        if capacity != self.keys.size:
            kept = self.filled
            old_keys, old_values = self.keys[kept], self.values[kept]
            self._allocate(capacity)
            _add(self.keys, self.filled, self.values, old_keys, old_values, self.shift)
            self.count = old_keys.size
        if LOAD * (self.count + bits.size) > capacity:  # full: start again
            self._allocate(capacity)
        if LOAD * bits.size <= capacity:
            _add(self.keys, self.filled, self.values, bits, rows, self.shift)
            self.count += bits.size
