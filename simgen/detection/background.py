"""Detector (b): sees only the RGB frames; OpenCV MOG2 background subtraction -> blobs -> boxes.

Pipeline per frame: downscale by `downscale` (cv2.INTER_AREA), MOG2 foreground (no shadow
detection), a 3x3 morphological closing, 8-connected components; components of at least
`min_area` full-resolution pixels become boxes, rescaled to full resolution. A pixel centre x_s
of the small image is x = (x_s + 0.5) * W / w_s - 0.5 in the full one, so a component spanning
small columns l..l+w-1 gets x1 = l * W / w_s - 0.5 and x2 = (l + w) * W / w_s - 0.5.
Only then are the boxes, in ``canonical_order``, associated with agents: IoU with the agents' mask boxes (from the
agent-id map), greedy one-to-one, IoU >= min_iou, else agent_id -1. Score: the fraction of the
box the component fills.

State and resume: MOG2 is deterministic and its state depends only on the frames fed to it.
The model is restarted at every frame that is a multiple of `reset_every`, and first re-fed the
`warmup` frames before it. So the state at frame f depends only on frames
max(0, b - warmup) .. f with b = f - f % reset_every. To resume a run at frame r, feed frames
`resume_start(r)` .. r - 1 to a fresh detector with `feed` (rgb only), then call `detect` from r:
its output is then identical to an uninterrupted run's. At most reset_every + warmup - 1 frames
are re-fed; none beyond `warmup` if runs resume at multiples of reset_every.
Caveat: like any background subtraction it misses agents that stand still (they become background).
"""
from __future__ import annotations

from collections import deque

import cv2
import numpy as np

from simgen.detection.association import associate
from simgen.detection.batch import DetectionBatch, canonical_order
from simgen.detection.masks import id_boxes

_CLOSE_KERNEL = np.ones((3, 3), np.uint8)


class BackgroundSubtractionDetector:
    """Background subtraction (MOG2) on RGB frames; frames must be fed in order, without gaps.

    Args:
        downscale: integer factor the frame is shrunk by before MOG2 (2: 1280x720 -> 640x360).
        history, var_threshold: MOG2's history (frames) and squared Mahalanobis threshold.
        min_area: smallest blob kept, in full-resolution pixels.
        min_iou: smallest box IoU for associating a blob with an agent's mask box.
        reset_every, warmup: model restart period and re-fed frames, in frames (module docstring).
    """

    name = "rgb"

    def __init__(
        self,
        downscale: int = 2,
        history: int = 500,
        var_threshold: float = 16.0,
        min_area: int = 40,
        min_iou: float = 0.3,
        reset_every: int = 600,
        warmup: int = 60,
    ) -> None:
        if downscale < 1 or reset_every < 1 or warmup < 0:
            raise ValueError(
                f"BackgroundSubtractionDetector: need downscale >= 1, reset_every >= 1, warmup >= 0; "
                f"got {downscale}, {reset_every}, {warmup}"
            )
        self.downscale, self.history, self.var_threshold = downscale, history, var_threshold
        self.min_area, self.min_iou = min_area, min_iou
        self.reset_every, self.warmup = reset_every, warmup
        self._recent: deque[np.ndarray] = deque(maxlen=warmup)
        self._model: cv2.BackgroundSubtractorMOG2 | None = None
        self._last_frame: int | None = None

    def resume_start(self, frame: int) -> int:
        """First frame to `feed` a fresh detector so that `detect(frame, ...)` matches an uninterrupted run."""
        return max(0, frame - frame % self.reset_every - self.warmup)

    def feed(self, frame: int, rgb: np.ndarray) -> np.ndarray | None:
        """Update the model with frame `frame`; rgb: (H, W, 3) uint8 -> (H // downscale, W // downscale) uint8
        foreground (255) mask; all 0 on frame 0, which has no background yet; None while no restart frame
        has been fed (the frame is only remembered for the warm-up)."""
        if self._last_frame is not None and frame != self._last_frame + 1:
            raise ValueError(f"{self.name} detector: got frame {frame} after frame {self._last_frame}")
        self._last_frame = frame
        h, w = rgb.shape[:2]
        small = cv2.resize(rgb, (w // self.downscale, h // self.downscale), interpolation=cv2.INTER_AREA)
        restart = frame % self.reset_every == 0
        if restart:
            self._model = cv2.createBackgroundSubtractorMOG2(self.history, self.var_threshold, detectShadows=False)
            for old in self._recent:
                self._model.apply(old)
        has_background = not (restart and not self._recent)  # a model's first frame is all foreground
        self._recent.append(small)
        if self._model is None:
            return None
        foreground = self._model.apply(small)
        return foreground if has_background else np.zeros_like(foreground)

    def detect(self, frame: int, t: float, rgb: np.ndarray, agent_ids: np.ndarray) -> DetectionBatch:
        """rgb: (H, W, 3) uint8; agent_ids: (H, W) int32, -1 where no agent (used only to associate)."""
        if self._model is None and frame % self.reset_every != 0:
            raise ValueError(
                f"{self.name} detector: frame {frame} needs frames {self.resume_start(frame)}..{frame - 1} fed first"
            )
        foreground = cv2.morphologyEx(self.feed(frame, rgb), cv2.MORPH_CLOSE, _CLOSE_KERNEL)
        _, _, stats, _ = cv2.connectedComponentsWithStats(foreground, connectivity=8)
        sx = rgb.shape[1] / foreground.shape[1]
        sy = rgb.shape[0] / foreground.shape[0]
        stats = stats[1:].astype(np.float64)  # row 0 is the background
        left, top, width, height, area = stats[stats[:, cv2.CC_STAT_AREA] * sx * sy >= self.min_area].T
        xyxy = np.column_stack([left * sx, top * sy, (left + width) * sx, (top + height) * sy]) - 0.5
        xyxy, score = canonical_order(xyxy, area / (width * height))
        ids, mask_xyxy, _ = id_boxes(agent_ids)
        return DetectionBatch(self.name, frame, t, xyxy, score, associate(xyxy, ids, mask_xyxy, self.min_iou))
