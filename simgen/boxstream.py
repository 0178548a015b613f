"""Render-free people's boxes of a scene seen by a camera that moves (``box_stream``): for long streams
(hours) where rendering would take days.

The people are simgen's walkers (simgen.agents.Crowd: the same routes, speeds, waits, heights and poses as a
rendered dataset of the same scene and seed). Each frame, every body's geoms (capsules and the head's sphere:
segment ends and radii, ``bodies``) are seen by the scene's camera, posed at each instant as in a rendered dataset
(``Scene.camera_at``: its ``[[camera.moves]]`` and ``[camera.sway]``). Each geom's outline is the convex hull of its
end spheres' silhouettes (``simgen.truth.silhouette_outlines``, as gt.parquet's visible fraction), and it covers the
pixels whose centres lie inside it (``spans``: the rasteriser's rule). People hide people (``boxes_of``): where the
outlines of people whose boxes overlap cover the same pixel, the pixel is the nearest geom's (by the depth of each
geom's centre along the optical axis), as in the segmentation render. A person's box is the box of their pixels
(edges at half-integers, as a segmentation mask's box), within the image; a person wholly hidden or outside the
image gives no box. ``occlusion=False`` gives every person's box as if nobody stood in front.

What the renders have and these boxes do not: the scene's props (its houses, cars, poles) hiding people,
MuJoCo's faceted capsules (sub-pixel), and the detectors' noise and misses (the rgb detector's above all): a best
case of the segmentation detector. Against a render of the same scene and seed (tests/simgen/test_boxstream.py,
research/boxstream_check.py): 93-94 % of scene1's boxes identical to the pixel, 99.8 % within 2 px.
"""
from __future__ import annotations

from collections.abc import Iterator

import cv2
import numpy as np

from homocal.geometry import PinholeCamera
from simgen.agents import Crowd
from simgen.scene import Scene
from simgen.truth import silhouette_outlines


def bodies(scene: Scene, seed: int, seconds: float, fps: float) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """Yield (frame, segments (A, G, 2, 3) world geom segment ends m, radii (A, G) m, agent ids (A,)) for frames
    0 .. seconds * fps - 1 of the scene's walkers (seed as ``simgen generate --seed``), at t = frame / fps."""
    crowd = Crowd(scene, seed, seconds)
    for frame in range(round(seconds * fps)):
        state = crowd.state(frame / fps)
        yield frame, state.segments, state.radii, state.agent_id.astype(np.int64)


def spans(outlines: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pixels whose centres (integer px) lie in each convex hull of outlines (N, P, 2) px, within the image
    (size: width, height): the rasteriser's rule, as the segmentation render's (OpenCV's fill takes every pixel a
    polygon touches). Returns (S,) int arrays: the hull's index, the row, the first and last column of each span."""
    w, h = size
    orders = [cv2.convexHull(points, returnPoints=False)[:, 0] for points in outlines.astype(np.float32)]
    index = np.zeros((len(outlines), max(map(len, orders), default=1)), int)
    for k, order in enumerate(orders):
        index[k, :len(order)], index[k, len(order):] = order, order[0]  # padded with its first vertex: empty edges
    hulls = np.take_along_axis(outlines, index[:, :, None], axis=1)
    lo, hi = np.ceil(hulls[:, :, 1].min(axis=1)), np.floor(hulls[:, :, 1].max(axis=1))
    r0, r1 = np.maximum(lo, 0).astype(int), np.minimum(hi, h - 1).astype(int)
    count = np.maximum(r1 - r0 + 1, 0)
    which = np.repeat(np.arange(len(hulls)), count)
    row = r0[which] + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    p = hulls[which]  # (S, P, 2): each span's hull; edges p -> q
    q = np.roll(p, -1, axis=1)
    y = row[:, None].astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (y - p[:, :, 1]) / (q[:, :, 1] - p[:, :, 1])  # where each edge crosses the row
        x = np.where((s >= 0) & (s <= 1), p[:, :, 0] + s * (q[:, :, 0] - p[:, :, 0]), np.nan)
        first = np.maximum(np.ceil(np.fmin.reduce(x, axis=1)), 0)
        last = np.minimum(np.floor(np.fmax.reduce(x, axis=1)), w - 1)
        keep = first <= last  # NaN (a row only touched at a vertex) or no centre between: no pixel
    return which[keep], row[keep], first[keep].astype(int), last[keep].astype(int)


def boxes_of(camera: PinholeCamera, segments: np.ndarray, radii: np.ndarray, occlusion: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(xyxy (M, 4) homocal pixel edges, seen (A,) bool) of the people's geoms (segments (A, G, 2, 3) m, radii (A, G)
    m) seen by the camera: the boxes of those with a pixel in view (module docstring; a geom partly behind the
    camera is left out). Cost per frame: the pixel spans of every geom (at most the image's rows each), and a depth
    sort of the pixels of the people whose boxes overlap another's."""
    a_n, g_n = radii.shape
    outlines = silhouette_outlines(camera, segments, radii)  # (A, G, P, 2), NaN: not in front of the camera
    outlines = outlines.reshape(-1, *outlines.shape[2:])
    front = np.flatnonzero(np.isfinite(outlines).all(axis=(1, 2)))
    geom, row, first, last = spans(outlines[front], (camera.width, camera.height))
    person = front[geom] // g_n
    box = span_boxes(a_n, person, row, first, last)
    x1, y1, x2, y2 = box.T[:, :, None]  # each (A, 1)
    with np.errstate(invalid="ignore"):
        touch = (np.minimum(x2, x2.T) >= np.maximum(x1, x1.T)) & (np.minimum(y2, y2.T) >= np.maximum(y1, y1.T))
    crowded = touch.sum(axis=1) > 1  # (A,): their boxes share a pixel with another's: may hide or be hidden
    if occlusion and crowded.any():  # their pixels, each the nearest geom's person's
        pick = crowded[person]
        n = last[pick] - first[pick] + 1
        pixel = np.repeat(row[pick] * camera.width + first[pick] - np.cumsum(n) + n, n) + np.arange(n.sum())
        depth = (segments.mean(axis=2) @ camera.R.T + camera.t)[:, :, 2].ravel()[front[geom][pick]]  # m, optical axis
        order = np.lexsort((np.repeat(depth, n), pixel))
        pixel = pixel[order]
        top = np.r_[True, pixel[1:] != pixel[:-1]]
        r, c = np.divmod(pixel[top], camera.width)
        box[crowded] = span_boxes(a_n, np.repeat(person[pick], n)[order][top], r, c, c)[crowded]
    seen = np.isfinite(box[:, 0])
    return box[seen] + [-0.5, -0.5, 0.5, 0.5], seen


def span_boxes(count: int, person: np.ndarray, row: np.ndarray, first: np.ndarray, last: np.ndarray) -> np.ndarray:
    """(count, 4) float: each person's pixel box (first column, first row, last column, last row; inf where none)
    of the spans (S,) ints: person, row, first and last column."""
    box = np.full((count, 4), np.inf)
    box[:, 2:] = -np.inf
    for col, values, reduce in ((0, first, np.minimum), (1, row, np.minimum), (2, last, np.maximum), (3, row, np.maximum)):
        reduce.at(box[:, col], person, values)
    return box


def box_stream(scene: Scene, seed: int, seconds: float, fps: float, occlusion: bool = True) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Yield (frame, xyxy (N, 4) homocal pixel edges, agent ids (N,)) of the bodies seen by the scene's camera
    as posed at time t = frame / fps (``Scene.camera_at``; ``boxes_of``)."""
    for frame, segments, radii, ids in bodies(scene, seed, seconds, fps):
        xyxy, seen = boxes_of(scene.camera_at(frame / fps), segments, radii, occlusion)
        yield frame, xyxy, ids[seen]
