"""What a detector returns for one frame (``DetectionBatch``), the ``Detector`` interface, and the detections table built from batches.

Image coordinates are continuous pixels: x right, y down, the centre of the top-left pixel at
(0, 0). A box (x1, y1, x2, y2) that covers pixel columns c0..c1 and rows r0..r1 has
x1 = c0 - 0.5, x2 = c1 + 0.5, y1 = r0 - 0.5, y2 = r1 + 0.5, so x2 - x1 is its width in pixels.
The foot point is the bottom centre of the box: u = (x1 + x2) / 2, v = y2.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import pyarrow as pa

from homocal.geometry.boxes import box_bottom_points

DETECTIONS_SCHEMA = pa.schema(
    [
        ("detector", pa.string()),
        ("frame", pa.int32()),
        ("t", pa.float64()),
        ("agent_id", pa.int32()),
        ("x1", pa.float64()),
        ("y1", pa.float64()),
        ("x2", pa.float64()),
        ("y2", pa.float64()),
        ("score", pa.float64()),
        ("u", pa.float64()),
        ("v", pa.float64()),
    ]
)


def foot_points(xyxy: np.ndarray) -> np.ndarray:
    """(N, 4) boxes (x1, y1, x2, y2) -> (N, 2) foot points (u, v) = ((x1 + x2) / 2, y2), pixels: simgen's boxes
    are in homocal's pixel convention (homocal.box_bottom_points)."""
    return box_bottom_points(np.asarray(xyxy, dtype=np.float64).reshape(-1, 4), convention="homocal")


def canonical_order(xyxy: np.ndarray, score: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 4) boxes and (N,) scores sorted by (x1, y1, x2, y2, score).

    A detector's output in this order does not depend on how it was computed (OpenCV's HOG returns the same
    boxes in an order that varies with its threads), so association, which is greedy and breaks ties by row,
    and the detections' rows are the same from run to run.
    """
    order = np.lexsort((score, xyxy[:, 3], xyxy[:, 2], xyxy[:, 1], xyxy[:, 0]))
    return xyxy[order], score[order]


@dataclass(frozen=True)
class DetectionBatch:
    """The detections of one detector on one frame.

    Attributes:
        detector: the detector's name.
        frame: 0-based frame index.
        t: simulated time of the frame, seconds.
        xyxy: (N, 4) float64 boxes (x1, y1, x2, y2), continuous pixels (module docstring).
        score: (N,) float64 confidence in [0, 1].
        agent_id: (N,) int32 associated agent, -1 where none.
    """

    detector: str
    frame: int
    t: float
    xyxy: np.ndarray
    score: np.ndarray
    agent_id: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.xyxy)
        if np.shape(self.xyxy) != (n, 4) or np.shape(self.score) != (n,) or np.shape(self.agent_id) != (n,):
            raise ValueError(
                f"DetectionBatch: shapes xyxy {np.shape(self.xyxy)}, score {np.shape(self.score)}, "
                f"agent_id {np.shape(self.agent_id)} do not agree"
            )

    def __len__(self) -> int:
        return len(self.xyxy)

    @property
    def foot(self) -> np.ndarray:
        """(N, 2) foot points (u, v), pixels."""
        return foot_points(self.xyxy)


class Detector(Protocol):
    """Anything that turns a rendered frame into a DetectionBatch."""

    name: str

    def detect(self, frame: int, t: float, rgb: np.ndarray, agent_ids: np.ndarray) -> DetectionBatch:
        """rgb: (H, W, 3) uint8; agent_ids: (H, W) int32 agent visible at each pixel, -1 where none."""
        ...


def detections_table(batches: list[DetectionBatch]) -> pa.Table:
    """Stack batches into one table with DETECTIONS_SCHEMA, one row per detection, in batch order."""
    if not batches:
        return DETECTIONS_SCHEMA.empty_table()
    counts = [len(b) for b in batches]
    xyxy = np.concatenate([b.xyxy for b in batches]).reshape(-1, 4)
    foot = foot_points(xyxy)
    columns = {
        "detector": np.repeat([b.detector for b in batches], counts),
        "frame": np.repeat([b.frame for b in batches], counts),
        "t": np.repeat([b.t for b in batches], counts),
        "agent_id": np.concatenate([b.agent_id for b in batches]),
        "x1": xyxy[:, 0],
        "y1": xyxy[:, 1],
        "x2": xyxy[:, 2],
        "y2": xyxy[:, 3],
        "score": np.concatenate([b.score for b in batches]),
        "u": foot[:, 0],
        "v": foot[:, 1],
    }
    return pa.table([pa.array(columns[f.name], type=f.type) for f in DETECTIONS_SCHEMA], schema=DETECTIONS_SCHEMA)
