"""What the page draws over the frame and the site map, computed from the library's mappings.

A mapping is any function image points (N, 2) px -> ground points (N, 2) m (a ViewTransformer's
``transform_points`` or a fitted corrector's), so the corrected grid is drawn by the same code as the plain
one: the mapping is sampled on a lattice of image points and its iso-lines (x = k, y = k, distance = r) are
traced with contourpy (matplotlib's contour engine).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import contourpy
import numpy as np

from homocal.geometry import SiteMap, ViewTransformer

Mapping = Callable[[np.ndarray], np.ndarray]

LATTICE_COLUMNS = 200     # image samples across the frame for the iso-lines
MIN_LINE_GAP_PX = 8.0     # a family of grid lines is drawn only where its lines are at least this far apart
HORIZON_MARGIN_PX = 1.0   # image points closer than this to the horizon are left out
RING_STEP_M = 10.0        # range rings every 10 m, like the major grid lines
LENS_STEP_PX = 8.0        # a straight line of the undistorted image is drawn through the lens in steps this long


def horizon_segment(transformer: ViewTransformer, width: int, height: int) -> list[list[float]] | None:
    """The horizon (paper eq. (4)) as two image points at the sides of a box 3x the frame around it, or
    None if it misses that box. Pixels."""
    a, b, c = transformer.horizon
    lo, hi = np.array([-width, -height], float), np.array([2 * width, 2 * height], float)
    if abs(b) >= abs(a):  # mostly horizontal: cut at the left and right sides
        ends = [[u, -(a * u + c) / b] for u in (lo[0], hi[0])]
        inside = any(lo[1] <= v <= hi[1] for _, v in ends)
    else:
        ends = [[-(b * v + c) / a, v] for v in (lo[1], hi[1])]
        inside = any(lo[0] <= u <= hi[0] for u, _ in ends)
    return [[float(u), float(v)] for u, v in ends] if inside else None


@dataclass(frozen=True)
class Field:
    """A mapping sampled on a lattice of image points: us (n_u,), vs (n_v,) px; X, Y (n_v, n_u) ground m (NaN
    above the horizon); metres_per_px (n_v, n_u), the ground length of one image pixel there (the RMS of the
    mapping's 2x2 Jacobian's singular values)."""

    us: np.ndarray
    vs: np.ndarray
    X: np.ndarray
    Y: np.ndarray
    metres_per_px: np.ndarray

    def drawn(self, spacing_m: float) -> np.ndarray:
        """(n_v, n_u) bool: where lines spacing_m apart are at least MIN_LINE_GAP_PX apart in the image."""
        return np.isfinite(self.metres_per_px) & (self.metres_per_px * MIN_LINE_GAP_PX <= spacing_m)


def through_lens(line: list[list[float]] | None, lens) -> list[list[float]] | None:
    """An image polyline of undistorted pixels as the frame shows it: densified to points LENS_STEP_PX apart, those
    inside the lens's fold (radius < max_monotonic_radius: a straight line meets that disc in one run) distorted
    by lens (homocal.geometry.Lens; None: as it is). Curved where the lens bends it; None if nothing is left."""
    if line is None or lens is None:
        return line
    q = np.asarray(line, dtype=np.float64)
    steps = np.maximum(1, np.ceil(np.hypot(*np.diff(q, axis=0).T) / LENS_STEP_PX).astype(int))
    dense = np.vstack([q[i] + np.linspace(0, 1, n, endpoint=False)[:, None] * (q[i + 1] - q[i])
                       for i, n in enumerate(steps)] + [q[-1:]])
    radius = np.hypot(*((dense - lens.K[:2, 2]) / np.diag(lens.K)[:2]).T)
    dense = dense[radius < lens.max_monotonic_radius]
    return _rounded(lens.distort_points(dense)) if len(dense) >= 2 else None


def sample_mapping(mapping: Mapping, transformer: ViewTransformer, width: int, height: int, lens=None) -> Field:
    """The mapping on a lattice of LATTICE_COLUMNS image columns, below the transformer's horizon; with a lens
    (homocal.geometry.Lens) the lattice is the frame's pixels and the mapping and horizon see them undistorted."""
    step = width / LATTICE_COLUMNS
    us = np.arange(-0.5, width - 0.5 + step / 2, step)
    vs = np.arange(-0.5, height - 0.5 + step / 2, step)
    uu, vv = np.meshgrid(us, vs)
    q = np.column_stack([uu.ravel(), vv.ravel()])
    if lens is not None:
        q = lens.undistort_points(q)
        uu, vv = q[:, 0].reshape(uu.shape), q[:, 1].reshape(uu.shape)
    a, b, c = transformer.horizon
    with np.errstate(invalid="ignore"):
        below = a * uu + b * vv + c >= HORIZON_MARGIN_PX
    xy = np.full(q.shape, np.nan)
    xy[below.ravel()] = mapping(q[below.ravel()])
    X, Y = xy[:, 0].reshape(uu.shape), xy[:, 1].reshape(uu.shape)
    Xv, Xu = np.gradient(X, vs, us)
    Yv, Yu = np.gradient(Y, vs, us)
    return Field(us, vs, X, Y, np.sqrt((Xu**2 + Xv**2 + Yu**2 + Yv**2) / 2))


def ground_grid(field: Field, camera_origin: np.ndarray) -> dict:
    """Image polylines of the ground grid of a sampled mapping: {"minor": 1 m lines, "major": 10 m lines,
    "rings": [{"r": metres, "lines": [...]}]} (range rings around camera_origin (2,) m), each line a list of
    [u, v] px. A family is traced only where its lines are >= MIN_LINE_GAP_PX apart in the image."""
    f = field
    out: dict = {"minor": [], "major": [], "rings": []}
    for spacing, key in ((1.0, "minor"), (10.0, "major")):
        keep = f.drawn(spacing)
        for Z in (f.X, f.Y):
            levels = [k for k in _levels(Z[keep], spacing) if key == "major" or k % 10 != 0]
            out[key] += [line for lines in _iso_lines(f.us, f.vs, Z, keep, levels) for line in lines]
    R, keep = np.hypot(f.X - camera_origin[0], f.Y - camera_origin[1]), f.drawn(RING_STEP_M)
    radii = [r for r in _levels(R[keep], RING_STEP_M) if r > 0]
    out["rings"] = [{"r": r, "lines": lines} for r, lines in zip(radii, _iso_lines(f.us, f.vs, R, keep, radii))]
    return out


def grid_nodes(field: Field, transformer: ViewTransformer, spacing_m: float = 10.0, lens=None) -> np.ndarray:
    """Image points (K, 2) px (the transformer's: undistorted with a lens) of the nodes of the spacing_m grid (a
    plain transformer's field) that fall on the lattice (the frame's pixels) where that grid is drawn."""
    f, keep = field, field.drawn(spacing_m)
    if not keep.any():
        return np.zeros((0, 2))
    xs, ys = _levels(f.X[keep], spacing_m), _levels(f.Y[keep], spacing_m)
    nodes = transformer.inverse_transform_points(np.array([[x, y] for y in ys for x in xs]).reshape(-1, 2))
    seen = nodes if lens is None else lens.distort_points(nodes)
    inside = (np.isfinite(seen).all(axis=1) & (seen[:, 0] >= f.us[0]) & (seen[:, 0] <= f.us[-1])
              & (seen[:, 1] >= f.vs[0]) & (seen[:, 1] <= f.vs[-1]))
    nodes, seen = nodes[inside], seen[inside]
    col = np.clip(np.searchsorted(f.us, seen[:, 0]), 0, len(f.us) - 1)
    row = np.clip(np.searchsorted(f.vs, seen[:, 1]), 0, len(f.vs) - 1)
    return nodes[keep[row, col]]


def footprint(transformer: ViewTransformer, width: int, height: int, site_map: SiteMap,
              camera_origin: np.ndarray, max_range_m: float, lens=None) -> list[list[float]]:
    """The frame's ground footprint on the site map, (K, 2) map px as a list: the image rectangle cut at the
    horizon (less HORIZON_MARGIN_PX), its border sampled (undistorted with a lens) and mapped to the ground, each
    point pulled towards camera_origin (2,) m to at most max_range_m."""
    a, b, c = transformer.horizon
    corners = np.array([[-0.5, -0.5], [width - 0.5, -0.5], [width - 0.5, height - 0.5], [-0.5, height - 0.5]])
    polygon = _clip_half_plane(corners, np.array([a, b, c - HORIZON_MARGIN_PX]))
    if len(polygon) < 3:
        return []
    t = np.linspace(0, 1, 64, endpoint=False)[:, None]
    border = np.vstack([p + t * (polygon[(i + 1) % len(polygon)] - p) for i, p in enumerate(polygon)])
    ground = transformer.transform_points(border if lens is None else lens.undistort_points(border))
    ground = ground[np.isfinite(ground).all(axis=1)]
    offset = ground - camera_origin
    dist = np.hypot(*offset.T)
    ground = camera_origin + offset * np.minimum(1.0, max_range_m / np.maximum(dist, 1e-300))[:, None]
    return _rounded(site_map.to_pixels(ground))


def _clip_half_plane(polygon: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: the part of a convex polygon (K, 2) where line . (u, v, 1) >= 0."""
    out = []
    side = polygon @ line[:2] + line[2]
    for i in range(len(polygon)):
        j = (i + 1) % len(polygon)
        if side[i] >= 0:
            out.append(polygon[i])
        if (side[i] >= 0) != (side[j] >= 0):
            out.append(polygon[i] + (polygon[j] - polygon[i]) * side[i] / (side[i] - side[j]))
    return np.array(out).reshape(-1, 2)


def _levels(values: np.ndarray, spacing: float) -> list[float]:
    if values.size == 0:
        return []
    lo, hi = np.ceil(values.min() / spacing), np.floor(values.max() / spacing)
    return [float(k * spacing) for k in np.arange(lo, hi + 1)]


def _iso_lines(us: np.ndarray, vs: np.ndarray, Z: np.ndarray, keep: np.ndarray, levels: list[float]) -> list[list]:
    """For each level, the polylines (lists of [u, v] px) where Z (n_v, n_u) = level, inside ``keep``."""
    if not levels:
        return []
    gen = contourpy.contour_generator(us, vs, np.ma.masked_array(Z, ~keep), line_type="Separate")
    return [[_rounded(line) for line in gen.lines(level) if len(line) >= 2] for level in levels]


def _rounded(points: np.ndarray) -> list[list[float]]:
    """Points (N, 2) as a JSON-ready list, to 0.1 px (display precision, keeps the responses small)."""
    return np.round(points, 1).tolist()


def ring_in_image(transformer: ViewTransformer, camera_origin: np.ndarray, radius_m: float, width: int,
                  height: int) -> list:
    """The ground circle of radius_m around camera_origin (2,) m as image polylines ([u, v] px lists): the
    parts in front of the camera that fall within a box 3x the frame around it."""
    angle = np.linspace(0, 2 * np.pi, 721)
    circle = camera_origin + radius_m * np.column_stack([np.cos(angle), np.sin(angle)])
    q = transformer.inverse_transform_points(circle)
    keep = (np.isfinite(q).all(axis=1) & (q[:, 0] >= -width) & (q[:, 0] <= 2 * width)
            & (q[:, 1] >= -height) & (q[:, 1] <= 2 * height))
    runs = np.split(np.arange(len(q)), np.flatnonzero(np.diff(keep.astype(int))) + 1)
    return [_rounded(q[run]) for run in runs if keep[run[0]] and len(run) >= 2]
