"""A keyed, counter-based random stream (splitmix64) shared by the readable correctors and the compiled
study kernels, so both visit the descent's coordinates in the same order for the same (seed, pass).

A numpy Generator cannot be rebuilt cheaply per sample inside a compiled loop over 19 million samples;
a counter-based hash of (seed, pass) can, and gives the same numbers in Python and in numba.

The order of pass p is permutation number floor(z 8! / 2^64) of 0..7 in lexicographic order, for the one
draw z = splitmix64(seed ^ p 0xD1B54A32D192ED03) (multiply-shift range reduction; its bias, 8!/2^64 < 3e-15,
is immaterial), read from a table of the 8! orders. The study draws about 25 orders per sample for 19
million samples; a Fisher-Yates shuffle's seven chained draws made its kernels 7-9 % slower than this one
draw and a lookup.
"""
from __future__ import annotations

import hashlib
import itertools
import math

import numba
import numpy as np

_MASK = (1 << 64) - 1
N_COORDINATES = 8
N_ORDERS = math.factorial(N_COORDINATES)
_PASS_MULTIPLIER = 0xD1B54A32D192ED03
# ORDERS[i] = the i-th permutation of 0..7 in lexicographic order, packed 4 bits a position (bits 4c..4c+3:
# the coordinate visited c-th); every entry < 2**31
ORDERS = (np.array(list(itertools.permutations(range(N_COORDINATES))), np.int64)
          << (4 * np.arange(N_COORDINATES))).sum(axis=1).astype(np.int32)


@numba.njit(cache=True)
def splitmix64(x: np.uint64) -> np.uint64:
    """One splitmix64 output for state x (uint64 arithmetic wraps modulo 2**64)."""
    z = x + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@numba.njit(cache=True, inline="always")
def order_index(seed: np.uint64, pass_index: np.int64) -> np.int64:
    """floor(z 8! / 2^64) for z = splitmix64(seed ^ pass_index 0xD1B54A32D192ED03): in [0, 8!)."""
    z = splitmix64(seed ^ (np.uint64(pass_index) * np.uint64(_PASS_MULTIPLIER)))
    m = np.uint64(N_ORDERS)  # < 2**16, so both partial products fit in 64 bits
    low = ((z & np.uint64(0xFFFFFFFF)) * m) >> np.uint64(32)
    return np.int64(((z >> np.uint64(32)) * m + low) >> np.uint64(32))


@numba.njit(cache=True, inline="always")
def packed_order(seed: np.uint64, pass_index: np.int64) -> np.int64:
    """The order of (seed, pass_index), packed 4 bits a position (the compiled kernels' form)."""
    return np.int64(ORDERS[order_index(seed, pass_index)])


@numba.njit(cache=True)
def shuffled_order(seed: np.uint64, pass_index: np.int64, out: np.ndarray) -> None:
    """Fill out (8,) int64 with the order of (seed, pass_index): a permutation of the coordinates 0..7."""
    if out.shape[0] != N_COORDINATES:
        raise ValueError("shuffled_order orders the 8 coordinates of a trapezoid: out must have shape (8,)")
    order = packed_order(seed, pass_index)
    for c in range(N_COORDINATES):
        out[c] = (order >> (4 * c)) & 15


def seed_from_key(*key: int | str) -> int:
    """A uint64 seed from a stable key (run seed, scene, variant, triple...), independent of run order."""
    state = 0
    for part in key:
        if isinstance(part, str):
            part = int.from_bytes(hashlib.blake2b(part.encode(), digest_size=8).digest(), "little")
        value = int(part)
        state = int(splitmix64(np.uint64((state ^ (value & _MASK)) & _MASK)))
    return state
