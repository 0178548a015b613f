"""Where the pedestrians' fitted roll comes from on a dataset (docs/real-camera.md, "Why the roll is not 1"): each
person's share of the roll and tilt error at the camera's true pose.

Run: python research/roll_budget.py DATASET [--detector segmentation] [--drop-hidden-feet yes|no] [--walks yes|no]
         [--people 8]

The fit's equations (homocal.correctors.pedestrians.fit_tilt_roll, its walks' sole offset held at 0: the fit's
prior mean) linearised at camera.json's tilt_deg and roll_deg, with the dataset's own people (detections.parquet's agent_id; their boxes clear of the border, and of
hidden_feet's boxes with --drop-hidden-feet yes, within 3 sd of the prior mean): each person's height r_p = (H_p -
mu) / sigma (H_p the median of its boxes') and, with --walks yes (the fit's), each box's r_j = (H_j - mean_p H) /
(BOX_HEIGHT_SD mu) about its person's mean, weighted m = (1, 1) and (0, c) (c = walk_weight). The error of (tilt,
roll) their root lies at is -A^-1 sum m psi(r) grad r (A = sum psi' m grad r grad r^T, grad r by central
differences), split into the part of the people's own heights (psi of (true height - mu) / sigma: who walked
by) and the part of the boxes (the people's psi of (implied - true height) / sigma, and the walks': how the
boxes measure them), the prior simgen's people's (box_heights.HEIGHT_M). --walks no: the people's heights alone
(each person one box's height: the fit before the walks). Prints the three errors, the sandwich sigma of the roll
over the people, the walks' weight, where the boxes' middle column lies along their person's axis (middle_share:
the fit takes it halfway between the foot's column and the head's) and the people who carry the most of the roll
(their share, boxes, median foot column from the principal point and foot row, true and implied height).
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq

from homocal.correctors.pedestrians import BOX_HEIGHT_SD, HUBER_K, OUTLIER_SIGMAS, walk_weight
from homocal.geometry.boxes import on_border
from homocal.dataset import load_dataset
from homocal.files import read_json
from homocal.geometry.boxes import hidden_feet, undistort_boxes
from research.box_heights import HEIGHT_M, box_heights, true_heights

STEP_DEG = 1e-4  # central-difference step of the people's heights, degrees
LEAN_PX = 4.0  # middle_share uses the boxes whose person's axis leans more than this many px


def people_heights(edges: np.ndarray, labels: np.ndarray, K: np.ndarray, tilt_deg: float, roll_deg: float,
                   camera_height_m: float) -> np.ndarray:
    """(P,) each person's implied height, metres: the median of its undistorted boxes' (N, 4) px, labels (N,) 0..P-1,
    at the pose (tilt_deg, roll_deg) of a camera with intrinsics K at camera_height_m (box_heights)."""
    h = box_heights(edges, K, tilt_deg, roll_deg, camera_height_m)
    return np.array([np.median(h[labels == k]) for k in range(labels.max() + 1)])


def linearised(J: np.ndarray, H: np.ndarray, truth: np.ndarray, mean: float, sd: float,
               walks: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> dict:
    """The equations' root's error at the true pose, linearised (the module docstring), from the people's heights'
    gradient J (P, 2) m per radian of (tilt, roll), their implied heights H (P,) and true heights truth (P,), m, the
    prior (mean, sd) m, and walks: None (the people alone) or the walk residuals' (r (n,), their gradient (n, 2) per
    radian, their people labels (n,) 0..P-1): "share" (P, 2) degrees, each person's part of it; "heights" and
    "boxes" (2,) degrees, the parts of the people's own heights and of their boxes; "roll_sigma" degrees, the
    sandwich sigma of the roll over the people; "walk_weight" c."""
    r = (H - mean) / sd
    use = (np.abs(r) <= OUTLIER_SIGMAS).astype(float)
    rw, Jw, labels = walks if walks is not None else (np.zeros(0), np.zeros((0, 2)), np.zeros(0, int))
    psi_w, dpsi_w = np.clip(rw, -HUBER_K, HUBER_K), (np.abs(rw) <= HUBER_K).astype(float)
    c = walk_weight(Jw[:, 1], psi_w, dpsi_w, labels, len(H)) if len(rw) else 0.0
    Jp, mw = J / sd, np.array([0.0, c])
    dpsi = (np.abs(r) <= HUBER_K).astype(float)
    A_inv = np.linalg.inv((Jp * dpsi[:, None]).T @ Jp + (mw * Jw * dpsi_w[:, None]).T @ Jw)
    walk_share = np.column_stack([np.bincount(labels, mw[k] * Jw[:, k] * psi_w, len(H)) for k in range(2)])  # (P, 2)

    def error(residual: np.ndarray, walk: bool) -> np.ndarray:  # (P, 2) degrees: each person's share
        return np.degrees(-(A_inv @ ((Jp * (np.clip(residual, -HUBER_K, HUBER_K) * use)[:, None]) + walk * walk_share).T).T)

    scores = Jp * (np.clip(r, -HUBER_K, HUBER_K) * use)[:, None] + walk_share
    cov = A_inv @ scores.T @ scores @ A_inv.T
    return {"share": error(r, True), "heights": error((truth - mean) / sd, False).sum(0),
            "boxes": error((H - truth) / sd, True).sum(0), "roll_sigma": math.degrees(math.sqrt(cov[1, 1])),
            "walk_weight": c}


def walk_residuals(edges: np.ndarray, labels: np.ndarray, K: np.ndarray, tilt_deg: float, roll_deg: float,
                   camera_height_m: float) -> np.ndarray:
    """(n,) each box's implied height about its person's mean over the boxes given, in BOX_HEIGHT_SD of the prior
    mean (fit_tilt_roll's walk residuals), the boxes (n, 4) px and labels (n,) 0..P-1 as people_heights'."""
    h = box_heights(edges, K, tilt_deg, roll_deg, camera_height_m)
    mean = np.bincount(labels, h) / np.maximum(np.bincount(labels), 1)
    return (h - mean[labels]) / (BOX_HEIGHT_SD * HEIGHT_M[0])


def at_pose(fn, edges: np.ndarray, labels: np.ndarray, K: np.ndarray, pose: np.ndarray, camera_height_m: float):
    """(value, its gradient (M, 2) per radian of (tilt, roll) by central differences, STEP_DEG) of fn (people_heights
    or walk_residuals, (M,)) at pose (tilt_deg, roll_deg) (2,) for the boxes (n, 4) px and labels (n,)."""
    J = np.column_stack([fn(edges, labels, K, *(pose + d), camera_height_m) - fn(edges, labels, K, *(pose - d), camera_height_m)
                         for d in np.eye(2) * STEP_DEG]) / (2 * math.radians(STEP_DEG))
    return fn(edges, labels, K, *pose, camera_height_m), J


def middle_share(edges: np.ndarray, ground: np.ndarray, heights: np.ndarray, camera) -> tuple[float, int]:
    """Where undistorted boxes' (N, 4) px middle column lies along their people's axis, and over how many boxes:
    the median of (m - x_f) / (x_t - x_f) over the boxes whose axis leans more than LEAN_PX, m the box's middle
    column, x_f and x_t the columns of the person's ground point ground (N, 2) m and of the point heights (N,) m
    above it, by cv2.projectPoints through camera's K, R, t (the undistorted image). upright_columns takes 1/2 (a
    box bounding an outline of even width about the axis)."""
    rvec = cv2.Rodrigues(np.asarray(camera.R, dtype=np.float64))[0]
    foot, head = (cv2.projectPoints(np.column_stack([ground, z]), rvec, np.asarray(camera.t, dtype=np.float64), camera.K,
                                    None)[0][:, 0, 0] for z in (np.zeros(len(ground)), heights))
    lean = np.abs(head - foot) > LEAN_PX
    return float(np.median(((edges[:, 0] + edges[:, 2]) / 2 - foot)[lean] / (head - foot)[lean])), int(lean.sum())


def budget(path: Path, detector: str, drop_hidden: bool, walks: bool = True) -> dict:
    """The module docstring's figures of one dataset and detector."""
    ds, raw = load_dataset(path), read_json(path / "camera.json")
    t = pq.read_table(path / "detections.parquet", columns=["detector", "frame", "agent_id", "x1", "y1", "x2", "y2", "gt_x",
                                                            "gt_y"]).to_pandas()
    t = t[t["detector"] == detector]
    edges, agents = t[["x1", "y1", "x2", "y2"]].to_numpy(np.float64), t["agent_id"].to_numpy()
    keep = ~on_border(edges, ds.camera.image_size) & (agents >= 0)
    if drop_hidden:
        keep &= ~hidden_feet(edges, t["frame"].to_numpy())
    edges, agents, ground = undistort_boxes(edges[keep], ds.camera.lens), agents[keep], t[["gt_x", "gt_y"]].to_numpy()[keep]
    ids, labels = np.unique(agents, return_inverse=True)
    K, h_c = ds.camera.K, ds.camera.mount_height_m
    pose = np.array([raw["tilt_deg"], raw.get("roll_deg", 0.0)])
    H, J = at_pose(people_heights, edges, labels, K, pose, h_c)  # (P,) m, (P, 2) m per radian
    truth = np.array([true_heights(ds.manifest)[a] for a in ids])
    middle, leaning = middle_share(edges, ground, truth[labels], ds.camera)
    inlier = np.abs(box_heights(edges, K, *pose, h_c) - HEIGHT_M[0]) <= OUTLIER_SIGMAS * HEIGHT_M[1]
    parts = linearised(J, H, truth, *HEIGHT_M,
                       (*at_pose(walk_residuals, edges[inlier], labels[inlier], K, pose, h_c), labels[inlier]) if walks else None)
    share = parts["share"]
    cols = np.array([np.median((edges[labels == k, 0] + edges[labels == k, 2]) / 2) for k in range(len(ids))]) - K[0, 2]
    rows = np.array([np.median(edges[labels == k, 3]) for k in range(len(ids))])
    return {"people": len(ids), "total": share.sum(0), "heights": parts["heights"], "boxes": parts["boxes"],
            "roll_sigma": parts["roll_sigma"], "walk_weight": parts["walk_weight"], "middle_share": middle, "leaning": leaning,
            "table": sorted(zip(share[:, 1], np.bincount(labels), cols, rows, truth, H), key=lambda x: -abs(x[0]))}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--detector", default="segmentation")
    ap.add_argument("--drop-hidden-feet", choices=("yes", "no"), default="no")
    ap.add_argument("--walks", choices=("yes", "no"), default="yes",
                    help="no: the people's heights alone, one height each (the fit before the walks)")
    ap.add_argument("--people", type=int, default=8, help="how many of the people carrying the most roll to list")
    args = ap.parse_args(argv)
    b = budget(args.dataset, args.detector, args.drop_hidden_feet == "yes", args.walks == "yes")
    (tt, tr), (ht, hr), (bt, br) = b["total"], b["heights"], b["boxes"]
    print(f"{args.dataset} {args.detector}, hidden feet dropped: {args.drop_hidden_feet}, walks: {args.walks} (weight "
          f"{b['walk_weight']:.3f}); {b['people']} people; at the true pose the equations' root is off by roll {tr:+.2f} deg, tilt {tt:+.3f} deg (the people's heights: roll {hr:+.2f}, "
          f"tilt {ht:+.3f}; the boxes: roll {br:+.2f}, tilt {bt:+.3f}); roll sigma {b['roll_sigma']:.2f} deg")
    print(f"the boxes' middle column lies {b['middle_share']:.3f} of the way from the foot's column to the head's (median "
          f"of {b['leaning']} boxes leaning over {LEAN_PX:g} px; the fit takes 0.5)")
    print("roll share (deg), boxes, foot column - cx (px), foot row (px), true height (m), implied height (m)")
    for row in b["table"][:args.people]:
        print("%+.3f  %4d  %+5.0f  %4.0f  %.3f  %.3f" % row)


if __name__ == "__main__":
    main()
