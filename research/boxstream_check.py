"""simgen.boxstream's render-free boxes against a rendered dataset's segmentation boxes of the same scene and seed.

For every (frame, agent) the segmentation detector reports, the render-free box of that agent at t = frame / fps
(``box_stream`` with and without occlusion): the share identical to the pixel and within 2 px on every edge, and
the share whose bottom edge (the feet) is within 2 px; over all boxes, over the partly occluded ones (gt.parquet's
visible_fraction below 0.9) and over those the occlusion changes. A static dataset of a shipped scene:

    python research/boxstream_check.py DATASET
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from simgen.boxstream import box_stream  # noqa: E402
from simgen.scene import load_scene  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    args = ap.parse_args()
    manifest = json.loads((args.dataset / "manifest.json").read_text())
    fps, gt_dt = manifest["fps"], manifest["gt_dt"]
    det = pq.read_table(args.dataset / "detections.parquet").to_pydict()
    rendered = {(f, a): b for d, f, a, *b in zip(*(det[c] for c in ("detector", "frame", "agent_id", "x1", "y1", "x2", "y2")))
                if d == "segmentation"}
    gt = pq.read_table(args.dataset / "gt.parquet", columns=["step", "agent_id", "visible_fraction"]).to_pydict()
    partly = {(s, a) for s, a, v in zip(gt["step"], gt["agent_id"], gt["visible_fraction"]) if v < 0.9}
    scene = load_scene(Path(__file__).resolve().parents[1] / "scenes" / manifest["scene"])
    boxes = {flag: {(f, int(a)): box for f, xyxy, ids in box_stream(scene, manifest["seed"], manifest["seconds"], fps, flag)
                    for box, a in zip(xyxy, ids)} for flag in (True, False)}
    print(f"{args.dataset.name}: {manifest['scene']}, seed {manifest['seed']}, {manifest['seconds']:g} s at {fps:g} fps: "
          f"{len(rendered)} rendered boxes, {len(boxes[True])} render-free ({len(set(rendered) - set(boxes[True]))} "
          f"rendered ones without)")
    both = [k for k in rendered if k in boxes[True]]
    cut = [k for k in both if not np.array_equal(boxes[True][k], boxes[False][k])]
    groups = {"all": both, "partly occluded (visible_fraction < 0.9)":
              [k for k in both if (round(k[0] / fps / gt_dt), k[1]) in partly], "changed by occlusion": cut}
    for name, keys in groups.items():
        for flag, label in ((True, "occluded"), (False, "whole")):
            d = np.abs(np.array([boxes[flag][k] for k in keys]) - np.array([rendered[k] for k in keys])).reshape(-1, 4)
            print(f"  {name}, {len(keys)} boxes, {label}: identical {np.mean(d.max(axis=1) == 0):.1%}, within 2 px "
                  f"{np.mean(d.max(axis=1) <= 2):.1%}, bottom within 2 px {np.mean(d[:, 3] <= 2):.1%}")


if __name__ == "__main__":
    main()
