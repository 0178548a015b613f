"""Associating detections with agents (box IoU, greedy one-to-one) and with ground truth in time."""
from __future__ import annotations

import numpy as np
import pyarrow as pa

from homocal.geometry.boxes import box_iou, greedy_pairs

TIE_TOLERANCE_S = 1e-9
"""Two time gaps that differ by at most this many seconds are a tie; ties go to the earlier sample."""


def greedy_assign(score: np.ndarray, min_score: float) -> tuple[np.ndarray, np.ndarray]:
    """One-to-one pairs from an (N, M) score matrix, best score first.

    Pairs with score >= min_score are taken in order of decreasing score (ties: lower row, then
    lower column) while both their row and column are free (homocal.geometry.boxes.greedy_pairs).
    Deterministic. Returns (rows, cols), each (P,) intp, in the order taken.
    """
    rows, cols = np.nonzero(score >= min_score)
    return greedy_pairs(rows, cols, score[rows, cols], score.shape[1])


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
