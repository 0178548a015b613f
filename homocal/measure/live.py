"""``GroundTracker``: ground positions and speeds frame by frame from a tracker's boxes, such as supervision's
``sv.Detections`` with ``tracker_id`` (duck-typed: supervision is not imported, the extra
``pip install "homocal[supervision]"`` only brings it in for its users)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from homocal.correctors.pedestrians import SETTINGS as PEDESTRIAN_SETTINGS
from homocal.correctors.pedestrians import _check_image_size
from homocal.geometry.boxes import box_bottom_points, box_edges, trim_boxes
from homocal.measure.kalman import ACCEL_PSD, correlated_noise, imm_start, imm_step, motion_model
from homocal.measure.tracks import (FEET, FOOT, FOOT_NOISE, FOOT_TAILS, as_mapping, box_margin_of, foot_noise_options,
                                    map_points, measured_feet, measurement_dof, point_noise, state_speed)
from homocal.uncertainty import sigma_radius

MAX_AGE_S = 2.0
"""A track not seen for longer than this is forgotten (its state dropped: memory stays bounded by the
people seen in the last MAX_AGE_S); seen again, it starts anew."""


@dataclass(frozen=True)
class GroundState:
    """One frame's answer of ``GroundTracker.update``, aligned with the detections given (N rows).

    Attributes: tracker_id (N,) int64; xy (N, 2) mapped foot points, metres; sigma_m (N,) their 1-sigma
    radius; xy_filtered (N, 2) and velocity (N, 2) m/s, the forward Kalman filter's state; speed_mps (N,)
    and speed_sigma_mps (N,) its speed and 1-sigma (homocal measure's: the delta method, with IMM the half-width
    holding 68.27 % of the models' mixture; homocal.measure.kalman.mixture_speed), NaN for a track not
    measured yet; foot (N,) str, one of homocal.measure.tracks.FOOT: the foot point measured ("used") or, with
    feet="soles", predicted through ("hidden", "border")."""

    tracker_id: np.ndarray
    xy: np.ndarray
    sigma_m: np.ndarray
    xy_filtered: np.ndarray
    velocity: np.ndarray
    speed_mps: np.ndarray
    speed_sigma_mps: np.ndarray
    foot: np.ndarray


class GroundTracker:
    """A causal constant-velocity Kalman filter per track on the ground (homocal measure's filter, forward pass
    only: each answer uses the frames up to it); with accel_psd IMM (homocal.measure.kalman) the two-regime
    model's IMM filter, its models' mixture (no smoother: a manoeuvre's bar widens only once its frames show it).

    Args:
        mapping: a fitted Corrector (homocal.load_corrector) or a ViewTransformer.
        fps: frames per second of the video (> 0): t = frame / fps.
        convention: the boxes' pixel convention (homocal.box_bottom_points): "corners" for supervision's
            Detections of YOLO-like models, "indices" for its mask_to_xyxy boxes, "homocal" for simgen's.
        accel_psd, click_sigma_px, point_sigma_px: as homocal.measure.measure_tracks (accel_psd a q or IMM).
        foot_noise: the foot point's noise model, one of homocal.measure.tracks.FOOT_NOISE (homocal measure
            --foot-noise): "fixed" (point_sigma_px), "box-height" or "correlated".
        foot_tails: its distribution, one of homocal.measure.tracks.FOOT_TAILS (homocal measure
            --foot-noise-tails): "normal", or "student" (heavy tailed; with a foot_noise of STUDENT_FOOT_NOISE).
        feet: the foot points measured, one of homocal.measure.tracks.FEET (homocal measure --feet): "all", or
            "soles": not a box whose feet a nearer box of the frame may hide, nor, with image_size, one whose
            bottom or side edge the image border cuts (homocal.measure.tracks.foot_status).
        image_size: (width, height) px of the frames the boxes are in (the camera's pixels), or None.
        box_margin_px: how much taller than their people the boxes are, px (homocal measure --box-margin: half off
            each box's top and bottom edge, a box no taller not measured, foot "short"); None: the mapping's
            (a pedestrians correction's box_margin_px, else 0).
    """

    def __init__(self, mapping, fps: float, *, convention: str = "corners", accel_psd: float | str = ACCEL_PSD,
                 click_sigma_px: float = 1.5, point_sigma_px: float = 1.0, foot_noise: str = FOOT_NOISE[0],
                 feet: str = FEET[0], image_size: tuple[int, int] | None = None, foot_tails: str = FOOT_TAILS[0],
                 box_margin_px: float | None = None) -> None:
        if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
            raise ValueError(f"fps: expected a finite number > 0, got {fps!r}")
        foot_noise_options(foot_noise, np.zeros((0, 4)), point_sigma_px, foot_tails)  # ValueError for an unknown model
        if feet not in FEET:
            raise ValueError(f"feet: expected one of {', '.join(FEET)}, got {feet!r}")
        self.mapping, self.fps, self.convention = as_mapping(mapping), float(fps), convention
        self.accel_psd, self.click_sigma_px, self.point_sigma_px = accel_psd, click_sigma_px, point_sigma_px
        self.foot_noise, self.feet, self.image_size = foot_noise, feet, _check_image_size(image_size)
        self.foot_tails = foot_tails
        self.box_margin_px = box_margin_of(mapping) if box_margin_px is None else float(
            PEDESTRIAN_SETTINGS["box_margin_px"].check("box_margin_px", box_margin_px))
        self._motion = motion_model(accel_psd)
        self._tracks: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, int, bool]] = {}  # id -> each model's state
        # (M, d), covariance (M, d, d), the models' probabilities (M,), frame, a foot point measured yet
        self._frame: int | None = None

    def update(self, detections, frame: int) -> GroundState:
        """The ground state of each detection in video frame ``frame`` (an integer, larger than the last
        update's). detections: anything with ``xyxy`` (N, 4) boxes and ``tracker_id`` (N,) integers, one box
        per id (sv.Detections whose tracker_id a tracker filled). ValueError otherwise."""
        xyxy, ids = getattr(detections, "xyxy", None), getattr(detections, "tracker_id", None)
        if xyxy is None or ids is None:
            raise ValueError("detections: needs xyxy and tracker_id (run a tracker on them first)")
        ids = np.asarray(ids)
        if ids.dtype.kind not in "iu" or ids.shape != (len(np.asarray(xyxy)),):
            raise ValueError(f"detections.tracker_id: expected (N,) integers for the N boxes, got {ids.dtype} {ids.shape}")
        if len(np.unique(ids)) != len(ids):
            raise ValueError("detections.tracker_id: an id twice in one frame")
        if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or (self._frame is not None and frame <= self._frame):
            raise ValueError(f"frame: expected an integer larger than the last one ({self._frame}), got {frame!r}")
        self._frame = int(frame)
        self._tracks = {k: s for k, s in self._tracks.items() if (frame - s[3]) / self.fps <= MAX_AGE_S}
        detected = box_edges(np.asarray(xyxy), convention=self.convention)
        edges = trim_boxes(detected, self.box_margin_px)
        feet = box_bottom_points(edges, convention="homocal")
        foot = measured_feet(detected, np.zeros(len(ids), np.int64), self.image_size, self.feet, self.box_margin_px)
        used = foot == FOOT[0]
        noise = foot_noise_options(self.foot_noise, edges, self.point_sigma_px, self.foot_tails)
        xy, cov = map_points(self.mapping, feet, self.click_sigma_px, noise["point_sigma_px"])
        R, correlated = correlated_noise(noise["noise_scale"]**2 * (point_noise(self.mapping, feet, noise["point_sigma_px"])
                                         if noise["split_mapping_error"] else cov), noise["foot_correlation_s"])
        x, P, mu = imm_start(len(ids), len(self._motion[0]), self._motion[1],
                             None if correlated is None else correlated[0])
        dt, known = np.zeros(len(ids)), used.copy()
        for i, k in enumerate(ids.tolist()):
            if k in self._tracks:
                x[i], P[i], mu[i], last, measured = self._tracks[k]
                dt[i], known[i] = (frame - last) / self.fps, used[i] or measured
        step = imm_step(x, P, mu, dt, np.where(used[:, None], xy, np.nan), R, *self._motion, correlated,
                        measurement_dof(noise["student_dof"]))
        for i, k in enumerate(ids.tolist()):
            self._tracks[k] = (step["x"][i], step["P"][i], step["mu"][i], int(frame), bool(known[i]))
        x = np.where(known[:, None, None], step["x"], np.nan)  # no foot point of the track measured yet: nothing known
        x, speed, speed_sigma = state_speed(self.mapping, feet, step["mu"], x, step["P"],
                                            self.click_sigma_px if noise["split_mapping_error"] else None)
        return GroundState(ids.astype(np.int64), xy, sigma_radius(cov), x[:, :2], x[:, 2:4], speed, speed_sigma, foot)
