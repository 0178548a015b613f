"""``simgen preview``: one frame of a scene, annotated with boxes, foot points (detected and true), trapezoids and the
horizon, with a legend strip below it."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from PIL import Image
from PIL.PngImagePlugin import PngInfo

from homocal.files import check_output_file, write_atomic
from homocal.geometry.camera import PinholeCamera
from simgen.detection import SegmentationDetector
from simgen.scene import Scene
from simgen.stage import Stage

_SHIFT = 4  # cv2 fixed-point bits, so sub-pixel coordinates are drawn where they are
SOFTWARE = "simgen preview"  # the PNG's Software text: marks a file preview wrote (and may replace)
# What preview draws, each in its colour (BGR) and as the legend names it, in the legend's order.
HORIZON, EXACT, HAND_PLACED = (255, 0, 255), (255, 255, 0), (0, 255, 255)
BOX, FOOT, TRUE_FOOT = (0, 200, 0), (0, 0, 255), (255, 80, 0)
LEGEND = ((BOX, "box", "person's box (segmentation detector)"), (FOOT, "dot", "its foot point (detected)"),
          (TRUE_FOOT, "cross", "true foot point (ground truth)"), (HAND_PLACED, "line", "hand-placed trapezoid"),
          (EXACT, "line", "exact trapezoid"), (HORIZON, "line", "horizon"))


def _px(points: np.ndarray) -> np.ndarray:
    """(N, 2) float pixels (centres at integers) -> int32 fixed-point coordinates for cv2."""
    return np.round(np.asarray(points, dtype=np.float64) * (1 << _SHIFT)).astype(np.int32)


def annotate(scene: Scene, rgb: np.ndarray, agent_ids: np.ndarray, foot_xy: np.ndarray | None = None,
             camera: PinholeCamera | None = None) -> np.ndarray:
    """(H, W, 3) RGB frame -> annotated BGR copy: segmentation boxes (green), their foot points (red),
    the ground truth's foot points ``foot_xy`` (N, 2) m if given (blue crosses), hand-placed trapezoid
    (yellow), exact trapezoid (cyan, of the ``[camera]`` pose), horizon (magenta), with a legend of them in a strip
    below (with_legend). ``camera``: the frame's pose of a moving camera (default: the ``[camera]`` pose)."""
    img = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    cam = scene.camera if camera is None else camera
    a, b, c = cam.horizon
    if any(cam.distortion):  # a line of the undistorted image, curved by the lens
        u = np.linspace(-cam.width, 2.0 * cam.width, 300)
        curve = cam.distort(np.column_stack([u, -(c + a * u) / b]))
        cv2.polylines(img, [_px(curve[np.isfinite(curve).all(axis=1)])], False, HORIZON, 1, cv2.LINE_AA, _SHIFT)
    else:
        ends = np.array([[0.0, -(c + a * 0) / b], [cam.width - 1.0, -(c + a * (cam.width - 1)) / b]])
        cv2.line(img, *map(tuple, _px(ends)), HORIZON, 1, cv2.LINE_AA, _SHIFT)
    cv2.polylines(img, [_px(scene.trapezoid_exact_image)], True, EXACT, 1, cv2.LINE_AA, _SHIFT)
    cv2.polylines(img, [_px(scene.hand_placed_image)], True, HAND_PLACED, 1, cv2.LINE_AA, _SHIFT)
    batch = SegmentationDetector().detect(0, 0.0, rgb, agent_ids)
    for (x1, y1, x2, y2), (u, v) in zip(batch.xyxy, batch.foot):
        cv2.rectangle(img, tuple(_px([x1, y1])), tuple(_px([x2, y2])), BOX, 1, cv2.LINE_8, _SHIFT)
        cv2.circle(img, tuple(_px([u, v])), 3 << _SHIFT, FOOT, -1, cv2.LINE_AA, _SHIFT)
    if foot_xy is not None:
        for u, v in cam.project_ground(foot_xy):
            if np.isfinite(u + v):
                cv2.drawMarker(img, (round(u), round(v)), TRUE_FOOT, cv2.MARKER_CROSS, 7, 1)
    return with_legend(img)


def with_legend(img: np.ndarray) -> np.ndarray:
    """The BGR image with a strip below it naming what preview draws (LEGEND): each entry's mark and name,
    wrapped to the image's width."""
    font, scale, row = cv2.FONT_HERSHEY_SIMPLEX, 0.4, 16
    width = img.shape[1]
    places, x, y = [], 6, 0
    for color, mark, text in LEGEND:
        size = 26 + cv2.getTextSize(text, font, scale, 1)[0][0]
        if x > 6 and x + size > width:
            x, y = 6, y + row
        places.append((x, y))
        x += size + 14
    strip = np.full((y + row + 6, width, 3), 32, np.uint8)
    for (color, mark, text), (x, y) in zip(LEGEND, places):
        cy = y + row // 2 + 3
        if mark == "box":
            cv2.rectangle(strip, (x + 2, cy - 5), (x + 14, cy + 5), color, 1)
        elif mark == "dot":
            cv2.circle(strip, (x + 8, cy), 3, color, -1)
        elif mark == "cross":
            cv2.drawMarker(strip, (x + 8, cy), color, cv2.MARKER_CROSS, 7, 1)
        else:
            cv2.line(strip, (x, cy), (x + 16, cy), color, 2)
        cv2.putText(strip, text, (x + 22, cy + 4), font, scale, (235, 235, 235), 1, cv2.LINE_AA)
    return np.vstack([img, strip])


def is_preview(path: Path) -> bool:
    """Whether ``path`` is a PNG written by preview (its Software text)."""
    try:
        with Image.open(path) as image:
            return image.format == "PNG" and image.text.get("Software") == SOFTWARE
    except (OSError, ValueError):
        return False


def preview(scene: Scene, seed: int, t: float, path: str | Path) -> int:
    """Render the scene at time t (seconds) with ``seed``, write the annotated frame to ``path`` as a PNG
    (atomically; an existing ``path`` is replaced only if preview wrote it, homocal.files.check_output_file)
    and return the number of agents in view."""
    check_output_file(path, is_preview, "PNG written by simgen preview")
    with Stage(scene, seed, t_end=t + 1.0) as stage:
        state = stage.set_time(t)
        agent_ids = stage.agent_ids()
        img = annotate(scene, stage.rgb(), agent_ids, state.xy, stage.camera)
    info = PngInfo()
    info.add_text("Software", SOFTWARE)
    write_atomic(path, lambda tmp: Image.fromarray(img[..., ::-1]).save(tmp, format="PNG", pnginfo=info))
    return len(np.unique(agent_ids[agent_ids >= 0]))
