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

import numpy as np

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
    foot, head, left, right = (lens.undistort_points(np.column_stack(p)) for p in ((xc, y2), (xc, y1), (x1, y2), (x2, y2)))
    lost = np.flatnonzero(np.isfinite(edges).all(axis=1) & ~np.isfinite(np.column_stack([foot, head, left, right])).all(axis=1))
    if lost.size:
        raise ValueError(f"xyxy[{lost[0]}] = {edges[lost[0]].tolist()} lies beyond the lens's fold: no ray of this "
                         "lens reaches it")
    half = np.hypot(*(right - left).T) / 2.0
    return np.column_stack([foot[:, 0] - half, head[:, 1], foot[:, 0] + half, foot[:, 1]])


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection over union (N, M) of boxes a (N, 4) and b (M, 4), edges (x1, y1, x2, y2) in one convention."""
    w = np.clip(np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None)
    h = np.clip(np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None)
    inter = w * h
    area = lambda x: (x[:, 2] - x[:, 0]) * (x[:, 3] - x[:, 1])  # noqa: E731
    return inter / (area(a)[:, None] + area(b)[None, :] - inter)


def link_tracks(frames: np.ndarray, xyxy: np.ndarray, min_iou: float = 0.3, max_gap: int = 5) -> np.ndarray:
    """Track ids (N,) int64, 0, 1, ... in order of first appearance, for boxes xyxy (N, 4) in video frames
    frames (N,) int: frame by frame in increasing order, ``TrackLinker.link`` (one box per track and frame,
    IoU >= min_iou, boxes at most max_gap frames apart). A simple linker of detections (no motion model):
    enough to count people once rather than once per frame."""
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
        """Track ids (M,) int64 of the boxes xyxy (M, 4) of video frame ``frame`` (not before the last one)."""
        live = np.flatnonzero(frame - self._frames <= self.max_gap)
        ids = np.full(len(xyxy), -1, dtype=np.int64)
        iou = box_iou(xyxy, self._boxes[live])
        taken = set()
        for flat in np.argsort(-iou, axis=None, kind="stable"):
            i, j = divmod(int(flat), len(live))
            if iou[i, j] < self.min_iou:
                break
            if ids[i] < 0 and live[j] not in taken:
                ids[i] = self._ids[live[j]]
                taken.add(live[j])
        new = ids < 0
        ids[new] = self.tracks + np.arange(int(new.sum()))
        self.tracks += int(new.sum())
        keep = np.setdiff1d(live, list(taken))  # live tracks not continued in this frame
        self._ids = np.concatenate([self._ids[keep], ids])
        self._boxes = np.concatenate([self._boxes[keep], np.asarray(xyxy, float).reshape(-1, 4)])
        self._frames = np.concatenate([self._frames[keep], np.full(len(ids), frame, np.int64)])
        order = np.argsort(self._ids, kind="stable")  # live tracks in id order (the ties' rule)
        self._ids, self._boxes, self._frames = self._ids[order], self._boxes[order], self._frames[order]
        return ids
