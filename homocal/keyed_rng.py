"""A keyed, counter-based random stream (splitmix64) shared by the readable correctors and the compiled
study kernels, so both shuffle the descent's coordinate order identically for the same (seed, pass).

A numpy Generator cannot be rebuilt cheaply per sample inside a compiled loop over 19 million samples;
a counter-based hash of (seed, pass, draw) can, and gives the same numbers in Python and in numba.
"""
from __future__ import annotations

import hashlib

import numba
import numpy as np

_MASK = (1 << 64) - 1


@numba.njit(cache=True)
def splitmix64(x: np.uint64) -> np.uint64:
    """One splitmix64 output for state x (uint64 arithmetic wraps modulo 2**64)."""
    z = x + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@numba.njit(cache=True)
def shuffled_order(seed: np.uint64, pass_index: np.int64, out: np.ndarray) -> None:
    """Fill out (n,) int64 with a permutation of 0..n-1 drawn from (seed, pass_index) (Fisher-Yates).
    n = 8 (the descent's coordinates) runs shuffled_order8, the one implementation the correctors and the
    study kernels share."""
    if out.shape[0] == 8:
        shuffled_order8(seed, pass_index, out.reshape((1, 8)), 0)
    else:
        fisher_yates(seed, pass_index, out)


@numba.njit(cache=True)
def fisher_yates(seed: np.uint64, pass_index: np.int64, out: np.ndarray) -> None:
    """shuffled_order for any n: for i = n-1..1, swap out[i] with out[splitmix64 draw % (i + 1)]."""
    n = out.shape[0]
    for i in range(n):
        out[i] = i
    state = splitmix64(seed ^ (np.uint64(pass_index) * np.uint64(0xD1B54A32D192ED03)))
    for i in range(n - 1, 0, -1):
        state = splitmix64(state)
        j = np.int64(state % np.uint64(i + 1))
        out[i], out[j] = out[j], out[i]


@numba.njit(cache=True, inline="always")
def shuffled_order8(seed: np.uint64, pass_index: np.int64, out: np.ndarray, r: np.int64) -> None:
    """fisher_yates for n = 8 into row r of out (rows of 8 int64: a row per descent lane in the study
    kernels), unrolled so that every modulo has a constant divisor (the general loop's 64-bit divisions
    were a quarter of the kernels' descent) and inlined where it is called (no array view per call)."""
    for i in range(8):
        out[r, i] = i
    state = splitmix64(seed ^ (np.uint64(pass_index) * np.uint64(0xD1B54A32D192ED03)))
    state = splitmix64(state)
    _swap(out, r, 7, np.int64(state % np.uint64(8)))
    state = splitmix64(state)
    _swap(out, r, 6, np.int64(state % np.uint64(7)))
    state = splitmix64(state)
    _swap(out, r, 5, np.int64(state % np.uint64(6)))
    state = splitmix64(state)
    _swap(out, r, 4, np.int64(state % np.uint64(5)))
    state = splitmix64(state)
    _swap(out, r, 3, np.int64(state % np.uint64(4)))
    state = splitmix64(state)
    _swap(out, r, 2, np.int64(state % np.uint64(3)))
    state = splitmix64(state)
    _swap(out, r, 1, np.int64(state % np.uint64(2)))


@numba.njit(cache=True, inline="always")
def _swap(out, r, i, j):
    out[r, i], out[r, j] = out[r, j], out[r, i]


def seed_from_key(*key: int | str) -> int:
    """A uint64 seed from a stable key (run seed, scene, variant, triple...), independent of run order."""
    state = 0
    for part in key:
        if isinstance(part, str):
            part = int.from_bytes(hashlib.blake2b(part.encode(), digest_size=8).digest(), "little")
        value = int(part)
        state = int(splitmix64(np.uint64((state ^ (value & _MASK)) & _MASK)))
    return state
