"""The one codec of camera files: a dataset's camera.json, a lens.json and the page's camera_intrinsics.json,
read into one typed, validated ``CameraModel`` (data_schema.md "## camera.json" and "## lens.json").

simgen writes camera.json through ``camera_json_dict``; homocal reads every camera file through ``read_camera``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from homocal.files import read_json
from homocal.geometry.camera import PinholeCamera
from homocal.geometry.lens import Lens, check_image_size, float_array

UNIT_LINE_TOL = 1e-9  # a horizon line (a, b, c) has hypot(a, b) = 1 within this (float64 rounding is ~1e-16)

MAX_CAMERA_BYTES = 1 << 20  # a camera file's size (camera.json is about 2 KB)
NO_DISTORTION = (0.0, 0.0, 0.0, 0.0, 0.0)
ARRAYS = {"K": (3, 3), "distortion": (5,), "R": (3, 3), "t": (3,), "horizon": (3,), "camera_origin": (2,)}  # field: shape
NUMBERS = {"mount_height_m": "mount_height_m", "horizon_row_px": "horizon_row"}  # field: the file's key


@dataclass(frozen=True, eq=False)
class CameraModel:
    """A camera as homocal knows it: always the image size; the intrinsics, distortion and pose when the file
    gives them. Every array is float64 and read-only; None: the file does not say.

    Attributes:
        image_size: (width, height) px of the (distorted) frame.
        K: (3, 3) intrinsics, px, or None (a camera_intrinsics.json of a fit whose focal length was clicked).
        distortion: (5,) OpenCV's (k1, k2, p1, p2, k3); zeros when absent (the ideal pinhole).
        R: (3, 3) world-to-camera rotation; t: (3,) translation, metres (X_cam = R X_world + t).
        horizon: (3,) image line (a, b, c) of the undistorted image, positive below the horizon.
        mount_height_m: optical centre above the ground, metres. camera_origin: (2,) ground point under it, metres.
        horizon_row_px: the file's horizon_row (v of a level horizon in the undistorted image), or None.
    """

    image_size: tuple[int, int]
    K: np.ndarray | None = None
    distortion: np.ndarray = NO_DISTORTION
    R: np.ndarray | None = None
    t: np.ndarray | None = None
    horizon: np.ndarray | None = None
    mount_height_m: float | None = None
    camera_origin: np.ndarray | None = None
    horizon_row_px: float | None = None

    def __post_init__(self) -> None:
        for key, shape in ARRAYS.items():
            if getattr(self, key) is not None:
                object.__setattr__(self, key, float_array(getattr(self, key), shape, key))
        object.__setattr__(self, "image_size", check_image_size(self.image_size))
        if self.K is not None:
            Lens(self.K, self.distortion, self.image_size)  # K's own checks
        elif self.distortion.any():
            raise ValueError("distortion: needs K (the coefficients act on K's normalised coordinates)")
        if self.R is not None and (not np.allclose(self.R @ self.R.T, np.eye(3), atol=1e-9) or np.linalg.det(self.R) < 0):
            raise ValueError(f"R: not a rotation (orthonormal, det +1): {self.R.tolist()}")
        if self.horizon is not None and not math.isclose(math.hypot(*self.horizon[:2]), 1.0, abs_tol=UNIT_LINE_TOL):
            raise ValueError(f"horizon: hypot(a, b) must be 1, got {self.horizon.tolist()}")
        for key in NUMBERS:
            value = getattr(self, key)
            if value is not None:
                if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)):
                    raise ValueError(f"{key}: expected a finite number, got {value!r}")
                object.__setattr__(self, key, float(value))
        if self.mount_height_m is not None and not self.mount_height_m > 0:
            raise ValueError(f"mount_height_m: must be > 0 m, got {self.mount_height_m!r}")

    @property
    def lens(self) -> Lens | None:
        """The Lens (K, distortion, image size), or None without K."""
        return None if self.K is None else Lens(self.K, self.distortion, self.image_size)

    @property
    def horizon_row(self) -> float:
        """v of the horizon in the undistorted image: the file's horizon_row, else where the horizon line crosses
        the principal column (the same row for a level camera). ValueError if the file gives neither."""
        if self.horizon_row_px is not None:
            return self.horizon_row_px
        if self.horizon is None or self.K is None:
            raise ValueError("horizon_row: the camera file gives no horizon_row, nor a horizon and K")
        a, b, c = self.horizon
        return float(-(a * self.K[0, 2] + c) / b)

    @classmethod
    def from_dict(cls, data: dict) -> CameraModel:
        """A camera.json, lens.json or camera_intrinsics.json object -> CameraModel; ValueError "key: problem".

        The image size is "image_size" [W, H] (lens.json) or "width" and "height" (camera.json); every other key
        is optional; keys the model does not hold (hfov_deg, the homographies, roll_deg, ...) are ignored."""
        if "image_size" in data:
            size = data["image_size"]
        elif "width" in data and "height" in data:
            size = (data["width"], data["height"])
        else:
            raise ValueError("image_size: missing (give image_size [W, H], or width and height)")
        if isinstance(size, list):
            size = tuple(size)
        arrays = {key: data.get(key) for key in ARRAYS} | {"distortion": data.get("distortion", NO_DISTORTION)}
        return cls(size, **arrays, **{field: data.get(key) for field, key in NUMBERS.items()})

    def to_dict(self) -> dict:
        """The keys the model holds, as plain lists: {"K", "distortion", "image_size"} (lens.json) and, when known,
        "R", "t", "horizon", "mount_height_m", "camera_origin", "horizon_row" (camera.json's names).
        ``from_dict`` reads it back."""
        out: dict = {} if self.K is None else {"K": self.K.tolist()}
        out |= {"distortion": self.distortion.tolist(), "image_size": list(self.image_size)}
        out |= {key: getattr(self, key).tolist() for key in ARRAYS if key not in out and getattr(self, key) is not None}
        return out | {key: getattr(self, field) for field, key in NUMBERS.items() if getattr(self, field) is not None}


def read_camera(path: str | Path) -> CameraModel:
    """Read a camera file (camera.json, lens.json, camera_intrinsics.json) of at most MAX_CAMERA_BYTES; refuse a
    lens whose distortion folds its frame. ValueError, one line naming the file and the key."""
    data = read_json(path, max_bytes=MAX_CAMERA_BYTES)
    try:
        camera = CameraModel.from_dict(data)
        if camera.lens is not None:
            camera.lens.check_folds()
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    return camera


def camera_json_dict(camera: PinholeCamera, camera_origin: tuple[float, float] = (0.0, 0.0)) -> dict:
    """camera.json's object for a simgen camera (data_schema.md "## camera.json"; ``read_camera`` reads it).

    The ideal pinhole (no distortion, roll or yaw) gives exactly the keys and values of datasets before the lens;
    a camera with any of them adds "distortion", "roll_deg" and "yaw_deg", and drops "horizon_row" under a roll
    (the horizon is then a slanted line: "horizon"). The homographies and the horizon are those of the undistorted
    image."""
    lists = lambda a: np.asarray(a, dtype=float).tolist()  # noqa: E731
    roll, yaw, distortion = camera.roll_deg, camera.yaw_deg, tuple(camera.distortion)
    out = {
        "K": lists(camera.K), "R": lists(camera.R), "t": lists(camera.t), "width": camera.width, "height": camera.height,
        "hfov_deg": camera.hfov_deg, "vfov_deg": camera.vfov_deg, "mount_height_m": camera.mount_height_m,
        "tilt_deg": camera.tilt_deg, "image_to_ground": lists(camera.image_to_ground),
        "ground_to_image": lists(camera.ground_to_image), "horizon": lists(camera.horizon),
        **({} if roll else {"horizon_row": camera.horizon_row}), "camera_origin": [float(x) for x in camera_origin],
    }  # fmt: skip
    if roll or yaw or any(distortion):
        out |= {"distortion": lists(distortion), "roll_deg": roll, "yaw_deg": yaw}
    return out
