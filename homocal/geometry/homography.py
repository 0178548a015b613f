"""Homographies from four point pairs, and the ViewTransformer built on them.

The homography is computed in closed form in float64 without fixing h33 = 1 (the projective basis
construction: each quad is the image of the standard basis e1, e2, e3 and (1, 1, 1)), so it stays exact
when the horizon passes through the image origin (h33 = 0), which a solver fixing h33 = 1 cannot represent
(OpenCV 5.0's getPerspectiveTransform, in float32, still agreed within 1e-6 m there: docs/camera.md, measured by tests/test_docs.py).
"""
from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # sitemap imports this module
    from homocal.geometry.sitemap import SiteMap

QUAD_ORDER = "TL, TR, BR, BL"
MAX_COORDINATE = 1e9  # larger |coordinates| (a billion pixels or metres) are an overflow or a typo, not a click


def as_points(points: np.ndarray, name: str = "points") -> np.ndarray:
    """Return points of shape (N, 2) or (N, 1, 2), any real dtype, as a new (N, 2) float64 array."""
    arr = np.asarray(points)
    if arr.dtype.kind not in "fiu":
        raise ValueError(f"{name}: expected numbers, got dtype {arr.dtype}")
    if arr.ndim == 3 and arr.shape[1:] == (1, 2):
        arr = arr[:, 0, :]
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name}: expected shape (N, 2) or (N, 1, 2), got {arr.shape}")
    return arr.astype(np.float64, copy=True)


def validate_quad(quad: np.ndarray, name: str = "quad") -> np.ndarray:
    """Check a quadrilateral (4, 2) is a usable convex quad in order TL, TR, BR, BL; return it as float64.

    Raises ValueError naming the problem: wrong shape, NaN/inf, a coordinate beyond +/-MAX_COORDINATE, a
    repeated vertex, three collinear vertices (which includes zero area), self-intersection, or a non-convex quad.
    """
    q = as_points(quad, name)
    if q.shape != (4, 2):
        raise ValueError(f"{name}: a trapezoid needs exactly 4 vertices ({QUAD_ORDER}), got {len(q)}")
    if not np.isfinite(q).all():
        raise ValueError(f"{name}: vertices contain NaN or inf: {q.tolist()}")
    check_magnitude(q, name, "vertex")
    scale = max(float(np.ptp(q, axis=0).max()), 1e-300)
    for i, j in itertools.combinations(range(4), 2):
        if np.hypot(*(q[i] - q[j])) <= 1e-12 * scale:
            raise ValueError(f"{name}: vertices {i} and {j} are the same point {q[i].tolist()}")
    for i, j, k in itertools.combinations(range(4), 3):
        if abs(_cross(q[j] - q[i], q[k] - q[i])) <= 1e-9 * scale * scale:
            raise ValueError(f"{name}: vertices {i}, {j}, {k} are collinear (zero-area or degenerate trapezoid)")
    if _segments_cross(q[0], q[1], q[2], q[3]) or _segments_cross(q[1], q[2], q[3], q[0]):
        raise ValueError(f"{name}: the trapezoid is self-intersecting; give the vertices in order {QUAD_ORDER}")
    turns = [_cross(q[(i + 1) % 4] - q[i], q[(i + 2) % 4] - q[(i + 1) % 4]) for i in range(4)]
    if not (all(t > 0 for t in turns) or all(t < 0 for t in turns)):
        raise ValueError(f"{name}: the trapezoid is not convex")
    return q


def check_magnitude(points: np.ndarray, name: str, what: str = "point") -> None:
    """ValueError naming the first of points (N, 2) with a |coordinate| > MAX_COORDINATE (an overflow or a typo:
    the geometry's products of coordinates would overflow or lose every digit)."""
    big = np.flatnonzero((np.abs(points) > MAX_COORDINATE).any(axis=1))
    if big.size:
        raise ValueError(f"{name}: {what} {big[0]} = {points[big[0]].tolist()} is out of range (|coordinate| > "
                         f"{MAX_COORDINATE:g}): an overflow or a typo?")


def signed_area(quad: np.ndarray) -> float:
    """Shoelace signed area of a polygon (N, 2): > 0 if its vertices turn counter-clockwise in a y-up frame
    (clockwise as drawn in a y-down frame such as the image)."""
    x, y = quad[:, 0], quad[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def check_orientation(image_quad: np.ndarray, ground_quad: np.ndarray, target_y_up: bool = True) -> None:
    """Refuse a map trapezoid that is mirrored or turned against the image trapezoid.

    Both are given in the same order (TL, TR, BR, BL as seen in the image). The image's v axis points down; a
    ground frame in metres (homocal's world: y forward) has y up on a map, so a correct pair has signed areas of
    OPPOSITE sign (target_y_up=True); a site map in pixels (py down, like the image) has the SAME sign
    (target_y_up=False). A mirrored (left-right) or upside-down (near-far) map flips the sign: such a pair still
    gives a homography, but one that maps the scene mirrored (17 m errors in the probe of issue 12). A map
    turned by 90 or 180 degrees keeps the sign; it is caught by the far edge: the edge that is higher in the
    image (TL-TR, or whichever pair the order makes the upper one) lies farther from the camera, so it must be
    the farther one on the map too (larger y in metres, smaller py in site-map pixels).
    """
    image, ground = np.asarray(image_quad, float), np.asarray(ground_quad, float)
    sign = -1 if target_y_up else 1  # of the products below in a correct pair (y flipped between the frames or not)
    if not signed_area(image) * signed_area(ground) * sign > 0:
        raise ValueError(f"the map trapezoid's corners go round the other way from the image's (mirrored or upside "
                         f"down?): give both in the order {QUAD_ORDER} as seen in the image")
    upper_image = image[:2, 1].sum() - image[2:, 1].sum()  # < 0: TL, TR higher in the image than BR, BL
    upper_map = ground[:2, 1].sum() - ground[2:, 1].sum()
    if not upper_image * upper_map * sign > 0:
        raise ValueError(f"the map trapezoid is turned against the image's: the edge higher in the image lies farther "
                         f"from the camera and must be the farther one on the map (map up = forward); give both "
                         f"in the order {QUAD_ORDER} as seen in the image")


def homography_from_quads(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The (3, 3) homography H with H [s_i, 1]^T ~ [t_i, 1]^T for 4 point pairs (4, 2), float64.

    Closed form: B_q = [q1 q2 q3] diag(lambda) with [q1 q2 q3] lambda = q4 (homogeneous) maps the
    projective basis to quad q; H = B_target B_source^-1. Scaled to unit Frobenius norm with the sign
    that makes the homogeneous scale w = H[2] . [s, 1] positive on the source vertices. Raises ValueError
    if the vertices are in a degenerate configuration.
    """
    Bs, Bt = _basis_map(source), _basis_map(target)
    H = Bt @ np.linalg.inv(Bs)
    H /= np.linalg.norm(H)
    w = np.column_stack([source, np.ones(4)]) @ H[2]
    if np.all(w < 0):
        H = -H
    elif not np.all(w > 0):
        raise ValueError("the trapezoids imply a horizon that crosses the source trapezoid")
    return H


def apply_homography(H: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Map (N, 2) points through H; points on or beyond its horizon (see _in_front) give NaN."""
    x, y = points[:, 0], points[:, 1]
    valid = _in_front(H, x, y)
    xyw = np.column_stack([x[valid], y[valid], np.ones(valid.sum())]) @ H.T
    out = np.full((len(points), 2), np.nan)
    out[valid] = xyw[:, :2] / xyw[:, 2:]
    return out


def _in_front(H: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bool array (x's and y's broadcast shape): True where H maps (x, y) to a finite point on the side it
    keeps, w = H[2] . (x, y, 1) > 1e-12 (|x| + |y| + 1) |H[2]|; False on or beyond its horizon and for NaN."""
    w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    return w > 1e-12 * (np.abs(x) + np.abs(y) + 1.0) * np.linalg.norm(H[2])


class ViewTransformer:
    """Image-to-ground mapping from a trapezoid clicked on the image and its 4 points on the ground/site map.

    Same method names as supervision's ViewTransformer, so its users can switch; unlike it, computed in
    float64 without fixing h33 = 1, never casting to int, and giving NaN (not a huge or zero value) for a
    point on or above the horizon. Filter those before any ``.astype(int)``, which turns NaN into
    -9223372036854775808 with only a warning: ``return_valid=True`` gives the mask, or use ``np.isfinite``.
    Points are in homocal's pixel convention (centres at integers); boxes from other tools: box_bottom_points.

    Args:
        source: (4, 2) image trapezoid, pixels, order TL, TR, BR, BL.
        target: (4, 2) the same 4 points on the ground (metres) or site map (pixels).

    Attributes:
        m: (3, 3) image-to-target homography (unit Frobenius norm, w > 0 on the ground side).
        m_inv: (3, 3) target-to-image homography (unit Frobenius norm, w > 0 in front of the camera).
    """

    def __init__(self, source: np.ndarray, target: np.ndarray) -> None:
        self.source = validate_quad(source, "source")
        self.target = validate_quad(target, "target")
        self.m = homography_from_quads(self.source, self.target)
        self.m_inv = homography_from_quads(self.target, self.source)

    def transform_points(self, points: np.ndarray, return_valid: bool = False) -> np.ndarray | tuple:
        """Map image points (N, 2) or (N, 1, 2), pixels, to target points (N, 2) float64; NaN on/above the horizon.

        With return_valid, also valid (N,) bool: False exactly where a result is NaN (on or above the horizon,
        or a NaN input), as in np.unique's return_* flags."""
        return _with_valid(apply_homography(self.m, as_points(points)), return_valid)

    def inverse_transform_points(self, points: np.ndarray, return_valid: bool = False) -> np.ndarray | tuple:
        """Map target points (N, 2) or (N, 1, 2) to image pixels (N, 2) float64; NaN behind the camera.
        return_valid: as in transform_points."""
        return _with_valid(apply_homography(self.m_inv, as_points(points)), return_valid)

    def transform_image(self, image: np.ndarray, size: tuple[int, int], site_map: SiteMap | None = None) -> np.ndarray:
        """Warp the camera image (H, W) or (H, W, C) onto the target plane: (h, w) or (h, w, C), image's dtype,
        for size = (w, h) target pixels (roboflow/sports' transform_image, cv2.warpPerspective, bilinear).

        site_map: the map whose pixels the output is in when the target is in metres; None if the target is
        already in (site-map) pixels. Output pixels whose ground point is behind the camera (it has no image
        point: inverse_transform_points gives NaN) are 0, where warpPerspective alone paints a mirrored copy
        of the image above the horizon; other pixels outside the camera's view are 0 too."""
        if not (len(size) == 2 and all(isinstance(n, (int, np.integer)) and n > 0 for n in size)):
            raise ValueError(f"size: expected (width, height), two positive integers, got {size!r}")
        image = np.asarray(image)
        if image.ndim not in (2, 3):
            raise ValueError(f"image: expected shape (H, W) or (H, W, C), got {image.shape}")
        to_pixels = np.eye(3) if site_map is None else np.linalg.inv(site_map.to_metres_matrix)
        m = to_pixels @ self.m
        import cv2  # loads where an image is warped (a cheap ``import homocal``)

        out = cv2.warpPerspective(image, m, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        inv = np.linalg.inv(m)
        x, y = np.arange(size[0], dtype=np.float64), np.arange(size[1], dtype=np.float64)
        # w - margin is concave in (x, y) (linear minus |x| + |y|): if the 4 corners are in front, every pixel is
        if not _in_front(inv, x[[0, -1, -1, 0]], y[[0, 0, -1, -1]]).all():
            out[~_in_front(inv, x[None, :], y[:, None])] = 0
        return out

    @property
    def horizon(self) -> np.ndarray:
        """(3,) image line (a, b, c) with a^2 + b^2 = 1: a u + b v + c = 0 on the horizon, > 0 on the ground side."""
        line = self.m[2]
        return line / np.hypot(line[0], line[1])

    def horizon_row(self, u: float | np.ndarray) -> float | np.ndarray:
        """Image row v of the horizon at column(s) u, pixels (paper eq. (4): v_h = -D / C)."""
        a, b, c = self.horizon
        return -(a * np.asarray(u, dtype=np.float64) + c) / b

    def __repr__(self) -> str:
        return f"ViewTransformer(source={self.source.tolist()}, target={self.target.tolist()})"


def _with_valid(out: np.ndarray, return_valid: bool):
    """out (N, 2), or (out, valid (N,) bool: no NaN in the row) if return_valid."""
    return (out, ~np.isnan(out).any(axis=1)) if return_valid else out


def _basis_map(quad: np.ndarray) -> np.ndarray:
    """(3, 3) matrix mapping e1, e2, e3, (1, 1, 1) to the quad's 4 homogeneous vertices."""
    P = np.vstack([quad[:3].T, np.ones(3)])
    try:
        lam = np.linalg.solve(P, np.array([quad[3, 0], quad[3, 1], 1.0]))
    except np.linalg.LinAlgError:
        raise ValueError("degenerate trapezoid: three vertices are collinear") from None
    if not np.all(np.isfinite(lam)) or np.any(lam == 0):
        raise ValueError("degenerate trapezoid: three vertices are collinear")
    return P * lam


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _segments_cross(p1, p2, p3, p4) -> bool:
    """True if the open segments p1p2 and p3p4 properly intersect."""
    d1, d2 = _cross(p2 - p1, p3 - p1), _cross(p2 - p1, p4 - p1)
    d3, d4 = _cross(p4 - p3, p1 - p3), _cross(p4 - p3, p2 - p3)
    return d1 * d2 < 0 and d3 * d4 < 0
