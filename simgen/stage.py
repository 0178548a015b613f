"""The run's world at one instant: the model posed at time t (or for one calibration object), rendered.

``Stage`` is what the dataset writer, the preview, the benchmark and the tests drive.
"""
from __future__ import annotations

import numpy as np

from homocal.geometry.camera import PinholeCamera
from simgen.agents import AgentState, Crowd
from simgen.backend import mujoco
from simgen.humanoid import to_world
from simgen.model import CALIBRATION, CAMERA, PARKED, build_model, pose_geoms, standing
from simgen.render import FrameRenderer, apply_quality, id_map
from simgen.scene import Scene


class Stage:
    """Model, data, renderer and crowd of a run; a context manager (closes the renderer)."""

    def __init__(self, scene: Scene, seed: int, t_end: float | None = None) -> None:
        self.scene = scene
        self.run_model = build_model(scene)
        self.model = self.run_model.model
        apply_quality(self.model, scene.quality)
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)  # camera poses are set by mj_forward, not mj_kinematics
        self.crowd = Crowd(scene, seed, scene.seconds if t_end is None else t_end)
        self.renderer = FrameRenderer(self.model, scene.camera)
        self._geom_agent = np.full(self.model.ngeom, -1, np.int32)
        self.camera = scene.camera  # the pose the MuJoCo camera has now

    def place(self, state: AgentState, camera: PinholeCamera | None = None) -> None:
        """Pose the agents of ``state`` in their slots, park the other bodies, aim the camera as ``camera`` (a
        pose of the scene's camera; default: the ``[camera]`` pose), render-ready the scene."""
        d, rm = self.data, self.run_model
        d.mocap_pos[rm.slot_mocap.ravel()] = PARKED
        pose_geoms(self.model, d, rm.slot_mocap[state.slot].ravel(), rm.slot_geom[state.slot].ravel(),
                   state.segments.reshape(-1, 2, 3), state.radii.ravel(), state.rgba.reshape(-1, 4))
        mujoco.mj_kinematics(self.model, d)
        self._aim(self.scene.camera if camera is None else camera)
        self.renderer.update(d)
        geom_agent = np.full(len(rm.slot_mocap), -1, np.int32)
        geom_agent[state.slot] = state.agent_id
        self._geom_agent = np.append(geom_agent, np.int32(-1))[rm.geom_slot]

    def _aim(self, camera: PinholeCamera) -> None:
        """Turn the MuJoCo camera to ``camera``'s rotation (its position never changes). A static scene's camera is
        never touched: it keeps the compiled pose bit for bit."""
        if camera is self.camera:
            return
        quat = np.zeros(4)  # MuJoCo's camera axes (x right, y up, z backwards) as columns, in world coordinates
        mujoco.mju_mat2Quat(quat, (np.diag([1.0, -1.0, -1.0]) @ camera.R).T.ravel())
        self.model.cam_quat[self.model.camera(CAMERA).id] = quat
        mujoco.mj_camlight(self.model, self.data)
        self.camera = camera

    def set_time(self, t: float) -> AgentState:
        """Pose every agent and the camera (``Scene.camera_at``) at time t (seconds); returns the active agents' state."""
        state = self.crowd.state(t)
        self.place(state, self.scene.camera_at(t))
        return state

    def set_calibration(self, xy: tuple[float, float], agent_id: int = 0) -> AgentState:
        """Only the calibration object, standing at ground point ``xy`` (m) facing the camera (in its ``[camera]``
        pose, whatever its moves); it shows as ``agent_id``."""
        segments, radii = standing(CALIBRATION)
        xy = np.array([xy], dtype=np.float64)
        heading = np.array([np.arctan2(-xy[0, 1], -xy[0, 0])])  # facing the camera's ground point
        state = AgentState(np.array([agent_id], np.int32), np.array([len(self.run_model.slot_mocap) - 1]), xy, heading,
                           np.zeros(1), to_world(segments[None], xy, heading), radii[None], CALIBRATION.rgba[None])
        self.place(state)
        return state

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
