"""The MuJoCo model of a run: the scene's MJCF plus the camera, the pedestrians and a calibration object.

A pedestrian is a mocap body whose frame sits on the ground-contact point (z = 0), facing its +x;
its geoms (``PERSON``) are capsules and spheres, about 1.7 m tall, with contype = conaffinity = 0.
Idle bodies are parked at ``PARKED``, far behind the camera.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from homocal.geometry.camera import PinholeCamera
from simgen.rng import keyed_rng
from simgen.scene import Scene

CAMERA = "simgen_camera"
PARKED = np.array([0.0, -1000.0, 0.0])  # behind the camera and beyond zfar

# (p0, p1, radius, part) in the body frame (x forward, y left, z up), metres; p0 == p1 is a sphere.
PERSON = (
    ((0.0, 0.10, 0.08), (0.0, 0.10, 0.84), 0.08, "legs"),
    ((0.0, -0.10, 0.08), (0.0, -0.10, 0.84), 0.08, "legs"),
    ((0.0, 0.0, 1.02), (0.0, 0.0, 1.30), 0.17, "shirt"),
    ((0.0, 0.25, 1.40), (0.03, 0.27, 0.88), 0.055, "shirt"),
    ((0.0, -0.25, 1.40), (0.03, -0.27, 0.88), 0.055, "shirt"),
    ((0.0, 0.0, 1.585), (0.0, 0.0, 1.585), 0.115, "skin"),
)
SHIRTS = ((0.80, 0.15, 0.12), (0.12, 0.30, 0.75), (0.90, 0.75, 0.15), (0.20, 0.55, 0.25), (0.85, 0.85, 0.85),
          (0.15, 0.15, 0.18), (0.55, 0.20, 0.60), (0.95, 0.45, 0.10))
LEGS = ((0.10, 0.12, 0.25), (0.20, 0.20, 0.22), (0.35, 0.28, 0.20), (0.45, 0.45, 0.50))
SKINS = ((0.93, 0.78, 0.65), (0.78, 0.57, 0.42), (0.55, 0.38, 0.26), (0.36, 0.24, 0.17))
CALIBRATION_COLOURS = {"legs": (0.15, 0.15, 0.20), "shirt": (1.0, 0.45, 0.0), "skin": (0.85, 0.70, 0.55)}


@dataclass(frozen=True)
class RunModel:
    """The compiled model and the index arrays that tie its parts to slots.

    Attributes:
        model: the MjModel.
        slot_mocap: (S,) mocap index of each pedestrian slot.
        calib_mocap: mocap index of the calibration object.
        geom_slot: (ngeom,) int32: slot of each pedestrian geom, S for the calibration object, -1 otherwise.
    """

    model: mujoco.MjModel
    slot_mocap: np.ndarray
    calib_mocap: int
    geom_slot: np.ndarray


def add_camera(spec: mujoco.MjSpec, camera: PinholeCamera) -> None:
    """Add the pinhole camera (position, xyaxes, fovy from ``camera``) and size the offscreen buffer."""
    cam = spec.worldbody.add_camera(name=CAMERA, pos=camera.position.tolist(), fovy=camera.vfov_deg)
    cam.alt.type = mujoco.mjtOrientation.mjORIENTATION_XYAXES
    cam.alt.xyaxes = list(camera.mujoco_xyaxes)
    spec.visual.global_.offwidth = max(spec.visual.global_.offwidth, camera.width)
    spec.visual.global_.offheight = max(spec.visual.global_.offheight, camera.height)


def _add_person(spec: mujoco.MjSpec, name: str, colours: dict[str, tuple]) -> None:
    body = spec.worldbody.add_body(name=name, mocap=True, pos=PARKED.tolist())
    for i, (p0, p1, r, part) in enumerate(PERSON):
        common = dict(name=f"{name}_{i}", size=[r, 0, 0], rgba=[*colours[part], 1.0], contype=0, conaffinity=0)
        if p0 == p1:
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, pos=list(p0), **common)
        else:
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[*p0, *p1], **common)


def build_model(scene: Scene, seed: int) -> RunModel:
    """Compile the scene MJCF with the camera, ``scene.agent_count`` pedestrians and the calibration object."""
    spec = mujoco.MjSpec.from_file(str(scene.model_path))
    add_camera(spec, scene.camera)
    for k in range(scene.agent_count):
        rng = keyed_rng(seed, scene.name, "colour", k)
        colours = {"shirt": SHIRTS[rng.integers(len(SHIRTS))], "legs": LEGS[rng.integers(len(LEGS))],
                   "skin": SKINS[rng.integers(len(SKINS))]}
        _add_person(spec, f"agent_{k}", colours)
    _add_person(spec, "calibration", CALIBRATION_COLOURS)
    model = spec.compile()

    n = scene.agent_count
    body_mocap = lambda name: int(model.body_mocapid[model.body(name).id])  # noqa: E731
    geom_slot = np.full(model.ngeom, -1, np.int32)
    for k, name in enumerate([f"agent_{k}" for k in range(n)] + ["calibration"]):
        geom_slot[model.geom_bodyid == model.body(name).id] = k
    return RunModel(model, np.array([body_mocap(f"agent_{k}") for k in range(n)], np.int64), body_mocap("calibration"), geom_slot)


def yaw_quat(heading: np.ndarray) -> np.ndarray:
    """(N,) yaw angles, rad -> (N, 4) MuJoCo quaternions (w, x, y, z) about +z."""
    h = np.asarray(heading, dtype=np.float64) / 2.0
    return np.column_stack([np.cos(h), np.zeros_like(h), np.zeros_like(h), np.sin(h)])
