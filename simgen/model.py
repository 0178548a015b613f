"""The MuJoCo model of a run: the scene's MJCF plus the camera, the pedestrians and a calibration object.

A person (humanoid.py) is ``len(PARTS)`` mocap bodies, one geom each (a capsule along the body's z,
or the head's sphere) with contype = conaffinity = 0; ``pose_geoms`` puts each body at its segment's
midpoint, turns its z along the segment and sets the geom's radius, half-length and colour, so one
slot shows one agent after another, each with its own size and clothes. No physics: only
``mj_kinematics`` runs. Idle bodies are parked at ``PARKED``, far behind the camera.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from homocal.geometry.camera import PinholeCamera
from simgen.backend import mujoco
from simgen.humanoid import PARTS, Person, pose
from simgen.lens_warp import render_view
from simgen.scene import Scene

CAMERA = "simgen_camera"
PARKED = np.array([0.0, -1000.0, 0.0])  # behind the camera and beyond zfar
# the calibration object: a standing person 1.75 m tall in an orange shirt
CALIBRATION = Person(1.75, 1.0, np.array([[*{"skin": (0.85, 0.70, 0.55), "shirt": (1.0, 0.45, 0.0), "sleeve": (1.0, 0.45, 0.0),
                                              "trousers": (0.15, 0.15, 0.20), "shoes": (0.1, 0.1, 0.1)}[key], 1.0]
                                           for _, key in PARTS]))


@dataclass(frozen=True)
class RunModel:
    """The compiled model and the index arrays that tie its parts to slots.

    Attributes:
        model: the MjModel.
        slot_mocap: (S + 1, G) mocap index of each geom's body of each pedestrian slot; row S: the calibration object.
        slot_geom: (S + 1, G) geom id of the same.
        geom_slot: (ngeom,) int32: slot of each pedestrian geom, S for the calibration object, -1 otherwise.
    """

    model: mujoco.MjModel
    slot_mocap: np.ndarray
    slot_geom: np.ndarray
    geom_slot: np.ndarray


def add_camera(spec: mujoco.MjSpec, camera: PinholeCamera) -> None:
    """Add the pinhole camera (position, xyaxes, fovy from ``camera``; with a lens, the wider pinhole view of
    ``simgen.lens_warp``) and size the offscreen buffer."""
    width, height, fovy = render_view(camera)
    cam = spec.worldbody.add_camera(name=CAMERA, pos=camera.position.tolist(), fovy=fovy)
    cam.alt.type = mujoco.mjtOrientation.mjORIENTATION_XYAXES
    cam.alt.xyaxes = list(camera.mujoco_xyaxes)
    spec.visual.global_.offwidth = max(spec.visual.global_.offwidth, width)
    spec.visual.global_.offheight = max(spec.visual.global_.offheight, height)


def _add_person(spec: mujoco.MjSpec, name: str) -> None:
    for part, _ in PARTS:
        body = spec.worldbody.add_body(name=f"{name}_{part}", mocap=True, pos=PARKED.tolist())
        kind = mujoco.mjtGeom.mjGEOM_SPHERE if part == "head" else mujoco.mjtGeom.mjGEOM_CAPSULE
        body.add_geom(name=f"{name}_{part}", type=kind, size=[0.05, 0.05, 0], contype=0, conaffinity=0)


def build_model(scene: Scene) -> RunModel:
    """Compile the scene MJCF with the camera, ``scene.agent_count`` pedestrian slots and the calibration object."""
    spec = mujoco.MjSpec.from_file(str(scene.model_path))
    add_camera(spec, scene.camera)
    names = [f"agent_{k}" for k in range(scene.agent_count)] + ["calibration"]
    for name in names:
        _add_person(spec, name)
    model = spec.compile()
    bodies = np.array([[model.body(f"{name}_{part}").id for part, _ in PARTS] for name in names], np.int64).reshape(len(names), -1)
    slot_geom = np.array([[model.geom(f"{name}_{part}").id for part, _ in PARTS] for name in names], np.int64).reshape(len(names), -1)
    geom_slot = np.full(model.ngeom, -1, np.int32)
    geom_slot[slot_geom] = np.arange(len(names))[:, None]
    return RunModel(model, model.body_mocapid[bodies].astype(np.int64), slot_geom, geom_slot)


def segment_quat(segments: np.ndarray) -> np.ndarray:
    """(N, 2, 3) segments -> (N, 4) quaternions (w, x, y, z) turning +z along p1 - p0 (or p0 - p1,
    whichever points up: a capsule is symmetric); identity for a zero-length segment."""
    d = segments[:, 1] - segments[:, 0]
    d = np.where(d[:, 2:3] < 0, -d, d)
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    d = np.divide(d, norm, out=np.tile([0.0, 0.0, 1.0], (len(d), 1)), where=norm > 0)
    q = np.column_stack([1.0 + d[:, 2], -d[:, 1], d[:, 0], np.zeros(len(d))])  # half-way rotation from +z to d
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def pose_geoms(model: mujoco.MjModel, data: mujoco.MjData, mocap: np.ndarray, geoms: np.ndarray,
               segments: np.ndarray, radii: np.ndarray, rgba: np.ndarray) -> None:
    """Put N single-geom mocap bodies on segments (N, 2, 3) m with radii (N,) m and colours (N, 4).

    Args:
        mocap: (N,) mocap indices; geoms: (N,) their geoms' ids.
    """
    data.mocap_pos[mocap] = segments.mean(axis=1)
    data.mocap_quat[mocap] = segment_quat(segments)
    model.geom_size[geoms, 0] = radii
    model.geom_size[geoms, 1] = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1) / 2
    model.geom_rgba[geoms] = rgba


def standing(person: Person) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame segments (G, 2, 3) and radii (G,) of ``person`` standing with the feet together."""
    segments, radii = pose(np.array([person.height]), np.array([person.width]), np.zeros(1), np.zeros(1), np.zeros((1, 2)),
                           np.zeros(1))
    return segments[0], radii[0]
