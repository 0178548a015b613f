"""Scene configs: the shipped scenes match the paper, bad configs are refused with one line naming the field."""
from __future__ import annotations

import numpy as np
import pytest

from simgen.cli import main
from simgen.scene import load_scene

from scene_copies import SCENES, copy_scene, edit_toml


@pytest.mark.parametrize("name, count, stop", [("scene1", 40, 44.0), ("scene2", 39, 49.0)])
def test_shipped_scenes(name, count, stop):
    scene = load_scene(SCENES / name)
    cam = scene.camera
    assert (cam.width, cam.height, cam.hfov_deg, cam.mount_height_m, cam.tilt_deg) == (1280, 720, 95.0, 4.0, 15.0)
    assert cam.vfov_deg == pytest.approx(63.088285, abs=1e-6)
    np.testing.assert_allclose(scene.calibration_distances, np.linspace(5.0, stop, count))
    for hand, exact in ((scene.hand_placed_image, scene.trapezoid_exact_image), (scene.hand_placed_map, scene.trapezoid_exact_map)):
        off = np.hypot(*(hand - exact).T)
        assert hand.dtype.kind == "i" and np.all((off >= 1.0) & (off <= 2.0)), off
    np.testing.assert_allclose(scene.trapezoid_exact_map, scene.to_map(scene.trapezoid_ground))


BAD = [
    # (section, key, new TOML value or None to delete, the field the message must name)
    ("camera", "tilt_deg", None, "camera.tilt_deg: missing"),
    ("camera", "tilt_deg", "-40.0", "sees no ground"),
    ("camera", "width", "'wide'", "camera.width: expected int"),
    ("calibration", "distances_m", "{ start = 2.0, stop = 44.0, count = 40 }", "calibration.distances_m: 2 m is outside the view"),
    ("calibration", "distances_m", "{ start = 5.0, stop = 400.0, count = 3 }", "calibration.distances_m: 202.5 m is outside the view"),
    ("trapezoid", "hand_placed_image", "[[0, 0], [2000, 0], [10, 10], [0, 10]]", "trapezoid.hand_placed_image"),
    ("run", "fps", "0", "run.fps"),
    ("agents", "speed_mps", "[2.0, 1.0]", "agents.speed_mps"),
    ("", "model", "'missing.xml'", "model: "),
]


@pytest.mark.parametrize("section, key, value, message", BAD, ids=[b[3].split(":")[0] + "-" + str(b[2]) for b in BAD])
def test_bad_config_is_refused_with_one_line(tmp_path, capsys, section, key, value, message):
    folder = copy_scene(tmp_path, small=False)
    edit_toml(folder / "scene.toml", section, key, value)
    out = tmp_path / "out"
    code = main(["generate", str(folder), "--out", str(out), "--seconds", "1", "--seed", "0", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and err.startswith("simgen: error: scene.toml: ") and message in err, err
    assert not out.exists()


@pytest.mark.parametrize("option, message", [(["--seconds", "0.123"], "run.seconds"), (["--detectors", "yolo"], "detection.detectors")])
def test_bad_run_option_is_refused(tmp_path, capsys, option, message):
    out = tmp_path / "out"
    code = main(["generate", str(SCENES / "scene1"), "--out", str(out), "--seed", "0", *option])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
