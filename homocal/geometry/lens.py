"""A real lens: intrinsics K and OpenCV's 5-coefficient distortion (k1, k2, p1, p2, k3), for one image size.

The model (OpenCV's, the one ``cv2.projectPoints`` applies): an ideal pinhole pixel (u, v) of the same K has
normalised coordinates x = (u - cx) / fx, y = (v - cy) / fy, r^2 = x^2 + y^2; the lens moves it to

    x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y

and the camera records (fx x_d + cx, fy y_d + cy). "Undistorted" pixels are those of the ideal pinhole with the same
K: the image where straight lines are straight and the paper's homographies hold.

The inverse has no closed form. OpenCV's ``undistortPoints`` is a fixed-point iteration that leaves 0.24 px at the
corners of a k1 = -0.2 lens and diverges at those of a k1 = -0.3 one (NOTES.md); ``undistort_points`` solves the
radial part by safeguarded Newton inside the monotonic range of the radial map, then the full model by Newton, and
accepts a point only once the forward model reproduces it within UNDISTORT_TOLERANCE_PX.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from homocal.geometry.homography import as_points

MAX_IMAGE_SIDE = 100_000  # px: an image's width or height (78x our datasets' 1280)
FRAME_MARGIN_PX = 1.0  # px: how far outside its frame a clicked point may lie (a click on the frame's edge pixel)
UNDISTORT_TOLERANCE_PX = 1e-9  # an undistorted point is accepted when it re-distorts within this of its input, px
MAX_NEWTON_STEPS = 100  # per stage; a safeguarded radial step at least halves the bracket, so 100 exhausts float64
MAX_HALVINGS = 30  # of one Newton step on the full model (2^-30: below the tolerance of any step that could help)


@dataclass(frozen=True, eq=False)
class Lens:
    """Intrinsics and distortion of one camera, valid over its whole frame.

    Args:
        K: (3, 3) intrinsics [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], pixels; fx, fy > 0.
        distortion: (5,) OpenCV coefficients (k1, k2, p1, p2, k3), on normalised coordinates.
        image_size: (width, height) of the distorted frame, pixels.

    Raises ValueError naming the field: a wrong shape, NaN/inf, fx or fy <= 0, skew, a size outside
    [1, MAX_IMAGE_SIDE]. Coefficients that fold the frame are refused by ``check_folds``, which every reader of a
    user's lens calls (a Lens itself may fold, for tests and estimators: points beyond the fold undistort to NaN).
    """

    K: np.ndarray
    distortion: np.ndarray
    image_size: tuple[int, int]

    def __post_init__(self) -> None:
        K = float_array(self.K, (3, 3), "K")
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            raise ValueError(f"K: fx and fy must be > 0, got fx = {K[0, 0]!r}, fy = {K[1, 1]!r}")
        if K[0, 1] != 0 or K[1, 0] != 0 or K[2].tolist() != [0.0, 0.0, 1.0]:
            raise ValueError(f"K: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew), got {K.tolist()}")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "distortion", float_array(self.distortion, (5,), "distortion"))
        object.__setattr__(self, "image_size", check_image_size(self.image_size))

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, Lens) and self.image_size == other.image_size
                and np.array_equal(self.K, other.K) and np.array_equal(self.distortion, other.distortion))

    __hash__ = None  # mutable-looking arrays inside: compare, do not hash

    # ---- properties -------------------------------------------------------------------
    @property
    def is_identity(self) -> bool:
        """True when every coefficient is zero: distorted and undistorted pixels coincide (callers skip the work)."""
        return not self.distortion.any()

    @property
    def max_monotonic_radius(self) -> float:
        """Normalised undistorted radius r* where the radial map g(r) = r (1 + k1 r^2 + k2 r^4 + k3 r^6) stops
        increasing (the first positive root of g'(r) = 1 + 3 k1 r^2 + 5 k2 r^4 + 7 k3 r^6); inf if it never does."""
        k1, k2, _, _, k3 = self.distortion
        roots = np.roots([7.0 * k3, 5.0 * k2, 3.0 * k1, 1.0])  # in s = r^2; np.roots drops leading zeros
        s = roots.real[(np.abs(roots.imag) <= 1e-9 * np.abs(roots)) & (roots.real > 0)]
        return float(np.sqrt(s.min())) if s.size else math.inf

    @property
    def max_distorted_radius(self) -> float:
        """g(r*): the largest normalised distorted radius with a pre-image in the monotonic range (inf if none)."""
        r = self.max_monotonic_radius
        return float(r * self._radial(r * r)) if math.isfinite(r) else math.inf

    def check_folds(self, image_size: tuple[int, int] | None = None) -> "Lens":
        """Return self, or ValueError (one line) if the radial map folds inside a frame of image_size = (W, H) px
        (default: the lens's own): a corner of the frame (the outer edges of its corner pixels) lies at or beyond
        g(r*), so frame pixels there have no pre-image (and rays beyond r* land twice)."""
        w, h = self.image_size if image_size is None else image_size
        corners = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])
        reach = float(np.hypot(*self._normalise(corners).T).max())
        if reach >= self.max_distorted_radius:
            r = self.max_monotonic_radius
            raise ValueError(f"distortion: {self.distortion.tolist()} folds the image at radius {r:.4g} (normalised, "
                             f"{r * self.K[0, 0]:.0f} px from the principal point), inside the {w}x{h} frame whose "
                             f"corners reach {reach:.4g}: the radial map is not monotonic there")
        return self

    def check_matches(self, K=None, image_size=None) -> "Lens":
        """Return self, or ValueError (one line, naming both) unless the lens's K equals K (3, 3) and its image size
        equals image_size (width, height) px, where given (None: not compared): whoever takes a lens with K and an
        image size (PedestrianCorrector.fit, homocal.watch.OnlineCalibrator) undistorts with the lens into the
        image of the lens's K and measures with K. K equal to 1e-9 relative (a JSON round trip is exact)."""
        try:
            k = None if K is None else np.asarray(K, dtype=np.float64)
        except (TypeError, ValueError):  # not numbers, or ragged
            k = np.full(0, np.nan)
        if k is not None and not (k.shape == (3, 3) and np.allclose(k, self.K, rtol=1e-9, atol=0.0)):
            raise ValueError(f"K: {k.tolist() if k.size else K!r} is not the lens's K {self.K.tolist()}: give the lens "
                             "of this camera")
        if image_size is not None and tuple(image_size) != self.image_size:
            raise ValueError(f"image_size: {tuple(image_size)} is not the lens's image size {self.image_size}: give "
                             "the lens of this camera")
        return self

    # ---- the model --------------------------------------------------------------------
    def distort_points(self, points: np.ndarray) -> np.ndarray:
        """Ideal pinhole pixels (N, 2) of the same K -> distorted pixels (N, 2), as cv2.projectPoints; NaN stays NaN."""
        p = as_points(points)
        if self.is_identity:
            return p
        return self._pixels(self._distort(self._normalise(p)))

    def undistort_points(self, points: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) -> ideal pinhole pixels (N, 2) of the same K, exact: each returned point
        re-distorts within UNDISTORT_TOLERANCE_PX of its input. NaN for a point with no pre-image inside the
        monotonic range r < r* of the radial map (beyond the fold) and for NaN input.

        Newton on the full model from the radial start, each step halved (up to MAX_HALVINGS times) until it
        lowers the pixel residual and stays inside r < r*; a point no halving improves has no pre-image there."""
        p = as_points(points)
        if self.is_identity:
            return p
        target = self._normalise(p)
        xy = self._radial_start(target)
        scale = np.array([self.K[0, 0], self.K[1, 1]])  # normalised -> pixels
        r_star2 = self.max_monotonic_radius ** 2

        def error(xy_: np.ndarray, rows: np.ndarray) -> np.ndarray:
            return np.hypot(*((self._distort(xy_) - target[rows]) * scale).T)

        done = np.zeros(len(p), dtype=bool)
        active = np.flatnonzero(np.isfinite(xy).all(axis=1))
        for _ in range(MAX_NEWTON_STEPS):
            err = error(xy[active], active)
            done[active[err <= UNDISTORT_TOLERANCE_PX]] = True
            keep = err > UNDISTORT_TOLERANCE_PX
            active, err = active[keep], err[keep]
            if not active.size:
                break
            (a, b), (c, d) = self._jacobian(xy[active])
            (ex, ey), det = (self._distort(xy[active]) - target[active]).T, a * d - b * c
            with np.errstate(divide="ignore", invalid="ignore"):  # a singular Jacobian (on the fold): no step
                step = np.column_stack([d * ex - b * ey, a * ey - c * ex]) / det[:, None]
            moved = np.zeros(len(active), dtype=bool)
            for halving in range(MAX_HALVINGS + 1):
                rows = np.flatnonzero(~moved)
                trial = xy[active[rows]] - step[rows] * 0.5**halving
                better = (error(trial, active[rows]) < err[rows]) & (np.sum(trial**2, axis=1) < r_star2)
                xy[active[rows[better]]] = trial[better]
                moved[rows[better]] = True
                if moved.all():
                    break
            active = active[moved]  # stuck points: no pre-image inside the fold
        xy[~done] = np.nan
        return self._pixels(xy)

    def distort_jacobian(self, points: np.ndarray) -> np.ndarray:
        """(N, 2, 2) derivative of distort_points at ideal pinhole pixels (N, 2): d(distorted u, v) / d(u, v), the
        model's analytic derivative (``_jacobian``, on normalised coordinates) scaled to pixels. Its inverse is
        undistort_points' derivative at the distorted point: a pixel error of covariance S on the frame is
        A S A^T in the undistorted image, A = inv(distort_jacobian). The identity for a lens without distortion."""
        p = as_points(points)
        (a, b), (c, d) = self._jacobian(self._normalise(p))
        fx, fy = self.K[0, 0], self.K[1, 1]
        return np.stack([np.column_stack([a, b * fx / fy]), np.column_stack([c * fy / fx, d])], axis=1)

    def to_dict(self) -> dict:
        """{"K", "distortion", "image_size"} as plain lists: lens.json's content."""
        return {"K": self.K.tolist(), "distortion": self.distortion.tolist(), "image_size": list(self.image_size)}

    # ---- helpers ----------------------------------------------------------------------
    def _normalise(self, pixels: np.ndarray) -> np.ndarray:
        return (pixels - self.K[:2, 2]) / np.array([self.K[0, 0], self.K[1, 1]])

    def _pixels(self, xy: np.ndarray) -> np.ndarray:
        return xy * np.array([self.K[0, 0], self.K[1, 1]]) + self.K[:2, 2]

    def _radial(self, r2: np.ndarray) -> np.ndarray:
        k1, k2, _, _, k3 = self.distortion
        return 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))

    def _distort(self, xy: np.ndarray) -> np.ndarray:
        """Normalised (N, 2) -> distorted normalised (N, 2): the model in the module docstring."""
        _, _, p1, p2, _ = self.distortion
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        a = self._radial(r2)
        return np.column_stack([x * a + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                                y * a + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y])

    def _jacobian(self, xy: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """Derivative of _distort at normalised xy (N, 2): ((dxd/dx, dxd/dy), (dyd/dx, dyd/dy)), each (N,)."""
        k1, k2, p1, p2, k3 = self.distortion
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        a, b = self._radial(r2), k1 + r2 * (2 * k2 + 3 * k3 * r2)  # b = da / d(r^2)
        off = 2 * x * y * b + 2 * p1 * x + 2 * p2 * y
        return (a + 2 * x * x * b + 2 * p1 * y + 6 * p2 * x, off), (off, a + 2 * y * y * b + 6 * p1 * y + 2 * p2 * x)

    def _radial_start(self, target: np.ndarray) -> np.ndarray:
        """Newton's start: solve the radial map g(r) = |target| for r in [0, r*] (safeguarded by bisection: g is
        increasing there), keep the direction. A target beyond g(r*) + 4 (|p1| + |p2|) r*^2 (the tangential terms'
        reach) has no pre-image inside the fold: NaN; one nearer starts just inside r*."""
        _, _, p1, p2, _ = self.distortion
        rd = np.hypot(*target.T)
        r_star = self.max_monotonic_radius
        hi = np.full(len(rd), r_star) if math.isfinite(r_star) else np.maximum(rd, 1.0)
        for _ in range(MAX_NEWTON_STEPS):  # an increasing g with no fold passes any radius: double until it does
            short = hi * self._radial(hi * hi) < rd
            if not short.any():
                break
            hi[short] *= 2.0
        reach = rd.copy()
        if math.isfinite(r_star):
            reach = np.minimum(rd, self.max_distorted_radius * (1 - 1e-9))
        lo, r = np.zeros(len(rd)), np.minimum(reach, hi)
        for _ in range(MAX_NEWTON_STEPS):
            f = r * self._radial(r * r) - reach
            lo, hi = np.where(f < 0, r, lo), np.where(f > 0, r, hi)
            if not (np.abs(f) * self.K[0, 0] > UNDISTORT_TOLERANCE_PX).any():
                break
            k1, k2, _, _, k3 = self.distortion
            slope = 1.0 + r * r * (3 * k1 + r * r * (5 * k2 + 7 * k3 * r * r))
            with np.errstate(divide="ignore", invalid="ignore"):
                step = r - f / slope
            r = np.where((step > lo) & (step < hi), step, 0.5 * (lo + hi))
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = target * np.where(rd > 0, r / rd, 1.0)[:, None]
        if math.isfinite(r_star):
            xy[rd > self.max_distorted_radius + 4 * (abs(p1) + abs(p2)) * r_star**2] = np.nan
        return xy


def undistort_input(points: np.ndarray, lens: Lens | None, name: str) -> np.ndarray:
    """The one step from the camera's pixels to the undistorted image for points a user gives (trapezoid corners,
    reference points, box corners): (N, 2) px -> (N, 2) px of ``lens.undistort_points``; as they are (a copy)
    without a lens or with an identity lens. ValueError naming ``name`` and the first finite point with no
    pre-image (beyond the lens's fold: outside any frame this lens can record)."""
    p = as_points(points, name)
    if lens is None or lens.is_identity:
        return p
    out = lens.undistort_points(p)
    lost = np.flatnonzero(np.isfinite(p).all(axis=1) & ~np.isfinite(out).all(axis=1))
    if lost.size:
        raise ValueError(f"{name}: point {lost[0]} = {p[lost[0]].tolist()} lies beyond the lens's fold (radius "
                         f"{lens.max_distorted_radius:.4g} normalised): no ray of this lens reaches it")
    return out


def first_outside_frame(points: np.ndarray, image_size: tuple[int, int]) -> int | None:
    """The index of the first of points (N, 2) px (homocal's convention: the frame spans -0.5 .. size - 0.5) more
    than FRAME_MARGIN_PX outside the image_size frame, or None: a point clicked on another camera's frame."""
    (w, h), m = image_size, FRAME_MARGIN_PX + 0.5
    outside = np.flatnonzero(~((points >= -m) & (points <= np.array([w, h]) - 1 + m)).all(axis=1))
    return int(outside[0]) if outside.size else None


def check_image_size(size) -> tuple[int, int]:
    """(width, height) as two ints in [1, MAX_IMAGE_SIDE]; ValueError naming image_size otherwise."""
    if not (isinstance(size, (tuple, list, np.ndarray)) and len(size) == 2
            and all(isinstance(x, (int, np.integer)) and not isinstance(x, bool) for x in size)
            and all(0 < x <= MAX_IMAGE_SIDE for x in size)):
        raise ValueError(f"image_size: expected (width, height), two integers in [1, {MAX_IMAGE_SIDE}] px, got {size!r}")
    return int(size[0]), int(size[1])


def float_array(value, shape: tuple[int, ...], name: str) -> np.ndarray:
    """value as a read-only float64 array of shape, finite; ValueError naming name otherwise."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected numbers of shape {shape}, got {value!r}") from None
    if arr.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}: contains NaN or inf: {arr.tolist()}")
    arr.setflags(write=False)
    return arr
