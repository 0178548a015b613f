"""Writing a dataset folder (data_schema.md): static files, calibration, chunks of frames, final files.

Work is done in chunks of ``chunk_seconds``; each chunk's video segment and tables go to ``_parts/``
under temporary names and are renamed, then ``manifest.json`` records ``frames_done``. A killed run
resumed with ``resume=True`` redoes the unfinished chunk and ends with the same bytes as an
uninterrupted run: every draw is keyed by (seed, scene, slot), renders are deterministic, the rgb
detector restarts at every chunk from the ``rgb_warmup_frames`` frames before it (re-rendered on
resume), and the final files are written once from the parts.
"""
from __future__ import annotations

import json
import os
import platform
import shutil
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from tqdm import tqdm

import simgen
from homocal.files import write_atomic, write_json_atomic
from simgen.detection import (
    BackgroundSubtractionDetector,
    HogDetector,
    SegmentationDetector,
    detections_table,
    match_to_gt,
    write_mot_gt,
)
from simgen.render import backend, mujoco
from simgen.scene import GT_DT, GT_RATE, Scene
from simgen.stage import Stage
from simgen.truth import GT_SCHEMA, gt_columns
from simgen.video import SegmentWriter, concat

PARTS = "_parts"

CALIBRATION_SCHEMA = pa.schema([
    ("index", pa.int32()), ("distance_m", pa.float64()), ("x", pa.float64()), ("y", pa.float64()),
    ("u", pa.float64()), ("v", pa.float64()), ("u_exact", pa.float64()), ("v_exact", pa.float64()),
    ("x1", pa.float64()), ("y1", pa.float64()), ("x2", pa.float64()), ("y2", pa.float64()),
])  # fmt: skip


class DatasetError(RuntimeError):
    """The output folder cannot be (re)used; one-line message."""


# ---- atomic writes -----------------------------------------------------------------------
def _tmp(path: Path) -> Path:
    """Temporary name beside ``path`` keeping its extension, for files streamed in place (the video segments)."""
    return path.with_name(f"{path.stem}.tmp{path.suffix}")


def write_parquet(path: Path, table: pa.Table) -> None:
    write_atomic(path, lambda p: pq.write_table(table, p, compression="zstd"))


# ---- the static files ----------------------------------------------------------------------
def camera_json(scene: Scene) -> dict:
    cam = scene.camera
    lists = lambda a: np.asarray(a, dtype=float).tolist()  # noqa: E731
    return {
        "K": lists(cam.K), "R": lists(cam.R), "t": lists(cam.t), "width": cam.width, "height": cam.height,
        "hfov_deg": cam.hfov_deg, "vfov_deg": cam.vfov_deg, "mount_height_m": cam.mount_height_m,
        "tilt_deg": cam.tilt_deg, "image_to_ground": lists(cam.image_to_ground),
        "ground_to_image": lists(cam.ground_to_image), "horizon": lists(cam.horizon),
        "horizon_row": cam.horizon_row, "camera_origin": [0.0, 0.0],
    }  # fmt: skip


def trapezoids_json(scene: Scene) -> dict:
    return {
        "order": "TL,TR,BR,BL",
        "hand_placed": {"image": scene.hand_placed_image.tolist(), "map": scene.hand_placed_map.tolist()},
        "exact": {"image": scene.trapezoid_exact_image.tolist(), "map": scene.trapezoid_exact_map.tolist()},
        "ground_m": scene.trapezoid_ground.tolist(),
    }


def site_map(scene: Scene) -> np.ndarray:
    """(H, W, 3) uint8 BGR top-down map at ``scene.map_scale`` px per metre: the ground texture, with the
    footprints of the scene's static boxes (buildings) in grey."""
    x0, x1, y0, y1 = scene.ground.extent
    size = (round((x1 - x0) * scene.map_scale), round((y1 - y0) * scene.map_scale))
    image = cv2.resize(cv2.imread(str(scene.ground.texture), cv2.IMREAD_COLOR), size, interpolation=cv2.INTER_AREA)
    model = mujoco.MjModel.from_xml_path(str(scene.model_path))
    for g in np.flatnonzero((model.geom_type == mujoco.mjtGeom.mjGEOM_BOX) & (model.geom_bodyid == 0)):
        corners = np.array([[sx, sy, 0.0] for sx, sy in ((1, 1), (1, -1), (-1, -1), (-1, 1))]) * model.geom_size[g]
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, model.geom_quat[g])
        xy = (corners @ rot.reshape(3, 3).T + model.geom_pos[g])[:, :2]
        cv2.fillPoly(image, [np.round(scene.to_map(xy) * 16).astype(np.int32)], (150, 150, 150), cv2.LINE_AA, 4)
    return image


def manifest(scene: Scene, seed: int, frames_done: int, complete: bool) -> dict:
    return {
        "scene": scene.name, "seed": seed, "config_hash": scene.config_hash(),
        "versions": {"python": platform.python_version(), "numpy": np.__version__, "mujoco": mujoco.__version__,
                     "opencv": cv2.__version__, "simgen": simgen.__version__},
        "frames_total": scene.frames_total, "frames_done": frames_done, "complete": complete,
        "fps": scene.fps, "gt_dt": GT_DT, "seconds": scene.seconds, "detectors": list(scene.detectors),
        "steps_total": scene.steps_total, "chunk_seconds": scene.chunk_seconds,
        "rgb_reset_every_frames": _chunk_frames(scene), "rgb_warmup_frames": scene.rgb_warmup_frames,
        "backend": backend(),
    }  # fmt: skip


def _write_static(scene: Scene, out: Path) -> None:
    write_json_atomic(out / "camera.json", camera_json(scene))
    write_json_atomic(out / "trapezoids.json", trapezoids_json(scene))
    image = site_map(scene)
    write_atomic(out / "site_map.png", lambda p: p.write_bytes(cv2.imencode(".png", image)[1].tobytes()))
    write_json_atomic(out / "site_map.json", {"file": "site_map.png", "scale_px_per_m": scene.map_scale,
                                       "origin_px": list(scene.map_origin), "width": image.shape[1], "height": image.shape[0]})


# ---- calibration ---------------------------------------------------------------------------
def calibration_table(stage: Stage) -> pa.Table:
    """One row per calibration distance: the object alone at its point (scene.calibration_xy), detected by the segmentation detector."""
    scene, detector = stage.scene, SegmentationDetector()
    xy = scene.calibration_xy
    d = np.hypot(xy[:, 0], xy[:, 1])  # the distances themselves with layout "line"
    box = np.full((len(d), 4), np.nan)
    for i, point in enumerate(xy):
        stage.set_calibration(point)
        batch = detector.detect(-1, 0.0, None, stage.agent_ids())
        if len(batch):
            box[i] = batch.xyxy[np.flatnonzero(batch.agent_id == 0)[0]]
    exact = scene.camera.project_ground(xy)
    cols = [np.arange(len(d), dtype=np.int32), d, xy[:, 0], xy[:, 1], (box[:, 0] + box[:, 2]) / 2, box[:, 3],
            exact[:, 0], exact[:, 1], box[:, 0], box[:, 1], box[:, 2], box[:, 3]]
    return pa.Table.from_arrays([pa.array(c) for c in cols], schema=CALIBRATION_SCHEMA)


# ---- chunks --------------------------------------------------------------------------------
def _chunk_frames(scene: Scene) -> int:
    return round(scene.chunk_seconds * scene.fps)


def _chunk_count(scene: Scene) -> int:
    return -(-scene.frames_total // _chunk_frames(scene))


def _timeline(scene: Scene, c: int) -> list[tuple[float, int | None, int | None]]:
    """Chunk c's instants in time order: (pose time s, frame or None, gt step or None); exact merge."""
    per_f, per_s = _chunk_frames(scene), round(scene.chunk_seconds * GT_RATE)
    events: dict[Fraction, list] = {}
    for k in range(c * per_f, min((c + 1) * per_f, scene.frames_total)):
        events.setdefault(Fraction(k, scene.fps), [None, None])[0] = k
    for j in range(c * per_s, min((c + 1) * per_s, scene.steps_total)):
        events.setdefault(Fraction(j, GT_RATE), [None, None])[1] = j
    return [(float(t), *events[t]) for t in sorted(events)]


def make_detectors(scene: Scene) -> list:
    """The scene's detectors, in order; the rgb one restarts at every chunk."""
    make = {
        "segmentation": SegmentationDetector,
        "rgb": lambda: BackgroundSubtractionDetector(reset_every=_chunk_frames(scene), warmup=scene.rgb_warmup_frames),
        "hog": HogDetector,
    }
    return [make[name]() for name in scene.detectors]


def _warm_up(stage: Stage, detectors: list, frame: int) -> None:
    """Before resuming at ``frame``: feed the rgb detector the frames its state depends on."""
    for det in detectors:
        if isinstance(det, BackgroundSubtractionDetector):
            for k in range(det.resume_start(frame), frame):
                stage.set_time(k / stage.scene.fps)
                det.feed(k, stage.rgb())


def _run_chunk(stage: Stage, detectors: list, c: int, parts: Path, bar: tqdm) -> None:
    scene = stage.scene
    gt, batches = [], []
    video, cam = parts / f"{c:05d}.mp4", scene.camera
    with SegmentWriter(_tmp(video), cam.width, cam.height, scene.fps) as writer:
        for t, frame, step in _timeline(scene, c):
            state = stage.set_time(t)
            ids = stage.agent_ids()
            if step is not None:
                gt.append(gt_columns(step, cam, state, ids))
            if frame is not None:
                rgb = stage.rgb()
                writer.append(rgb)
                batches += [d.detect(frame, frame / scene.fps, rgb, ids) for d in detectors]
                bar.update(1)
    os.replace(_tmp(video), video)
    columns = {name: np.concatenate([g[name] for g in gt]) for name in GT_SCHEMA.names}
    write_parquet(parts / f"{c:05d}.gt.parquet", pa.Table.from_pydict(columns, schema=GT_SCHEMA))
    write_parquet(parts / f"{c:05d}.det.parquet", detections_table(batches))


# ---- the final files -------------------------------------------------------------------------
def _finalize(scene: Scene, out: Path) -> None:
    parts, n = out / PARTS, _chunk_count(scene)
    gt = pa.concat_tables([pq.read_table(parts / f"{c:05d}.gt.parquet") for c in range(n)])
    det = pa.concat_tables([pq.read_table(parts / f"{c:05d}.det.parquet") for c in range(n)])
    rank = {name: i for i, name in enumerate(scene.detectors)}
    det_rank = np.array([rank[x] for x in det.column("detector").to_pylist()], dtype=np.int64)
    det = det.take(np.lexsort((det.column("frame").to_numpy(), det_rank)))
    write_parquet(out / "gt.parquet", gt)
    write_parquet(out / "detections.parquet", match_to_gt(det, gt))
    write_mot_gt(gt, scene.fps, out / "mot" / "gt.txt")
    write_atomic(out / "video.mp4", lambda p: concat([parts / f"{c:05d}.mp4" for c in range(n)], p))


# ---- the run -------------------------------------------------------------------------------
def generate(scene: Scene, seed: int, out: str | Path, resume: bool = False, progress: bool = True) -> Path:
    """Write (or with ``resume`` continue) the dataset of ``scene`` with ``seed`` into ``out``."""
    out = Path(out)
    frames_done = 0
    if (out / "manifest.json").is_file() and resume:
        m = json.loads((out / "manifest.json").read_text())
        if m.get("config_hash") != scene.config_hash() or m.get("seed") != seed:
            raise DatasetError(f"{out}: --resume: it was made with another scene config, run options or seed")
        if m.get("backend") != backend():
            raise DatasetError(f"{out}: --resume: it was rendered with MUJOCO_GL={m.get('backend')}; resume with the same backend")
        if m.get("complete"):
            shutil.rmtree(out / PARTS, ignore_errors=True)
            return out
        frames_done = int(m["frames_done"])
    elif out.exists() and any(out.iterdir()) and not resume:
        raise DatasetError(f"{out}: exists and is not empty (use --resume to continue it, or another --out)")

    with Stage(scene, seed) as stage:  # fails (backend) before anything is written
        out.mkdir(parents=True, exist_ok=True)
        for stale in out.rglob("*.tmp*"):
            stale.unlink()
        _write_static(scene, out)
        write_json_atomic(out / "manifest.json", manifest(scene, seed, frames_done, False))
        if not (out / "calibration.parquet").is_file():
            write_parquet(out / "calibration.parquet", calibration_table(stage))
        parts = out / PARTS
        parts.mkdir(exist_ok=True)
        detectors = make_detectors(scene)
        first = frames_done // _chunk_frames(scene)
        _warm_up(stage, detectors, first * _chunk_frames(scene))
        with tqdm(total=scene.frames_total, initial=first * _chunk_frames(scene), unit="frame",
                  desc=scene.name, disable=not progress, smoothing=0.05) as bar:
            for c in range(first, _chunk_count(scene)):
                _run_chunk(stage, detectors, c, parts, bar)
                done = min((c + 1) * _chunk_frames(scene), scene.frames_total)
                write_json_atomic(out / "manifest.json", manifest(scene, seed, done, False))
    _finalize(scene, out)
    write_json_atomic(out / "manifest.json", manifest(scene, seed, scene.frames_total, True))
    shutil.rmtree(out / PARTS)
    return out
