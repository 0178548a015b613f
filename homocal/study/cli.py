"""`homocal study DATASET... --out DIR`: the paper's evaluation (Sections 5-6) over simgen datasets."""
from __future__ import annotations

import argparse
import math

from homocal.arguments import number
from homocal.dataset import calibration_source
from homocal.progress import add_progress_option, show_progress
from homocal.study.engine import PRESETS, dry_run_counts, run_study
from homocal.study.inputs import MAX_IMAGE_WIDTH, MAX_MAP_SCALE, METRICS, StudyParams, descent_settings
from homocal.study.perturb import PERTURBATIONS


MAX_VARIANTS = 100_000  # 100x the paper's 1000 trapezoid variants per scene (one shard each)
MAX_N_TEST = 1_000_000  # test points per scene


def add_study_options(p: argparse.ArgumentParser, sweep: bool = False) -> None:
    """The options that set StudyParams (shared by study and sweep). Absent options are left out of the
    namespace (argparse.SUPPRESS), so the preset's values apply unless an option is given. sweep: the
    sweepable ones are read as text (a list of values, see sweep.expand_values)."""
    quiet = dict(default=argparse.SUPPRESS)

    def typed(kind):
        return str if sweep else kind

    p.add_argument("--preset", choices=sorted(PRESETS), default="quick",
                   help="paper: the paper's protocol (1000 variants, 2000 test points) with the open choices closest "
                        f"to its Table 1 (see README): base error (horizon {PRESETS['paper']['horizon_shift']} px "
                        f"above), the perturbation read as {PRESETS['paper']['perturbation']}, site-map scale "
                        f"({PRESETS['paper']['map_scale']:g} px/m) and descent's largest move "
                        f"({PRESETS['paper']['descent']['delta_max']:g} px), errors as {PRESETS['paper']['metric']} errors; "
                        "quick: 50 variants, no base error, the dataset's site map, descent's defaults, euclidean "
                        "errors (default)")
    p.add_argument("--variants", dest="n_variants", type=number(int, 0, MAX_VARIANTS), metavar="N",
                   help="perturbed variants per scene (overrides the preset)", **quiet)
    p.add_argument("--seed", type=typed(int), help="run seed (variants, base errors, descent orders, test subsample; default 0)", **quiet)
    p.add_argument("--foot-source", help="exact (projected contact points, default) or a detector of the datasets: "
                                         "segmentation, rgb, hog (if generated with it) or an imported one; its "
                                         "test points are its matched detections, the calibration points are then "
                                         "the segmentation detector's", **quiet)
    p.add_argument("--n-test", type=number(int, 1, MAX_N_TEST), help="test points per scene, a seeded subsample of "
                   "those the dataset has (all of them if it has fewer; default 2000)", **quiet)
    p.add_argument("--max-test-distance", type=typed(metres_or_none), metavar="M", **quiet,
                   help="test points at most M metres from the camera (default 50, the paper's operating range, Fig. 2); "
                        "'none' for all")
    p.add_argument("--test-lateral-max", type=typed(metres_or_none), metavar="M", **quiet,
                   help="test points at most M metres to the side of the calibration line x = 0 (default: none)")
    p.add_argument("--horizon-shift", metavar="SPEC", **quiet,
                   help="the clicked trapezoid's systematic error: the hand-placed trapezoid moved as a tilt error "
                        "moves it, so that its horizon lies SPEC px above the true one (positive: the mapping "
                        "underestimates range); SPEC is a number or a per-variant distribution normal:MU:SIGMA or "
                        "uniform:A:B; 'none': the hand-placed trapezoid as it is (the default, unless the preset sets one)")
    p.add_argument("--click-noise", type=typed(float), metavar="PX", **quiet,
                   help="per-variant Gaussian noise (standard deviation, px) on the 8 clicked image coordinates (default 0)")
    p.add_argument("--metric", **({} if sweep else dict(choices=METRICS)), **quiet,
                   help="calibration and path errors as Euclidean ground error (default) or range error |d_true - d_mapped|")
    p.add_argument("--map-scale", type=typed(per_metre_or_none), metavar="PX_PER_M", **quiet,
                   help="scale of the site map the 0-3 px map-side perturbations are clicked on, px per metre "
                        "(the paper does not give its map's; default: the dataset's site map, 'none')")
    p.add_argument("--image-width", type=typed(pixels_or_none), metavar="PX", **quiet,
                   help="width of the camera image (same field of view) the 0-3 px image-side perturbations are "
                        "clicked on, px (the paper does not give its camera's resolution; default: the dataset's "
                        "image, 'none'); --horizon-shift, --click-noise and descent's moves stay in the dataset's px")
    p.add_argument("--perturbation", **({} if sweep else dict(choices=PERTURBATIONS)), **quiet,
                   help="how the paper's 'perturbation of 0, 1, 2, or 3 pixels ... to a randomly selected subset of 2 "
                        "to 16 coordinate values' is read: coordinate (each chosen coordinate its own 0-3 px and "
                        "sign, default), variant (one 0-3 px per variant, each coordinate its own sign) or "
                        "variant-positive (one 0-3 px per variant, added to every chosen coordinate)")
    p.add_argument("--descent-delta-max", type=typed(float), metavar="PX", **quiet,
                   help="descent: largest move of a trapezoid coordinate, px (default 8; the phase-1 grid spans "
                        "+/- half of it in 5 steps)")
    add_progress_option(p)


def params_from_args(args: argparse.Namespace, **override) -> StudyParams:
    """StudyParams of the preset, then the options given, then override; ValueError naming a bad option."""
    names = ("n_variants", "seed", "foot_source", "n_test", "max_test_distance", "test_lateral_max", "horizon_shift",
             "click_noise", "metric", "map_scale", "image_width", "perturbation", "descent_delta_max")
    values = {**PRESETS[args.preset], **{n: getattr(args, n) for n in names if hasattr(args, n)}, **override}
    if str(values.get("horizon_shift")).lower() == "none":  # the hand-placed trapezoid as it is (a preset's shift off)
        values["horizon_shift"] = None
    if "descent_delta_max" in values:
        values["descent"] = descent_settings(values.pop("descent_delta_max"))
    return StudyParams(**values)


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "study", help="run the correction study (every trapezoid variant x every calibration triple)",
        description="Per scene: the clicked base trapezoid and N perturbed variants, every combination of three "
                    "calibration points, the seven corrections (the paper's two, their hybrid and four more: "
                    "README); per-sample results as Parquet shards in --out. --preset paper runs the paper's 1000 "
                    "variants.")
    p.add_argument("datasets", nargs="+", metavar="DATASET", help="simgen dataset folders (one per scene)")
    p.add_argument("-o", "--out", required=True, help="results directory")
    add_study_options(p)
    group = p.add_mutually_exclusive_group()
    group.add_argument("--workers", type=number(int, 1, 1024), help="start a local Dask cluster of N worker processes")
    group.add_argument("--scheduler", help="address of a running Dask scheduler")
    p.add_argument("--resume", action="store_true", help="continue the study in --out, skipping finished shards")
    p.add_argument("--dry-run", action="store_true", help="print the sample counts and exit")
    p.set_defaults(handler=handle_study)


def positive_or_none(what: str, upper: float = math.inf):
    """An argparse type: 'none' (None) or a finite number in (0, upper], described by `what` in its error."""
    def parse(text: str) -> float | None:
        if text.lower() == "none":
            return None
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if not (math.isfinite(value) and 0 < value <= upper):
            raise argparse.ArgumentTypeError(f"must be {what} or 'none', got {text}")
        return value
    return parse


metres_or_none = positive_or_none("a positive number of metres")
per_metre_or_none = positive_or_none(f"px per metre in (0, {MAX_MAP_SCALE:g}]", MAX_MAP_SCALE)
pixels_or_none = positive_or_none(f"px in (0, {MAX_IMAGE_WIDTH:g}]", MAX_IMAGE_WIDTH)


def point_counts(entry: dict, params: StudyParams) -> str:
    """What a dataset gives the study: its calibration and test points (entry: study.json's datasets item), and
    whether it has fewer test points than --n-test (a detector that finds few people, a short dataset)."""
    source = params.foot_source
    text = (f"{entry['n_calibration']} calibration points ({calibration_source(source)}), "
            f"{entry['n_test']:,} test points ({source})")
    if entry["n_test"] < params.n_test:
        limits = [f"within {params.max_test_distance:g} m" if params.max_test_distance else "",
                  f"within {params.test_lateral_max:g} m of x = 0" if params.test_lateral_max else ""]
        where = " and ".join(x for x in limits if x)
        text += f": fewer than --n-test {params.n_test}, all the dataset has{' ' + where if where else ''}"
    return text


def handle_study(args: argparse.Namespace) -> int:
    params = params_from_args(args)
    if args.dry_run:
        counts = dry_run_counts(args.datasets, params)
        for entry in counts:
            print(f"{entry['scene']}: {entry['samples']:,} samples; {point_counts(entry, params)}")
        print(f"total: {sum(e['samples'] for e in counts):,} samples ({params.n_variants + 1} trapezoids per scene)")
        return 0
    study = run_study(args.datasets, args.out, params, preset=args.preset, resume=args.resume,
                      workers=args.workers, scheduler=args.scheduler, progress=show_progress(args))
    for entry in study["datasets"]:
        print(f"{entry['scene']}: {point_counts(entry, params)}")
    rate = study["samples_done"] / max(study["elapsed_seconds"], 1e-9)
    print(f"{study['samples_done']:,} of {study['samples_total']:,} samples in {args.out} "
          f"({study['elapsed_seconds']:.1f} s, {rate:,.0f} samples/s); complete: {study['complete']}")
    print(f"degenerate variants: {study['n_degenerate']}")
    for d in study["degenerate"]:
        print(f"  {d['scene']} variant {d['variant']}: {d['reason']}")
    return 0
