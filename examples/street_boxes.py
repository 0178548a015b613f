"""Write examples/street/boxes.csv: three people walking 8 s in front of the street camera (homocal's
PinholeCamera(): 1280x720, 4 m high, 15 degrees down; examples/street/trapezoid.json is a clicked trapezoid of
it), their boxes as a tracker gives them at 10 fps (frame, track_id, x1, y1, x2, y2; pixel corners at integers,
as supervision's Detections.xyxy), 1 px of seeded noise on each edge. The second person stands still for 3 s.

    python examples/street_boxes.py
"""
from pathlib import Path

import numpy as np

from homocal.geometry import PinholeCamera

FPS, SECONDS, HEIGHT_M = 10, 8.0, 1.7


def positions(t: np.ndarray) -> list[np.ndarray]:
    """Each person's ground point (len(t), 2), metres, at times t (s)."""
    stop = np.clip(t, 0, 3) + np.clip(t - 6, 0, None)  # walks 0-3 s, stands 3-6 s, walks on
    return [np.column_stack([-4 + 0.3 * t, 8 + 1.3 * t]),
            np.column_stack([5 - 0.9 * stop, 30 - 0.6 * stop]),
            np.column_stack([1.5 + 0 * t, 45 - 1.4 * t])]


def main() -> None:
    camera, rng = PinholeCamera(), np.random.default_rng(0)
    frames = np.arange(int(SECONDS * FPS))
    lines = ["frame,track_id,x1,y1,x2,y2"]
    for k, xy in enumerate(positions(frames / FPS)):
        foot = camera.project(np.column_stack([xy, np.zeros(len(xy))]))
        head = camera.project(np.column_stack([xy, np.full(len(xy), HEIGHT_M)]))
        half = 0.2 * (foot[:, 1] - head[:, 1])  # a person is about 0.4 of their height wide
        boxes = np.column_stack([foot[:, 0] - half, head[:, 1], foot[:, 0] + half, foot[:, 1]]) + 0.5  # homocal -> corners
        boxes += rng.normal(0, 1, boxes.shape)
        lines += [f"{f},{k}," + ",".join(f"{v:.1f}" for v in b) for f, b in zip(frames, boxes)]
    (Path(__file__).parent / "street" / "boxes.csv").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
