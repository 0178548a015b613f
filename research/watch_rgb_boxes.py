"""Why the rgb boxes' horizon is off after a move: a rendered recording whose camera moves (research/watch.py
--datasets), its rgb detector's boxes against the ground truth's boxes of the same people at the same instants.

Printed: the rgb boxes per second around the move and per 10 s throughout, matched to a person or not (the
background model restarts every chunk from the frames before it, so a move at a chunk's start meets a model of the
scene before it); the signed
offsets of the matched boxes' head (y1) and foot (y2) edges from gt.parquet's box of that person and step, and the
box height's ratio, by gt box height, before and after the move; and the horizon ``homocal watch`` estimates (as
research/watch.py runs it, the same people's height prior) from: all rgb boxes; the matched ones with the person's
id as track id; gt.parquet's boxes of those same people and steps; the segmentation boxes with ids; each minus the
true horizon just before the move and 0.5, 10 and 30 s after the first alarm after it.

    python research/watch_rgb_boxes.py DATASET --work WORK
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from homocal.cli import main as homocal_main  # noqa: E402
from homocal.dataset import load_dataset  # noqa: E402

HEIGHT_BINS_PX = (0, 30, 60, 120, 10_000)  # gt box heights


def matched(det, gt, gt_dt: float):
    """A detector's boxes matched to a person (agent_id >= 0) joined with gt.parquet's box of that person at the
    detection's step (columns x1..y2 the detector's, x1_gt..y2_gt the ground truth's), both boxes inside the image
    by more than a pixel (rows 1 .. 719 of 720, columns 1 .. 1279 of 1280)."""
    det = det[det.agent_id >= 0].assign(step=np.round(det.t[det.agent_id >= 0] / gt_dt).astype(int))
    m = det.merge(gt[["step", "agent_id", "x1", "y1", "x2", "y2"]], on=["step", "agent_id"], suffixes=("", "_gt"))
    inside = np.ones(len(m), bool)
    for edge in ("x1", "y1", "x2", "y2", "x1_gt", "y1_gt", "x2_gt", "y2_gt"):
        limit = 1279 if edge.startswith("x2") else 719 if edge.startswith("y2") else None
        inside &= (m[edge] > 1) if limit is None else (m[edge] < limit)
    return m[inside]


def watched_rows(dataset: Path, boxes, out: Path, ids: bool) -> tuple[np.ndarray, np.ndarray, list]:
    """homocal watch on boxes (homocal's pixel edges; track ids from agent_id when ``ids``), as research/watch.py
    runs it: times (s), the horizon estimate (px) per person observed, the alarms' detection times (s)."""
    import pyarrow.parquet as pq

    out.mkdir(parents=True)
    csv = boxes[["frame", "x1", "y1", "x2", "y2"] + (["agent_id"] if ids else [])].copy()
    csv[["x1", "y1", "x2", "y2"]] += 0.5  # homocal's pixel edges -> the CSV's corner pixels at integers
    csv.rename(columns={"agent_id": "track_id"}).to_csv(out / "boxes.csv", index=False)
    ds = load_dataset(dataset)
    with contextlib.redirect_stdout(io.StringIO()):
        code = homocal_main(["watch", "--trapezoid", str(dataset / "trapezoids.json"), "--boxes", str(out / "boxes.csv"),
                             "--fps", str(ds.manifest["fps"]), "--camera-json", str(dataset / "camera.json"),
                             "--camera-height", str(ds.camera.mount_height_m), "--height-mean", "1.71", "--height-sd", "0.09",
                             "--out", str(out / "watch")])
    assert code == 0, f"homocal watch failed on {out / 'boxes.csv'}"
    h = pq.read_table(out / "watch" / "horizon.parquet").to_pydict()
    alarms = [m["detected_s"] for m in json.loads((out / "watch" / "moves.json").read_text())["moves"]]
    return np.array(h["t_s"]), np.array(h["horizon_row_px"]), alarms


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset")
    ap.add_argument("--work", required=True, help="a folder for the homocal watch runs (new)")
    args = ap.parse_args()
    dataset, work = Path(args.dataset), Path(args.work)
    ds = load_dataset(dataset)
    dt = ds.manifest["gt_dt"]
    tilt = ds.pose.tilt_deg
    t_move = float(ds.pose.t[np.flatnonzero(tilt != tilt[0])[0]])
    truth = ds.pose.horizon_rows(ds.camera.K[0, 2])
    det, gt = ds.table("detections.parquet").to_pandas(), ds.table("gt.parquet").to_pandas()
    rgb, seg = det[det.detector == "rgb"], det[det.detector == "segmentation"]

    print(f"{dataset.name}: the camera moves at {t_move:g} s; rgb boxes per second, matched to a person / not:")
    for t in np.arange(t_move - 3, t_move + 4):
        x = rgb[(rgb.t >= t) & (rgb.t < t + 1)]
        print(f"  {t:5.0f}-{t + 1:.0f} s: {np.sum(x.agent_id >= 0):4d} / {np.sum(x.agent_id < 0):4d}")

    print("rgb boxes per 10 s, matched to a person / not: " + ", ".join(
        f"{t:.0f}-{t + 10:.0f} s {np.sum(x.agent_id >= 0)} / {np.sum(x.agent_id < 0)}"
        for t in np.arange(0, ds.manifest["seconds"], 10) for x in [rgb[(rgb.t >= t) & (rgb.t < t + 10)]]))

    m = matched(rgb, gt, dt)
    h = m.y2_gt - m.y1_gt
    print("matched rgb boxes vs gt.parquet's: dy1 (head; < 0 higher), dy2 (foot), median / mean px; height ratio - 1, median")
    for name, part in (("before", m.t < t_move), ("after", m.t >= t_move)):
        for lo, hi in zip(HEIGHT_BINS_PX[:-1], HEIGHT_BINS_PX[1:]):
            x = m[part & (h >= lo) & (h < hi)]
            r = (x.y2 - x.y1) / (x.y2_gt - x.y1_gt) - 1
            print(f"  {name} the move, gt height {lo}-{hi} px: {len(x):5d} boxes, dy1 {np.median(x.y1 - x.y1_gt):+.1f} / "
                  f"{np.mean(x.y1 - x.y1_gt):+.2f}, dy2 {np.median(x.y2 - x.y2_gt):+.1f} / {np.mean(x.y2 - x.y2_gt):+.2f}, "
                  f"height {r.median():+.3f}")

    same = m.drop(columns=["x1", "y1", "x2", "y2"]).rename(columns=lambda c: c.removesuffix("_gt"))
    print("homocal watch's estimate minus the true horizon (px): just before the move; 0.5, 10, 30 s after the first alarm after it")
    for i, (name, boxes, ids) in enumerate((("rgb boxes, all", rgb, False), ("rgb boxes matched, with ids", rgb[rgb.agent_id >= 0], True),
                                            ("gt boxes of those, with ids", same, True), ("segmentation boxes, with ids", seg[seg.agent_id >= 0], True))):
        t_s, row, alarms = watched_rows(dataset, boxes, work / f"run{i}", ids)
        err = row - truth[np.minimum(np.round(t_s / dt).astype(int), len(truth) - 1)]
        before = err[t_s < t_move]  # none where the move starts with the recording (a sway)
        line = f"  {name}: {before[-1]:+.1f}" if before.size else f"  {name}: -"
        after = [a for a in alarms if a >= t_move]
        if after:
            line += "; " + ", ".join(f"{err[t_s <= after[0] + s][-1]:+.1f}" for s in (0.5, 10, 30))
        print(line + (f" (alarms at {', '.join(f'{a:g}' for a in alarms)} s)" if alarms else " (no alarm)"))


if __name__ == "__main__":
    main()
