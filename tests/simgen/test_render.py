"""Rendering: the MuJoCo camera is the PinholeCamera (markers within 0.5 px, each backend), the
segmentation ids map to the right agents, and a missing backend is one clear line."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from simgen.detection import id_boxes
from simgen.scene import load_scene
from simgen.stage import Stage
from simgen.truth import silhouette_outlines

from scene_copies import SCENES

pytestmark = pytest.mark.generate  # renders frames with MuJoCo

HERE = Path(__file__).resolve().parent


def _env(**set_vars: str) -> dict:
    """This environment for a fresh process: no DISPLAY, and PyOpenGL free to follow MUJOCO_GL."""
    drop = ("DISPLAY", "PYOPENGL_PLATFORM")
    return {k: v for k, v in os.environ.items() if k not in drop} | set_vars


REAL_CAMERA = {"yaw_deg": 8.0, "roll_deg": 1.0, "distortion": [-0.30678, 0.0825017, 0.0028784, -0.00015829, 0.0]}


@pytest.mark.parametrize("camera", [{}, pytest.param(REAL_CAMERA, marks=pytest.mark.slow)], ids=["pinhole", "real"])
@pytest.mark.parametrize("backend", ["egl", "osmesa"])
def test_marker_on_ground_point_lands_on_its_projection(backend, camera):
    """Rendered markers land on cv2.projectPoints of their centres (with the lens, roll and yaw: through the wide
    pinhole render and the remap) within 0.5 px."""
    env = _env(MUJOCO_GL=backend)
    run = subprocess.run([sys.executable, str(HERE / "marker_check.py"), json.dumps(camera)], env=env, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    result = json.loads(run.stdout)
    assert result["backend"] == backend
    distances = np.hypot(*np.array(result["points"]).T)
    assert len(result["errors_px"]) >= 20 and distances.min() <= 5.0 and distances.max() >= 50.0
    assert max(result["errors_px"]) < 0.5


@pytest.mark.parametrize("name", ["scene1", pytest.param("scene3", marks=pytest.mark.slow)])
def test_segmentation_ids_are_the_right_agents(name):
    """Each visible agent's mask lies inside the silhouette predicted from that agent's own pose (scene3: the
    remapped segmentation of a real camera against the silhouettes through its lens)."""
    scene = load_scene(SCENES / name)
    checked = 0
    with Stage(scene, seed=11) as stage:
        for t in (3.0, 17.0):
            state = stage.set_time(t)
            seen, xyxy, counts = id_boxes(stage.agent_ids())
            assert set(seen) <= set(state.agent_id)
            outlines = silhouette_outlines(scene.camera, state.segments, state.radii)
            for agent, box in zip(seen, xyxy):
                pts = outlines[list(state.agent_id).index(agent)].reshape(-1, 2)
                lo, hi = pts.min(axis=0), pts.max(axis=0)
                assert lo[0] - 1 <= box[0] and box[2] <= hi[0] + 1, (agent, box, lo, hi)
                assert lo[1] - 1 <= box[1] and box[3] <= hi[1] + 1, (agent, box, lo, hi)
                checked += 1
    assert checked >= 20


def test_calibration_object_is_alone_and_only_it_is_seen():
    scene = load_scene(SCENES / "scene1")
    with Stage(scene, seed=0) as stage:
        stage.set_calibration((0.0, 12.0), agent_id=7)
        seen, xyxy, _ = id_boxes(stage.agent_ids())
    assert seen.tolist() == [7]
    u, v = scene.camera.project_ground([[0.0, 12.0]])[0]
    assert abs((xyxy[0, 0] + xyxy[0, 2]) / 2 - u) < 1.0 and abs(xyxy[0, 3] - v) < 2.0


def test_missing_display_is_one_clear_line(tmp_path):
    env = _env(MUJOCO_GL="glfw")
    out = tmp_path / "out"
    run = subprocess.run(
        [sys.executable, "-m", "simgen.cli", "generate", str(SCENES / "scene1"), "--out", str(out), "--seconds", "1", "--seed", "0"],
        env=env, capture_output=True, text=True, timeout=120,
    )
    assert run.returncode == 3
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "MUJOCO_GL=glfw" in lines[0] and "apt-get install" in lines[0], run.stderr
    assert not out.exists()


def test_preview_writes_an_annotated_frame(small_scene, tmp_path):
    import cv2

    from simgen.cli import main
    from simgen.preview import LEGEND

    assert main(["preview", str(small_scene), "-o", str(tmp_path / "frame.png"), "--t", "0.0"]) == 0  # two people 25-36 px tall
    first = (tmp_path / "frame.png").read_bytes()
    assert main(["preview", str(small_scene), "-o", str(tmp_path / "frame.png"), "--t", "0.0"]) == 0  # its own PNG: replaced
    assert (tmp_path / "frame.png").read_bytes() == first and sorted(tmp_path.glob("frame*")) == [tmp_path / "frame.png"]
    img = cv2.imread(str(tmp_path / "frame.png"))
    assert img.shape[0] > 180 and img.shape[1:] == (320, 3)  # the frame, then the legend strip below it
    frame, strip = img[:180], img[180:]
    green = (frame[:, :, 1] == 200) & (frame[:, :, 0] == 0) & (frame[:, :, 2] == 0)  # box outlines
    assert green.sum() > 20
    for color, _, text in LEGEND:  # each mark of the legend in its colour, as the frame draws it
        assert (strip == color).all(axis=2).sum() >= 5, text
