"""Offscreen rendering with MuJoCo's classic renderer: RGB and segmentation passes of the run camera.

The backend is ``MUJOCO_GL`` (simgen.backend: egl by default, osmesa supported). When it cannot work, a
``BackendError`` carries one line naming the Debian packages to install.
"""
from __future__ import annotations

import warnings

import numpy as np

from homocal.geometry.camera import PinholeCamera
from simgen.backend import BackendError, backend_message, mujoco
from simgen.lens_warp import lens_warp, render_view
from simgen.model import CAMERA

QUALITY = {  # preset -> (offscreen multisamples, shadow map px; 0: no shadows): ``[render] quality``, ``--quality``
    "draft": (0, 0),  # no anti-aliasing: edges stair-stepped; RGB in 0.29x default's time on llvmpipe (docs/measurements.md)
    "default": (4, 0),  # MuJoCo's 4 samples, shadows off
    "high": (8, 4096),  # 8 samples, every light of the scene casts shadows; RGB 2.2x default's time
}


def apply_quality(model: mujoco.MjModel, quality: str) -> None:
    """Set ``model``'s offscreen samples and shadows to the preset ``quality`` (before a Renderer is made)."""
    samples, shadow_size = QUALITY[quality]
    model.vis.quality.offsamples = samples
    model.vis.quality.shadowsize = shadow_size
    model.light_castshadow[:] = shadow_size > 0


class FrameRenderer:
    """The RGB and segmentation passes of the run camera (the model's, added by ``add_camera(spec, camera)``), in
    the camera's frame: with a lens, MuJoCo's wider pinhole render remapped through it (``simgen.lens_warp``);
    a context manager (closes the GL context)."""

    def __init__(self, model: mujoco.MjModel, camera: PinholeCamera) -> None:
        self._warp = lens_warp(camera)
        width, height, _ = render_view(camera)
        try:
            with warnings.catch_warnings():  # glfw warns (several lines) before failing without a DISPLAY
                warnings.simplefilter("ignore")
                self._r = mujoco.Renderer(model, height, width)
        except Exception as e:  # EGL without Mesa's DRI driver, no DISPLAY for glfw, ...
            raise BackendError(backend_message(e)) from e

    def update(self, data: mujoco.MjData) -> None:
        """Take the current poses (after mj_kinematics) into the scene."""
        self._r.update_scene(data, camera=CAMERA)

    def rgb(self) -> np.ndarray:
        """(H, W, 3) uint8, row 0 at the top."""
        image = self._r.render()
        return image if self._warp is None else self._warp.rgb(image)

    def segmentation(self) -> np.ndarray:
        """(H, W) int32 geom id at each pixel, -1 where no geom (background or other objects)."""
        self._r.enable_segmentation_rendering()
        try:
            seg = self._r.render()
        finally:
            self._r.disable_segmentation_rendering()
        ids = np.where(seg[:, :, 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[:, :, 0], -1)
        return ids if self._warp is None else self._warp.ids(ids)

    def close(self) -> None:
        self._r.close()

    def __enter__(self) -> "FrameRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def id_map(geom_ids: np.ndarray, geom_value: np.ndarray) -> np.ndarray:
    """Per-pixel value of the geom seen there: ``geom_value[geom_ids]``, -1 where geom_ids == -1.

    Args:
        geom_ids: (H, W) int32 from ``FrameRenderer.segmentation``.
        geom_value: (ngeom,) int32, e.g. the agent_id of each geom (-1 for scenery).
    Returns:
        (H, W) int32.
    """
    return np.append(geom_value.astype(np.int32), np.int32(-1))[geom_ids]
