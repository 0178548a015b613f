"""How tall each detector's boxes make a dataset's people at the camera's true pose (docs/real-camera.md, "The
people"): why the pedestrians' fit refuses scene3's rgb boxes.

Run: python research/box_heights.py DATASET [DATASET ...] [--detectors segmentation,rgb] [--lens known|ignore]

Per dataset and detector, every box of detections.parquet clear of the frame's border (on_border, as the fit
leaves them out) is undistorted with camera.json's lens (homocal.geometry.undistort_boxes, as homocal fit
--camera-json does; --lens ignore: read as a pinhole's, as homocal study --lens ignore does) and its implied height computed at camera.json's tilt_deg and roll_deg and mount_height_m
(homocal.correctors.pedestrians.upright_heights: the derolled rows of the foot and the head on the vertical through
the box, the fit's own model at the true pose). The people's true heights are simgen's: the person drawn for each agent (simgen.agents.Crowd of the
shipped scene the manifest names, its seed and seconds). Prints per detector: the boxes, the median implied
height and the share beyond 3 sd (OUTLIER_SIGMAS x 0.09 m) of 1.71 m (simgen's people); of the boxes associated
with an agent (agent_id >= 0), the median of implied / true height and the median true height of the agents
seen (over their boxes); of the others (agent_id -1: blobs of no one person, or of several), their share and
median implied height; and the walks' spread: 1.4826 times the median absolute deviation of the associated boxes'
implied heights within 3 sd about their agent's median (pedestrians.BOX_HEIGHT_SD).
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from homocal.correctors.pedestrians import OUTLIER_SIGMAS, upright_heights
from homocal.dataset import load_dataset
from homocal.files import read_json
from homocal.geometry.boxes import on_border, undistort_boxes
from homocal.study.inputs import LENS_MODES
from simgen.agents import Crowd
from simgen.scene import SHIPPED, load_scene

HEIGHT_M = (1.71, 0.09)  # simgen's people: mean and sd, metres (simgen.humanoid.draw_person)


def box_heights(edges: np.ndarray, K: np.ndarray, tilt_deg: float, roll_deg: float, camera_height_m: float) -> np.ndarray:
    """Implied heights (N,) m of undistorted boxes (N, 4) homocal px of a camera with intrinsics K (3, 3), tilted
    tilt_deg below the horizontal, rolled roll_deg (camera.json's sign), camera_height_m over the ground: the fit's
    own model (homocal.correctors.pedestrians.upright_heights)."""
    return upright_heights(edges, math.radians(tilt_deg), math.radians(roll_deg), float(K[1, 1]),
                           (float(K[0, 2]), float(K[1, 2])), camera_height_m)


def true_heights(manifest: dict) -> dict[int, float]:
    """{agent_id: height m} of every walk of the run the manifest describes (its shipped scene, seed, seconds)."""
    crowd = Crowd(load_scene(SHIPPED / manifest["scene"]), int(manifest["seed"]), float(manifest["seconds"]))
    return {w.agent_id: w.person.height for walks in crowd.slots for w in walks}


def summary(path: Path, detector: str, lens: str = "known") -> dict:
    """The figures of one dataset's detector, its boxes undistorted (lens "known") or not ("ignore") (the module
    docstring)."""
    ds = load_dataset(path)
    raw = read_json(path / "camera.json")
    table = pq.read_table(path / "detections.parquet", columns=["detector", "agent_id", "x1", "y1", "x2", "y2"]).to_pandas()
    table = table[table["detector"] == detector]
    edges = table[["x1", "y1", "x2", "y2"]].to_numpy(np.float64)
    inside = ~on_border(edges, ds.camera.image_size)
    edges, agents = edges[inside], table["agent_id"].to_numpy()[inside]
    H = box_heights(undistort_boxes(edges, ds.camera.lens) if lens == "known" else edges, ds.camera.K, raw["tilt_deg"], raw.get("roll_deg", 0.0),
                    ds.camera.mount_height_m)
    truth = true_heights(ds.manifest)
    seen = agents >= 0
    true = np.array([truth[a] for a in agents[seen]])
    inlier = seen & (np.abs(H - HEIGHT_M[0]) <= OUTLIER_SIGMAS * HEIGHT_M[1])
    ids, labels = np.unique(agents[inlier], return_inverse=True)
    about = H[inlier] / np.array([np.median(H[inlier][labels == k]) for k in range(len(ids))])[labels] - 1
    return {"boxes": len(H), "median_m": float(np.median(H)),
            "outside_pct": 100 * float(np.mean(np.abs(H - HEIGHT_M[0]) > OUTLIER_SIGMAS * HEIGHT_M[1])),
            "ratio": float(np.median(H[seen] / true)), "seen_true_m": float(np.median(true)),
            "unassociated_pct": 100 * float(np.mean(~seen)),
            "unassociated_m": float(np.median(H[~seen])) if (~seen).any() else math.nan,
            "walk_spread_pct": 100 * 1.4826 * float(np.median(np.abs(about)))}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("datasets", nargs="+", type=Path)
    ap.add_argument("--detectors", default="segmentation,rgb")
    ap.add_argument("--lens", choices=LENS_MODES, default="known")
    args = ap.parse_args(argv)
    for path in args.datasets:
        for detector in args.detectors.split(","):
            e = summary(path, detector, args.lens)
            print(f"{path} {detector}, lens {args.lens}: {e['boxes']} boxes, implied height median {e['median_m']:.3f} m, "
                  f"{e['outside_pct']:.1f} % beyond {OUTLIER_SIGMAS:g} sd of {HEIGHT_M[0]:g} m; associated: implied / "
                  f"true {e['ratio']:.3f}, the agents seen {e['seen_true_m']:.3f} m tall (median over boxes); "
                  f"no agent: {e['unassociated_pct']:.0f} % of the boxes, implied {e['unassociated_m']:.3f} m; "
                  f"walk spread {e['walk_spread_pct']:.1f} %")


if __name__ == "__main__":
    main()
