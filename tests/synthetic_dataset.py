"""A small synthetic dataset folder (data_schema.md) from the paper's pinhole camera, for the study tests that
need fast datasets with chosen sizes; real datasets come from `simgen generate` (tests/conftest.py)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from homocal.geometry import PinholeCamera, SiteMap
from homocal.geometry.camera_file import camera_json_dict

GROUND_RECT = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])  # TL, TR, BR, BL, metres


def write_dataset(path: str | Path, scene: str = "synthetic", n_calibration: int = 12, n_test: int = 500,
                  seed: int = 0, distortion: list[float] | None = None, camera: PinholeCamera | None = None) -> Path:
    """Write a complete dataset folder: calibration objects at 5..44 m ahead, n_test agent positions on the road
    (exact projections; the "segmentation" detector adds 0.5 px noise), a hand-placed trapezoid within 2 px.
    With distortion (OpenCV's k1, k2, p1, p2, k3) every image point is the lens's (Lens.distort_points) and
    camera.json says it. camera: another camera (its lens, roll and yaw; distortion then unused), whose
    camera.json is simgen's (camera_json_dict)."""
    cam = camera or PinholeCamera(distortion=(0.0,) * 5 if distortion is None else tuple(distortion))
    site, project = SiteMap(10.0, (200.0, 600.0)), cam.project_ground  # the camera's (distorted) pixels

    rng = np.random.default_rng(seed)
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    exact_image = project(GROUND_RECT)
    hand_image = np.round(exact_image + rng.uniform(-2, 2, (4, 2)))
    exact_map = site.to_pixels(GROUND_RECT)
    hand_map = np.round(exact_map + rng.uniform(-1, 1, (4, 2)))
    dist = np.linspace(5.0, 44.0, n_calibration)
    cal_g = np.column_stack([np.zeros(n_calibration), dist])
    cal_q = project(cal_g)
    test_g = np.column_stack([rng.uniform(-4, 4, n_test), rng.uniform(5, 45, n_test)])
    test_q = project(test_g)
    det_q = test_q + rng.normal(0, 0.5, test_q.shape)
    nan = np.full(n_test, np.nan)
    tables = {
        "calibration.parquet": {"index": np.arange(n_calibration, dtype=np.int32), "distance_m": dist,
                                "x": cal_g[:, 0], "y": cal_g[:, 1], "u": cal_q[:, 0] + 0.3, "v": cal_q[:, 1] + 0.5,
                                "u_exact": cal_q[:, 0], "v_exact": cal_q[:, 1]},
        "gt.parquet": {"t": np.arange(n_test) * 0.05, "agent_id": np.arange(n_test, dtype=np.int32),
                       "x": test_g[:, 0], "y": test_g[:, 1], "u": test_q[:, 0], "v": test_q[:, 1],
                       "in_frame": np.ones(n_test, bool)},
        "detections.parquet": {"detector": ["segmentation"] * n_test, "frame": np.arange(n_test, dtype=np.int32),
                               "agent_id": np.arange(n_test, dtype=np.int32), "u": det_q[:, 0], "v": det_q[:, 1],
                               "gt_x": test_g[:, 0], "gt_y": test_g[:, 1], "score": nan + 1.0},
    }
    for name, cols in tables.items():
        pq.write_table(pa.table(cols), path / name)
    files = {
        "manifest.json": {"scene": scene, "seed": seed, "config_hash": f"synthetic-{scene}-{seed}", "complete": True,
                          "detectors": ["segmentation"]},
        "camera.json": camera_json_dict(camera) if camera is not None else {
            "camera_origin": [0.0, 0.0], "width": cam.width, "height": cam.height, "K": cam.K.tolist(),
            "horizon_row": cam.horizon_row, **({} if distortion is None else {"distortion": distortion})},
        "trapezoids.json": {"order": "TL,TR,BR,BL", "hand_placed": {"image": hand_image.tolist(), "map": hand_map.tolist()},
                            "exact": {"image": exact_image.tolist(), "map": exact_map.tolist()},
                            "ground_m": GROUND_RECT.tolist()},
        "site_map.json": {"file": "site_map.png", "scale_px_per_m": site.scale_px_per_m, "origin_px": list(site.origin_px)},
    }
    for name, content in files.items():
        (path / name).write_text(json.dumps(content))
    return path


def pose_columns(steps: int, dt: float = 0.05) -> dict:
    """camera_pose.parquet's columns (data_schema.md) of a camera tilted 15 degrees that steps to 16 half-way: its
    horizon a level line at row 202, then 191."""
    step = np.arange(steps)
    later = step >= steps // 2
    return {"t": step * dt, "step": step, "tilt_deg": np.where(later, 16.0, 15.0), "roll_deg": np.zeros(steps),
            "yaw_deg": np.zeros(steps), "horizon_a": np.zeros(steps), "horizon_b": np.ones(steps),
            "horizon_c": np.where(later, -191.0, -202.0)}


def make_moving(path: str | Path, steps: int = 20) -> Path:
    """Give a dataset folder a moving camera: camera_pose.parquet (pose_columns), one row per step of its
    manifest's steps_total (set to ``steps``, with gt_dt 0.05, when the manifest has none)."""
    path = Path(path)
    manifest = json.loads((path / "manifest.json").read_text())
    manifest = {"steps_total": steps, "gt_dt": 0.05, **manifest}
    (path / "manifest.json").write_text(json.dumps(manifest))
    pq.write_table(pa.table(pose_columns(manifest["steps_total"], manifest["gt_dt"])), path / "camera_pose.parquet")
    return path
