"""Least-change beside the paper's regression, regression-intercept, horizon and descent on random study samples.

A sample is what the study draws (homocal.study): a trapezoid variant v (the hand-placed trapezoid, or with
the clicked horizon 6 px above the true one, plus the variant's 0-3 px corner perturbations of both
quads) and a triple of the scene's calibration points; the path improvement is over the study's test points
(n_test 2000, out to 50 m). Printed per scene, setting and method: path improvement median, mean, 1st and
5th percentile, share positive, and the calibration improvement median (percent). Settings: hand-placed
(horizon_shift None) and the clicked horizon 6 px above the true one ("6"), both at the dataset's own site-map
scale. --sweep adds least-change with other priors (the search that chose LeastChangeCorrector's defaults);
--foot-source takes a detector's points as the study does (its calibration points are then the segmentation
detector's).

    python research/compare_least_change.py DATA/scene1 DATA/scene2 [--samples 300] [--seed 1] [--sweep] [--foot-source segmentation]
"""
import argparse

import numpy as np

from homocal import DescentCorrector, HorizonCorrector, LeastChangeCorrector, RegressionCorrector, ViewTransformer
from homocal.arguments import number
from homocal.keyed_rng import seed_from_key
from homocal.study.inputs import StudyParams, StudyScene

METHODS = {
    "regression (paper)": lambda key: RegressionCorrector(),
    "regression-intercept": lambda key: RegressionCorrector(signed=True, intercept=True),
    "horizon": lambda key: HorizonCorrector(),
    "descent": lambda key: DescentCorrector(seed=seed_from_key(*key)),
    "least-change": lambda key: LeastChangeCorrector(),
}

def least_change(point_sigma_m: float, map_sigma_m: float):
    return lambda key: LeastChangeCorrector(point_sigma_m=point_sigma_m, map_sigma_m=map_sigma_m)


SWEEP = {  # (point_sigma_m, map_sigma_m), click_sigma_px 1; the defaults are (0.05, 0.2)
    f"least-change ps {ps:g} ms {ms:g}": least_change(ps, ms)
    for ps, ms in ((0.1, 0.1), (0.03, 0.1), (0.3, 0.1), (0.1, 0.0), (0.1, 0.3), (0.03, 0.3), (0.05, 0.3))
}


def samples(path: str, shift: str | None, n: int, seed: int, foot_source: str):
    """n study samples of one scene and setting: (scene, vt, q (3, 2) px, g (3, 2) m, descent key)."""
    params = StudyParams(n_test=2000, horizon_shift=shift, foot_source=foot_source)
    sc = StudyScene.from_dataset(path, params)
    rng = np.random.default_rng(seed)
    for _ in range(n):
        v = int(rng.integers(0, params.n_variants + 1))
        tri = sc.triples[rng.integers(len(sc.triples))]
        image, mq = sc.variant_quads(params, v)
        sel = list(tri)
        yield sc, ViewTransformer(image, sc.site_map.to_metres(mq)), sc.cal_image[sel], sc.cal_ground[sel], (
            0, sc.name, v, *map(int, tri))


def run(path: str, shift: str | None, n: int, seed: int, methods: dict, foot_source: str) -> None:
    path_imp = {name: [] for name in methods}
    cal_imp = {name: [] for name in methods}
    for sc, vt, q, g, key in samples(path, shift, n, seed, foot_source):
        before = np.linalg.norm(vt.transform_points(sc.test_image) - sc.test_ground, axis=1).mean()
        for name, make in methods.items():
            c = make(key).fit(vt, q, g, sc.origin)
            after = np.linalg.norm(c.transform_points(sc.test_image) - sc.test_ground, axis=1).mean()
            path_imp[name].append(100 * (before - after) / before)
            cal_imp[name].append(c.calibration_improvement_)
    setting = "hand-placed" if shift is None else f"horizon shift {shift} px"
    print(f"\n{sc.name}, {setting}, {foot_source} foot points, {n} samples, seed {seed}: path improvement (%) "
          "and calibration improvement median (%)\n")
    print("| method | median | mean | 1st pct | 5th pct | positive | calibration median |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name in methods:
        x = np.array(path_imp[name])
        print(f"| {name} | {np.median(x):.1f} | {x.mean():.1f} | {np.percentile(x, 1):.1f} | "
              f"{np.percentile(x, 5):.1f} | {100 * np.mean(x > 0):.1f} | {np.median(cal_imp[name]):.1f} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+", help="simgen dataset folders")
    parser.add_argument("--samples", type=number(int, 1), default=300, help="samples per scene and setting (default 300)")
    parser.add_argument("--seed", type=number(int, 0), default=1, help="seed of the sample draws (default 1)")
    parser.add_argument("--sweep", action="store_true", help="also least-change with other point and map sigmas")
    parser.add_argument("--setting", choices=("both", "hand", "shift6"), default="both",
                        help="hand-placed trapezoids, a horizon shift of 6 px, or both (default)")
    parser.add_argument("--foot-source", default="exact", help="exact (default) or a detector of the datasets")
    args = parser.parse_args()
    methods = {**METHODS, **(SWEEP if args.sweep else {})}
    for path in args.scenes:
        for shift in {"both": (None, "6"), "hand": (None,), "shift6": ("6",)}[args.setting]:
            run(path, shift, args.samples, args.seed, methods, args.foot_source)


if __name__ == "__main__":
    main()
