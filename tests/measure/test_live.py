"""GroundTracker: frame by frame it gives what homocal measure's forward filter gives on the whole file; with
supervision's real Detections (the extra) and with any object of the same two fields; supervision is never
imported by homocal."""
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from homocal.geometry import PinholeCamera, ViewTransformer
from homocal.measure import GroundTracker, measure_tracks
from homocal.measure.kalman import ACCEL_PSD, IMM
from homocal.measure.tracks import FOOT_NOISE, foot_noise_options

CAMERA = PinholeCamera()
GROUND = np.array([[-3.0, 40.0], [3.0, 40.0], [3.0, 10.0], [-3.0, 10.0]])
FPS = 10.0


def walkers():
    """frames (N,), track ids (N,), boxes (N, 4) in supervision's convention (pixel corners at integers): two
    walkers with 1 px of foot noise, the second missing frames 4-6 and starting at frame 2."""
    rng = np.random.default_rng(5)
    frames, ids, boxes = [], [], []
    for k, (p0, v) in enumerate([((-2.0, 9.0), (0.4, 1.2)), ((4.0, 30.0), (-1.1, -0.6))]):
        for f in range(2 * k, 20):
            if k == 1 and 4 <= f <= 6:
                continue
            u, row = CAMERA.project_ground(np.array([p0]) + np.array(v) * f / FPS)[0] + rng.normal(0, 1, 2)
            frames.append(f), ids.append(k), boxes.append([u - 9.5, row - 69.5, u + 10.5, row + 0.5])
    return np.array(frames), np.array(ids), np.array(boxes)


def run(tracker, make):
    frames, ids, boxes = walkers()
    out = {}
    for f in np.unique(frames):
        at = frames == f
        state = tracker.update(make(boxes[at], ids[at]), int(f))
        for i, k in enumerate(state.tracker_id):
            out[(int(f), int(k))] = (state.xy_filtered[i], state.velocity[i], state.speed_mps[i], state.speed_sigma_mps[i])
    return out


def check_against_the_file_filter(out, foot_noise="fixed", foot=None, accel_psd=ACCEL_PSD, foot_tails="normal"):
    frames, ids, boxes = walkers()
    feet = np.column_stack([(boxes[:, 0] + boxes[:, 2]) / 2 - 0.5, boxes[:, 3] - 0.5])  # corners -> homocal
    mapping = ViewTransformer(CAMERA.project_ground(GROUND), GROUND)
    for batch in measure_tracks(mapping, frames, feet, ids, FPS, smooth=False, foot=foot, accel_psd=accel_psd,
                                **foot_noise_options(foot_noise, boxes, 1.0, foot_tails)):
        for j, (f, k) in enumerate(zip(batch["frame"], batch["track_id"])):
            xy, v, speed, sigma = out[(int(f), int(k))]
            np.testing.assert_allclose(xy, [batch["x_smooth"][j], batch["y_smooth"][j]], rtol=1e-9)
            np.testing.assert_allclose(v, [batch["vx"][j], batch["vy"][j]], rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose([speed, sigma], [batch["speed_mps"][j], batch["speed_sigma_mps"][j]], rtol=1e-9)


def test_with_supervision_detections():
    sv = pytest.importorskip("supervision", reason="the supervision extra is not installed (pip install 'homocal[supervision]')")
    tracker = GroundTracker(ViewTransformer(CAMERA.project_ground(GROUND), GROUND), FPS)  # convention "corners"
    out = run(tracker, lambda xyxy, ids: sv.Detections(xyxy=xyxy, tracker_id=ids))
    check_against_the_file_filter(out)
    assert np.hypot(0.4, 1.2) == pytest.approx(out[(19, 0)][2], abs=3 * out[(19, 0)][3])


def test_duck_typed_detections_and_their_refusals():
    tracker = GroundTracker(ViewTransformer(CAMERA.project_ground(GROUND), GROUND), FPS)
    check_against_the_file_filter(run(tracker, lambda xyxy, ids: SimpleNamespace(xyxy=xyxy, tracker_id=ids)))
    box = np.array([[600.0, 300.0, 620.0, 400.0]])
    for detections, frame, words in [
        (SimpleNamespace(xyxy=box, tracker_id=None), 30, "run a tracker on them first"),
        (SimpleNamespace(xyxy=box, tracker_id=np.array([1.5])), 30, "tracker_id: expected (N,) integers"),
        (SimpleNamespace(xyxy=np.vstack([box, box]), tracker_id=np.array([3, 3])), 30, "an id twice"),
        (SimpleNamespace(xyxy=box, tracker_id=np.array([1])), 19, "larger than the last one (19)"),
    ]:
        with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
            tracker.update(detections, frame)
    with pytest.raises(ValueError, match="fps"):
        GroundTracker(ViewTransformer(CAMERA.project_ground(GROUND), GROUND), float("nan"))


@pytest.mark.parametrize("foot_noise", FOOT_NOISE[1:])
def test_foot_noise_models_as_the_file_filter(foot_noise):
    """GroundTracker(foot_noise=...) frame by frame: homocal measure --foot-noise's forward filter on the file
    (each box's sigma from its height, the split, the correlated foot error in the state)."""
    mapping = ViewTransformer(CAMERA.project_ground(GROUND), GROUND)
    out = run(GroundTracker(mapping, FPS, foot_noise=foot_noise), lambda xyxy, ids: SimpleNamespace(xyxy=xyxy, tracker_id=ids))
    check_against_the_file_filter(out, foot_noise)
    fixed = run(GroundTracker(mapping, FPS), lambda xyxy, ids: SimpleNamespace(xyxy=xyxy, tracker_id=ids))
    assert out[(19, 0)][3] != fixed[(19, 0)][3]  # another model: another bar
    with pytest.raises(ValueError, match="foot_noise: expected one of fixed, box-height, correlated"):
        GroundTracker(mapping, FPS, foot_noise="white")


@pytest.mark.parametrize("foot_noise", FOOT_NOISE[::2])
def test_two_regime_model_as_the_file_filter(foot_noise):
    """GroundTracker(accel_psd=IMM) frame by frame: homocal measure --accel-psd imm's forward IMM filter on the
    file (white and correlated foot error); its bars are not the single q's."""
    mapping = ViewTransformer(CAMERA.project_ground(GROUND), GROUND)
    out = run(GroundTracker(mapping, FPS, accel_psd=IMM, foot_noise=foot_noise),
              lambda xyxy, ids: SimpleNamespace(xyxy=xyxy, tracker_id=ids))
    check_against_the_file_filter(out, foot_noise, accel_psd=IMM)
    single = run(GroundTracker(mapping, FPS, foot_noise=foot_noise), lambda xyxy, ids: SimpleNamespace(xyxy=xyxy, tracker_id=ids))
    assert out[(19, 0)][3] != single[(19, 0)][3]
    with pytest.raises(ValueError, match="accel_psd: expected a number"):
        GroundTracker(mapping, FPS, accel_psd="fitted")


@pytest.mark.parametrize("foot_noise, accel_psd", [("fixed", ACCEL_PSD), ("fixed", IMM)])
def test_student_tails_as_the_file_filter(foot_noise, accel_psd):
    """GroundTracker(foot_tails="student") frame by frame: homocal measure --foot-noise-tails student's forward
    filter on the file (one model and the IMM); its bars are not the normal noise's."""
    mapping = ViewTransformer(CAMERA.project_ground(GROUND), GROUND)
    make = lambda xyxy, ids: SimpleNamespace(xyxy=xyxy, tracker_id=ids)  # noqa: E731
    out = run(GroundTracker(mapping, FPS, accel_psd=accel_psd, foot_noise=foot_noise, foot_tails="student"), make)
    check_against_the_file_filter(out, foot_noise, accel_psd=accel_psd, foot_tails="student")
    normal = run(GroundTracker(mapping, FPS, accel_psd=accel_psd, foot_noise=foot_noise), make)
    assert out[(19, 0)][3] != normal[(19, 0)][3]
    with pytest.raises(ValueError, match="foot_tails student: needs foot_noise fixed, not correlated"):
        GroundTracker(mapping, FPS, foot_noise="correlated", foot_tails="student")


def test_homocal_never_imports_supervision():
    code = "import sys, homocal, homocal.measure, homocal.cli; print('supervision' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout == "False\n"
