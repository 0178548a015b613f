"""Ground truth of one 50 ms step: positions, exact projections, visible boxes and visible fractions.

The visible fraction divides an agent's visible pixels (segmentation render) by the pixels of its
unoccluded, unclipped silhouette, which is computed here from the posed geoms (``AgentState.segments``): a
sphere projects to the projection of its tangent circle, a capsule (the convex hull of two spheres)
to the convex hull of its two end spheres' silhouettes; polygons are filled with OpenCV.
"""
from __future__ import annotations

import cv2
import numpy as np
import pyarrow as pa

from homocal.geometry.camera import PinholeCamera
from simgen.agents import AgentState
from simgen.detection import id_boxes
from simgen.scene import GT_RATE, Scene, in_frame

GT_SCHEMA = pa.schema([
    ("t", pa.float64()), ("step", pa.int64()), ("agent_id", pa.int32()),
    ("x", pa.float64()), ("y", pa.float64()), ("heading", pa.float64()), ("speed", pa.float64()),
    ("u", pa.float64()), ("v", pa.float64()), ("in_frame", pa.bool_()),
    ("x1", pa.float64()), ("y1", pa.float64()), ("x2", pa.float64()), ("y2", pa.float64()),
    ("visible_fraction", pa.float64()), ("visible_pixels", pa.int32()),
])  # fmt: skip

CAMERA_POSE_SCHEMA = pa.schema([
    ("t", pa.float64()), ("step", pa.int64()), ("tilt_deg", pa.float64()), ("roll_deg", pa.float64()),
    ("yaw_deg", pa.float64()), ("horizon_a", pa.float64()), ("horizon_b", pa.float64()), ("horizon_c", pa.float64()),
])  # fmt: skip

_ANGLES = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
_SHIFT = 4  # cv2 fixed-point bits: polygons are filled at 1/16 px precision
_SUPER = 4  # small silhouettes are filled on a 4x finer grid (large ones on coarser) and counted in image pixels
_MAX_SPAN = 8192  # px: a silhouette larger than this (an agent almost at the lens) has no area (NaN)


def _sphere_outline(camera: PinholeCamera, centres: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """(N, 3) world sphere centres, (N,) radii -> (N, 24, 2) pixel outline of their silhouettes (NaN if not in front),
    through the lens (the outline's points distorted; the hull between them stays straight, a sub-pixel error at
    an agent's size)."""
    cc = centres @ camera.R.T + camera.t  # camera frame
    d2 = np.einsum("ij,ij->i", cc, cc)
    centre = cc * (1.0 - radius**2 / d2)[:, None]  # the tangent circle, in the plane normal to cc
    rad = radius * np.sqrt(np.maximum(d2 - radius**2, 0.0) / d2)
    axis = cc / np.sqrt(d2)[:, None]
    e1 = np.cross(axis, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(axis, e1)
    ring = centre[:, None] + rad[:, None, None] * (np.cos(_ANGLES)[None, :, None] * e1[:, None] + np.sin(_ANGLES)[None, :, None] * e2[:, None])
    uvw = ring @ camera.K.T
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = uvw[..., :2] / uvw[..., 2:]
    uv[~(ring[..., 2] > radius[:, None])] = np.nan
    return camera.distort(uv.reshape(-1, 2)).reshape(uv.shape)


def silhouette_outlines(camera: PinholeCamera, segments: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Outline points of each agent's geoms: (A, G, 48, 2) pixels, NaN where not in front of the camera.

    Args:
        segments: (A, G, 2, 3) world segment ends of the geoms, metres; radii: (A, G) metres.
    Each geom's silhouette is the convex hull of its 48 points (24 per end sphere).
    """
    a, g = radii.shape
    ends = _sphere_outline(camera, segments.reshape(-1, 3), np.repeat(radii.ravel(), 2))
    return ends.reshape(a, g, 48, 2)


def silhouette_pixels(camera: PinholeCamera, segments: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Area of each agent's unoccluded, unclipped silhouette: (A,) float64 pixels, NaN if partly behind the camera.

    Args:
        segments: (A, G, 2, 3) world segment ends of the geoms, metres; radii: (A, G) metres.
    """
    out = np.full(len(segments), np.nan)
    for a, geoms in enumerate(silhouette_outlines(camera, segments, radii)):
        if not np.isfinite(geoms).all():
            continue
        lo = np.floor(geoms.reshape(-1, 2).min(axis=0)) - 1
        span = np.ceil(geoms.reshape(-1, 2).max(axis=0)) + 2 - lo
        if span.max() > _MAX_SPAN:
            continue
        sup = int(np.clip(1024 // span.max(), 1, _SUPER))
        canvas = np.zeros((int(span[1]) * sup, int(span[0]) * sup), np.uint8)
        for g in geoms:  # fine-grid pixel centres at (i + 0.5) / sup - 0.5 in image pixels
            fine = ((g - lo + 0.5) * sup - 0.5) * (1 << _SHIFT)
            cv2.fillConvexPoly(canvas, cv2.convexHull(np.round(fine).astype(np.int32)), 1, lineType=cv2.LINE_8, shift=_SHIFT)
        out[a] = np.count_nonzero(canvas) / sup**2
    return out


def gt_columns(step: int, camera: PinholeCamera, state: AgentState, agent_ids: np.ndarray) -> dict[str, np.ndarray]:
    """The gt.parquet columns (GT_SCHEMA) of one step: one entry per active agent, sorted by agent_id.

    Args:
        step: ground-truth step; t = step * 0.05.
        state: the active agents at t = step / 20.
        agent_ids: (H, W) int32 agent-id map of the segmentation render at that time.
    """
    order = np.argsort(state.agent_id, kind="stable")
    ids, xy = state.agent_id[order], state.xy[order]
    uv = camera.project_ground(xy)
    box = np.full((len(ids), 4), np.nan)
    pixels = np.zeros(len(ids), np.int32)
    seen, xyxy, counts = id_boxes(agent_ids)
    hit = np.isin(ids, seen)
    where = np.searchsorted(seen, ids[hit])
    box[hit], pixels[hit] = xyxy[where], counts[where]
    fraction = np.zeros(len(ids))
    area = silhouette_pixels(camera, state.segments[order][hit], state.radii[order][hit])  # only agents with visible pixels
    with np.errstate(invalid="ignore", divide="ignore"):
        fraction[hit] = np.where(np.isfinite(area), np.clip(pixels[hit] / area, 0.0, 1.0), 1.0)
    return {
        "t": np.full(len(ids), step * 0.05), "step": np.full(len(ids), step, np.int64), "agent_id": ids,
        "x": xy[:, 0], "y": xy[:, 1], "heading": state.heading[order], "speed": state.speed[order],
        "u": uv[:, 0], "v": uv[:, 1], "in_frame": in_frame(camera, uv),
        "x1": box[:, 0], "y1": box[:, 1], "x2": box[:, 2], "y2": box[:, 3],
        "visible_fraction": fraction, "visible_pixels": pixels,
    }  # fmt: skip


def camera_pose_table(scene: Scene) -> pa.Table:
    """camera_pose.parquet (CAMERA_POSE_SCHEMA): the moving camera's pose at every ground-truth step
    (``Scene.camera_at``) and its horizon a u + b v + c = 0 (``PinholeCamera.horizon``: the undistorted image,
    a^2 + b^2 = 1, positive below the horizon)."""
    steps = np.arange(scene.steps_total, dtype=np.int64)
    poses = [scene.camera_at(x) for x in steps / GT_RATE]  # the instants simgen.chunks renders
    angles = np.array([(c.tilt_deg, c.roll_deg, c.yaw_deg) for c in poses]).reshape(-1, 3)
    lines = np.array([c.horizon for c in poses]).reshape(-1, 3)
    return pa.Table.from_arrays([pa.array(steps * 0.05), pa.array(steps), *map(pa.array, angles.T), *map(pa.array, lines.T)],
                                schema=CAMERA_POSE_SCHEMA)
