"""PinholeCamera's roll, yaw and lens against independent computations: scipy's rotations, cv2.projectPoints."""
import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from homocal.geometry import PinholeCamera

POSES = [(0.0, 0.0), (8.0, 0.0), (0.0, 1.0), (8.0, 1.0), (-30.0, -5.0), (150.0, 20.0)]  # (yaw_deg, roll_deg)
LENSES = [(0.0,) * 5, (-0.2, 0.04, 0.0, 0.0, 0.0), (-0.2, 0.04, 5e-4, -3e-4, -0.001)]
GROUND = np.array([(x, y) for x in np.linspace(-12.0, 12.0, 7) for y in (2.0, 6.0, 12.0, 25.0, 45.0)])
LEVEL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # camera x, y, z columns at yaw = tilt = roll = 0


def rotation_by_scipy(yaw: float, tilt: float, roll: float) -> np.ndarray:
    """World-to-camera R built by scipy: yaw about the world's z, then tilt down (-tilt about the camera's own x),
    then roll about its own z (intrinsic "XZ"), on the level camera looking along +y."""
    camera_to_world = (Rotation.from_euler("z", yaw, degrees=True) * Rotation.from_matrix(LEVEL)
                       * Rotation.from_euler("XZ", [-tilt, roll], degrees=True))
    return camera_to_world.as_matrix().T


def ground_points(cam: PinholeCamera) -> np.ndarray:
    """GROUND turned with the camera's yaw, so that the points lie in its view."""
    return GROUND @ Rotation.from_euler("z", cam.yaw_deg, degrees=True).as_matrix()[:2, :2].T


@pytest.mark.parametrize("yaw, roll", POSES)
def test_rotation_matches_scipy(yaw, roll):
    cam = PinholeCamera(tilt_deg=15.0, yaw_deg=yaw, roll_deg=roll)
    np.testing.assert_allclose(cam.R, rotation_by_scipy(yaw, 15.0, roll), atol=1e-12)
    np.testing.assert_allclose(cam.t, -cam.R @ [0.0, 0.0, 4.0], atol=1e-12)


def test_signs_of_yaw_and_roll():
    """Yaw > 0 looks towards -x; roll > 0 lowers the camera's right side."""
    forward = PinholeCamera(yaw_deg=10.0).R[2]
    assert forward[0] < 0 and forward[1] > 0
    right = PinholeCamera(roll_deg=5.0).R[0]
    assert right[2] < 0  # the camera's right axis points below the horizontal


@pytest.mark.parametrize("yaw, roll", POSES)
@pytest.mark.parametrize("distortion", LENSES)
def test_project_matches_cv2_project_points(yaw, roll, distortion):
    cam = PinholeCamera(yaw_deg=yaw, roll_deg=roll, distortion=distortion)
    xyz = np.column_stack([ground_points(cam), np.zeros(len(GROUND))])
    xyz = np.vstack([xyz, xyz + [0.0, 0.0, 1.7]])  # heads too
    rvec, _ = cv2.Rodrigues(cam.R)
    expected, _ = cv2.projectPoints(xyz, rvec, cam.t, cam.K, np.array(distortion))
    got = cam.project(xyz)
    seen = np.isfinite(got).all(axis=1)
    assert seen.sum() > len(xyz) // 2
    np.testing.assert_allclose(got[seen], expected[seen, 0], atol=1e-6)


@pytest.mark.parametrize("yaw, roll", POSES)
def test_horizon_holds_the_vanishing_points(yaw, roll):
    """Points far along any ground direction project onto the horizon line (undistorted image)."""
    cam = PinholeCamera(yaw_deg=yaw, roll_deg=roll)
    forward = np.arctan2(-cam.R[2, 0], cam.R[2, 1])  # heading of the optical axis, from +y towards -x
    angles = forward + np.radians([-30.0, 0.0, 30.0])
    far = 1e9 * np.column_stack([-np.sin(angles), np.cos(angles), np.zeros(3)])
    rvec, _ = cv2.Rodrigues(cam.R)
    uv = cv2.projectPoints(far, rvec, cam.t, cam.K, None)[0][:, 0]
    a, b, c = cam.horizon
    np.testing.assert_allclose(a * uv[:, 0] + b * uv[:, 1] + c, 0.0, atol=1e-5)
    slope = np.arctan2(uv[2, 1] - uv[0, 1], uv[2, 0] - uv[0, 0])  # the line's angle, v down: -roll (mod 180 deg)
    assert np.sin(slope + np.radians(roll)) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("yaw, roll", POSES)
@pytest.mark.parametrize("distortion", LENSES)
def test_ground_homography_is_the_undistorted_image(yaw, roll, distortion):
    cam = PinholeCamera(yaw_deg=yaw, roll_deg=roll, distortion=distortion)
    xy = ground_points(cam)
    rvec, _ = cv2.Rodrigues(cam.R)
    pinhole = cv2.projectPoints(np.column_stack([xy, np.zeros(len(xy))]), rvec, cam.t, cam.K, None)[0][:, 0]
    front = (np.column_stack([xy, np.zeros(len(xy))]) @ cam.R.T + cam.t)[:, 2] > 0
    mapped = cv2.perspectiveTransform(xy[front, None], cam.ground_to_image)[:, 0]
    np.testing.assert_allclose(mapped, pinhole[front], atol=1e-6)
    np.testing.assert_allclose(cam.ray_to_ground(cam.project_ground(xy[front])), xy[front], atol=1e-6)


def test_horizon_row_only_without_roll():
    assert PinholeCamera(yaw_deg=8.0).horizon_row == pytest.approx(PinholeCamera().horizon_row, abs=1e-9)
    with pytest.raises(ValueError, match="roll_deg"):
        PinholeCamera(roll_deg=1.0).horizon_row


def test_mujoco_xyaxes_are_the_camera_axes():
    cam = PinholeCamera(yaw_deg=8.0, roll_deg=1.0)
    xy = np.array(cam.mujoco_xyaxes).reshape(2, 3)
    np.testing.assert_allclose(xy[0], rotation_by_scipy(8.0, 15.0, 1.0)[0], atol=1e-12)  # right
    np.testing.assert_allclose(xy[1], -rotation_by_scipy(8.0, 15.0, 1.0)[1], atol=1e-12)  # up


@pytest.mark.parametrize("field, value, message", [
    ("roll_deg", 90.0, "roll_deg"), ("yaw_deg", -180.0, "yaw_deg"), ("distortion", (0.1, 0.2), "distortion"),
    ("distortion", (float("nan"), 0, 0, 0, 0), "distortion"), ("distortion", ("a", 0, 0, 0, 0), "distortion"),
])
def test_bad_pose_or_lens_is_refused(field, value, message):
    with pytest.raises(ValueError, match=message):
        PinholeCamera(**{field: value})
