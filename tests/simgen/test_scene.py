"""Scene configs: the shipped scenes match the paper, bad configs are refused with one line naming the field."""
from __future__ import annotations

import re
import shutil
import subprocess
import sys

import cv2
import numpy as np
import pytest

from simgen.cli import main
from simgen.scene import ConfigError, load_scene

from scene_copies import SCENES, copy_scene, edit_toml


@pytest.mark.parametrize("name, count, stop", [("scene1", 40, 44.0), ("scene2", 39, 49.0), ("scene3", 40, 44.0)])
def test_shipped_scenes(name, count, stop):
    scene = load_scene(SCENES / name)
    cam = scene.camera
    assert (cam.width, cam.height, cam.hfov_deg, cam.mount_height_m, cam.tilt_deg) == (1280, 720, 95.0, 4.0, 15.0)
    assert cam.vfov_deg == pytest.approx(63.088285, abs=1e-6)
    np.testing.assert_allclose(scene.calibration_distances, np.linspace(5.0, stop, count))
    for hand, exact in ((scene.hand_placed_image, scene.trapezoid_exact_image), (scene.hand_placed_map, scene.trapezoid_exact_map)):
        off = np.hypot(*(hand - exact).T)
        assert hand.dtype.kind == "i" and np.all((off >= 1.0) & (off <= 2.0)), off
    x0, x1, y0, y1 = scene.ground.extent  # the ground plane's corners are the map image's outer pixel corners
    size = [(x1 - x0) * scene.map_scale, (y1 - y0) * scene.map_scale]
    np.testing.assert_allclose(scene.site_map.to_pixels([[x0, y1], [x1, y0]]), [[-0.5, -0.5], np.subtract(size, 0.5)])


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
    ("camera", "mount_height_m", "nan", "camera.mount_height_m: must be a finite number, got nan"),
    ("camera", "mount_height_m", "1e308", "camera: mount_height_m must be in (0, 10000] m, got 1e+308"),
    ("run", "seconds", "1e12", "run.seconds: must be a positive multiple of 0.05 s, at most 86400"),
    ("run", "fps", "100000", "run.fps: must be an integer in [1, 1000], got 100000"),
    ("camera", "tilt_deg", "inf", "camera.tilt_deg: must be a finite number, got inf"),
    ("camera", "hfov_deg", "-inf", "camera.hfov_deg: must be a finite number"),
    ("site_map", "scale_px_per_m", "nan", "site_map.scale_px_per_m: must be a finite number"),
    ("agents", "speed_mps", "[1.0, inf]", "agents.speed_mps"),
    ("agents", "speed_mps", "[1.0, nan]", "agents.speed_mps"),
    ("trapezoid", "ground_m", "[[-3.25, nan], [3.25, 40.0], [3.25, 10.0], [-3.25, 10.0]]", "trapezoid.ground_m: coordinates must be finite"),
    ("camera", "tilt_deg", "15.0\ntlit_deg = 16.0", "camera.tlit_deg: unknown key (did you mean camera.tilt_deg?)"),
    ("run", "fps", "20\nfsp = 10", "run.fsp: unknown key (did you mean run.fps?)"),
    ("", "model", "'scene.xml'\nmodle = 'x.xml'", "modle: unknown key (did you mean model?)"),
    ("agents", "count", "24\nspeed = 1.0", "agents.speed: unknown key (did you mean agents.speed_mps?)"),
    # the camera moved but the hand-placed trapezoid was not rewritten: 100+ px off
    ("camera", "tilt_deg", "12.0", "trapezoid.hand_placed_image: vertex 2 is 31.9 px from the exact one"),
    ("camera", "mount_height_m", "5.0", "trapezoid.hand_placed_image: vertex 3 is 49.8 px"),
    ("trapezoid", "ground_m", "[[-3.25, 41.0], [3.25, 40.0], [3.25, 10.0], [-3.25, 10.0]]", "trapezoid.hand_placed_"),
    ("trapezoid", "hand_placed_map", "[[266, 800], [333, 800], [333, 1099], [265, 1098]]", "trapezoid.hand_placed_map: vertex 4 is 2.5 px"),
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


APPENDED = [
    # (text appended to scene.toml, the message)
    ("[render]\nquality = 'draft'\n", None),
    ("[render]\nquality = 'best'\n", "render.quality: expected one of draft, default, high, got 'best'"),
    ("[render]\nqualty = 'draft'\n", "render.qualty: unknown key (did you mean render.quality?)"),
    ("[rendr]\nquality = 'draft'\n", "rendr: unknown key (did you mean render?)"),
    ("[[agents.routes]]\nname = 'x'\npoints = [[0.0, 0.0], [1.0, 1.0]]\nwidth_m = 1.0\nboth_ways = true\nweigth = 1.0\n",
     "agents.routes[6].weight: missing (is weigth a typo of weight?)"),
    ("[calibration.extra]\nx = 1\n", "calibration.extra: unknown key"),
]  # fmt: skip


@pytest.mark.parametrize("text, message", APPENDED, ids=[a[1] or "accepted" for a in APPENDED])
def test_appended_tables(tmp_path, text, message):
    folder = copy_scene(tmp_path, small=False)
    with open(folder / "scene.toml", "a") as f:
        f.write("\n" + text)
    if message is None:
        assert load_scene(folder).quality == "draft"
    else:
        with pytest.raises(ConfigError, match=re.escape(message)):
            load_scene(folder)


def test_non_utf8_config_names_the_file(tmp_path):
    folder = copy_scene(tmp_path, small=False)
    with open(folder / "scene.toml", "ab") as f:
        f.write(b"# caf\xe9\n")
    with pytest.raises(ConfigError, match=r"scene\.toml: not UTF-8 text"):
        load_scene(folder)


def test_copied_and_edited_scene_gets_its_own_trapezoid(tmp_path):
    """scenes/make_scene_assets.py DIR derives the hand-placed trapezoid of any folder from its camera."""
    folder = copy_scene(tmp_path, small=False)
    edit_toml(folder / "scene.toml", "camera", "tilt_deg", "12.0")
    with pytest.raises(ConfigError, match="make_scene_assets.py"):
        load_scene(folder)
    subprocess.run([sys.executable, str(SCENES / "make_scene_assets.py"), str(folder)], check=True, capture_output=True)
    scene = load_scene(folder)
    for hand, exact in ((scene.hand_placed_image, scene.trapezoid_exact_image), (scene.hand_placed_map, scene.trapezoid_exact_map)):
        off = np.hypot(*(hand - exact).T)
        assert np.all((off >= 1.0) & (off <= 2.0)), off


def test_a_copied_scene_given_a_real_camera_gets_its_trapezoid(tmp_path):
    """A user adds yaw, roll and a lens to a copy of scene1: load_scene asks for the derivation, which then places
    the trapezoid 1-2 px from the distorted pixels of its ground corners (cv2.projectPoints)."""
    folder = copy_scene(tmp_path, small=False)
    toml = folder / "scene.toml"
    toml.write_text(toml.read_text().replace("[camera]", "[camera]\nyaw_deg = -6.0\nroll_deg = 2.0\n"
                                             "distortion = [-0.2, 0.04, 0.0, 0.0, 0.0]", 1))
    with pytest.raises(ConfigError, match="make_scene_assets.py"):
        load_scene(folder)
    subprocess.run([sys.executable, str(SCENES / "make_scene_assets.py"), str(folder)], check=True, capture_output=True)
    scene, cam = load_scene(folder), load_scene(folder).camera
    ground = np.column_stack([scene.trapezoid_ground, np.zeros(4)])
    exact = cv2.projectPoints(ground, cv2.Rodrigues(cam.R)[0], cam.t, cam.K, np.array([-0.2, 0.04, 0.0, 0.0, 0.0]))[0][:, 0]
    off = np.hypot(*(scene.hand_placed_image - exact).T)
    assert (cam.yaw_deg, cam.roll_deg) == (-6.0, 2.0) and np.all((off >= 1.0) & (off <= 2.0)), off


@pytest.mark.parametrize("key, value, message", [
    ("distortion", "[-0.30, 0.09, 0.0005, -0.0003, -0.012]", "camera.distortion: .* folds the image"),
    ("distortion", "[-0.2, 0.04]", "camera: distortion must be 5 finite numbers"),
    ("roll_deg", "95.0", "camera: roll_deg must be in"),
    ("yaw_deg", "\"8\"", "camera.yaw_deg: expected float"),
])
def test_a_bad_real_camera_is_refused_in_one_line(tmp_path, key, value, message):
    folder = copy_scene(tmp_path, small=False)
    toml = folder / "scene.toml"
    toml.write_text(toml.read_text().replace("[camera]", f"[camera]\n{key} = {value}", 1))
    with pytest.raises(ConfigError, match=message) as e:
        load_scene(folder)
    assert str(e.value).startswith("scene.toml: ") and len(str(e.value).splitlines()) == 1


@pytest.mark.parametrize("name", ["scene1", "scene2", "scene3"])
def test_shipped_trapezoids_are_the_derivation(tmp_path, name):
    """Rerunning the derivation on a copy of a shipped scene gives its scene.toml byte for byte."""
    folder = tmp_path / name
    shutil.copytree(SCENES / name, folder)
    subprocess.run([sys.executable, str(SCENES / "make_scene_assets.py"), str(folder)], check=True, capture_output=True)
    assert (folder / "scene.toml").read_bytes() == (SCENES / name / "scene.toml").read_bytes()


@pytest.mark.parametrize("option, message", [(["--seconds", "0.123"], "run.seconds"), (["--detectors", "yolo"], "argument --detectors")])
def test_bad_run_option_is_refused(tmp_path, capsys, option, message):
    out = tmp_path / "out"
    code = main(["generate", str(SCENES / "scene1"), "--out", str(out), "--seed", "0", *option])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.parametrize("name", ["my scene", "a\nb", "x" * 65, ".hidden", "é"])
def test_a_scene_folder_whose_name_is_no_safe_name_is_refused(tmp_path, capsys, name):
    """The folder's name names the scene in manifest.json, which homocal turns into file names: check_name's rule."""
    folder = tmp_path / name
    shutil.copytree(SCENES / "scene1", folder)
    with pytest.raises(ConfigError, match=re.escape(f"scene (the scene folder's name) {name!r:.30}")):
        load_scene(folder)
    assert main(["generate", str(folder), "--out", str(tmp_path / "out"), "--seconds", "0.5"]) == 2
    err = capsys.readouterr().err
    assert "expected 1-64 letters, digits" in err and len(err.splitlines()) == 1 and not (tmp_path / "out").exists()


def test_a_shipped_scene_by_name_is_the_scene_by_path(tmp_path, monkeypatch):
    from simgen.scene import SHIPPED, scene_folder, shipped_scenes

    monkeypatch.chdir(tmp_path)
    assert shipped_scenes() == ["scene1", "scene2", "scene3"]
    assert scene_folder("scene1") == SHIPPED / "scene1" and (SHIPPED / "scene1").resolve() == (SCENES / "scene1").resolve()
    (tmp_path / "scene1").mkdir()  # a folder of that name where the user is: the path wins
    assert scene_folder("scene1") == tmp_path.joinpath("scene1").relative_to(tmp_path)
