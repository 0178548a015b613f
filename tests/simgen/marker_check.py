"""Render small spheres centred on known ground points and print how far each lands from its projection
(cv2.projectPoints through the camera's K, R, t and distortion).

Run as a script (MUJOCO_GL must be set before mujoco is imported, so each backend runs in its own
process), optionally with a JSON object of PinholeCamera fields (``{"yaw_deg": 8, "distortion": [...]}``):
prints JSON {"backend", "errors_px" (one per marker), "points" (world x, y)}.
The sphere radius is 1 % of its distance, so the perspective offset of its centroid is < 0.05 px.
"""
import json
import sys

import cv2
import numpy as np

from simgen.backend import backend, mujoco
from simgen.render import FrameRenderer
from simgen.model import add_camera
from homocal.geometry.camera import PinholeCamera


def main() -> None:
    cam = PinholeCamera(1280, 720, 95.0, 4.0, 15.0, **json.loads(sys.argv[1] if sys.argv[1:] else "{}"))
    ys = np.array([5.0, 8.0, 12.0, 20.0, 30.0, 40.0, 50.0])
    points = np.array([(f * y, y) for i, y in enumerate(ys) for f in np.linspace(-0.9, 0.9, 5) + 0.15 * (i % 2)])
    yaw = np.radians(cam.yaw_deg)
    points = points @ np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]).T  # into the yawed view
    xyz = np.column_stack([points, np.zeros(len(points))])
    uv = cv2.projectPoints(xyz, cv2.Rodrigues(cam.R)[0], cam.t, cam.K, np.array(cam.distortion))[0][:, 0]
    radius_px = 1.5 * 0.01 * cam.focal_px  # generous image radius of a sphere of 1 % of its distance
    apart = np.hypot(*(uv[:, None] - uv[None]).transpose(2, 0, 1)) + np.eye(len(uv)) * 1e9 > 2 * radius_px
    keep = (uv[:, 0] > 20) & (uv[:, 0] < 1260) & (uv[:, 1] > 20) & (uv[:, 1] < 700) & apart.all(axis=1)
    points, uv = points[keep], uv[keep]
    spec = mujoco.MjSpec.from_string("<mujoco/>")
    add_camera(spec, cam)
    for x, y in points:
        r = 0.01 * np.linalg.norm([x, y, -cam.mount_height_m])
        spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[r, 0, 0], pos=[x, y, 0.0])
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with FrameRenderer(model, cam) as r:
        r.update(data)
        ids = r.segmentation()
    rows, cols = np.nonzero(ids >= 0)
    errors = []
    for g in range(len(points)):
        sel = ids[rows, cols] == g
        centroid = np.array([cols[sel].mean(), rows[sel].mean()]) if sel.any() else np.array([np.inf, np.inf])
        errors.append(float(np.hypot(*(centroid - uv[g]))))
    print(json.dumps({"backend": backend(), "errors_px": errors, "points": points.tolist()}))


if __name__ == "__main__":
    main()
