"""Detector boxes from other tools in homocal's pixels: their edges and foot points (data_schema.md, Image and
Boxes).

homocal's pixels are OpenCV's: the centre of the pixel in row r, column c is (c, r). A box over mask rows
r0..r1 and columns c0..c1 has its edges half a pixel outside those centres, x1 = c0 - 0.5, y1 = r0 - 0.5,
x2 = c1 + 0.5, y2 = r1 + 0.5; its foot point is its bottom edge's centre, its head row its top edge.
Other tools write the same box in one of three conventions (BOX_CONVENTIONS, the shifts (dx1, dy1, dx2, dy2)
that take a box to homocal's edges):

    "corners"  pixel corners at integers, the image spans [0, W] x [0, H] (YOLO/ultralytics, torchvision,
               COCO, cv2.boundingRect, and supervision's Detections of these models): x1 = c0, x2 = c1 + 1,
               y1 = r0, y2 = r1 + 1. Edges: every coordinate - 0.5.
    "indices"  inclusive pixel indices (supervision's mask_to_xyxy): x1 = c0, x2 = c1, y1 = r0, y2 = r1.
               Edges: (x1 - 0.5, y1 - 0.5, x2 + 0.5, y2 + 0.5).
    "homocal"  box edges in homocal's pixels (simgen's datasets). Edges: as they are.

Taking a "corners" y2 for a homocal row puts the foot point 0.5 px low, so nearer the camera: on the paper's
camera (PinholeCamera()), straight ahead, 0.02 m at 10 m, 0.09 m at 20 m, 0.33 m at 40 m, 0.51 m at 50 m.
"""
from __future__ import annotations

import heapq

import numpy as np

MAX_BOXES_PER_FRAME = 500
"""The most boxes of one video frame that homocal reads (homocal.boxes.read_boxes) and links into tracks
(link_tracks): a crowd at MOT20's densest holds a few hundred people per frame."""
BOX_CONVENTIONS = {"corners": (-0.5, -0.5, -0.5, -0.5), "indices": (-0.5, -0.5, 0.5, 0.5), "homocal": (0.0, 0.0, 0.0, 0.0)}


def box_edges(xyxy: np.ndarray, *, convention: str) -> np.ndarray:
    """Boxes xyxy (N, 4) = (x1, y1, x2, y2) in the given convention (a key of BOX_CONVENTIONS: "corners",
    "indices" or "homocal") as their edges (N, 4) float64 in homocal's pixels. NaN stays NaN. ValueError
    for another convention or another shape."""
    if convention not in BOX_CONVENTIONS:
        raise ValueError(f"convention {convention!r}: expected one of {', '.join(BOX_CONVENTIONS)}")
    boxes = np.asarray(xyxy)
    if boxes.dtype.kind not in "fiu" or boxes.ndim != 2 or boxes.shape[1] != 4:
        raise ValueError(f"xyxy: expected numbers of shape (N, 4), got {boxes.dtype} of shape {boxes.shape}")
    return boxes.astype(np.float64) + BOX_CONVENTIONS[convention]


def box_bottom_points(xyxy: np.ndarray, *, convention: str) -> np.ndarray:
    """Foot points (N, 2) float64, homocal pixels, of boxes xyxy (N, 4) = (x1, y1, x2, y2) in the given
    convention (see box_edges): the centre of the box's bottom edge. NaN boxes give NaN points. ValueError
    for another convention or another shape."""
    edges = box_edges(xyxy, convention=convention)
    return np.column_stack([(edges[:, 0] + edges[:, 2]) / 2.0, edges[:, 3]])


MAX_BOX_MARGIN_PX = 64.0
"""The largest box margin taken (trim_boxes; homocal fit --box-margin): a detector's boxes taller than their
people by more than this are not boxes of people."""


def trim_boxes(edges: np.ndarray, margin_px: float) -> np.ndarray:
    """Box edges (N, 4) homocal px (x1, y1, x2, y2) of a detector whose boxes are margin_px taller than their
    people (px, in the camera's frame, in [0, MAX_BOX_MARGIN_PX]) -> the people's edges (N, 4) float64: margin_px / 2
    off the top edge and off the bottom edge (the foot point margin_px / 2 up). A box no taller than margin_px
    keeps no height (both edges on its middle row: ``short_boxes``). margin_px 0: a copy as they are; below 0 the
    boxes grow (research/speeds_rgb.py's derivative)."""
    edges = np.array(edges, dtype=np.float64)
    middle, half = (edges[:, 1] + edges[:, 3]) / 2.0, margin_px / 2.0
    edges[:, 1], edges[:, 3] = np.minimum(edges[:, 1] + half, middle), np.maximum(edges[:, 3] - half, middle)
    return edges


def short_boxes(edges: np.ndarray, margin_px: float) -> np.ndarray:
    """(N,) bool: the boxes edges (N, 4) homocal px that a margin of margin_px > 0 px leaves with no height
    (trim_boxes); none for margin_px 0."""
    return (edges[:, 3] - edges[:, 1] <= margin_px) if margin_px > 0 else np.zeros(len(edges), bool)


def undistort_boxes(edges: np.ndarray, lens) -> np.ndarray:
    """Box edges (N, 4) homocal px in the camera's (distorted) pixels -> edges (N, 4) in the undistorted image of
    ``lens`` (homocal.geometry.Lens; None or an identity lens: a copy as they are). The foot point (the bottom
    edge's centre) and the head row (the top edge's centre) are undistorted exactly; the width is that of the
    undistorted bottom edge, centred on the foot. ValueError naming xyxy[i] for a box beyond the lens's fold."""
    edges = np.array(edges, dtype=np.float64)
    if lens is None or lens.is_identity:
        return edges
    x1, y1, x2, y2 = edges.T
    xc = (x1 + x2) / 2.0
    points = np.vstack([np.column_stack(p) for p in ((xc, y2), (xc, y1), (x1, y2), (x2, y2))])
    foot, head, left, right = np.split(lens.undistort_points(points), 4)  # one call: its cost is mostly per call
    lost = np.flatnonzero(np.isfinite(edges).all(axis=1) & ~np.isfinite(np.column_stack([foot, head, left, right])).all(axis=1))
    if lost.size:
        raise ValueError(f"xyxy[{lost[0]}] = {edges[lost[0]].tolist()} lies beyond the lens's fold: no ray of this "
                         "lens reaches it")
    half = np.hypot(*(right - left).T) / 2.0
    return np.column_stack([foot[:, 0] - half, head[:, 1], foot[:, 0] + half, foot[:, 1]])


BORDER_PX = 1.0
"""A box edge within this many px of the image's border is cut by it: the frame, not the person, ends the box there."""


def cut_edges(edges: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(N, 4) bool for box edges (N, 4) homocal px (x1, y1, x2, y2) in the camera's raw pixels of an image of size
    (width, height) px: each edge lies within BORDER_PX of the image's border (-0.5 .. size - 0.5)."""
    w, h = size
    x1, y1, x2, y2 = np.asarray(edges, dtype=np.float64).T
    return np.column_stack([x1 <= -0.5 + BORDER_PX, y1 <= -0.5 + BORDER_PX, x2 >= w - 0.5 - BORDER_PX,
                            y2 >= h - 0.5 - BORDER_PX])


def on_border(edges: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(N,) bool: any edge of the boxes edges (N, 4) is cut by the image's border (``cut_edges``)."""
    return cut_edges(edges, size).any(axis=1)


HIDDEN_FEET_PX = 1.0
"""A box whose bottom edge lies below a nearer box's top edge, or within this many px above it, may have its feet
hidden by the nearer person (hidden_feet)."""


def hidden_feet(edges: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """(N,) bool for boxes edges (N, 4) homocal px (x1, y1, x2, y2) of video frames (N,) int: the box's feet may be
    hidden by a nearer person, so that its bottom edge is that person's outline, not the sole. A nearer person is
    a box j of the same frame standing lower (y2_j > y2_i) whose columns overlap the box's and whose top edge
    reaches down to HIDDEN_FEET_PX above the box's bottom edge or lower (y1_j <= y2_i + HIDDEN_FEET_PX). From the
    boxes alone, as the image border's rule: a person hidden by a car or a pole is not found. Cost per frame
    O(n^2) in its n <= MAX_BOXES_PER_FRAME boxes."""
    edges, frames = np.asarray(edges, dtype=np.float64), np.asarray(frames)
    hidden = np.zeros(len(edges), bool)
    order = np.argsort(frames, kind="stable")
    _, first = np.unique(frames[order], return_index=True)
    for rows in np.split(order, first[1:]) if len(order) else ():
        x1, y1, x2, y2 = edges[rows].T[:, :, None]  # each (n, 1): rows i, columns (after .T) j
        nearer = (y2.T > y2) & (np.minimum(x2, x2.T) > np.maximum(x1, x1.T)) & (y1.T <= y2 + HIDDEN_FEET_PX)
        hidden[rows] = nearer.any(axis=1)
    return hidden


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection over union (N, M) of boxes a (N, 4) and b (M, 4) (any shape ending in 4 is read as rows of
    four), edges (x1, y1, x2, y2) in one convention. A box's width and height are max(0, x2 - x1) and
    max(0, y2 - y1): an empty (zero-area) or upside-down box has area 0, so its IoU with any box is 0 (0 also
    where both are empty: the union is 0). NaN coordinates give NaN."""
    return _iou(np.reshape(np.asarray(a, dtype=np.float64), (-1, 1, 4)),
                np.reshape(np.asarray(b, dtype=np.float64), (1, -1, 4)))


def _iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """box_iou of boxes a (..., 4) and b (..., 4), broadcast against each other."""
    w = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0.0, None)
    h = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0.0, None)
    inter = w * h
    area = lambda x: np.clip(x[..., 2] - x[..., 0], 0.0, None) * np.clip(x[..., 3] - x[..., 1], 0.0, None)  # noqa: E731
    union = area(a) + area(b) - inter
    return np.divide(inter, union, out=np.where(np.isnan(union), np.nan, 0.0), where=union > 0)


def link_tracks(frames: np.ndarray, xyxy: np.ndarray, min_iou: float = 0.3, max_gap: int = 5) -> np.ndarray:
    """Track ids (N,) int64, 0, 1, ... in order of first appearance, for boxes xyxy (N, 4) (finite) in video
    frames frames (N,) int: frame by frame in increasing order, ``TrackLinker.link`` (one box per track and frame,
    IoU >= min_iou > 0, boxes at most max_gap frames apart). A simple linker of detections (no motion model):
    enough to count people once rather than once per frame. Bounded by design: ValueError naming the first frame
    with more than MAX_BOXES_PER_FRAME boxes; see TrackLinker for the cost per frame."""
    if not min_iou > 0:
        raise ValueError(f"min_iou must be > 0 (boxes that do not overlap are never linked), got {min_iou!r}")
    frames = np.asarray(frames, dtype=np.int64)
    ids = np.full(len(frames), -1, dtype=np.int64)
    linker = TrackLinker(min_iou, max_gap)
    order = np.argsort(frames, kind="stable")
    numbers, first = np.unique(frames[order], return_index=True)
    for frame, rows in zip(numbers, np.split(order, first[1:])):
        ids[rows] = linker.link(int(frame), xyxy[rows])
    return ids


class TrackLinker:
    """Boxes linked into tracks frame by frame, as they come (link_tracks over a stream): each box continues the
    live track (last box at most max_gap frames earlier) whose last box overlaps it most, greedily (highest IoU
    first; ties: lower box index, then lower track id), one box per track and frame, IoU >= min_iou; any other
    box starts a track (ids 0, 1, ... in order of first appearance). Only live tracks are kept: memory is
    bounded by the boxes of the last max_gap frames."""

    def __init__(self, min_iou: float = 0.3, max_gap: int = 5) -> None:
        self.min_iou, self.max_gap = min_iou, max_gap
        self.tracks = 0  # track ids given so far
        self._ids, self._boxes, self._frames = np.zeros(0, np.int64), np.zeros((0, 4)), np.zeros(0, np.int64)

    def link(self, frame: int, xyxy: np.ndarray) -> np.ndarray:
        """Track ids (M,) int64 of the boxes xyxy (M, 4) of video frame ``frame`` (not before the last one), at most
        MAX_BOXES_PER_FRAME of them. Only the pairs whose columns overlap are compared (``_overlapping``): memory
        and time per frame are at most O(max_gap MAX_BOXES_PER_FRAME^2) (every box on one spot), near
        O(MAX_BOXES_PER_FRAME) for people spread across the image."""
        xyxy = np.asarray(xyxy, float).reshape(-1, 4)
        if len(xyxy) > MAX_BOXES_PER_FRAME:
            raise ValueError(f"frames: frame {frame} has {len(xyxy):,} boxes, more than {MAX_BOXES_PER_FRAME:,} (the "
                             "most per frame linked into tracks)")
        live = np.flatnonzero(frame - self._frames <= self.max_gap)  # in track id order (the ties' rule)
        ids = np.full(len(xyxy), -1, dtype=np.int64)
        i, j = _overlapping(xyxy, self._boxes[live])
        iou = _iou(xyxy[i], self._boxes[live[j]])
        keep = iou >= self.min_iou
        box, track = greedy_pairs(i[keep], j[keep], iou[keep], len(live))
        ids[box] = self._ids[live[track]]
        new = ids < 0
        ids[new] = self.tracks + np.arange(int(new.sum()))
        self.tracks += int(new.sum())
        keep = np.setdiff1d(live, live[track])  # live tracks not continued in this frame
        self._ids = np.concatenate([self._ids[keep], ids])
        self._boxes = np.concatenate([self._boxes[keep], xyxy])
        self._frames = np.concatenate([self._frames[keep], np.full(len(ids), frame, np.int64)])
        order = np.argsort(self._ids, kind="stable")
        self._ids, self._boxes, self._frames = self._ids[order], self._boxes[order], self._frames[order]
        return ids


def _overlapping(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(i, j) (P,) intp: every pair of boxes a[i] (N, 4), b[j] (M, 4) whose columns can overlap (b's left edge
    within (a's left edge - b's widest width, a's right edge)), a superset of the pairs with IoU > 0, by a sort
    of b's left edges and two binary searches per box of a."""
    if len(a) == 0 or len(b) == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    order = np.argsort(b[:, 0], kind="stable")
    left = b[order, 0]
    lo = np.searchsorted(left, a[:, 0] - np.max(b[:, 2] - b[:, 0]), side="right")
    counts = np.maximum(np.searchsorted(left, a[:, 2], side="left") - lo, 0)
    i = np.repeat(np.arange(len(a)), counts)
    offsets = np.arange(len(i)) - np.repeat(np.cumsum(counts) - counts, counts)
    return i, order[np.repeat(lo, counts) + offsets]


def greedy_pairs(rows: np.ndarray, cols: np.ndarray, scores: np.ndarray, n_cols: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) (P,) of the greedy one-to-one matching of candidate pairs (rows, cols, scores) (K,): taken in
    order of decreasing score (ties: lower row, then lower column) while both are free. Each row's candidates
    sorted once; a heap holds each free row's best candidate whose column was free when it was pushed (a stale
    one moves on to its row's next free column by one vectorised search): O(K log K) time, O(K) memory."""
    order = np.lexsort((cols, -scores, rows))
    rows, cols, scores = rows[order], cols[order], scores[order]
    firsts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]]) if len(rows) else np.zeros(0, np.intp)
    ends = dict(zip(rows[firsts].tolist(), np.r_[firsts[1:], len(rows)].tolist()))
    taken = np.zeros(n_cols, bool)
    heap = [(-scores[s], int(rows[s]), int(cols[s]), int(s)) for s in firsts]
    heapq.heapify(heap)
    pairs = []
    while heap:
        _, r, c, s = heapq.heappop(heap)
        if not taken[c]:
            taken[c] = True
            pairs.append((r, c))
            continue
        free = np.flatnonzero(~taken[cols[s + 1:ends[r]]])
        if free.size:
            s += 1 + int(free[0])
            heapq.heappush(heap, (-scores[s], r, int(cols[s]), s))
    pairs = np.array(pairs, dtype=np.intp).reshape(-1, 2)
    return pairs[:, 0], pairs[:, 1]
