"""People's boxes from files, in homocal's pixels: MOTChallenge text files, a simgen dataset's
detections.parquet, and a CSV (``read_boxes``).

MOTChallenge lines hold comma-separated values; the first seven are
``frame, id, bb_left, bb_top, bb_width, bb_height, conf``, followed by either ``x, y, z``
(10 values: MOT15 files and MOT17 det.txt, as detectors and ``simgen export-mot`` write them) or
``class, visibility`` (9 values: MOT16/17 gt.txt). frame is 1-based: MOT frame n is our frame n - 1.
MOT pixel coordinates are 1-based: the top-left pixel is (1, 1) and a box covers pixels
bb_left .. bb_left + bb_width - 1. Ours put that pixel's centre at (0, 0) and a box's edges half a
pixel outside its outermost pixel centres, so
    x1 = bb_left - 1.5, y1 = bb_top - 1.5, x2 = x1 + bb_width, y2 = y1 + bb_height,
and back: bb_left = x1 + 1.5, bb_top = y1 + 1.5, bb_width = x2 - x1, bb_height = y2 - y1.
(A detector whose boxes have pixel edges at integers, the image's top-left corner at (0, 0), and
which adds 1 when writing MOT, as MOTChallenge exporters do, lands exactly on our convention.)
"""
from __future__ import annotations

import configparser
import dataclasses
import itertools
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from homocal.files import check_input_file, read_json, read_points_csv
from homocal.geometry.boxes import MAX_BOXES_PER_FRAME, box_edges, undistort_boxes
from homocal.geometry.camera_file import read_camera
from homocal.geometry.lens import Lens

if TYPE_CHECKING:
    import pyarrow as pa  # pyarrow loads where a Parquet file is read (a cheap ``import homocal``)

MOT_COLUMNS = (9, 10)
MAX_FPS = 1000.0  # the highest frame rate of a boxes file's video (--fps of measure, watch and the page)
MAX_BOXES_BYTES = 2**28
"""The largest boxes file read, of any kind (256 MiB, some 4 million MOT lines): read_boxes refuses a larger
file before reading it, read_mot a larger file or stream."""
MAX_BOXES = 2**21
"""The most boxes a file gives (2,097,152: a MOT, CSV or Parquet file with more rows is refused, as read so
far, or from the Parquet metadata); with MAX_BOXES_PER_FRAME in a frame (homocal.geometry.boxes)."""
MAX_LINE_CHARS = 1024
"""The longest line read_mot reads (a MOT line has ten numbers): it reads lines in pieces of this bound."""
MOT_OFFSET = 1.5
"""bb_left = x1 + MOT_OFFSET, bb_top = y1 + MOT_OFFSET (module docstring)."""
DEFAULT_DETECTOR = "segmentation"
CSV_COLUMNS = ("frame", "x1", "y1", "x2", "y2")
CSV_CONVENTION = "corners"  # a CSV's boxes are as supervision's Detections.xyxy of YOLO-like models give them


def read_mot(path: str | os.PathLike, frames_total: int | None = None, size: tuple[int, int] | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Parse a MOTChallenge text file -> frame (N,) int64 1-based, xyxy (N, 4) our pixels, conf (N,) float64,
    id (N,) float64 (the second column as given: -1 in a det file).

    What a file must satisfy (each violation is a ValueError naming the file and 1-based line number; the file
    alone when it is not UTF-8 text or holds no detection): 9 or 10 numbers a line, finite; frame n an integer,
    1 <= n <= frames_total (when given); a box with width, height > 0 that overlaps the image
    and whose edges lie within one image width / height of it (when size (width, height) is given); conf in
    [0, 1] (MOTChallenge itself does not bound conf, "the detection confidence"; MOT17's DPM files hold raw SVM
    scores such as -0.3 or 2.3, but detections.parquet's score is in [0, 1]: map raw scores into it first).
    Blank lines are skipped. The file is read in lines of at most MAX_LINE_CHARS, MAX_BOXES_BYTES and MAX_BOXES lines in all (a
    stream such as /dev/zero too).
    """
    if os.path.isfile(path) and os.path.getsize(path) > MAX_BOXES_BYTES:
        raise _too_large(path)
    try:
        with open(path, encoding="utf-8-sig") as f:  # tolerates a byte-order mark
            frames, boxes, confs, ids = _parse_mot(path, _bounded_lines(path, f), frames_total, size)
    except UnicodeDecodeError as e:
        raise ValueError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start})") from None
    if not frames:
        raise ValueError(f"{path}: no detections in the file")
    return (np.array(frames, dtype=np.int64), np.array(boxes, dtype=np.float64).reshape(-1, 4), np.array(confs),
            np.array(ids))


def _bounded_lines(path, f):
    """The lines of the open text file ``f``, read in pieces: ValueError at a line longer than MAX_LINE_CHARS or
    past MAX_BOXES_BYTES characters in all."""
    total = 0
    for number in itertools.count(1):
        line = f.readline(MAX_LINE_CHARS + 1)
        if not line:
            return
        total += len(line)
        if len(line) > MAX_LINE_CHARS:
            raise ValueError(f"{path}: line {number}: longer than {MAX_LINE_CHARS} characters; not a MOTChallenge file")
        if total > MAX_BOXES_BYTES:
            raise _too_large(path)
        yield line


def _too_large(path) -> ValueError:
    return ValueError(f"{path}: larger than {MAX_BOXES_BYTES >> 20} MiB (the most a boxes file holds); split it by frame")


def _parse_mot(path, f, frames_total: int | None, size: tuple[int, int] | None) -> tuple[list, list, list, list]:
    """The lines of the open file ``f`` (read_mot) -> lists of frames, boxes (our pixels), confs and ids."""
    frames, boxes, confs, ids = [], [], [], []
    for number, line in enumerate(f, start=1):
        if not line.strip():
            continue
        if len(frames) == MAX_BOXES:
            raise ValueError(f"{path}: line {number}: more than {MAX_BOXES:,} boxes (the most a boxes file holds); "
                             "split it by frame")
        fields = line.split(",")
        if len(fields) not in MOT_COLUMNS:
            raise ValueError(f"{path}: line {number}: expected 9 or 10 comma-separated values, got {len(fields)}")
        try:
            values = [float(v) for v in fields]
        except ValueError:
            raise ValueError(f"{path}: line {number}: not a number in {line.strip()!r}") from None
        frame, track, left, top, width, height, conf = values[:7]
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
        ids.append(track)
    return frames, boxes, confs, ids


def _near_image(box: tuple[float, float, float, float], width: int, height: int) -> bool:
    """The box (x1, y1, x2, y2, our pixels) overlaps the image and its edges lie within one image size of it."""
    x1, y1, x2, y2 = box
    lo_x, hi_x, lo_y, hi_y = -0.5, width - 0.5, -0.5, height - 0.5
    overlaps = x1 < hi_x and x2 > lo_x and y1 < hi_y and y2 > lo_y
    return overlaps and lo_x - width <= x1 and x2 <= hi_x + width and lo_y - height <= y1 and y2 <= hi_y + height


@dataclass(frozen=True)
class PersonBoxes:
    """People's boxes read from a file (read_boxes).

    Attributes:
        frames: (N,) int64 video frame of each box, 0-based.
        xyxy: (N, 4) float64 box edges (x1, y1, x2, y2) in homocal's pixels (convention "homocal"): y1 the
            head row, y2 the foot row.
        track_ids: (N,) int64 person of each box, or None when the file has none.
        image_size: (width, height) px when the file's folder says it (seqinfo.ini, camera.json), else None.
        K: (3, 3) intrinsics when the file's folder has them (a dataset's camera.json), else None.
        lens: the Lens the boxes were undistorted with (read_boxes' lens, undistort=True), else None: xyxy are the
            file's pixels.
    """

    frames: np.ndarray
    xyxy: np.ndarray
    track_ids: np.ndarray | None = None
    image_size: tuple[int, int] | None = None
    K: np.ndarray | None = None
    lens: Lens | None = None


def read_boxes(path: str | os.PathLike, detector: str | None = None, lens: Lens | None = None, *,
               undistort: bool = True) -> PersonBoxes:
    """People's boxes from a file, by its extension, in the undistorted image of ``lens`` when given
    (geometry.boxes.undistort_boxes; its image size must be the file's when the file says one); with
    undistort=False checked against the lens as the same but left in the camera's pixels, image_size and K the
    lens's (for PedestrianCorrector.fit(lens=) and OnlineCalibrator(lens=), which test a box for the image border
    there, where the frame cuts it, and then undistort it):

    - ``.txt``: a MOTChallenge file (read_mot), such as ``simgen export-mot``'s ``SEQ/det/<detector>.txt``
      (ids -1: no tracks) or a gt.txt (its ids are the tracks). When the file sits in ``SEQ/det/`` or
      ``SEQ/gt/`` beside ``SEQ/seqinfo.ini``, that file's imWidth, imHeight and seqLength bound the boxes and
      frames and give image_size.
    - ``.parquet``: a simgen dataset's detections.parquet, the rows of ``detector`` (default segmentation);
      image_size and K from the camera.json beside it, when there is one. (Its agent_id column is the
      association with the ground truth, not a tracker's output: it is not used.)
    - ``.csv``: a header line with columns frame, x1, y1, x2, y2 (others ignored; track_id, when present, gives
      the tracks), boxes as supervision's Detections.xyxy of YOLO-like models give them (convention
      "corners": pixel corners at integers), frames 0-based.

    ValueError naming the file (and line or row) for anything else: a missing file, a folder or a device
    (check_input_file), a file larger than MAX_BOXES_BYTES or with more than MAX_BOXES boxes, another
    extension, a detector for a file that is not Parquet, a detector with no rows, no boxes, a value that is not
    a finite number, a frame or track id that is not an integer >= 0, a box upside down or empty (read_mot
    refuses a width or height <= 0; PedestrianCorrector.fit checks every box again), more than
    MAX_BOXES_PER_FRAME boxes in a frame, a lens whose image size is not the file's, a box beyond the lens's
    fold, no lens for a detections.parquet whose camera.json has a distortion.
    """
    path = check_input_file(path, MAX_BOXES_BYTES)
    kind = path.suffix.lower()
    if detector is not None and kind != ".parquet":
        raise ValueError(f"{path}: a detector name is for a dataset's detections.parquet, not a {kind or 'bare'} file")
    if kind == ".txt":
        boxes = _read_mot_boxes(path)
    elif kind == ".parquet":
        boxes = _read_detections(path, DEFAULT_DETECTOR if detector is None else detector)
    elif kind == ".csv":
        boxes = _read_csv_boxes(path)
    else:
        raise ValueError(f"{path}: expected a MOTChallenge .txt, a detections .parquet or a .csv of frame,x1,y1,x2,y2")
    numbers, counts = np.unique(boxes.frames, return_counts=True)
    crowded = np.flatnonzero(counts > MAX_BOXES_PER_FRAME)
    if crowded.size:
        raise ValueError(f"{path}: frame {numbers[crowded[0]]} has {counts[crowded[0]]:,} boxes, more than "
                         f"{MAX_BOXES_PER_FRAME:,} (the most per frame homocal reads)")
    if lens is None:  # boxes.lens here: the lens of the camera.json beside a detections.parquet (_read_detections)
        if boxes.lens is not None and not boxes.lens.is_identity:
            raise ValueError(f"{path}: the camera.json beside it has a lens distortion: give that lens (homocal fit "
                             "--camera-json) so that the boxes are undistorted as the trapezoid is")
        return dataclasses.replace(boxes, lens=None)
    if boxes.image_size is not None and boxes.image_size != lens.image_size:
        raise ValueError(f"{path}: its image size {list(boxes.image_size)} differs from the lens's {list(lens.image_size)}")
    try:
        xyxy = undistort_boxes(boxes.xyxy, lens)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    if not undistort:
        return dataclasses.replace(boxes, image_size=lens.image_size, K=lens.K, lens=None)
    return dataclasses.replace(boxes, xyxy=xyxy, image_size=lens.image_size, K=lens.K, lens=lens)


def _read_mot_boxes(path: Path) -> PersonBoxes:
    seqinfo = path.parent.parent / "seqinfo.ini"
    size = frames_total = None
    if path.parent.name in ("det", "gt") and seqinfo.is_file():
        parser = configparser.ConfigParser()
        try:
            parser.read(seqinfo, encoding="utf-8")
            section = parser["Sequence"]
            size = (int(section["imWidth"]), int(section["imHeight"]))
            frames_total = int(section["seqLength"])
        except (configparser.Error, KeyError, ValueError, UnicodeDecodeError) as e:
            raise ValueError(f"{seqinfo}: not a MOTChallenge seqinfo.ini with imWidth, imHeight and seqLength ({e})") from None
    frames, xyxy, _, ids = read_mot(path, frames_total, size)
    tracks = ids.astype(np.int64) if ((ids >= 0) & (ids == np.round(ids)) & (ids <= 2**53)).all() else None
    return PersonBoxes(frames - 1, xyxy, tracks, size)


def read_detections_table(path: str | os.PathLike, columns: list[str]) -> pa.Table:
    """The ``columns`` of a detections.parquet; ValueError naming the file when it is not one or has more than
    MAX_BOXES rows (its metadata says, before any is read)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        rows = pq.read_metadata(path).num_rows
        if rows > MAX_BOXES:
            raise ValueError(f"{path}: {rows:,} rows, more than {MAX_BOXES:,} (the most a boxes file holds)")
        return pq.read_table(path, columns=columns)
    except (pa.ArrowException, OSError) as e:
        raise ValueError(f"{path}: not a detections.parquet ({(str(e).splitlines() or [type(e).__name__])[0]})") from None


def _read_detections(path: Path, detector: str) -> PersonBoxes:
    import pyarrow.compute as pc

    table = read_detections_table(path, ["detector", "frame", "x1", "y1", "x2", "y2"])
    names = sorted(set(table.column("detector").to_pylist()))
    table = table.filter(pc.equal(table.column("detector"), detector))
    if table.num_rows == 0:
        raise ValueError(f"{path}: no boxes of detector {detector!r} (has: {', '.join(names) or 'none'})")
    xyxy = np.column_stack([table.column(c).to_numpy(zero_copy_only=False).astype(np.float64) for c in ("x1", "y1", "x2", "y2")])
    bad = np.flatnonzero(~np.isfinite(xyxy).all(axis=1))
    if bad.size:
        raise ValueError(f"{path}: row {bad[0]} of detector {detector!r} has no finite box")
    size = K = lens = None
    camera_path = path.parent / "camera.json"
    if camera_path.is_file():
        camera = read_camera(camera_path)
        size, K = camera.image_size, camera.K
        lens = camera.lens
    return PersonBoxes(table.column("frame").to_numpy().astype(np.int64), xyxy, None, size, K, lens)


def _read_csv_boxes(path: Path) -> PersonBoxes:
    _, _, cols, lines = read_points_csv(path, CSV_COLUMNS, finite=True, most=MAX_BOXES, optional=("track_id",),
                                        keep_rows=False)
    if not lines:
        raise ValueError(f"{path}: no boxes (a header line, then one row per box: {','.join(CSV_COLUMNS)})")
    for name in ("frame", "track_id"):
        if name in cols:
            bad = np.flatnonzero((cols[name] != np.round(cols[name])) | (cols[name] < 0) | (cols[name] > 2**53))
            if bad.size:
                raise ValueError(f"{path}, line {lines[bad[0]]}: column {name}: {cols[name][bad[0]]:g} is not an integer >= 0")
    xyxy = box_edges(np.column_stack([cols[c] for c in ("x1", "y1", "x2", "y2")]), convention=CSV_CONVENTION)
    bad = np.flatnonzero(~((xyxy[:, 3] > xyxy[:, 1]) & (xyxy[:, 2] > xyxy[:, 0])))
    if bad.size:
        raise ValueError(f"{path}, line {lines[bad[0]]}: the box is upside down or empty (needs x1 < x2 and y1 < y2: "
                         "y1 the top edge, y2 the bottom edge, image rows counted down)")
    tracks = cols["track_id"].astype(np.int64) if "track_id" in cols else None
    return PersonBoxes(cols["frame"].astype(np.int64), xyxy, tracks)


def file_fps(path: Path) -> float | None:
    """The frame rate the boxes' file's folder says: a dataset's manifest.json "fps", a MOT sequence's
    seqinfo.ini frameRate; None when neither is there; ValueError when it says a rate outside (0, MAX_FPS]."""
    said = None
    if path.suffix.lower() == ".parquet" and (path.parent / "manifest.json").is_file():
        said = read_json(path.parent / "manifest.json").get("fps")
    seqinfo = path.parent.parent / "seqinfo.ini"
    if path.suffix.lower() == ".txt" and seqinfo.is_file():
        parser = configparser.ConfigParser()
        try:
            parser.read(seqinfo, encoding="utf-8")
        except (configparser.Error, UnicodeDecodeError) as e:
            raise ValueError(f"{seqinfo}: not a MOTChallenge seqinfo.ini ({e})") from None
        said = parser.get("Sequence", "frameRate", fallback=None)
    if said is None:
        return None
    try:
        fps = float(said)
    except (TypeError, ValueError):
        fps = math.nan
    if not 0 < fps <= MAX_FPS:
        raise ValueError(f"{path}: its folder's frame rate {said!r} is not in (0, {MAX_FPS:g}]: give --fps")
    return fps


def boxes_fps(path: Path, fps: float | None) -> float:
    """Frames per second of the boxes' video: fps (--fps) when given, else ``file_fps``'s; ValueError naming
    --fps when the file's folder does not say it (or says a rate outside (0, MAX_FPS])."""
    said = fps if fps is not None else file_fps(path)
    if said is None:
        raise ValueError(f"--fps: required ({path} does not say its frame rate)")
    return said
