"""research/camera_variants.py against simgen's own dataset: the dataset's camera reprojects it exactly (gt, the
calibration objects, the trapezoids, camera.json), draw:2024 clicks the shipped scene's hand-placed trapezoid, and
another camera's dataset is what that camera projects (homocal's PinholeCamera through cv2.projectPoints)."""
import importlib.util
import json
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq

from homocal.geometry import PinholeCamera
from simgen.scene import load_scene

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("camera_variants", ROOT / "research" / "camera_variants.py")
script = importlib.util.module_from_spec(spec)
spec.loader.exec_module(script)


def test_own_camera_reproduces_the_dataset(tiny_dataset, tmp_path):
    script.main([str(tiny_dataset), "-o", str(tmp_path / "same"), "--hand-placed", "draw:2024"])
    for name, cols in (("gt", ["u", "v", "in_frame"]), ("calibration", ["u_exact", "v_exact"])):
        a, b = (pq.read_table(d / f"{name}.parquet", columns=cols).to_pandas() for d in (tiny_dataset, tmp_path / "same"))
        assert a.equals(b)
    assert json.loads((tmp_path / "same" / "camera.json").read_text()) == json.loads((tiny_dataset / "camera.json").read_text())
    traps = json.loads((tmp_path / "same" / "trapezoids.json").read_text())
    scene1 = load_scene(ROOT / "scenes" / "scene1")
    assert traps["hand_placed"]["image"] == scene1.hand_placed_image.tolist()
    assert traps["hand_placed"]["map"] == scene1.hand_placed_map.tolist()


def test_another_camera_projects_the_same_ground(tiny_dataset, tmp_path):
    lens = [-0.2, 0.04, 0.0, 0.0, 0.0]
    script.main([str(tiny_dataset), "-o", str(tmp_path / "rolled"), "--roll", "2", "--yaw", "-5",
                 "--distortion=" + ",".join(map(str, lens))])  # "=": the value starts with a minus
    cam = PinholeCamera(roll_deg=2.0, yaw_deg=-5.0)
    gt = pq.read_table(tmp_path / "rolled" / "gt.parquet").to_pandas()
    gt = gt[gt["in_frame"]]
    points = np.column_stack([gt["x"], gt["y"], np.zeros(len(gt))])
    expected, _ = cv2.projectPoints(points, cv2.Rodrigues(cam.R)[0], cam.t, cam.K, np.array(lens))
    np.testing.assert_allclose(gt[["u", "v"]].to_numpy(), expected[:, 0], atol=1e-6)
    camera = json.loads((tmp_path / "rolled" / "camera.json").read_text())
    assert (camera["roll_deg"], camera["yaw_deg"], camera["distortion"]) == (2.0, -5.0, lens)
