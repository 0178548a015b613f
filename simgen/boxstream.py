"""Render-free people's boxes of a scene seen by a camera that moves (``box_stream``): for long streams
(hours) where rendering would take days.

The people are simgen's walkers (simgen.agents.Crowd: the same routes, speeds, waits, heights and poses as a
rendered dataset of the same scene and seed). Each frame, every body's geoms (capsules and the head's sphere:
segment ends and radii, ``bodies``) are seen by the scene's camera, posed at each instant as in a rendered dataset
(``Scene.camera_at``: its ``[[camera.moves]]`` and ``[camera.sway]``). Each geom's outline is the convex hull of
its end spheres' silhouettes (``simgen.truth.silhouette_outlines``, as gt.parquet's visible fraction); ``boxes_of``
fills the geoms far to near (by the depth of each geom's centre) into a label image, so that a nearer person hides
a farther one as in the segmentation render, and a person's box is the box of the pixels left with their label
(edges at half-integers, as a segmentation mask's box), within the box of their whole outline; a person wholly
hidden or outside the image gives no box. ``occlusion=False`` gives each person's whole box (the box of the pixel
centres their outline covers, clipped to the image), as if nobody stood in front. Not modelled: occlusion by props
(cars, poles, the scene's static objects), the renderer's anti-aliased rim and sub-pixel limbs, and the
detectors' noise and misses: a best case of the segmentation detector.
"""
from __future__ import annotations

from collections.abc import Iterator

import cv2
import numpy as np

from homocal.geometry import PinholeCamera
from simgen.agents import Crowd
from simgen.scene import Scene
from simgen.truth import silhouette_outlines

SHIFT = 4  # cv2 fixed-point bits: outlines are filled at 1/16 px


def bodies(scene: Scene, seed: int, seconds: float, fps: float) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """Yield (frame, segments (A, G, 2, 3) world geom segment ends m, radii (A, G) m, agent ids (A,)) for frames
    0 .. seconds * fps - 1 of the scene's walkers (seed as ``simgen generate --seed``), at t = frame / fps."""
    crowd = Crowd(scene, seed, seconds)
    for frame in range(round(seconds * fps)):
        state = crowd.state(frame / fps)
        yield frame, state.segments, state.radii, state.agent_id.astype(np.int64)


def boxes_of(camera: PinholeCamera, segments: np.ndarray, radii: np.ndarray, occlusion: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(xyxy (M, 4) homocal pixel edges, seen (A,) bool) of the people's geoms (segments (A, G, 2, 3) m, radii (A, G)
    m) seen by the camera: the boxes of those with a pixel in view (module docstring). Cost per frame: one fill per
    geom and a scan of each person's box."""
    w, h = camera.width, camera.height
    outlines = silhouette_outlines(camera, segments, radii)  # (A, G, 48, 2), NaN: not in front of the camera
    flat = outlines.reshape(len(outlines), -1, 2)
    with np.errstate(invalid="ignore"):  # all-NaN: wholly behind the camera
        lo, hi = np.fmin.reduce(flat, axis=1), np.fmax.reduce(flat, axis=1)
    whole = np.clip(np.column_stack([np.ceil(lo) - 0.5, np.floor(hi) + 0.5]), -0.5, [w - 0.5, h - 0.5, w - 0.5, h - 0.5])
    with np.errstate(invalid="ignore"):
        seen = (whole[:, 2] > whole[:, 0]) & (whole[:, 3] > whole[:, 1])
    x1, y1, x2, y2 = whole.T[:, :, None]  # each (A, 1)
    with np.errstate(invalid="ignore"):
        overlap = (np.minimum(x2, x2.T) > np.maximum(x1, x1.T)) & (np.minimum(y2, y2.T) > np.maximum(y1, y1.T))
    crowded = seen & (overlap.sum(axis=1) > 1)  # another person's box overlaps theirs: they may hide each other
    if not occlusion or not crowded.any():
        return whole[seen], seen
    labels = np.zeros((h, w), np.int32)  # 0: nobody; person a: a + 1
    depth = (segments.mean(axis=2) @ camera.R.T + camera.t)[:, :, 2]  # (A, G) m along the optical axis
    for a, g in zip(*np.unravel_index(np.argsort(-depth, axis=None, kind="stable"), depth.shape)):
        if crowded[a] and np.isfinite(outlines[a, g]).all():
            hull = cv2.convexHull(np.round(outlines[a, g] * (1 << SHIFT)).astype(np.int32))
            cv2.fillConvexPoly(labels, hull, int(a) + 1, lineType=cv2.LINE_8, shift=SHIFT)
    for a in np.flatnonzero(crowded):
        c1, r1, c2, r2 = (whole[a] + 0.5).astype(int)  # the whole box's pixels: columns c1 .. c2 - 1
        mine = labels[r1:r2, c1:c2] == a + 1
        rows, cols = np.flatnonzero(mine.any(axis=1)), np.flatnonzero(mine.any(axis=0))
        if rows.size:
            whole[a] = (c1 + cols[0] - 0.5, r1 + rows[0] - 0.5, c1 + cols[-1] + 0.5, r1 + rows[-1] + 0.5)
        else:
            seen[a] = False
    return whole[seen], seen


def box_stream(scene: Scene, seed: int, seconds: float, fps: float, occlusion: bool = True) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Yield (frame, xyxy (N, 4) homocal pixel edges, agent ids (N,)) of the bodies seen by the scene's camera
    as posed at time t = frame / fps (``Scene.camera_at``; ``boxes_of``)."""
    for frame, segments, radii, ids in bodies(scene, seed, seconds, fps):
        xyxy, seen = boxes_of(scene.camera_at(frame / fps), segments, radii, occlusion)
        yield frame, xyxy, ids[seen]
