"""homocal measure on walkers of a known camera: their speeds, paths and distances against the truth the camera
gives; bad input as one line, exit 2, nothing written."""
import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from cli_run import homocal_main
from homocal.geometry import PinholeCamera
from homocal.measure import COLUMNS
from homocal.measure.kalman import ACCEL_PSD, ACCEL_PSD_BOUNDS
from homocal.measure.tracks import FOOT_SIGMA_PER_BOX_HEIGHT, STUDENT_FOOT_NOISE

CAMERA = PinholeCamera()  # 1280x720, 4 m high, 15 degrees down
FPS = 10.0
WALKERS = [(-4.0, 8.0, 0.3, 1.3), (5.0, 30.0, -1.0, -0.8), (0.5, 20.0, 0.0, 0.0)]  # x0, y0 (m), vx, vy (m/s)
FRAMES = 60


def truth(k: int, frames: np.ndarray) -> np.ndarray:
    x0, y0, vx, vy = WALKERS[k]
    return np.column_stack([x0 + vx * frames / FPS, y0 + vy * frames / FPS])


def write_csv(path, rows):
    path.write_text("frame,track_id,x1,y1,x2,y2\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))


def walker_rows(frames=np.arange(FRAMES)):
    """CSV rows of the walkers' boxes, pixel corners at integers (the CSV's convention): a foot point's homocal
    row v is the corner row v + 0.5."""
    rows = []
    for k in range(len(WALKERS)):
        for f, (u, v) in zip(frames, CAMERA.project_ground(truth(k, frames))):
            rows.append((int(f), k, u - 10 + 0.5, v - 80 + 0.5, u + 10 + 0.5, v + 0.5))
    return rows


@pytest.fixture
def scene(tmp_path):
    ground = np.array([[-3.0, 40.0], [3.0, 40.0], [3.0, 10.0], [-3.0, 10.0]])
    (tmp_path / "trap.json").write_text(json.dumps({"image": CAMERA.project_ground(ground).tolist(), "map": ground.tolist()}))
    write_csv(tmp_path / "boxes.csv", walker_rows())
    return tmp_path


def test_speeds_paths_and_distances_of_known_walkers(scene, capsys, monkeypatch):
    r = homocal_main("measure", "trap.json", "--boxes", "boxes.csv", "--fps", "10", "--out", "tracks.parquet",
                     "--summary", "summary.parquet", "--pairs", "pairs.parquet", cwd=scene, capsys=capsys,
                     monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("homocal measure: 180 boxes in 3 tracks (tracks of the file)")
    tracks = pq.read_table(scene / "tracks.parquet").to_pandas()
    assert list(tracks.columns) == list(COLUMNS)
    for k, track in tracks.groupby("track_id"):
        assert track.frame.tolist() == list(range(FRAMES))
        np.testing.assert_allclose(track.t, track.frame / FPS)
        true = truth(k, track.frame.to_numpy())
        # the exact trapezoid maps exact foot points exactly (closed-form homography, float64)
        np.testing.assert_allclose(track[["x", "y"]], true, atol=1e-6)
        # noise-free constant velocity: the smoother recovers it up to its 0-velocity start prior's pull
        speed = np.hypot(*WALKERS[k][2:])
        np.testing.assert_allclose(track.speed_mps, speed, atol=0.02)
        np.testing.assert_allclose(track[["x_smooth", "y_smooth"]], true, atol=0.02)
        assert (track.speed_sigma_mps > 0).all() and (track.sigma_m > 0).all()
    summary = pq.read_table(scene / "summary.parquet").to_pandas()
    for k, row in summary.iterrows():
        speed = np.hypot(*WALKERS[k][2:])
        assert row.frames == FRAMES and row.duration_s == pytest.approx((FRAMES - 1) / FPS)
        assert row.path_length_m == pytest.approx(speed * row.duration_s, abs=0.05)
        assert row.stationary_s == pytest.approx(row.duration_s if speed == 0 else 0.0)
    pairs = pq.read_table(scene / "pairs.parquet").to_pandas()
    assert len(pairs) == 3 * FRAMES
    for _, p in pairs.iloc[::17].iterrows():
        f = np.array([p.frame])
        true = np.linalg.norm(truth(int(p.track_a), f) - truth(int(p.track_b), f))
        assert p.distance_m == pytest.approx(true, abs=1e-6) and 0 < p.distance_sigma_m < 5


def test_rerun_replaces_its_own_output_only(scene, capsys, monkeypatch):
    (scene / "mine.parquet").write_text("a user's file")
    r = homocal_main("measure", "trap.json", "--boxes", "boxes.csv", "--fps", "10", "--out", "mine.parquet",
                     cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 2 and (scene / "mine.parquet").read_text() == "a user's file"


def _one_frame(tmp):
    write_csv(tmp / "bad.csv", [(0, k, 100, 400, 120, 500) for k in range(3)])


def _out_of_order(tmp):
    rows = walker_rows()
    rows[3], rows[4] = rows[4], rows[3]
    write_csv(tmp / "bad.csv", rows)


def _duplicate(tmp):
    rows = walker_rows()
    write_csv(tmp / "bad.csv", rows[:5] + [rows[4]] + rows[5:])


def _other_image(tmp):
    (tmp / "SEQ" / "gt").mkdir(parents=True)
    (tmp / "SEQ" / "seqinfo.ini").write_text("[Sequence]\nname=x\nframeRate=10\nseqLength=100\nimWidth=640\nimHeight=360\n")
    (tmp / "SEQ" / "gt" / "gt.txt").write_text("".join(f"{f + 1},1,100,100,20,80,1,1,1\n" for f in range(5)))


def _empty(tmp):
    (tmp / "bad.csv").write_text("frame,track_id,x1,y1,x2,y2\n")


def _nan(tmp):
    write_csv(tmp / "bad.csv", walker_rows()[:3] + [(3, 0, "nan", 400, 120, 500)])


BAD = [  # (writes the boxes, extra arguments, the error's words)
    (_one_frame, ["--boxes", "bad.csv", "--fps", "10"], "no track has 2 frames or more"),
    (_out_of_order, ["--boxes", "bad.csv", "--fps", "10"], "track 0 goes back from frame 4 to frame 3"),
    (_duplicate, ["--boxes", "bad.csv", "--fps", "10"], "track 0 has two boxes in frame 4"),
    (_other_image, ["--boxes", "SEQ/gt/gt.txt"], "outside the 640x360 image"),
    (_empty, ["--boxes", "bad.csv", "--fps", "10"], "no boxes"),
    (_nan, ["--boxes", "bad.csv", "--fps", "10"], "not a finite number"),
    (walker_rows, ["--boxes", "boxes.csv", "--fps", "0"], "argument --fps: must be a finite number in (0, 1000]"),
    (walker_rows, ["--boxes", "boxes.csv", "--fps", "nan"], "argument --fps: must be a finite number in (0, 1000]"),
    (walker_rows, ["--boxes", "boxes.csv", "--fps", "1e9"], "argument --fps: must be a finite number in (0, 1000]"),
    (walker_rows, ["--boxes", "boxes.csv"], "--fps: required (boxes.csv does not say its frame rate)"),
    (walker_rows, ["--boxes", "boxes.csv", "--fps", "10", "--foot-noise", "bogus"], "argument --foot-noise: invalid choice"),
    (walker_rows, ["--boxes", "boxes.csv", "--fps", "10", "--feet", "heels"], "argument --feet: invalid choice: 'heels'"),
    (walker_rows, ["--boxes", "boxes.csv", "--fps", "10", "--foot-noise-tails", "cauchy"],
     "argument --foot-noise-tails: invalid choice: 'cauchy'"),
    (walker_rows, ["--boxes", "boxes.csv", "--fps", "10", "--foot-noise-tails", "student", "--foot-noise", "correlated"],
     "--foot-noise-tails student: needs --foot-noise fixed, not correlated"),
    (walker_rows, ["--boxes", "boxes.csv", "--fps", "10", "--accel-psd", "fast"],
     "argument --accel-psd: fitted, imm or a number: expected a number, got 'fast'"),
    (walker_rows, ["--boxes", "boxes.csv", "--fps", "10", "--accel-psd", "0"],
     "argument --accel-psd: fitted, imm or a number: must be a finite number in (0, 1e+06], got 0"),
    (walker_rows, ["--boxes", "boxes.csv", "--fps", "10", "--camera-json", "missing.json"], "--camera-json missing.json: no such file"),
    (walker_rows, ["--boxes", "boxes.csv", "--fps", "10", "--camera-json", "trap.json"], "--camera-json trap.json: image_size: missing"),
]


@pytest.mark.parametrize("write, extra, words", BAD, ids=[w.__name__ + "-" + e[-1] for w, e, _ in BAD])
def test_bad_input_is_one_line_and_writes_nothing(scene, capsys, monkeypatch, write, extra, words):
    if write is not walker_rows:
        write(scene)
    before = sorted(p.name for p in scene.rglob("*"))
    r = homocal_main("measure", "trap.json", *extra, "--out", "tracks.parquet", "--summary", "s.parquet", "--pairs",
                     "p.parquet", cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 2
    assert r.stderr.startswith("homocal: error: ") and r.stderr.count("\n") == 1 and words in r.stderr, r.stderr
    assert sorted(p.name for p in scene.rglob("*")) == before


def test_mot_sequence_gives_fps_and_tracks(scene, capsys, monkeypatch):
    """A MOT gt.txt beside seqinfo.ini: its frame rate and image size come from seqinfo.ini, its ids are the
    tracks (MOT frames 1-based, boxes 1-based pixels: bb_left = x1 + 1.5)."""
    (scene / "SEQ" / "gt").mkdir(parents=True)
    (scene / "SEQ" / "seqinfo.ini").write_text("[Sequence]\nname=x\nframeRate=10\nseqLength=60\nimWidth=1280\nimHeight=720\n")
    lines = [f"{f + 1},{k + 1},{x1 - 0.5 + 1.5},{y1 - 0.5 + 1.5},{x2 - x1},{y2 - y1},1,1,1\n"
             for f, k, x1, y1, x2, y2 in walker_rows()]
    (scene / "SEQ" / "gt" / "gt.txt").write_text("".join(lines))
    r = homocal_main("measure", "trap.json", "--boxes", "SEQ/gt/gt.txt", "--out", "tracks.parquet", cwd=scene,
                     capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    assert "180 boxes in 3 tracks (tracks of the file)" in r.stdout and "at 10 fps" in r.stdout
    tracks = pq.read_table(scene / "tracks.parquet").to_pandas()
    assert sorted(tracks.track_id.unique()) == [1, 2, 3]
    np.testing.assert_allclose(tracks[tracks.track_id == 1][["x", "y"]], truth(0, np.arange(FRAMES)), atol=1e-6)


def test_pairs_refuse_a_crowded_frame_before_writing(scene, capsys, monkeypatch):
    monkeypatch.setattr("homocal.measure.tracks.MAX_PEOPLE_PER_FRAME", 2)
    r = homocal_main("measure", "trap.json", "--boxes", "boxes.csv", "--fps", "10", "--out", "tracks.parquet",
                     "--pairs", "pairs.parquet", cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 2 and "--pairs: boxes.csv: frame 0 has 3 people: at most 2 a frame" in r.stderr, r.stderr
    assert not (scene / "tracks.parquet").exists() and not (scene / "pairs.parquet").exists()


def test_a_track_longer_than_the_bound_is_refused(scene, capsys, monkeypatch):
    monkeypatch.setattr("homocal.measure.cli.MAX_TRACK_FRAMES", FRAMES - 1)
    r = homocal_main("measure", "trap.json", "--boxes", "boxes.csv", "--fps", "10", "--out", "tracks.parquet",
                     cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 2 and f"a track of {FRAMES} frames: at most {FRAMES - 1}" in r.stderr, r.stderr
    assert not (scene / "tracks.parquet").exists()


@pytest.mark.slow
def test_a_trapezoid_on_a_distorted_camera_takes_the_lens(tmp_path, capsys, monkeypatch):
    """A trapezoid clicked on a wide lens's frame and boxes from it: with --camera-json (a lens.json) the feet and
    the corners are undistorted before the homography, so the exact clicks map the walkers to their true ground
    points (the lens's exact inverse: within 1e-4 m); without it they land a tenth of a metre off. A correction file with
    --camera-json is refused in one line (it carries its own lens)."""
    from homocal.geometry import Lens

    lens = Lens(CAMERA.K, [-0.2, 0.04, 5e-4, -3e-4, -0.002], (1280, 720))
    ground = np.array([[-3.0, 40.0], [3.0, 40.0], [3.0, 10.0], [-3.0, 10.0]])
    (tmp_path / "trap.json").write_text(json.dumps({"image": lens.distort_points(CAMERA.project_ground(ground)).tolist(),
                                                    "map": ground.tolist()}))
    (tmp_path / "lens.json").write_text(json.dumps(lens.to_dict()))
    frames = np.arange(FRAMES)
    rows = [(int(f), k, u - 10 + 0.5, v - 80 + 0.5, u + 10 + 0.5, v + 0.5) for k in range(len(WALKERS))
            for f, (u, v) in zip(frames, lens.distort_points(CAMERA.project_ground(truth(k, frames))))]
    write_csv(tmp_path / "boxes.csv", rows)
    off = {}
    for flags in (["--camera-json", "lens.json"], []):
        r = homocal_main("measure", "trap.json", "--boxes", "boxes.csv", "--fps", "10", *flags, "--out", "t.parquet",
                         cwd=tmp_path, capsys=capsys, monkeypatch=monkeypatch)
        assert r.returncode == 0, r.stderr
        tracks = pq.read_table(tmp_path / "t.parquet").to_pandas()
        off[bool(flags)] = max(np.abs(track[["x", "y"]].to_numpy() - truth(k, track.frame.to_numpy())).max()
                               for k, track in tracks.groupby("track_id"))
    assert off[True] < 1e-4 and off[False] > 0.05, off  # lens-blind: 0.12 m
    ref = np.array([[0.0, 12.0], [1.0, 20.0], [-1.0, 30.0]])
    (tmp_path / "ref.csv").write_text("u,v,x,y\n" + "".join(
        f"{float(u)!r},{float(v)!r},{float(x)!r},{float(y)!r}\n" for (u, v), (x, y) in zip(lens.distort_points(CAMERA.project_ground(ref)), ref)))
    r = homocal_main("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "--method", "horizon", "--camera-json",
                     "lens.json", "--out", "c.json", cwd=tmp_path, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    r = homocal_main("measure", "c.json", "--boxes", "boxes.csv", "--fps", "10", "--camera-json", "lens.json",
                     "--out", "u.parquet", cwd=tmp_path, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "carries the lens it was fitted with" in r.stderr
    assert not (tmp_path / "u.parquet").exists()


def test_foot_noise_by_box_height(scene, capsys, monkeypatch):
    """--foot-noise box-height: each foot point's (u, v) sigmas FOOT_SIGMA_PER_BOX_HEIGHT x its box's 80 px, so
    sigma_m is that of the mapping at the smaller of the two as one --point-sigma-px (fixed) or more, and at the
    larger or less (the covariance is monotonic in each sigma), and the noise-free walkers' speeds stay."""
    out = {}
    low, high = (f"{80 * s!r}" for s in sorted(FOOT_SIGMA_PER_BOX_HEIGHT))
    for name, extra in (("box", ["--foot-noise", "box-height"]), ("low", ["--point-sigma-px", low]),
                        ("high", ["--point-sigma-px", high])):
        r = homocal_main("measure", "trap.json", "--boxes", "boxes.csv", "--fps", "10", "--out", f"{name}.parquet",
                         *extra, cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
        assert r.returncode == 0, r.stderr
        out[name] = pq.read_table(scene / f"{name}.parquet").to_pandas()
    assert (out["low"].sigma_m <= out["box"].sigma_m * (1 + 1e-12)).all()
    assert (out["box"].sigma_m <= out["high"].sigma_m * (1 + 1e-12)).all()
    assert (out["box"].sigma_m > 1.01 * out["low"].sigma_m).any() and (out["box"].sigma_m < 0.99 * out["high"].sigma_m).any()
    for k, track in out["box"].groupby("track_id"):
        np.testing.assert_allclose(track.speed_mps, np.hypot(*WALKERS[k][2:]), atol=0.02)


def test_foot_noise_correlated(scene, capsys, monkeypatch):
    """--foot-noise correlated: box-height's sigmas with the foot error an AR(1) in the filter: the same sigma_m,
    the noise-free walkers' speeds stay, and the speed's bar is wider than box-height's inside the tracks (a
    correlated error averages away more slowly than a white one of the same size)."""
    out = {}
    for name in ("box-height", "correlated"):
        r = homocal_main("measure", "trap.json", "--boxes", "boxes.csv", "--fps", "10", "--out", f"{name}.parquet",
                         "--foot-noise", name, cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
        assert r.returncode == 0, r.stderr
        out[name] = pq.read_table(scene / f"{name}.parquet").to_pandas()
    np.testing.assert_array_equal(out["correlated"].sigma_m, out["box-height"].sigma_m)
    for k, track in out["correlated"].groupby("track_id"):
        np.testing.assert_allclose(track.speed_mps, np.hypot(*WALKERS[k][2:]), atol=0.02)
    assert out["correlated"].speed_sigma_mps.median() > 1.1 * out["box-height"].speed_sigma_mps.median()



@pytest.mark.parametrize("foot_noise", list(STUDENT_FOOT_NOISE))
def test_foot_noise_tails_student(scene, capsys, monkeypatch, foot_noise):
    """--foot-noise-tails student: a foot point 40 px low in one frame (hidden feet) moves the walker's smoothed
    position and speed there less than with normal noise; the other frames' speeds stay the truth's, sigma_m
    the mapping's."""
    rows = walker_rows()
    k = next(i for i, r in enumerate(rows) if r[:2] == (30, 0))
    rows[k] = rows[k][:3] + (rows[k][3] + 40, rows[k][4], rows[k][5] + 40)
    write_csv(scene / "jump.csv", rows)
    out = {}
    for tails in ("normal", "student"):
        r = homocal_main("measure", "trap.json", "--boxes", "jump.csv", "--fps", "10", "--out", f"{tails}.parquet",
                         "--foot-noise", foot_noise, "--foot-noise-tails", tails, cwd=scene, capsys=capsys,
                         monkeypatch=monkeypatch)
        assert r.returncode == 0, r.stderr
        out[tails] = pq.read_table(scene / f"{tails}.parquet").to_pandas()
    np.testing.assert_array_equal(out["student"].sigma_m, out["normal"].sigma_m)
    true_speed = np.hypot(*WALKERS[0][2:])
    err = {k: np.abs(v[(v.track_id == 0) & (v.frame.between(27, 33))].speed_mps - true_speed).max() for k, v in out.items()}
    assert err["student"] < err["normal"] / 2, err
    far = out["student"][~out["student"].frame.between(20, 40)]
    for k, track in far.groupby("track_id"):
        np.testing.assert_allclose(track.speed_mps, np.hypot(*WALKERS[k][2:]), atol=0.02)


def test_accel_psd_fitted(scene, capsys, monkeypatch):
    """--accel-psd fitted on walkers at constant velocity with exact foot points: no acceleration in their
    innovations, so the likelihood's q is its lower bound (ACCEL_PSD_BOUNDS), printed, and the speeds stay."""
    r = homocal_main("measure", "trap.json", "--boxes", "boxes.csv", "--fps", "10", "--out", "fitted.parquet",
                     "--accel-psd", "fitted", cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    q = float(r.stdout.split("Process noise fitted to the tracks: ")[1].split(" m^2/s^3")[0])
    assert ACCEL_PSD_BOUNDS[0] <= q < 1.1 * ACCEL_PSD_BOUNDS[0]
    for k, track in pq.read_table(scene / "fitted.parquet").to_pandas().groupby("track_id"):
        np.testing.assert_allclose(track.speed_mps, np.hypot(*WALKERS[k][2:]), atol=0.02)


def test_accel_psd_imm(scene, capsys, monkeypatch):
    """--accel-psd imm on walkers at constant velocity: the speeds stay, and their bars are narrower than the
    default q's (the steady model's q is smaller; the walkers never manoeuvre, so it takes them)."""
    out = {}
    for q in ("imm", str(ACCEL_PSD)):
        r = homocal_main("measure", "trap.json", "--boxes", "boxes.csv", "--fps", "10", "--out", f"{q}.parquet",
                         "--accel-psd", q, cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
        assert r.returncode == 0, r.stderr
        out[q] = pq.read_table(scene / f"{q}.parquet").to_pandas()
    for k, track in out["imm"].groupby("track_id"):
        np.testing.assert_allclose(track.speed_mps, np.hypot(*WALKERS[k][2:]), atol=0.02)
    assert out["imm"].speed_sigma_mps.median() < out[str(ACCEL_PSD)].speed_sigma_mps.median()


def test_exact_foot_points_on_a_shorter_track(scene, capsys, monkeypatch):
    """--click-sigma-px 0 --point-sigma-px 0 (exact points: zero covariance) with a track shorter than another:
    the smoother's padding after its end is no singular matrix, and the noise-free walkers come out exact."""
    write_csv(scene / "short.csv", [r for r in walker_rows() if not (r[1] == 2 and r[0] >= 30)])
    r = homocal_main("measure", "trap.json", "--boxes", "short.csv", "--fps", "10", "--out", "short.parquet",
                     "--click-sigma-px", "0", "--point-sigma-px", "0", cwd=scene, capsys=capsys, monkeypatch=monkeypatch)
    assert r.returncode == 0, r.stderr
    tracks = pq.read_table(scene / "short.parquet").to_pandas()
    assert (tracks.track_id == 2).sum() == 30 and (tracks.sigma_m == 0).all()
    for k, track in tracks.groupby("track_id"):
        np.testing.assert_allclose(track[["x_smooth", "y_smooth"]], truth(k, track.frame.to_numpy()), atol=1e-6)
