"""The same scene seen by other cameras: a dataset's ground truth reprojected exactly, for the study's exact
foot points (docs/real-camera.md, "Why the paper's methods lose on scene3").

Run: python research/camera_variants.py DATASET -o OUT [--roll DEG] [--yaw DEG] [--distortion K1,K2,P1,P2,K3]
         [--tilt DEG] [--hand-placed offsets|exact|draw:SEED[:NAME]] [--scene NAME]

DATASET is a simgen dataset (camera.json with K, R, t, its pose keys and distortion); OUT a new folder. Every
ground point of DATASET (gt.parquet's agents' contact points x, y; calibration.parquet's objects; the trapezoid's
ground corners) keeps its world position and is projected through the camera of DATASET's camera.json with
--roll, --yaw, --tilt and --distortion in place of its own (each defaults to DATASET's): gt's u, v and in_frame,
calibration's u_exact, v_exact (and u, v, x1..y2: left NaN, no detector ran), the exact trapezoid. camera.json is
written by simgen's codec (homocal.geometry.camera_file.camera_json_dict). The hand-placed trapezoid:
  offsets (default): DATASET's hand-placed image corners minus its exact ones, both undistorted with DATASET's
          lens (px of the pinhole image), added to the new exact corners of the pinhole image and distorted with
          the new lens: the same clicking error, seen by the new camera; the map corners as DATASET's;
  exact:  the exact corners (image and map);
  draw:SEED[:NAME]: clicked anew on the new camera's frame as scenes/make_scene_assets.py clicks a scene's (each
          corner 1-2 px off in a random direction, rounded; its ``hand_placed``), keyed by SEED and NAME (default:
          the scene's name): seed 2024 gives the shipped scenes' own (scene3's on scene3's camera, scene1's with
          NAME scene1 on scene1's).
--scene NAME: the dataset's scene name (manifest.json's scene, default DATASET's), which keys the study's random
draws (its variants' perturbations) and draw:SEED's default NAME.
detections.parquet is written empty (the study's exact foot source needs none); manifest.json says which scene
and camera it came from. The study's exact foot source then gives what `simgen generate` of a scene with that
camera gives, up to its hand-placed trapezoid (a scene's own is drawn by scenes/make_scene_assets.py).
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from homocal.files import read_json
from homocal.geometry import PinholeCamera
from homocal.geometry.camera_file import camera_json_dict, read_camera
from scenes.make_scene_assets import hand_placed as clicked
from simgen.rng import keyed_generator
from simgen.scene import in_frame


def dataset_camera(camera_json: dict) -> PinholeCamera:
    """The PinholeCamera camera.json describes (its size, field of view, height, tilt, roll, yaw, distortion)."""
    return PinholeCamera(camera_json["width"], camera_json["height"], camera_json["hfov_deg"],
                         camera_json["mount_height_m"], camera_json["tilt_deg"], camera_json.get("roll_deg", 0.0),
                         camera_json.get("yaw_deg", 0.0), tuple(camera_json.get("distortion", (0.0,) * 5)))


def seen(camera: PinholeCamera, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the camera's pixels (N, 2), in frame (N,) bool) of ground points xy (N, 2) m, as simgen writes them."""
    pixels = camera.project_ground(xy)
    return pixels, in_frame(camera, pixels)


def reproject(src: Path, out: Path, camera: PinholeCamera, hand_placed: str, scene: str) -> None:
    """Write OUT: DATASET src's ground truth seen by camera, named scene (the module's docstring)."""
    old = read_camera(src / "camera.json")
    origin = tuple(float(x) for x in old.camera_origin)
    out.mkdir(parents=True)
    gt = pq.read_table(src / "gt.parquet")
    uv, inside = seen(camera, np.column_stack([gt.column("x").to_numpy(), gt.column("y").to_numpy()]))
    for name, values in (("u", uv[:, 0]), ("v", uv[:, 1]), ("in_frame", inside)):
        gt = gt.set_column(gt.schema.get_field_index(name), name, pa.array(values))
    pq.write_table(gt, out / "gt.parquet")
    cal = pq.read_table(src / "calibration.parquet")
    uv, inside = seen(camera, np.column_stack([cal.column("x").to_numpy(), cal.column("y").to_numpy()]))
    if not inside.all():
        sys.exit(f"camera_variants: error: calibration objects {np.flatnonzero(~inside).tolist()} leave the frame")
    for name in cal.schema.names:
        values = {"u_exact": uv[:, 0], "v_exact": uv[:, 1]}.get(name)
        if values is None and name in ("u", "v", "x1", "y1", "x2", "y2"):
            values = np.full(len(uv), np.nan)
        if values is not None:
            cal = cal.set_column(cal.schema.get_field_index(name), name, pa.array(values))
    pq.write_table(cal, out / "calibration.parquet")
    detections = pq.read_table(src / "detections.parquet")
    pq.write_table(detections.slice(0, 0), out / "detections.parquet")

    traps = read_json(src / "trapezoids.json")
    ground = np.asarray(traps["ground_m"], float)
    exact_pinhole = replace(camera, distortion=(0.0,) * 5).project_ground(ground)
    exact = camera.project_ground(ground)
    image, site_map = exact, np.asarray(traps["exact"]["map"], float)
    if hand_placed == "offsets":
        undistort = (lambda q: q) if old.lens is None else old.lens.undistort_points
        click = undistort(np.asarray(traps["hand_placed"]["image"], float)) - undistort(np.asarray(traps["exact"]["image"], float))
        image, site_map = camera.lens.distort_points(exact_pinhole + click), np.asarray(traps["hand_placed"]["map"], float)
    elif hand_placed.startswith("draw:"):
        _, seed, *name = hand_placed.split(":")
        rng = keyed_generator(int(seed), name[0] if name else scene, "hand-placed trapezoid")
        image, site_map = (clicked(corners, rng).astype(float) for corners in (exact, site_map))
    traps["exact"]["image"], traps["hand_placed"] = exact.tolist(), {"image": image.tolist(), "map": site_map.tolist()}
    (out / "trapezoids.json").write_text(json.dumps(traps, indent=2))
    (out / "camera.json").write_text(json.dumps(camera_json_dict(camera, origin), indent=2))
    manifest = read_json(src / "manifest.json")
    manifest |= {"scene": scene, "detectors": [], "config_hash": f"{manifest.get('config_hash', '')}+{camera}+{hand_placed}",
                 "reprojected_from": str(src), "camera": str(camera), "hand_placed": hand_placed}
    (out / "manifest.json").write_text(json.dumps(manifest, indent=2))
    for name in ("site_map.json", "site_map.png"):
        shutil.copyfile(src / name, out / name)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("-o", "--out", type=Path, required=True, help="a new folder")
    ap.add_argument("--roll", type=float, help="roll_deg (default: the dataset's)")
    ap.add_argument("--yaw", type=float, help="yaw_deg (default: the dataset's)")
    ap.add_argument("--tilt", type=float, help="tilt_deg (default: the dataset's)")
    ap.add_argument("--distortion", help="k1,k2,p1,p2,k3 (default: the dataset's; 0 for none)")
    ap.add_argument("--hand-placed", default="offsets", help="offsets, exact or draw:SEED[:NAME]")
    ap.add_argument("--scene", help="the dataset's scene name (default: DATASET's)")
    args = ap.parse_args(argv)
    if args.out.exists():
        sys.exit(f"camera_variants: error: --out {args.out} exists")
    data = read_json(args.dataset / "camera.json")
    given = {"roll_deg": args.roll, "yaw_deg": args.yaw, "tilt_deg": args.tilt}
    data |= {k: v for k, v in given.items() if v is not None}
    if args.distortion is not None:
        values = [float(x) for x in args.distortion.split(",")]
        data["distortion"] = values if len(values) == 5 else values * 5 if values == [0.0] else sys.exit(
            "camera_variants: error: --distortion: expected 5 numbers k1,k2,p1,p2,k3 or 0")
    if not (args.hand_placed in ("offsets", "exact") or re.fullmatch(r"draw:\d+(:\w+)?", args.hand_placed)):
        sys.exit(f"camera_variants: error: --hand-placed {args.hand_placed!r}: expected offsets, exact or draw:SEED[:NAME]")
    camera = dataset_camera(data)
    reproject(args.dataset, args.out, camera, args.hand_placed, args.scene or read_json(args.dataset / "manifest.json")["scene"])
    print(f"{args.out}: {args.dataset} seen by {camera} (hand-placed trapezoid: {args.hand_placed})")


if __name__ == "__main__":
    main()
