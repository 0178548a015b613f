"""Render-free people's boxes of a scene seen by a camera that moves (``box_stream``): for long streams
(hours) where rendering would take days.

The people are simgen's walkers (simgen.agents.Crowd: the same routes, speeds, waits, heights and poses as a
rendered dataset of the same scene and seed). Each frame, every body's geoms (capsules: segment ends and
radii) give the points ``body_points``: the segment ends moved by +-radius along x and z (world). The scene's
camera, posed at each instant as in a rendered dataset (``Scene.camera_at``: its ``[[camera.moves]]`` and
``[camera.sway]``), projects them (``boxes_of``): a person's box is the box of the pixels whose centres their
bounding box covers (edges at half-integers, as a segmentation mask's box), clipped to the image; a box wholly
outside the image is not given. Not modelled: occlusion between people and by props, detector noise and misses:
a best case of the segmentation detector.
"""
from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from homocal.geometry import PinholeCamera
from simgen.agents import Crowd
from simgen.scene import Scene

CORNERS = ((1, 0, 1), (-1, 0, 1), (1, 0, -1), (-1, 0, -1))  # a geom end's offsets, in radii, along world x, y, z


def body_points(scene: Scene, seed: int, seconds: float, fps: float) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Yield (frame, points (A, P, 3) metres, agent ids (A,)) for frames 0 .. seconds * fps - 1 of the scene's
    walkers (seed as ``simgen generate --seed``), at t = frame / fps."""
    crowd = Crowd(scene, seed, seconds)
    for frame in range(round(seconds * fps)):
        state = crowd.state(frame / fps)
        ends, radii = state.segments, state.radii[:, :, None, None]  # (A, G, 2, 3), (A, G, 1, 1)
        points = np.stack([ends + radii * np.array(d) for d in CORNERS], axis=2).reshape(len(ends), -1, 3)
        yield frame, points, state.agent_id.astype(np.int64)


def boxes_of(camera: PinholeCamera, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(xyxy (M, 4) homocal pixel edges, seen (A,) bool) of the people's points (A, P, 3) seen by the camera: the
    boxes of those at least partly in the image (module docstring)."""
    w, h = camera.width, camera.height
    uv = camera.project(points.reshape(-1, 3)).reshape(len(points), -1, 2)
    lo, hi = np.fmin.reduce(uv, axis=1), np.fmax.reduce(uv, axis=1)  # NaN: wholly behind the camera
    xyxy = np.clip(np.column_stack([np.ceil(lo) - 0.5, np.floor(hi) + 0.5]), -0.5, [w - 0.5, h - 0.5, w - 0.5, h - 0.5])
    with np.errstate(invalid="ignore"):
        seen = (xyxy[:, 2] > xyxy[:, 0]) & (xyxy[:, 3] > xyxy[:, 1])
    return xyxy[seen], seen


def box_stream(scene: Scene, seed: int, seconds: float, fps: float) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Yield (frame, xyxy (N, 4) homocal pixel edges, agent ids (N,)) of body_points seen by the scene's camera
    as posed at time t = frame / fps (``Scene.camera_at``)."""
    for frame, points, ids in body_points(scene, seed, seconds, fps):
        xyxy, seen = boxes_of(scene.camera_at(frame / fps), points)
        yield frame, xyxy, ids[seen]
