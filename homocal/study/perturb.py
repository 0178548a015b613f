"""Trapezoid variants of the study (paper Section 5.2): the clicked base trapezoid and its perturbations.

A variant's image trapezoid is built in three steps, each seeded by (run seed, scene, variant):
  1. the base error of the clicking (the paper's "residual geometric errors", whose size it never gives):
     the hand-placed trapezoid as it is, or moved so that its horizon lies a chosen number of pixels above
     the true one (``tilt_shift``: the vertices move as a change of the camera's tilt moves them), and
     Gaussian click noise on the 8 image coordinates (``draw_base_error``, ``base_trapezoid``);
  2. the paper's perturbation: 2 to 16 of the 16 coordinates moved by 0-3 px (``draw_variant``; how the
     0-3 px are drawn is a reading of the paper's sentence, ``PERTURBATIONS``).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from homocal.geometry import ViewTransformer
from homocal.geometry.camera import tilt_homography
from homocal.keyed_rng import seed_from_key

N_COORDS = 16  # 8 image coordinates (TL.u, TL.v, ..., BL.v), then 8 site-map coordinates
MAX_PIXELS = 3
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@dataclass(frozen=True)
class ShiftSpec:
    """A horizon-shift SPEC: a number of pixels (kind "fixed", a = the shift), or a per-variant distribution
    "normal" (a = mean, b = standard deviation) or "uniform" (on [a, b]). Positive: the clicked trapezoid's
    horizon lies above the true one, so the mapping underestimates range."""

    kind: str
    a: float
    b: float = 0.0

    @classmethod
    def parse(cls, text: str) -> "ShiftSpec":
        """'8', '-2.5', 'normal:MU:SIGMA' or 'uniform:A:B'; a ValueError saying what is expected otherwise."""
        text = str(text).strip()
        usage = "expected a number of pixels, normal:MU:SIGMA or uniform:A:B"
        if re.fullmatch(_NUMBER, text):
            spec = cls("fixed", float(text))
        elif m := re.fullmatch(rf"(normal|uniform):({_NUMBER}):({_NUMBER})", text):
            spec = cls(m.group(1), float(m.group(2)), float(m.group(3)))
        else:
            raise ValueError(usage)
        if not (math.isfinite(spec.a) and math.isfinite(spec.b) and abs(spec.a) <= 100 and abs(spec.b) <= 100):
            raise ValueError("expected finite values of at most 100 px")
        if spec.kind == "normal" and spec.b < 0:
            raise ValueError("expected a standard deviation >= 0")
        if spec.kind == "uniform" and spec.b < spec.a:
            raise ValueError("expected A <= B in uniform:A:B")
        return spec

    def __str__(self) -> str:
        return f"{self.a:g}" if self.kind == "fixed" else f"{self.kind}:{self.a:g}:{self.b:g}"


def draw_base_error(seed: int, scene: str, variant: int, shift: ShiftSpec | None, click_noise: float) -> tuple[float | None, np.ndarray]:
    """(horizon shift (px; None without a spec), click noise (8,) px) of one variant's clicked base trapezoid,
    drawn from np.random.default_rng(seed_from_key(seed, scene, variant, "base")): the shift from the spec,
    then 8 independent N(0, click_noise^2) offsets of the image coordinates. Every variant, the 0th too, has
    its own."""
    rng = np.random.default_rng(seed_from_key(seed, scene, variant, "base"))
    if shift is None:
        eps = None
    elif shift.kind == "normal":
        eps = float(rng.normal(shift.a, shift.b))
    elif shift.kind == "uniform":
        eps = float(rng.uniform(shift.a, shift.b))
    else:
        eps = shift.a
    return eps, rng.normal(0.0, 1.0, 8) * click_noise


def tilt_shift(image: np.ndarray, K: np.ndarray, horizon_row: float, shift_px: float) -> np.ndarray:
    """The image quad (4, 2) px moved as a change of the camera's tilt would move it, so that the horizon row
    at the principal column, horizon_row (px), rises by shift_px (positive: up, the mapping then
    underestimates range).

    The horizon lies at elevation alpha = atan((cy - v_h) / f) above the optical axis; raising it to
    v_h - shift_px needs alpha' = atan(tan(alpha) + shift_px / f), a rotation of every viewing ray by
    delta = alpha' - alpha about the camera's x-axis: the image homography G = K R_x(delta) K^-1 (OpenCV
    camera frame, y down), applied to the vertices. G maps column cx onto itself, so the new horizon at cx
    is exactly horizon_row - shift_px. K (3, 3) intrinsics with fx = fy.
    """
    f, cy = K[1, 1], K[1, 2]
    alpha = math.atan((cy - horizon_row) / f)
    G = tilt_homography(K, math.atan(math.tan(alpha) + shift_px / f) - alpha)
    moved = np.column_stack([image, np.ones(len(image))]) @ G.T
    return moved[:, :2] / moved[:, 2:]


def base_quad(image: np.ndarray, K: np.ndarray, horizon_row: float, true_row: float, shift_px: float | None,
              noise: np.ndarray) -> np.ndarray:
    """The clicked base image quad (4, 2) px: the hand-placed image quad (4, 2), whose mapping's horizon is at
    horizon_row (px, principal column), moved by tilt_shift so that its horizon lies shift_px above the true
    horizon true_row (left as it is when shift_px is None, the default), plus click noise (8,) px."""
    moved = image if shift_px is None else tilt_shift(image, K, horizon_row, horizon_row - true_row + shift_px)
    return moved + noise.reshape(4, 2)


def base_trapezoid(image: np.ndarray, target: np.ndarray, K: np.ndarray, true_row: float, shift_px: float | None,
                   noise: np.ndarray) -> np.ndarray:
    """The clicked base image quad (4, 2) px of a variant (base_quad), from the hand-placed image quad (4, 2) px and
    its map quad target (4, 2) m, whose mapping gives the horizon row (at the principal column K[0, 2]): the one
    function the study's engine and its figures build it with."""
    horizon_row = math.nan if shift_px is None else float(ViewTransformer(image, target).horizon_row(K[0, 2]))
    return base_quad(image, K, horizon_row, true_row, shift_px, noise)


PERTURBATIONS = ("coordinate", "variant", "variant-positive")  # readings of the paper's perturbation (draw_variant)


def check_reading(reading: str) -> str:
    """reading if it is one of PERTURBATIONS; else a ValueError naming the parameter reading."""
    if reading not in PERTURBATIONS:
        raise ValueError(f"reading {reading!r}: expected one of {', '.join(PERTURBATIONS)}")
    return reading


def draw_variant(seed: int, scene: str, variant: int, reading: str = "coordinate") -> tuple[np.ndarray, int]:
    """(offsets (16,) float64 px, n_perturbed) of one variant: no offsets for variant 0 (the hand-placed
    trapezoid); otherwise a random subset of n_perturbed = 2..16 of the 16 coordinates, drawn from
    np.random.default_rng(seed_from_key(seed, scene, variant)), moved as the paper's "a random perturbation of
    0, 1, 2, or 3 pixels was applied to a randomly selected subset of 2 to 16 coordinate values" reads:
      "coordinate": each chosen coordinate by its own 0, 1, 2 or 3 px with its own random sign (the default);
      "variant": every chosen coordinate by the variant's one 0, 1, 2 or 3 px, each with its own random sign;
      "variant-positive": every chosen coordinate by + the variant's one 0, 1, 2 or 3 px.
    """
    check_reading(reading)
    offsets = np.zeros(N_COORDS)
    if variant == 0:
        return offsets, 0
    rng = np.random.default_rng(seed_from_key(seed, scene, variant))
    n = int(rng.integers(2, N_COORDS + 1))
    chosen = rng.choice(N_COORDS, size=n, replace=False)
    size = rng.integers(0, MAX_PIXELS + 1, size=1 if reading != "coordinate" else n)
    offsets[chosen] = size * (1.0 if reading == "variant-positive" else rng.choice([-1.0, 1.0], size=n))
    return offsets, n


def perturbed_quads(image: np.ndarray, site_map: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The variant's (image (4, 2) px, map (4, 2) map px) quads from the base ones and (16,) offsets."""
    return image + offsets[:8].reshape(4, 2), site_map + offsets[8:].reshape(4, 2)
