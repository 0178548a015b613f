"""``homocal watch``: watch a camera from a stream of people's boxes (homocal.watch.OnlineCalibrator).

DIR gets watch.json (the marker: the settings, and whether the stream ended), moves.json (every detected move),
horizon.parquet (one row per person observed: HORIZON_COLUMNS) and corrections/<start_s>.json (one correction
per stretch between moves, as ``homocal fit --method pedestrians`` writes them; ``homocal apply DIR --at S``
picks the stretch). Each file is written whole (a temporary, then a rename): moves.json at each move, a
stretch's correction every MIN_PEOPLE people and when it ends, horizon.parquet in row groups of ROW_GROUP rows
to a temporary renamed when the stream ends (end of file, Ctrl-C or SIGTERM: an endless stream is stopped so)
or stops at bad input or past MAX_MOVES moves (one line naming it, exit 2, every file written so far whole).
"""
from __future__ import annotations

import argparse
import csv
import math
import signal
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from homocal.arguments import camera_json, number, xy_pair
from homocal.boxes import CSV_COLUMNS, CSV_CONVENTION, MAX_FPS, MAX_LINE_CHARS, boxes_fps, read_boxes
from homocal.correctors.cli import add_pedestrian_flags, pedestrian_flag_error
from homocal.files import create_temporary, output_folder, write_json_atomic
from homocal.geometry import ViewTransformer, read_trapezoid_file
from homocal.geometry.boxes import MAX_BOXES_PER_FRAME, box_edges
from homocal.study.options import Option, OptionError, YesNo, flag_type
from homocal.watch.calibrator import (
    DEFAULT_ARL0_PEOPLE,
    MIN_PEOPLE,
    OnlineCalibrator,
    by_frame,
    camera_of,
    stretch_correction,
)
from homocal.watch.folder import MARKER, REFUSED, TOOL

CALIBRATOR_SETTINGS = ("height_mean_m", "height_sd_m", "estimate_roll", "box_margin_px")  # OnlineCalibrator's pedestrian settings
WATCH_SETTINGS = ("camera_height_m", *CALIBRATOR_SETTINGS)  # the pedestrian settings (PEDESTRIAN_SETTINGS) homocal watch takes
DRIFT_TEST = Option("--drift-test", YesNo(), "also test for a move from the people already in view, each one's "
                    "implied horizon along their walk (homocal.watch.drift), sharing --arl0-people with the row test",
                    metavar="{yes,no}")  # OnlineCalibrator's drift_test
ROW_GROUP = 4096  # horizon.parquet rows held before they are written
MAX_MOVES = 10_000  # moves (and stretches) one run records at most: past it the run stops
HORIZON_COLUMNS = ("t_s", "person_row_px", "person_sigma_px", "horizon_row_px", "horizon_sigma_px", "n_people",
                   "stretch_start_s", "cusum_up", "cusum_down", "threshold", "person_column_px", "roll_deg",
                   "roll_sigma_deg", "cusum_roll_up", "cusum_roll_down", "cusum_drift_up", "cusum_drift_down", "n_outliers")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``watch``."""
    p = subparsers.add_parser(
        "watch", help="watch a camera for moves from people's boxes, with a correction per stretch",
        description="Read people's boxes in time order, keep the camera's horizon estimated from them, detect "
                    "moves (two-sided CUSUMs: one on the row, with --estimate-roll yes one on the roll, with --drift-test "
                    "yes one on the people in view, whose false-alarm rate together is --arl0-people) and write a correction per stretch between moves "
                    "(docs/moving-camera.md).")
    p.add_argument("--trapezoid", required=True, type=Path, metavar="TRAP.json", help="the clicked trapezoid (as homocal fit's)")
    p.add_argument("--boxes", required=True, metavar="BOXES", help="a MOT .txt, a detections.parquet (--detector), a "
                   f".csv of {','.join(CSV_COLUMNS)}[,track_id] (corner pixels), or - for such CSV lines on standard "
                   "input, as a running detector writes them; frames in time order")
    p.add_argument("--detector", metavar="NAME", help="a detections.parquet's detector (default segmentation)")
    p.add_argument("--fps", type=number(float, 0, MAX_FPS, low_open=True), metavar="F",
                   help="frames per second of the boxes' video (default: the boxes' file's, when it says it; "
                        "needed for standard input)")
    p.add_argument("--camera-json", type=Path, metavar="CAMERA.json", help="the image size and intrinsics K (default: "
                   "those beside the boxes file); needed for a CSV or standard input")
    add_pedestrian_flags(p, WATCH_SETTINGS)
    p.add_argument("--arl0-people", type=number(float, 10, 1e9), default=DEFAULT_ARL0_PEOPLE, metavar="N",
                   help="mean number of people between false alarms on a steady camera (default %(default)g; "
                        "the CUSUM thresholds follow)")
    p.add_argument(DRIFT_TEST.flag, type=flag_type(DRIFT_TEST), default=True, metavar=DRIFT_TEST.metavar,
                   help=f"{DRIFT_TEST.help}: {DRIFT_TEST.expected()} (default: yes)")
    p.add_argument("--camera-origin", type=xy_pair, default=(0.0, 0.0), metavar="X,Y",
                   help="ground point under the camera, metres (default 0,0)")
    p.add_argument("-o", "--out", required=True, type=Path, metavar="DIR", help="a new output folder")
    p.set_defaults(handler=handle_watch)


def handle_watch(args: argparse.Namespace) -> int:
    camera = camera_json(args.camera_json)
    lens = None if camera is None else camera.lens
    transformer = read_trapezoid_file(args.trapezoid, lens)[0]
    if args.detector is not None and not str(args.boxes).endswith(".parquet"):
        raise ValueError("--detector: for a detections.parquet")
    if args.boxes == "-" and args.fps is None:
        raise ValueError("--fps: required with --boxes - (standard input does not say its frame rate)")
    fps = boxes_fps(Path(args.boxes), args.fps)
    stream, size, K = _open_boxes(args, lens)
    if camera is not None:
        size, K = camera.image_size, camera.K
    if K is None and size is None:
        raise ValueError(f"--camera-json: needed ({args.boxes} gives neither the image size nor K)")
    K, height = camera_of(transformer, size, K, args.camera_height_m)
    prior = {name: getattr(args, name) for name in CALIBRATOR_SETTINGS if getattr(args, name) is not None}
    try:
        calibrator = OnlineCalibrator(K, height, fps, size, **prior, arl0_people=args.arl0_people, lens=lens,
                                      drift_test=args.drift_test)
    except OptionError as e:
        raise pedestrian_flag_error(e) from None
    settings = {"format": TOOL, "boxes": str(args.boxes), "detector": args.detector, "fps": fps,
                "camera_height_m": height, "K": K.tolist(), "image_size": None if size is None else list(size),
                **{name: getattr(calibrator, name) for name in CALIBRATOR_SETTINGS}, "drift_test": args.drift_test,
                "arl0_people": args.arl0_people, "threshold": calibrator.threshold}
    with output_folder(args.out, TOOL, resume=False, marker=MARKER, resumable=False) as folder:
        write_json_atomic(folder.marker, {**settings, "ended": None})
        (folder.path / "corrections").mkdir()
        run = _Run(folder.path, calibrator, transformer, args.camera_origin, lens)
        ended, error = "end of stream", None
        previous = signal.signal(signal.SIGTERM, _interrupt)
        try:
            for frame, xyxy, ids in stream:
                run.update(frame, xyxy, ids)
        except KeyboardInterrupt:
            ended = "interrupted"
        except UnicodeDecodeError as e:
            error = ValueError(f"{args.boxes}: not UTF-8 text ({e.reason} at byte {e.start} of a line)")
            ended = f"stopped: {error}"
        except ValueError as e:
            ended, error = f"stopped: {e}", e
        finally:
            signal.signal(signal.SIGTERM, previous)
            run.finish()
            write_json_atomic(folder.marker, {**settings, "ended": ended, "boxes_read": run.boxes,
                                              "boxes_hidden": run.hidden, "people": run.people,
                                              "moves": len(run.moves)})
    if error is not None:
        raise error
    refused = [why for why in run.stretches.values() if why]
    if refused:
        print(f"homocal watch: warning: {len(refused)} of the {len(run.stretches)} stretches' corrections refused "
              f"(homocal apply refuses their times): {refused[0]}", file=sys.stderr)
    print(f"homocal watch: {run.boxes} boxes, {run.people} people of {args.boxes} ({ended}): {len(run.moves)} "
          f"move{'s' if len(run.moves) != 1 else ''} detected; {len(run.stretches)} correction"
          f"{'s' if len(run.stretches) != 1 else ''} written to {args.out / 'corrections'}"
          f"{f' ({len(refused)} refused)' if refused else ''}.")
    return 0


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


class _Run:
    """The outputs of one watch (the module docstring's schedule)."""

    def __init__(self, path: Path, calibrator: OnlineCalibrator, transformer: ViewTransformer, origin, lens=None) -> None:
        self.path, self.calibrator, self.transformer, self.origin = path, calibrator, transformer, origin
        self.lens = None if lens is None or lens.is_identity else lens  # saved with each stretch's correction
        self.moves: list = []
        self.rows: list = []
        self.boxes = self.people = self.hidden = 0
        self.stretches: dict[Path, str | None] = {}  # each stretch's corrections/<start_s>.json: None, or why refused
        self.stretch_start = 0.0
        self.tmp = create_temporary(path / "horizon.parquet")
        schema = pa.schema([(c, pa.int64() if c in ("n_people", "n_outliers") else pa.float64()) for c in HORIZON_COLUMNS])
        self.writer = pq.ParquetWriter(self.tmp, schema)
        write_json_atomic(path / "moves.json", {"moves": []})

    def update(self, frame: int, xyxy: np.ndarray, ids) -> None:
        cal = self.calibrator
        state = cal.update(frame, xyxy, ids)
        self.boxes += len(xyxy)
        self.hidden += state.hidden_boxes
        if state.move is not None:
            if len(self.moves) == MAX_MOVES:
                raise ValueError(f"more than {MAX_MOVES:,} moves: the camera is not steady enough to watch")
            m = state.move
            if m.n_before >= 3:
                self._save(self.stretch_start, m.horizon_before, m.sigma_before, m.roll_before_deg,
                           m.roll_sigma_before_deg, m.n_before, m.n_outliers_before)
            self.moves.append(m.to_dict())
            write_json_atomic(self.path / "moves.json", {"moves": self.moves})
        self.stretch_start = state.stretch_start_s
        for row, sigma, column in zip(state.person_rows, state.person_sigmas, state.person_columns):
            self.people += 1
            self.rows.append((state.t_s, row, sigma, state.horizon_row, state.horizon_sigma_px, state.n_people,
                              state.stretch_start_s, state.cusum_up, state.cusum_down, state.threshold, column,
                              state.roll_deg, state.roll_sigma_deg, state.cusum_roll_up, state.cusum_roll_down,
                              state.cusum_drift_up, state.cusum_drift_down, state.n_outliers))
        if state.person_rows and state.n_people % MIN_PEOPLE == 0:
            self._save(state.stretch_start_s, state.horizon_row, state.horizon_sigma_px, state.roll_deg,
                       state.roll_sigma_deg, state.n_people, state.n_outliers)
        if len(self.rows) >= ROW_GROUP:
            self._flush()

    def _save(self, start: float, row: float, sigma: float, roll_deg: float, roll_sigma_deg: float, n: int,
              n_outliers: int) -> None:
        """Write the stretch's correction, corrections/<start_s>.json (``stretch_correction``), or where it is refused
        (its people's outliers) the refusal there: {"format": REFUSED, "start_s", "refused": why}."""
        name = self.path / "corrections" / f"{start:.2f}.json"
        try:
            corrector = stretch_correction(self.transformer, self.calibrator, row, sigma, roll_deg, roll_sigma_deg, n,
                                           self.origin, n_outliers)
        except ValueError as e:
            self.stretches[name] = f"the stretch from {start:.2f} s: {e}"
            write_json_atomic(name, {"format": REFUSED, "start_s": round(start, 2), "refused": self.stretches[name]})
            return
        self.stretches[name] = None
        corrector.lens_ = self.lens  # apply undistorts the feet it is given
        corrector.save(name)

    def _flush(self) -> None:
        if self.rows:
            self.writer.write_table(pa.table(dict(zip(HORIZON_COLUMNS, map(list, zip(*self.rows))))), row_group_size=ROW_GROUP)
            self.rows = []

    def finish(self) -> None:
        """The current stretch's correction (3 people or more), horizon.parquet closed and put in place."""
        cal = self.calibrator
        n = cal.n_people
        if n >= 3:
            line = cal.estimate
            self._save(cal.stretch_start_s, line.row, line.sigma, line.roll_deg, line.roll_sigma_deg, n, line.n_outliers)
        self._flush()
        self.writer.close()
        self.tmp.replace(self.path / "horizon.parquet")


def _open_boxes(args, lens=None):
    """(iterator of (frame, xyxy (N, 4) homocal edges in the camera's pixels, track ids (N,) or None), image size,
    K) of --boxes (a file's checked against lens: OnlineCalibrator(lens=) undistorts them)."""
    if args.boxes == "-":
        return _stdin_boxes(sys.stdin), None, None
    boxes = read_boxes(Path(args.boxes), args.detector, lens, undistort=False)
    return by_frame(boxes.frames, boxes.xyxy, boxes.track_ids, args.boxes), boxes.image_size, boxes.K


def _stdin_boxes(f):
    """Frames of CSV lines from the text stream f (a header line, then frame,x1,y1,x2,y2[,track_id], corner
    pixels), each frame given when the next one starts. ValueError naming the line for a bad line, a frame
    going backwards or one of more than MAX_BOXES_PER_FRAME boxes; a last line cut short (no newline, not
    parseable) is dropped with a warning."""
    header = [h.strip() for h in f.readline(MAX_LINE_CHARS + 1).split(",")]
    missing = [c for c in CSV_COLUMNS if c not in header]
    if missing:
        raise ValueError(f"standard input: the header line lacks {', '.join(missing)} (expected "
                         f"{','.join(CSV_COLUMNS)}[,track_id])")
    cols = [header.index(c) for c in CSV_COLUMNS]
    track_col = header.index("track_id") if "track_id" in header else None
    frame, boxes, ids = None, [], []
    number_ = 1
    while True:
        line = f.readline(MAX_LINE_CHARS + 1)
        number_ += 1
        if not line:
            break
        if len(line) > MAX_LINE_CHARS:
            raise ValueError(f"standard input, line {number_}: longer than {MAX_LINE_CHARS} characters")
        if not line.strip():
            continue
        fields = next(csv.reader([line]))
        try:
            values = [float(fields[c]) for c in cols]
            track = None if track_col is None else float(fields[track_col])
        except (ValueError, IndexError):
            if not line.endswith("\n"):
                print(f"homocal: warning: standard input, line {number_}: cut short at the end of the stream; "
                      "dropped", file=sys.stderr)
                break
            raise ValueError(f"standard input, line {number_}: not {len(header)} numbers: {line.strip()!r}") from None
        if not all(math.isfinite(v) for v in values) or (track is not None and not math.isfinite(track)):
            raise ValueError(f"standard input, line {number_}: a value is not a finite number: {line.strip()!r}")
        if values[0] != int(values[0]) or values[0] < 0:
            raise ValueError(f"standard input, line {number_}: frame must be an integer >= 0, got {fields[cols[0]]}")
        n = int(values[0])
        if frame is not None and n < frame:
            raise ValueError(f"standard input, line {number_}: frame {n} after frame {frame}: boxes must come in "
                             "time order")
        if frame is not None and n != frame:
            yield frame, box_edges(np.array(boxes).reshape(-1, 4), convention=CSV_CONVENTION), \
                None if track_col is None else np.array(ids, np.int64)
            boxes, ids = [], []
        frame = n
        if len(boxes) == MAX_BOXES_PER_FRAME:
            raise ValueError(f"standard input, line {number_}: frame {n} has more than {MAX_BOXES_PER_FRAME:,} boxes "
                             "(the most per frame homocal reads)")
        boxes.append(values[1:])
        ids.append(0 if track is None else int(track))
    if frame is not None:
        yield frame, box_edges(np.array(boxes).reshape(-1, 4), convention=CSV_CONVENTION), \
            None if track_col is None else np.array(ids, np.int64)
