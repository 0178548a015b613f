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
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from homocal.correctors.pedestrians import PedestrianCorrector  # noqa: E402
from homocal.geometry import ViewTransformer  # noqa: E402
from homocal.watch import OnlineCalibrator  # noqa: E402
from homocal.watch.calibrator import DEFAULT_ARL0_PEOPLE  # noqa: E402
from simgen.boxstream import body_points, boxes_of  # noqa: E402
from simgen.scene import load_scene  # noqa: E402

HEIGHT = (1.71, 0.09)  # the datasets' own people (data_schema.md), as docs/pedestrians.md's measurements
CASES = {"step 0.5": lambda t, at: 0.5 * (t >= at), "step 1": lambda t, at: 1.0 * (t >= at),
         "step 2": lambda t, at: 2.0 * (t >= at), "ramp 2 over 60 s": lambda t, at: 2.0 * min(max(t - at, 0) / 60, 1),
         "sway 0.3, 60 s": lambda t, at: 0.3 * math.sin(2 * math.pi * t / 60)}


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


def run(scene, frames, fps, tilt, arl0, clicked):
    """The calibrator over the cached frames under the tilt: moves, (t, estimate, true row) per person and the
    estimate at every frame (row)."""
    cam0 = scene.camera
    cal = OnlineCalibrator(cam0.K, cam0.mount_height_m, fps, (cam0.width, cam0.height), *HEIGHT, arl0_people=arl0)
    moves, track, rows = [], [], np.full(len(frames), np.nan)
    for frame, points, ids in frames:
        t = frame / fps
        cam = dataclasses.replace(cam0, tilt_deg=cam0.tilt_deg + tilt(t))
        xyxy, seen = boxes_of(cam, points)
        s = cal.update(frame, xyxy, ids[seen])
        if s.move:
            moves.append(s.move)
        if s.person_rows:
            track.append((t, s.horizon_row, cam.horizon_row))
        rows[frame] = s.horizon_row
    return moves, np.array(track), rows


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
    args = ap.parse_args()
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
        alarms = sum(len(run(scene, f, args.fps, lambda t: 0.0, arl0, clicked)[0]) for f in cached)
        print(f"  ARL0 {arl0:>9,.0f}: {alarms} alarms in {hours:.2f} h = {alarms / hours:.2f} per hour")
    if args.static_only:
        return

    print(f"\nmoves at {args.at:g} s (ARL0 {args.case_arl0:,.0f}): delay median / 90th pct (s), missed, "
          "false alarms per hour, tracking RMS (px), range error 5-50 m static -> watched (%) at -10 s, and 0, 30, 60 s after detection")
    for name, shape in CASES.items():
        tilt = lambda t, shape=shape: shape(t, args.at)  # noqa: E731
        delays, false, rms, errors = [], 0, [], []
        for frames in cached:
            moves, track, rows = run(scene, frames, args.fps, tilt, args.case_arl0, clicked)
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
                cam = dataclasses.replace(cam0, tilt_deg=cam0.tilt_deg + tilt(frame / args.fps))
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
