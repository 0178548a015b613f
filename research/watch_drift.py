"""The within-person block residuals (homocal.watch.drift) on a steady camera: their scale, tails and lag-1
correlation at a few block lengths, on render-free streams (research/watch.py's cached posed streams: --cache) and
on rendered recordings (--datasets, each detector's boxes linked by overlap as ``homocal watch`` links them).

Per stream and block length: the usable boxes (the calibrator's: not cut by the border, feet not hidden) of each
track give blocks and their recursive residuals e (DriftTest, unarmed); printed, pooled over the streams: the
residuals, s (the median absolute e / 0.6745: the blocks' edge noise, px), the share of |e / s| beyond 3 and 4
(normal: 0.27 % and 0.006 %), the root mean square of e / s clipped at 3 (normal: 0.89), the mean of e / s by
the block's place in its track (1, 2-4, 5 and on: a walk-dependent bias shows as a drift of this mean), the
lag-1 correlation of a track's successive residuals (0 for independent blocks), and the median of D / (s g), the
standardised shift of a 1-degree tilt step at the boxes' edge gains g (D = f tan(1 degree) px, the horizon's
shift near the principal point).

    python research/watch.py --scene scene1 --seeds 6 --minutes 10 --fps 5 --cache CACHE   # makes the streams
    python research/watch_drift.py --cache CACHE --seeds 0,1,2 --blocks 1,2,4
    python research/watch_drift.py --datasets /work/wt/moves2-data/rec/static_scene1_s4 ... --blocks 1,2,4

With --alarms WORK, instead: ``homocal watch`` on each recording's boxes (research/watch.py's ``watch_dataset``, the
default --arl0-people, into WORK) and, per drift test alarm on its static minutes, the residuals that made it: the
alarming side's run since its statistic last left 0 (its residuals, tracks and seconds), the mean of e / s over it
(signed the side's way), the share beyond 3, and the clipped increments' sum carried by its two largest tracks.

    python research/watch_drift.py --datasets DIRS --detectors rgb --alarms WORK
"""
from __future__ import annotations

import argparse
import json
import math
import pickle
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from homocal.boxes import read_boxes  # noqa: E402
from homocal.geometry.boxes import TrackLinker, hidden_feet, on_border  # noqa: E402
from homocal.correctors.pedestrians import LINK_GAP  # noqa: E402
from homocal.watch.calibrator import by_frame  # noqa: E402
from homocal.watch.calibrator import BOX_SIGMA_PX  # noqa: E402
from homocal.watch.drift import DriftTest, edge_gains  # noqa: E402

HEIGHT_M, HEIGHT_SD_M = 1.71, 0.09  # the datasets' people (research/watch.py's HEIGHT)


def residuals(frames, K, camera_height_m, size, fps, block_s, until_s=math.inf):
    """(track id, e, block index) of every block residual of the frames' boxes [(frame, xyxy, ids or None)] up to
    until_s, and the edge gains of the usable boxes."""
    test, linker, out, gains, index = DriftTest(K, camera_height_m, fps, HEIGHT_M, HEIGHT_SD_M, block_s), TrackLinker(max_gap=LINK_GAP), [], [], {}
    for frame, xyxy, ids in frames:
        t = frame / fps
        if t >= until_s:
            break
        ids = linker.link(frame, xyxy) if ids is None else ids
        g = edge_gains(xyxy, K, camera_height_m, HEIGHT_M)[2]
        usable = ~on_border(xyxy, size) & ~hidden_feet(xyxy, np.zeros(len(xyxy), np.int64))
        gains += g[usable & np.isfinite(g)].tolist()
        for key, e in test.update(t, frame, ids, xyxy, usable, None):
            index[key] = index.get(key, 0) + 1
            out.append((key, e, index[key]))
    return out, gains


def summary(name: str, res: list, gains: list, step_px: float) -> None:
    """Print the pooled figures (module docstring) of the residuals res [(key, e, k)] of one block length."""
    e = np.array([r[1] for r in res])
    s = max(float(np.median(np.abs(e))) / 0.6745, BOX_SIGMA_PX)
    z = e / s
    k = np.array([r[2] for r in res])
    pairs, last = [], {}
    for key, x, _ in res:  # successive residuals of a track
        if key in last:
            pairs.append((last[key], x))
        last[key] = x
    p = np.array(pairs)
    lag1 = float(np.corrcoef(p[:, 0], p[:, 1])[0, 1]) if len(p) > 2 else math.nan
    by_k = "; ".join(f"{lab} {np.mean(z[m]):+.2f} ({m.sum()})" for lab, m in
                     (("1", k == 1), ("2-4", (k >= 2) & (k <= 4)), ("5+", k >= 5)) if m.any())
    rms = float(np.sqrt(np.mean(np.clip(z, -3, 3) ** 2)))
    print(f"  {name}: {len(e)} residuals, s {s:.2f} px, |e/s| > 3: {np.mean(np.abs(z) > 3) * 100:.2f} %, > 4: "
          f"{np.mean(np.abs(z) > 4) * 100:.2f} %, clipped RMS {rms:.2f}, mean by block: {by_k}; lag-1 corr "
          f"{lag1:+.2f}; 1-degree step / (s g) median {np.median(step_px / (s * np.array(gains))):.1f}")


def alarm_runs(datasets: list[Path], detectors: list[str], work: Path) -> None:
    """Print the runs behind each drift alarm on the datasets' static minutes (module docstring)."""
    from watch import watch_dataset  # research/watch.py

    from homocal.watch.calibrator import CLIP, CUSUM_K, SD_CLIPPED
    log, update = [], DriftTest.update

    def logged(self, t, *args):
        out = update(self, t, *args)
        log.extend((t, key, e / self.scale, tuple(self.cusum)) for key, e in out)
        return out

    DriftTest.update = logged
    for d in datasets:
        for detector in detectors:
            log.clear()
            out = work / f"{d.name}_{detector}"
            static_s = watch_dataset(d, detector, out, 20000.0, measure=False)["static_s"]
            for m in json.loads((out / "moves.json").read_text())["moves"]:
                if m["test"] != "drift" or m["detected_s"] >= static_s:
                    continue
                side, run = (0 if m["direction"] > 0 else 1), []
                for t, key, z, cusum in (x for x in reversed(log) if x[0] <= m["detected_s"]):
                    if cusum[side] == 0.0:
                        break
                    run.append((t, key, z * m["direction"]))
                z = np.array([r[2] for r in run])
                u = np.clip(z, -CLIP, CLIP) / SD_CLIPPED - CUSUM_K
                by_track = {}
                for (_, key, _), x in zip(run, u):
                    by_track[key] = by_track.get(key, 0.0) + x
                top = sum(sorted(by_track.values())[-2:])
                print(f"  {d.name} {detector}: drift alarm declared at {m['detected_s']:.1f} s; its run {len(run)} residuals "
                      f"of {len(by_track)} tracks over {run[0][0] - run[-1][0]:.1f} s, mean e/s {z.mean():+.2f}, "
                      f"|e/s| > 3: {np.mean(np.abs(z) > 3) * 100:.0f} %, the two largest tracks' share of the "
                      f"increments' sum {top / u.sum() * 100:.0f} %")
    DriftTest.update = update


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cache", help="research/watch.py --cache's folder (render-free streams)")
    ap.add_argument("--scene", default="scene1")
    ap.add_argument("--seeds", default="0,1,2", help="render-free seeds")
    ap.add_argument("--datasets", nargs="+", metavar="DIR", help="rendered recordings (their static part)")
    ap.add_argument("--detectors", default="segmentation,rgb")
    ap.add_argument("--blocks", default="1,2,4", help="block lengths, s")
    ap.add_argument("--alarms", metavar="WORK", help="the drift alarms' runs on --datasets instead (homocal watch into WORK)")
    args = ap.parse_args()
    if args.alarms:
        return alarm_runs([Path(d) for d in args.datasets], args.detectors.split(","), Path(args.alarms))
    blocks = [float(b) for b in args.blocks.split(",")]
    if args.cache:
        from simgen.scene import load_scene
        scene = load_scene(Path(__file__).resolve().parents[1] / "simgen" / "scenes" / args.scene)
        cam = scene.camera
        streams = []
        for seed in map(int, args.seeds.split(",")):
            path = sorted(Path(args.cache).glob(f"{args.scene}_s{seed}_*.pickle"))[0]
            streams.append(pickle.loads(path.read_bytes())["static"])
        fps = float(path.name.split("_")[3].removesuffix("fps"))
        print(f"render-free {args.scene}, seeds {args.seeds}, {fps:g} fps:")
        for b in blocks:
            res, gains = [], []
            for frames in streams:
                r, g = residuals(frames, cam.K, cam.mount_height_m, (cam.width, cam.height), fps, b)
                res += [(key + 10**7 * len(res), e, k) for key, e, k in r]
                gains += g
            summary(f"block {b:g} s", res, gains, cam.K[1, 1] * math.tan(math.radians(1)))
    for detector in (args.detectors.split(",") if args.datasets else []):
        print(f"rendered, {detector} boxes (static parts):")
        for b in blocks:
            res, gains = [], []
            for d in map(Path, args.datasets):
                manifest = json.loads((d / "manifest.json").read_text())
                cam = json.loads((d / "camera.json").read_text())
                boxes = read_boxes(d / "detections.parquet", detector, None, undistort=False)
                until = 30.0 if (d / "camera_pose.parquet").exists() and not d.name.startswith("static") else math.inf
                K = boxes.K
                r, g = residuals(by_frame(boxes.frames, boxes.xyxy, None), K, cam["mount_height_m"], boxes.image_size,
                                 float(manifest["fps"]), b, until)
                res += [(key + 10**7 * len(res), e, k) for key, e, k in r]
                gains += g
            summary(f"block {b:g} s", res, gains, K[1, 1] * math.tan(math.radians(1)))


if __name__ == "__main__":
    main()
