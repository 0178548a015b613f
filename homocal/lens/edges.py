"""Straight-in-the-world edges found in one frame, with no click (``homocal lens --frame``).

OpenCV's line segment detector (LSD, von Gioi et al. 2012) cuts a curved image of a straight edge into short
straight segments; segments that continue one another (an end near the next one's start, the direction turning
by little) are chained into polylines, and the long chains are fitted as clicked lines (``homocal.lens.lines``).
Chains that are not straight in the world (a car's outline, a person) fit worse than the rest: they are dropped
and the fit repeated once.
"""
from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial import cKDTree

from homocal.lens.checkerboard import read_gray
from homocal.lens.lines import LensFit, fit_lines, intrinsics, line_residuals

MIN_SEGMENT_PX = 12.0  # shorter LSD segments are texture
MAX_SEGMENTS = 5_000  # the longest segments chained (about 4 s at most; a 1280x720 street frame has about 250)
MAX_GAP_PX = 10.0  # an end this near the next segment's start continues it
MAX_TURN_DEG = 6.0  # and turns by at most this much
MAX_OFFSET_PX = 1.5  # and starts at most this far to the side of the end's line (not a parallel edge beside it)
SAMPLE_PX = 20.0  # a chain's points: one about every this many pixels along its segments
MIN_CHAIN = 0.15  # of the image width: shorter chains bend too little to say anything
OUTLIER_FACTOR = 3.0  # a chain whose RMS after the fit is above this many times the median is not straight in the world


def _samples(segment: np.ndarray) -> np.ndarray:
    """Points along a segment (x1, y1, x2, y2), (M, 2): about every SAMPLE_PX, none at its ends (LSD places a
    segment's middle better than its ends); at least its middle."""
    n = max(1, int(np.hypot(*(segment[2:] - segment[:2])) // SAMPLE_PX))
    return segment[:2] + ((np.arange(n) + 0.5) / n)[:, None] * (segment[2:] - segment[:2])


def chains(segments: np.ndarray) -> list[np.ndarray]:
    """Chain (N, 4) segments (x1, y1, x2, y2) into polylines [(M_i, 2)]: a segment continues a chain when one of
    its ends lies within MAX_GAP_PX of the chain's end, at most MAX_OFFSET_PX to the side of its line, and it turns
    by at most MAX_TURN_DEG (the nearest such);
    longest segments first, each used once. A polyline holds the ``_samples`` of its segments."""
    cos_turn = math.cos(math.radians(MAX_TURN_DEG))
    both = np.concatenate([segments, segments[:, [2, 3, 0, 1]]])  # each segment in both directions: (2N, 4)
    length = np.hypot(both[:, 2] - both[:, 0], both[:, 3] - both[:, 1])
    starts = cKDTree(both[:, :2])
    used = np.zeros(len(segments), bool)
    out = []
    for i in np.argsort(-length[:len(segments)]):
        if used[i]:
            continue
        used[i] = True
        chain = [both[i]]
        for forward in (True, False):
            while True:
                last = chain[-1] if forward else chain[0][[2, 3, 0, 1]]  # the chain's end segment, pointing outwards
                heading = (last[2:] - last[:2]) / np.hypot(*(last[2:] - last[:2]))
                near = np.array(starts.query_ball_point(last[2:], MAX_GAP_PX), dtype=int)
                step = both[near, :2] - last[2:]
                gap, offset = np.hypot(*step.T), np.abs(step @ [-heading[1], heading[0]])
                fits = ((offset <= MAX_OFFSET_PX) & ~used[near % len(segments)]
                        & ((both[near, 2:] - both[near, :2]) @ heading >= cos_turn * length[near]))
                if not fits.any():
                    break
                j = near[fits][np.argmin(gap[fits])]
                used[j % len(segments)] = True
                chain = chain + [both[j]] if forward else [both[j][[2, 3, 0, 1]]] + chain
        out.append(np.concatenate([_samples(seg) for seg in chain]))
    return out


def frame_lines(path: Path) -> tuple[tuple[int, int], list[np.ndarray]]:
    """((W, H), polylines) of the long chains of the MAX_SEGMENTS longest LSD segments of the image ``path``;
    ValueError if there are none."""
    gray = read_gray(path)
    found = cv2.createLineSegmentDetector().detect(gray)[0]
    segments = np.zeros((0, 4)) if found is None else found.reshape(-1, 4).astype(np.float64)
    length = np.hypot(segments[:, 2] - segments[:, 0], segments[:, 3] - segments[:, 1])
    segments = segments[np.argsort(-length)[:MAX_SEGMENTS]]
    segments = segments[np.hypot(segments[:, 2] - segments[:, 0], segments[:, 3] - segments[:, 1]) >= MIN_SEGMENT_PX]
    size = (gray.shape[1], gray.shape[0])
    lines = [c for c in chains(segments) if np.linalg.norm(c[-1] - c[0]) >= MIN_CHAIN * size[0]]
    if not lines:
        raise ValueError(f"{path}: no long straight edge found (chains of segments {MIN_CHAIN:.0%} of the width or "
                         "longer); click lines instead (--lines)")
    return size, [np.clip(c, -0.5, np.array(size) - 0.5) for c in lines]


def fit_frame(path: Path, terms: str, hfov_deg: float | None = None, focal_px: float | None = None) -> LensFit:
    """The plumb-line fit (K: ``intrinsics``) of ``frame_lines(path)``, refitted once without the chains whose RMS
    distance from their straight line is above OUTLIER_FACTOR times the median chain's."""
    size, lines = frame_lines(path)
    K = intrinsics(size, hfov_deg, focal_px)
    fit = fit_lines(size, lines, K, terms)
    rms = [np.sqrt(np.mean(line_residuals(fit.lens.undistort_points(line), np.array([0, len(line)]))[0] ** 2))
           for line in lines]
    keep = [line for line, r in zip(lines, rms) if r <= OUTLIER_FACTOR * np.median(rms)]
    return fit_lines(size, keep, K, terms) if len(keep) < len(lines) else fit

