"""homocal.geometry.camera_file: camera.json, lens.json and camera_intrinsics.json through one codec."""
import dataclasses
import hashlib
import json

import numpy as np
import pytest

from homocal.geometry import CameraModel, Lens, PinholeCamera, camera_json_dict, read_camera
from homocal.geometry.camera_file import ARRAYS, MAX_CAMERA_BYTES, NUMBERS

CAM = PinholeCamera()
# sha256 of scene1's and scene2's camera.json as simgen wrote them at 2b0ea99 (before the lens): the ideal pinhole
TODAY_SHA256 = "0c96ad0e39a6d84c08cfcbaaf2d1e0ffd688d9f411b6b69df65287e01eb0d37c"
BARREL = [-0.2, 0.04, 0.0, 0.0, 0.0]


def write(tmp_path, obj, name="camera.json"):
    path = tmp_path / name
    path.write_text(obj if isinstance(obj, str) else json.dumps(obj))
    return path


def test_pinhole_camera_json_is_byte_identical_to_before():
    text = json.dumps(camera_json_dict(CAM), indent=2) + "\n"  # as write_json_atomic writes it
    assert hashlib.sha256(text.encode()).hexdigest() == TODAY_SHA256


def test_camera_json_reads_into_the_model(tmp_path):
    camera = read_camera(write(tmp_path, camera_json_dict(CAM, (1.5, -2.0))))
    np.testing.assert_array_equal(camera.K, CAM.K)
    np.testing.assert_array_equal(camera.R, CAM.R)
    np.testing.assert_array_equal(camera.t, CAM.t)
    np.testing.assert_array_equal(camera.horizon, CAM.horizon)
    assert camera.image_size == (1280, 720) and camera.mount_height_m == 4.0
    np.testing.assert_array_equal(camera.camera_origin, [1.5, -2.0])
    assert camera.horizon_row == CAM.horizon_row
    assert camera.lens.is_identity and not camera.distortion.any()  # old datasets: no "distortion" key


def test_horizon_row_without_the_key_is_the_horizon_at_the_principal_column():
    data = camera_json_dict(CAM)
    del data["horizon_row"]
    assert CameraModel.from_dict(data).horizon_row == pytest.approx(CAM.horizon_row, abs=1e-9)
    tilted = [0.1, np.sqrt(1 - 0.01), -300.0]  # a slanted line: v at u = cx
    expected = -(0.1 * CAM.K[0, 2] - 300.0) / np.sqrt(0.99)
    assert CameraModel.from_dict({**data, "horizon": tilted}).horizon_row == pytest.approx(expected, rel=1e-12)


def test_a_real_camera_adds_its_keys():
    @dataclasses.dataclass(frozen=True)
    class Rolled(PinholeCamera):  # PinholeCamera's fields of issue 32 (roll_deg, yaw_deg, distortion)
        roll_deg: float = 1.0
        yaw_deg: float = 8.0
        distortion: tuple = tuple(BARREL)

    data = camera_json_dict(Rolled())
    assert list(data)[-3:] == ["distortion", "roll_deg", "yaw_deg"] and "horizon_row" not in data
    assert data["distortion"] == BARREL and (data["roll_deg"], data["yaw_deg"]) == (1.0, 8.0)
    camera = CameraModel.from_dict(data)
    assert camera.lens == Lens(CAM.K, BARREL, (1280, 720))


def test_lens_json_round_trip(tmp_path):
    lens = Lens(CAM.K, BARREL, (1280, 720))
    camera = read_camera(write(tmp_path, lens.to_dict(), "lens.json"))
    assert camera.lens == lens and camera.R is None and camera.mount_height_m is None
    assert CameraModel.from_dict(camera.to_dict()).to_dict() == camera.to_dict() == lens.to_dict()
    full = CameraModel.from_dict(camera_json_dict(CAM))
    again = CameraModel.from_dict(full.to_dict())
    assert again.to_dict() == full.to_dict() and again.horizon_row == full.horizon_row


def test_intrinsics_without_K(tmp_path):
    camera = read_camera(write(tmp_path, {"width": 640, "height": 480}))
    assert camera.image_size == (640, 480) and camera.K is None and camera.lens is None


LENS = {"K": CAM.K.tolist(), "distortion": BARREL, "image_size": [1280, 720]}


@pytest.mark.parametrize("content, message", [
    ({"K": CAM.K.tolist()}, "image_size: missing"),
    ({**LENS, "image_size": [1280]}, "image_size: expected (width, height)"),
    ({**LENS, "K": [[1, 0], [0, 1]]}, "K: expected shape (3, 3)"),
    ({**LENS, "K": "identity"}, "K: expected numbers"),
    ({**LENS, "distortion": [0.1, 0.2]}, "distortion: expected shape (5,)"),
    ({**LENS, "distortion": [-0.5, 0, 0, 0, 0]}, "distortion: [-0.5, 0.0, 0.0, 0.0, 0.0] folds the image at radius"),
    ({"width": 1280, "height": 720, "distortion": BARREL}, "distortion: needs K"),
    ({**LENS, "R": np.diag([1.0, 1.0, -1.0]).tolist()}, "R: not a rotation"),
    ({**LENS, "horizon": [0, 2, 3]}, "horizon: hypot(a, b) must be 1"),
    ({**LENS, "mount_height_m": -4}, "mount_height_m: must be > 0"),
    ({**LENS, "mount_height_m": "4"}, "mount_height_m: expected a finite number"),
    ({**LENS, "camera_origin": [0, 0, 0]}, "camera_origin: expected shape (2,)"),
    (json.dumps(LENS).replace("-0.2", "NaN"), "distortion: contains NaN or inf"),
    ("[1, 2]", "expected a JSON object"),
    ("{", "not a JSON file"),
    (" " * (MAX_CAMERA_BYTES + 1) + "{}", f"larger than {MAX_CAMERA_BYTES / 2**20:g} MiB"),
])
def test_bad_camera_files(tmp_path, content, message):
    path = write(tmp_path, content)
    with pytest.raises(ValueError) as e:
        read_camera(path)
    assert str(e.value).startswith(f"{path}: ") and message in str(e.value) and "\n" not in str(e.value)


def test_every_field_is_in_one_table():
    """CameraModel's fields besides image_size are each in ARRAYS or NUMBERS (which its checks, from_dict and
    to_dict read): a new field without an entry fails here; every entry round-trips through to_dict/from_dict."""
    assert sorted(f.name for f in dataclasses.fields(CameraModel)) == sorted(["image_size", *ARRAYS, *NUMBERS])
    full = CameraModel((1280, 720), K=np.diag([900.0, 900.0, 1.0]) + [[0, 0, 639.5], [0, 0, 359.5], [0, 0, 0]],
                       distortion=[-0.1, 0.01, 0.0, 0.0, 0.0], R=np.eye(3), t=[0.0, 0.0, 4.0], horizon=[0.0, 1.0, -300.0],
                       mount_height_m=4.0, camera_origin=[1.0, 2.0], horizon_row_px=300.0)
    again = CameraModel.from_dict(full.to_dict())
    for name in [*ARRAYS, *NUMBERS]:
        assert np.array_equal(getattr(again, name), getattr(full, name)), name
