"""MOTChallenge text files: import an external detector's output, export the ground truth and detections.

Lines hold comma-separated values; the first seven are
``frame, id, bb_left, bb_top, bb_width, bb_height, conf``, followed by either ``x, y, z``
(10 values: MOT15 files and MOT17 det.txt, as detectors write them) or ``class, visibility``
(9 values: MOT16/17 gt.txt, as `write_mot_gt` writes them). Reading uses the first seven only.
frame is 1-based: MOT frame n is our frame n - 1, at time t = (n - 1) / fps.
MOT pixel coordinates are 1-based: the top-left pixel is (1, 1) and a box covers pixels
bb_left .. bb_left + bb_width - 1. Ours put that pixel's centre at (0, 0) and a box's edges half a
pixel outside its outermost pixel centres, so
    x1 = bb_left - 1.5, y1 = bb_top - 1.5, x2 = x1 + bb_width, y2 = y1 + bb_height,
and back: bb_left = x1 + 1.5, bb_top = y1 + 1.5, bb_width = x2 - x1, bb_height = y2 - y1.
(A detector whose boxes have pixel edges at integers, the image's top-left corner at (0, 0), and
which adds 1 when writing MOT, as MOTChallenge exporters do, lands exactly on our convention.)

What an imported file must satisfy (each violation names the file and line): at least one detection;
frame n within the video (1 <= n <= frames_total); a finite box with width, height > 0 that overlaps the
image and whose edges lie within one image width / height of it (no huge boxes); conf in [0, 1].
MOTChallenge itself does not bound conf ("the detection confidence"; MOT17's DPM files hold raw SVM
scores such as -0.3 or 2.3), but detections.parquet's score is in [0, 1]: map raw scores into it first.
"""
from __future__ import annotations

import itertools
import math
import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from homocal.files import read_json, write_json_atomic, write_text_atomic
from homocal.names import check_name
from simgen.detection.association import TIE_TOLERANCE_S, associate, match_to_gt, nearest_sample
from simgen.detection.batch import DetectionBatch, detections_table
from simgen.parquet import write_parquet

BUILTIN_DETECTORS = ("segmentation", "rgb", "hog")

MOT_COLUMNS = (9, 10)
MAX_MOT_BYTES = 2**28
"""The largest MOT file read (256 MiB, some 4 million lines): read_mot refuses more, and streams beyond it."""
MAX_LINE_CHARS = 1024
"""The longest line read_mot reads (a MOT line has ten numbers): it reads lines in pieces of this bound."""
MOT_OFFSET = 1.5
"""bb_left = x1 + MOT_OFFSET, bb_top = y1 + MOT_OFFSET (module docstring)."""


def read_mot(path: str | os.PathLike, frames_total: int | None = None, size: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Parse a MOTChallenge text file -> frame (N,) int64 1-based, xyxy (N, 4) our pixels, conf (N,) float64.

    Blank lines are skipped. ``frames_total`` and ``size`` (width, height), when given, bound the frames
    and boxes (module docstring). The file is read in lines of at most MAX_LINE_CHARS and MAX_MOT_BYTES in
    all (a stream such as /dev/zero too). Raises ValueError naming the file and 1-based line number of the
    first bad line (or the file, when it is not UTF-8 text, holds no detection or is beyond a bound).
    """
    if os.path.isfile(path) and os.path.getsize(path) > MAX_MOT_BYTES:
        raise _too_large(path)
    try:
        with open(path, encoding="utf-8-sig") as f:  # tolerates a byte-order mark
            frames, boxes, confs = _parse_mot(path, _bounded_lines(path, f), frames_total, size)
    except UnicodeDecodeError as e:
        raise ValueError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start})") from None
    if not frames:
        raise ValueError(f"{path}: no detections in the file")
    return np.array(frames, dtype=np.int64), np.array(boxes, dtype=np.float64).reshape(-1, 4), np.array(confs)


def _bounded_lines(path, f):
    """The lines of the open text file ``f``, read in pieces: ValueError at a line longer than MAX_LINE_CHARS or
    past MAX_MOT_BYTES characters in all."""
    total = 0
    for number in itertools.count(1):
        line = f.readline(MAX_LINE_CHARS + 1)
        if not line:
            return
        total += len(line)
        if len(line) > MAX_LINE_CHARS:
            raise ValueError(f"{path}: line {number}: longer than {MAX_LINE_CHARS} characters; not a MOTChallenge file")
        if total > MAX_MOT_BYTES:
            raise _too_large(path)
        yield line


def _too_large(path) -> ValueError:
    return ValueError(f"{path}: larger than {MAX_MOT_BYTES >> 20} MiB (import-mot's bound); split it by frame")


def _parse_mot(path, f, frames_total: int | None, size: tuple[int, int] | None) -> tuple[list, list, list]:
    """The lines ``f`` of a MOT file (read_mot) -> lists of frames, boxes (our pixels) and confs."""
    frames, boxes, confs = [], [], []
    for number, line in enumerate(f, start=1):
        if not line.strip():
            continue
        fields = line.split(",")
        if len(fields) not in MOT_COLUMNS:
            raise ValueError(f"{path}: line {number}: expected 9 or 10 comma-separated values, got {len(fields)}")
        try:
            values = [float(v) for v in fields]
        except ValueError:
            raise ValueError(f"{path}: line {number}: not a number in {line.strip()!r}") from None
        frame, _, left, top, width, height, conf = values[:7]
        if not all(math.isfinite(v) for v in values[:7]):
            raise ValueError(f"{path}: line {number}: non-finite value in {line.strip()!r}")
        if frame != int(frame) or frame < 1:
            raise ValueError(f"{path}: line {number}: frame must be an integer >= 1, got {fields[0].strip()}")
        if width <= 0 or height <= 0:
            raise ValueError(f"{path}: line {number}: box width and height must be > 0, got {width}, {height}")
        if frames_total is not None and frame > frames_total:
            raise ValueError(f"{path}: line {number}: frame {int(frame)} is beyond the video ({frames_total} frames)")
        if not 0.0 <= conf <= 1.0:
            raise ValueError(f"{path}: line {number}: conf must be in [0, 1] (detections.parquet's score), got {fields[6].strip()}")
        box = (left - MOT_OFFSET, top - MOT_OFFSET, left - MOT_OFFSET + width, top - MOT_OFFSET + height)
        if size is not None and not _near_image(box, *size):
            raise ValueError(f"{path}: line {number}: box {','.join(v.strip() for v in fields[2:6])} "
                             f"does not overlap the {size[0]}x{size[1]} image or reaches more than one image size beyond it")
        frames.append(int(frame))
        boxes.append(box)
        confs.append(conf)
    return frames, boxes, confs


def _near_image(box: tuple[float, float, float, float], width: int, height: int) -> bool:
    """The box (x1, y1, x2, y2, our pixels) overlaps the image and its edges lie within one image size of it."""
    x1, y1, x2, y2 = box
    lo_x, hi_x, lo_y, hi_y = -0.5, width - 0.5, -0.5, height - 0.5
    overlaps = x1 < hi_x and x2 > lo_x and y1 < hi_y and y2 > lo_y
    return overlaps and lo_x - width <= x1 and x2 <= hi_x + width and lo_y - height <= y1 and y2 <= hi_y + height


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
    frames, xyxy, conf = read_mot(mot_txt_path, manifest.get("frames_total"), size)

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
