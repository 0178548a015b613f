"""CPU time of the study's test-point loops and of a whole shard, per call and per sample (thread CPU time, so
the figures hold on a shared machine better than wall time).

    python benchmarks/bench_path_loops.py DATA/scene1 [--variant 3] [--triples 2000]

Prints the median of 7 repeats for each path kernel over the scene's test points (the table1-fit preset's 2000),
least change's fit (method_kernels.least_change3) per triple, and run_tables' CPU per sample (every method) on
the first --triples triples of one variant.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from homocal.study import kernels
from homocal.study import method_kernels as mk
from homocal.study.inputs import StudyScene, preset_params
from homocal.study.shards import prepare_variant, run_tables


def cpu_per_call(f, *args, calls: int = 2000, repeats: int = 7) -> float:
    """Median over repeats of thread CPU seconds per call of f(*args)."""
    f(*args)  # compile or load
    times = []
    for _ in range(repeats):
        start = time.thread_time()
        for _ in range(calls):
            f(*args)
        times.append((time.thread_time() - start) / calls)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset")
    ap.add_argument("--variant", type=int, default=3)
    ap.add_argument("--triples", type=int, default=2000)
    args = ap.parse_args()
    params = preset_params("table1-fit")
    scene = StudyScene.from_dataset(args.dataset, params)
    tables = prepare_variant(scene, params, args.variant)
    test, n = tables.test, tables.test.shape[1]
    dH = np.zeros(9, np.float32)
    dH[8] = np.float32(1e-4)
    loops = {"regression_path (one regression; the study runs two)": (kernels.regression_path, test, 1e-3, 1e-2, False),
             "regression_path_intercept": (mk.regression_path_intercept, test, 1e-3, 1e-2, 1e-2),
             "descent_path (also the horizon correction's)": (kernels.descent_path, test, dH)}
    for name, (f, *a) in loops.items():
        print(f"{name}: {cpu_per_call(f, *a) * 1e6:.2f} us CPU per call ({n} test points)")
    idx = scene.triples[: args.triples]
    lc = params.least_change
    z0, z, Bt = np.concatenate((tables.v0, tables.t0)), np.empty(16), np.empty((3, 3))
    fits = [(scene.cal_image[t], scene.cal_ground[t]) for t in idx[:200]]

    def least_change_fits():
        for q3, g3 in fits:
            mk.least_change3(z0, q3, g3, lc["click_sigma_px"], lc["map_sigma_m"], lc["point_sigma_m"],
                             lc["iterations"], z, Bt)

    per_fit = cpu_per_call(least_change_fits, calls=5) / len(fits)
    steps = np.mean([mk.least_change3(z0, q3, g3, lc["click_sigma_px"], lc["map_sigma_m"], lc["point_sigma_m"],
                                      lc["iterations"], z, Bt)[0] for q3, g3 in fits])
    print(f"least_change3: {per_fit * 1e6:.2f} us CPU per fit, {steps:.1f} Gauss-Newton steps on average (the first "
          f"{len(fits)} triples of variant {args.variant})")
    per_sample = cpu_per_call(run_tables, scene, tables, params, args.variant, idx, calls=1) / len(idx)
    print(f"run_tables, every method: {per_sample * 1e6:.1f} us CPU per sample ({len(idx)} triples of variant {args.variant})")


if __name__ == "__main__":
    main()
