"""The run's world at one instant: the model posed at time t (or for one calibration object), rendered.

``Stage`` is what the dataset writer, the preview, the benchmark and the tests drive.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simgen.render import FrameRenderer, apply_quality, id_map, mujoco  # render first: it guards the mujoco import
from simgen.agents import Crowd
from simgen.model import PARKED, build_model, yaw_quat
from simgen.scene import Scene


@dataclass(frozen=True)
class AgentState:
    """Active agents at one time: agent_id (A,) int32, xy (A, 2) m, heading (A,) rad, speed (A,) m/s."""

    agent_id: np.ndarray
    xy: np.ndarray
    heading: np.ndarray
    speed: np.ndarray


class Stage:
    """Model, data, renderer and crowd of a run; a context manager (closes the renderer)."""

    def __init__(self, scene: Scene, seed: int, t_end: float | None = None) -> None:
        self.scene = scene
        self.run_model = build_model(scene, seed)
        self.model = self.run_model.model
        apply_quality(self.model, scene.quality)
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)  # camera poses are set by mj_forward, not mj_kinematics
        self.crowd = Crowd(scene, seed, scene.seconds if t_end is None else t_end)
        self.renderer = FrameRenderer(self.model, scene.camera.width, scene.camera.height)
        self._geom_agent = np.full(self.model.ngeom, -1, np.int32)

    def _place(self, slot_xy: np.ndarray, slot_heading: np.ndarray, calib_y: float | None) -> None:
        """Move the mocap bodies (idle slots: NaN xy, parked) and render-ready the scene."""
        pos = np.tile(PARKED, (len(slot_xy), 1))
        active = np.isfinite(slot_xy[:, 0])
        pos[active, :2] = slot_xy[active]
        d, rm = self.data, self.run_model
        d.mocap_pos[rm.slot_mocap] = pos
        d.mocap_quat[rm.slot_mocap] = yaw_quat(np.where(active, slot_heading, 0.0))
        d.mocap_pos[rm.calib_mocap] = PARKED if calib_y is None else (0.0, calib_y, 0.0)
        d.mocap_quat[rm.calib_mocap] = yaw_quat([-np.pi / 2])[0]  # facing the camera
        mujoco.mj_kinematics(self.model, d)
        self.renderer.update(d)

    def set_time(self, t: float) -> AgentState:
        """Pose every agent at time t (seconds); returns the active agents' state."""
        ids, xy, heading, speed = self.crowd.state(t)
        self._place(xy, heading, None)
        self._geom_agent = np.append(ids, np.int32(-1))[self.run_model.geom_slot]
        a = ids >= 0
        return AgentState(ids[a], xy[a], heading[a], speed[a])

    def set_calibration(self, distance_m: float, agent_id: int = 0) -> None:
        """Only the calibration object, at (0, distance_m) facing the camera; it shows as ``agent_id``."""
        n = self.scene.agent_count
        self._place(np.full((n, 2), np.nan), np.zeros(n), distance_m)
        self._geom_agent = np.where(self.run_model.geom_slot == n, agent_id, -1).astype(np.int32)

    def rgb(self) -> np.ndarray:
        """(H, W, 3) uint8 render of the current pose."""
        return self.renderer.rgb()

    def agent_ids(self) -> np.ndarray:
        """(H, W) int32 agent_id visible at each pixel, -1 where none (segmentation render)."""
        return id_map(self.renderer.segmentation(), self._geom_agent)

    def close(self) -> None:
        self.renderer.close()

    def __enter__(self) -> "Stage":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
