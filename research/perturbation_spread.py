"""How far the study's trapezoid variants spread under each reading of the paper's perturbation (docs/reproduction.md,
"What Table 1 requires of the setup").

Run: python research/perturbation_spread.py DATASET [DATASET ...] [study options] [--variants N]
     (the study options as `homocal study` takes them, e.g. --preset paper --horizon-shift 15 --map-scale 2.5;
     --perturbation is ignored: every reading of perturb.PERTURBATIONS is measured)

Per scene and reading, over the non-degenerate variants 1..N of the study those options describe: the standard
deviation of the horizon's movement from the base trapezoid's (px at the principal column, positive: up), the
standard deviation and mean of the range change at RANGE_M straight ahead of the camera (m, positive: farther;
the ground point's image under the base mapping, mapped by the variant's), and the share of variants whose
drawn offsets are all 0 (the base trapezoid itself).
"""
from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from homocal.geometry import ViewTransformer
from homocal.study.cli import add_study_options, params_from_args
from homocal.study.engine import load_scenes
from homocal.study.inputs import StudyScene
from homocal.study.perturb import PERTURBATIONS

RANGE_M = 44.0  # the farthest calibration distance of scene1 (the paper's 5-44 m)


def spread(scene: StudyScene, params, variants: int) -> dict[str, float]:
    """{horizon_sd_px, range_sd_m, range_mean_m, unperturbed, variants} of one scene's variants 1..variants."""
    base_image, base_map = scene.variant_quads(params, 0)
    base = ViewTransformer(base_image, scene.site_map.to_metres(base_map))
    u = scene.K[0, 2]
    base_row = base.horizon_row(u)
    q = base.inverse_transform_points(scene.origin + np.array([[0.0, RANGE_M]]))
    rows, ranges, unperturbed = [], [], 0
    for v in range(1, variants + 1):
        image, map_quad = scene.variant_quads(params, v)
        unperturbed += bool((image == base_image).all() and (map_quad == base_map).all())
        try:
            other = ViewTransformer(image, scene.site_map.to_metres(map_quad))
        except ValueError:  # a degenerate variant (the study leaves it out too)
            continue
        rows.append(base_row - other.horizon_row(u))
        ranges.append(np.linalg.norm(other.transform_points(q)[0] - scene.origin) - RANGE_M)
    return {"horizon_sd_px": float(np.std(rows)), "range_sd_m": float(np.std(ranges)),
            "range_mean_m": float(np.mean(ranges)), "unperturbed": unperturbed / variants, "variants": len(rows)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("datasets", nargs="+", metavar="DATASET")
    add_study_options(parser)
    args = parser.parse_args()
    try:
        params = params_from_args(args)
        scenes = load_scenes(args.datasets, params)
    except ValueError as e:
        raise SystemExit(f"perturbation_spread.py: {e}") from None
    if params.n_variants < 2:
        raise SystemExit("perturbation_spread.py: --variants must be at least 2 (a spread needs two variants)")
    print(f"{params.n_variants} variants per scene; range change at {RANGE_M:g} m straight ahead\n")
    print("| scene | reading | variants | horizon movement sd (px) | range change sd (m) | range change mean (m) | "
          "unperturbed variants |\n|---|---|---:|---:|---:|---:|---:|")
    for scene in scenes:
        for reading in PERTURBATIONS:
            r = spread(scene, dataclasses.replace(params, perturbation=reading), params.n_variants)
            print(f"| {scene.name} | {reading} | {r['variants']} | {r['horizon_sd_px']:.2f} | {r['range_sd_m']:.2f} | "
                  f"{r['range_mean_m']:+.2f} | {100 * r['unperturbed']:.1f} % |")


if __name__ == "__main__":
    main()
