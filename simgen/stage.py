"""The run's world at one instant: the model posed at time t (or for one calibration object), rendered.

``Stage`` is what the dataset writer, the preview, the benchmark and the tests drive.
"""
from __future__ import annotations

import numpy as np

from simgen.agents import AgentState, Crowd
from simgen.backend import mujoco
from simgen.humanoid import to_world
from simgen.model import CALIBRATION, PARKED, build_model, pose_geoms, standing
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

    def place(self, state: AgentState) -> None:
        """Pose the agents of ``state`` in their slots, park the other bodies, render-ready the scene."""
        d, rm = self.data, self.run_model
        d.mocap_pos[rm.slot_mocap.ravel()] = PARKED
        pose_geoms(self.model, d, rm.slot_mocap[state.slot].ravel(), rm.slot_geom[state.slot].ravel(),
                   state.segments.reshape(-1, 2, 3), state.radii.ravel(), state.rgba.reshape(-1, 4))
        mujoco.mj_kinematics(self.model, d)
        self.renderer.update(d)
        geom_agent = np.full(len(rm.slot_mocap), -1, np.int32)
        geom_agent[state.slot] = state.agent_id
        self._geom_agent = np.append(geom_agent, np.int32(-1))[rm.geom_slot]

    def set_time(self, t: float) -> AgentState:
        """Pose every agent at time t (seconds); returns the active agents' state."""
        state = self.crowd.state(t)
        self.place(state)
        return state

    def set_calibration(self, xy: tuple[float, float], agent_id: int = 0) -> AgentState:
        """Only the calibration object, standing at ground point ``xy`` (m) facing the camera; it shows as ``agent_id``."""
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
