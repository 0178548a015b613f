"""Beyond the paper: the clicked mapping corrected from the people in view, with no reference point.

The paper's error model (Section 3) says most distance error is the clicked trapezoid's horizon being off, and
a tilt error of the clicked trapezoid is exactly an image rotation: if its corners are the true ones moved by
G = K R_x(delta) K^-1 (``homocal.geometry.camera.tilt_homography``), the true mapping is H_clicked . G. The
people in view fix delta once the camera's height and the people's height distribution are known.

Camera model (``homocal.geometry.camera``: pinhole, square pixels, roll 0 (below: Roll), focal length f,
principal row cy, optical centre h_c above a flat ground, tilted theta below the horizontal). Image row v is the plane through
the optical centre and the camera's horizontal x-axis, inclined theta + beta(v) below the horizontal,
beta(v) = atan((v - cy) / f); the horizon is the row v_h = cy - f tan(theta). A person standing at forward
distance Y (world y) whose box has its bottom edge (the nearest sole) on row v_f and its top edge (the top of
the head) on row v_t: Y = h_c / tan(theta + beta_f), and the vertical through that ground point meets the
head's row plane at the implied height

    H(theta) = h_c (1 - tan(theta + beta_t) / tan(theta + beta_f))                       (``implied_heights``)

exactly, in any image column (the vertical vanishing point is accounted for: the naive
H / h_c = (v_f - v_t) / (v_f - v_h) is 1.3-9.5 % short on a 4 m camera tilted 15 degrees, 7 % at 6-10 m,
2 % at 20-45 m). H decreases as theta grows (the horizon
rises) wherever the foot is below the horizon and theta + beta_t + theta + beta_f < 90 degrees.

Fit (``fit_tilt``). With the prior N(mu, sigma^2) of the people's heights, theta is the robust maximum
likelihood estimate: start where the median implied height of all boxes is mu (bisection); then repeat,
at most MAX_ROUNDS times, until the set of inlier boxes no longer changes or comes back to an earlier round's
(the rounds can cycle between two sets: the fit stops at the return, at the set before it, whatever MAX_ROUNDS
is): the inliers are the boxes whose implied height is within OUTLIER_SIGMAS sigma of mu (occluded or
border-cut boxes, sitting people, children and false detections fall outside), each person (track) is one
height, the median of its inlier boxes',
and theta solves the Huber score equation

    sum_j psi((H_j(theta) - mu) / sigma) H_j'(theta) = 0,    psi(r) = max(-k, min(k, r)), k = HUBER_K

(bisection). The weights H_j' make this the likelihood's own score: a relative height error epsilon of a
person at distance Y moves the horizon by epsilon f h_c / Y, so far people carry more information per
person and near ones, whose boxes' bottom edge (the nearest sole's edge, up to a quarter stride and half a
foot nearer than the body's axis) biases their implied heights up (+3.8 % within 8 m, +1.6 % at 8-12 m
for scene1's segmentation boxes), carry little.

Uncertainty: the sandwich variance of the M-estimate over the people (tracks), sigma_theta^2 =
sigma^2 sum psi^2 H'^2 / (sum psi' H'^2)^2, as a horizon row sigma f sec^2(theta) sigma_theta (px); and the
horizon's shift per centimetre of error in the prior mean (dtheta / dmu = sum psi' H' / sum psi' H'^2),
which no number of people reduces: the prior mean's own uncertainty sigma_mu (height_mean_sigma_m) adds
f sec^2(theta) |dtheta / dmu| sigma_mu in quadrature to the horizon's sigma. Without track ids, boxes in
frames up to LINK_GAP apart are linked into tracks by box overlap (``homocal.geometry.boxes.link_tracks``);
without frames either, every box counts as an independent person and the uncertainty is understated.

Roll (``fit_tilt_roll``, PedestrianCorrector(estimate_roll=True)): a camera rolled by phi about its optical
axis (simgen's camera.json convention, data_schema.md: phi > 0 lowers the camera's right side) sees the unrolled
camera's image turned by -phi about the principal point, so the same heights hold for the rows of the foot and
head points turned back by phi (``derolled_rows``), each at its own column: an upright person's foot and head lie
on a line to the verticals' vanishing point and their box's middle column is the two columns' mean
(``upright_columns``; taking the middle column for both put the roll 3.5-3.8 % of itself high on noise-free
walkers, tests/correctors/test_pedestrians.py -k lean); tilt and roll are fitted
together when the people's foot columns spread over ROLL_SPREAD of the image width. On a rolled camera a short
person on one side and a rolled horizon look alike: each person's one height against the prior fixes the roll only
as well as who happened to walk by. A person's own walk does not depend on their height: their boxes' implied
heights H_j(tilt, roll) must stay their own h_p along the walk, however tall, and how they drift with the column
is the roll. So ``fit_tilt_roll`` takes the roll from both (the people's heights against the prior, and each
box's height about its person's mean, h_p profiled out: a free height per person), the tilt from the people's heights
alone as fit_tilt does (within a walk the nearest sole's edge makes near boxes look taller, which reads as a tilt),
and weighs the walks by their honest information. On a yawed camera a walk along the street changes its range with
its column, so the near boxes' excess would read as a roll too (without it the fitted roll on scene3's render-free
walkers falls from 1.0 to 0.45 degrees as the recording grows from 10 to 120 s: docs/real-camera.md): the walks' heights are the box's with its bottom edge taken d
metres nearer than the body's axis (upright_heights' sole_offset_m), d one offset shared by everyone, fitted with
the roll from the walks (its prior SOLE_OFFSET_M: without walks whose range changes, no offset), and d >= 0: the
nearest sole is never behind the axis (where every walk runs the same way, d follows the roll and ran to -0.9 m
without the bound, tests/correctors/test_pedestrians.py -k walks_give). The walks' weight: a person's boxes are not
independent (consecutive frames, the gait), so the walks' weight is their information as if independent over its
spread among the people, the information and the spread of the roll's score with d profiled out (walk_weight's
nuisance): where d follows the roll the walks know the roll less than their roll slopes alone say, and weighed as
if d were known they took a 10 s recording's roll to 8.7 degrees, then -23 (tests/research/test_recording_length.py). Lens
distortion: the boxes' foot and head points are undistorted first (``homocal.geometry.Lens``).

What it takes from the clicked mapping: nothing for theta when K and h_c are given. Without K: the focal
length from the clicked homography (``focal_from_homography``: principal point at the image centre, square
pixels, zero skew); without h_c: the camera height from its decomposition with K
(``camera_height_from_homography``). A pure tilt error leaves both exact (the clicked mapping is then a
camera with the same K and the same optical centre, only rotated); other click errors do not.
"""
from __future__ import annotations

import copy
import math

import numpy as np

from homocal.correctors.base import Corrector, check_calibration, check_camera_origin, improvement_percent, mean_error
from homocal.correctors.serialization import float_or_none, integer, number
from homocal.geometry import ViewTransformer, apply_homography, as_points
from homocal.geometry.boxes import (MAX_BOX_MARGIN_PX, box_edges, hidden_feet, link_tracks, on_border, trim_boxes,
                                    undistort_boxes)
from homocal.geometry.camera import tilt_homography
from homocal.geometry.lens import Lens
from homocal.study.options import Number, Option, OptionError, YesNo

# Adult heights, metres: NCD-RisC 2016 (eLife 5:e13410, "A century of trends in adult human height"), as
# summarised by Our World in Data: the global mean of adults born in 1996 is 171 cm for men and 159 cm for
# women; an equal mix has mean 1.65 m and, with a within-sex sd of about 7 cm (NCD-RisC gives means only),
# sd sqrt(0.07^2 + 0.06^2) = 0.09 m.
DEFAULT_HEIGHT_MEAN_M = 1.65
DEFAULT_HEIGHT_SD_M = 0.09
# The prior mean's own 1-sigma uncertainty, metres: the people in one view are not the world's adults. Country
# means of adult men range from 160 to 183 cm and of women from 150 to 170 cm (NCD-RisC 2016, eLife 5:e13410);
# a street's mix of men and women moves an equal mix's mean by up to 6 cm; shoes add 2-3 cm; walking people's
# boxes are shorter than their standing heights (about 5 cm on simgen's people, docs/pedestrians.md). Together
# about +-5 cm on the mean of a population one has not measured: DEFAULT_HEIGHT_MEAN_SIGMA_M.
DEFAULT_HEIGHT_MEAN_SIGMA_M = 0.05
OUTLIER_SIGMAS = 3.0  # a box whose implied height is farther than this many prior sds from the mean is an outlier
HUBER_K = 1.345  # Huber's constant (95 % efficiency at the normal)
MAX_ROUNDS = 20  # inlier-set rounds of fit_tilt at most
MIN_PEOPLE = 3  # fewer inlier people (tracks) than this is refused
MAX_OUTLIER_SHARE = 0.5  # more outlier boxes, or people, than this share of those used is refused (PedestrianCorrector.fit)
LINK_GAP = 5  # frames: boxes this many frames apart at most are linked into one track
MIN_CAMERA_HEIGHT_M, MAX_CAMERA_HEIGHT_M = 0.5, 100.0  # below half a metre no box of a standing person fits
BOX_STATUS = ("used", "outlier", "border", "hidden")  # a box's part in a fit (box_status_), the page draws each kind
HIDDEN_FEET = ("kept", "dropped", "no frames")  # a fit's hidden_feet_: boxes whose feet may be hidden used, left out,
# or not looked for (drop_hidden_feet "auto" on boxes without frames)
MODELS = ("camera", "rotation")  # PedestrianCorrector's corrected mappings (its docstring); the first is the default
GRID = 128  # tilt grid of the median start over its 90 degree range (then bisection)
BOX_HEIGHT_SD = 0.02  # a box's implied height about its person's, relative 1-sigma: Huber's scale of a walk's boxes
# (fit_tilt_roll); scene1's and scene2's boxes spread 1.7-1.9 % about their person's at the true pose, both detectors
# (1.4826 MAD, research/box_heights.py: docs/real-camera.md, "The people on scene3")
ROLL_SPREAD = 0.1  # estimate_roll fits roll when the people's foot columns' interquartile range spans this share of the width
MAX_ROLL_DEG = 10.0  # a fitted roll beyond this is refused (a camera on a pole is rolled a degree or two)
DIFF_STEP = 1e-7  # radians: central-difference step of the people's heights in fit_tilt_roll
STEP_TOLERANCE = 1e-9  # radians: fit_tilt_roll stops at a step this small, the size of the rounding in its
# gradient (a height's 2e-16 relative rounding over DIFF_STEP)
SOLE_OFFSET_M = (0.0, 0.2)  # metres: the prior N(mean, sd^2) of how much nearer a box's bottom edge (the nearest
# sole) lies than the body's axis, shared by the people's walks (fit_tilt_roll; d >= 0: never behind it): none without
# evidence (mean 0: a box of the axis alone is fitted exactly), up to a quarter stride and half a foot (0.3-0.45 m) within 2 sd
SOLE_STEP_TOLERANCE_M = 1e-6  # metres: fit_tilt_roll stops at a step of the sole's offset this small (its rounding
# floor is 1e-8 m; a micrometre moves a box's height at 5 m by under 1e-6 m, where a pixel is a centimetre)
SETTINGS = {
    "height_mean_m": Option("--height-mean", Number(0.5, 2.5), "the people's mean height (the default: adults, "
                            "docs/pedestrians.md)", metavar="M", unit="m"),
    "height_sd_m": Option("--height-sd", Number(0.01, 0.625), "the spread of the people's heights (at most a "
                          "quarter of the mean)", metavar="M", unit="m"),
    "height_mean_sigma_m": Option("--height-mean-sigma", Number(0.0, 0.5), "the 1-sigma uncertainty of the people's "
                                  "mean height (0: known exactly), part of the horizon's and every point's error "
                                  "bars", metavar="M", unit="m"),
    "estimate_roll": Option("--estimate-roll", YesNo(), "fit the camera's "
                            "roll with its tilt (the horizon as a line) when the people spread across the image",
                            metavar="{yes,no}"),
    "drop_hidden_feet": Option("--drop-hidden-feet", YesNo(auto=True), "leave out the boxes whose feet a nearer "
                               "person's box may hide (homocal.geometry.hidden_feet, in each video frame; needs the "
                               "boxes' frames); auto: only if the fit with them is refused for its outliers and the "
                               "fit without them is not", metavar="{yes,no,auto}"),
    "camera_height_m": Option("--camera-height", Number(MIN_CAMERA_HEIGHT_M, MAX_CAMERA_HEIGHT_M), "the camera's "
                              "height over the ground", metavar="M", unit="m", none="from the clicked trapezoid with K"),
    "box_margin_px": Option("--box-margin", Number(0.0, MAX_BOX_MARGIN_PX), "how much taller than their people the "
                            "detector's boxes are, in the camera's pixels: half off each box's top and bottom edge "
                            "before the fit (a box no taller: an outlier), kept in the correction for homocal measure",
                            metavar="PX", unit="px"),
}
"""The settings of a pedestrian fit, each declared once (homocal.study.options.Option: flag, bounds, unit, help):
PedestrianCorrector's checks (an OptionError names the parameter), homocal fit's flags and their error
messages, and the page's fields derive from it. All but camera_height_m (fit's) are constructor parameters."""


def implied_heights(foot_rows: np.ndarray, head_rows: np.ndarray, tilt: float, focal_px: float, cy: float,
                    camera_height_m: float) -> np.ndarray:
    """Heights (N,) metres of people whose boxes span image rows head_rows (N,) (top edges) to foot_rows (N,)
    (bottom edges), pixels, for a camera tilted ``tilt`` radians below the horizontal, focal length focal_px,
    principal row cy (px), at camera_height_m over a flat ground (module docstring):
    H = h_c (1 - tan(tilt + beta_t) / tan(tilt + beta_f)), beta = atan((v - cy) / f). +inf where the foot row
    is on or above the horizon (tilt + beta_f <= 0: the person would be infinitely far)."""
    beta_t, beta_f = (np.arctan((np.asarray(v, float) - cy) / focal_px) for v in (head_rows, foot_rows))
    return _heights(beta_f, beta_t, tilt, camera_height_m)[0]


def _heights(beta_f: np.ndarray, beta_t: np.ndarray, tilt: float, camera_height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(H, dH/dtilt) (N,) of implied_heights from the row angles beta_f, beta_t (N,) radians:
    with a = tilt + beta_t, b = tilt + beta_f, H = h_c (1 - tan a / tan b) and
    dH/dtilt = -h_c (sec^2 a tan b - tan a sec^2 b) / tan^2 b; (+inf, 0) where b <= 0."""
    ta, tb = np.tan(tilt + beta_t), np.tan(tilt + beta_f)
    front = tilt + beta_f > 0
    tb = np.where(front, tb, 1.0)
    h = np.where(front, camera_height_m * (1.0 - ta / tb), np.inf)
    dh = np.where(front, -camera_height_m * ((1.0 + ta * ta) * tb - ta * (1.0 + tb * tb)) / (tb * tb), 0.0)
    return h, dh


def implied_horizon_rows(foot_rows: np.ndarray, head_rows: np.ndarray, focal_px: float, cy: float,
                         camera_height_m: float, height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Per box, the horizon row (N,) px at which a person of height_m metres spans rows head_rows .. foot_rows
    (N,) px, and its change per metre of the person's height (N,) px/m: the inverse of implied_heights. With
    t = tan(tilt), a = (v_t - cy) / f, b = (v_f - cy) / f and r = 1 - height_m / h_c, H(tilt) = height_m is
    tan(tilt + beta_t) = r tan(tilt + beta_f), a quadratic (r a - b) t^2 + (1 - a b - r + r a b) t + (a - r b) = 0
    whose root of smallest tilt with the foot in front (0 < tilt + beta_f < 90 degrees) is the one on H's
    decreasing branch (module docstring); the row is cy - f t, its slope -f sec^2(tilt) / (dH/dtilt).
    NaN where no tilt gives that height."""
    a, b = ((np.asarray(v, float) - cy) / focal_px for v in (head_rows, foot_rows))
    r = 1.0 - height_m / camera_height_m
    qa, qb, qc = r * a - b, 1.0 - a * b - r + r * a * b, a - r * b
    disc = np.sqrt(np.where(qb * qb - 4 * qa * qc >= 0, qb * qb - 4 * qa * qc, np.nan))
    with np.errstate(divide="ignore", invalid="ignore"):
        roots = np.stack([(-qb - disc) / (2 * qa), (-qb + disc) / (2 * qa)])
    (r0, r1), (v0, v1) = roots, (roots + b > 0) & (roots * b < 1)
    t = np.where(v0 & ~(v1 & (r1 < r0)), r0, np.where(v1, r1, np.nan))
    dh = _heights(np.arctan(b), np.arctan(a), np.arctan(t), camera_height_m)[1]
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = -focal_px * (1.0 + t * t) / dh
    return cy - focal_px * t, slope


def horizon_row(tilt: float, focal_px: float, cy: float) -> float:
    """The horizon's image row v_h = cy - f tan(tilt), px, of a camera tilted ``tilt`` radians down (roll 0)."""
    return cy - focal_px * math.tan(tilt)


def focal_from_homography(image_to_ground: np.ndarray, principal_point: tuple[float, float]) -> float:
    """Focal length (px) of the camera a ground homography (3, 3) image -> ground implies, for a principal point
    (cx, cy) px, square pixels and zero skew: with G = inverse of it = K [r1 r2 t] up to scale and
    K^-1 g_i = ((g_ix - cx g_iw) / f, (g_iy - cy g_iw) / f, g_iw), the conditions r1 . r2 = 0 and |r1| = |r2|
    are linear in x = 1 / f^2: (a1 . a2) x = -w1 w2, (|a1|^2 - |a2|^2) x = w2^2 - w1^2 (a_i the first two
    entries of g_i - (cx, cy) g_iw, w_i = g_iw), solved together by least squares. ValueError if they imply
    no real focal length."""
    g = np.linalg.inv(image_to_ground)
    g = g / np.linalg.norm(g)
    cx, cy = principal_point
    a = [g[:2, i] - np.array([cx, cy]) * g[2, i] for i in (0, 1)]
    w = g[2, :2]
    coef = np.array([a[0] @ a[1], a[0] @ a[0] - a[1] @ a[1]])
    rhs = np.array([-w[0] * w[1], w[1] ** 2 - w[0] ** 2])
    x = float(coef @ rhs / (coef @ coef)) if coef @ coef > 0 else math.nan
    if not x > 0:
        raise ValueError("the clicked mapping implies no real focal length for a principal point at the image centre: "
                         "give the intrinsics K")
    return 1.0 / math.sqrt(x)


def intrinsics(image_to_ground: np.ndarray, image_size: tuple[int, int] | None, K=None) -> np.ndarray:
    """(3, 3) the intrinsics a fit from people uses: K checked (finite, fx = fy > 0), or when K is None the principal
    point at the centre of image_size (width, height) px and the focal length ``focal_from_homography`` gives the
    clicked mapping image_to_ground (3, 3). ValueError naming K for bad K, or when neither K nor image_size is given."""
    if K is None:
        if image_size is None:
            raise ValueError("K and image_size are both None: give the intrinsics K or the image size")
        cx, cy = image_size[0] / 2.0 - 0.5, image_size[1] / 2.0 - 0.5
        f = focal_from_homography(image_to_ground, (cx, cy))
        return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.isfinite(K).all() or not K[0, 0] > 0 or abs(K[0, 0] - K[1, 1]) > 1e-6 * K[0, 0]:
        raise ValueError(f"K: expected finite (3, 3) intrinsics with fx = fy > 0, got {K.tolist()}")
    return K


def camera_height_from_homography(image_to_ground: np.ndarray, K: np.ndarray) -> float:
    """Height (the ground homography's target units, metres) of the optical centre above the ground plane, from a
    ground homography (3, 3) image -> ground and the intrinsics K (3, 3): with B = K^-1 G = lambda [r1 r2 t]
    (G its inverse), lambda = (|b1| + |b2|) / 2, r3 = r1 x r2 / |r1 x r2|, the height is |r3 . t|, the distance
    from the optical centre to the plane z = 0."""
    B = np.linalg.inv(K) @ np.linalg.inv(image_to_ground)
    lam = 0.5 * (np.linalg.norm(B[:, 0]) + np.linalg.norm(B[:, 1]))
    r3 = np.cross(B[:, 0], B[:, 1])
    return float(abs(r3 @ B[:, 2]) / (np.linalg.norm(r3) * lam))


def _huber(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(psi(r), psi'(r)) of Huber's function with k = HUBER_K."""
    return np.clip(r, -HUBER_K, HUBER_K), (np.abs(r) <= HUBER_K).astype(np.float64)


def _bisect(g, lo: float, hi: float, steps: int = 50) -> float:
    """The root of g in [lo, hi] where g(lo) > 0 >= g(hi), by bisection (50 halvings: 1e-15 of a 90 degree range)."""
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if g(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


def _group_medians(values: np.ndarray, slopes: np.ndarray, labels: np.ndarray, starts: np.ndarray,
                   counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(median, its slope) (G,) per group of values (M,) with dense labels (M,) 0..G-1, groups starting at
    starts (G,) with counts (G,) in label order: the middle value (mean of the two middle ones for an even count)
    and the same combination of slopes."""
    lo, hi = _median_pairs(values, labels, starts, counts)
    return 0.5 * (values[lo] + values[hi]), 0.5 * (slopes[lo] + slopes[hi])


def _median_pairs(values: np.ndarray, labels: np.ndarray, starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(2, G) indices into values (M,) of each group's two middle values (one twice for an odd count); the groups
    as _group_medians'."""
    order = np.lexsort((values, labels))
    return np.stack([order[starts + (counts - 1) // 2], order[starts + counts // 2]])


def _people(tracks: np.ndarray, mean_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(people, labels, starts, counts) of the inlier boxes' tracks (M,) (np.unique's, with each group's start in
    label order: _group_medians' arguments); ValueError for fewer than MIN_PEOPLE people."""
    people, labels, counts = np.unique(tracks, return_inverse=True, return_counts=True)
    if len(people) < MIN_PEOPLE:
        raise ValueError(f"only {len(people)} people (tracks) have a box whose implied height is within "
                         f"{OUTLIER_SIGMAS:g} sd of {mean_m:g} m: need at least {MIN_PEOPLE}")
    return people, labels, np.concatenate([[0], np.cumsum(counts)[:-1]]), counts


def fit_tilt(foot_rows: np.ndarray, head_rows: np.ndarray, tracks: np.ndarray, focal_px: float, cy: float,
             camera_height_m: float, mean_m: float, sd_m: float) -> dict:
    """The camera's tilt from people's boxes (module docstring, Fit and Uncertainty).

    Args:
        foot_rows, head_rows: (N,) bottom and top edge rows of the boxes, px (homocal's pixels).
        tracks: (N,) int person (track) of each box.
        focal_px, cy: the focal length and principal row, px. camera_height_m: metres.
        mean_m, sd_m: the prior of the people's heights, metres.
    Returns a dict: tilt (radians), tilt_sigma (radians), mean_sensitivity (dtilt / dmu, radians per metre),
    inlier_boxes (N,) bool, n_people (tracks with an inlier box), rounds.
    ValueError if no tilt makes the median implied height mu or fewer than MIN_PEOPLE people are inliers.
    """
    beta_f, beta_t = np.arctan((foot_rows - cy) / focal_px), np.arctan((head_rows - cy) / focal_px)
    lo, hi = -beta_f.max(), math.pi / 2 - beta_f.max()  # every foot on or above the horizon .. the lowest straight down

    def median_excess(tilt: float) -> float:
        return float(np.median(_heights(beta_f, beta_t, tilt, camera_height_m)[0])) - mean_m

    grid = lo + (hi - lo) * np.arange(1, GRID) / GRID
    below = np.flatnonzero(np.array([median_excess(t) for t in grid]) <= 0)
    if below.size == 0 or below[0] == 0:
        raise ValueError(f"no tilt makes the median implied height {mean_m:g} m (camera height {camera_height_m:g} m): "
                         "are these boxes of standing people, and is the camera height right?")
    tilt = _bisect(median_excess, grid[below[0] - 1], grid[below[0]])

    inliers, seen = None, set()
    for rounds in range(1, MAX_ROUNDS + 1):
        new = np.abs(_heights(beta_f, beta_t, tilt, camera_height_m)[0] - mean_m) <= OUTLIER_SIGMAS * sd_m
        if new.tobytes() in seen:  # settled, or back to an earlier round's set
            break
        seen.add(new.tobytes())
        inliers = new
        people, labels, starts, counts = _people(tracks[inliers], mean_m)
        bf, bt = beta_f[inliers], beta_t[inliers]

        def people_heights(t: float) -> tuple[np.ndarray, np.ndarray]:
            return _group_medians(*_heights(bf, bt, t, camera_height_m), labels, starts, counts)

        def score(t: float) -> float:
            h, dh = people_heights(t)
            return float(np.sum(_huber((h - mean_m) / sd_m)[0] * -dh))

        width = math.radians(0.5)
        while not (score(tilt - width) > 0 >= score(tilt + width)) and width < math.radians(20):
            width *= 2
        if score(tilt - width) > 0 >= score(tilt + width):
            tilt = _bisect(score, tilt - width, tilt + width)
    h, d = people_heights(tilt)
    psi, dpsi = _huber((h - mean_m) / sd_m)
    curvature = float(np.sum(dpsi * d * d))
    tilt_sigma = sd_m * math.sqrt(float(np.sum(psi * psi * d * d))) / curvature if curvature > 0 else math.inf
    sensitivity = float(np.sum(dpsi * d)) / curvature if curvature > 0 else math.nan
    return {"tilt": tilt, "tilt_sigma": tilt_sigma, "mean_sensitivity": sensitivity, "inlier_boxes": inliers,
            "n_people": len(people), "rounds": rounds}

def derolled_rows(points: np.ndarray, roll: float, principal: tuple[float, float]) -> np.ndarray:
    """Rows (N,) of image points (N, 2) px of a camera rolled by ``roll`` radians (camera.json's sign: > 0 lowers
    its right side) as the same camera unrolled sees them (the image turned by roll about the principal point
    (cx, cy); square pixels): sin(roll) (u - cx) + cos(roll) (v - cy) + cy. Roll 0: the rows themselves."""
    c, s = math.cos(roll), math.sin(roll)
    return principal[1] + s * (points[:, 0] - principal[0]) + c * (points[:, 1] - principal[1])


def upright_columns(middle: np.ndarray, foot_rows: np.ndarray, head_rows: np.ndarray, tilt, roll: float,
                    focal_px: float, principal: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The foot's and the head's columns (N,) px of upright people whose boxes have the middle column middle (N,)
    and the bottom and top rows foot_rows, head_rows (N,) px (undistorted), on a camera tilted ``tilt`` radians
    below the horizontal (a number, or one per box) and rolled ``roll`` radians (camera.json's sign), focal length
    focal_px, principal point (cx, cy) px. An upright person's foot and head lie on a line to the verticals'
    vanishing point V, (f / tan(tilt)) (sin(roll), cos(roll)) px from the principal point (the unrolled camera's
    nadir, turned by -roll: derolled_rows), and their box bounds the person's outline leaning along that line, so
    its middle column is the foot's and the head's mean: x = x_V + k (y - y_V), k = 2 (m - x_V) / (y_f + y_t -
    2 y_V), in columns x and rows y from the principal point. Multiplied through by t = tan(tilt), so that a level
    camera (V at infinity: every vertical at the roll's slope) needs no special case:
    x(y) = (f (sin(roll) S - 2 cos(roll) m) + 2 (m t - f sin(roll)) y) / (S t - 2 f cos(roll)), S = y_f + y_t.
    Roll 0 and tilt 0: both the middle column."""
    cx, cy = principal
    t, s, c = np.tan(tilt), math.sin(roll), math.cos(roll)
    m, yf, yt = middle - cx, foot_rows - cy, head_rows - cy
    total = yf + yt
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = 1.0 / (total * t - 2 * focal_px * c)
    base, slope = focal_px * (s * total - 2 * c * m) * scale, 2 * (m * t - focal_px * s) * scale
    return cx + base + slope * yf, cx + base + slope * yt


def upright_heights(edges: np.ndarray, tilt: float, roll: float, focal_px: float, principal: tuple[float, float],
                    camera_height_m: float, sole_offset_m: float = 0.0) -> np.ndarray:
    """Implied heights (N,) m of upright people's boxes (N, 4) homocal px (undistorted) on a camera tilted ``tilt``
    and rolled ``roll`` radians (camera.json's sign), focal length focal_px, principal point (cx, cy) px,
    camera_height_m over a flat ground: the foot and the head at their columns (upright_columns) on the box's
    bottom and top rows, turned back to the unrolled camera's rows (derolled_rows), then implied_heights. Roll 0:
    implied_heights of the box's rows (the columns do not matter). sole_offset_m: the box's bottom edge is the
    nearest sole's, d metres nearer along the line of sight than the body's axis at forward distance Y + d (Y =
    h_c / tan(tilt + beta_f), the box's foot point's): the head's ray then meets the axis at
    H_d = H - (h_c - H) d / Y (exact for that geometry; d = 0: H)."""
    x1, y1, x2, y2 = np.asarray(edges, dtype=np.float64).T
    foot, head = upright_columns((x1 + x2) / 2, y2, y1, tilt, roll, focal_px, principal)
    rows = [derolled_rows(np.column_stack(p), roll, principal) for p in ((foot, y2), (head, y1))]
    H = implied_heights(rows[0], rows[1], tilt, focal_px, principal[1], camera_height_m)
    if sole_offset_m == 0.0:
        return H
    inverse_range = np.tan(tilt + np.arctan((rows[0] - principal[1]) / focal_px)) / camera_height_m  # 1 / Y, per m
    return H - (camera_height_m - H) * sole_offset_m * inverse_range


def roll_homography(K: np.ndarray, roll: float) -> np.ndarray:
    """(3, 3) image homography K R_z(roll) K^-1: the image turned by ``roll`` radians about the principal point
    (x right, y down; fx = fy). It takes the image of a camera rolled by ``roll`` (camera.json's sign) to the
    unrolled camera's (derolled_rows); roll_homography(K, -roll) rolls it."""
    c, s = math.cos(roll), math.sin(roll)
    return K @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.linalg.inv(K)


def walk_weight(slopes: np.ndarray, psi: np.ndarray, dpsi: np.ndarray, labels: np.ndarray, n_people: int,
                nuisance: np.ndarray | None = None, prior_curvature: float = 0.0) -> float:
    """The walks' weight c = A_W / B_W in fit_tilt_roll (at most 1; 0 for walks with no spread), from the walk
    residuals' roll slopes s_j = dr_j / droll (n,), psi(r_j) and psi'(r_j) (n,) and their people labels (n,) 0..P-1:
    A_W = sum psi'_j s_j^2, B_W = P times the sample variance over people of sum_j psi_j s_j. nuisance (n,): the
    slopes t_j = dr_j / dd of a parameter d fitted from the same walks alongside (fit_tilt_roll's sole offset; its
    prior's curvature prior_curvature, per unit of d squared): the roll's score is then the one with d profiled out,
    s - k t, k = c I_st / (c I_tt + prior_curvature) (I_st = sum psi' s t), and A_W = sum psi' s (s - k t), the
    roll's information that d leaves (both make c's roll variance (c A_W)^-1 the true one, B_W / A_W^2), at the c
    that is its own weight: the root of A_W / B_W = c in [0, 1] (bisection). Where the walks' range changes with their
    column (a yawed camera's walks along the street) t follows s, and the walks know the roll less than s says."""
    def weight(k: float) -> float:
        profiled = slopes - k * nuisance if k else slopes
        walks = np.bincount(labels, profiled * psi, n_people)
        spread = np.sum((walks - walks.mean()) ** 2) * n_people / (n_people - 1)
        return min(1.0, float(np.sum(dpsi * slopes * profiled)) / spread) if spread > 0 else 0.0

    if nuisance is None:
        return weight(0.0)
    i_st, i_tt = float(np.sum(dpsi * slopes * nuisance)), float(np.sum(dpsi * nuisance**2))
    return _bisect(lambda c: weight(c * i_st / (c * i_tt + prior_curvature)) - c, 0.0, 1.0)


def fit_tilt_roll(edges: np.ndarray, tracks: np.ndarray, focal_px: float, principal: tuple[float, float],
                  camera_height_m: float, mean_m: float, sd_m: float, start: dict) -> dict:
    """The camera's tilt and roll together from people's boxes (N, 4) homocal px (undistorted), tracks (N,), the
    focal length, principal point, camera height and height prior (fit_tilt's), from fit_tilt's result ``start``
    (roll 0), by the module docstring's Roll: the inlier boxes' implied heights H_j(tilt, roll) (upright_heights:
    the derolled rows of their foot and head, each at its column on the vertical through the box) give two kinds of
    residual, each person's
    r_p = (H_p - mu) / sigma (H_p its median inlier box's at the start, the mean of the two middle ones for an even
    count, held through the fit: chosen anew as the roll moves, the median box moved along the walk and the rounds
    did not settle on scene3's boxes) and each box's r_j = (H_j - mean_p H) / (BOX_HEIGHT_SD mu), its height about
    its person's mean (the walk: the person's own height cancels), H_j with its sole d metres nearer than the axis
    (upright_heights' sole_offset_m; d shared by all, a third unknown, d >= 0). The equations
    sum psi(r) m grad r + P_d = 0 in (tilt, roll, d) weigh the people's by m = (1, 1, 0) and the walks' by
    m = (0, c, c): the walks give the roll and d alone, c their information as if their boxes were independent over
    its spread among the people (walk_weight, of the roll with d profiled out), set at the start of each inlier
    round; P_d the Gaussian prior SOLE_OFFSET_M's on d ((d - d_0) / s_d^2, curvature 1 / s_d^2); solved by
    iteratively reweighted least squares (Huber's weights min(1, k / |r|); grad r by central differences,
    DIFF_STEP; a step that takes d below 0 puts d at 0 and solves the tilt and roll with d held there; until a step
    is below STEP_TOLERANCE, SOLE_STEP_TOLERANCE_M for d), the inlier boxes (within
    OUTLIER_SIGMAS sd of mu) updated until they settle or return to an earlier set. Uncertainty: the sandwich
    A^-1 (sum_p s_p s_p^T) A^-T over the people (over tilt and roll alone where d ends at 0, held there),
    A = sum psi' m grad r grad r^T plus the prior's curvature and
    s_p = sum psi m grad r over the person's own residual and its boxes' (a person's boxes are not independent); the
    prior mean's effect d(tilt, roll) / dmu = A^-1 sum_p psi'_p grad r_p / sigma.
    Returns a dict: tilt, roll (radians; roll in camera.json's sign), cov (2, 2) radians^2 (people), sensitivity (2,)
    radians per metre, sole_offset_m (d), inlier_boxes (N,) bool (each box's implied height within OUTLIER_SIGMAS sd
    of mu at the fitted tilt and roll), n_people, walk_weight (c), rounds. ValueError as fit_tilt, or for a roll
    beyond MAX_ROLL_DEG."""
    beta, box_sd = np.array([start["tilt"], 0.0, SOLE_OFFSET_M[0]]), BOX_HEIGHT_SD * mean_m
    prior = np.diag([0.0, 0.0, SOLE_OFFSET_M[1] ** -2])  # the sole's offset's prior: its curvature

    def box_heights(b: np.ndarray, e: np.ndarray, sole_offset_m: float = 0.0) -> np.ndarray:
        return upright_heights(e, b[0], b[1], focal_px, principal, camera_height_m, sole_offset_m)

    pick = np.flatnonzero(start["inlier_boxes"])  # fit_tilt's inlier boxes: a person's height is their median's
    _, labels, starts, counts = _people(tracks[pick], mean_m)
    lo, hi = pick[_median_pairs(box_heights(beta, edges[pick]), labels, starts, counts)]

    def held(b: np.ndarray, which: np.ndarray) -> np.ndarray:  # the people's held heights H_p
        return 0.5 * (box_heights(b, edges[lo[which]]) + box_heights(b, edges[hi[which]]))

    people, inliers, seen = np.ones(len(lo), bool), start["inlier_boxes"], set()
    for rounds in range(1, MAX_ROUNDS + 1):
        used = people  # this round's people (people is the next round's after it)
        kept = _people(tracks[lo[used]], mean_m)[0]  # their tracks, sorted
        walk = inliers & np.isin(tracks, kept)  # the inlier boxes of those people
        e, n, P, labels = edges[walk], int(walk.sum()), len(kept), np.searchsorted(kept, tracks[walk])
        counts = np.maximum(np.bincount(labels, minlength=P), 1)
        owner = np.concatenate([labels, np.arange(P)])  # the person of each residual: the boxes', then the people's

        def residuals(b: np.ndarray) -> np.ndarray:  # (n + P,): the walks' r_j, the people's r_p
            H = box_heights(b, e, b[2])
            return np.concatenate([(H - (np.bincount(labels, H, P) / counts)[labels]) / box_sd,
                                   (held(b, used) - mean_m) / sd_m])

        def gradient(b: np.ndarray) -> np.ndarray:  # (n + P, 3)
            return np.column_stack([(residuals(b + e) - residuals(b - e)) / (2 * DIFF_STEP) for e in np.eye(3) * DIFF_STEP])

        J, psi, dpsi = gradient(beta), *_huber(residuals(beta))
        c = walk_weight(J[:n, 1], psi[:n], dpsi[:n], labels, P, J[:n, 2], prior[2, 2])
        m = np.where(np.arange(n + P)[:, None] < n, [0.0, c, c], [1.0, 1.0, 0.0])
        for _ in range(MAX_ROUNDS):
            r, J = residuals(beta), gradient(beta)
            weights = np.minimum(1.0, HUBER_K / np.maximum(np.abs(r), 1e-300))
            A = (m * J * weights[:, None]).T @ J + prior
            g = (m * J).T @ _huber(r)[0] + prior @ (beta - [0.0, 0.0, SOLE_OFFSET_M[0]])
            step = -np.linalg.solve(A, g)
            if beta[2] + step[2] < 0:  # d >= 0: d to its bound, the tilt and roll with it held there
                step = np.append(-np.linalg.solve(A[:2, :2], g[:2]), -beta[2])
            beta = beta + step
            if (np.abs(step) < [STEP_TOLERANCE, STEP_TOLERANCE, SOLE_STEP_TOLERANCE_M]).all():
                break
        if abs(math.degrees(beta[1])) > MAX_ROLL_DEG:
            raise ValueError(f"the people imply a roll of {math.degrees(beta[1]):.1f} degrees, beyond "
                             f"{MAX_ROLL_DEG:g}: are these boxes of standing people?")
        seen.add(people.tobytes() + inliers.tobytes())
        people = np.abs(held(beta, np.ones(len(lo), bool)) - mean_m) <= OUTLIER_SIGMAS * sd_m
        inliers = np.abs(box_heights(beta, edges) - mean_m) <= OUTLIER_SIGMAS * sd_m
        if people.tobytes() + inliers.tobytes() in seen:  # settled, or back to an earlier round's
            break
    J, (psi, dpsi) = gradient(beta), _huber(residuals(beta))
    free = 3 if beta[2] > 0 else 2  # d at its bound is held there: the tilt and roll's uncertainty without it
    A_inv = np.linalg.inv(((m * J * dpsi[:, None]).T @ J + prior)[:free, :free])
    scores = np.column_stack([np.bincount(owner, m[:, k] * J[:, k] * psi, P) for k in range(free)])  # (P, free) each person's share
    return {"tilt": float(beta[0]), "roll": float(beta[1]), "cov": (A_inv @ scores.T @ scores @ A_inv.T)[:2, :2],
            "sensitivity": (A_inv @ (J[n:, :free].T @ dpsi[n:]) / sd_m)[:2], "sole_offset_m": float(beta[2]),
            "inlier_boxes": inliers, "n_people": P, "walk_weight": c, "rounds": rounds}


class PedestrianCorrector(Corrector):
    """The clicked mapping corrected from people's boxes, with no reference point (module docstring).

    Args:
        height_mean_m, height_sd_m: the prior of the people's heights, metres (default: adults, NCD-RisC 2016,
            DEFAULT_HEIGHT_MEAN_M and DEFAULT_HEIGHT_SD_M).
        height_mean_sigma_m: the 1-sigma uncertainty of height_mean_m itself, metres (DEFAULT_HEIGHT_MEAN_SIGMA_M:
            its sources are at its declaration; 0 for a mean measured on these people): part of
            horizon_sigma_px_ and of ground_uncertainty. Bounds: SETTINGS.
        estimate_roll: fit the camera's roll with its tilt (fit_tilt_roll) when the people's foot columns spread
            over ROLL_SPREAD of the image width (image_size given); otherwise, and by default, roll 0.
        drop_hidden_feet: True: leave out the boxes whose feet a nearer person's box of the same frame may hide
            (homocal.geometry.hidden_feet on the camera's pixels, after the track linking of all boxes; fit needs
            frames). "auto": fit with every box; if and only if that fit is refused for its outliers
            (max_outlier_share) and the boxes have frames, fit again with those boxes left out and keep that fit
            if it passes the same check (else refuse, naming both); without frames as False (hidden_feet_ says
            "no frames"). False: every box. Default False: "auto" gives every bit of its fit where that fit is
            not refused, but of the twelve refused fits it fitted (docs/pedestrians.md, "Hidden feet") two are
            far off with sigmas five times smaller (24 px with 4 px, 13 px with 2.4 px), the confident far-off
            answers the refusal is for.
        box_margin_px: how much taller than their people the detector's boxes are, px in the camera's frame
            (SETTINGS' bounds; default 0: boxes as tight as the people): fit takes half of it off each box's top
            and bottom edge (homocal.geometry.boxes.trim_boxes) after the border test, the hidden feet and the track
            linking (on the boxes as given), before the undistortion and the fit; a box no taller keeps no height, an
            outlier. Saved with the correction: homocal measure and GroundTracker take it off their boxes too. A
            background subtractor at half resolution gives boxes some 2 px too tall (simgen's rgb detector,
            docs/measure-accuracy.md), which the fit otherwise reads as a tilt (2 px of horizon per px).
        model: the corrected mapping (``transformer_``: the image trapezoid that maps with it onto the clicked
            map trapezoid, whose site-map frame is kept):
            "camera" (the default): the camera's own ground mapping (K, the camera height, the fitted tilt,
                roll 0), placed with its ground point on camera_origin and turned about it (yaw_deg_) so that
                the clicked corners, turned back by G^-1 (below), fall nearest the map corners: the clicked
                trapezoid then only gives the map's axes, and none of its other click errors stay; K and the
                camera height must be right (given, or from a clicked mapping that is a camera).
            "rotation": H_clicked . G, G = K R_x(delta) K^-1, delta the angle between the clicked mapping's
                horizon and the fitted one at the principal column: the clicked mapping with only its tilt
                error undone; its other click errors stay, and where they had compensated the horizon's error
                the correction breaks that (docs/pedestrians.md has the measurements of both).

    Fit with ``fit(transformer, xyxy, convention=..., ...)``.

    Attributes after fit (or load): horizon_row_ (the fitted horizon, px at the principal column),
    clicked_horizon_row_, horizon_sigma_px_ (its 1-sigma uncertainty: horizon_sigma_people_px_, from the
    people's spread and number, and height_mean_sigma_m times the horizon's move per metre of the prior mean,
    in quadrature), mean_sensitivity_px_per_cm_ (the horizon's move, px, per cm the prior mean is off: not
    reduced by more people), tilt_deg_, rotation_deg_ (delta), focal_px_, principal_point_ (cx, cy), camera_height_m_,
    yaw_deg_ (model "camera"; NaN for "rotation"), focal_source_ and camera_height_source_ ("given" or
    "clicked mapping"), n_boxes_, n_border_ (cut by the image border, not used), n_hidden_ (their feet may be
    hidden, not used: drop_hidden_feet; 0 otherwise), hidden_feet_ (one of HIDDEN_FEET: whether the fit left them out),
    first_refusal_ (drop_hidden_feet "auto" that left them out: why the fit with every box was refused; else None), n_outliers_ (beyond
    OUTLIER_SIGMAS), n_people_ (tracks), n_people_used_, roll_estimated_, roll_deg_ (0 unless estimated; camera.json's
    roll_deg: > 0 lowers the camera's right side, the horizon's slope in the image is -tan(roll_deg_)), roll_sigma_deg_
    (NaN unless estimated), tilt_roll_cov_ and tilt_roll_sensitivity_ (the people's 2x2 covariance of (tilt,
    roll), rad^2, and their move per metre of the prior mean; None unless estimated), transformer_, m, plus those
    of ``Corrector`` (error_before_ and error_after_ on check points if fit had them, else NaN). After fit only
    (not saved): box_status_ (N,) str, each box's part in the fit, one of BOX_STATUS: "used", "outlier", "border" or "hidden".
    """

    method = "pedestrians"
    param_names = ("height_mean_m", "height_sd_m", "model", "height_mean_sigma_m", "estimate_roll", "drop_hidden_feet",
                   "box_margin_px")

    def __init__(self, height_mean_m: float = DEFAULT_HEIGHT_MEAN_M, height_sd_m: float = DEFAULT_HEIGHT_SD_M,
                 model: str = "camera", height_mean_sigma_m: float = DEFAULT_HEIGHT_MEAN_SIGMA_M,
                 estimate_roll: bool = False, drop_hidden_feet: bool | str = False, box_margin_px: float = 0.0) -> None:
        if model not in MODELS:
            raise ValueError(f"model {model!r}: expected one of {', '.join(MODELS)}")
        self.model, self.estimate_roll, self.drop_hidden_feet = model, *(
            SETTINGS[name].check(name, value) for name, value in (("estimate_roll", estimate_roll),
                                                                   ("drop_hidden_feet", drop_hidden_feet)))
        self.height_mean_m, self.height_sd_m, self.height_mean_sigma_m, self.box_margin_px = (
            float(SETTINGS[name].check(name, value)) for name, value in (("height_mean_m", height_mean_m), ("height_sd_m", height_sd_m),
                                ("height_mean_sigma_m", height_mean_sigma_m), ("box_margin_px", box_margin_px)))
        if self.height_sd_m > self.height_mean_m / 4:
            raise OptionError("height_sd_m", height_sd_m, f"expected at most height_mean_m / 4 = {self.height_mean_m / 4:g} m")

    def fit(self, transformer: ViewTransformer, xyxy: np.ndarray, *, convention: str, frames: np.ndarray | None = None,
            track_ids: np.ndarray | None = None, camera_height_m: float | None = None, K: np.ndarray | None = None,
            image_size: tuple[int, int] | None = None, image_points: np.ndarray | None = None,
            ground_points: np.ndarray | None = None, camera_origin=(0.0, 0.0),
            max_outlier_share: float = MAX_OUTLIER_SHARE, lens: Lens | None = None) -> PedestrianCorrector:
        """Fit from people's boxes.

        Args:
            transformer: the clicked image-to-ground ViewTransformer (target in metres).
            xyxy: (N, 4) boxes (x1, y1, x2, y2) of people, pixels, in ``convention`` (homocal.geometry.boxes:
                "corners" for supervision's Detections.xyxy of YOLO-like models, "homocal" for simgen's).
                The bottom edge y2 is the foot row, the top edge y1 the head row.
            frames: (N,) int video frame of each box (to link boxes into tracks, and for drop_hidden_feet, which
                needs them); None: each box is a person.
            track_ids: (N,) int person of each box (one height per person); None: linked from frames.
            camera_height_m: the optical centre's height over the ground; None: from the clicked mapping with K.
            K: (3, 3) intrinsics (fx = fy, roll 0); None: principal point at the centre of image_size, focal
                length from the clicked mapping.
            image_size: (width, height) px; boxes within BORDER_PX (homocal.geometry.boxes) of its border are not used.
            image_points, ground_points, camera_origin: optional check points (N, 2) px, (N, 2) m, (2,) m: not
                used by the fit, their mean errors before and after are error_before_ and error_after_.
            max_outlier_share: the largest share of outlier boxes, and of rejected people, a fit accepts (1: none
                refused, to measure what a refused fit reaches; research/pedestrians.py --accept-outliers).
            lens: the camera's lens (homocal.geometry.Lens; its K and image size those given: ValueError naming
                both otherwise, Lens.check_matches): the boxes are undistorted
                (homocal.geometry.undistort_boxes: the foot point and the head row exactly; ValueError naming
                xyxy for a box beyond the lens's fold) after the border test and the track linking, before the
                fit; the transformer, the check points and the corrected mapping are then in undistorted pixels.
                None: a pinhole (the boxes as given).
        Returns self. ValueError naming the argument for bad input, and for a fit that cannot be trusted: fewer
        than MIN_PEOPLE inlier people, or more than max_outlier_share of the used boxes or of the people
        outliers (the median start and the inlier rounds break down there: HOG boxes gave a horizon 82 px off
        on scene2 with 61 of 102 people rejected, 7 px off on scene1 with 61 % of the boxes outliers; 60 s of
        segmentation boxes have 3-5 % outlier boxes and 27-29 % rejected people, the rgb detector's 25-37 %
        and 22-36 %, docs/pedestrians.md).
        """
        if not isinstance(transformer, ViewTransformer):
            raise TypeError(f"transformer: expected a homocal.ViewTransformer, got {type(transformer).__name__}")
        if not (isinstance(max_outlier_share, (int, float)) and 0 < max_outlier_share <= 1):
            raise ValueError(f"max_outlier_share must be a share in (0, 1], got {max_outlier_share!r}")
        edges = _check_boxes(xyxy, convention)
        n = len(edges)
        frames = _check_labels(frames, n, "frames")
        tracks = _check_labels(track_ids, n, "track_ids")
        size = _check_image_size(image_size)
        if lens is not None:
            lens.check_matches(K, size)
        self.focal_source_ = "clicked mapping" if K is None else "given"
        K = intrinsics(transformer.m, size, K)
        principal, focal = (float(K[0, 2]), float(K[1, 2])), float(K[1, 1])
        self.focal_px_, self.principal_point_ = focal, principal
        if camera_height_m is None:
            self.camera_height_source_ = "clicked mapping"
            try:
                self.camera_height_m_ = _check_camera_height(camera_height_from_homography(transformer.m, self.K))
            except OptionError as e:
                raise ValueError(f"the clicked mapping implies a camera height of {e.value:.3g} m, "
                                 f"{e.expected.removeprefix('expected ')}: give camera_height_m") from None
        else:
            self.camera_height_source_, self.camera_height_m_ = "given", _check_camera_height(camera_height_m)
        clicked_row = float(transformer.horizon_row(principal[0]))
        if not (edges[:, 3] > transformer.horizon_row((edges[:, 0] + edges[:, 2]) / 2)).any():  # roughly, in any lens
            raise ValueError(f"xyxy: all {n} boxes have their bottom edge on or above the clicked mapping's horizon "
                             f"(row {clicked_row:.1f} at the principal column): none stands on its ground")
        border = np.zeros(n, bool) if size is None else on_border(edges, size)
        if border.all():
            raise ValueError(f"xyxy: all {n} boxes touch the {size[0]}x{size[1]} image's border (cut by it)")
        if self.drop_hidden_feet is True and frames is None:
            raise ValueError("frames: needed with drop_hidden_feet (a nearer person hides feet in the same frame)")
        auto = self.drop_hidden_feet == "auto"
        looked = frames is not None and self.drop_hidden_feet is not False
        hidden = hidden_feet(edges, frames) & ~border if looked else np.zeros(n, bool)
        if self.drop_hidden_feet is True and (border | hidden).all():
            raise ValueError(f"xyxy: all {n} boxes touch the image's border or may have their feet hidden by a nearer "
                             "person's")
        if tracks is None:
            tracks = np.arange(n) if frames is None else link_tracks(frames, edges, max_gap=LINK_GAP)
        edges = trim_boxes(edges, self.box_margin_px)  # after the border, the hidden feet and the tracks: the boxes' own
        if lens is not None:  # the camera's pixels to the undistorted image, as homocal.boxes.read_boxes does
            edges = undistort_boxes(edges, lens)
        self.hidden_feet_, self.first_refusal_ = "no frames" if auto and frames is None else "kept", None
        drop = hidden if self.drop_hidden_feet is True else np.zeros(n, bool)
        fit, used, refusal = self._attempt(edges, tracks, border | drop, size, focal, principal, max_outlier_share)
        if refusal is not None and auto and hidden.any() and not (border | hidden).all():
            first = refusal
            try:
                fit, used, refusal = self._attempt(edges, tracks, border | hidden, size, focal, principal, max_outlier_share)
            except ValueError as e:
                raise ValueError(f"xyxy: {first} with every box; without the {int(hidden.sum())} boxes whose feet a "
                                 f"nearer person may hide (--drop-hidden-feet auto): {e}") from None
            if refusal is not None:
                refusal = (f"{first} with every box, {refusal} without the {int(hidden.sum())} boxes whose feet a nearer "
                           "person may hide (--drop-hidden-feet auto)")
            drop, self.first_refusal_ = hidden, first
        if refusal is not None:
            hide = ""
            if frames is not None and self.drop_hidden_feet is False:
                hide = "; leave out the boxes whose feet a nearer person may hide (drop_hidden_feet, --drop-hidden-feet yes)"
            elif auto and not hidden.any():
                hide = " (--drop-hidden-feet auto: " + ("the boxes have no frames, no hidden feet looked for)" if frames is None
                                                        else "no box's feet a nearer person may hide)")
            raise ValueError(f"xyxy: {self._refusal(refusal, 'the fitted tilt', max_outlier_share)}{hide}")
        if drop.any() or self.drop_hidden_feet is True:
            self.hidden_feet_ = "dropped"
        self.roll_deg_, self.tilt_roll_cov_, self.tilt_roll_sensitivity_ = 0.0, None, None
        if self.roll_estimated_:
            self.roll_deg_ = math.degrees(fit["roll"])
            self.tilt_roll_cov_, self.tilt_roll_sensitivity_ = fit["cov"], fit["sensitivity"]
        self.base_transformer_ = transformer
        self.camera_origin_ = check_camera_origin(camera_origin)
        self.horizon_row_ = principal[1] + (horizon_row(fit["tilt"], focal, principal[1]) - principal[1]) / math.cos(fit["roll"] if self.roll_estimated_ else 0.0)
        secant2 = 1.0 + math.tan(fit["tilt"]) ** 2
        self.horizon_sigma_people_px_ = focal * secant2 * fit["tilt_sigma"]
        self.mean_sensitivity_px_per_cm_ = abs(focal * secant2 * fit["mean_sensitivity"]) / 100.0
        self._set_horizon_sigma()
        self.n_boxes_, self.n_border_, self.n_hidden_ = n, int(border.sum()), int(drop.sum())
        self.n_outliers_ = int(used.sum() - fit["inlier_boxes"].sum())
        used_, outlier, cut, hid = BOX_STATUS
        self.box_status_ = np.where(border, cut, np.where(drop, hid, outlier))
        self.box_status_[np.flatnonzero(used)[fit["inlier_boxes"]]] = used_
        self.n_people_, self.n_people_used_ = len(np.unique(tracks[used])), fit["n_people"]
        self._set_transformer()
        self._check_points(image_points, ground_points)
        return self

    def _attempt(self, edges: np.ndarray, tracks: np.ndarray, left_out: np.ndarray, size, focal: float,
                 principal: tuple[float, float], max_outlier_share: float) -> tuple[dict, np.ndarray, str | None]:
        """One fit of the boxes edges (N, 4) (undistorted) with tracks (N,) but those left_out (N,) bool: fit_tilt,
        and fit_tilt_roll when estimate_roll and the used foot columns spread (sets roll_estimated_); returns the fit
        (fit_tilt's dict, tilt_sigma and mean_sensitivity the tilt's where roll was fitted), the used boxes (N,) bool
        and the refusal: "OUT of the OF boxes|people (tracks) are outliers" for the first share beyond
        max_outlier_share, None if neither is."""
        foot_rows, head_rows = edges[:, 3], edges[:, 1]
        middle = (edges[:, 0] + edges[:, 2]) / 2
        used = ~left_out & np.isfinite(middle) & np.isfinite(foot_rows) & np.isfinite(head_rows)
        fit = fit_tilt(foot_rows[used], head_rows[used], tracks[used], focal, principal[1], self.camera_height_m_,
                       self.height_mean_m, self.height_sd_m)
        spread = np.subtract(*np.percentile(middle[used], [75, 25])) if used.any() else 0.0
        self.roll_estimated_ = bool(self.estimate_roll and size is not None and spread >= ROLL_SPREAD * size[0])
        if self.roll_estimated_:
            fit = fit_tilt_roll(edges[used], tracks[used], focal, principal, self.camera_height_m_,
                                self.height_mean_m, self.height_sd_m, fit)
            fit["tilt_sigma"], fit["mean_sensitivity"] = math.sqrt(fit["cov"][0, 0]), fit["sensitivity"][0]
        n_people = len(np.unique(tracks[used]))
        rejected = {"boxes": (int(used.sum() - fit["inlier_boxes"].sum()), int(used.sum())),
                    "people (tracks)": (n_people - fit["n_people"], n_people)}
        for what, (out, of) in rejected.items():
            if out > max_outlier_share * of:
                return fit, used, f"{out} of the {of} {what} are outliers"
        return fit, used, None

    def _refusal(self, outliers: str, at: str, max_outlier_share: float) -> str:
        """Why a fit is refused: outliers ("OUT of the OF boxes|people are outliers") beyond max_outlier_share, their
        implied heights judged at ``at`` (the fitted tilt, a horizon)."""
        return (f"{outliers} (implied height beyond {OUTLIER_SIGMAS:g} sd of {self.height_mean_m:g} m at {at}): more "
                f"than {max_outlier_share:.0%}, where the robust fit can follow the outliers; use boxes that reach from "
                "the top of the head to the lowest sole, or check the camera height")

    def with_mapping(self, transformer: ViewTransformer) -> PedestrianCorrector:
        """The same fitted horizon on another clicked mapping of the same camera (a re-clicked trapezoid): a copy
        whose correction takes that mapping's horizon to the fitted one, with no check points. Only for a fit
        whose focal length and camera height were given (theirs from the clicked mapping would change with it):
        ValueError otherwise."""
        if not isinstance(transformer, ViewTransformer):
            raise TypeError(f"transformer: expected a homocal.ViewTransformer, got {type(transformer).__name__}")
        if "clicked mapping" in (self.focal_source_, self.camera_height_source_):
            raise ValueError("this fit read the focal length or the camera height from its clicked mapping: fit again")
        other = copy.copy(self)
        other.base_transformer_ = transformer
        other._set_transformer()
        other.error_before_ = other.error_after_ = other.calibration_improvement_ = math.nan
        return other

    def from_horizon(self, transformer: ViewTransformer, horizon_row_px: float, horizon_sigma_px: float, K: np.ndarray,
                     camera_height_m: float, n_people: int, camera_origin=(0.0, 0.0), roll_deg: float | None = None,
                     roll_sigma_deg: float = 0.0, n_outliers: int = 0,
                     max_outlier_share: float = MAX_OUTLIER_SHARE) -> PedestrianCorrector:
        """Set up as fit would from a horizon row (px at the principal column, with its 1-sigma) found elsewhere from
        n_people people (each one box: homocal.watch.OnlineCalibrator's estimate), with K and the camera height given
        and no check points; with roll_deg (degrees, camera.json's sign; its 1-sigma roll_sigma_deg) the camera's
        roll found with the row, stored as a fit with roll stores it: the (tilt, roll) covariance from the two
        sigmas (their correlation left out), no sensitivity to the prior mean; n_outliers of the people beyond
        OUTLIER_SIGMAS of the prior at that horizon, refused (ValueError, as fit refuses) beyond max_outlier_share of
        them. Returns self; ValueError naming the argument for bad input."""
        if not isinstance(transformer, ViewTransformer):
            raise TypeError(f"transformer: expected a homocal.ViewTransformer, got {type(transformer).__name__}")
        K = np.asarray(K, dtype=np.float64)
        self.focal_px_, self.principal_point_ = float(K[1, 1]), (float(K[0, 2]), float(K[1, 2]))
        self.focal_source_ = self.camera_height_source_ = "given"
        self.camera_height_m_ = _check_camera_height(camera_height_m)
        self.horizon_row_ = number(horizon_row_px, "horizon_row_px")
        self.horizon_sigma_people_px_ = number(horizon_sigma_px, "horizon_sigma_px", minimum=0)
        self.mean_sensitivity_px_per_cm_ = math.nan  # the estimate's sigma is all there is: horizon_sigma_px_ is it
        self._set_horizon_sigma()
        roll = None
        if roll_deg is not None:  # d tilt / d row = -cos(roll) / (f sec^2(tilt)) at the principal column
            phi = math.radians(number(roll_deg, "roll_deg"))
            secant2 = 1 + ((self.principal_point_[1] - self.horizon_row_) * math.cos(phi) / self.focal_px_) ** 2
            tilt_sigma = self.horizon_sigma_people_px_ * math.cos(phi) / (self.focal_px_ * secant2)
            roll = {"roll_deg": roll_deg, "tilt_roll_sensitivity_rad_per_m": [0.0, 0.0], "tilt_roll_cov_rad2":
                    np.diag([tilt_sigma, math.radians(number(roll_sigma_deg, "roll_sigma_deg", minimum=0))]) ** 2}
        self._set_roll_state(roll)
        self.n_boxes_ = self.n_people_ = self.n_people_used_ = integer(n_people, "n_people", MIN_PEOPLE, 2**62)
        self.n_outliers_ = integer(n_outliers, "n_outliers", 0, self.n_people_)
        if self.n_outliers_ > max_outlier_share * self.n_people_:
            raise ValueError(self._refusal(f"{self.n_outliers_} of the {self.n_people_} people are outliers",
                                           f"the horizon row {self.horizon_row_:.1f} px", max_outlier_share))
        self.n_border_ = self.n_hidden_ = 0
        self.hidden_feet_, self.first_refusal_ = "kept", None
        self.base_transformer_, self.camera_origin_ = transformer, check_camera_origin(camera_origin)
        self._set_transformer()
        self._check_points(None, None)
        return self

    @property
    def roll_sigma_deg_(self) -> float:
        """The fitted roll's 1-sigma uncertainty, degrees (the people's and the prior mean's); NaN when roll was not
        estimated."""
        if not self.roll_estimated_:
            return math.nan
        s = self.tilt_roll_sensitivity_
        return math.degrees(math.sqrt(self.tilt_roll_cov_[1, 1] + (self.height_mean_sigma_m * s[1]) ** 2))

    @property
    def K(self) -> np.ndarray:
        """(3, 3) the intrinsics the fit used."""
        f, (cx, cy) = self.focal_px_, self.principal_point_
        return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])

    def _set_roll_state(self, roll) -> None:
        """roll_estimated_, roll_deg_, tilt_roll_cov_, tilt_roll_sensitivity_ from the fitted state's "roll" (None:
        not estimated, as files written without it); ValueError for what fit could not write."""
        self.roll_estimated_, self.roll_deg_, self.tilt_roll_cov_, self.tilt_roll_sensitivity_ = False, 0.0, None, None
        if roll is None:
            return
        try:
            deg = number(roll["roll_deg"], "fitted.roll.roll_deg")
            cov = np.array(roll["tilt_roll_cov_rad2"], dtype=np.float64)
            sens = np.array(roll["tilt_roll_sensitivity_rad_per_m"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"field fitted.roll: expected roll_deg, tilt_roll_cov_rad2 and tilt_roll_sensitivity_rad_per_m ({e})") from None
        if not (abs(deg) <= MAX_ROLL_DEG and cov.shape == (2, 2) and sens.shape == (2,) and np.isfinite(cov).all()
                and np.isfinite(sens).all() and np.allclose(cov, cov.T) and (np.linalg.eigvalsh(cov) >= -1e-18).all()):
            raise ValueError(f"field fitted.roll: expected |roll_deg| <= {MAX_ROLL_DEG:g}, a symmetric (2, 2) covariance "
                             "and (2,) sensitivities, all finite")
        self.roll_estimated_, self.roll_deg_, self.tilt_roll_cov_, self.tilt_roll_sensitivity_ = True, deg, cov, sens

    def _set_horizon_sigma(self) -> None:
        """horizon_sigma_px_: the people's sigma and the prior mean's (height_mean_sigma_m times the horizon's move
        per metre of it) added in quadrature; the people's alone where the sensitivity is unknown (NaN)."""
        prior = self.mean_sensitivity_px_per_cm_ * 100.0 * self.height_mean_sigma_m
        self.horizon_sigma_px_ = math.hypot(self.horizon_sigma_people_px_, prior if math.isfinite(prior) else 0.0)

    def _set_transformer(self) -> None:
        """clicked_horizon_row_, tilt_deg_, rotation_deg_, yaw_deg_ and transformer_ from the base transformer, K,
        the camera height and horizon_row_ (the class docstring's two models): delta = the clicked horizon's
        elevation minus the fitted one's (G = tilt_homography(K, delta) takes the fitted horizon to the clicked
        one at the principal column)."""
        f, (cx, cy) = self.focal_px_, self.principal_point_
        base = self.base_transformer_
        self.clicked_horizon_row_ = float(base.horizon_row(cx))
        roll = math.radians(self.roll_deg_)
        tilt = math.atan((cy - self.horizon_row_) * math.cos(roll) / f)
        delta = math.atan((cy - self.clicked_horizon_row_) / f) - tilt
        self.tilt_deg_, self.rotation_deg_ = math.degrees(tilt), math.degrees(delta)
        source = apply_homography(tilt_homography(self.K, -delta), base.source)  # the clicked corners turned back
        self.yaw_deg_ = math.nan
        if self.model == "camera":
            level = self.K @ np.array([[1.0, 0.0, 0.0], [0.0, 0.0, self.camera_height_m_], [0.0, 1.0, 0.0]])
            camera = np.linalg.inv(level) @ tilt_homography(self.K, -tilt) @ roll_homography(self.K, roll)  # image -> ground
            w, t = apply_homography(camera, source), base.target - self.camera_origin_
            yaw = float(np.angle(np.sum((t[:, 0] + 1j * t[:, 1]) * np.conj(w[:, 0] + 1j * w[:, 1]))))
            turn = np.array([[math.cos(yaw), -math.sin(yaw), self.camera_origin_[0]],
                             [math.sin(yaw), math.cos(yaw), self.camera_origin_[1]], [0.0, 0.0, 1.0]])
            self.yaw_deg_ = math.degrees(yaw)
            source = apply_homography(np.linalg.inv(turn @ camera), base.target)
        self.transformer_ = ViewTransformer(source, base.target)

    def _check_points(self, image_points, ground_points) -> None:
        """error_before_ / error_after_ / calibration_improvement_ on the check points, NaN without them."""
        if image_points is None and ground_points is None:
            self.error_before_ = self.error_after_ = self.calibration_improvement_ = math.nan
            return
        q, p, g, _ = check_calibration(self.base_transformer_, image_points, ground_points, self.camera_origin_)
        self.error_before_, self.error_after_ = mean_error(p, g), mean_error(self._transform(q), g)
        self.calibration_improvement_ = improvement_percent(self.error_before_, self.error_after_)

    @property
    def m(self) -> np.ndarray:
        """(3, 3) corrected image-to-ground homography (unit Frobenius norm, w > 0 on the ground side)."""
        return self.transformer_.m

    def _transform(self, q: np.ndarray) -> np.ndarray:
        return self.transformer_.transform_points(q)

    def ground_uncertainty(self, image_points: np.ndarray, click_sigma_px: float = 1.5, point_sigma_px: float = 1.0,
                           map_sigma_px: float = 0.0) -> np.ndarray:
        """First-order covariance (N, 2, 2), metres^2, of the corrected ground points of image points (N, 2) px:
        ``Corrector.ground_uncertainty`` (homocal.ground_uncertainty of transformer_: click_sigma_px on each
        corrected trapezoid corner coordinate, map_sigma_px on each map corner coordinate, point_sigma_px on the
        point) plus the fitted horizon's own uncertainty, horizon_sigma_px_ as a tilt sigma
        sigma_theta = horizon_sigma_px_ / (f sec^2(theta)) (the module docstring's Uncertainty), J J^T
        sigma_theta^2 with J the derivative of the corrected point along the tilt (central differences of
        transformer_ turned by tilt_homography(K, -+1e-6))."""
        q = as_points(image_points, "image_points")
        cov = super().ground_uncertainty(q, click_sigma_px, point_sigma_px, map_sigma_px)
        J, angles = self.angle_modes(q)
        return cov + J @ angles @ np.swapaxes(J, 1, 2)

    def angle_modes(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The fitted camera angles' share of ``ground_uncertainty`` at image points q (N, 2) px: J (N, 2, 2),
        the derivative of the corrected points (metres) along (tilt, roll) (radians), and the angles'
        covariance (2, 2) (radians^2); the share is J cov J^T."""
        f, cy = self.focal_px_, self.principal_point_[1]
        roll = math.radians(self.roll_deg_)
        tilt = math.atan((cy - self.horizon_row_) * math.cos(roll) / f)
        step = 1e-6
        turns = {"tilt": lambda e: roll_homography(self.K, -roll) @ tilt_homography(self.K, -e) @ roll_homography(self.K, roll),
                 "roll": lambda e: roll_homography(self.K, e)}  # the camera's tilt or roll moved by e, as the mapping sees it
        J = np.stack([(apply_homography(self.m @ turn(step), q) - apply_homography(self.m @ turn(-step), q)) / (2 * step)
                      for turn in turns.values()], axis=-1)  # (N, 2, 2): d(x, y) / d(tilt, roll)
        if self.roll_estimated_:
            s = self.tilt_roll_sensitivity_
            angles = self.tilt_roll_cov_ + self.height_mean_sigma_m**2 * np.outer(s, s)
        else:
            tilt_sigma = self.horizon_sigma_px_ / (f * (1.0 + math.tan(tilt) ** 2))
            angles = np.diag([tilt_sigma**2, 0.0])
        return J, angles

    # ---- JSON ----------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """As Corrector.to_dict; error_before, error_after (null without check points)."""
        data = super().to_dict()
        data["error_before"], data["error_after"] = float_or_none(self.error_before_), float_or_none(self.error_after_)
        return data

    @classmethod
    def _from_fields(cls, data: dict) -> PedestrianCorrector:
        """Corrector._from_fields, with error_before and error_after both null (no check points) or both numbers."""
        missing = [data.get(k) is None for k in ("error_before", "error_after")]
        if any(missing) and not all(missing):
            raise ValueError("fields error_before and error_after: both numbers (check points) or both null")
        obj = super()._from_fields({**data, **({"error_before": 0.0, "error_after": 0.0} if all(missing) else {})})
        if all(missing):
            obj.error_before_ = obj.error_after_ = math.nan
        return obj

    def _fitted_state(self) -> dict:
        sigma, people = self.horizon_sigma_px_, self.horizon_sigma_people_px_
        return {"horizon_row": self.horizon_row_, "horizon_sigma_px": sigma if math.isfinite(sigma) else None,
                "horizon_sigma_people_px": people if math.isfinite(people) else None,
                "mean_sensitivity_px_per_cm": float_or_none(self.mean_sensitivity_px_per_cm_),
                "focal_px": self.focal_px_, "principal_point": list(self.principal_point_),
                "focal_source": self.focal_source_, "camera_height_m": self.camera_height_m_,
                "camera_height_source": self.camera_height_source_, "n_boxes": self.n_boxes_,
                "n_border": self.n_border_, "n_hidden": self.n_hidden_, "hidden_feet": self.hidden_feet_,
                "first_refusal": self.first_refusal_, "n_outliers": self.n_outliers_,
                "n_people": self.n_people_, "n_people_used": self.n_people_used_,
                "roll": None if not self.roll_estimated_ else {
                    "roll_deg": self.roll_deg_, "tilt_roll_cov_rad2": self.tilt_roll_cov_.tolist(),
                    "tilt_roll_sensitivity_rad_per_m": self.tilt_roll_sensitivity_.tolist()}}

    def _set_fitted_state(self, state: dict) -> None:
        """Check what fit could have produced: finite numbers, a focal length > 0, a camera height in bounds,
        counts that add up, a source fit names; then rebuild transformer_ (a quad ViewTransformer accepts)."""
        self.focal_px_ = number(state["focal_px"], "fitted.focal_px")
        if not self.focal_px_ > 0:
            raise ValueError(f"field fitted.focal_px: must be > 0, got {self.focal_px_}")
        pp = state["principal_point"]
        if not (isinstance(pp, list) and len(pp) == 2):
            raise ValueError(f"field fitted.principal_point: expected [cx, cy], got {pp!r}")
        self.principal_point_ = tuple(number(x, "fitted.principal_point") for x in pp)
        self.horizon_row_ = number(state["horizon_row"], "fitted.horizon_row")
        sens = state["mean_sensitivity_px_per_cm"]
        self.mean_sensitivity_px_per_cm_ = math.nan if sens is None else number(sens, "fitted.mean_sensitivity_px_per_cm", minimum=0)
        key = "horizon_sigma_people_px" if "horizon_sigma_people_px" in state else "horizon_sigma_px"  # older files: the people's
        sigma = state[key]
        self.horizon_sigma_people_px_ = math.inf if sigma is None else number(sigma, f"fitted.{key}", minimum=0)
        self._set_horizon_sigma()
        for key in ("focal_source", "camera_height_source"):
            if state[key] not in ("given", "clicked mapping"):
                raise ValueError(f"field fitted.{key}: expected 'given' or 'clicked mapping', got {state[key]!r}")
        self.focal_source_, self.camera_height_source_ = state["focal_source"], state["camera_height_source"]
        try:
            self.camera_height_m_ = _check_camera_height(state["camera_height_m"])
        except ValueError as e:
            raise ValueError(f"field fitted.camera_height_m: {e}") from None
        self.n_boxes_ = integer(state["n_boxes"], "fitted.n_boxes", 1, 2**62)
        self.n_border_ = integer(state["n_border"], "fitted.n_border", 0, self.n_boxes_ - 1)
        self.n_hidden_ = integer(state.get("n_hidden", 0), "fitted.n_hidden", 0, self.n_boxes_ - self.n_border_ - 1)  # older files: 0
        left = self.n_boxes_ - self.n_border_ - self.n_hidden_
        self.hidden_feet_ = state.get("hidden_feet", "dropped" if self.drop_hidden_feet is True else "kept")  # older files
        if self.hidden_feet_ not in HIDDEN_FEET:
            raise ValueError(f"field fitted.hidden_feet: expected one of {', '.join(HIDDEN_FEET)}, got {self.hidden_feet_!r}")
        self.first_refusal_ = state.get("first_refusal")
        if not (self.first_refusal_ is None or isinstance(self.first_refusal_, str) and self.hidden_feet_ == "dropped"):
            raise ValueError(f"field fitted.first_refusal: expected null, or text with hidden_feet 'dropped', got "
                             f"{self.first_refusal_!r}")
        self.n_outliers_ = integer(state["n_outliers"], "fitted.n_outliers", 0, left)
        self.n_people_ = integer(state["n_people"], "fitted.n_people", 1, left)
        self.n_people_used_ = integer(state["n_people_used"], "fitted.n_people_used", MIN_PEOPLE, self.n_people_)
        self._set_roll_state(state.get("roll"))
        try:
            self._set_transformer()
        except ValueError as e:
            raise ValueError(f"field fitted.horizon_row: {e}") from None


def _check_boxes(xyxy, convention: str) -> np.ndarray:
    """Box edges (N, 4) homocal px of xyxy; ValueError for no boxes, a non-finite or huge coordinate, or a box
    upside down or empty (y2 <= y1 or x2 <= x1), naming the first."""
    edges = box_edges(xyxy, convention=convention)
    if len(edges) == 0:
        raise ValueError("xyxy: no boxes")
    bad = np.flatnonzero(~(np.abs(edges) <= 1e9).all(axis=1))
    if bad.size:
        raise ValueError(f"xyxy: box {bad[0]} (from 0) = {np.asarray(xyxy)[bad[0]].tolist()} is not finite (or beyond 1e9 px)")
    bad = np.flatnonzero(~((edges[:, 3] > edges[:, 1]) & (edges[:, 2] > edges[:, 0])))
    if bad.size:
        raise ValueError(f"xyxy: box {bad[0]} (from 0) = {np.asarray(xyxy)[bad[0]].tolist()} is upside down or empty (needs "
                         "x1 < x2 and y1 < y2: y1 the top edge, y2 the bottom edge, image rows counted down)")
    return edges


def _check_labels(labels, n: int, name: str) -> np.ndarray | None:
    """labels (N,) as int64 (None stays None); ValueError for another length or non-integers."""
    if labels is None:
        return None
    arr = np.asarray(labels)
    if arr.shape != (n,) or arr.dtype.kind not in "iu":
        raise ValueError(f"{name}: expected ({n},) integers, one per box, got {arr.dtype} of shape {arr.shape}")
    return arr.astype(np.int64)


def _check_image_size(image_size) -> tuple[int, int] | None:
    if image_size is None:
        return None
    if not (len(image_size) == 2 and all(isinstance(x, (int, np.integer)) and 0 < x <= 100_000 for x in image_size)):
        raise ValueError(f"image_size: expected (width, height), two integers in [1, 100000] px, got {image_size!r}")
    return int(image_size[0]), int(image_size[1])


def _check_camera_height(value) -> float:
    """camera_height_m as a float within SETTINGS' bounds; OptionError naming camera_height_m otherwise."""
    return float(SETTINGS["camera_height_m"].check("camera_height_m", value))
