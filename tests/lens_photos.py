"""A known lens (a wide CCTV lens on a 640x360 frame) and checkerboard photographs seen through it, for the tests
of homocal lens and of the page's checkerboard. Images go through OpenCV (cv2.undistortPoints with tight
criteria), never through the Lens under test."""
from __future__ import annotations

import functools

import cv2
import numpy as np

from homocal.lens.lines import intrinsics

SIZE = (640, 360)
K = intrinsics(SIZE, 95.0)  # f = 293.2 px
TRUE = np.array([-0.2, 0.04, 0.0, 0.0, 0.0])  # a wide CCTV lens (docs/real-camera.md)
EXACT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)


def undistort_cv(pixels: np.ndarray, dist=TRUE, k=K) -> np.ndarray:
    return cv2.undistortPoints(pixels.reshape(-1, 1, 2), k, dist, P=k, criteria=EXACT).reshape(-1, 2)


@functools.cache
def undistorted_frame() -> np.ndarray:
    """(H W, 2) every frame pixel, row by row, undistorted (cv2): the pinhole pixel it sees."""
    u, v = np.meshgrid(np.arange(SIZE[0], dtype=np.float64), np.arange(SIZE[1], dtype=np.float64))
    return undistort_cv(np.column_stack([u.ravel(), v.ravel()]))


def render_board(pose: tuple[np.ndarray, np.ndarray], pattern=(9, 6), square_px=40) -> np.ndarray:
    """A SIZE frame of a (cols + 1) x (rows + 1) board of 1-unit squares at world pose (rvec, tvec), seen through
    TRUE: each frame pixel undistorted (cv2), its ray met with the board's plane, the board image sampled there."""
    cols, rows = pattern
    board = np.kron((np.indices((rows + 1, cols + 1)).sum(axis=0) % 2) * 255, np.ones((square_px, square_px)))
    board = cv2.copyMakeBorder(board.astype(np.uint8), square_px, square_px, square_px, square_px, cv2.BORDER_CONSTANT, value=255)
    R, _ = cv2.Rodrigues(pose[0])
    rays = (np.column_stack([undistorted_frame(), np.ones(SIZE[0] * SIZE[1])]) - [*K[:2, 2], 0]) / [*K[[0, 1], [0, 1]], 1]
    rays = rays @ R  # in board coordinates, from the camera centre
    centre = -R.T @ pose[1]
    s = -centre[2] / rays[:, 2]
    xy = (centre[:2] + s[:, None] * rays[:, :2] + 1.0) * square_px - 0.5  # board units -> board image pixels
    xy[s <= 0] = -1e4
    maps = xy.reshape(SIZE[1], SIZE[0], 2).astype(np.float32)
    return cv2.remap(board, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR, borderValue=128)


POSES = [(np.array(r, float), np.array(t, float)) for r, t in (
    ([0.0, 0.0, 0.0], [-4.0, -2.5, 7.0]), ([0.4, 0.0, 0.0], [-4.0, -3.0, 7.5]), ([0.0, 0.45, 0.0], [-2.0, -3.0, 9.0]),
    ([-0.3, -0.3, 0.1], [-3.5, -3.0, 7.0]), ([0.2, -0.4, -0.1], [-4.5, -2.5, 8.0]), ([0.0, 0.0, 0.3], [-3.0, -4.0, 7.0]),
    ([0.0, 0.0, 0.0], [-1.0, -5.5, 7.5]), ([0.3, -0.2, 0.0], [-0.5, -1.0, 7.0]), ([0.0, 0.0, 0.0], [-8.5, -5.5, 7.5]))]
