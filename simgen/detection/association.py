"""Associating detections with agents (box IoU, greedy one-to-one) and with ground truth in time."""
from __future__ import annotations

import numpy as np
import pyarrow as pa

TIE_TOLERANCE_S = 1e-9
"""Two time gaps that differ by at most this many seconds are a tie; ties go to the earlier sample."""


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection over union of (N, 4) and (M, 4) boxes (x1, y1, x2, y2) -> (N, M); 0 where both are empty."""
    a, b = np.reshape(a, (-1, 1, 4)), np.reshape(b, (1, -1, 4))
    iw = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0.0, None)
    ih = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0.0, None)
    inter = iw * ih
    area_a = (a[..., 2] - a[..., 0]) * (a[..., 3] - a[..., 1])
    area_b = (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1])
    union = area_a + area_b - inter
    return np.divide(inter, union, out=np.zeros_like(inter), where=union > 0)


def greedy_assign(score: np.ndarray, min_score: float) -> tuple[np.ndarray, np.ndarray]:
    """One-to-one pairs from an (N, M) score matrix, best score first.

    Pairs with score >= min_score are taken in order of decreasing score (ties: lower row, then
    lower column) while both their row and column are free. Deterministic.
    Returns (rows, cols), each (P,) intp, in the order taken.
    """
    rows, cols = np.nonzero(score >= min_score)
    order = np.lexsort((cols, rows, -score[rows, cols]))
    taken_rows, taken_cols, pairs = set(), set(), []
    for r, c in zip(rows[order].tolist(), cols[order].tolist()):
        if r not in taken_rows and c not in taken_cols:
            taken_rows.add(r)
            taken_cols.add(c)
            pairs.append((r, c))
    pairs = np.array(pairs, dtype=np.intp).reshape(-1, 2)
    return pairs[:, 0], pairs[:, 1]


def associate(xyxy: np.ndarray, ref_ids: np.ndarray, ref_xyxy: np.ndarray, min_iou: float) -> np.ndarray:
    """Agent of each of (N, 4) boxes: greedy one-to-one by IoU with (M, 4) reference boxes of agents
    (M,) ref_ids, IoU >= min_iou -> (N,) int32 agent ids, -1 where unmatched."""
    agent_id = np.full(len(xyxy), -1, dtype=np.int32)
    rows, cols = greedy_assign(box_iou(xyxy, ref_xyxy), min_iou)
    agent_id[rows] = ref_ids[cols]
    return agent_id


def nearest_sample(times: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Index of the nearest of ascending (M,) `times` (M >= 1) for each of (N,) `query` times, seconds.

    Ties (within TIE_TOLERANCE_S) and repeated times go to the earlier index.
    """
    times, query = np.asarray(times, dtype=np.float64), np.asarray(query, dtype=np.float64)
    hi = np.minimum(np.searchsorted(times, query, side="left"), times.size - 1)
    lo = np.maximum(hi - 1, 0)
    nearest = np.where(query - times[lo] <= times[hi] - query + TIE_TOLERANCE_S, lo, hi)
    return np.searchsorted(times, times[nearest], side="left")  # the first of repeated times


def match_to_gt(detections: pa.Table, gt: pa.Table) -> pa.Table:
    """Add gt_t (s), gt_x, gt_y (m): the temporally nearest ground-truth sample of the detection's agent.

    Paper Section 5.1. detections: columns t (s), agent_id; gt: columns t (s), agent_id, x, y (m).
    NaN where agent_id == -1 or the agent has no ground-truth sample; ties go to the earlier sample.
    """
    det_t = detections.column("t").to_numpy()
    det_agent = detections.column("agent_id").to_numpy()
    gt_agent = gt.column("agent_id").to_numpy()
    gt_t = gt.column("t").to_numpy()
    order = np.lexsort((gt_t, gt_agent))
    gt_agent, gt_t = gt_agent[order], gt_t[order]
    gt_x, gt_y = gt.column("x").to_numpy()[order], gt.column("y").to_numpy()[order]

    out = np.full((len(det_t), 3), np.nan)
    for agent in np.unique(det_agent[det_agent >= 0]):
        start, stop = np.searchsorted(gt_agent, agent, side="left"), np.searchsorted(gt_agent, agent, side="right")
        if start == stop:
            continue
        rows = np.flatnonzero(det_agent == agent)
        idx = start + nearest_sample(gt_t[start:stop], det_t[rows])
        out[rows] = np.column_stack([gt_t[idx], gt_x[idx], gt_y[idx]])
    for j, name in enumerate(("gt_t", "gt_x", "gt_y")):
        detections = detections.append_column(pa.field(name, pa.float64()), pa.array(out[:, j]))
    return detections
