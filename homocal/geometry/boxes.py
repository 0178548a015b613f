"""Foot points of detector boxes from other tools, in homocal's pixels (data_schema.md, Image and Boxes).

homocal's pixels are OpenCV's: the centre of the pixel in row r, column c is (c, r). A box over mask rows
r0..r1 and columns c0..c1 has its bottom edge at v = r1 + 0.5, and its foot point is that edge's centre.
Other tools write the same box in one of three conventions (BOX_CONVENTIONS, the shift to homocal's pixels):

    "corners"  pixel corners at integers, the image spans [0, W] x [0, H] (YOLO/ultralytics, torchvision,
               COCO, and supervision's Detections of these models): x1 = c0, x2 = c1 + 1, y2 = r1 + 1.
               Foot point ((x1 + x2) / 2 - 0.5, y2 - 0.5).
    "indices"  inclusive pixel indices (supervision's mask_to_xyxy): x1 = c0, x2 = c1, y2 = r1.
               Foot point ((x1 + x2) / 2, y2 + 0.5).
    "homocal"  box edges in homocal's pixels (simgen's datasets): x1 = c0 - 0.5, x2 = c1 + 0.5, y2 = r1 + 0.5.
               Foot point ((x1 + x2) / 2, y2).

Taking a "corners" y2 for a homocal row puts the foot point 0.5 px low, so nearer the camera: on the paper's
camera (PinholeCamera()), straight ahead, 0.02 m at 10 m, 0.09 m at 20 m, 0.33 m at 40 m, 0.51 m at 50 m.
"""
from __future__ import annotations

import numpy as np

BOX_CONVENTIONS = {"corners": (-0.5, -0.5), "indices": (0.0, 0.5), "homocal": (0.0, 0.0)}


def box_bottom_points(xyxy: np.ndarray, *, convention: str) -> np.ndarray:
    """Foot points (N, 2) float64, homocal pixels, of boxes xyxy (N, 4) = (x1, y1, x2, y2) in the given
    convention (a key of BOX_CONVENTIONS: "corners", "indices" or "homocal"): the centre of the box's bottom
    edge. NaN boxes give NaN points. ValueError for another convention or another shape."""
    if convention not in BOX_CONVENTIONS:
        raise ValueError(f"convention {convention!r}: expected one of {', '.join(BOX_CONVENTIONS)}")
    boxes = np.asarray(xyxy)
    if boxes.dtype.kind not in "fiu" or boxes.ndim != 2 or boxes.shape[1] != 4:
        raise ValueError(f"xyxy: expected numbers of shape (N, 4), got {boxes.dtype} of shape {boxes.shape}")
    du, dv = BOX_CONVENTIONS[convention]
    boxes = boxes.astype(np.float64)
    return np.column_stack([(boxes[:, 0] + boxes[:, 2]) / 2.0 + du, boxes[:, 3] + dv])
