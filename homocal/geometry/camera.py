"""The camera of the paper (Section 5.1), and a real one: the one home of the camera model.

Frames (see data_schema.md):
  world  metres; x right, y forward (the ground projection of the optical axis at yaw 0: the scene's forward),
         z up; origin on the ground directly under the camera, so range = ||(x, y)||.
  camera OpenCV: x right, y down, z forward; ``X_cam = R @ X_world + t``.
  image  pixels; u right, v down; the centre of the top-left pixel is (0, 0).

Pose: from the level camera looking along +y, turned by yaw about the world's vertical (right-handed about +z:
yaw > 0 turns the view towards -x, to the left), then tilted down by tilt about its own x axis, then rolled by roll
about its own optical axis (right-handed about the camera's z: roll > 0 lowers the camera's right side, so the
scene turns counter-clockwise in the image). Lens: OpenCV's distortion (k1, k2, p1, p2, k3) applied to the
pinhole image of K (``homocal.geometry.lens.Lens``); the ground homographies and the horizon are those of that
undistorted pinhole image, and ``project`` gives the distorted pixels the camera records.

The same numbers feed the MuJoCo camera (simgen), the exported ``camera.json``, the exact
trapezoids and the render tests.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from homocal.geometry.lens import Lens


@dataclass(frozen=True)
class PinholeCamera:
    """A camera at (0, 0, mount_height_m): yawed, tilted down, rolled (in that order), with a lens.

    Args:
        width, height: image size in pixels.
        hfov_deg: horizontal field of view in degrees (of the undistorted pinhole image).
        mount_height_m: height of the optical centre above the ground, metres.
        tilt_deg: downward pitch of the optical axis below the horizontal, degrees.
        roll_deg: turn about the optical axis, degrees in (-90, 90); > 0 lowers the camera's right side.
        yaw_deg: turn about the vertical, degrees in (-180, 180]; > 0 turns the view from +y towards -x.
        distortion: (k1, k2, p1, p2, k3), OpenCV's order and meaning on normalised coordinates; zeros: none.
    """

    width: int = 1280
    height: int = 720
    hfov_deg: float = 95.0
    mount_height_m: float = 4.0
    tilt_deg: float = 15.0
    roll_deg: float = 0.0
    yaw_deg: float = 0.0
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        d = tuple(self.distortion)
        if len(d) != 5 or not all(isinstance(k, (int, float)) and not isinstance(k, bool) and math.isfinite(k) for k in d):
            raise ValueError(f"camera: distortion must be 5 finite numbers (k1, k2, p1, p2, k3), got {list(d)!r}")
        object.__setattr__(self, "distortion", tuple(float(k) for k in d))
        if not -90.0 < self.roll_deg < 90.0:
            raise ValueError(f"camera: roll_deg must be in (-90, 90), got {self.roll_deg}")
        if not -180.0 < self.yaw_deg <= 180.0:
            raise ValueError(f"camera: yaw_deg must be in (-180, 180], got {self.yaw_deg}")
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
        """(3, 3) world-to-camera rotation (OpenCV); rows are the camera x (right), y (down), z (forward) in world
        coordinates: R = Rz(roll)^T R_tilt Rz(yaw)^T, Rz(a) the right-handed turn by a about z (the module's order)."""
        s, c = math.sin(math.radians(self.tilt_deg)), math.cos(math.radians(self.tilt_deg))
        right = [1.0, 0.0, 0.0]
        forward = [0.0, c, -s]
        down = [0.0, -s, -c]  # forward x right
        R = np.array([right, down, forward])
        if self.yaw_deg:
            R = R @ _turn_z(self.yaw_deg).T
        if self.roll_deg:
            R = _turn_z(self.roll_deg).T @ R
        return R

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
        """(3, 3) homography from world ground (x, y, 1) in metres to undistorted image pixels: K [r1 r2 t]."""
        R = self.R
        H = self.K @ np.column_stack([R[:, 0], R[:, 1], self.t])
        return H / np.linalg.norm(H)

    @property
    def image_to_ground(self) -> np.ndarray:
        """(3, 3) homography from undistorted image pixels (u, v, 1) to world ground metres; inverse of ground_to_image."""
        H = np.linalg.inv(self.ground_to_image)
        return H / np.linalg.norm(H)

    @property
    def horizon(self) -> np.ndarray:
        """(3,) line (a, b, c) of the undistorted image, a u + b v + c = 0, unit (a, b): where the ground's points at
        infinity project.

        It is the vanishing line of the ground plane, l = K^-T R e_z; for a level camera row v = cy - f tan(tilt).
        """
        line = np.linalg.inv(self.K).T @ self.R @ np.array([0.0, 0.0, 1.0])
        line = line / np.hypot(line[0], line[1])
        return line if line[1] > 0 else -line  # positive below the horizon (on the ground side)

    @property
    def horizon_row(self) -> float:
        """Image row v of the horizon (undistorted image) when it is a horizontal line: roll 0 (any yaw).
        ValueError with a roll (the horizon is then a slanted line: ``horizon``)."""
        if self.roll_deg:
            raise ValueError(f"camera: horizon_row: the horizon is not a row with roll_deg = {self.roll_deg}; use horizon")
        a, b, c = self.horizon
        return float(-c / b)

    @property
    def lens(self) -> Lens:
        """The lens: K, distortion and image size (``homocal.geometry.lens.Lens``)."""
        return Lens(self.K, np.array(self.distortion), (self.width, self.height))

    def project(self, points_world: np.ndarray) -> np.ndarray:
        """Project world points (N, 3) metres to the camera's pixels (N, 2), distorted by the lens; NaN for points
        behind the camera and for rays beyond the lens's fold (radius >= ``Lens.max_monotonic_radius``, where
        OpenCV's polynomial turns back and no real lens images them)."""
        P = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        cam = P @ self.R.T + self.t
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (cam @ self.K.T)[:, :2] / cam[:, 2:3]
        uv[cam[:, 2] <= 0] = np.nan
        return self.distort(uv)

    def distort(self, pixels: np.ndarray) -> np.ndarray:
        """Undistorted pixels (N, 2) (the pinhole image of K) -> the camera's pixels (N, 2) through the lens; NaN
        beyond the lens's fold (normalised radius >= ``Lens.max_monotonic_radius``). Without distortion: the input."""
        if not any(self.distortion):
            return pixels
        lens = self.lens
        uv = np.array(pixels, dtype=np.float64).reshape(-1, 2)
        with np.errstate(invalid="ignore"):
            uv[np.hypot(*((uv - self.K[:2, 2]) / self.focal_px).T) >= lens.max_monotonic_radius] = np.nan
        return lens.distort_points(uv)

    def project_ground(self, points_xy: np.ndarray) -> np.ndarray:
        """Project ground points (N, 2) metres (z = 0) to the camera's pixels (N, 2)."""
        xy = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        return self.project(np.column_stack([xy, np.zeros(len(xy))]))

    def ray_to_ground(self, pixels: np.ndarray) -> np.ndarray:
        """Back-project the camera's pixels (N, 2) (distorted, as ``project`` gives them) to the ground (N, 2)
        metres; at or above the horizon gives NaN."""
        uv = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        if any(self.distortion):
            uv = self.lens.undistort_points(uv)
        rays = np.column_stack([uv, np.ones(len(uv))]) @ np.linalg.inv(self.K).T @ self.R  # world directions
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -self.mount_height_m / rays[:, 2]
        xy = rays[:, :2] * s[:, None]
        xy[~(rays[:, 2] < 0)] = np.nan
        return xy

    def to_dict(self) -> dict:
        """The parameters, for configs and manifests."""
        return asdict(self)


def _turn_z(degrees: float) -> np.ndarray:
    """(3, 3) right-handed rotation by ``degrees`` about the z axis."""
    s, c = math.sin(math.radians(degrees)), math.cos(math.radians(degrees))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def tilt_homography(K: np.ndarray, delta: float) -> np.ndarray:
    """(3, 3) image homography G = K R_x(delta) K^-1: every viewing ray turned by delta radians about the camera's
    x-axis (OpenCV camera frame, y down), as tilting the camera down by delta more (tilt_deg + delta) moves the
    image: a point at elevation alpha above the optical axis (row cy - f tan(alpha)) goes to elevation
    alpha + delta, the horizon too (delta > 0: up). G maps the principal column onto itself. K (3, 3) intrinsics, fx = fy."""
    c, s = math.cos(delta), math.sin(delta)
    return K @ np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]) @ np.linalg.inv(K)
