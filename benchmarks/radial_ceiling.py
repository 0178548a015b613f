"""How much of a study's path error a radial correction can remove at best (README, "Reproducing Table 1").

Run: python benchmarks/radial_ceiling.py STUDY [--variants N]
     (STUDY a complete `homocal study` results folder; its study.json names the datasets and parameters)

The paper's regression moves each mapped point p along its bearing from the camera origin o by
c(d) = a d^2 + b d, d = ||p - o|| (eqs. (23)-(24)); the signed and intercept forms use the same family
(a, b free in sign; + c). Per trapezoid variant this script finds the coefficients that minimise the mean
test-point error of the study's metric over the test points themselves, an oracle that knows every test
point's true position, so that no three calibration points can do better on that variant: for every sample
(variant, triple) the methods' path improvement is at most the variant's ceiling, and the median over the
study's samples at most the median of the ceilings weighted by the samples per variant. Also the ceiling
of any radial correction at all (every point moved along its bearing to its true range).

The mean error after c(theta) = A theta (A_i = [d_i^2, d_i] or [d_i^2, d_i, 1]) is
sum_i sqrt((t_i + A_i theta)^2 + q_i^2) / N with t_i = u_i . (p_i - g_i), u_i = (p_i - o)/d_i and q_i the
error across the bearing (euclidean), or t_i = d_i - ||g_i - o||, q_i = 0 (range): convex in theta, minimised
by iteratively reweighted least squares (a majorise-minimise scheme: the mean never rises) until it changes
by less than 1e-12 m.

Prints, per scene and over both: the study's median path improvement of the three radial methods, and the
medians (over samples) of the two ceilings.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from homocal.arguments import number
from homocal.geometry.homography import apply_homography, homography_from_quads
from homocal.study.engine import load_scenes
from homocal.study.inputs import StudyParams
from homocal.study.metrics import load_study, shard_files

RADIAL = ("regression", "regression_signed", "regression_intercept")
FAMILIES = {"a d^2 + b d": 2, "a d^2 + b d + c": 3}  # the correction families and their number of terms


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
    mean = np.sqrt((t + A @ theta) ** 2 + q**2).mean()
    for _ in range(most):
        w = 1.0 / np.maximum(np.sqrt((t + A @ theta) ** 2 + q**2), 1e-12)
        theta = np.linalg.solve((A * w[:, None]).T @ A, -(A * w[:, None]).T @ t)
        new = np.sqrt((t + A @ theta) ** 2 + q**2).mean()
        if mean - new < tol:
            return min(mean, new)
        mean = new
    return mean


def variant_ceilings(scene, params: StudyParams, variant: int) -> dict[str, float]:
    """Path-improvement ceilings (%) of one variant: per correction family, and for any radial correction."""
    image, map_quad = scene.variant_quads(params, variant)
    H = homography_from_quads(image, scene.site_map.to_metres(map_quad))
    d, t, q = along_and_across(apply_homography(H, scene.test_image), scene.test_ground, scene.origin, params.metric)
    before = np.sqrt(t**2 + q**2).mean()
    terms = np.column_stack([d**2, d, np.ones_like(d)])
    out = {name: 100.0 * (1.0 - least_mean_error(terms[:, :k], t, q) / before) for name, k in FAMILIES.items()}
    out["any radial"] = 100.0 * (1.0 - q.mean() / before)
    return out


def weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    order = np.argsort(values)
    cum = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cum, 0.5 * cum[-1])])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("study", type=Path, metavar="STUDY")
    parser.add_argument("--variants", type=number(int, 1), help="only the first N shards per scene (default: all)")
    args = parser.parse_args()
    try:
        study = load_study(args.study)
        if not study.get("complete"):
            raise ValueError("the study is not complete: finish it with homocal study --resume")
        params = StudyParams.from_dict(study)
        scenes = load_scenes([d["path"] for d in study["datasets"]], params)
        shards = shard_files(args.study, study)
    except (ValueError, KeyError, OSError) as e:
        raise SystemExit(f"{args.study}: not a complete study folder ({e})") from None
    print(f"{args.study}: metric {params.metric}; medians over samples (variant, triple) of path improvement (%); "
          f"a ceiling is the oracle's, per variant\n")
    names = [*(f"ceiling, {f}" for f in FAMILIES), "ceiling, any radial"]
    print(f"| scene | variants | {' | '.join(f'study: {m}' for m in RADIAL)} | {' | '.join(names)} |")
    print("|---|---:|" + "---:|" * (len(RADIAL) + len(names)))
    pooled: dict[str, list] = {k: [] for k in (*RADIAL, *names, "weight")}
    for scene in scenes:
        files = shards[scene.name][: args.variants]
        paths = {m: [] for m in RADIAL}
        for path in files:
            table = pq.read_table(path, columns=[f"path_{m}" for m in RADIAL] + ["variant"])
            variant = int(table.column("variant")[0].as_py())
            for m in RADIAL:
                paths[m].append(table.column(f"path_{m}").to_numpy())
            ceil = variant_ceilings(scene, params, variant)
            for name, key in zip(names, (*FAMILIES, "any radial")):
                pooled[name].append(ceil[key])
            pooled["weight"].append(table.num_rows)
        for m in RADIAL:
            pooled[m].append(np.concatenate(paths[m]))
        weights = np.asarray(pooled["weight"][-len(files):], float)
        cells = [f"{np.nanmedian(pooled[m][-1]):.1f}" for m in RADIAL]
        cells += [f"{weighted_median(np.asarray(pooled[n][-len(files):]), weights):.1f}" for n in names]
        print(f"| {scene.name} | {len(files)} | {' | '.join(cells)} |")
    weights = np.asarray(pooled["weight"], float)
    cells = [f"{np.nanmedian(np.concatenate(pooled[m])):.1f}" for m in RADIAL]
    cells += [f"{weighted_median(np.asarray(pooled[n]), weights):.1f}" for n in names]
    print(f"| both | {len(weights)} | {' | '.join(cells)} |")


if __name__ == "__main__":
    main()
