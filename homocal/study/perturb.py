"""Trapezoid variants of the study (paper Section 5.2): the hand-placed trapezoid and its perturbations."""
from __future__ import annotations

import numpy as np

from homocal.keyed_rng import seed_from_key

N_COORDS = 16  # 8 image coordinates (TL.u, TL.v, ..., BL.v), then 8 site-map coordinates
MAX_PIXELS = 3


def draw_variant(seed: int, scene: str, variant: int) -> tuple[np.ndarray, int]:
    """(offsets (16,) float64 px, n_perturbed) of one variant: no offsets for variant 0 (the hand-placed
    trapezoid); otherwise a random subset of n_perturbed = 2..16 of the 16 coordinates, each moved by 0, 1, 2
    or 3 px with a random sign, drawn from np.random.default_rng(seed_from_key(seed, scene, variant))."""
    offsets = np.zeros(N_COORDS)
    if variant == 0:
        return offsets, 0
    rng = np.random.default_rng(seed_from_key(seed, scene, variant))
    n = int(rng.integers(2, N_COORDS + 1))
    chosen = rng.choice(N_COORDS, size=n, replace=False)
    offsets[chosen] = rng.integers(0, MAX_PIXELS + 1, size=n) * rng.choice([-1.0, 1.0], size=n)
    return offsets, n


def perturbed_quads(image: np.ndarray, site_map: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The variant's (image (4, 2) px, map (4, 2) map px) quads from the hand-placed ones and (16,) offsets."""
    return image + offsets[:8].reshape(4, 2), site_map + offsets[8:].reshape(4, 2)
