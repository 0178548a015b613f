"""How well homocal.watch.OnlineCalibrator notices a camera that moves, on render-free streams of a scene
(simgen.boxstream: the scene's walkers, boxes from their bodies' geometry, no occlusion or detector noise).

Per seed, --minutes of the scene's walkers at --fps are posed once (``body_points``, kept as each person's
at most 8 points extreme in the image of the static camera: 2 per side; the boxes they give under a camera
tilted up to 2 degrees are checked against all points' on the first seed and the mismatches printed), then
seen by the camera moving as each case says, the move at --at seconds:

- static: no move (false alarms per simulated hour, at --arl0 values: the trade-off curve);
- step 0.5, 1, 2 degrees (further down); ramp: 2 degrees over 60 s; sway: 0.3 degrees, period 60 s.

Printed: per case, the detection delay (median, 90th percentile, s, of the first alarm after the move began)
and the missed moves (no alarm within the stream), the false alarms (before the move; on a swaying camera all
alarms) per simulated hour, the horizon tracking RMS against the true horizon (px, over the person
observations), and the median relative range error at 5-50 m (a grid of ground points straight ahead and to
the sides) of the static calibration (the true mapping of the camera before the move) and of the watched one
(PedestrianCorrector.from_horizon of the current estimate) 10 s before the move and 0, 30 and 60 s after its
detection. Then the throughput of OnlineCalibrator.update alone (boxes per second; times real time at the
scene's density and frame rate) and its peak memory (tracemalloc, a second pass) after each --minutes of the
stream of all seeds back to back.

    python research/watch.py --scene scene1 --seeds 6 --minutes 10 --fps 5
    python research/watch.py --scene scene1 --seeds 6 --minutes 10 --fps 5 --static-only --arl0 50,100,200,500
    python research/watch.py --scene scene1 --seeds 6 --minutes 10 --fps 5 --arl0 1000 --case-arl0 1000

With --datasets, rendered recordings instead (simgen datasets of a scene whose camera moves: camera_pose.parquet
gives its pose; one without it is a static recording): ``homocal watch`` runs on each one's boxes of each of
--detectors (its hand-placed trapezoid, camera.json, the camera's true height, the people's own height prior,
--case-arl0) into --work, and is measured against the true pose (``watch_dataset``); printed per recording and
pooled per detector:

    python research/watch.py --datasets DIR [DIR ...] --detectors segmentation,rgb --work WORK
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import json
import math
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from homocal.cli import main as homocal_main  # noqa: E402
from homocal.correctors.pedestrians import PedestrianCorrector  # noqa: E402
from homocal.geometry import PinholeCamera, ViewTransformer, read_trapezoid_file  # noqa: E402
from homocal.watch import OnlineCalibrator  # noqa: E402
from homocal.watch.calibrator import DEFAULT_ARL0_PEOPLE  # noqa: E402
from simgen.boxstream import body_points, boxes_of  # noqa: E402
from simgen.scene import CameraMove, Sway, load_scene  # noqa: E402

HEIGHT = (1.71, 0.09)  # the datasets' own people (data_schema.md), as docs/pedestrians.md's measurements
CASES = {  # the camera's moves and sway (scene.toml's [[camera.moves]], [camera.sway]) for a move at ``at`` s
    "step 0.5": lambda at: ((CameraMove(at, tilt_deg=0.5),), None),
    "step 1": lambda at: ((CameraMove(at, tilt_deg=1.0),), None),
    "step 2": lambda at: ((CameraMove(at, tilt_deg=2.0),), None),
    "ramp 2 over 60 s": lambda at: ((CameraMove(at, 60.0, 2.0),), None),
    "sway 0.3, 60 s": lambda at: ((), Sway(0.3, 60.0)),
}


def reduced(points: np.ndarray, camera) -> np.ndarray:
    """Each person's at most 8 points (A, 8, 3) extreme in the camera's image: 2 per side."""
    uv = camera.project(points.reshape(-1, 3)).reshape(len(points), -1, 2)
    uv = np.where(np.isnan(uv), 0.0, uv)
    keys = [uv[:, :, 0], -uv[:, :, 0], uv[:, :, 1], -uv[:, :, 1]]
    idx = np.concatenate([np.argsort(k, axis=1)[:, :2] for k in keys], axis=1)
    return np.take_along_axis(points, idx[:, :, None], axis=1)


def ground_grid() -> np.ndarray:
    """Ground points (N, 2) m at ranges 5-50 m, 16 bearings within the view."""
    r, b = np.meshgrid(np.linspace(5, 50, 10), np.radians(np.linspace(-35, 35, 15)))
    return np.column_stack([(r * np.sin(b)).ravel(), (r * np.cos(b)).ravel()])


def range_error(transformer: ViewTransformer, camera, ground: np.ndarray) -> float:
    """Median |range - true range| / true range (%) of the ground points as the camera sees them, mapped back."""
    got = transformer.transform_points(camera.project_ground(ground))
    true = np.hypot(*ground.T)
    return float(np.nanmedian(np.abs(np.hypot(*got.T) - true) / true)) * 100


def run(scene, frames, fps, arl0):
    """The calibrator over the cached frames seen by the scene's camera as it moves (``Scene.camera_at``): moves,
    (t, estimate, true row) per person and the estimate at every frame (row)."""
    cam0 = scene.camera
    cal = OnlineCalibrator(cam0.K, cam0.mount_height_m, fps, (cam0.width, cam0.height), *HEIGHT, arl0_people=arl0)
    moves, track, rows = [], [], np.full(len(frames), np.nan)
    for frame, points, ids in frames:
        t = frame / fps
        cam = scene.camera_at(t)
        xyxy, seen = boxes_of(cam, points)
        s = cal.update(frame, xyxy, ids[seen])
        if s.move:
            moves.append(s.move)
        if s.person_rows:
            track.append((t, s.horizon_row, cam.horizon_row))
        rows[frame] = s.horizon_row
    return moves, np.array(track), rows


def true_cameras(dataset: Path) -> tuple[np.ndarray, list]:
    """(times (N,) s, PinholeCamera (N,)) of a dataset's camera at each ground-truth step: camera.json's camera
    posed as camera_pose.parquet says (the [camera] pose throughout when the dataset has none: a static camera)."""
    cam = json.loads((dataset / "camera.json").read_text())
    manifest = json.loads((dataset / "manifest.json").read_text())
    static = PinholeCamera(cam["width"], cam["height"], cam["hfov_deg"], cam["mount_height_m"], cam["tilt_deg"],
                           cam.get("roll_deg", 0.0), cam.get("yaw_deg", 0.0), tuple(cam.get("distortion", [0.0] * 5)))
    if not (dataset / "camera_pose.parquet").is_file():
        return np.arange(manifest["steps_total"]) * 0.05, [static] * manifest["steps_total"]
    pose = pq.read_table(dataset / "camera_pose.parquet").to_pydict()
    cameras = [dataclasses.replace(static, tilt_deg=a, roll_deg=b, yaw_deg=c)
               for a, b, c in zip(pose["tilt_deg"], pose["roll_deg"], pose["yaw_deg"])]
    return np.array(pose["t"]), cameras


def watch_dataset(dataset: Path, detector: str, out: Path, arl0: float) -> dict:
    """``homocal watch`` on a dataset's boxes of ``detector`` (its hand-placed trapezoid, camera.json, the camera's
    true height, the people's own height prior) into ``out``, measured against the dataset's true camera: the move
    (the first step whose pose differs from the first's), the first alarm after it, the other alarms (false), the
    horizon RMS (px) before the move and from the detection on, and the median range error at 5-50 m (%) of the
    static and the watched calibration (the online estimate at that time) 10 s before the move and 0, 30, 60 s
    after its detection (those within the recording)."""
    manifest = json.loads((dataset / "manifest.json").read_text())
    cam_height = json.loads((dataset / "camera.json").read_text())["mount_height_m"]
    with contextlib.redirect_stdout(io.StringIO()):  # its one summary line; the figures are printed here
        code = homocal_main(["watch", "--trapezoid", str(dataset / "trapezoids.json"), "--boxes", str(dataset / "detections.parquet"),
                             "--detector", detector, "--fps", str(manifest["fps"]), "--camera-json", str(dataset / "camera.json"),
                             "--camera-height", str(cam_height), "--height-mean", str(HEIGHT[0]), "--height-sd", str(HEIGHT[1]),
                             "--arl0-people", str(arl0), "--out", str(out)])
    assert code == 0, f"homocal watch failed on {dataset} ({detector})"
    times, cameras = true_cameras(dataset)
    angles = np.array([(c.tilt_deg, c.roll_deg, c.yaw_deg) for c in cameras])
    moved = np.flatnonzero(np.any(angles != angles[0], axis=1))
    t_move = float(times[moved[0]]) if moved.size else float(manifest["seconds"])
    alarms = [m["detected_s"] for m in json.loads((out / "moves.json").read_text())["moves"]]
    detected = next((a for a in alarms if a >= t_move), None) if moved.size else None
    horizon = pq.read_table(out / "horizon.parquet").to_pydict()
    t_s, row = np.array(horizon["t_s"]), np.array(horizon["horizon_row_px"])
    true_row = np.array([_row(cameras[min(round(t * 20), len(cameras) - 1)]) for t in t_s])
    err = row - true_row

    def rms(mask) -> float:
        return float(np.sqrt(np.nanmean(err[mask] ** 2))) if np.any(mask & np.isfinite(err)) else math.nan

    clicked = read_trapezoid_file(dataset / "trapezoids.json", cameras[0].lens)[0]
    ground, ranges = ground_grid(), []
    for when in [t_move - 10] + ([] if detected is None else [detected, detected + 30, detected + 60]):
        i = np.searchsorted(t_s, when, side="right") - 1
        if when < 0 or when > times[-1] or i < 0 or not np.isfinite(row[i]):
            ranges.append(None)
            continue
        cam = cameras[min(round(when * 20), len(cameras) - 1)]
        watched = PedestrianCorrector(*HEIGHT).from_horizon(clicked, row[i], 0.0, cam.K, cam_height, 3).transformer_
        ranges.append((range_error(clicked, cam, ground), range_error(watched, cam, ground)))
    return {"t_move": t_move if moved.size else None, "size_deg": (angles[-1] - angles[0]).tolist(), "detected": detected,
            "false": len(alarms) - (detected is not None), "seconds": manifest["seconds"], "rms_before": rms(t_s < t_move),
            "rms_after": rms(t_s >= detected) if detected is not None else math.nan, "ranges": ranges, "people": len(t_s)}


def _row(camera) -> float:
    """The horizon's row at the principal point's column (undistorted image), px."""
    a, b, c = camera.horizon
    return float(-(a * camera.K[0, 2] + c) / b)


def datasets_main(args) -> None:
    """--datasets: homocal watch on rendered recordings, per detector (watch_dataset), and the pooled figures."""
    for detector in args.detectors.split(","):
        print(f"\n{detector} boxes, --arl0-people {args.case_arl0:,.0f}:")
        delays, false, seconds, missed = [], 0, 0.0, 0
        for dataset in map(Path, args.datasets):
            r = watch_dataset(dataset, detector, Path(args.work) / f"{dataset.name}_{detector}", args.case_arl0)
            false, seconds = false + r["false"], seconds + r["seconds"]
            if r["t_move"] is not None:
                if r["detected"] is None:
                    missed += 1
                else:
                    delays.append(r["detected"] - r["t_move"])
            ranges = "; ".join("-" if x is None else f"{x[0]:.1f} -> {x[1]:.1f}" for x in r["ranges"])
            move = "static" if r["t_move"] is None else f"tilt {r['size_deg'][0]:+g} deg at {r['t_move']:g} s"
            delay = "-" if r["detected"] is None else f"{r['detected'] - r['t_move']:.1f} s"
            print(f"  {dataset.name}: {move}, {r['people']} people; delay {delay}; {r['false']} other alarms; "
                  f"horizon RMS {r['rms_before']:.2f} px before, {r['rms_after']:.2f} px from detection; range error "
                  f"static -> watched (%) at -10 s; detection; +30 s; +60 s: {ranges}")
        found = (f"median {np.median(delays):.1f} s, 90th pct {np.percentile(delays, 90):.1f} s" if delays else "none found")
        print(f"  pooled: delay {found}, missed {missed}; {false} false alarms (all but the first after each move) in "
              f"{seconds / 60:.1f} minutes ({false / (seconds / 3600):.1f} per hour)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="scene1")
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--fps", type=float, default=5.0)
    ap.add_argument("--at", type=float, default=300.0, help="the move's time, s")
    ap.add_argument("--arl0", default=f"2000,5000,{DEFAULT_ARL0_PEOPLE},100000", help="static: ARL0 values, people")
    ap.add_argument("--static-only", action="store_true", help="only the static streams' false alarms")
    ap.add_argument("--case-arl0", type=float, default=DEFAULT_ARL0_PEOPLE, help="the moving cases' ARL0, people")
    ap.add_argument("--datasets", nargs="+", metavar="DIR", help="rendered simgen datasets instead (module docstring)")
    ap.add_argument("--detectors", default="segmentation,rgb", help="--datasets: the detectors whose boxes are watched")
    ap.add_argument("--work", default="watch-runs", help="--datasets: a folder for the homocal watch outputs (new)")
    args = ap.parse_args()
    if args.datasets:
        return datasets_main(args)
    scene = load_scene(Path(__file__).resolve().parents[1] / "simgen" / "scenes" / args.scene)
    cam0, seconds = scene.camera, args.minutes * 60
    clicked = ViewTransformer(cam0.project_ground(scene.trapezoid_ground), scene.trapezoid_ground)
    ground = ground_grid()
    t0 = time.time()
    cached = []
    for seed in range(args.seeds):
        frames = []
        for frame, points, ids in body_points(scene, seed, seconds, args.fps):
            small = reduced(points, cam0) if len(points) else points
            if seed == 0 and frame % 50 == 0 and len(points):
                moved = dataclasses.replace(cam0, tilt_deg=cam0.tilt_deg + 2.0)
                assert np.array_equal(boxes_of(moved, points)[0], boxes_of(moved, small)[0]), frame
            frames.append((frame, small, ids))
        cached.append(frames)
    hours = args.seeds * seconds / 3600
    print(f"{args.scene}: {args.seeds} seeds x {args.minutes:g} min at {args.fps:g} fps posed in {time.time() - t0:.0f} s "
          f"(boxes from the 8 extreme points equal all points' under a 2 degree tilt on seed 0, every 50th frame)")

    print("\nstatic: false alarms per simulated hour by ARL0 (people)")
    for arl0 in [float(a) for a in args.arl0.split(",")]:
        alarms = sum(len(run(scene, f, args.fps, arl0)[0]) for f in cached)
        print(f"  ARL0 {arl0:>9,.0f}: {alarms} alarms in {hours:.2f} h = {alarms / hours:.2f} per hour")
    if args.static_only:
        return

    print(f"\nmoves at {args.at:g} s (ARL0 {args.case_arl0:,.0f}): delay median / 90th pct (s), missed, "
          "false alarms per hour, tracking RMS (px), range error 5-50 m static -> watched (%) at -10 s, and 0, 30, 60 s after detection")
    for name, motion in CASES.items():
        moving = dataclasses.replace(scene, moves=motion(args.at)[0], sway=motion(args.at)[1])
        delays, false, rms, errors = [], 0, [], []
        for frames in cached:
            moves, track, rows = run(moving, frames, args.fps, args.case_arl0)
            sway = name.startswith("sway")
            false += len(moves) if sway else sum(m.detected_s < args.at for m in moves)
            after = [m.detected_s for m in moves if m.detected_s >= args.at]
            rms.append(np.sqrt(np.mean((track[:, 1] - track[:, 2]) ** 2)))
            if sway or not after:
                delays.append(math.inf if not sway else math.nan)
                continue
            delays.append(after[0] - args.at)
            row_errors = []
            for when in (args.at - 10, after[0], after[0] + 30, after[0] + 60):
                frame = min(int(when * args.fps), len(rows) - 1)
                cam = moving.camera_at(frame / args.fps)
                watched = PedestrianCorrector(*HEIGHT).from_horizon(clicked, rows[frame], 0.0, cam0.K,
                                                                     cam0.mount_height_m, 3).transformer_
                row_errors.append((range_error(clicked, cam, ground), range_error(watched, cam, ground)))
            errors.append(row_errors)
        d = np.array(delays)
        found = d[np.isfinite(d)]
        delay = (f"{np.median(found):5.1f} / {np.percentile(found, 90):5.1f}" if found.size else "  -  /  -  ")
        err = ""
        if errors:
            e = np.median(np.array(errors), axis=0)
            err = "; ".join(f"{s:.1f} -> {w:.1f}" for s, w in e)
        print(f"  {name:18s} delay {delay}, missed {int(np.isinf(d).sum())} of {len(d)}, false alarms "
              f"{false / hours:.2f}/h, RMS {np.sqrt(np.mean(np.square(rms))):.2f} px; {err}")

    print("\nthroughput and memory (all seeds' static streams back to back)")
    stream = []
    for k, frames in enumerate(cached):
        offset = int(k * seconds * args.fps)
        for frame, points, ids in frames:
            xyxy, seen = boxes_of(cam0, points)
            stream.append((frame + offset, xyxy, ids[seen] + 10**6 * k))
    def feed(watch_memory: bool) -> tuple[float, int, list]:
        cal = OnlineCalibrator(cam0.K, cam0.mount_height_m, args.fps, (cam0.width, cam0.height), *HEIGHT)
        start, boxes, peaks = time.perf_counter(), 0, []
        for i, (frame, xyxy, ids) in enumerate(stream):
            cal.update(frame, xyxy, ids)
            boxes += len(xyxy)
            if watch_memory and (i + 1) % int(seconds * args.fps) == 0:
                peaks.append(tracemalloc.get_traced_memory()[1] / 2**20)
        return time.perf_counter() - start, boxes, peaks

    elapsed, boxes, _ = feed(False)
    tracemalloc.start()
    peaks = feed(True)[2]
    tracemalloc.stop()
    per_second = boxes / (len(stream) / args.fps) * scene.fps / args.fps  # boxes a second of video at the scene's fps
    print(f"  {boxes:,} boxes in {elapsed:.1f} s: {boxes / elapsed:,.0f} boxes/s; the scene at {scene.fps} fps has "
          f"{per_second:.0f} boxes a second of video: {boxes / elapsed / per_second:.0f} times real time")
    print("  peak traced memory after each block of " + f"{args.minutes:g} min (MiB): " + ", ".join(f"{p:.2f}" for p in peaks))


if __name__ == "__main__":
    main()
