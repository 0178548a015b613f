"""`homocal study DATASET... --out DIR`: the paper's evaluation (Sections 5-6) over simgen datasets."""
from __future__ import annotations

import argparse

from homocal.study.engine import PRESETS, dry_run_counts, run_study
from homocal.study.scene import StudyParams


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "study", help="run the correction study (every trapezoid variant x every calibration triple)",
        description="Per scene: the hand-placed trapezoid and N perturbed variants, every combination of three "
                    "calibration points, regression (faithful and signed), descent and hybrid; per-sample results "
                    "as Parquet shards in --out. --preset paper runs the paper's 1000 variants.")
    p.add_argument("datasets", nargs="+", metavar="DATASET", help="simgen dataset folders (one per scene)")
    p.add_argument("--out", required=True, help="results directory")
    p.add_argument("--preset", choices=sorted(PRESETS), default="quick",
                   help="paper: 1000 variants, 2000 test points; quick: 50 variants (default)")
    p.add_argument("--variants", type=int, help="perturbed variants per scene (overrides the preset)")
    p.add_argument("--seed", type=int, default=0, help="run seed (variants, descent orders, test subsample)")
    p.add_argument("--foot-source", default="exact",
                   help="exact (projected contact points), segmentation or rgb (a detector's matched detections)")
    p.add_argument("--n-test", type=int, help="test points per scene, a seeded subsample (default: the preset's, 2000)")
    p.add_argument("--max-test-distance", type=_metres_or_none, default=StudyParams.max_test_distance, metavar="M",
                   help="test points at most M metres from the camera (default 50, the paper's operating range, Fig. 2); "
                        "'none' for all")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--workers", type=int, help="start a local Dask cluster of N worker processes")
    group.add_argument("--scheduler", help="address of a running Dask scheduler")
    p.add_argument("--resume", action="store_true", help="continue the study in --out, skipping finished shards")
    p.add_argument("--dry-run", action="store_true", help="print the sample counts and exit")
    p.set_defaults(handler=handle)


def _metres_or_none(text: str) -> float | None:
    if text.lower() == "none":
        return None
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be a positive number of metres or 'none', got {text}")
    return value


def handle(args: argparse.Namespace) -> int:
    preset = PRESETS[args.preset]
    params = StudyParams(seed=args.seed, foot_source=args.foot_source,
                         n_variants=preset["n_variants"] if args.variants is None else args.variants,
                         n_test=preset["n_test"] if args.n_test is None else args.n_test,
                         max_test_distance=args.max_test_distance)
    if params.n_variants < 0 or params.n_test < 1 or (args.workers is not None and args.workers < 1):
        raise ValueError("--variants must be >= 0, --n-test and --workers >= 1")
    if args.dry_run:
        counts = dry_run_counts(args.datasets, params)
        for scene, n in counts.items():
            print(f"{scene}: {n:,} samples")
        print(f"total: {sum(counts.values()):,} samples ({params.n_variants + 1} trapezoids per scene)")
        return 0
    study = run_study(args.datasets, args.out, params, preset=args.preset, resume=args.resume,
                      workers=args.workers, scheduler=args.scheduler)
    rate = study["samples_done"] / max(study["elapsed_seconds"], 1e-9)
    print(f"{study['samples_done']:,} of {study['samples_total']:,} samples in {args.out} "
          f"({study['elapsed_seconds']:.1f} s, {rate:,.0f} samples/s); complete: {study['complete']}")
    print(f"degenerate variants: {study['n_degenerate']}")
    for d in study["degenerate"]:
        print(f"  {d['scene']} variant {d['variant']}: {d['reason']}")
    return 0
