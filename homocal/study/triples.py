"""Calibration triples: every combination of three calibration points (blind protocol, paper Section 5.2)."""
from __future__ import annotations

import itertools
import math

import numpy as np


def triples(m: int) -> np.ndarray:
    """(C(m, 3), 3) int16 indices (i, j, k), i < j < k, in itertools.combinations order."""
    if m < 3:
        raise ValueError(f"need at least 3 calibration points, got {m}")
    return np.array(list(itertools.combinations(range(m), 3)), dtype=np.int16).reshape(-1, 3)


def n_samples(m: int, n_variants: int) -> int:
    """Samples of one scene: (n_variants + 1) trapezoids (the hand-placed one too) x C(m, 3) triples."""
    return (n_variants + 1) * math.comb(m, 3)


def distance_features(distance: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(d_sum, d_spread) (S,) float32 metres: sum and max - min of each triple's true distances (M,)."""
    d = distance[idx.astype(np.int64)]
    return d.sum(axis=1).astype(np.float32), (d.max(axis=1) - d.min(axis=1)).astype(np.float32)
