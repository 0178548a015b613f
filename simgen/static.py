"""The static files of a dataset folder (data_schema.md): camera.json, trapezoids.json, the site map and
calibration.parquet, written once before the chunks of frames."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa

from homocal.files import write_atomic, write_json_atomic
from homocal.geometry.camera_file import camera_json_dict
from simgen.backend import mujoco
from simgen.detection import SegmentationDetector
from simgen.scene import Scene
from simgen.stage import Stage

CALIBRATION_SCHEMA = pa.schema([
    ("index", pa.int32()), ("distance_m", pa.float64()), ("x", pa.float64()), ("y", pa.float64()),
    ("u", pa.float64()), ("v", pa.float64()), ("u_exact", pa.float64()), ("v_exact", pa.float64()),
    ("x1", pa.float64()), ("y1", pa.float64()), ("x2", pa.float64()), ("y2", pa.float64()),
])  # fmt: skip


def trapezoids_json(scene: Scene) -> dict:
    return {
        "order": "TL,TR,BR,BL",
        "hand_placed": {"image": scene.hand_placed_image.tolist(), "map": scene.hand_placed_map.tolist()},
        "exact": {"image": scene.trapezoid_exact_image.tolist(), "map": scene.trapezoid_exact_map.tolist()},
        "ground_m": scene.trapezoid_ground.tolist(),
    }


def site_map(scene: Scene) -> np.ndarray:
    """(H, W, 3) uint8 BGR top-down map at ``scene.map_scale`` px per metre: the ground texture, with the
    footprints of the scene's static boxes (buildings) in grey."""
    x0, x1, y0, y1 = scene.ground.extent
    size = (round((x1 - x0) * scene.map_scale), round((y1 - y0) * scene.map_scale))
    image = cv2.resize(cv2.imread(str(scene.ground.texture), cv2.IMREAD_COLOR), size, interpolation=cv2.INTER_AREA)
    model = mujoco.MjModel.from_xml_path(str(scene.model_path))
    for g in np.flatnonzero((model.geom_type == mujoco.mjtGeom.mjGEOM_BOX) & (model.geom_bodyid == 0)):
        corners = np.array([[sx, sy, 0.0] for sx, sy in ((1, 1), (1, -1), (-1, -1), (-1, 1))]) * model.geom_size[g]
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, model.geom_quat[g])
        xy = (corners @ rot.reshape(3, 3).T + model.geom_pos[g])[:, :2]
        cv2.fillPoly(image, [np.round(scene.site_map.to_pixels(xy) * 16).astype(np.int32)], (150, 150, 150), cv2.LINE_AA, 4)
    return image


def write_static(scene: Scene, out: Path) -> None:
    write_json_atomic(out / "camera.json", camera_json_dict(scene.camera))  # homocal's camera codec
    write_json_atomic(out / "trapezoids.json", trapezoids_json(scene))
    image = site_map(scene)
    write_atomic(out / "site_map.png", lambda p: p.write_bytes(cv2.imencode(".png", image)[1].tobytes()))
    write_json_atomic(out / "site_map.json", {"file": "site_map.png", "scale_px_per_m": scene.map_scale,
                                       "origin_px": list(scene.site_map.origin_px), "width": image.shape[1], "height": image.shape[0]})


def calibration_table(stage: Stage) -> pa.Table:
    """One row per calibration distance: the object alone at its point (scene.calibration_xy), detected by the segmentation detector."""
    scene, detector = stage.scene, SegmentationDetector()
    xy = scene.calibration_xy
    d = np.hypot(xy[:, 0], xy[:, 1])  # the distances themselves with layout "line"
    box = np.full((len(d), 4), np.nan)
    for i, point in enumerate(xy):
        stage.set_calibration(point)
        batch = detector.detect(-1, 0.0, None, stage.agent_ids())
        if len(batch):
            box[i] = batch.xyxy[np.flatnonzero(batch.agent_id == 0)[0]]
    exact = scene.camera.project_ground(xy)
    cols = [np.arange(len(d), dtype=np.int32), d, xy[:, 0], xy[:, 1], (box[:, 0] + box[:, 2]) / 2, box[:, 3],
            exact[:, 0], exact[:, 1], box[:, 0], box[:, 1], box[:, 2], box[:, 3]]
    return pa.Table.from_arrays([pa.array(c) for c in cols], schema=CALIBRATION_SCHEMA)
