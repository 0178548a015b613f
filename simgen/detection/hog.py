"""Detectors that see only the RGB frame: the plug-in point for any function frame -> boxes, and HOG.

``FunctionDetector(name, boxes)`` turns a function ``boxes(rgb) -> (xyxy (N, 4), score (N,))`` (boxes
in this package's pixel convention, scores in [0, 1]) into a Detector: each box is then associated
with an agent by IoU with the agents' visible-mask boxes, greedy one-to-one, IoU >= min_iou, else
agent_id -1, exactly as the rgb detector's blobs (both first put their boxes in ``canonical_order``).
Bring your own model this way (a YOLO, say) and run it in the generation loop, or offline on a
finished dataset's video with ``simgen import-mot``.

``HogDetector`` ("hog") is OpenCV's HOG + linear SVM people detector (Dalal & Triggs 2005; the
weights ship inside OpenCV, ``HOGDescriptor_getDefaultPeopleDetector``): a 64x128 window slid over
the full frame at every level of an image pyramid (``detectMultiScale``, levels ``scale`` apart),
overlapping hits grouped. The window of its training set (INRIA) holds a person about 96 px tall
with 16 px of margin above and below, so each window is trimmed by 1/8 of its height at the top
and bottom (and 1/4 of its width at each side) before it becomes a box: the box's bottom centre is
then the foot point. The frame is first enlarged 2x (``upscale``): the 128 px window then fits people
from about 50 px tall, the heights most pedestrians have in a 1280x720 street view; at 1x it finds
none under about 80 px, at a quarter of the cost.
"""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version
from typing import Callable

import cv2
import numpy as np

from simgen.detection.association import associate
from simgen.detection.batch import DetectionBatch, canonical_order
from simgen.detection.masks import id_boxes

BoxFunction = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
"""rgb (H, W, 3) uint8 -> (xyxy (N, 4) float64 continuous pixels, score (N,) float64 in [0, 1])."""

WINDOW_TRIM = (0.25, 0.125)  # fraction of the HOG window's width (each side) and height (top and bottom) that is margin


class FunctionDetector:
    """A Detector from a function of the RGB frame (module docstring); ``name`` labels its detections."""

    def __init__(self, name: str, boxes: BoxFunction, min_iou: float = 0.3) -> None:
        self.name, self.boxes, self.min_iou = name, boxes, min_iou

    def detect(self, frame: int, t: float, rgb: np.ndarray, agent_ids: np.ndarray) -> DetectionBatch:
        """rgb: (H, W, 3) uint8; agent_ids: (H, W) int32, -1 where no agent (used only to associate)."""
        xyxy, score = self.boxes(rgb)
        xyxy, score = canonical_order(np.asarray(xyxy, np.float64).reshape(-1, 4), np.asarray(score, np.float64).reshape(-1))
        ids, mask_xyxy, _ = id_boxes(agent_ids)
        return DetectionBatch(self.name, frame, t, xyxy, score, associate(xyxy, ids, mask_xyxy, self.min_iou))


CONTRIB = "opencv-contrib-python-headless"  # the hog extra's OpenCV build (pyproject.toml)


def hog_missing() -> str | None:
    """None if this OpenCV has the HOG people detector, else one line saying the pip command that repairs cv2:
    reinstalling the contrib build's files (at its installed version) over the base build's, or installing it."""
    if hasattr(cv2, "HOGDescriptor"):
        return None
    try:
        fix = f"pip install --force-reinstall --no-deps {CONTRIB}=={version(CONTRIB)}"
    except PackageNotFoundError:
        fix = f"pip install {CONTRIB} (the hog extra)"
    return (f"OpenCV {cv2.__version__} at {cv2.__file__} has no HOGDescriptor (OpenCV 5 keeps it in the contrib "
            f"build, whose cv2 files the base build's replaced): {fix}")


def _hog() -> "cv2.HOGDescriptor":
    missing = hog_missing()
    if missing:
        raise RuntimeError(f"the hog detector: {missing}")
    hog = cv2.HOGDescriptor()
    hog.setSVMDetector(cv2.HOGDescriptor_getDefaultPeopleDetector())
    return hog


class HogDetector(FunctionDetector):
    """OpenCV's HOG people detector on the full frame (module docstring).

    Args:
        upscale: the frame is enlarged by this factor (cv2.INTER_LINEAR) before detection; 1 finds people from
            about 80 px tall, 2 from about 50 px, at about 4x the cost.
        scale: ratio of successive pyramid levels; win_stride: window step, px; hit_threshold: SVM margin a
            window needs; group_threshold: grouping strength of overlapping hits (OpenCV's finalThreshold).
        min_iou: smallest box IoU for associating a box with an agent's mask box.
    Score: the logistic function of the SVM margin, 1 / (1 + exp(-weight)).
    """

    def __init__(self, upscale: float = 2.0, scale: float = 1.05, win_stride: int = 8, hit_threshold: float = 0.0,
                 group_threshold: int = 2, min_iou: float = 0.3) -> None:
        if not (upscale > 0 and scale > 1 and win_stride >= 1):
            raise ValueError(f"HogDetector: need upscale > 0, scale > 1, win_stride >= 1; got {upscale}, {scale}, {win_stride}")
        self.upscale, self.scale, self.win_stride = upscale, scale, win_stride
        self.hit_threshold, self.group_threshold = hit_threshold, group_threshold
        self._hog = _hog()
        super().__init__("hog", self.people, min_iou)

    def people(self, rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """rgb (H, W, 3) uint8 -> person boxes (N, 4) float64 (continuous pixels, trimmed windows) and scores (N,)."""
        f = self.upscale
        image = rgb if f == 1 else cv2.resize(rgb, None, fx=f, fy=f, interpolation=cv2.INTER_LINEAR)
        rects, weights = self._hog.detectMultiScale(
            image, hitThreshold=self.hit_threshold, winStride=(self.win_stride, self.win_stride), padding=(8, 8),
            scale=self.scale, groupThreshold=self.group_threshold)
        rects = np.asarray(rects, np.float64).reshape(-1, 4)
        x, y, w, h = rects.T
        tw, th = WINDOW_TRIM
        # window columns x .. x + w - 1 of the enlarged image: edges at x / f - 0.5 and (x + w) / f - 0.5
        xyxy = np.column_stack([x + tw * w, y + th * h, x + (1 - tw) * w, y + (1 - th) * h]) / f - 0.5
        return xyxy, 1.0 / (1.0 + np.exp(-np.asarray(weights, np.float64).reshape(-1)))
