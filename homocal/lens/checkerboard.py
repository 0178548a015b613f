"""The lens from photographs of a checkerboard: OpenCV's way (``cv2.findChessboardCorners``, ``cornerSubPix``,
``cv2.calibrateCamera``: Zhang 2000), for ``homocal lens --checkerboard``."""
from __future__ import annotations

import os
import threading
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from homocal.geometry.lens import MAX_IMAGE_SIDE, Lens
from homocal.lens.lines import DEFAULT_TERMS, TERMS

MAX_FRAMES = 200  # checkerboard photographs in one calibration
MAX_FRAME_BYTES = 64 * 2**20  # one image file
MAX_FRAME_PIXELS = 50_000_000  # one decoded frame (8K is 33 million)
MAX_SEARCH_PIXELS = 500_000_000  # frames x pixels one calibration searches for the board (40 photographs of 12 MP):
# findChessboardCorners takes ~2.2 us a pixel on a photograph without a board (26.8 s on 12 MP of noise, one core
# of the 2-core reference machine), so a calibration searches for at most ~18 min
MIN_FRAMES = 3  # views of the board calibrateCamera needs for K and five coefficients
MIN_CORNERS, MAX_CORNERS = 2, 100  # inner corners along each side of the board
MAX_SQUARE_M = 100.0  # the side of one square, metres (more than 0)
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-3)  # cornerSubPix: 0.001 px or 100 steps
_ONE_THREAD = threading.Lock()  # one calibration at a time sets OpenCV's (process-wide) thread count to 1


@dataclass(frozen=True)
class BoardFit:
    """lens: the calibrated Lens. terms: the fitted distortion coefficients. rms_px: calibrateCamera's RMS reprojection error, pixels. frames: the files
    where the board was found; missing: those where it was not."""

    lens: Lens
    terms: str
    rms_px: float
    frames: list[str]
    missing: list[str]

    def to_json(self) -> dict:
        """lens.json: K, distortion, image_size and the calibration's diagnostics."""
        return {**self.lens.to_dict(),
                "fit": {"method": "checkerboard", "terms": self.terms, "rms_px": self.rms_px, "frames": self.frames, "missing": self.missing}}


def parse_pattern(text: str) -> tuple[int, int]:
    """COLSxROWS inner corners ("9x6") -> (columns, rows), each in [MIN_CORNERS, MAX_CORNERS]; ValueError otherwise."""
    try:
        cols, rows = (int(part) for part in text.lower().split("x"))
    except (ValueError, AttributeError):
        raise ValueError(f"expected COLSxROWS inner corners such as 9x6, got {text!r}") from None
    if not (MIN_CORNERS <= cols <= MAX_CORNERS and MIN_CORNERS <= rows <= MAX_CORNERS):
        raise ValueError(f"each count must be in [{MIN_CORNERS}, {MAX_CORNERS}], got {text!r}")
    return cols, rows


def read_gray(path: Path) -> np.ndarray:
    """A frame as (H, W) uint8 grey; ValueError naming the file if it is missing, too large (its file, or its size
    read from its header before decoding) or not an image."""
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    if os.path.getsize(path) > MAX_FRAME_BYTES:
        raise ValueError(f"{path}: larger than {MAX_FRAME_BYTES // 2**20} MiB (the most an image file may be)")
    try:
        with Image.open(path) as header:  # the size, before any pixel is decoded
            width, height = header.size
    except (OSError, Image.DecompressionBombError):
        raise ValueError(f"{path}: not a readable image") from None
    if max(width, height) > MAX_IMAGE_SIDE or width * height > MAX_FRAME_PIXELS:
        raise ValueError(f"{path}: {width}x{height} px, larger than {MAX_FRAME_PIXELS:,} pixels or {MAX_IMAGE_SIDE} px "
                         "a side (the most a frame may be)")
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise ValueError(f"{path}: not a readable image")
    return image


def calibrate_board(paths: list[Path], pattern: tuple[int, int], square_m: float, terms: str = DEFAULT_TERMS,
                    image_size: tuple[int, int] | None = None) -> BoardFit:
    """Calibrate from photographs of a board of ``pattern`` = (columns, rows) inner corners, ``square_m`` apart.

    The focal lengths, the principal point and the distortion ``terms`` (a key of TERMS; the others fixed at 0:
    calibrateCamera's FIX_K2, FIX_K3, ZERO_TANGENT_DIST) are fitted. ValueError: no file, more than MAX_FRAMES or
    MAX_SEARCH_PIXELS (frames x the first frame's pixels: the search's time), frames of different sizes
    (or not ``image_size`` (W, H), when given: a camera's frame), the board found in fewer than MIN_FRAMES of them,
    a calibrated distortion that folds the frame (Lens.check_folds).
    """
    if not paths:
        raise ValueError("no frame to read")
    if len(paths) > MAX_FRAMES:
        raise ValueError(f"{len(paths)} frames, more than {MAX_FRAMES} (the most one calibration takes)")
    cols, rows = pattern
    board = np.zeros((rows * cols, 3), np.float32)
    board[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_m
    size, found, missing, corners = image_size, [], [], []
    for path in paths:
        gray = read_gray(path)
        if size is not None and gray.shape[::-1] != tuple(size):
            which = "the first frame" if image_size is None else "the camera's frame"
            raise ValueError(f"{path}: {gray.shape[1]}x{gray.shape[0]}, {which} is {size[0]}x{size[1]} (one camera, one "
                             "image size)")
        size = gray.shape[::-1]
        if len(paths) * gray.size > MAX_SEARCH_PIXELS:
            raise ValueError(f"{len(paths)} frames of {size[0]}x{size[1]} px, {len(paths) * gray.size:,} pixels to search "
                             f"for the board, more than {MAX_SEARCH_PIXELS:,} (fewer or smaller photographs)")
        ok, c = cv2.findChessboardCorners(gray, pattern)
        if not ok:
            missing.append(str(path))
            continue
        corners.append(cv2.cornerSubPix(gray, c, (5, 5), (-1, -1), SUBPIX_CRITERIA))
        found.append(str(path))
    if len(found) < MIN_FRAMES:
        raise ValueError(f"the {cols}x{rows} board was found in {len(found)} of {len(paths)} frames; calibration needs "
                         f"it in at least {MIN_FRAMES} (is --pattern the count of inner corners, columns x rows?)")
    index = TERMS[terms]
    flags = ((cv2.CALIB_FIX_K2 if 1 not in index else 0) | (cv2.CALIB_FIX_K3 if 4 not in index else 0)
             | (cv2.CALIB_ZERO_TANGENT_DIST if 2 not in index else 0))
    with _ONE_THREAD:  # OpenCV's threads sum calibrateCamera's normal equations in any order: the last digits vary
        threads = cv2.getNumThreads()
        cv2.setNumThreads(1)
        try:
            rms, K, dist, _, _ = cv2.calibrateCamera([board] * len(corners), corners, size, None, None, flags=flags)
        finally:
            cv2.setNumThreads(threads)
    lens = Lens(K, dist.ravel()[:5], size)
    try:
        lens.check_folds()
    except ValueError as e:
        raise ValueError(f"the calibrated {e} (photograph the board out to the frame's corners, or fit fewer terms)") from None
    return BoardFit(lens, terms, float(rms), found, missing)
