"""A camera that moves: scene.toml's [[camera.moves]] and [camera.sway], the pose function, the rendered frames, the
ground truth and camera_pose.parquet that follow it, and the refusals of bad keys."""
from __future__ import annotations

import dataclasses
import json
import math

import cv2
import numpy as np
import pyarrow.parquet as pq
import pytest

from homocal.dataset import load_dataset
from simgen.boxstream import bodies, box_stream, boxes_of
from simgen.cli import main
from simgen.scene import CameraMove, Sway, camera_offsets, load_scene
from simgen.stage import Stage

from scene_copies import SCENES, copy_scene
from schema_tables import schema_names

MOVES = (CameraMove(1.0, 0.0, 2.0), CameraMove(2.0, 4.0, -1.0, 0.5, 3.0))  # a step at 1 s; a ramp over 2-6 s


@pytest.mark.parametrize("t, expected", [
    (0.999, (0.0, 0.0, 0.0)),  # before the step
    (1.0, (2.0, 0.0, 0.0)),  # the step, from at_s on
    (2.0, (2.0, 0.0, 0.0)),  # the ramp's start
    (4.0, (1.5, 0.25, 1.5)),  # half-way through the ramp: half of it
    (6.0, (1.0, 0.5, 3.0)),  # the ramp's end
    (100.0, (1.0, 0.5, 3.0)),
])  # fmt: skip
def test_moves_add_steps_and_ramps(t, expected):
    np.testing.assert_allclose(camera_offsets(MOVES, None, [t])[0], expected, atol=1e-12)


@pytest.mark.parametrize("t, tilt", [(0.0, 0.0), (2.0, 0.3), (4.0, 0.0), (6.0, -0.3), (1.0, 0.3 * math.sqrt(0.5))])
def test_sway_is_a_sine_of_the_tilt(t, tilt):
    """Sway(0.3 degree, period 8 s): its peak a quarter period in, its trough at three quarters."""
    np.testing.assert_allclose(camera_offsets((), Sway(0.3, 8.0), [t])[0], (tilt, 0.0, 0.0), atol=1e-12)


def _moving_copy(tmp_path, text: str, small: bool = True):
    folder = copy_scene(tmp_path, small=small)
    with open(folder / "scene.toml", "a") as f:
        f.write("\n" + text)
    return folder


def test_the_scene_poses_its_camera_at_each_time(tmp_path):
    scene = load_scene(_moving_copy(tmp_path, "[[camera.moves]]\nat_s = 1.0\ntilt_deg = 2.0\nyaw_deg = -1.0\n"
                                              "[camera.sway]\namplitude_deg = 0.3\nperiod_s = 8.0\n"))
    assert scene.moves == (CameraMove(1.0, 0.0, 2.0, 0.0, -1.0),) and scene.sway == Sway(0.3, 8.0) and scene.moving
    cam = scene.camera_at(2.0)  # the step and the sway's peak
    assert (cam.tilt_deg, cam.roll_deg, cam.yaw_deg) == pytest.approx((15.0 + 2.0 + 0.3, 0.0, -1.0), abs=1e-12)
    static = load_scene(SCENES / "scene1")
    assert not static.moving and static.camera_at(2.0) is static.camera


def test_render_free_boxes_follow_the_moves(tmp_path):
    """simgen.boxstream poses the camera as the renders do: the same boxes as the static camera's before the step,
    others after it."""
    scene = load_scene(_moving_copy(tmp_path, "[[camera.moves]]\nat_s = 0.5\ntilt_deg = 2.0\n"))
    static = dataclasses.replace(scene, moves=())
    for (frame, moved, _), (_, still, _) in zip(box_stream(scene, 0, 1.0, 10), box_stream(static, 0, 1.0, 10)):
        assert np.array_equal(moved, still) == (frame < 5), frame


@pytest.mark.generate
@pytest.mark.slow
def test_a_static_scene_never_touches_the_mujoco_camera(small_scene):
    """A static camera keeps MuJoCo's compiled pose bit for bit (its datasets are byte-identical to those before
    cameras could move; tests/simgen/test_generate.py checks they gain no file)."""
    with Stage(load_scene(small_scene), seed=0) as stage:
        quat, xmat = stage.model.cam_quat.copy(), stage.data.cam_xmat.copy()
        stage.set_time(0.5)
        assert np.array_equal(stage.model.cam_quat, quat) and np.array_equal(stage.data.cam_xmat, xmat)


BAD = [
    ("[[camera.moves]]\nat_s = 1.0\nover_s = -2.0\n", "camera.moves[0].over_s: must be in [0, 86400] s, got -2.0"),
    ("[[camera.moves]]\nat_s = 1.0\ntilt_deg = nan\n", "camera.moves[0].tilt_deg: must be a finite number, got nan"),
    ("[[camera.moves]]\nat_s = inf\n", "camera.moves[0].at_s: must be a finite number"),
    ("[[camera.moves]]\ntilt_deg = 1.0\n", "camera.moves[0].at_s: missing"),
    ("[[camera.moves]]\nat_s = 2.0\n[[camera.moves]]\nat_s = 1.0\n", "camera.moves[1].at_s: moves must come in time order"),
    ("[[camera.moves]]\nat_s = 1.0\ntlit_deg = 1.0\n", "camera.moves[0].tlit_deg: unknown key (did you mean camera.moves[0].tilt_deg?)"),
    ("[[camera.moves]]\nat_s = 1.0\n" * 101, "camera.moves: at most 100 moves, got 101"),
    ("[[camera.moves]]\nat_s = 1.0\ntilt_deg = -60.0\n", "camera.moves, camera.sway: a pose they reach is no camera: camera: tilt_deg="),
    # a ramp up 80 degrees and a step back down at its end: the pose just before the step tilts 95 degrees
    ("[[camera.moves]]\nat_s = 0.0\nover_s = 10.0\ntilt_deg = 80.0\n[[camera.moves]]\nat_s = 10.0\ntilt_deg = -80.0\n",
     "a pose they reach is no camera: camera: tilt_deg must be in (-90, 90)"),
    ("[[camera.moves]]\nat_s = 1.0\nroll_deg = 95.0\n", "a pose they reach is no camera: camera: roll_deg must be in (-90, 90)"),
    ("[camera.sway]\namplitude_deg = 0.3\nperiod_s = 0.0\n", "camera.sway.period_s: must be in (0, 86400] s, got 0.0"),
    ("[camera.sway]\namplitude_deg = nan\nperiod_s = 60.0\n", "camera.sway.amplitude_deg: must be a finite number"),
    ("[camera.sway]\namplitude_deg = -1.0\nperiod_s = 60.0\n", "camera.sway.amplitude_deg: must be in [0, 45], got -1.0"),
    ("[camera.sway]\namplitude_deg = 0.3\n", "camera.sway.period_s: missing"),
    ("[camera.sway]\namplitude_deg = 0.3\nperiod_s = 60.0\nphase = 1.0\n", "camera.sway.phase: unknown key"),
]  # fmt: skip


@pytest.mark.parametrize("text, message", BAD, ids=[b[1].split(":")[0] + "-" + str(i) for i, b in enumerate(BAD)])
def test_bad_moves_are_refused_with_one_line(tmp_path, capsys, text, message):
    folder = _moving_copy(tmp_path, text, small=False)
    out = tmp_path / "out"
    code = main(["generate", str(folder), "--out", str(out), "--seconds", "1", "--seed", "0", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    assert len(err.strip().splitlines()) == 1 and err.startswith("simgen: error: scene.toml: ") and message in err, err


# ---- a rendered moving dataset -----------------------------------------------------------------
MOVING = ("[[camera.moves]]\nat_s = 0.0\ntilt_deg = 1.0\n"  # from the start: the calibration stays the [camera] pose's
          "[[camera.moves]]\nat_s = 0.5\ntilt_deg = 2.0\nroll_deg = 1.0\nyaw_deg = -1.5\n")


@pytest.fixture(scope="module")
def moving(tmp_path_factory):
    """(scene, dataset folder) of 1 s of the small scene1 copy (320x180) whose camera moves at 0 and 0.5 s."""
    tmp = tmp_path_factory.mktemp("moving")
    folder = _moving_copy(tmp, MOVING)
    out = tmp / "out"
    assert main(["generate", str(folder), "--out", str(out), "--seconds", "1", "--seed", "1", "--no-progress"]) == 0
    return load_scene(folder), out


def _rotation(tilt: float, roll: float, yaw: float) -> np.ndarray:
    """World-to-camera rotation of data_schema.md's convention built from cv2.Rodrigues: the level camera looking
    along +y, turned by yaw about the vertical, tilted down about its x axis, rolled about its optical axis."""
    level = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    turn = lambda axis, deg: cv2.Rodrigues(np.radians(deg) * np.array(axis, dtype=np.float64))[0]  # noqa: E731
    return turn([0, 0, -1], roll) @ turn([1, 0, 0], tilt) @ level @ turn([0, 0, -1], yaw)


@pytest.mark.generate
@pytest.mark.slow
def test_camera_pose_table_is_each_steps_pose(moving):
    scene, out = moving
    pose, gt = pq.read_table(out / "camera_pose.parquet").to_pandas(), pq.read_table(out / "gt.parquet").to_pandas()
    assert pose.step.tolist() == list(range(20)) and np.array_equal(pose.t, pose.step * 0.05)
    assert set(zip(gt.step, gt.t)) <= set(zip(pose.step, pose.t))
    before, after = pose.step < 10, pose.step >= 10
    np.testing.assert_allclose(pose[before][["tilt_deg", "roll_deg", "yaw_deg"]], [[16.0, 0.0, 0.0]] * 10, atol=1e-12)
    np.testing.assert_allclose(pose[after][["tilt_deg", "roll_deg", "yaw_deg"]], [[18.0, 1.0, -1.5]] * 10, atol=1e-12)
    K = np.array(json.loads((out / "camera.json").read_text())["K"])
    for row in pose.itertuples():  # the horizon: the line through the vanishing points of two ground directions
        R = _rotation(row.tilt_deg, row.roll_deg, row.yaw_deg)
        line = np.array([row.horizon_a, row.horizon_b, row.horizon_c])
        assert math.hypot(*line[:2]) == pytest.approx(1.0, abs=1e-12)
        for direction in ([0.5, 1.0, 0.0], [-0.5, 1.0, 0.0]):  # ahead of the camera: finite vanishing points
            vanishing = K @ R @ direction
            assert line @ (vanishing / vanishing[2]) == pytest.approx(0.0, abs=1e-9)
        assert line @ [K[0, 2], K[1, 2] + 1000.0, 1.0] > 0  # positive below it


@pytest.mark.generate
@pytest.mark.slow
def test_data_schema_names_every_pose_column_once(moving):
    """data_schema.md's camera_pose.parquet table is the file's columns, each once."""
    documented = schema_names("camera_pose.parquet")
    assert sorted(documented) == sorted(pq.read_schema(moving[1] / "camera_pose.parquet").names)


@pytest.mark.generate
@pytest.mark.slow
def test_load_dataset_gives_the_pose_track(moving):
    """homocal.load_dataset's pose track (Dataset.pose) is camera_pose.parquet's rows, read through pyarrow alone."""
    _, out = moving
    table, pose = pq.read_table(out / "camera_pose.parquet").to_pydict(), load_dataset(out).pose
    for key in ("t", "step", "tilt_deg", "roll_deg", "yaw_deg"):
        np.testing.assert_array_equal(getattr(pose, key), table[key])
    np.testing.assert_array_equal(pose.horizon, np.column_stack([table[f"horizon_{k}"] for k in "abc"]))


@pytest.mark.generate
@pytest.mark.slow
def test_gt_pixels_are_each_steps_projection(moving):
    """gt.parquet's u, v: cv2.projectPoints of the ground point through the step's pose of camera_pose.parquet."""
    _, out = moving
    pose, gt = pq.read_table(out / "camera_pose.parquet").to_pandas(), pq.read_table(out / "gt.parquet").to_pandas()
    cam = json.loads((out / "camera.json").read_text())
    checked = 0
    for row in pose.itertuples():
        rows = gt[gt.step == row.step]
        R = _rotation(row.tilt_deg, row.roll_deg, row.yaw_deg)
        points = np.column_stack([rows.x, rows.y, np.zeros(len(rows))])
        uv = cv2.projectPoints(points, cv2.Rodrigues(R)[0], -R @ [0.0, 0.0, cam["mount_height_m"]], np.array(cam["K"]),
                               np.zeros(5))[0][:, 0]
        front = (points - [0.0, 0.0, cam["mount_height_m"]]) @ R[2] > 0
        np.testing.assert_allclose(rows[["u", "v"]].to_numpy()[front], uv[front], atol=1e-6, rtol=0)
        checked += front.sum()
    assert checked >= 100


@pytest.mark.generate
@pytest.mark.slow
def test_rendered_people_and_calibration_follow_the_pose(moving):
    """The segmentation renders (gt boxes) and the segmentation detector's boxes against the boxes the people's
    geometry gives through each step's pose (simgen.boxstream.boxes_of, no renderer): the same to a pixel or two,
    and clearly not those of the camera before the move; calibration.parquet is the [camera] pose's."""
    scene, out = moving
    gt = pq.read_table(out / "gt.parquet").to_pandas()
    det = pq.read_table(out / "detections.parquet").to_pandas()
    det = det[det.detector == "segmentation"]
    pose = pq.read_table(out / "camera_pose.parquet").to_pandas().set_index("step")
    first = dataclasses.replace(scene.camera, tilt_deg=16.0)  # the pose before the move at 0.5 s
    diffs = {"pose": [], "before the move": [], "detector": []}
    for frame, segments, radii, ids in bodies(scene, 1, 1.0, 20):
        p = pose.loc[frame]
        cam = dataclasses.replace(scene.camera, tilt_deg=p.tilt_deg, roll_deg=p.roll_deg, yaw_deg=p.yaw_deg)
        rendered = gt[(gt.step == frame) & gt.x1.notna()].set_index("agent_id")[["x1", "y1", "x2", "y2"]]
        found = det[det.frame == frame].set_index("agent_id")[["x1", "y1", "x2", "y2"]]
        for key, camera in (("pose", cam), ("before the move", first)):
            xyxy, seen = boxes_of(camera, segments, radii)
            for box, agent in zip(xyxy, ids[seen]):
                if agent in rendered.index and (key == "pose" or frame >= 10):
                    diffs[key].append(np.abs(box - rendered.loc[agent].to_numpy()))
                if key == "pose" and agent in found.index:
                    diffs["detector"].append(np.abs(box - found.loc[agent].to_numpy()))
    pose_diff, old_diff, det_diff = (np.array(diffs[k]) for k in ("pose", "before the move", "detector"))
    assert len(pose_diff) >= 60 and len(det_diff) >= 60
    assert np.median(pose_diff) == 0 and np.percentile(pose_diff, 90) <= 2 and np.percentile(det_diff, 90) <= 2
    assert np.median(old_diff[:, [1, 3]]) >= 3  # 2 degrees more tilt and a roll: rows several pixels away
    calib = pq.read_table(out / "calibration.parquet").to_pandas()
    np.testing.assert_allclose(calib[["u_exact", "v_exact"]], scene.camera.project_ground(calib[["x", "y"]].to_numpy()))
    seen = calib.v.notna()
    assert np.abs(calib.v - calib.v_exact)[seen].median() <= 1.0  # rendered at the [camera] pose, not the moved one
    assert np.abs(calib.v - scene.camera_at(0.0).project_ground(calib[["x", "y"]].to_numpy())[:, 1])[seen].median() >= 1.5
