"""``homocal advise --trapezoid T.json``: where to put the three reference points, from the study's machinery.

The user's clicked trapezoid is taken as the truth. Its mapping puts every candidate reference position (the
ground points o + (l, d) for each distance d of --distances straight ahead and each lateral offset l of
--lateral, o the camera origin) and every test point (a seeded uniform sample of x in o_x +/- --test-lateral,
y in o_y + --test-range, or the ground points of --test-points) into the image exactly. The study's perturbation model (perturb.draw_variant: 2-16 of
the 16 trapezoid coordinates moved by 0-3 px) then draws --samples clicked trapezoids around it, and the
study's compiled kernels (scene.prepare_variant, scene.run_tables) correct each with every triple of
candidates. Triples are ranked by the chosen method's mean path improvement (the study's, paper Section 6) over
the samples, ties by its 5th percentile.
"""
from __future__ import annotations

import argparse
import csv
import io
import math
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from homocal.arguments import CAMERA_JSON_HELP, camera_json, number, xy_pair
from homocal.correctors.base import MAX_REFERENCE_POINTS
from homocal.correctors.catalogue import DEFAULT_METHOD, METHODS as CATALOGUE_METHODS
from homocal.files import check_output_file, csv_header, read_points_csv, write_text_atomic
from homocal.geometry import SiteMap, ViewTransformer, read_trapezoid_file
from homocal.keyed_rng import seed_from_key
from homocal.study import kernels
from homocal.study.inputs import MAX_SEED, StudyParams, StudyScene
from homocal.study.shards import prepare_variant, run_tables
from homocal.study.sweep import expand_values
from homocal.study.triples import triples
from homocal.uncertainty import straight_ahead_column

NAME = "advise"  # the scene name that keys the variants' random draws
DEFAULT_MAP_SCALE = 10.0  # px per metre: a map given in metres is perturbed as a site map of this scale (the scenes')
MAX_SAMPLES = 20_000_000  # triples x samples (about a minute on 2 cores)
MAX_TEST_POINTS = 100_000  # --test-points rows read
CSV_FIELDS = ("rank", "x1", "y1", "x2", "y2", "x3", "y3", "mean_path", "p5_path", "median_path", "positive_path")


@dataclass
class Advice:
    """Ranked triples of candidate positions (M, 2) metres: triples (S, 3) indices, order (S,) best first, and
    per triple the chosen method's path improvement over the samples (percent, (S,) each): mean, 5th
    percentile, median and the share of samples above 0. n_used of n_samples perturbed trapezoids counted;
    skipped: {reason: count} for the others."""

    method: str
    positions: np.ndarray
    triples: np.ndarray
    mean: np.ndarray
    p5: np.ndarray
    median: np.ndarray
    positive: np.ndarray
    order: np.ndarray
    n_samples: int
    n_used: int
    skipped: dict


def candidate_positions(distances, laterals, origin) -> np.ndarray:
    """(len(distances) * len(laterals), 2) ground positions o + (l, d), metres, distance-major."""
    d, l = np.meshgrid(np.asarray(distances, float), np.asarray(laterals, float), indexing="ij")
    return np.column_stack([l.ravel(), d.ravel()]) + np.asarray(origin, float)


def uniform_test_points(n: int, seed: int, origin, test_range=(5.0, 50.0), lateral: float = 8.0) -> np.ndarray:
    """(n, 2) ground points, metres: x uniform in o_x +/- lateral, y in o_y + test_range, seeded by (seed, "advise",
    "test")."""
    rng = np.random.default_rng(seed_from_key(seed, NAME, "test"))
    return np.column_stack([rng.uniform(-lateral, lateral, n), rng.uniform(*test_range, n)]) + np.asarray(origin, float)


def advise_scene(transformer: ViewTransformer, site_map: SiteMap, positions: np.ndarray, test_ground: np.ndarray,
                 origin) -> StudyScene:
    """The StudyScene of a clicked trapezoid taken as the truth: candidate positions (M, 2) and test points
    (N, 2), metres, mapped into the image by transformer.inverse_transform_points; the map quad in site_map's
    pixels (the perturbation moves them). K: the intrinsics are unknown, only the principal column is set (the
    straight-ahead column, where perturb.base_trapezoid reads the horizon); NaN elsewhere, as no horizon shift is
    applied. ValueError if a position or test point maps behind the camera."""
    images = []
    for what, ground in (("reference position", positions), ("test point", test_ground)):
        image = transformer.inverse_transform_points(ground)
        bad = np.flatnonzero(np.isnan(image).any(axis=1))
        if bad.size:
            x, y = ground[bad[0]]
            raise ValueError(f"{what} ({x:g}, {y:g}) m lies behind the camera of the trapezoid's mapping "
                             f"(is --camera-origin right?)")
        images.append(image)
    K = np.full((3, 3), np.nan)
    K[0, 2] = straight_ahead_column(transformer)
    origin = np.asarray(origin, float)
    return StudyScene(NAME, site_map, transformer.source, site_map.to_pixels(transformer.target), origin, images[0],
                 positions, np.linalg.norm(positions - origin, axis=1), images[1], test_ground,
                 triples(len(positions)), K, math.nan)  # K and the true horizon serve only horizon shifts: none here


def advise(scene: StudyScene, method: str, samples: int, seed: int = 0, progress: bool = False) -> Advice:
    """Rank scene's triples by method's (kernels.METHODS) path improvement over perturbed variants 1..samples of
    scene's trapezoid (variant 0 is the unperturbed truth). A variant is skipped when it is degenerate
    (scene.prepare_variant's reason) or moves no coordinate (nothing to correct). ValueError if all are."""
    if method not in kernels.METHODS:
        raise ValueError(f"unknown method {method!r}: expected one of {', '.join(kernels.METHODS)}")
    column = kernels.OUT_COLUMNS.index(f"path_{method}")
    params = StudyParams(seed=seed, n_variants=samples, n_test=len(scene.test_image))

    def one(variant: int):
        tables = prepare_variant(scene, params, variant)
        if isinstance(tables, str):
            return tables
        if tables.path_before == 0.0:
            return "the perturbation moved no coordinate"
        return run_tables(scene, tables, params, variant, scene.triples)[0][:, column]

    paths, skipped = [], {}
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:  # the kernel releases the GIL
        for result in tqdm(pool.map(one, range(1, samples + 1)), total=samples, unit="trapezoid", desc=NAME,
                           disable=None if progress else True):  # None: off unless stderr is a terminal
            if isinstance(result, str):
                skipped[result] = skipped.get(result, 0) + 1
            else:
                paths.append(result)
    if not paths:
        raise ValueError(f"every perturbed trapezoid was skipped: {_skipped_text(skipped)}")
    P = np.array(paths)
    mean, p5 = P.mean(axis=0), np.percentile(P, 5, axis=0)
    return Advice(method, scene.cal_ground, scene.triples, mean, p5, np.median(P, axis=0), 100.0 * (P > 0).mean(axis=0),
                  np.lexsort((-p5, -mean)), samples, len(paths), skipped)


def _skipped_text(skipped: dict) -> str:
    return "; ".join(f"{n} x {reason}" for reason, n in sorted(skipped.items()))


def to_csv(advice: Advice) -> str:
    """Every triple, best first: rank, the three positions (x, y) metres, mean, 5th percentile, median path
    improvement and positive share (percent)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_FIELDS)
    for rank, s in enumerate(advice.order, 1):
        xy = advice.positions[advice.triples[s]].ravel()
        writer.writerow([rank, *(repr(float(v)) for v in xy),
                         *(repr(float(a[s])) for a in (advice.mean, advice.p5, advice.median, advice.positive))])
    return buffer.getvalue()


def summary(advice: Advice, lateral: bool, top: int) -> str:
    """The best `top` triples as a table, then the spread of all triples' means."""
    label = "positions (x, y) m" if lateral else "distances m"
    rows = [f"{'rank':>4}  {label:<34} {'mean':>7} {'5th pct':>8} {'median':>7} {'positive':>9}"]
    for rank, s in enumerate(advice.order[:top], 1):
        p = advice.positions[advice.triples[s]]
        where = "  ".join(f"({x:g}, {y:g})" for x, y in p) if lateral else ", ".join(f"{y:g}" for y in p[:, 1])
        rows.append(f"{rank:>4}  {where:<34} {advice.mean[s]:6.1f}% {advice.p5[s]:7.1f}% {advice.median[s]:6.1f}% "
                    f"{advice.positive[s]:8.1f}%")
    m = advice.mean
    rows.append(f"All {len(m):,} triples: mean path improvement {np.min(m):.1f} % (worst) .. {np.median(m):.1f} % "
                f"(median triple) .. {np.max(m):.1f} % (best).")
    return "\n".join(rows)


# ---- command line ------------------------------------------------------------------------------------------
def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "advise", help="where to put the three reference points: triples ranked by simulated path improvement",
        formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__.split("\n", 2)[2],
        description="Rank triples of reference positions by the path improvement a correction from them gives, "
                    "simulated around your clicked trapezoid with the study's perturbation model.")
    p.add_argument("--trapezoid", required=True, type=Path, metavar="TRAP.json", help="the trapezoid homocal fit reads")
    p.add_argument("--camera-json", type=Path, metavar="CAMERA.json", help=CAMERA_JSON_HELP)
    p.add_argument("--distances", default="5:50:1", metavar="SPEC",
                   help="reference distances straight ahead of the camera origin, metres: START:STOP:STEP (STOP "
                        "included) and/or a comma list, at least 3 (default 5:50:1)")
    p.add_argument("--lateral", default="0", metavar="L,...",
                   help="lateral offsets (x, metres) tried at each distance, e.g. -3,0,3 (default 0: straight ahead "
                        "only); the candidates are every (offset, distance) pair, triples any three of them")
    p.add_argument("--method", default=DEFAULT_METHOD,  # the methods with a study kernel
                   choices=[m.name for m in CATALOGUE_METHODS.values() if m.column in kernels.METHODS],
                   help="the correction to advise for (default %(default)s, homocal fit's)")
    p.add_argument("--samples", type=int, default=100, metavar="N",
                   help="perturbed trapezoids (default 100; 1000 orders triples that differ by tenths of a point as "
                        "the study does, about 3 min for least-change: docs/measurements.md)")
    p.add_argument("--camera-origin", type=xy_pair, default=(0.0, 0.0), metavar="X,Y",
                   help="ground point under the camera, metres (default 0,0)")
    p.add_argument("--test-range", default="5:50", metavar="MIN:MAX",
                   help="test points' distance ahead of the camera origin, metres (default 5:50)")
    p.add_argument("--test-lateral", type=float, default=8.0, metavar="M",
                   help="test points' largest lateral offset, metres (default 8)")
    p.add_argument("--test-points", type=Path, metavar="GROUND.csv",
                   help="test points from a CSV with columns x, y (ground metres, e.g. where your pedestrians walk) "
                        "instead of the uniform sample")
    p.add_argument("--map-scale", type=float, metavar="PX_PER_M",
                   help="site-map scale the 0-3 px map perturbations are in (default: the trapezoid file's; "
                        f"{DEFAULT_MAP_SCALE:g} for a map in metres)")
    p.add_argument("--seed", type=number(int, 0, MAX_SEED), default=0, help="seed of the perturbations and test points (default 0)")
    p.add_argument("--top", type=int, default=5, help="triples to print (default 5)")
    p.add_argument("-o", "--out", type=Path, metavar="ADVICE.csv", help="write every triple, ranked")
    p.set_defaults(handler=handle_advise)


def _numbers(text: str, flag: str) -> list[float]:
    """The finite numbers of a SPEC (sweep.expand_values: START:STOP:STEP and comma lists), each once."""
    try:
        items = expand_values(text)
    except ValueError as e:
        raise ValueError(f"{flag} {e}") from None
    values = []
    for item in items:
        try:
            value = float(item)
        except ValueError:
            raise ValueError(f"{flag} {text!r}: {item!r} is not a number") from None
        if not math.isfinite(value):
            raise ValueError(f"{flag} {text!r}: {item!r} is not a finite number")
        if value in values:
            raise ValueError(f"{flag} {text!r}: {item!r} is given twice")
        values.append(value)
    return values


def handle_advise(args: argparse.Namespace) -> int:
    distances = _numbers(args.distances, "--distances")
    if len(distances) < 3 or min(distances) <= 0:
        raise ValueError(f"--distances {args.distances!r}: need at least 3 distances > 0, got {distances}")
    laterals = _numbers(args.lateral, "--lateral")
    try:
        test_range = [float(x) for x in args.test_range.split(":")]
    except ValueError:
        test_range = []
    if len(test_range) != 2 or not 0 <= test_range[0] < test_range[1] < math.inf:
        raise ValueError(f"--test-range {args.test_range!r}: expected MIN:MAX with 0 <= MIN < MAX metres")
    if not (math.isfinite(args.test_lateral) and args.test_lateral >= 0):
        raise ValueError(f"--test-lateral must be a finite number >= 0, got {args.test_lateral}")
    if args.samples < 1 or args.top < 1:
        raise ValueError(f"--samples and --top must be >= 1, got {args.samples} and {args.top}")
    if args.map_scale is not None and not (math.isfinite(args.map_scale) and args.map_scale > 0):
        raise ValueError(f"--map-scale must be a finite number > 0, got {args.map_scale}")
    positions = candidate_positions(distances, laterals, args.camera_origin)
    if len(positions) > MAX_REFERENCE_POINTS:
        raise ValueError(f"--distances x --lateral: {len(positions):,} reference positions, at most "
                         f"{MAX_REFERENCE_POINTS:,}")
    n_triples = math.comb(len(positions), 3)
    if n_triples * args.samples > MAX_SAMPLES:
        raise ValueError(f"{n_triples:,} triples x {args.samples} samples is over {MAX_SAMPLES:,} samples: use fewer "
                         f"distances or lateral offsets, or fewer --samples")
    if args.out is not None:
        check_output_file(args.out, lambda p: csv_header(p) == list(CSV_FIELDS), "homocal advise CSV")
    camera = camera_json(args.camera_json)
    transformer, site_map = read_trapezoid_file(args.trapezoid, None if camera is None else camera.lens)
    if site_map is None or args.map_scale is not None:
        site_map = SiteMap(args.map_scale or DEFAULT_MAP_SCALE, site_map.origin_px if site_map else (0.0, 0.0))
    if args.test_points is None:
        test_ground = uniform_test_points(StudyParams().n_test, args.seed, args.camera_origin, test_range, args.test_lateral)
        test_area = f"|x| <= {args.test_lateral:g} m, y {test_range[0]:g}..{test_range[1]:g} m"
    else:
        _, _, cols, _ = read_points_csv(args.test_points, ("x", "y"), finite=True, most=MAX_TEST_POINTS)
        test_ground, test_area = np.column_stack([cols["x"], cols["y"]]), f"from {args.test_points}"
        if not len(test_ground):
            raise ValueError(f"{args.test_points}: no test points")
    scene = advise_scene(transformer, site_map, positions, test_ground, args.camera_origin)
    start = time.perf_counter()
    advice = advise(scene, CATALOGUE_METHODS[args.method].column, args.samples, args.seed, progress=True)
    elapsed = time.perf_counter() - start
    skipped = f"; skipped: {_skipped_text(advice.skipped)}" if advice.skipped else ""
    print(f"homocal advise: {args.method} from {n_triples:,} triples of {len(positions)} reference positions, each "
          f"corrected on {advice.n_used} of {args.samples} perturbed trapezoids{skipped} ({elapsed:.1f} s); path "
          f"improvement on {len(test_ground)} test points, {test_area}; map perturbations in px of a {site_map.scale_px_per_m:g} px/m site map.")
    print(summary(advice, lateral=laterals != [0.0], top=args.top))
    if args.out is not None:
        write_text_atomic(args.out, to_csv(advice))
        print(f"Every triple, ranked: {args.out}")
    return 0
