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
    """Fill out (n,) int64 with a permutation of 0..n-1 drawn from (seed, pass_index) (Fisher-Yates)."""
    n = out.shape[0]
    for i in range(n):
        out[i] = i
    state = splitmix64(seed ^ (np.uint64(pass_index) * np.uint64(0xD1B54A32D192ED03)))
    for i in range(n - 1, 0, -1):
        state = splitmix64(state)
        j = np.int64(state % np.uint64(i + 1))
        out[i], out[j] = out[j], out[i]


def seed_from_key(*key: int | str) -> int:
    """A uint64 seed from a stable key (run seed, scene, variant, triple...), independent of run order."""
    state = 0
    for part in key:
        if isinstance(part, str):
            part = int.from_bytes(hashlib.blake2b(part.encode(), digest_size=8).digest(), "little")
        value = int(part)
        state = int(splitmix64(np.uint64((state ^ (value & _MASK)) & _MASK)))
    return state
