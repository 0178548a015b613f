"""The best a radial correction can do on a study's test points (docs/reproduction.md).

The paper's regression moves each mapped point p along its bearing from the camera origin o by
c(d) = a d^2 + b d, d = ||p - o|| (eqs. (23)-(24)); the signed and intercept forms use the same family (a, b
free in sign; + c). Per trapezoid variant, the coefficients that minimise the mean test-point error of the
study's metric over the test points themselves (an oracle that knows every test point's true position) give
that variant's ceiling: no three calibration points can do better, so every sample's path improvement under
the family is at most it. The mean error after c(theta) = A theta (A_i = [d_i^2, d_i] or [d_i^2, d_i, 1]) is
sum_i sqrt((t_i + A_i theta)^2 + q_i^2) / N, with t_i = u_i . (p_i - g_i), u_i = (p_i - o)/d_i and q_i the error
across the bearing (euclidean), or t_i = d_i - ||g_i - o||, q_i = 0 (range): convex in theta, minimised by
iteratively reweighted least squares (a majorise-minimise scheme: the mean never rises). With range errors
the study scores | ||g - o|| - |d + c| |, the same while d + c >= 0: there the bound holds for the samples whose
correction moves no test point past the camera (all but rare catastrophic fits).
"""
from __future__ import annotations

import numpy as np

from homocal.geometry.homography import apply_homography, homography_from_quads
from homocal.study.inputs import StudyParams, StudyScene

FAMILIES = {"a d^2 + b d": 2, "a d^2 + b d + c": 3}  # the correction families and their number of terms
QUADRATIC = "a d^2 + b d"  # the paper's
CEILINGS = (*FAMILIES, "any radial")


def along_and_across(p: np.ndarray, g: np.ndarray, o: np.ndarray, metric: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(d, t, q) (N,) m of mapped points p (N, 2) against true g (N, 2), camera origin o (2,): range d, the error
    along the bearing t (moving p by c along it leaves |t + c|) and across it q (euclidean; 0 for range)."""
    d = np.hypot(*(p - o).T)
    if metric == "range":
        return d, d - np.hypot(*(g - o).T), np.zeros_like(d)
    u = (p - o) / d[:, None]
    r = p - g
    t = np.einsum("ij,ij->i", u, r)
    return d, t, np.abs(u[:, 0] * r[:, 1] - u[:, 1] * r[:, 0])


def least_mean_error(A: np.ndarray, t: np.ndarray, q: np.ndarray, tol: float = 1e-12, most: int = 5000) -> float:
    """min over theta of mean(sqrt((t + A theta)^2 + q^2)) (m), A (N, K); IRLS from the least-squares start."""
    theta = np.linalg.lstsq(A, -t, rcond=None)[0]
    error = np.sqrt((t + A @ theta) ** 2 + q**2)
    mean = error.mean()
    for _ in range(most):
        w = 1.0 / np.maximum(error, 1e-12)
        theta = np.linalg.solve((A * w[:, None]).T @ A, -(A * w[:, None]).T @ t)
        error = np.sqrt((t + A @ theta) ** 2 + q**2)
        new = error.mean()
        if mean - new < tol:
            return min(mean, new)
        mean = new
    return mean


def weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    """The lower weighted median of values (N,) with weights (N,) > 0: the median over samples of per-variant
    values weighted by the samples per variant (numpy's median of an even count would average two)."""
    order = np.argsort(values)
    cum = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cum, 0.5 * cum[-1])])


def variant_ceilings(scene: StudyScene, params: StudyParams, variant: int) -> dict[str, float]:
    """Path-improvement ceilings (%) of one variant: per correction family, and for any radial correction."""
    image, map_quad = scene.variant_quads(params, variant)
    H = homography_from_quads(image, scene.site_map.to_metres(map_quad))
    d, t, q = along_and_across(apply_homography(H, scene.test_image), scene.test_ground, scene.origin, params.metric)
    before = np.sqrt(t**2 + q**2).mean()
    terms = np.column_stack([d**2, d, np.ones_like(d)])
    out = {name: 100.0 * (1.0 - least_mean_error(terms[:, :k], t, q) / before) for name, k in FAMILIES.items()}
    out["any radial"] = 100.0 * (1.0 - q.mean() / before)
    return out
