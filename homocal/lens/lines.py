"""The lens from lines that are straight in the world (the plumb-line method, Devernay and Faugeras 2001,
"Straight lines have to be straight"): the distortion coefficients that make every clicked polyline straight.

LINES.json (``homocal lens --lines``; the page's line tool writes it)::

    {"image_size": [W, H], "lines": [[[u, v], ...], ...]}     pixels of the distorted frame, 3 or more per line

The model is OpenCV's (``homocal.geometry.lens.Lens``): distortion ``[k1, k2, p1, p2, k3]`` in normalised
coordinates around the principal point, taken at the image centre. Straightness fixes the distortion in pixels
(``k1 / f^2``, ``k2 / f^4``, ...), not the focal length: ``f`` comes from the field of view the caller gives
(``intrinsics``), and the undistorted pixels do not depend on it; the coefficients scale with it.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from homocal.files import read_json
from homocal.geometry.lens import MAX_IMAGE_SIDE, Lens

MAX_LINES_BYTES = 16 * 2**20  # LINES.json: 16 MiB (about 400,000 clicked points)
MAX_LINES = 10_000  # polylines in one fit
MAX_POINTS = 200_000  # points over all lines
MIN_POINTS_PER_LINE = 3  # two points are always on a straight line: they say nothing of the distortion
DEFAULT_HFOV_DEG = 95.0  # the focal length when none is given: a wide CCTV lens (the card's camera)
TERMS = {"k1": (0,), "k1,k2": (0, 1), "k1,k2,k3": (0, 1, 4), "k1,k2,p1,p2": (0, 1, 2, 3)}  # fitted -> index in [k1, k2, p1, p2, k3]
DEFAULT_TERMS = "k1,k2"
FOLDED_RESIDUAL_PX = 1e3  # each point's residual while the coefficients fold the frame before it
FD_STEP_PX = 1e-3  # central differences of the lens's derivative: error ~ step^2 * the map's 3rd derivative, far below 1e-6
MIN_CENTRE_DISTANCE = 0.05  # of the half diagonal: a line nearer the image centre than this stays straight under any radial distortion


@dataclass(frozen=True)
class LensFit:
    """A fitted lens and how straight it makes the lines.

    lens: the Lens (K (3, 3), distortion (5,), image size). terms: the fitted coefficients ("k1,k2").
    sigma: (5,) 1-sigma of each coefficient from the fit's Jacobian (0 for those not fitted).
    rms_before_px, rms_after_px: RMS distance of the points from their lines' best straight fit, frame pixels,
    with no distortion and with the fitted one. lines, points: how many were used.
    corner_displacement_px: how far the lens moves the frame's corner (0, 0), ||undistort - corner||, pixels.
    """

    lens: Lens
    terms: str
    sigma: np.ndarray
    rms_before_px: float
    rms_after_px: float
    lines: int
    points: int
    corner_displacement_px: float

    def to_json(self) -> dict:
        """lens.json: K, distortion, image_size (what --camera-json reads) and the fit's diagnostics."""
        return {**self.lens.to_dict(),
                "fit": {"method": "plumb-line", "terms": self.terms, "sigma": [float(s) for s in self.sigma],
                        "lines": self.lines, "points": self.points, "rms_before_px": self.rms_before_px,
                        "rms_after_px": self.rms_after_px, "corner_displacement_px": self.corner_displacement_px}}


def intrinsics(image_size: tuple[int, int], hfov_deg: float | None = None, focal_px: float | None = None) -> np.ndarray:
    """(3, 3) K: focal length ``focal_px``, else (W / 2) / tan(hfov / 2) (default DEFAULT_HFOV_DEG); principal point
    at the image centre (W/2 - 0.5, H/2 - 0.5), pixel centres at integers."""
    w, h = image_size
    f = focal_px if focal_px is not None else (w / 2.0) / math.tan(math.radians(hfov_deg or DEFAULT_HFOV_DEG) / 2.0)
    return np.array([[f, 0.0, w / 2.0 - 0.5], [0.0, f, h / 2.0 - 0.5], [0.0, 0.0, 1.0]])


def read_lines_file(path: str | Path) -> tuple[tuple[int, int], list[np.ndarray]]:
    """LINES.json -> ((W, H), [(N_i, 2) float64 pixels]); ValueError naming the file and the problem (too large,
    not JSON, a missing key, a line of fewer than 3 points, a non-finite or out-of-frame point)."""
    path = Path(path)
    if path.is_file() and os.path.getsize(path) > MAX_LINES_BYTES:
        raise ValueError(f"{path}: larger than {MAX_LINES_BYTES // 2**20} MiB (the most a lines file may be)")
    data = read_json(path)
    try:
        size, lines = data["image_size"], data["lines"]
    except KeyError as e:
        raise ValueError(f"{path}: missing key {e} (expected \"image_size\" and \"lines\")") from None
    try:
        return check_lines(size, lines)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


def check_lines(image_size, lines) -> tuple[tuple[int, int], list[np.ndarray]]:
    """Validate an image size [W, H] and polylines [[[u, v], ...], ...] (bounds above); ValueError otherwise."""
    if (not isinstance(image_size, list) or len(image_size) != 2
            or not all(isinstance(s, int) and not isinstance(s, bool) and 1 <= s <= MAX_IMAGE_SIDE for s in image_size)):
        raise ValueError(f"image_size must be two integers [W, H] in [1, {MAX_IMAGE_SIDE}], got {image_size!r}")
    if not isinstance(lines, list) or not lines:
        raise ValueError("lines must be a non-empty list of polylines [[u, v], ...]")
    if len(lines) > MAX_LINES:
        raise ValueError(f"{len(lines):,} lines, more than {MAX_LINES:,} (the most one fit takes)")
    if sum(len(line) if isinstance(line, list) else 0 for line in lines) > MAX_POINTS:
        raise ValueError(f"more than {MAX_POINTS:,} points over all lines (the most one fit takes)")
    w, h = image_size
    out = []
    for i, line in enumerate(lines):
        try:
            pts = np.array(line, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"line {i}: expected a list of [u, v] pairs of numbers") from None
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise ValueError(f"line {i}: expected a list of [u, v] pairs of numbers")
        if len(pts) < MIN_POINTS_PER_LINE:
            raise ValueError(f"line {i}: {len(pts)} points; a line needs at least {MIN_POINTS_PER_LINE} "
                             "(two points are straight under any distortion)")
        if not np.isfinite(pts).all():
            raise ValueError(f"line {i}: a point is not a finite number (NaN or infinity)")
        if (pts < -0.5).any() or (pts[:, 0] > w - 0.5).any() or (pts[:, 1] > h - 0.5).any():
            raise ValueError(f"line {i}: a point lies outside the {w}x{h} frame")
        out.append(pts)
    return (w, h), out


def line_residuals(points: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each point's signed distance (N,) from the total-least-squares line of its polyline (rows ``starts[i]`` to
    ``starts[i + 1]``), and that line's unit normal (N, 2)."""
    distance, normal = np.empty(len(points)), np.empty((len(points), 2))
    for a, b in zip(starts[:-1], starts[1:]):
        p = points[a:b] - points[a:b].mean(axis=0)
        normal[a:b] = np.linalg.svd(p, full_matrices=False)[2][1]  # the direction of least spread
        distance[a:b] = p @ normal[a]
    return distance, normal


def _in_frame_pixels(lens: Lens, undistorted: np.ndarray, distance: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Distances (N,) of undistorted points from their lines, along ``normal`` (N, 2), as distances in the distorted
    frame (to first order): distance / |J^-T normal|, J (N, 2, 2) the lens's derivative at each point (central
    differences of ``distort_points``, FD_STEP_PX)."""
    columns = [(lens.distort_points(undistorted + step) - lens.distort_points(undistorted - step)) / (2 * FD_STEP_PX)
               for step in (np.array([FD_STEP_PX, 0.0]), np.array([0.0, FD_STEP_PX]))]
    jacobian_t = np.stack(columns, axis=1)  # rows: d(distorted)/du, d(distorted)/dv: J transposed
    return distance / np.linalg.norm(np.linalg.solve(jacobian_t, normal[..., None])[..., 0], axis=1)


def fit_lines(image_size: tuple[int, int], lines: list[np.ndarray], K: np.ndarray, terms: str = DEFAULT_TERMS) -> LensFit:
    """Fit the distortion ``terms`` (a key of TERMS) that makes each polyline straight.

    Args:
        image_size: (W, H) pixels. lines: [(N_i, 2)] distorted pixels, as ``check_lines`` returns them.
        K: (3, 3) intrinsics (``intrinsics``). terms: which of [k1, k2, p1, p2, k3] are fitted; the rest stay 0.
    Returns:
        LensFit. Residual of a point: its distance from its undistorted polyline's best straight line, measured in
        the distorted frame (``_in_frame_pixels``), where the clicks' errors are: so the fit weighs each click
        alike wherever the lens stretches the image, and shrinking the image cannot make lines straighter.
    Raises:
        ValueError: every line passes within MIN_CENTRE_DISTANCE of the half diagonal of the image centre (radial
        distortion leaves such lines straight), or fewer residuals than coefficients.
    """
    index = TERMS[terms]
    points = np.concatenate(lines)
    starts = np.concatenate([[0], np.cumsum([len(line) for line in lines])])
    centre, half_diagonal = K[:2, 2], 0.5 * math.hypot(*image_size)
    distances = [abs((line.mean(axis=0) - centre) @ np.linalg.svd(line - line.mean(axis=0))[2][1]) for line in lines]
    if max(distances) < MIN_CENTRE_DISTANCE * half_diagonal:
        raise ValueError(f"every line passes within {MIN_CENTRE_DISTANCE * half_diagonal:.0f} px of the image centre: "
                         "lines through the centre stay straight under any radial distortion (click lines away from it)")
    if len(points) - 2 * len(lines) <= len(index):
        raise ValueError(f"{len(points)} points on {len(lines)} lines fix no more than {len(points) - 2 * len(lines)} "
                         f"coefficients; {terms} needs more")

    def lens_of(x: np.ndarray) -> Lens:
        distortion = np.zeros(5)
        distortion[list(index)] = x
        return Lens(K, distortion, image_size)

    def residuals(x: np.ndarray) -> np.ndarray:
        lens = lens_of(x)
        undistorted = lens.undistort_points(points)
        if not np.isfinite(undistorted).all():  # a point beyond the fold: coefficients far from any answer
            return np.full(len(points), FOLDED_RESIDUAL_PX)
        return _in_frame_pixels(lens, undistorted, *line_residuals(undistorted, starts))

    before = residuals(np.zeros(len(index)))
    result = least_squares(residuals, np.zeros(len(index)), x_scale=0.1, method="lm")
    lens = lens_of(result.x)
    try:
        lens.check_folds()
    except ValueError as e:
        raise ValueError(f"the fitted {e} (fit fewer terms, or click lines nearer the frame's edges)") from None
    dof = len(points) - 2 * len(lines) - len(index)
    s2 = 2 * result.cost / dof
    sigma = np.zeros(5)
    sigma[list(index)] = np.sqrt(np.diag(np.linalg.pinv(result.jac.T @ result.jac)) * s2)
    corner = np.zeros((1, 2))
    return LensFit(lens=lens, terms=terms, sigma=sigma, rms_before_px=float(np.sqrt(np.mean(before**2))),
                   rms_after_px=float(np.sqrt(np.mean(result.fun**2))), lines=len(lines), points=len(points),
                   corner_displacement_px=float(np.linalg.norm(lens.undistort_points(corner) - corner)))
