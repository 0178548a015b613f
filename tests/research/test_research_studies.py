"""research/pedestrians.py (--study and DATASET modes) and research/reproduction_tables.py on tiny real studies:
the pedestrian rows against PedestrianCorrector and numpy by hand, the seven methods' rows against homocal
report's table.csv, refused fits as failure rows, and each script's bad input as one line with nothing written."""
import csv
import importlib.util
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from homocal.cli import main
from homocal.correctors.pedestrians import PedestrianCorrector
from homocal.geometry import ViewTransformer
from homocal.study.inputs import StudyParams, StudyScene
from homocal.study.metrics import METHODS, METRICS, OVERALL, build_table, complete_shard_files, format_metric, load_study

pytestmark = pytest.mark.slow  # the research scripts' studies on a rendered dataset

RESEARCH = Path(__file__).resolve().parents[2] / "research"
PEDESTRIANS, REPRODUCTION = RESEARCH / "pedestrians.py", RESEARCH / "reproduction_tables.py"


def load(path: Path):
    """The research script at path as a module."""
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


script, reproduction = load(PEDESTRIANS), load(REPRODUCTION)
TINY = ["--preset", "table1-fit", "--variants", "2", "--n-test", "50", "--no-progress"]


def run(path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(path), *map(str, args)], capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def datasets(tiny_dataset, tmp_path_factory) -> list[Path]:
    """tiny_dataset and a copy of it under another scene name (a second scene, so that the study pools two)."""
    copy = tmp_path_factory.mktemp("copy") / "scene1b"
    shutil.copytree(tiny_dataset, copy)
    manifest = json.loads((copy / "manifest.json").read_text())
    (copy / "manifest.json").write_text(json.dumps({**manifest, "scene": "scene1b"}))
    return [tiny_dataset, copy]


@pytest.fixture(scope="module")
def studies(datasets, tmp_path_factory) -> dict[str, Path]:
    """Tiny complete studies of both datasets: seed 0 and 1, seed 0 with 40 test points, and seed 0 with a
    shard deleted (incomplete)."""
    root = tmp_path_factory.mktemp("studies")
    made = {}
    for name, extra in {"s0": [], "s1": ["--seed", "1"], "n40": ["--n-test", "40"], "cut": []}.items():
        assert main(["study", *map(str, datasets), "-o", str(root / name), *TINY, *extra]) == 0
        made[name] = root / name
    (made["cut"] / "shards" / "scene1b" / "variant_00001.parquet").unlink()
    return made


@pytest.fixture(scope="module")
def report(studies, tmp_path_factory) -> Path:
    """pedestrians.py --study s0, segmentation and rgb boxes of the first 1 and 1.5 s."""
    out = tmp_path_factory.mktemp("report") / "out"
    done = run(PEDESTRIANS, "--study", studies["s0"], "-o", out, "--detectors", "segmentation,rgb", "--seconds", "1,1.5")
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == (out / "pedestrians.md").read_text().strip()
    return out


def call(module, args, capsys) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of the script's main(args) run here (argparse's refusals exit by SystemExit)."""
    try:
        code = module.main([str(a) for a in args])
    except SystemExit as e:
        code = e.code
    out, err = capsys.readouterr()
    return code, out, err


def csv_rows(path: Path) -> list[dict]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def by_hand(dataset: Path, detector: str, seconds: float, params: StudyParams, start: float = 0.0
            ) -> tuple[np.ndarray, np.ndarray]:
    """(path improvement %, horizon error px) per variant: ViewTransformer and PedestrianCorrector fitted on each
    variant's clicked trapezoid from the boxes of `seconds` of video from `start`, the range errors in numpy."""
    camera = json.loads((dataset / "camera.json").read_text())
    fps = json.loads((dataset / "manifest.json").read_text())["fps"]
    boxes = pq.read_table(dataset / "detections.parquet")
    boxes = boxes.filter(pc.and_(pc.equal(boxes["detector"], detector), pc.and_(
        pc.greater_equal(boxes["frame"], start * fps), pc.less(boxes["frame"], (start + seconds) * fps))))
    xyxy = np.column_stack([boxes[c].to_numpy() for c in ("x1", "y1", "x2", "y2")]).astype(float)
    scene = StudyScene.from_dataset(dataset, params)  # the study's test points and variants
    o, g = scene.origin, scene.test_ground
    improvements, horizon = [], []
    for v in range(params.n_variants + 1):
        image, map_quad = scene.variant_quads(params, v)
        clicked = ViewTransformer(image, scene.site_map.to_metres(map_quad))
        fitted = PedestrianCorrector().fit(clicked, xyxy, convention="homocal", frames=boxes["frame"].to_numpy(),
                                           K=np.array(camera["K"]), camera_height_m=camera["mount_height_m"],
                                           image_size=(camera["width"], camera["height"]), camera_origin=o)
        true_range = np.hypot(*(g - o).T)
        before = np.abs(true_range - np.hypot(*(clicked.transform_points(scene.test_image) - o).T)).mean()
        after = np.abs(true_range - np.hypot(*(fitted.transform_points(scene.test_image) - o).T)).mean()
        improvements.append(100 * (before - after) / before)
        horizon.append(fitted.horizon_row_ - camera["horizon_row"])
    return np.array(improvements), np.array(horizon)


def test_pedestrian_rows_against_the_corrector_by_hand(report, studies, datasets):
    """Each scene's row and the pooled row: positive share, median, 1st percentile (numpy's linear), failures and
    horizon RMS from one PedestrianCorrector fit per variant by hand; one variant's improvement from variant_rows."""
    params = StudyParams.from_dict(json.loads((studies["s0"] / "study.json").read_text()))
    rows = {(r["scene"], r["detector"], r["seconds"]): r for r in csv_rows(report / "pedestrians.csv")}
    assert len(rows) == 2 * 2 * 3  # 2 scenes and pooled x 2 detectors x 2 seconds
    for detector in ("segmentation", "rgb"):
        pooled = []
        for dataset, scene in zip(datasets, ("scene1", "scene1b")):
            path, horizon = by_hand(dataset, detector, 1.0, params)
            pooled.append(path)
            row = rows[scene, detector, "1.0"]
            assert int(row["variants"]) == 3 and row["refused"] == "False" and int(row["failures"]) == 0
            assert float(row["pos_path"]) == pytest.approx(100 * np.mean(path > 0))
            assert float(row["median_path"]) == pytest.approx(np.median(path), rel=1e-6)
            assert float(row["p1_path"]) == pytest.approx(np.percentile(path, 1), rel=1e-6)
            assert float(row["horizon_rms_px"]) == pytest.approx(np.sqrt(np.mean(horizon**2)), rel=1e-9)
        row = rows["overall", detector, "1.0"]
        assert float(row["median_path"]) == pytest.approx(np.median(np.concatenate(pooled)), rel=1e-6)
    args = script.argparse.Namespace(height_mean=1.65, height_sd=0.09, model="camera", estimate_camera=False,
                                     accept_outliers=False)
    ds = script.load_dataset(datasets[0])
    one = script.variant_rows(StudyScene.from_dataset(datasets[0], params), params, ds,
                              *script.detector_boxes(ds, "segmentation", 1.0), args)[1]
    assert one["variant"] == 1 and one["path"] == pytest.approx(by_hand(datasets[0], "segmentation", 1.0, params)[0][1], rel=1e-12)


def test_seven_methods_are_the_reports_table_csv(report, studies, tmp_path):
    """pedestrians.md's method rows per scene and pooled: homocal report's table.csv numbers, as its table formats them."""
    assert main(["report", str(studies["s0"]), "-o", str(tmp_path / "r"), "--no-progress"]) == 0
    table = {(r["method"], r["metric"]): r for r in csv_rows(tmp_path / "r" / "table.csv")}
    sections = (report / "pedestrians.md").read_text().split("\n## ")[1:]
    assert [s.split("\n")[0] for s in sections] == ["scene1", "scene1b", "all scenes pooled"]
    for section, scope in zip(sections, ("scene1", "scene1b", "overall")):
        cells = {line.split(" | ")[0].strip("| "): line.strip("| ").split(" | ") for line in section.splitlines()[3:] if line}
        for method in METHODS:
            expected = [format_metric(k, float(table[method, k][scope])) for k in ("n", *script.TAILS)]
            assert cells[method][1:7] == expected, (scope, method)
        assert sum(name.startswith("pedestrians, ") for name in cells) == 4
    assert set(script.TAILS) <= set(METRICS)


def test_a_refused_fit_is_a_row_of_failures(studies, datasets, tmp_path):
    """A prior no box fits (2.4 m): PedestrianCorrector.fit refuses; the row says why, its variants are failures,
    the command goes on (exit 0); the same in DATASET mode."""
    done = run(PEDESTRIANS, "--study", studies["s0"], "-o", tmp_path / "out", "--height-mean", "2.4", "--height-sd", "0.05")
    assert done.returncode == 0, done.stderr
    for row in csv_rows(tmp_path / "out" / "pedestrians.csv"):
        assert row["refused"] == "True" and "outliers" in row["refusal"] and row["people_used"] == ""
        assert (row["failures"], row["pos_path"], row["median_path"], row["rel_range_after_mean"]) == ("6" if row["scene"] == "overall" else "3", "0.0", "-inf", "inf")
    assert "(refused: xyxy: " in done.stdout
    done = run(PEDESTRIANS, datasets[0], "--variants", "1", "--height-mean", "2.4", "--height-sd", "0.05")
    line = json.loads(done.stdout.replace("-Infinity", "null").replace("Infinity", "null").replace("NaN", "null"))
    assert done.returncode == 0 and line["refused"] and line["failures"] == 2 and line["pos_path"] == 0.0
    done = run(PEDESTRIANS, datasets[0], "--variants", "1", "--height-mean", "2.4", "--height-sd", "0.05", "--accept-outliers")
    line = json.loads(done.stdout)  # --accept-outliers: the fit the refusal stopped, with its figures
    assert done.returncode == 0 and not line["refused"] and line["max_outlier_share"] == 1.0
    assert line["outlier_boxes"] > line["boxes"] / 2 and math.isfinite(line["horizon_rms_px"])


def test_dataset_mode_still_measures(datasets, tmp_path):
    """DATASET mode: one JSON line per detector and seconds value, on the variants it draws; --end-to-end writes
    its correction file to -o and prints its line."""
    subprocess.run([sys.executable, "-m", "simgen.cli", "export-mot", str(datasets[0]), "-o", str(tmp_path / "mot")],
                   check=True, capture_output=True, timeout=300)
    done = run(PEDESTRIANS, datasets[0], "--end-to-end", "exact", "--det", tmp_path / "mot" / "det" / "segmentation.txt",
               "-o", tmp_path)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["clicked_horizon_above_true_px"] == pytest.approx(16.0)
    assert (tmp_path / "end_to_end_scene1_exact.json").is_file()
    done = run(PEDESTRIANS, datasets[0], "--variants", "1", "--detectors", "segmentation,rgb", "--seconds", "1,1.5")
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert done.returncode == 0, done.stderr
    assert [(r["detector"], r["seconds"], r["variants"]) for r in lines] == [
        ("segmentation", 1.0, 2), ("segmentation", 1.5, 2), ("rgb", 1.0, 2), ("rgb", 1.5, 2)]
    assert all(r["pos_path"] == 100.0 and not r["refused"] for r in lines)


def test_windows_measure_every_disjoint_window_and_their_spread(datasets):
    """DATASET mode --windows: a line per disjoint window, each against a fit by hand on that window's boxes, then
    their mean, min and max."""
    done = run(PEDESTRIANS, datasets[0], "--variants", "1", "--seconds", "0.75", "--windows")
    assert done.returncode == 0, done.stderr
    *windows, spread = [json.loads(line) for line in done.stdout.splitlines()]
    assert [w["start"] for w in windows] == [0.0, 0.75] and spread["windows"] == 2
    params = script.preset_params(script.BASES["fitted"], n_variants=1)
    for w in windows:
        path, horizon = by_hand(datasets[0], "segmentation", 0.75, params, start=w["start"])
        assert w["horizon_rms_px"] == pytest.approx(np.sqrt(np.mean(horizon**2)), rel=1e-9)
        assert w["median_path"] == pytest.approx(np.median(path), rel=1e-6)
    rms = [w["horizon_rms_px"] for w in windows]
    assert rms[0] != rms[1]
    assert spread["horizon_rms_px"] == {"mean": pytest.approx(np.mean(rms)), "min": min(rms), "max": max(rms)}


@pytest.mark.parametrize("case, args, code, message", [
    ("missing", ["--study", "{absent}"], 1, "not a results directory"),
    ("not a study", ["--study", "{dataset}"], 1, "study.json: no such file"),
    ("incomplete", ["--study", "{cut}"], 1, "the study is not complete (1 shard(s) missing)"),
    ("seconds 0", ["--study", "{s0}", "--seconds", "0"], 2, "argument --seconds: must be a finite number > 0, got 0"),
    ("seconds nan", ["--study", "{s0}", "--seconds", "1,nan"], 2, "argument --seconds: must be a finite number > 0, got nan"),
    ("seconds twice", ["--study", "{s0}", "--seconds", "1,1"], 2, "argument --seconds: a value given twice"),
    ("seconds beyond", ["--study", "{s0}", "--seconds", "1,2"], 1, "--seconds 2: beyond the 1.5 s of video of scene1"),
    ("detector", ["--study", "{s0}", "--detectors", "segmentation,hog"], 1, "--detectors hog: scene1"),
    ("not our folder", ["--study", "{s0}", "-o", "{foreign}"], 1, "not a homocal-pedestrians-report output folder"),
    ("boxes form", ["--study", "{s0}", "--boxes", "{dataset}/detections.parquet"], 1, "with --study, expected SCENE=FILE"),
    ("boxes scene", ["--study", "{s0}", "--boxes", "scene9=x.csv"], 1, "'scene9' is not a scene of the study"),
    ("no out", ["--study", "{s0}", "-o", ""], 2, "--study needs -o OUT"),
    ("both modes", ["{dataset}", "--study", "{s0}"], 2, "give DATASET ... or --study STUDY"),
    ("dataset flag", ["--study", "{s0}", "--variants", "3"], 2, "--variants: not with --study"),
    ("prior", ["--study", "{s0}", "--height-sd", "0"], 2, "argument --height-mean/--height-sd: height_sd_m 0.0: expected a number in [0.01, 0.625] (m)"),
])
def test_pedestrians_bad_input_is_one_line(case, args, code, message, studies, tiny_dataset, tmp_path, capsys):
    """Each bad input: its exit code, the last stderr line naming it, nothing on stdout, no report folder made
    (and a folder that is not ours left as it was)."""
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / "notes.txt").write_text("mine")
    places = {"absent": tmp_path / "absent", "dataset": tiny_dataset, "foreign": tmp_path / "foreign", **studies}
    args = [a.format(**places) for a in args]
    if "-o" not in args:
        args += ["-o", str(tmp_path / "out")]
    elif "" in args:
        args = args[:args.index("-o")]
    returned, out, err = call(script, args, capsys)
    last = err.strip().splitlines()[-1]
    assert returned == code and last.startswith("pedestrians.py: error: ") and message in last, err
    assert out == "" and not (tmp_path / "out").exists()
    assert [p.name for p in (tmp_path / "foreign").iterdir()] == ["notes.txt"]
    if code == 1:
        assert len(err.strip().splitlines()) == 1


def test_reproduction_tables_of_two_seeds(studies):
    done = run(REPRODUCTION, studies["s0"], studies["s1"])
    assert done.returncode == 0, done.stderr
    assert "Table 1, seeds 0, 1" in done.stdout
    tables = [build_table(complete_shard_files(studies[s], load_study(studies[s]))) for s in ("s0", "s1")]
    values = [t.value("least_change", "median_path", OVERALL) for t in tables]
    row = next(line for line in done.stdout.splitlines() if line.startswith(f"| {METRICS['median_path'][0]} |"))
    cell = row.split(" | ")[1 + list(METHODS).index("least_change")]
    assert cell == f"{np.mean(values):.1f} ({min(values):.1f}..{max(values):.1f})" and values[0] != values[1]


@pytest.mark.parametrize("case, folders, message", [
    ("missing", ["{absent}"], "{absent}: not a results directory"),
    ("not a study", ["{dataset}"], "study.json: no such file"),
    ("empty study.json", ["{empty}"], "needs a non-empty 'datasets' list"),
    ("configurations differ", ["{s0}", "{n40}"], "its configuration differs from {s0}'s other than by seed (n_test)"),
    ("same seed twice", ["{s0}", "{s0}"], "the same seed (0) as {s0}"),
    ("incomplete", ["{cut}"], "{cut}: the study is not complete (1 shard(s) missing)"),
])
def test_reproduction_tables_bad_input_is_one_line(case, folders, message, studies, tiny_dataset, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "study.json").write_text(json.dumps({"format": "homocal-study", "datasets": []}))
    places = {"absent": tmp_path / "absent", "dataset": tiny_dataset, "empty": tmp_path / "empty", **studies}
    code, out, err = call(reproduction, [f.format(**places) for f in folders], capsys)
    lines = err.strip().splitlines()
    assert code == 1 and len(lines) == 1 and message.format(**places) in lines[0], err
    assert lines[0].startswith("reproduction_tables.py: error: ") and out == ""


@pytest.mark.parametrize("args, flag", [(["--samples", "0"], "--samples"), (["--samples", "x"], "--samples"),
                                        (["--seed", "-1"], "--seed"), (["--seed", "1.5"], "--seed")])
def test_compare_least_change_bad_counts_are_one_line(args, flag, tmp_path):
    """research/compare_least_change.py refuses a count it cannot draw (no samples: no percentiles; a negative
    seed) as argparse's one line naming the flag, before reading any dataset."""
    done = run(RESEARCH / "compare_least_change.py", str(tmp_path), *args)
    assert done.returncode == 2 and done.stdout == "" and flag in done.stderr.strip().splitlines()[-1]


def test_foot_sources_exact_detections_alone_is_refused(tmp_path):
    """research/foot_sources.py --exact-detections without --calibration (which writes the dataset it applies to)
    is one line naming the flag, not an option silently ignored."""
    done = run(RESEARCH / "foot_sources.py", str(tmp_path), "--exact-detections")
    assert done.returncode == 2 and done.stdout == "" and "--exact-detections" in done.stderr.strip().splitlines()[-1]
