"""MOTChallenge text files: import an external detector's output, export the ground truth and detections.

The layouts and pixel conventions, and the reader, are homocal's (``homocal.boxes``: read_mot, MOT_OFFSET):
frame n is our frame n - 1, at time t = (n - 1) / fps; x1 = bb_left - 1.5, y1 = bb_top - 1.5,
x2 = x1 + bb_width, y2 = y1 + bb_height.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from homocal.boxes import MOT_OFFSET, read_mot
from homocal.files import read_json, write_json_atomic, write_text_atomic
from homocal.names import check_name
from simgen.detection.association import TIE_TOLERANCE_S, associate, match_to_gt, nearest_sample
from simgen.detection.batch import DetectionBatch, detections_table
from simgen.parquet import write_parquet
from simgen.scene import DETECTORS as BUILTIN_DETECTORS  # their rows a run writes: no import may replace them


def import_mot(dataset_dir: str | os.PathLike, mot_txt_path: str | os.PathLike, name: str, min_iou: float = 0.5) -> pa.Table:
    """An external detector's MOTChallenge output as a matched detections table (detector = name).

    Each MOT frame n is taken at t = (n - 1) / fps (fps from manifest.json) and compared with the
    ground-truth boxes (gt.parquet x1, y1, x2, y2; rows with a NaN box are skipped) of the nearest
    ground-truth time: boxes are associated with agents by IoU, greedy one-to-one, IoU >= min_iou,
    else agent_id -1; then matched to ground truth as by match_to_gt. The MOT id column is ignored.
    Frames and boxes are bounded by manifest.json's frames_total and camera.json's width and height
    (read_mot; a folder without them, like a hand-made test dataset, is not bounded).
    """
    if not 0.0 < min_iou <= 1.0:  # NaN too
        raise ValueError(f"--min-iou must be in (0, 1], got {min_iou}")
    dataset_dir = Path(dataset_dir)
    manifest = read_json(dataset_dir / "manifest.json")
    fps = float(manifest["fps"])
    camera_path = dataset_dir / "camera.json"
    camera = read_json(camera_path) if camera_path.is_file() else None
    gt = pq.read_table(dataset_dir / "gt.parquet")
    size = (int(camera["width"]), int(camera["height"])) if camera else None
    frames, xyxy, conf, _ = read_mot(mot_txt_path, manifest.get("frames_total"), size)

    gt_box, gt_agent = _boxes(gt), gt.column("agent_id").to_numpy()
    rows, times, starts, counts = _visible_by_time(gt)

    order = np.argsort(frames, kind="stable")
    numbers, first, count = np.unique(frames[order], return_index=True, return_counts=True)
    t = (numbers - 1) / fps
    samples = nearest_sample(times, t) if times.size else np.zeros(len(numbers), dtype=np.intp)
    batches = []
    for n, t_n, s, i, c in zip(numbers, t, samples, first, count):
        ref = rows[starts[s] : starts[s] + counts[s]] if times.size else rows
        det = order[i : i + c]
        agent_id = associate(xyxy[det], gt_agent[ref], gt_box[ref], min_iou)
        batches.append(DetectionBatch(name, int(n - 1), float(t_n), xyxy[det], conf[det], agent_id))
    return match_to_gt(detections_table(batches), gt)


def append_detections(dataset_dir: str | os.PathLike, table: pa.Table) -> None:
    """Add `table` to the dataset's detections.parquet atomically (temporary file, then rename), NaN as null.

    Rows of the existing file whose detector name occurs in `table` are replaced, so importing
    the same detector twice does not duplicate it. Columns must match the existing file's.
    """
    path = Path(dataset_dir) / "detections.parquet"
    if path.exists():
        existing = pq.read_table(path)
        keep = pc.invert(pc.is_in(existing.column("detector"), value_set=pc.unique(table.column("detector"))))
        table = pa.concat_tables([existing.filter(keep), table.select(existing.column_names).cast(existing.schema)])
    write_parquet(path, table)


def import_into_dataset(dataset_dir: str | os.PathLike, mot_txt_path: str | os.PathLike, name: str, min_iou: float = 0.5) -> int:
    """`simgen import-mot`: import_mot, append_detections, then list `name` last in manifest.json's detectors.

    Refuses an incomplete dataset, a name that fails ``homocal.names.check_name`` (export-mot makes it a file
    name) and the built-in detector names (importing under them would replace the run's own rows). Returns
    the number of detections imported. ValueError names the problem.
    """
    dataset_dir = Path(dataset_dir)
    manifest_path = dataset_dir / "manifest.json"
    if not manifest_path.is_file():
        raise ValueError(f"{dataset_dir}: not a dataset (no manifest.json)")
    manifest = read_json(manifest_path)
    if not manifest.get("complete"):
        raise ValueError(f"{dataset_dir}: the run is not complete; finish it with simgen generate --resume first")
    check_name(name, "detector name")
    if name in BUILTIN_DETECTORS:
        raise ValueError(f"--name {name!r} is reserved; choose another (built-in: {', '.join(BUILTIN_DETECTORS)})")
    table = import_mot(dataset_dir, mot_txt_path, name, min_iou)
    append_detections(dataset_dir, table)
    manifest["detectors"] = [d for d in manifest["detectors"] if d != name] + [name]
    write_json_atomic(manifest_path, manifest)
    return table.num_rows


def write_mot_gt(gt: pa.Table, fps: float, path: str | os.PathLike) -> int:
    """Write the ground truth as a MOT16/17 gt.txt (mot/gt.txt), atomically; returns the line count.

    gt: columns t (s), agent_id, x1, y1, x2, y2 (px, null or NaN when not visible), visible_fraction.
    One line per video frame n = 1 .. floor(t_max * fps) + 1 and agent visible (finite box) in the
    ground-truth sample nearest to t = (n - 1) / fps, ordered by frame, then agent_id:
    ``n, agent_id, bb_left, bb_top, bb_width, bb_height, 1, 1, visible_fraction``
    (conf 1: evaluate this box; class 1: pedestrian).
    """
    box, agent, visibility = _boxes(gt), gt.column("agent_id").to_numpy(), gt.column("visible_fraction").to_numpy()
    rows, times, starts, counts = _visible_by_time(gt)
    lines = []
    if times.size:
        n_frames = int(math.floor((times[-1] + TIE_TOLERANCE_S) * fps)) + 1
        for n, s in enumerate(nearest_sample(times, np.arange(n_frames) / fps), start=1):
            lines.extend(f"{n},{agent[i]},{_mot_box(box[i])},1,1,{visibility[i]:.6g}\n" for i in rows[starts[s] : starts[s] + counts[s]])
    write_text_atomic(path, "".join(lines))
    return len(lines)


def write_mot_det(detections: pa.Table, path: str | os.PathLike) -> int:
    """Write one detector's rows of a detections table as a MOT17 det.txt, atomically; returns the line count.

    detections: columns frame (0-based), x1, y1, x2, y2 (px), score; one line per row, ordered by frame
    (stable): ``frame + 1, -1, bb_left, bb_top, bb_width, bb_height, score, -1, -1, -1`` (id -1: a detection,
    not a track; x, y, z unused). ``read_mot`` reads it back.
    """
    frame, box, score = detections.column("frame").to_numpy(), _boxes(detections), detections.column("score").to_numpy()
    lines = [f"{frame[i] + 1},-1,{_mot_box(box[i])},{score[i]:.10g},-1,-1,-1\n" for i in np.argsort(frame, kind="stable")]
    write_text_atomic(path, "".join(lines))
    return len(lines)


def _mot_box(xyxy: np.ndarray) -> str:
    """``bb_left,bb_top,bb_width,bb_height`` of a box (x1, y1, x2, y2) in our pixels (module docstring), %.10g."""
    x1, y1, x2, y2 = xyxy
    return f"{x1 + MOT_OFFSET:.10g},{y1 + MOT_OFFSET:.10g},{x2 - x1:.10g},{y2 - y1:.10g}"


def _boxes(table: pa.Table) -> np.ndarray:
    """(N, 4) float64 columns x1, y1, x2, y2 of a table."""
    return np.column_stack([table.column(c).to_numpy() for c in ("x1", "y1", "x2", "y2")]).astype(np.float64)


def _visible_by_time(gt: pa.Table) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ground-truth rows with a finite box, grouped by time.

    Returns rows (V,) sorted by (t, agent_id), times (T,) ascending, and starts, counts (T,):
    the rows at times[j] are rows[starts[j] : starts[j] + counts[j]].
    """
    t, agent = gt.column("t").to_numpy(), gt.column("agent_id").to_numpy()
    rows = np.flatnonzero(np.isfinite(_boxes(gt)).all(axis=1))
    rows = rows[np.lexsort((agent[rows], t[rows]))]
    times, starts, counts = np.unique(t[rows], return_index=True, return_counts=True)
    return rows, times, starts, counts
