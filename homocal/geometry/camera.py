"""The ideal pinhole camera of the paper (Section 5.1): the one home of the camera model.

Frames (see data_schema.md):
  world  metres; x right, y forward (ground projection of the optical axis), z up;
         origin on the ground directly under the camera, so range = ||(x, y)||.
  camera OpenCV: x right, y down, z forward; ``X_cam = R @ X_world + t``.
  image  pixels; u right, v down; the centre of the top-left pixel is (0, 0).

The same numbers feed the MuJoCo camera (simgen), the exported ``camera.json``, the exact
trapezoids and the render tests.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class PinholeCamera:
    """A distortion-free pinhole camera at (0, 0, mount_height_m), yaw 0, tilted down.

    Args:
        width, height: image size in pixels.
        hfov_deg: horizontal field of view in degrees.
        mount_height_m: height of the optical centre above the ground, metres.
        tilt_deg: downward pitch of the optical axis below the horizontal, degrees.
    """

    width: int = 1280
    height: int = 720
    hfov_deg: float = 95.0
    mount_height_m: float = 4.0
    tilt_deg: float = 15.0

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"camera: width and height must be positive, got {self.width}x{self.height}")
        if not 0.0 < self.hfov_deg < 180.0:
            raise ValueError(f"camera: hfov_deg must be in (0, 180), got {self.hfov_deg}")
        if not 0.0 < self.mount_height_m <= 1e4:  # 10 km: above any mast, below where the maths overflows
            raise ValueError(f"camera: mount_height_m must be in (0, 10000] m, got {self.mount_height_m}")
        if not 0.0 < self.tilt_deg + self.vfov_deg / 2.0:
            raise ValueError(
                f"camera: tilt_deg={self.tilt_deg} with vertical fov {self.vfov_deg:.2f} deg sees no ground"
            )
        if not -90.0 < self.tilt_deg < 90.0:
            raise ValueError(f"camera: tilt_deg must be in (-90, 90), got {self.tilt_deg}")

    # ---- intrinsics -------------------------------------------------------------------
    @property
    def focal_px(self) -> float:
        """fx = fy = (W / 2) / tan(hfov / 2), pixels."""
        return (self.width / 2.0) / math.tan(math.radians(self.hfov_deg) / 2.0)

    @property
    def vfov_deg(self) -> float:
        """Vertical field of view (MuJoCo's ``fovy``): 2 atan(tan(hfov / 2) H / W), degrees."""
        return math.degrees(2.0 * math.atan(math.tan(math.radians(self.hfov_deg) / 2.0) * self.height / self.width))

    @property
    def K(self) -> np.ndarray:
        """(3, 3) intrinsics; principal point at (W/2 - 0.5, H/2 - 0.5) (pixel centres at integers)."""
        f = self.focal_px
        return np.array([[f, 0.0, self.width / 2.0 - 0.5], [0.0, f, self.height / 2.0 - 0.5], [0.0, 0.0, 1.0]])

    # ---- extrinsics -------------------------------------------------------------------
    @property
    def position(self) -> np.ndarray:
        """(3,) optical centre in world metres."""
        return np.array([0.0, 0.0, self.mount_height_m])

    @property
    def R(self) -> np.ndarray:
        """(3, 3) world-to-camera rotation (OpenCV); rows are the camera x (right), y (down), z (forward)."""
        s, c = math.sin(math.radians(self.tilt_deg)), math.cos(math.radians(self.tilt_deg))
        right = [1.0, 0.0, 0.0]
        forward = [0.0, c, -s]
        down = [0.0, -s, -c]  # forward x right
        return np.array([right, down, forward])

    @property
    def t(self) -> np.ndarray:
        """(3,) translation: t = -R @ position."""
        return -self.R @ self.position

    @property
    def mujoco_xyaxes(self) -> tuple[float, ...]:
        """MuJoCo camera ``xyaxes``: its x (right) and y (up = -down) axes in world coordinates."""
        R = self.R
        return tuple(float(x) for x in np.concatenate([R[0], -R[1]]))

    # ---- ground plane -----------------------------------------------------------------
    @property
    def ground_to_image(self) -> np.ndarray:
        """(3, 3) homography from world ground (x, y, 1) in metres to image pixels: K [r1 r2 t]."""
        R = self.R
        H = self.K @ np.column_stack([R[:, 0], R[:, 1], self.t])
        return H / np.linalg.norm(H)

    @property
    def image_to_ground(self) -> np.ndarray:
        """(3, 3) homography from image pixels (u, v, 1) to world ground metres; inverse of ground_to_image."""
        H = np.linalg.inv(self.ground_to_image)
        return H / np.linalg.norm(H)

    @property
    def horizon(self) -> np.ndarray:
        """(3,) image line (a, b, c), a u + b v + c = 0, unit (a, b): where the ground's points at infinity project.

        It is the vanishing line of the ground plane, l = K^-T R e_z; for a level camera row v = cy - f tan(tilt).
        """
        line = np.linalg.inv(self.K).T @ self.R @ np.array([0.0, 0.0, 1.0])
        line = line / np.hypot(line[0], line[1])
        return line if line[1] > 0 else -line  # positive below the horizon (on the ground side)

    @property
    def horizon_row(self) -> float:
        """Image row v of the horizon (yaw 0, no roll: the horizon is a horizontal line)."""
        a, b, c = self.horizon
        return float(-c / b)

    def project(self, points_world: np.ndarray) -> np.ndarray:
        """Project world points (N, 3) metres to pixels (N, 2); points behind the camera give NaN."""
        P = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        cam = P @ self.R.T + self.t
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (cam @ self.K.T)[:, :2] / cam[:, 2:3]
        uv[cam[:, 2] <= 0] = np.nan
        return uv

    def project_ground(self, points_xy: np.ndarray) -> np.ndarray:
        """Project ground points (N, 2) metres (z = 0) to pixels (N, 2)."""
        xy = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        return self.project(np.column_stack([xy, np.zeros(len(xy))]))

    def ray_to_ground(self, pixels: np.ndarray) -> np.ndarray:
        """Back-project pixels (N, 2) to the ground (N, 2) metres; at or above the horizon gives NaN."""
        uv = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        rays = np.column_stack([uv, np.ones(len(uv))]) @ np.linalg.inv(self.K).T @ self.R  # world directions
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -self.mount_height_m / rays[:, 2]
        xy = rays[:, :2] * s[:, None]
        xy[~(rays[:, 2] < 0)] = np.nan
        return xy

    def to_dict(self) -> dict:
        """The parameters, for configs and manifests."""
        return asdict(self)


def tilt_homography(K: np.ndarray, delta: float) -> np.ndarray:
    """(3, 3) image homography G = K R_x(delta) K^-1: every viewing ray turned by delta radians about the camera's
    x-axis (OpenCV camera frame, y down), as tilting the camera down by delta more (tilt_deg + delta) moves the
    image: a point at elevation alpha above the optical axis (row cy - f tan(alpha)) goes to elevation
    alpha + delta, the horizon too (delta > 0: up). G maps the principal column onto itself. K (3, 3) intrinsics, fx = fy."""
    c, s = math.cos(delta), math.sin(delta)
    return K @ np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]) @ np.linalg.inv(K)
