"""HOG people boxes from a finished dataset's video, every Nth frame, as a boxes CSV for homocal.

    python research/hog_boxes.py DATASET --every 10 [--seconds S] -o hog.csv

simgen's HogDetector (simgen.detection.hog: OpenCV's HOG people detector, the hog extra) on the dataset's
decoded H.264 video (video.mp4), on frames 0, N, 2N, ... of the first --seconds (default: all). A dataset
generated with `--detectors ...,hog` holds HOG rows for every rendered frame already; this reads the video of
one generated without (HOG costs seconds a frame). The CSV (homocal.boxes.read_boxes: frame,x1,y1,x2,y2 in the
corners convention; each sample's boxes in simgen's canonical order, so the same video gives the same bytes)
numbers the samples, frame // N, so that one person's boxes in consecutive samples link
into a track (homocal.geometry.boxes.link_tracks); boxes N frames apart overlap less than a frame apart, so
fewer link. The output file must not exist: the command writes a new file, never over one.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from homocal.arguments import number  # noqa: E402
from homocal.boxes import CSV_COLUMNS, CSV_CONVENTION  # noqa: E402
from homocal.dataset import load_dataset  # noqa: E402
from homocal.files import OutputFolderError, check_output_file, write_text_atomic  # noqa: E402
from homocal.geometry.boxes import BOX_CONVENTIONS  # noqa: E402


def hog_rows(video: Path, every: int, frames: int) -> list[tuple]:
    """(sample, x1, y1, x2, y2) corners-convention rows of HOG's boxes on frames 0, every, ... < frames."""
    from simgen.detection.batch import canonical_order  # noqa: PLC0415
    from simgen.detection.hog import HogDetector, hog_missing  # noqa: PLC0415  (cv2's HOG only when run)

    if problem := hog_missing():
        raise SystemExit(f"hog_boxes: {problem}")
    detector, rows = HogDetector(), []
    to_corners = -np.asarray(BOX_CONVENTIONS[CSV_CONVENTION])  # HogDetector's boxes are in homocal's pixels
    for i, rgb in enumerate(iio.imiter(video, plugin="FFMPEG")):
        if i >= frames:
            break
        if i % every == 0:
            xyxy, _ = canonical_order(*detector.people(rgb))  # HOG's order varies with its threads
            rows += [(i // every, *box) for box in (xyxy + to_corners).tolist()]
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("dataset", type=Path)
    p.add_argument("--every", type=number(int, 1, 10_000), default=10, help="every Nth frame (default 10)")
    p.add_argument("--seconds", type=number(float, 0, low_open=True), default=math.inf,
                   help="the first seconds of the video (default: all)")
    p.add_argument("-o", "--out", type=Path, required=True, help="the CSV to write (must not exist)")
    args = p.parse_args()
    try:
        ds = load_dataset(args.dataset)
        if args.out.exists() or args.out.is_symlink():
            raise OutputFolderError(f"{args.out}: exists; this command writes a new file, never over one")
        check_output_file(args.out, lambda _: False, "file")
    except (ValueError, OSError, OutputFolderError) as e:
        p.exit(2, f"hog_boxes: {e}\n")
    frames = int(ds.manifest["frames_total"])
    if math.isfinite(args.seconds):
        frames = min(frames, math.floor(args.seconds * float(ds.manifest["fps"])))
    rows = hog_rows(args.dataset / "video.mp4", args.every, frames)
    write_text_atomic(args.out, "\n".join([",".join(CSV_COLUMNS)] + [",".join(map(repr, r)) for r in rows]) + "\n")
    print(f"{len(rows)} boxes on {math.ceil(frames / args.every)} of {frames} frames -> {args.out}")


if __name__ == "__main__":
    main()
