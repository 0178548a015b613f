"""Benchmark of `homocal study`: the table1-fit preset's wall time (all six methods) against a straightforward
per-sample implementation of the paper's two methods (cv2.getPerspectiveTransform + cv2.perspectiveTransform
in a Python loop).

    python benchmarks/bench_study.py SCENE1_DATASET SCENE2_DATASET [--variants 1000] [--n-test 2000]

The datasets are `simgen generate` outputs of scenes/scene1 and scenes/scene2 (40 and 39 calibration
points: 1001 x (C(40,3) + C(39,3)) = 19,038,019 samples).
"""
from __future__ import annotations

import argparse
import itertools
import os
import statistics
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from homocal.keyed_rng import seed_from_key, shuffled_order
from homocal.study.engine import run_study
from homocal.study.perturb import draw_variant, perturbed_quads
from homocal.study.inputs import StudyParams, StudyScene, preset_params


def cv2_map(H: np.ndarray, points: np.ndarray) -> np.ndarray:
    return cv2.perspectiveTransform(points.reshape(-1, 1, 2), H).reshape(-1, 2)


def cv2_loss(v: np.ndarray, target: np.ndarray, q: np.ndarray, g: np.ndarray) -> float:
    H = cv2.getPerspectiveTransform(v.reshape(4, 2).astype(np.float32), target.astype(np.float32))
    return float(np.linalg.norm(cv2_map(H, q) - g, axis=1).mean())


def regression(p, g, o, signed):
    d = np.linalg.norm(p - o, axis=1)
    e = np.linalg.norm(g - o, axis=1) - d if signed else np.linalg.norm(p - g, axis=1)
    S2, S3, S4, T1, T2 = (d**2).sum(), (d**3).sum(), (d**4).sum(), (d * e).sum(), (d**2 * e).sum()
    det = S4 * S2 - S3**2
    a, b = (0.0, T1 / S2) if det <= 1e-12 * S4 * S2 else ((T2 * S2 - T1 * S3) / det, (S4 * T1 - S3 * T2) / det)
    return (a, b) if signed else (max(a, 0.0), max(b, 0.0))


def radial(p, o, a, b):
    d = np.linalg.norm(p - o, axis=1)
    return p + (p - o) / d[:, None] * (a * d**2 + b * d)[:, None]


def baseline_sample(scene: StudyScene, params: StudyParams, variant: int, triple) -> None:
    """Every method of one sample, per-sample cv2 calls in a Python loop (the straightforward way)."""
    dp = params.descent
    base = scene.base_image_quad(params, variant)
    image, map_quad = perturbed_quads(base, scene.map_quad, draw_variant(params.seed, scene.name, variant)[0])
    target = scene.site_map.to_metres(map_quad)
    q, g, o = scene.cal_image[list(triple)], scene.cal_ground[list(triple)], scene.origin
    H = cv2.getPerspectiveTransform(image.astype(np.float32), target.astype(np.float32))
    p, pt = cv2_map(H, q), cv2_map(H, scene.test_image)
    e_test = lambda pts: np.linalg.norm(pts - scene.test_ground, axis=1).mean()  # noqa: E731
    before = e_test(pt)
    results = [100 * (before - e_test(radial(pt, o, *regression(p, g, o, signed)))) / before for signed in (False, True)]
    v0 = image.ravel()
    cands = np.repeat(v0[None], len(dp["grid_offsets"]) ** 4, axis=0)
    cands[:, [0, 1, 4, 5]] += np.array(list(itertools.product(dp["grid_offsets"], repeat=4)))
    v = cands[int(np.argmin([cv2_loss(c, target, q, g) for c in cands]))].copy()
    L, step, pass_index, evals, order = cv2_loss(v, target, q, g), dp["initial_step"], 0, 0, np.empty(8, np.int64)
    seed = np.uint64(seed_from_key(params.seed, scene.name, variant, *map(int, triple)))
    done = False
    while not done:
        shuffled_order(seed, pass_index, order)
        improved = False
        for k in order:
            for sign in (1.0, -1.0):
                cand = v.copy()
                cand[k] += sign * step
                if abs(cand[k] - v0[k]) > dp["delta_max"]:
                    continue
                if evals == dp["max_evals"]:
                    done = True
                    break
                Lc = cv2_loss(cand, target, q, g)
                evals += 1
                if Lc < L:
                    v, L, improved = cand, Lc, True
                    break
            if done:
                break
        pass_index += 1
        if not improved and not done:
            step /= 2
            done = step < dp["min_step"]
    Hd = cv2.getPerspectiveTransform(v.reshape(4, 2).astype(np.float32), target.astype(np.float32))
    results.append(100 * (before - e_test(cv2_map(Hd, scene.test_image))) / before)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("datasets", nargs="+", help="the two scenes' simgen datasets")
    ap.add_argument("--variants", type=int, default=1000)
    ap.add_argument("--n-test", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=1, help="full-study runs (median printed)")
    ap.add_argument("--baseline-samples", type=int, default=40)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        paths = args.datasets
        params = preset_params("table1-fit", n_variants=args.variants, n_test=args.n_test)
        run_study(paths, tmp / "warmup", StudyParams(n_variants=1, n_test=args.n_test), progress=False)  # compile/load
        walls, cpus = [], []
        for r in range(args.repeats):
            start, cpu = time.perf_counter(), time.process_time()
            study = run_study(paths, tmp / f"study{r}", params, preset="table1-fit", progress=False)
            walls.append(time.perf_counter() - start)
            cpus.append(time.process_time() - cpu)
        wall, cpu, n = statistics.median(walls), statistics.median(cpus), study["samples_done"]
        print(f"study: {n:,} samples ({args.variants} variants, {args.n_test} test points, all methods) "
              f"in {wall:.1f} s wall (median of {len(walls)}): {n / wall:,.0f} samples/s; "
              f"{cpu:.1f} s CPU on {os.cpu_count()} cores (wall if the cores were ours alone: >= {cpu / os.cpu_count():.1f} s)")
        scene = StudyScene.from_dataset(paths[0], params)
        rng = np.random.default_rng(0)
        per_sample = []
        for _ in range(args.baseline_samples):
            variant, triple = int(rng.integers(0, args.variants + 1)), scene.triples[rng.integers(len(scene.triples))]
            start = time.perf_counter()
            baseline_sample(scene, params, variant, triple)
            per_sample.append(time.perf_counter() - start)
        base_rate = 1 / statistics.median(per_sample)
        print(f"baseline (cv2 per sample in a Python loop): {base_rate:,.1f} samples/s (median of {len(per_sample)} samples)")
        print(f"speed ratio: {n / wall / base_rate:,.0f}x (target >= 1000x); full-study target <= 60 s")


if __name__ == "__main__":
    main()
