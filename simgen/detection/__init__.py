"""Detections for simgen: detectors behind one interface, association with agents, matching to ground truth.

Conventions (also in data_schema.md): image pixels with the centre of the top-left pixel at
(0, 0), x right, y down; a box covering pixel columns c0..c1 has x1 = c0 - 0.5, x2 = c1 + 0.5
(rows likewise); the foot point is the bottom centre (u, v) = ((x1 + x2) / 2, y2); frames are
0-based; times in seconds.
"""
from simgen.detection.association import associate, box_iou, greedy_assign, match_to_gt, nearest_sample
from simgen.detection.background import BackgroundSubtractionDetector
from simgen.detection.batch import DETECTIONS_SCHEMA, DetectionBatch, Detector, canonical_order, detections_table, foot_points
from simgen.detection.hog import BoxFunction, FunctionDetector, HogDetector
from simgen.detection.masks import SegmentationDetector, id_boxes, mask_boxes
from simgen.detection.mot import append_detections, import_into_dataset, import_mot, read_mot, write_mot_det, write_mot_gt

__all__ = [
    "DETECTIONS_SCHEMA",
    "BackgroundSubtractionDetector",
    "BoxFunction",
    "DetectionBatch",
    "Detector",
    "FunctionDetector",
    "HogDetector",
    "SegmentationDetector",
    "append_detections",
    "associate",
    "box_iou",
    "canonical_order",
    "detections_table",
    "foot_points",
    "greedy_assign",
    "id_boxes",
    "import_into_dataset",
    "import_mot",
    "mask_boxes",
    "match_to_gt",
    "nearest_sample",
    "read_mot",
    "write_mot_det",
    "write_mot_gt",
]
