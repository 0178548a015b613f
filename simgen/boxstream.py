"""Render-free people's boxes of a scene seen by a camera that moves (``box_stream``): for long streams
(hours) where rendering would take days.

The people are simgen's walkers (simgen.agents.Crowd: the same routes, speeds, waits, heights and poses as a
rendered dataset of the same scene and seed). Each frame, every body's geoms (capsules: segment ends and
radii) are projected by the camera of that moment, a PinholeCamera whose tilt is the scene's plus
``tilt_deg(t)``: a person's box is the bounding box of its geoms' ends moved by +-radius along x and z
(world), in homocal's pixel edges snapped to whole pixels (edges at half-integers, as a segmentation mask's
box), clipped to the image; a box wholly outside the image is not given. Not modelled: occlusion between
people and by props, detector noise and misses: a best case of the segmentation detector.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator

import numpy as np

from simgen.agents import Crowd
from simgen.scene import Scene


def box_stream(scene: Scene, seed: int, seconds: float, fps: float,
               tilt_deg: Callable[[float], float] = lambda t: 0.0) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Yield (frame, xyxy (N, 4) homocal pixel edges, agent ids (N,)) for frames 0 .. seconds * fps - 1 of the
    scene's walkers (seed as ``simgen generate --seed``), seen by the scene's camera tilted tilt_deg(t) degrees
    further down at time t = frame / fps."""
    crowd = Crowd(scene, seed, seconds)
    base = scene.camera
    w, h = base.width, base.height
    for frame in range(int(round(seconds * fps))):
        t = frame / fps
        camera = dataclasses.replace(base, tilt_deg=base.tilt_deg + tilt_deg(t))
        state = crowd.state(t)
        if len(state.agent_id) == 0:
            yield frame, np.zeros((0, 4)), np.zeros(0, np.int64)
            continue
        ends, radii = state.segments, state.radii[:, :, None, None]  # (A, G, 2, 3), (A, G, 1, 1)
        points = [ends + radii * np.array(d) for d in ((1, 0, 1), (-1, 0, 1), (1, 0, -1), (-1, 0, -1))]
        uv = camera.project(np.stack(points, axis=2).reshape(-1, 3)).reshape(len(ends), -1, 2)
        lo, hi = np.fmin.reduce(uv, axis=1), np.fmax.reduce(uv, axis=1)  # NaN: wholly behind the camera
        xyxy = np.column_stack([np.floor(lo + 0.5) - 0.5, np.ceil(hi - 0.5) + 0.5])
        xyxy = np.clip(xyxy, -0.5, [w - 0.5, h - 0.5, w - 0.5, h - 0.5])
        with np.errstate(invalid="ignore"):
            seen = (xyxy[:, 2] > xyxy[:, 0]) & (xyxy[:, 3] > xyxy[:, 1])
        yield frame, xyxy[seen], state.agent_id[seen].astype(np.int64)
