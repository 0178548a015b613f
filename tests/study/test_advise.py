"""``homocal advise``: the simulated scene against the camera it stands for, the ranking against a study of the
same scene, the CSV, and bad input (one "homocal: error:" line, exit 2, nothing written)."""
import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from synthetic_dataset import GROUND_RECT, write_dataset
from cli_run import homocal_main  # homocal.cli.main in-process, as a CompletedProcess

from homocal.cli import main
from homocal.geometry import PinholeCamera, SiteMap, ViewTransformer
from homocal.study import advise as A
from homocal.study.inputs import StudyParams, StudyScene
from homocal.study.shards import compute_shard

CAM = PinholeCamera()
SITE_MAP = SiteMap(10.0, (200.0, 600.0))


def read_csv(path: Path) -> list[dict]:
    with path.open() as f:
        return list(csv.DictReader(f))


@pytest.fixture
def work(tmp_path: Path) -> Path:
    """trap.json: the paper camera's exact trapezoid, map in site-map pixels."""
    trapezoid = {"image": CAM.project_ground(GROUND_RECT).tolist(), "map": SITE_MAP.to_pixels(GROUND_RECT).tolist(),
                 "site_map": {"scale_px_per_m": 10.0, "origin_px": [200.0, 600.0]}}
    (tmp_path / "trap.json").write_text(json.dumps(trapezoid))
    return tmp_path


def test_scene_maps_the_positions_as_the_camera_does():
    """advise_scene's image points of the candidates and test points are the camera's own projections (the
    trapezoid is the exact one), the map quad is the site map's pixels and the triples are every C(M, 3)."""
    positions = A.candidate_positions([10.0, 20.0, 35.0], [-3.0, 0.0], (0.0, 0.0))
    assert positions.tolist() == [[-3, 10], [0, 10], [-3, 20], [0, 20], [-3, 35], [0, 35]]
    test = A.uniform_test_points(300, 4, (1.0, -2.0), (5.0, 50.0), 8.0)
    assert np.all(np.abs(test[:, 0] - 1.0) <= 8.0) and np.all((test[:, 1] >= 3.0) & (test[:, 1] <= 48.0))
    assert np.ptp(test[:, 0]) > 14 and np.ptp(test[:, 1]) > 40  # spread over the whole area
    vt = ViewTransformer(CAM.project_ground(GROUND_RECT), GROUND_RECT)
    scene = A.advise_scene(vt, SITE_MAP, positions, test, (0.0, 0.0))
    np.testing.assert_allclose(scene.cal_image, CAM.project_ground(positions), atol=1e-8)
    np.testing.assert_allclose(scene.test_image, CAM.project_ground(test), atol=1e-8)
    np.testing.assert_allclose(scene.map_quad, SITE_MAP.to_pixels(GROUND_RECT), atol=1e-9)
    np.testing.assert_allclose(scene.distance, np.hypot(positions[:, 0], positions[:, 1]))
    assert len(scene.triples) == math.comb(6, 3)
    assert ViewTransformer(scene.image_quad, scene.site_map.to_metres(scene.map_quad)).horizon_row(scene.K[0, 2]) == pytest.approx(
        CAM.horizon_row, abs=1e-6)


@pytest.fixture(scope="module")
def synthetic_study(tmp_path_factory):
    """(dataset folder, StudyScene, shards of variants 0..30): a study of a synthetic scene, 12 calibration points."""
    dataset = write_dataset(tmp_path_factory.mktemp("advise") / "ds", n_calibration=12, n_test=500, seed=0)
    params = StudyParams(n_variants=30, n_test=500)
    scene = StudyScene.from_dataset(dataset, params)
    return dataset, scene, [compute_shard(scene, params, v)[0] for v in range(params.n_variants + 1)]


@pytest.mark.parametrize("method", ["descent", "hybrid"])
def test_advised_triple_is_in_the_top_tenth_of_a_study(synthetic_study, tmp_path, method):
    """The issue's check, small: a study of a synthetic scene (its exact camera the truth, its hand-placed trapezoid
    1-2 px off, 30 variants) ranks the triples of its 12 calibration points by mean path improvement; advise, from the
    hand-placed trapezoid alone, picks a triple in that ranking's top 10 %. (Not asserted for regression-intercept:
    its triples lie within about 2 pp of each other in the study, and advise's pick lands near the middle there: see
    the README's "Where to put the reference points".)"""
    dataset, scene, shards = synthetic_study
    study_mean = np.array([shard.column(f"path_{method}").to_numpy() for shard in shards]).mean(axis=0)
    spec = ",".join(repr(float(d)) for d in scene.distance)
    out = tmp_path / "advice.csv"
    assert main(["advise", "--trapezoid", str(dataset / "trapezoids.json"), "--distances", spec, "--samples", "30",
                 "--method", method, "--test-lateral", "4", "--test-range", "5:45", "-o", str(out)]) == 0
    best = read_csv(out)[0]
    advised = sorted(int(np.argmin(np.abs(scene.distance - float(best[f"y{n}"])))) for n in (1, 2, 3))
    s = int(np.flatnonzero((scene.triples == advised).all(axis=1))[0])
    better = int((study_mean > study_mean[s]).sum())
    assert better < 0.1 * len(study_mean), (better, len(study_mean))
    assert np.median(study_mean) < study_mean[s] - 5  # a choice that matters: the median triple is far behind


def test_csv_ranks_every_triple_and_repeats_to_the_byte(work, capsys, monkeypatch):
    args = ["advise", "--trapezoid", "trap.json", "--distances", "10:30:10,40", "--lateral", "-3,0,3", "--samples", "8",
            "--method", "descent", "-o", "a.csv"]
    first = homocal_main(*args, cwd=work, capsys=capsys, monkeypatch=monkeypatch)
    assert first.returncode == 0, first.stderr
    text = (work / "a.csv").read_text()
    rows = read_csv(work / "a.csv")
    assert len(rows) == math.comb(12, 3) and [int(r["rank"]) for r in rows] == list(range(1, len(rows) + 1))
    mean, p5 = np.array([[float(r["mean_path"]), float(r["p5_path"])] for r in rows]).T
    assert np.all(np.diff(mean) <= 0) and np.all((np.diff(mean) < 0) | (np.diff(p5) <= 0))
    assert {float(r["x1"]) for r in rows} | {float(r["x3"]) for r in rows} == {-3.0, 0.0, 3.0}
    assert np.all(np.array([[float(r[k]) for k in ("mean_path", "median_path")] for r in rows]) >= p5[:, None] - 1e-9)
    top = rows[0]
    assert f"({float(top['x1']):g}, {float(top['y1']):g})" in first.stdout.splitlines()[2]
    assert f"{float(top['mean_path']):6.1f}%" in first.stdout.splitlines()[2]
    again = homocal_main(*args, cwd=work, capsys=capsys, monkeypatch=monkeypatch)  # replaces its own CSV
    assert again.returncode == 0 and (work / "a.csv").read_text() == text


def test_test_points_from_a_file(work, capsys, monkeypatch):
    ground = np.column_stack([np.linspace(-5, 5, 40), np.linspace(6, 45, 40)])
    (work / "tp.csv").write_text("id,x,y\n" + "".join(f"{i},{x!r},{y!r}\n" for i, (x, y) in enumerate(ground.tolist())))
    result = homocal_main("advise", "--trapezoid", "trap.json", "--distances", "10,20,30,40", "--samples", "4",
                          "--test-points", "tp.csv", cwd=work, capsys=capsys, monkeypatch=monkeypatch)
    assert result.returncode == 0, result.stderr
    assert "path improvement on 40 test points, from tp.csv" in result.stdout
    assert len(result.stdout.splitlines()) == 2 + 4 + 1  # header, table header, C(4, 3) triples, the spread


def test_samples_are_the_study_variants():
    """advise's figures for a triple are the mean and 5th percentile, over variants 1..N, of what the study's shard
    function computes for the same scene."""
    vt = ViewTransformer(CAM.project_ground(GROUND_RECT), GROUND_RECT)
    scene = A.advise_scene(vt, SITE_MAP, A.candidate_positions([8.0, 15.0, 30.0, 45.0], [0.0], (0, 0)),
                           A.uniform_test_points(200, 0, (0, 0)), (0, 0))
    advice = A.advise(scene, "horizon", 12, seed=3)
    params = StudyParams(seed=3, n_variants=12, n_test=200)
    path = np.array([compute_shard(scene, params, v)[0].column("path_horizon").to_numpy() for v in range(1, 13)])
    assert advice.n_used == 12 and not advice.skipped
    np.testing.assert_allclose(advice.mean, path.mean(axis=0), atol=1e-3)  # the shards hold float32
    np.testing.assert_allclose(advice.p5, np.percentile(path, 5, axis=0), atol=1e-3)
    assert advice.order[0] == np.argmax(advice.mean)


@pytest.mark.parametrize("name,extra,files,message", [
    ("no such file", ["--trapezoid", "missing.json"], {}, "missing.json: no such file"),
    ("two distances", ["--distances", "10,20"], {}, "need at least 3 distances"),
    ("NaN distance", ["--distances", "10,nan,20"], {}, "'nan' is not a finite number"),
    ("unparsable distance", ["--distances", "10,x,20"], {}, "'x' is not a number"),
    ("bad range", ["--distances", "50:5:1"], {}, "START <= STOP"),
    ("distance twice", ["--distances", "10,20,10"], {}, "'10' is given twice"),
    ("negative distance", ["--distances", "-5,10,20"], {}, "--distances"),
    ("zero distance", ["--distances", "0,10,20"], {}, "distances > 0"),
    ("unknown method", ["--method", "magic"], {}, "invalid choice: 'magic'"),
    ("zero samples", ["--samples", "0"], {}, "--samples and --top must be >= 1"),
    ("lateral NaN", ["--lateral", "0,nan"], {}, "--lateral"),
    ("bad test range", ["--test-range", "50:5"], {}, "--test-range '50:5'"),
    ("negative test lateral", ["--test-lateral", "-1"], {}, "--test-lateral must be"),
    ("zero map scale", ["--map-scale", "0"], {}, "--map-scale must be"),
    ("too many samples", ["--distances", "1:100:0.5", "--samples", "100"], {}, "over 20,000,000 samples"),
    ("behind the camera", ["--camera-origin", "0,-40"], {}, "behind the camera"),
    ("output folder missing", ["-o", "nowhere/a.csv"], {}, "the folder nowhere does not exist"),
    ("output not ours", ["-o", "notes.csv"], {"notes.csv": "mine\n"}, "not a homocal advise CSV"),
    ("test points without y", ["--test-points", "tp.csv"], {"tp.csv": "x\n1\n"}, "tp.csv: missing column(s) y"),
    ("no test points", ["--test-points", "tp.csv"], {"tp.csv": "x,y\n"}, "tp.csv: no test points"),
    ("test point behind the camera", ["--test-points", "tp.csv"], {"tp.csv": "x,y\n0,10\n1,-3\n"},
     "test point (1, -3) m lies behind the camera"),
    ("bad trapezoid", [], {"trap.json": '{"image": [[0, 0]], "map": []}'}, "trap.json"),
    ("too many test points", ["--test-points", "tp.csv"],
     {"tp.csv": "x,y\n" + "".join(f"{i % 7},{10 + i / 1e4}\n" for i in range(100_001))},
     "tp.csv, line 100002: more than 100,000 points"),
    ("too many reference positions", ["--distances", "1:1000:1", "--lateral", "-50:50:1"], {},
     "--distances x --lateral: 101,000 reference positions, at most 100,000"),
    ("--output is not a flag", ["--output", "b.csv"], {}, "unrecognized arguments: --output"),
])
def test_bad_input(work, name, extra, files, message, capsys, monkeypatch):
    for file, text in files.items():
        (work / file).write_text(text)
    before = {p.name: p.read_bytes() for p in work.iterdir()}
    result = homocal_main("advise", "--trapezoid", "trap.json", "--distances", "10,20,30", "--samples", "2",
                          "-o", "a.csv", *extra, cwd=work, capsys=capsys, monkeypatch=monkeypatch)
    assert result.returncode == 2
    assert result.stderr.startswith("homocal: error:") and result.stderr.count("\n") == 1, result.stderr
    assert message in result.stderr
    assert {p.name: p.read_bytes() for p in work.iterdir()} == before
