"""Why a detector's boxes give homocal watch false alarms: the people's standardised residuals on a recording's
static minutes (research/watch.py --datasets: a static recording whole, a moving one before its move).

Per detector, OnlineCalibrator runs on each recording's boxes (as ``homocal watch`` does: camera.json, the camera's
true height, the people's own height prior, --arl0) and each person's standardised residual z
(``State.person_z``, the CUSUM's increment before clipping) is kept with the box it came from (the frame's box
nearest the person's column: its height, its agent_id in detections.parquet, -1 for a box matched to nobody,
whether that agent has another box in the frame, a split) and the time into the detector's chunk (the rgb
background model restarts every chunk). Printed per detector, pooled over the recordings:

- the tails: the share of |z| over 2, 3 and 4 against the normal's, and the scale the CUSUM's increments
  u = clip(z, +-CLIP) / SD_CLIPPED really have (their RMS; 1 when z is standard normal);
- each side's tilt (``homocal.watch.calibrator.tilt``: 2 k = 1 for normal increments, smaller for a heavier tail)
  and root mean square of the increments u, and the mean run (people) Siegmund's approximation gives at --arl0's
  threshold for normal increments (the threshold before the tilts were measured) on increments of these tilts;
- the dependence: the lag-1 autocorrelation of u over consecutive people of a recording, and the variance of
  sums of 10 consecutive u over 10 times their variance (1 for independent increments);
- the mean and RMS of z by box height (far people: small boxes), by time into the chunk, for unmatched and split
  boxes, and for the people whose agent gave an observation before (the overlap linker lost their track: one
  person counted twice);
- per alarm, the people since the alarming statistic was last 0 (at the frames' ends): time, z, box height,
  agent, chunk time.

    python research/watch_residuals.py DIR [DIR ...] --detectors segmentation,rgb
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from homocal.boxes import read_boxes  # noqa: E402
from homocal.dataset import load_dataset  # noqa: E402
from homocal.watch import OnlineCalibrator  # noqa: E402
from homocal.watch.calibrator import CLIP, CUSUM_K, DEFAULT_ARL0_PEOPLE, SD_CLIPPED, by_frame, cusum_arl0, cusum_threshold, tilt  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))
from watch import HEIGHT, motion  # noqa: E402  (research/watch.py)

HEIGHT_BINS_PX = (0, 30, 60, 120, 10_000)  # box heights
BLOCK = 10  # people per block of the long-run variance


def people_of(dataset: Path, detector: str, arl0: float) -> tuple[pd.DataFrame, list]:
    """The people of a recording's static minutes (one row each: t, z, u, box height, agent, split, chunk time,
    the frame's end CUSUMs) and the alarms (detected_s, direction)."""
    ds = load_dataset(dataset)
    _, t_move = motion(ds.pose, ds.manifest["gt_dt"])
    end = float(ds.manifest["seconds"]) if t_move is None else t_move
    fps, chunk = float(ds.manifest["fps"]), float(ds.manifest.get("chunk_seconds", math.inf))
    cam, lens = ds.camera, ds.camera.lens
    boxes = read_boxes(dataset / "detections.parquet", detector, lens, undistort=False)
    det = pd.read_parquet(dataset / "detections.parquet")
    det = det[det.detector == detector]
    by = {f: g for f, g in det.groupby("frame")}
    cal = OnlineCalibrator(boxes.K, cam.mount_height_m, fps, boxes.image_size, *HEIGHT, arl0_people=arl0, lens=lens)
    rows, alarms = [], []
    for frame, xyxy, ids in by_frame(boxes.frames, boxes.xyxy, boxes.track_ids):
        if frame / fps >= end:
            break
        s = cal.update(frame, xyxy, ids)
        if s.move:
            alarms.append((s.move.detected_s, s.move.direction))
        g = by.get(frame)
        for z, column in zip(s.person_z, s.person_columns):
            i = int(np.argmin(np.abs((g.x1 + g.x2).to_numpy() / 2 - column)))
            box = g.iloc[i]
            rows.append({"dataset": dataset.name, "t": s.t_s, "z": z, "height": box.y2 - box.y1, "agent": int(box.agent_id),
                         "split": bool(box.agent_id >= 0 and (g.agent_id == box.agent_id).sum() > 1),
                         "chunk_t": s.t_s % chunk, "up": s.cusum_up, "down": s.cusum_down, "alarm": s.move is not None})
    people = pd.DataFrame(rows)
    if len(people):
        people["u"] = np.clip(people.z, -CLIP, CLIP) / SD_CLIPPED
    return people, alarms


def dependence(people: pd.DataFrame) -> tuple[float, float]:
    """(lag-1 autocorrelation of u over consecutive tested people within each recording, the variance of sums of
    BLOCK consecutive u over BLOCK times the variance of u); u about its mean per recording."""
    num = den = 0.0
    sums = []
    for _, g in people.dropna(subset=["u"]).groupby("dataset", sort=False):
        u = g.u.to_numpy() - g.u.mean()
        num, den = num + float(np.sum(u[1:] * u[:-1])), den + float(np.sum(u * u))
        sums += [u[i:i + BLOCK].sum() for i in range(0, len(u) - BLOCK + 1, BLOCK)]
    var = den / max(len(people.dropna(subset=["u"])), 1)
    return num / den, float(np.mean(np.square(sums)) / (BLOCK * var)) if sums else math.nan


def summary(name: str, g: pd.DataFrame) -> str:
    z = g.z.dropna()
    return f"{name}: {len(z)} people, z mean {z.mean():+.2f}, RMS {np.sqrt(np.mean(z ** 2)):.2f}" if len(z) else f"{name}: none"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("datasets", nargs="+", type=Path, metavar="DIR")
    ap.add_argument("--detectors", default="segmentation,rgb")
    ap.add_argument("--arl0", type=float, default=DEFAULT_ARL0_PEOPLE, help="--arl0-people, people")
    args = ap.parse_args()
    normal = {c: math.erfc(c / math.sqrt(2)) for c in (2, 3, 4)}
    for detector in args.detectors.split(","):
        runs = [people_of(d, detector, args.arl0) for d in args.datasets]
        people = pd.concat([p for p, _ in runs], ignore_index=True)
        tested = people.dropna(subset=["z"])
        z = tested.z.to_numpy()
        print(f"\n{detector} boxes, --arl0-people {args.arl0:,.0f}: {len(people)} people, {len(tested)} tested, "
              f"{sum(len(a) for _, a in runs)} alarms")
        print("  |z| over 2, 3, 4: " + ", ".join(f"{np.mean(np.abs(z) > c) * 100:.2f} % (normal {p * 100:.2f} %)"
                                                  for c, p in normal.items()))
        print(f"  z mean {z.mean():+.3f}, median {np.median(z):+.3f}, MAD/0.6745 {np.median(np.abs(z - np.median(z))) / 0.6745:.2f}; "
              f"increments u: mean {tested.u.mean():+.3f}, RMS {np.sqrt(np.mean(tested.u ** 2)):.3f} (1 if z is standard normal)")
        u, h = tested.u.to_numpy(), cusum_threshold(args.arl0)
        sd, theta = float(np.sqrt(np.mean(u ** 2))), (tilt(u, CUSUM_K), tilt(-u, CUSUM_K))
        run = 1 / sum(1 / (2 * cusum_arl0(h, CUSUM_K, t, sd)) for t in theta)  # one side's is twice the two-sided figure
        print(f"  tilts of the increments u, S+ {theta[0]:.3f} and S- {theta[1]:.3f} (normal: {2 * CUSUM_K:g}), RMS {sd:.3f}: "
              f"Siegmund's mean run at the normal's threshold {h:.2f} is {run:,.0f} people (normal increments: {args.arl0:,.0f})")
        rho, ratio = dependence(people)
        print(f"  lag-1 autocorrelation of u {rho:+.3f} (independent: 0 +- {1 / math.sqrt(len(tested)):.3f}); "
              f"variance of sums of {BLOCK} over {BLOCK} x variance {ratio:.2f} (independent: 1)")
        bins = pd.cut(tested.height, HEIGHT_BINS_PX, right=False)
        for b, g in tested.groupby(bins, observed=True):
            print("  " + summary(f"box height {b.left}-{b.right} px", g))
        print("  " + summary("first 2 s of a chunk", tested[tested.chunk_t < 2]))
        print("  " + summary("the rest of a chunk", tested[tested.chunk_t >= 2]))
        print("  " + summary("boxes matched to nobody", tested[tested.agent < 0]))
        print("  " + summary("split boxes (an agent's second box)", tested[tested.split]))
        again = tested[(tested.agent >= 0) & tested.duplicated(["dataset", "agent"])]
        print("  " + summary("an agent observed again (its track lost and found)", again))
        for (p, alarms), dataset in zip(runs, args.datasets):
            for t, side in alarms:
                col = "up" if side > 0 else "down"
                before = p[(p.t < t) & (p[col] == 0)]
                run = p[(p.t > (before.t.max() if len(before) else -1)) & (p.t <= t)]
                print(f"  alarm {dataset.name} at {t:.1f} s ({'down' if side > 0 else 'up'} the image): "
                      f"{len(run)} people since its statistic was 0:")
                for r in run.itertuples():
                    print(f"    {r.t:6.1f} s (chunk {r.chunk_t:4.1f} s) z {r.z:+6.2f} box {r.height:5.1f} px agent {r.agent}"
                          + (" split" if r.split else ""))


if __name__ == "__main__":
    main()
