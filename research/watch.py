"""How well homocal.watch.OnlineCalibrator notices a camera that moves, on render-free streams of a scene
(simgen.boxstream: the scene's walkers, the boxes of their bodies' visible pixels, people hiding people, no props
or detector noise).

Per seed, --minutes of the scene's walkers at --fps are posed once (``simgen.boxstream.bodies``) and seen by the
static camera and by the camera moving as each case says (``seen_boxes``), the move at --at seconds:

- static: no move (false alarms per simulated hour, at --arl0 values: the trade-off curve);
- step 0.5, 1, 2 degrees (further down); ramp: 2 degrees over 60 s; sway: 0.3 degrees, period 60 s.

Printed: per case, the detection delay (median, 90th percentile, s, of the first alarm after the move began)
and the missed moves (no alarm within the stream), the false alarms (before the move; on a swaying camera all
alarms) per simulated hour, the horizon tracking RMS against the true horizon (px, over the person
observations), and the median relative range error at 5-50 m (a grid of ground points straight ahead and to
the sides) of the static calibration (the true mapping of the camera before the move) and of the watched one
(PedestrianCorrector.from_horizon of the current estimate) 10 s before the move and 0, 30 and 60 s after its
detection. Then the throughput of OnlineCalibrator.update alone (boxes per second; times real time at the
scene's density and frame rate; the hidden-feet rule's share timed on its own) and its peak memory (tracemalloc, a second pass) after each --minutes of the
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
    python research/watch.py --datasets DIR [DIR ...] --detectors segmentation,rgb --work WORK2 --static-only --arl0 1000,20000
    python research/watch.py --datasets DIR [DIR ...] --detectors segmentation,rgb --work WORK3 --estimate-roll yes

(the second: the false alarms on the static minutes, the static recordings and the parts before each move, at each
--arl0; the third: with the roll estimated and tested, the watched calibration with each stretch's roll).
``--drift-test no`` runs homocal watch without its drift test (OnlineCalibrator(drift_test=False)), either way.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import json
import math
import pickle
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from homocal.cli import main as homocal_main  # noqa: E402
from homocal.correctors.pedestrians import PedestrianCorrector  # noqa: E402
from homocal.dataset import load_dataset  # noqa: E402
from homocal.geometry import PinholeCamera, ViewTransformer, read_trapezoid_file  # noqa: E402
from homocal.geometry.boxes import hidden_feet  # noqa: E402
from homocal.watch import OnlineCalibrator  # noqa: E402
from homocal.watch.calibrator import DEFAULT_ARL0_PEOPLE, stretch_correction  # noqa: E402
from simgen.boxstream import bodies, boxes_of  # noqa: E402
from simgen.scene import CameraMove, Sway, load_scene  # noqa: E402

HEIGHT = (1.71, 0.09)  # the datasets' own people (data_schema.md), as docs/pedestrians.md's measurements
CASES = {  # the camera's moves and sway (scene.toml's [[camera.moves]], [camera.sway]) for a move at ``at`` s
    "step 0.5": lambda at: ((CameraMove(at, tilt_deg=0.5),), None),
    "step 1": lambda at: ((CameraMove(at, tilt_deg=1.0),), None),
    "step 2": lambda at: ((CameraMove(at, tilt_deg=2.0),), None),
    "ramp 2 over 60 s": lambda at: ((CameraMove(at, 60.0, 2.0),), None),
    "sway 0.3, 60 s": lambda at: ((), Sway(0.3, 60.0)),
}


def seen_boxes(scenes: dict, seed: int, seconds: float, fps: float) -> dict[str, list]:
    """Per scene of ``scenes`` (the same walkers, each its camera's moves): the frames' (frame, xyxy (N, 4), ids (N,))
    of the seed's walkers, posed once (simgen.boxstream: ``bodies``, ``boxes_of``); a camera posed at a frame as
    another scene's reuses its boxes."""
    out: dict[str, list] = {name: [] for name in scenes}
    for frame, segments, radii, ids in bodies(next(iter(scenes.values())), seed, seconds, fps):
        done = {}
        for name, scene in scenes.items():
            cam = scene.camera_at(frame / fps)
            if cam not in done:
                xyxy, seen = boxes_of(cam, segments, radii)
                done[cam] = (frame, xyxy, ids[seen])
            out[name].append(done[cam])
    return out


def cached_boxes(cache: str | None, scenes: dict, seed: int, seconds: float, fps: float, at: float) -> dict[str, list]:
    """seen_boxes, kept in the folder ``cache`` (None: not kept) as one pickle per scene, seed, length, frame rate,
    move time and cases, and read back from there when it exists."""
    if cache is None:
        return seen_boxes(scenes, seed, seconds, fps)
    name = f"{next(iter(scenes.values())).name}_s{seed}_{seconds:g}s_{fps:g}fps_at{at:g}_{'+'.join(scenes)}.pickle"
    path = Path(cache) / name.replace(" ", "").replace(",", "")
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(pickle.dumps(seen_boxes(scenes, seed, seconds, fps)))
    return pickle.loads(path.read_bytes())


def ground_grid() -> np.ndarray:
    """Ground points (N, 2) m at ranges 5-50 m, 16 bearings within the view."""
    r, b = np.meshgrid(np.linspace(5, 50, 10), np.radians(np.linspace(-35, 35, 15)))
    return np.column_stack([(r * np.sin(b)).ravel(), (r * np.cos(b)).ravel()])


def range_error(transformer: ViewTransformer, camera, ground: np.ndarray) -> float:
    """Median |range - true range| / true range (%) of the ground points as the camera sees them, mapped back."""
    got = transformer.transform_points(camera.project_ground(ground))
    true = np.hypot(*ground.T)
    return float(np.nanmedian(np.abs(np.hypot(*got.T) - true) / true)) * 100


def run(scene, frames, fps, arl0, drift: bool = True):
    """The calibrator over the frames' boxes (``seen_boxes``) of the scene's camera as it moves (``Scene.camera_at``):
    moves, (t, estimate, true row) per person and the estimate at every frame (row)."""
    cam0 = scene.camera
    cal = OnlineCalibrator(cam0.K, cam0.mount_height_m, fps, (cam0.width, cam0.height), *HEIGHT, arl0_people=arl0,
                           drift_test=drift)
    moves, track, rows = [], [], np.full(len(frames), np.nan)
    for frame, xyxy, ids in frames:
        t = frame / fps
        cam = scene.camera_at(t)
        s = cal.update(frame, xyxy, ids)
        if s.move:
            moves.append(s.move)
        if s.person_rows:
            track.append((t, s.horizon_row, cam.horizon_row))
        rows[frame] = s.horizon_row
    return moves, np.array(track), rows


def motion(pose, gt_dt: float) -> tuple[str, float | None]:
    """A recording's camera motion, from its pose track (homocal's PoseTrack; None: a static camera), and when it
    starts (s; None: static): "step tilt +1" (the pose changes at once), "ramp tilt +2 over 60 s" (monotonically,
    over more than one step; it starts at the last unchanged step), "sway tilt 0.3" (it turns back; the largest
    change), of the angle that changes most; "static" when nothing changes."""
    if pose is None:
        return "static", None
    d = np.column_stack([pose.tilt_deg, pose.roll_deg, pose.yaw_deg])
    d = d - d[0]
    changed = np.flatnonzero(np.any(d != 0, axis=1))
    if not changed.size:
        return "static", None
    axis = int(np.argmax(np.abs(d).max(axis=0)))
    x, i = d[:, axis], changed[0]
    name = ("tilt", "roll", "yaw")[axis]
    steps = np.diff(x)
    if not (np.all(steps >= 0) or np.all(steps <= 0)):
        return f"sway {name} {np.abs(x).max():.3g}", float(pose.t[i - 1])
    reach = int(np.flatnonzero(x == x[-1])[0])
    if reach == i:
        return f"step {name} {x[-1]:+.3g}", float(pose.t[i])
    return f"ramp {name} {x[-1]:+.3g} over {(reach - i + 1) * gt_dt:.3g} s", float(pose.t[i - 1])


def watch_dataset(dataset: Path, detector: str, out: Path, arl0: float, measure: bool = True, roll: str = "no",
                  drift: str = "yes") -> dict:
    """``homocal watch`` on a dataset's boxes of ``detector`` (its hand-placed trapezoid, camera.json, the camera's
    true height, the people's own height prior, --estimate-roll ``roll``, --drift-test ``drift``) into ``out``, measured against the dataset's true camera
    (load_dataset's pose track): its motion and start (``motion``), the alarms before it (false: the static
    minutes), the first alarm after it on the side the horizon moved (the detection; none on a swaying camera:
    every alarm is false), the other alarms after it; with ``measure``, the horizon RMS (px) before the move and from the detection on (a
    missed move: from the move on; a sway: over the whole recording), and the median range error at 5-50 m (%) of the static and the watched calibration (the
    online estimate at that time) 10 s before the move and 0, 30, 60 s after its detection (those within the
    recording) and at its last frame."""
    ds = load_dataset(dataset)
    with contextlib.redirect_stdout(io.StringIO()):  # its one summary line; the figures are printed here
        code = homocal_main(["watch", "--trapezoid", str(dataset / "trapezoids.json"), "--boxes", str(dataset / "detections.parquet"),
                             "--detector", detector, "--fps", str(ds.manifest["fps"]), "--camera-json", str(dataset / "camera.json"),
                             "--camera-height", str(ds.camera.mount_height_m), "--height-mean", str(HEIGHT[0]),
                             "--height-sd", str(HEIGHT[1]), "--arl0-people", str(arl0), "--estimate-roll", roll,
                             "--drift-test", drift,
                             "--out", str(out)])
    assert code == 0, f"homocal watch failed on {dataset} ({detector})"
    case, t_move = motion(ds.pose, ds.manifest["gt_dt"])
    seconds = float(ds.manifest["seconds"])
    alarms = [(m["detected_s"], m["direction"], m["test"]) for m in json.loads((out / "moves.json").read_text())["moves"]]
    sway = case.startswith("sway")
    before = [a for a, _, _ in alarms if t_move is None or a < t_move or sway]
    after = [(a, side, test) for a, side, test in alarms if a not in before]
    # the detection: the first alarm after the move's start of the row or drift test on the side the horizon's row at
    # the principal column moved (+1: down the image), or of the roll test on the side the roll moved (+1: the horizon
    # down on the right, the roll smaller); any alarm when neither moved (a row by less than a pixel, a roll by
    # less than 0.1 degree: a yaw)
    rows = None if ds.pose is None else ds.pose.horizon_rows(ds.camera.K[0, 2])
    shift = 0.0 if rows is None else rows[-1] - rows[0]
    turn = 0.0 if ds.pose is None else ds.pose.roll_deg[-1] - ds.pose.roll_deg[0]
    found = [a for a, side, test in after if (abs(shift) < 1.0 and abs(turn) < 0.1) or (
        side == np.sign(shift) if test != "roll" else abs(turn) >= 0.1 and side == -np.sign(turn))]
    result = {"case": case, "t_move": t_move, "seconds": seconds, "static_s": seconds if t_move is None else t_move,
              "false": len(before), "detected": found[0] if found else None, "later": len(after) - bool(found)}
    if not measure:
        return result
    cam = json.loads((dataset / "camera.json").read_text())
    static = PinholeCamera(cam["width"], cam["height"], cam["hfov_deg"], cam["mount_height_m"], cam["tilt_deg"],
                           cam.get("roll_deg", 0.0), cam.get("yaw_deg", 0.0), tuple(cam.get("distortion", [0.0] * 5)))
    steps = ds.manifest["steps_total"]
    if ds.pose is None:
        a, b, c = static.horizon
        cameras, true_rows = [static] * steps, np.full(steps, -(a * static.K[0, 2] + c) / b)
    else:
        cameras = [dataclasses.replace(static, tilt_deg=a, roll_deg=b, yaw_deg=c)
                   for a, b, c in zip(ds.pose.tilt_deg, ds.pose.roll_deg, ds.pose.yaw_deg)]
        true_rows = rows
    horizon = pq.read_table(out / "horizon.parquet").to_pydict()
    t_s, row, roll = (np.array(horizon[c]) for c in ("t_s", "horizon_row_px", "roll_deg"))
    roll_sigma = np.array(horizon["roll_sigma_deg"])
    step_of = lambda t: np.minimum(np.round(np.asarray(t) / ds.manifest["gt_dt"]).astype(int), steps - 1)  # noqa: E731
    err = row - true_rows[step_of(t_s)]

    def rms(mask) -> float:
        return float(np.sqrt(np.nanmean(err[mask] ** 2))) if np.any(mask & np.isfinite(err)) else math.nan

    detected = result["detected"]
    result["rms_before"] = rms(np.ones(len(t_s), bool) if t_move is None or sway else t_s < t_move)
    result["rms_after"] = math.nan if t_move is None or sway else rms(t_s >= (t_move if detected is None else detected))
    clicked = read_trapezoid_file(dataset / "trapezoids.json", cameras[0].lens)[0]
    ground = ground_grid()
    prior = OnlineCalibrator(static.K, static.mount_height_m, ds.manifest["fps"], (static.width, static.height), *HEIGHT)

    def ranges_at(when: float) -> tuple[float, float] | None:
        i = np.searchsorted(t_s, when, side="right") - 1
        if when < 0 or when > seconds or i < 0 or not np.isfinite(row[i]):
            return None
        cam = cameras[step_of(when)]
        watched = stretch_correction(clicked, prior, row[i], 0.0, roll[i], roll_sigma[i], 3).transformer_
        return range_error(clicked, cam, ground), range_error(watched, cam, ground)

    whens = [] if t_move is None or sway else [t_move - 10] + ([] if detected is None else [detected, detected + 30, detected + 60])
    return {**result, "ranges": [ranges_at(when) for when in whens], "end": ranges_at(seconds - 1 / ds.manifest["fps"]),
            "people": len(t_s), "roll_end": (roll[-1], roll_sigma[-1], cameras[-1].roll_deg) if len(t_s) else None}


def pooled(results: list[dict]) -> dict:
    """watch_dataset's results of one detector pooled: per move case (in the order first seen) the delays (s, of
    the detected moves), the number missed, the horizon RMS before / from detection (px, RMS over the recordings)
    and the median range errors (static, watched; %) at each time; the static minutes (static recordings and the
    parts before each move), the false alarms in them and the rate per hour; the swaying minutes and their alarms."""
    cases: dict[str, dict] = {}
    for r in results:
        if r["t_move"] is None or r["case"].startswith("sway"):
            continue
        c = cases.setdefault(r["case"], {"delays": [], "missed": 0, "n": 0, "rms": [], "ranges": []})
        c["n"] += 1
        if r["detected"] is None:
            c["missed"] += 1
        else:
            c["delays"].append(r["detected"] - r["t_move"])
        c["rms"].append((r.get("rms_before", math.nan), r.get("rms_after", math.nan)))
        c["ranges"].append(r.get("ranges", []))
    for c in cases.values():
        c["rms"] = tuple(np.sqrt(np.nanmean(np.square(c["rms"]), axis=0))) if np.isfinite(c["rms"]).any() else (math.nan,) * 2
        width = max(map(len, c["ranges"]))
        c["ranges"] = [np.median([x[k] for x in c["ranges"] if len(x) > k and x[k] is not None], axis=0)
                       if any(len(x) > k and x[k] is not None for x in c["ranges"]) else None for k in range(width)]
    static_s = sum(r["static_s"] for r in results if not r["case"].startswith("sway"))
    false = sum(r["false"] for r in results if not r["case"].startswith("sway"))
    sway_s = sum(r["seconds"] for r in results if r["case"].startswith("sway"))
    sway = sum(r["false"] for r in results if r["case"].startswith("sway"))
    return {"cases": cases, "static_minutes": static_s / 60, "false": false,
            "false_per_hour": false / (static_s / 3600) if static_s else math.nan, "sway_minutes": sway_s / 60, "sway_alarms": sway}


def datasets_main(args) -> None:
    """--datasets: homocal watch on rendered recordings, per detector (watch_dataset), and the pooled figures; with
    --static-only, the false alarms on the static minutes at each --arl0 instead."""
    datasets = list(map(Path, args.datasets))
    for detector in args.detectors.split(","):
        if args.static_only:
            print(f"\n{detector} boxes: false alarms on the static minutes by ARL0 (people)")
            for arl0 in [float(a) for a in args.arl0.split(",")]:
                p = pooled([watch_dataset(d, detector, Path(args.work) / f"{d.name}_{detector}_{arl0:.0f}", arl0, False,
                                          args.estimate_roll, args.drift_test) for d in datasets])
                print(f"  ARL0 {arl0:>9,.0f}: {p['false']} alarms in {p['static_minutes']:.1f} min = {p['false_per_hour']:.1f} per hour")
            continue
        print(f"\n{detector} boxes, --arl0-people {args.case_arl0:,.0f}:")
        results = []
        for dataset in datasets:
            r = watch_dataset(dataset, detector, Path(args.work) / f"{dataset.name}_{detector}", args.case_arl0,
                              roll=args.estimate_roll, drift=args.drift_test)
            results.append(r)
            ranges = "; ".join("-" if x is None else f"{x[0]:.1f} -> {x[1]:.1f}" for x in r["ranges"])
            end = "-" if r["end"] is None else f"{r['end'][0]:.1f} -> {r['end'][1]:.1f}"
            move = r["case"] if r["t_move"] is None else f"{r['case']} at {r['t_move']:g} s"
            delay = "-" if r["detected"] is None else f"{r['detected'] - r['t_move']:.1f} s"
            print(f"  {dataset.name}: {move}, {r['people']} people; delay {delay}; {r['false']} alarms before, "
                  f"{r['later']} more after; horizon RMS {r['rms_before']:.2f} px before, {r['rms_after']:.2f} px from "
                  f"detection (or the move); range error static -> watched (%) at -10 s; detection; +30 s; +60 s: {ranges}; at the "
                  f"last frame: {end}; roll at the last person "
                  + ("-" if r["roll_end"] is None else "{:.2f} +- {:.2f} deg (true {:.2f})".format(*r["roll_end"])))
        p = pooled(results)
        for case, c in p["cases"].items():
            d = np.array(c["delays"])
            delay = f"{np.median(d):.1f} s / {np.percentile(d, 90):.1f} s" if d.size else "-"
            ranges = "; ".join("-" if x is None else f"{x[0]:.1f} -> {x[1]:.1f} %" for x in c["ranges"])
            print(f"  | {case} | {delay} | {c['missed']} of {c['n']} | {c['rms'][0]:.2f} / {c['rms'][1]:.2f} px | {ranges} |")
        print(f"  static: {p['false']} false alarms in {p['static_minutes']:.1f} minutes ({p['false_per_hour']:.1f} per hour); "
              f"swaying: {p['sway_alarms']} alarms in {p['sway_minutes']:.1f} minutes")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="scene1")
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--first-seed", type=int, default=0, help="the seeds are this one and the next --seeds - 1")
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--fps", type=float, default=5.0)
    ap.add_argument("--at", type=float, default=300.0, help="the move's time, s")
    ap.add_argument("--arl0", default=f"2000,5000,{DEFAULT_ARL0_PEOPLE},100000", help="static: ARL0 values, people")
    ap.add_argument("--static-only", action="store_true", help="only the static streams' false alarms")
    ap.add_argument("--case-arl0", type=float, default=DEFAULT_ARL0_PEOPLE, help="the moving cases' ARL0, people")
    ap.add_argument("--cache", metavar="DIR", help="keep the posed streams' boxes in DIR and read them back from there")
    ap.add_argument("--datasets", nargs="+", metavar="DIR", help="rendered simgen datasets instead (module docstring)")
    ap.add_argument("--detectors", default="segmentation,rgb", help="--datasets: the detectors whose boxes are watched")
    ap.add_argument("--work", default="watch-runs", help="--datasets: a folder for the homocal watch outputs (new)")
    ap.add_argument("--estimate-roll", choices=("yes", "no"), default="no", help="--datasets: homocal watch's --estimate-roll")
    ap.add_argument("--drift-test", choices=("yes", "no"), default="yes", help="homocal watch's --drift-test")
    args = ap.parse_args()
    if args.datasets:
        return datasets_main(args)
    scene = load_scene(Path(__file__).resolve().parents[1] / "simgen" / "scenes" / args.scene)
    cam0, seconds, drift = scene.camera, args.minutes * 60, args.drift_test == "yes"
    clicked = ViewTransformer(cam0.project_ground(scene.trapezoid_ground), scene.trapezoid_ground)
    ground = ground_grid()
    t0 = time.time()
    moving = {name: dataclasses.replace(scene, moves=case(args.at)[0], sway=case(args.at)[1]) for name, case in CASES.items()}
    scenes = {"static": scene, **({} if args.static_only else moving)}
    cached = [cached_boxes(args.cache, scenes, seed, seconds, args.fps, args.at)
              for seed in range(args.first_seed, args.first_seed + args.seeds)]
    hours = args.seeds * seconds / 3600
    people = sum(len(np.unique(np.concatenate([ids for _, _, ids in c["static"]]))) for c in cached)
    print(f"{args.scene}: {args.seeds} seeds from {args.first_seed} x {args.minutes:g} min at {args.fps:g} fps, {people:,} people in view "
          f"(static camera), posed and seen in {time.time() - t0:.0f} s")

    print("\nstatic: false alarms per simulated hour by ARL0 (people)")
    for arl0 in [float(a) for a in args.arl0.split(",")]:
        alarms = sum(len(run(scene, c["static"], args.fps, arl0, drift)[0]) for c in cached)
        print(f"  ARL0 {arl0:>9,.0f}: {alarms} alarms in {hours:.2f} h = {alarms / hours:.2f} per hour")
    if args.static_only:
        return

    print(f"\nmoves at {args.at:g} s (ARL0 {args.case_arl0:,.0f}): delay median / 90th pct (s), missed, "
          "false alarms per hour, tracking RMS (px), range error 5-50 m static -> watched (%) at -10 s, and 0, 30, 60 s after detection")
    for name in CASES:
        delays, false, rms, errors = [], 0, [], []
        for c in cached:
            moves, track, rows = run(moving[name], c[name], args.fps, args.case_arl0, drift)
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
                cam = moving[name].camera_at(frame / args.fps)
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
    for k, c in enumerate(cached):
        offset = int(k * seconds * args.fps)
        stream += [(frame + offset, xyxy, ids + 10**6 * k) for frame, xyxy, ids in c["static"]]
    def feed(watch_memory: bool) -> tuple[float, int, list, int]:
        cal = OnlineCalibrator(cam0.K, cam0.mount_height_m, args.fps, (cam0.width, cam0.height), *HEIGHT, drift_test=drift)
        start, boxes, peaks, hidden = time.perf_counter(), 0, [], 0
        for i, (frame, xyxy, ids) in enumerate(stream):
            hidden += cal.update(frame, xyxy, ids).hidden_boxes
            boxes += len(xyxy)
            if watch_memory and (i + 1) % int(seconds * args.fps) == 0:
                peaks.append(tracemalloc.get_traced_memory()[1] / 2**20)
        return time.perf_counter() - start, boxes, peaks, hidden

    elapsed, boxes, _, hidden = feed(False)
    start = time.perf_counter()
    for _, xyxy, _ in stream:
        hidden_feet(xyxy, np.zeros(len(xyxy), np.int64))
    alone = time.perf_counter() - start
    tracemalloc.start()
    peaks = feed(True)[2]
    tracemalloc.stop()
    per_second = boxes / (len(stream) / args.fps) * scene.fps / args.fps  # boxes a second of video at the scene's fps
    print(f"  {boxes:,} boxes in {elapsed:.1f} s: {boxes / elapsed:,.0f} boxes/s; the scene at {scene.fps} fps has "
          f"{per_second:.0f} boxes a second of video: {boxes / elapsed / per_second:.0f} times real time")
    print(f"  of which the hidden-feet rule (hidden_feet on every frame's boxes, timed alone): {alone:.1f} s; "
          f"{hidden:,} of the boxes measured may have hidden feet (left out)")
    print("  peak traced memory after each block of " + f"{args.minutes:g} min (MiB): " + ", ".join(f"{p:.2f}" for p in peaks))


if __name__ == "__main__":
    main()
