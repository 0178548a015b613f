"""Feet that are not the sole (homocal measure --feet soles, GroundTracker(feet="soles")): which boxes (foot_status,
against boxes drawn by hand), and a foot point not used is no measurement: the filter on a track whose feet are
hidden for some frames is the filter on the track without those frames, and the smoother there the batch
least-squares solution of the track's model with those measurements left out."""
import json
from types import SimpleNamespace

import numpy as np
import pyarrow.parquet as pq
import pytest
from test_kalman import batch_solution
from test_live import FPS, GROUND, CAMERA, check_against_the_file_filter, run, walkers
from test_measure_cli import scene, truth, walker_rows, write_csv  # noqa: F401 (scene: the fixture)

from cli_run import homocal_main
from homocal.geometry import ViewTransformer
from homocal.geometry.boxes import BORDER_PX, box_edges
from homocal.measure import GroundTracker, fit_tracks_accel_psd, measure_tracks
from homocal.measure.kalman import ACCEL_PSD, ACCEL_PSD_LOG_TOLERANCE
from homocal.measure.tracks import FOOT, foot_status
from homocal.uncertainty import ground_uncertainty

SIZE = (640, 480)
STATE = ["x_smooth", "y_smooth", "vx", "vy", "speed_mps", "speed_sigma_mps"]


def test_foot_status_of_boxes_drawn_by_hand():
    w, h = SIZE
    edges = np.array([
        [100, 100, 140, 200],  # 0: its bottom (200) below the top of box 1 (190), which stands lower: hidden
        [110, 190, 150, 300],  # 1: nearer, nothing in front of it: used
        [300, 100, 340, 200],  # 2: box 3 is lower and overlaps its columns but starts below 201: used
        [320, 202, 360, 300],  # 3: used
        [400, 50, 440, h - 0.5 - BORDER_PX],  # 4: its bottom on the border: border
        [-0.5 + BORDER_PX, 50, 40, 150],  # 5: its left side on the border: border
        [500, -0.5, 540, 150],  # 6: its top cut, its feet seen: used
        [100, 100, 140, 200],  # 7: box 0 again in another frame, alone there: used
    ], dtype=float)
    frames = np.array([0, 0, 0, 0, 0, 0, 0, 1])
    assert foot_status(edges, frames, SIZE).tolist() == ["hidden", "used", "used", "used", "border", "border", "used",
                                                         "used"]
    assert foot_status(edges, frames, None).tolist() == ["hidden"] + ["used"] * 7  # no image size: no border


def hidden_walker():
    """A walker's frames (L,), feet (L, 2) px with 1 px noise and foot (L,): hidden in frames 8-12, on the border
    in frame 20."""
    rng = np.random.default_rng(8)
    frames = np.arange(25)
    ground = np.array([-1.0, 12.0]) + np.outer(frames / FPS, [0.6, 1.1])
    feet = CAMERA.project_ground(ground) + rng.normal(0, 1.0, (len(frames), 2))
    foot = np.full(len(frames), FOOT[0])
    foot[8:13], foot[20] = FOOT[1], FOOT[2]
    return frames, feet, foot


@pytest.mark.parametrize("smooth", [True, False])
def test_a_hidden_foot_is_no_measurement(smooth):
    mapping = ViewTransformer(CAMERA.project_ground(GROUND), GROUND)
    frames, feet, foot = hidden_walker()
    ids = np.zeros(len(frames), np.int64)
    (out,) = measure_tracks(mapping, frames, feet, ids, FPS, smooth=smooth, foot=foot)
    kept = foot == FOOT[0]
    (alone,) = measure_tracks(mapping, frames[kept], feet[kept], ids[kept], FPS, smooth=smooth)
    for c in STATE:
        np.testing.assert_allclose(out[c][kept], alone[c], rtol=1e-9, atol=1e-12, err_msg=c)
    assert out["foot"].tolist() == foot.tolist()
    np.testing.assert_allclose(np.column_stack([out["x"], out["y"]]), mapping.transform_points(feet), atol=1e-9)
    if smooth:  # every row, the hidden ones too: the batch solution without their measurements
        z = mapping.transform_points(feet)
        z[~kept] = np.nan
        mean, _ = batch_solution(frames / FPS, z, ground_uncertainty(mapping, feet, 1.5, 1.0), ACCEL_PSD)
        state = np.column_stack([out[c] for c in STATE[:4]])
        np.testing.assert_allclose(state, mean, rtol=0, atol=1e-8 * np.abs(mean).max())


def test_a_hidden_foot_is_left_out_of_the_fitted_q():
    """The innovations' likelihood sums the measured steps only, and the motion model's prediction over two steps
    is its prediction over their sum: q fitted with feet hidden is q fitted on the tracks without those frames."""
    mapping = ViewTransformer(CAMERA.project_ground(GROUND), GROUND)
    rng = np.random.default_rng(9)
    frames, ids, feet = np.tile(np.arange(40), 3), np.repeat(np.arange(3), 40), []
    for start in ([-2.0, 12.0], [1.0, 18.0], [0.0, 25.0]):  # walkers whose velocity wanders (q 0.5 m^2/s^3)
        v = np.array([0.5, 1.0]) + np.cumsum(rng.normal(0, np.sqrt(0.5 / FPS), (40, 2)), axis=0)
        feet.append(CAMERA.project_ground(start + np.cumsum(v, axis=0) / FPS) + rng.normal(0, 1.0, (40, 2)))
    feet = np.vstack(feet)
    foot = np.where((frames % 10 >= 6) & (frames % 10 <= 8), FOOT[1], FOOT[0])  # hidden 3 frames in 10
    feet[foot == FOOT[1], 1] -= 10  # a hidden foot: the box ends above it
    kept = foot == FOOT[0]
    q = fit_tracks_accel_psd(mapping, frames, feet, ids, FPS, foot=foot)
    alone = fit_tracks_accel_psd(mapping, frames[kept], feet[kept], ids[kept], FPS)
    every = fit_tracks_accel_psd(mapping, frames, feet, ids, FPS)
    # the same likelihood to rounding: the same bounded search's answer, within its tolerance in ln q
    assert abs(np.log(q / alone)) <= ACCEL_PSD_LOG_TOLERANCE, (q, alone)
    assert abs(np.log(q / every)) > 10 * ACCEL_PSD_LOG_TOLERANCE, (q, every)  # the hidden feet do count otherwise


def test_a_track_with_no_foot_measured_has_no_state():
    mapping = ViewTransformer(CAMERA.project_ground(GROUND), GROUND)
    frames, feet, foot = hidden_walker()
    foot[:5] = FOOT[1]
    (smoothed,) = measure_tracks(mapping, frames, feet, np.zeros(len(frames), np.int64), FPS, foot=foot)
    assert np.isfinite(smoothed["vx"]).all()  # the smoother carries the later measurements back
    (filtered,) = measure_tracks(mapping, frames, feet, np.zeros(len(frames), np.int64), FPS, smooth=False, foot=foot)
    assert np.isnan(filtered["vx"][:5]).all() and np.isfinite(filtered["vx"][5:]).all()
    (none,) = measure_tracks(mapping, frames, feet, np.zeros(len(frames), np.int64), FPS,
                             foot=np.full(len(frames), FOOT[1]))
    assert all(np.isnan(none[c]).all() for c in STATE) and np.isfinite(none["x"]).all()


def test_live_soles_as_the_file_filter():
    """GroundTracker(feet="soles", image_size=...) frame by frame: the file's forward filter with foot_status's feet
    (the image 40 px shorter so that the near walker's first feet fall on its border)."""
    mapping = ViewTransformer(CAMERA.project_ground(GROUND), GROUND)
    size = (CAMERA.width, 440)
    make = lambda xyxy, ids: SimpleNamespace(xyxy=xyxy, tracker_id=ids)  # noqa: E731
    out = run(GroundTracker(mapping, FPS, feet="soles", image_size=size), make)
    frames, _, boxes = walkers()
    foot = foot_status(box_edges(boxes, convention="corners"), frames, size)
    assert 0 < (foot == "border").sum() < len(foot) // 2
    check_against_the_file_filter(out, foot=foot)
    with pytest.raises(ValueError, match="feet: expected one of all, soles"):
        GroundTracker(mapping, FPS, feet="sole")
    with pytest.raises(ValueError, match="image_size: expected"):
        GroundTracker(mapping, FPS, feet="soles", image_size=(640.5, 480))


def test_measure_soles_writes_why(scene, capsys, monkeypatch):  # noqa: F811 (scene: the fixture)
    """A nearer box (track 7) in front of walker 0's feet in frames 20-29, and walker 1 passing behind walker 2
    (standing nearer, its box 80 px tall: walker 1's feet hidden while their 20 px wide boxes share columns): with
    --feet soles those rows are "hidden", their x, y still the mapped foot point, the smoothed path through them
    near the truth."""
    rows = walker_rows()
    front = [(f, 7, x1 - 5, y2 - 20, x2 + 5, y2 + 60) for f, k, x1, y1, x2, y2 in rows if k == 0 and 20 <= f < 30]
    write_csv(scene / "boxes.csv", rows + front)
    for feet in ("all", "soles"):
        r = homocal_main("measure", "trap.json", "--boxes", "boxes.csv", "--fps", "10", "--out", f"{feet}.parquet",
                         "--feet", feet, cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
        assert r.returncode == 0, r.stderr
    every, soles = (pq.read_table(scene / f"{feet}.parquet").to_pandas() for feet in ("all", "soles"))
    assert set(every.foot) == {"used"}
    u1, u2 = (CAMERA.project_ground(truth(k, soles.frame.to_numpy()))[:, 0] for k in (1, 2))
    hidden = (((soles.track_id == 0) & soles.frame.between(20, 29))
              | ((soles.track_id == 1) & (np.abs(u1 - u2) < 20))).to_numpy()
    assert 10 < hidden.sum() < 40
    assert f"Feet not measured (predicted through): {hidden.sum()} hidden." in r.stdout
    assert soles.foot[hidden].eq("hidden").all() and soles.foot[~hidden].eq("used").all()
    np.testing.assert_array_equal(soles[["x", "y"]], every[["x", "y"]])
    walker = soles[soles.track_id == 0]
    np.testing.assert_allclose(walker[["x_smooth", "y_smooth"]], truth(0, walker.frame.to_numpy()), atol=0.05)


def test_measure_soles_on_the_border_of_a_mot_sequence(scene, capsys, monkeypatch):  # noqa: F811 (scene: the fixture)
    """seqinfo.ini gives the image size (1280 x 470): walker 0's first boxes, cut by the frame's bottom (their
    bottom edge at the border, as a detector clips them), are "border" with --feet soles, and no other box."""
    (scene / "SEQ" / "gt").mkdir(parents=True)
    (scene / "SEQ" / "seqinfo.ini").write_text("[Sequence]\nname=x\nframeRate=10\nseqLength=60\nimWidth=1280\nimHeight=470\n")
    rows = [(f, k, x1, y1, x2, min(y2, 470.0)) for f, k, x1, y1, x2, y2 in walker_rows()]  # corners: the frame ends at 470
    lines = [f"{f + 1},{k + 1},{x1 + 1},{y1 + 1},{x2 - x1},{y2 - y1},1,1,1\n" for f, k, x1, y1, x2, y2 in rows]
    (scene / "SEQ" / "gt" / "gt.txt").write_text("".join(lines))
    r = homocal_main("measure", "trap.json", "--boxes", "SEQ/gt/gt.txt", "--out", "tracks.parquet", "--feet", "soles",
                     cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    tracks = pq.read_table(scene / "tracks.parquet").to_pandas()
    # homocal's edge is the corner's - 0.5, within BORDER_PX of 469.5; the output's frames 0-based
    cut = {(f, k + 1) for f, k, x1, y1, x2, y2 in rows if y2 >= 470 - BORDER_PX}
    assert 0 < len(cut) < 10
    assert {(f, k) for f, k, foot in zip(tracks.frame, tracks.track_id, tracks.foot) if foot == "border"} == cut


def test_the_border_is_tested_in_the_cameras_own_pixels(tmp_path, capsys, monkeypatch):
    """A trapezoid and boxes on a barrel lens's frame, --camera-json: the lens gives the image size (a .csv says
    none). A box 15 px above the frame's bottom near its corner is used, though undistorted it lies beyond the
    border; a box whose bottom edge is the frame's is "border"."""
    from homocal.geometry import Lens
    from homocal.geometry.boxes import undistort_boxes

    lens = Lens(CAMERA.K, [-0.2, 0.04, 5e-4, -3e-4, -0.002], (1280, 720))
    (tmp_path / "trap.json").write_text(json.dumps({"image": lens.distort_points(CAMERA.project_ground(GROUND)).tolist(),
                                                    "map": GROUND.tolist()}))
    (tmp_path / "lens.json").write_text(json.dumps(lens.to_dict()))
    inside, cut = [100.0, 600.0, 120.0, 705.0], [600.0, 600.0, 620.0, 720.0]  # CSV corners: the frame ends at 720
    write_csv(tmp_path / "boxes.csv", [(f, k, *box) for f in range(3) for k, box in enumerate([inside, cut])])
    assert undistort_boxes(np.array([inside]) - 0.5, lens)[0, 3] > 720  # undistorted, beyond the border
    r = homocal_main("measure", "trap.json", "--boxes", "boxes.csv", "--fps", "10", "--camera-json", "lens.json",
                     "--feet", "soles", "--out", "t.parquet", cwd=tmp_path, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    tracks = pq.read_table(tmp_path / "t.parquet").to_pandas()
    assert tracks.groupby("track_id").foot.unique().map(list).to_dict() == {0: ["used"], 1: ["border"]}
    assert np.isnan(tracks.speed_mps[tracks.track_id == 1]).all()  # no foot measured: nothing known
