"""``homocal fit`` / ``homocal apply`` end to end in a subprocess: formats, results; and bad input that
ends with one "homocal: error:" line, exit code 2 and no output file (those tables run homocal.cli.main
in-process: the same code from argv to stderr, without a 3 s interpreter start per case)."""
import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from homocal.correctors import (DescentCorrector, HorizonCorrector, LeastChangeCorrector, RegressionCorrector,
                                load_corrector)
from homocal.geometry import PinholeCamera, SiteMap, ViewTransformer, read_trapezoid_file
from homocal.uncertainty import ground_uncertainty, max_trustworthy_range, sigma_radius

from cli_run import homocal_main

REPO = Path(__file__).resolve().parents[2]
STREET = REPO / "examples" / "street"
CAM = PinholeCamera()
GROUND = np.array([[-3.5, 30.0], [3.5, 30.0], [3.5, 8.0], [-3.5, 8.0]])
IMAGE = np.round(CAM.project_ground(GROUND)) + [[2, -1], [-1, 2], [3, 1], [-2, -2]]  # hand-placed, integers
REF_G = np.array([[0.0, 10.0], [0.0, 20.0], [0.0, 35.0]])
REF_Q = CAM.project_ground(REF_G)
FEET_Q = np.vstack([CAM.project_ground([[1.0, 7.0], [-2.0, 15.0], [0.5, 33.0]]), [[640.0, 100.0]]])  # last: sky
SITE_MAP = SiteMap(10.0, (200.0, 500.0))


def homocal(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "homocal.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=60)


def write_csv(path: Path, header: list[str], rows) -> None:
    path.write_text(",".join(header) + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))


@pytest.fixture
def work(tmp_path: Path) -> Path:
    (tmp_path / "trap.json").write_text(json.dumps({"image": IMAGE.tolist(), "map": GROUND.tolist()}))
    write_csv(tmp_path / "ref.csv", ["u", "v", "x", "y"], np.column_stack([REF_Q, REF_G]))
    write_csv(tmp_path / "feet.csv", ["id", "u", "v", "label"],
              [(i, u, v, f"p{i}") for i, (u, v) in enumerate(FEET_Q)])
    return tmp_path


@pytest.mark.slow  # two homocal processes per method, against the library
@pytest.mark.parametrize("method,expected", [
    ("regression", lambda: RegressionCorrector()),
    ("regression-signed", lambda: RegressionCorrector(signed=True)),
    ("regression-intercept", lambda: RegressionCorrector(signed=True, intercept=True)),
    ("horizon", lambda: HorizonCorrector()),
    ("descent", lambda: DescentCorrector()),
    ("least-change", lambda: LeastChangeCorrector()),
])
def test_fit_and_apply_match_the_library(work, method, expected):
    fit = homocal("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "--method", method, "-o", "c.json",
                  cwd=work)
    assert fit.returncode == 0, fit.stderr
    reference = expected().fit(ViewTransformer(IMAGE, GROUND), REF_Q, REF_G, (0.0, 0.0))
    assert f"{reference.calibration_improvement_:.1f} %" in fit.stdout and method in fit.stdout
    mapping = getattr(reference, "transformer_", reference.base_transformer_)  # the points methods' error model
    assert f"under 0.5 m out to {max_trustworthy_range(mapping, 0.5):.1f} m straight ahead" in fit.stdout
    app = homocal("apply", "c.json", "--points", "feet.csv", "-o", "out.csv", "--click-sigma-px", "2",
                  "--point-sigma-px", "0.5", cwd=work)
    assert app.returncode == 0, app.stderr
    assert "1 on or above the horizon (status beyond_horizon)" in app.stdout
    with (work / "out.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["id", "u", "v", "label", "x", "y", "sigma_m", "status"]  # extra columns carried through
    assert [r["label"] for r in rows] == ["p0", "p1", "p2", "p3"]
    assert [r["status"] for r in rows] == ["ok", "ok", "ok", "beyond_horizon"]
    xy = np.array([[float(r["x"]), float(r["y"])] for r in rows])
    np.testing.assert_array_equal(xy, reference.transform_points(FEET_Q))  # full precision, NaN beyond horizon
    sigma = np.array([float(r["sigma_m"]) for r in rows])
    np.testing.assert_array_equal(sigma, sigma_radius(ground_uncertainty(mapping, FEET_Q, 2.0, 0.5)))
    assert np.isnan(sigma[3]) and np.all(sigma[:3] > 0)
    assert sorted(p.name for p in work.iterdir()) == ["c.json", "feet.csv", "out.csv", "ref.csv", "trap.json"]


@pytest.mark.slow  # homocal in a subprocess
def test_apply_rounds_to_the_decimals_asked(work):
    """--decimals 3: x, y and sigma_m to the millimetre, each the full value rounded (nan stays nan); the input's
    columns as they were."""
    assert homocal("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "-o", "c.json", cwd=work).returncode == 0
    for out, extra in (("full.csv", []), ("mm.csv", ["--decimals", "3"])):
        assert homocal("apply", "c.json", "--points", "feet.csv", "-o", out, *extra, cwd=work).returncode == 0
    full, mm = (list(csv.DictReader((work / name).open())) for name in ("full.csv", "mm.csv"))
    for a, b in zip(full, mm):
        assert [a[k] for k in ("id", "u", "v", "label", "status")] == [b[k] for k in ("id", "u", "v", "label", "status")]
        for k in ("x", "y", "sigma_m"):
            assert b[k] == ("nan" if a[k] == "nan" else f"{round(float(a[k]), 3):.3f}")
    assert any(len(r["x"].split(".")[1]) > 3 for r in full) and all(len(r["x"].split(".")[1]) == 3 for r in mm[:3])


@pytest.mark.slow  # homocal in a subprocess
def test_fit_defaults_to_least_change(work):
    """The study's best method on median and failure tail together (README, paper preset) is fit's default."""
    fit = homocal("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "-o", "c.json", cwd=work)
    assert fit.returncode == 0 and fit.stdout.startswith("homocal fit: least-change correction")
    saved = json.loads((work / "c.json").read_text())
    assert saved == LeastChangeCorrector().fit(ViewTransformer(IMAGE, GROUND), REF_Q, REF_G, (0.0, 0.0)).to_dict()


@pytest.mark.slow  # homocal in a subprocess
def test_apply_marks_bad_rows_and_names_their_lines(work):
    assert homocal("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "--method", "regression-intercept",
                   "-o", "c.json", cwd=work).returncode == 0
    write_csv(work / "feet.csv", ["u", "v"], [(640, 500), ("nan", 500), (640, 100), (640, "inf"), (600, 450),
                                              (1e308, 400)])
    app = homocal("apply", "c.json", "--points", "feet.csv", "-o", "out.csv", cwd=work)
    assert app.returncode == 0, app.stderr
    assert "1 on or above the horizon (status beyond_horizon); 3 with u or v nan, inf or beyond 1e9 (status " \
           "bad_input, lines 3, 5, 7)" in app.stdout
    with (work / "out.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [r["status"] for r in rows] == ["ok", "bad_input", "beyond_horizon", "bad_input", "ok", "bad_input"]
    assert rows[5]["u"] == "1e+308"  # the input is carried through as given
    for r in rows:
        assert (r["status"] == "ok") == all(np.isfinite(float(r[c])) for c in ("x", "y", "sigma_m"))


@pytest.mark.slow  # homocal in a subprocess
def test_point_behind_the_camera_is_a_warning(work):
    rows = np.column_stack([REF_Q, REF_G * [[1, 1], [1, 1], [1, -1]]])
    write_csv(work / "ref.csv", ["u", "v", "x", "y"], rows)
    fit = homocal("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "--method", "horizon", "-o", "c.json",
                  cwd=work)
    assert fit.returncode == 0, fit.stderr
    assert fit.stderr == "homocal: warning: ref.csv: ground_points[2] = [0.0, -35.0] is behind the camera (y < 0, " \
                         "the camera origin's y; y points forward): a sign error?\n"
    assert (work / "c.json").is_file()


def _street_variants():
    """examples/street's trapezoid with the map's corners relabelled (the image's order kept)."""
    base = json.loads((STREET / "trapezoid.json").read_text())
    out = {}
    for name, order in [("mirrored", [1, 0, 3, 2]), ("upside down", [3, 2, 1, 0]), ("rotated", [2, 3, 0, 1])]:
        out[name] = {**base, "map": [base["map"][i] for i in order]}
    metres = SiteMap(10.0, (400.0, 600.0)).to_metres(base["map"]).tolist()
    out["metres mirrored"] = {"image": base["image"], "map": [metres[i] for i in (1, 0, 3, 2)]}
    return out


@pytest.mark.slow  # homocal in a subprocess
def test_street_example_fits(tmp_path):
    fit = homocal("fit", "--trapezoid", str(STREET / "trapezoid.json"), "--points", str(STREET / "reference_points.csv"),
                  "--method", "regression-intercept", "-o", "c.json", cwd=tmp_path)
    assert fit.returncode == 0 and fit.stderr == "", fit.stderr


@pytest.mark.slow  # homocal in a subprocess
def test_hybrid_reports_its_choice(work):
    fit = homocal("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "--method", "hybrid",
                  "--threshold", "50", "-o", "c.json", cwd=work)
    assert fit.returncode == 0, fit.stderr
    chosen = load_corrector(work / "c.json").chosen_
    assert f"hybrid chose {chosen}" in fit.stdout


@pytest.mark.slow  # homocal in a subprocess
@pytest.mark.parametrize("layout", ["site_map_inline", "simgen_dataset"])
def test_site_map_pixels_and_simgen_trapezoids(work, layout):
    map_px = SITE_MAP.to_pixels(GROUND).tolist()
    scale = {"scale_px_per_m": SITE_MAP.scale_px_per_m, "origin_px": list(SITE_MAP.origin_px)}
    if layout == "site_map_inline":
        (work / "trap.json").write_text(json.dumps({"image": IMAGE.tolist(), "map": map_px, "site_map": scale}))
    else:
        exact = {"image": CAM.project_ground(GROUND).tolist(), "map": map_px}
        (work / "trap.json").write_text(json.dumps({"order": "TL,TR,BR,BL", "exact": exact, "ground_m": GROUND.tolist(),
                                                    "hand_placed": {"image": IMAGE.tolist(), "map": map_px}}))
        (work / "site_map.json").write_text(json.dumps({"file": "site_map.png", **scale, "width": 400, "height": 600}))
    fit = homocal("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "--method", "regression-signed",
                  "-o", "c.json", cwd=work)
    assert fit.returncode == 0, fit.stderr
    reference = RegressionCorrector(signed=True).fit(ViewTransformer(IMAGE, GROUND), REF_Q, REF_G, (0.0, 0.0))
    np.testing.assert_allclose(load_corrector(work / "c.json").transform_points(FEET_Q),
                               reference.transform_points(FEET_Q), atol=1e-9)


def _bad_fit_inputs():
    """(name, files to write {name: text}, extra args, expected message fragment)."""
    ref_header = "u,v,x,y\n"
    rows = "".join(f"{u},{v},{x},{y}\n" for (u, v), (x, y) in zip(REF_Q, REF_G))
    return [
        ("missing trapezoid", {"trap.json": None}, [], "trap.json: no such file"),
        ("trapezoid not JSON", {"trap.json": "{oops"}, [], "trap.json: not a JSON file"),
        ("trapezoid without map", {"trap.json": json.dumps({"image": IMAGE.tolist()})}, [], "missing key 'map'"),
        ("degenerate trapezoid", {"trap.json": json.dumps({"image": [[0, 0], [1, 1], [2, 2], [0, 5]],
                                                            "map": GROUND.tolist()})}, [], "collinear"),
        ("dataset without site map", {"trap.json": json.dumps({"hand_placed": {"image": IMAGE.tolist(),
                                                                               "map": GROUND.tolist()}})},
         [], "site_map.json"),
        ("missing points", {"ref.csv": None}, [], "ref.csv: no such file"),
        ("missing column", {"ref.csv": "u,v,x\n1,2,3\n"}, [], "missing column(s) y"),
        ("unparsable number", {"ref.csv": ref_header + rows + "640,abc,0,40\n"}, [], "line 5: column v: 'abc'"),
        ("non-finite number", {"ref.csv": ref_header + "nan,400,0,12\n" + rows}, [], "line 2: column u"),
        ("ragged row", {"ref.csv": ref_header + rows + "1,2,3\n"}, [], "line 5: 3 fields"),
        ("too few points", {"ref.csv": ref_header + rows.split("\n", 1)[1].split("\n", 1)[1]}, [], "at least 3"),
        ("point above horizon", {"ref.csv": ref_header + rows + "640,100,0,80\n"}, [], "image_points[3]"),
        ("bad camera origin", {}, ["--camera-origin", "1;2"], "X,Y"),
        ("unknown method", {}, ["--method", "magic"], "invalid choice"),
        ("missing output folder", {}, ["-o", "no/such/dir/c.json"], "does not exist"),
        ("duplicate column", {"ref.csv": "u,v,x,y,u\n" + rows.replace("\n", ",1\n")}, [], "'u' appear more than once"),
        ("points not UTF-8", {"ref.csv": b"u,v,x,y\n\xff\xfe1,2,3,4\n"}, [], "ref.csv: not UTF-8 text"),
        ("trapezoid not UTF-8", {"trap.json": b'{"image": "\xff"}'}, [], "trap.json: not a JSON file"),
        ("duplicate image point", {"ref.csv": ref_header + rows + f"{REF_Q[0, 0]},{REF_Q[0, 1]},0,50\n"}, [],
         "image_points[0] and image_points[3] are the same point"),
        ("duplicate ground point", {"ref.csv": ref_header + rows + "600,300,0.0,10.0\n"}, [],
         "ground_points[0] and ground_points[3] are the same point"),
        ("overflow vertex", {"trap.json": json.dumps({"image": [[1e308, 0]] + IMAGE.tolist()[1:], "map": GROUND.tolist()})},
         [], "vertex 0 = [1e+308, 0.0] is out of range"),
        ("overflow reference point", {"ref.csv": ref_header + rows + "640,500,1e308,5\n"}, [],
         "ground_points: point 3 = [1e+308, 5.0] is out of range"),
        *[(f"street {name}", {"trap.json": json.dumps(trap)}, [], "other way from the image's (mirrored or upside down?)")
          for name, trap in _street_variants().items() if name != "rotated"],
        ("mirrored metres", {"trap.json": json.dumps({"image": IMAGE.tolist(), "map": GROUND[[1, 0, 3, 2]].tolist()})},
         [], "other way from the image's"),
        ("rotated metres", {"trap.json": json.dumps({"image": IMAGE.tolist(), "map": GROUND[[2, 3, 0, 1]].tolist()})},
         [], "turned against the image's"),
        ("street rotated", {"trap.json": json.dumps(_street_variants()["rotated"])}, [], "turned against the image's"),
        ("negative seed", {}, ["--seed", "-1"], "argument --seed: must be an integer in [0, 2**64 - 1], got -1"),
        ("too many points", {"ref.csv": ref_header + "".join(f"{600 + i % 300},{300 + i // 300},{i},1\n"
                                                             for i in range(100_001))}, [],
         "ref.csv, line 100002: more than 100,000 points (the most this command takes)"),
        ("huge seed", {}, ["--seed", str(2**64)], "argument --seed: must be an integer in [0, 2**64 - 1]"),
        ("NaN threshold", {}, ["--threshold", "nan"], "argument --threshold: must be a finite number in [0, 100], got nan"),
        ("threshold 101", {}, ["--threshold", "101"], "argument --threshold: must be a finite number in [0, 100]"),
    ]


@pytest.mark.parametrize("name,files,extra,message", _bad_fit_inputs(), ids=[c[0] for c in _bad_fit_inputs()])
def test_bad_fit_input(work, name, files, extra, message, capsys, monkeypatch):
    for file, text in files.items():
        (work / file).unlink()
        if isinstance(text, bytes):
            (work / file).write_bytes(text)
        elif text is not None:
            (work / file).write_text(text)
    before = sorted(p.name for p in work.rglob("*"))
    args = ["--trapezoid", "trap.json", "--points", "ref.csv", "--method", "descent", "-o", "c.json"]
    result = homocal_main("fit", *args, *extra, cwd=work, capsys=capsys, monkeypatch=monkeypatch)
    assert result.returncode == 2
    assert result.stderr.startswith("homocal: error:") and result.stderr.count("\n") == 1, result.stderr
    assert message in result.stderr
    assert sorted(p.name for p in work.rglob("*")) == before  # no output, no temporary file


def _edited_correction(edit) -> str:
    d = RegressionCorrector().fit(ViewTransformer(IMAGE, GROUND), REF_Q, REF_G, (0.0, 0.0)).to_dict()
    edit(d)
    return json.dumps(d)


@pytest.mark.parametrize("name,correction,feet,extra,message", [
    ("missing correction", None, None, [], "c.json: no such file"),
    ("correction of another kind", '{"format": "x"}', None, [], "not a homocal correction"),
    ("feet without v", "ok", "u,w\n1,2\n", [], "missing column(s) v"),
    ("unparsable foot point", "ok", "u,v\n640,500\n640,x5\n", [], "line 3: column v: 'x5'"),
    ("duplicate u column", "ok", "u,v,u\n640,500,600\n", [], "feet.csv: column(s) 'u' appear more than once"),
    ("feet not UTF-8", "ok", b"u,v\n640,500\n\xe9,1\n", [], "feet.csv: not UTF-8 text"),
    ("correction not UTF-8", b'{"format": "\xff"}', None, [], "c.json: not a JSON file"),
    ("hand-edited negative a", _edited_correction(lambda d: d["fitted"].update(a=-5.0)), None, [],
     "c.json: bad regression correction (field fitted.a: must be >= 0"),
    ("hand-edited NaN b", _edited_correction(lambda d: d["fitted"].update(b=float("nan"))), None, [],
     "c.json: bad regression correction (field fitted.b: expected a finite number"),
    ("negative click sigma", "ok", None, ["--click-sigma-px", "-1"], "--click-sigma-px: must be a finite number >= 0"),
    ("NaN point sigma", "ok", None, ["--point-sigma-px", "nan"], "--point-sigma-px: must be a finite number >= 0"),
    ("negative decimals", "ok", None, ["--decimals", "-1"], "--decimals: must be an integer in [0, 17], got -1"),
    ("huge decimals", "ok", None, ["--decimals", "99"], "--decimals: must be an integer in [0, 17], got 99"),
    ("fractional decimals", "ok", None, ["--decimals", "2.5"], "--decimals: expected an integer, got '2.5'"),
])
def test_bad_apply_input(work, name, correction, feet, extra, message, capsys, monkeypatch):
    if correction == "ok":
        fitted = RegressionCorrector().fit(ViewTransformer(IMAGE, GROUND), REF_Q, REF_G, (0.0, 0.0))
        fitted.save(work / "c.json")
    elif isinstance(correction, bytes):
        (work / "c.json").write_bytes(correction)
    elif correction is not None:
        (work / "c.json").write_text(correction)
    if isinstance(feet, bytes):
        (work / "feet.csv").write_bytes(feet)
    elif feet is not None:
        (work / "feet.csv").write_text(feet)
    before = sorted(p.name for p in work.iterdir())
    result = homocal_main("apply", "c.json", "--points", "feet.csv", "-o", "out.csv", *extra, cwd=work, capsys=capsys,
                          monkeypatch=monkeypatch)
    assert result.returncode == 2
    assert result.stderr.startswith("homocal: error:") and result.stderr.count("\n") == 1, result.stderr
    assert message in result.stderr
    assert sorted(p.name for p in work.iterdir()) == before


def test_least_change_priors_from_the_command_line(work, capsys, monkeypatch):
    """--click-sigma-px, --map-sigma-m, --point-sigma-m reach LeastChangeCorrector (saved with it); omitted ones
    keep its defaults; with another method they are refused; out-of-range values are refused where parsed."""
    run = lambda *a: homocal_main("fit", "--trapezoid", "trap.json", "--points", "ref.csv", "-o", "c.json", *a,  # noqa: E731
                                  cwd=work, capsys=capsys, monkeypatch=monkeypatch)
    assert run("--method", "least-change", "--click-sigma-px", "2.5", "--map-sigma-m", "0").returncode == 0
    params = json.loads((work / "c.json").read_text())["params"]
    assert params == {**LeastChangeCorrector().get_params(), "click_sigma_px": 2.5, "map_sigma_m": 0.0}
    refused = run("--method", "descent", "--point-sigma-m", "0.1")
    assert refused.returncode == 2 and "--point-sigma-m: the priors of --method least-change, not of descent" in refused.stderr
    for flag, value in (("--click-sigma-px", "0"), ("--point-sigma-m", "nan"), ("--map-sigma-m", "-1"), ("--click-sigma-px", "inf"),
                        ("--point-sigma-m", "0"), ("--map-sigma-m", "1e7"), ("--click-sigma-px", "one"), ("--map-sigma-m", "")):
        bad = run("--method", "least-change", flag, value)
        assert bad.returncode == 2 and flag in bad.stderr


# ---- --method pedestrians: fitted from people's boxes ----------------------------------------------------
@pytest.fixture(scope="module")
def boxes_work(tiny_dataset, tmp_path_factory) -> Path:
    """tiny_dataset's boxes as export-mot writes them (mot/det/segmentation.txt), its hand-placed trapezoid,
    reference points from its calibration objects and foot points from its ground truth."""
    import pyarrow.parquet as pq

    work = tmp_path_factory.mktemp("boxes")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    subprocess.run([sys.executable, "-m", "simgen.cli", "export-mot", str(tiny_dataset), "-o", str(work / "mot")],
                   check=True, env=env, capture_output=True, timeout=120)
    cal = pq.read_table(tiny_dataset / "calibration.parquet").to_pydict()
    write_csv(work / "ref.csv", ["u", "v", "x", "y"], zip(cal["u"], cal["v"], cal["x"], cal["y"]))
    gt = pq.read_table(tiny_dataset / "gt.parquet").to_pydict()
    feet = [(u, v) for u, v, inside in zip(gt["u"], gt["v"], gt["in_frame"]) if inside][::10]
    write_csv(work / "feet.csv", ["u", "v"], feet)
    return work


@pytest.mark.slow  # fit and apply in subprocesses on a rendered dataset
@pytest.mark.parametrize("boxes,flags", [("mot/det/segmentation.txt", []), ("{dataset}/detections.parquet", []),
                                         ("{dataset}/detections.parquet", ["--detector", "segmentation"])])
def test_pedestrians_fit_then_apply(boxes_work, tiny_dataset, boxes, flags):
    """fit's JSON is the library's fit on read_boxes of the same file; apply maps with it; the fitted horizon is
    nearer the camera's true one than the hand-placed trapezoid's."""
    from homocal import PedestrianCorrector, read_boxes

    boxes = boxes.format(dataset=tiny_dataset)
    trap = str(tiny_dataset / "trapezoids.json")
    fit = homocal("fit", "--trapezoid", trap, "--method", "pedestrians", "--boxes", boxes, "--camera-height", "4",
                  *flags, "-o", "c.json", cwd=boxes_work)
    assert fit.returncode == 0, fit.stderr
    read = read_boxes(boxes_work / boxes, "segmentation" if flags else None)
    assert f"from {len(read.xyxy)} boxes of {boxes}" in fit.stdout and "no check points" in fit.stdout
    assert "people (tracks):" in fit.stdout and " +- " in fit.stdout
    reference = PedestrianCorrector().fit(read_trapezoid_file(trap)[0], read.xyxy, convention="homocal",
                                          frames=read.frames, track_ids=read.track_ids, camera_height_m=4.0, K=read.K,
                                          image_size=read.image_size)
    assert json.loads((boxes_work / "c.json").read_text()) == json.loads(json.dumps(reference.to_dict()))
    true_row = json.loads((tiny_dataset / "camera.json").read_text())["horizon_row"]
    assert abs(reference.horizon_row_ - true_row) < abs(reference.clicked_horizon_row_ - true_row)
    (boxes_work / "out.csv").unlink(missing_ok=True)
    applied = homocal("apply", "c.json", "--points", "feet.csv", "-o", "out.csv", cwd=boxes_work)
    assert applied.returncode == 0, applied.stderr
    with open(boxes_work / "out.csv") as f:
        rows = list(csv.DictReader(f))
    q = np.array([[float(r["u"]), float(r["v"])] for r in rows])
    np.testing.assert_allclose([[float(r["x"]), float(r["y"])] for r in rows], reference.transform_points(q), atol=1e-9)
    # sigma_m and the Error bars line are the correction's own error model: the fitted horizon's uncertainty
    # on top of the corrected trapezoid's clicking and foot-point errors
    sigma = np.array([float(r["sigma_m"]) for r in rows])
    np.testing.assert_allclose(sigma, sigma_radius(reference.ground_uncertainty(q, 1.5, 1.0)), rtol=1e-12)
    assert (sigma > sigma_radius(ground_uncertainty(reference.transformer_, q, 1.5, 1.0))).all()
    trust = max_trustworthy_range(reference.mapping, 0.5, uncertainty=reference.ground_uncertainty)
    assert f"under 0.5 m out to {trust:.1f} m straight ahead" in fit.stdout
    assert trust < max_trustworthy_range(reference.mapping, 0.5)
    (boxes_work / "c.json").unlink()


def test_pedestrians_points_check_the_fit(boxes_work, tiny_dataset, capsys, monkeypatch):
    """--points with pedestrians: the same fit, its errors on the points reported and stored."""
    trap = str(tiny_dataset / "trapezoids.json")
    args = ["fit", "--trapezoid", trap, "--method", "pedestrians", "--boxes", "mot/det/segmentation.txt",
            "--camera-height", "4"]
    plain = homocal_main(*args, "-o", "a.json", cwd=boxes_work, capsys=capsys, monkeypatch=monkeypatch)
    checked = homocal_main(*args, "--points", "ref.csv", "-o", "b.json", cwd=boxes_work, capsys=capsys,
                           monkeypatch=monkeypatch)
    assert plain.returncode == checked.returncode == 0, checked.stderr
    a, b = (load_corrector(boxes_work / name) for name in ("a.json", "b.json"))
    assert a.horizon_row_ == b.horizon_row_ and np.array_equal(a.m, b.m)  # the points do not enter the fit
    assert np.isnan(a.error_before_) and b.error_before_ > 0 and b.error_after_ >= 0
    assert "checked on " in checked.stdout and f"{b.error_before_:.3f} m before, {b.error_after_:.3f} m after" in checked.stdout
    assert "on the check points, which the fit did not use" in checked.stdout
    for name in ("a.json", "b.json"):
        (boxes_work / name).unlink()


def _bad_pedestrian_inputs():
    """(name, files to write {name: text}, args after --trapezoid trap.json -o c.json, expected message)."""
    head = "frame,x1,y1,x2,y2\n"
    rows = "".join(f"{i},{x - 8},{top},{x + 8},{foot}\n" for i, (x, top, foot) in
                   enumerate([(500, 300, 400), (600, 310, 420), (700, 290, 395), (640, 320, 430)]))
    camera = json.dumps({"width": CAM.width, "height": CAM.height, "K": CAM.K.tolist()})
    ped = ["--method", "pedestrians", "--camera-json", "cam.json", "--camera-height", "4"]
    return [
        ("no boxes flag", {}, ["--method", "pedestrians"], "--boxes: required with --method pedestrians"),
        ("no boxes file", {}, [*ped, "--boxes", "none.csv"], "--boxes none.csv: no such file"),
        ("boxes a folder", {}, [*ped, "--boxes", "."], "--boxes .: is a folder, not a file"),
        ("boxes a device", {}, [*ped, "--boxes", "/dev/zero"], "--boxes /dev/zero: not a regular file"),
        ("camera json a folder", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--camera-json", "."],
         "--camera-json .: is a folder, not a file"),
        ("camera json a device", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--camera-json", "/dev/zero"],
         "--camera-json /dev/zero: not a regular file"),
        ("empty boxes file", {"b.csv": head}, [*ped, "--boxes", "b.csv"], "b.csv: no boxes"),
        ("empty MOT file", {"b.txt": ""}, [*ped, "--boxes", "b.txt"], "b.txt: no detections"),
        ("NaN box", {"b.csv": head + rows + "5,600,nan,620,500\n"}, [*ped, "--boxes", "b.csv"], "b.csv, line 6: column y1"),
        ("box upside down", {"b.csv": head + rows + "5,600,500,620,400\n"}, [*ped, "--boxes", "b.csv"], "upside down"),
        ("camera height 0", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--camera-height", "0"],
         "argument --camera-height: expected a number in [0.5, 100] (m) or none, got '0'"),
        ("camera height 1e6", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--camera-height", "1e6"],
         "argument --camera-height: expected a number in [0.5, 100] (m) or none, got '1e6'"),
        ("camera height 1e-9", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--camera-height", "1e-9"],
         "argument --camera-height: expected a number in [0.5, 100] (m) or none, got '1e-9'"),
        ("height sd 0", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--height-sd", "0"], "argument --height-sd: expected a number in"),
        ("height sd above a quarter of the mean", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--height-sd", "0.5"],
         "argument --height-sd: expected at most height_mean_m / 4 = 0.4125 m, got 0.5"),
        ("estimate roll not yes or no", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--estimate-roll", "1"],
         "argument --estimate-roll: expected yes or no, got '1'"),
        ("drop hidden feet not yes, no or auto", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--drop-hidden-feet",
         "1"], "argument --drop-hidden-feet: expected yes, no or auto, got '1'"),
        ("drop hidden feet Auto", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--drop-hidden-feet", "Auto"],
         "argument --drop-hidden-feet: expected yes, no or auto, got 'Auto'"),
        ("height mean sigma negative", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--height-mean-sigma", "-1"],
         "argument --height-mean-sigma: expected a number in [0, 0.5] (m), got '-1'"),
        ("height mean nan", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--height-mean", "nan"],
         "argument --height-mean: expected a number in [0.5, 2.5] (m), got 'nan'"),
        *((f"box margin {v or 'empty'}", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--box-margin", v],
           f"argument --box-margin: expected a number in [0, 64] (px), got '{v}'")
          for v in ("nan", "inf", "-1", "65", "1e308", "two", "")),
        ("no image size", {"b.csv": head + rows}, ["--method", "pedestrians", "--boxes", "b.csv"], "--camera-json: needed"),
        ("camera json without width", {"b.csv": head + rows, "cam.json": json.dumps({"height": 720})}, [*ped, "--boxes", "b.csv"],
         "--camera-json cam.json: image_size: missing"),
        ("camera json K 2x2", {"b.csv": head + rows, "cam.json": json.dumps({"width": 1280, "height": 720,
                                                                               "K": [[1, 0], [0, 1]]})},
         [*ped, "--boxes", "b.csv"], "--camera-json cam.json: K: expected shape (3, 3)"),
        ("camera json K NaN", {"b.csv": head + rows, "cam.json": json.dumps({"width": 1280, "height": 720}).replace(
            "}", ', "K": [[NaN, 0, 640], [0, 586, 360], [0, 0, 1]]}')}, [*ped, "--boxes", "b.csv"], "--camera-json cam.json: K: contains NaN"),
        ("camera json width text", {"b.csv": head + rows, "cam.json": json.dumps({"width": "1280", "height": 720})},
         [*ped, "--boxes", "b.csv"], "--camera-json cam.json: image_size: expected (width, height)"),
        ("camera json width 0", {"b.csv": head + rows, "cam.json": json.dumps({"width": 0, "height": 720})},
         [*ped, "--boxes", "b.csv"], "--camera-json cam.json: image_size: expected (width, height)"),
        ("camera json not JSON", {"b.csv": head + rows, "cam.json": "{"}, [*ped, "--boxes", "b.csv"], "cam.json"),
        ("detector of a CSV", {"b.csv": head + rows}, [*ped, "--boxes", "b.csv", "--detector", "hog"],
         "a detector name is for a dataset's detections.parquet"),
        ("all above the horizon", {"b.csv": head + "".join(f"{i},600,10,620,50\n" for i in range(5))},
         [*ped, "--boxes", "b.csv"], "on or above the clicked mapping's horizon"),
        ("boxes flag with a points method", {}, ["--points", "ref.csv", "--method", "descent", "--boxes", "b.csv"],
         "--boxes: for --method pedestrians, not descent"),
        ("no points for a points method", {}, ["--method", "horizon"], "--points: required with --method horizon"),
    ], camera


_PEDESTRIAN_CASES, _CAMERA_JSON = _bad_pedestrian_inputs()


@pytest.mark.parametrize("name,files,extra,message", _PEDESTRIAN_CASES, ids=[c[0] for c in _PEDESTRIAN_CASES])
def test_bad_pedestrian_input(work, name, files, extra, message, capsys, monkeypatch):
    (work / "cam.json").write_text(_CAMERA_JSON)
    for file, text in files.items():
        (work / file).write_text(text)
    before = sorted(p.name for p in work.rglob("*"))
    result = homocal_main("fit", "--trapezoid", "trap.json", "-o", "c.json", *extra, cwd=work, capsys=capsys,
                          monkeypatch=monkeypatch)
    assert result.returncode == 2
    assert result.stderr.startswith("homocal: error:") and result.stderr.count("\n") == 1, result.stderr
    assert message in result.stderr
    assert sorted(p.name for p in work.rglob("*")) == before


def test_pedestrians_refuse_a_majority_of_outliers(work, capsys, monkeypatch):
    """Most boxes cut to half height (a detector whose boxes miss the legs): refused, not a horizon far off."""
    from homocal.correctors.pedestrians import MAX_OUTLIER_SHARE

    rng = np.random.default_rng(0)
    xy = np.column_stack([rng.uniform(-4, 4, 60), rng.uniform(8, 40, 60)])
    foot = CAM.project_ground(xy)
    head = CAM.project(np.column_stack([xy, rng.normal(1.65, 0.07, 60)]))
    top = np.where(np.arange(60) < 40, (head[:, 1] + foot[:, 1]) / 2, head[:, 1])  # 2/3 cut
    write_csv(work / "b.csv", ["frame", "x1", "y1", "x2", "y2"],
              [(i * 20, u - 5, t, u + 5, v) for i, ((u, v), t) in enumerate(zip(foot, top))])
    (work / "cam.json").write_text(_CAMERA_JSON)
    for drop, way_out in (("no", "(drop_hidden_feet, --drop-hidden-feet yes)"),  # the boxes have frames: a way out named
                          ("auto", "(--drop-hidden-feet auto: no box's feet a nearer person may hide)")):
        result = homocal_main("fit", "--trapezoid", "trap.json", "-o", "c.json", "--method", "pedestrians", "--boxes",
                              "b.csv", "--camera-json", "cam.json", "--camera-height", "4", "--drop-hidden-feet", drop,
                              cwd=work, capsys=capsys, monkeypatch=monkeypatch)
        assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
        assert "are outliers" in result.stderr and f"more than {MAX_OUTLIER_SHARE:.0%}" in result.stderr
        assert result.stderr.endswith(way_out + "\n") and not (work / "c.json").exists()


def test_pedestrians_drop_hidden_feet(work, capsys, monkeypatch):
    """--drop-hidden-feet yes: the saved correction is the library's fit with drop_hidden_feet=True (its params
    record it, fitted.n_hidden counts the boxes left out) and fit's line says how many."""
    from homocal import PedestrianCorrector, read_boxes

    rng = np.random.default_rng(1)
    xy = np.column_stack([rng.uniform(-4, 4, 120), rng.uniform(8, 40, 120)])
    foot = CAM.project_ground(xy)
    head = CAM.project(np.column_stack([xy, rng.normal(1.65, 0.07, 120)]))
    write_csv(work / "b.csv", ["frame", "x1", "y1", "x2", "y2"],
              [(i // 6, u - 12, t, u + 12, v) for i, ((u, v), (_, t)) in enumerate(zip(foot, head))])
    (work / "cam.json").write_text(_CAMERA_JSON)
    result = homocal_main("fit", "--trapezoid", "trap.json", "-o", "c.json", "--method", "pedestrians", "--boxes",
                          "b.csv", "--camera-json", "cam.json", "--camera-height", "4", "--drop-hidden-feet", "yes",
                          cwd=work, capsys=capsys, monkeypatch=monkeypatch)
    assert result.returncode == 0, result.stderr
    read = read_boxes(work / "b.csv")
    reference = PedestrianCorrector(drop_hidden_feet=True).fit(
        read_trapezoid_file(work / "trap.json")[0], read.xyxy, convention="homocal", frames=read.frames,
        camera_height_m=4.0, K=CAM.K, image_size=(CAM.width, CAM.height))
    saved = json.loads((work / "c.json").read_text())
    assert saved == json.loads(json.dumps(reference.to_dict())) and saved["params"]["drop_hidden_feet"] is True
    assert saved["fitted"]["n_hidden"] == reference.n_hidden_ > 0
    assert f", {reference.n_hidden_} with feet a nearer person may hide," in result.stdout
    (work / "c.json").unlink()


def test_pedestrians_drop_hidden_feet_auto(work, capsys, monkeypatch):
    """--drop-hidden-feet auto on boxes whose fit with every box is refused for hidden feet: the saved correction is
    the library's fit with drop_hidden_feet="auto" (it left them out, fitted.first_refusal says why) and fit's line
    says so."""
    from homocal import PedestrianCorrector, read_boxes
    from tests.correctors.test_pedestrians import TestDropHiddenFeetAuto

    boxes, frames, _ = TestDropHiddenFeetAuto.crowd()
    write_csv(work / "b.csv", ["frame", "x1", "y1", "x2", "y2"], [(f, *b) for f, b in zip(frames, boxes)])
    (work / "cam.json").write_text(_CAMERA_JSON)
    result = homocal_main("fit", "--trapezoid", "trap.json", "-o", "c.json", "--method", "pedestrians", "--boxes",
                          "b.csv", "--camera-json", "cam.json", "--camera-height", "4", "--height-sd", "0.07",
                          "--drop-hidden-feet", "auto", cwd=work, capsys=capsys, monkeypatch=monkeypatch)
    assert result.returncode == 0, result.stderr
    read = read_boxes(work / "b.csv")
    reference = PedestrianCorrector(height_sd_m=0.07, drop_hidden_feet="auto").fit(
        read_trapezoid_file(work / "trap.json")[0], read.xyxy, convention="homocal", frames=read.frames,
        camera_height_m=4.0, K=CAM.K, image_size=(CAM.width, CAM.height))
    saved = json.loads((work / "c.json").read_text())
    assert saved == json.loads(json.dumps(reference.to_dict())) and saved["params"]["drop_hidden_feet"] == "auto"
    assert saved["fitted"]["hidden_feet"] == "dropped" and saved["fitted"]["first_refusal"] == reference.first_refusal_
    assert f"may hide (left out: with them {reference.first_refusal_})" in result.stdout
